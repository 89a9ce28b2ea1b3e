"""Old import paths of :mod:`leaderboard`, kept for one release after its service was cut in
routers (0.2.0; see ``CHANGELOG.md``): importing one still works and raises a
:class:`DeprecationWarning` that names the new home.

* :data:`MOVED_MODULES`: a module that moved whole (``leaderboard.checks`` ->
  ``leaderboard.query_checks``) is the same module object under its old name.

The mechanism is the kernel's (:mod:`dg16m_core.compat`); this module is the table.
"""

from __future__ import annotations

from dg16m_core import compat
from dg16m_core.compat import REMOVED_IN

__all__ = ["MOVED_MODULES", "REMOVED_IN", "install"]

MOVED_MODULES: dict[str, tuple[str, ...]] = {
    "leaderboard.checks": ("leaderboard.query_checks",),
    # the connection guard wraps uvicorn's protocol instead of subclassing it; its old module
    # keeps error_body, REASONS and H11_DEFAULT_HEAD_BYTES (not GuardedH11Protocol)
    "leaderboard.protocol": ("leaderboard.connections",),
}
"""Old module name -> its new module."""


def install() -> None:
    """Put the finder of the old module names on ``sys.meta_path`` (once)."""
    compat.install(MOVED_MODULES)
