"""Old import paths of :mod:`baselines`, kept for one release after two modules were renamed
for what they hold (0.2.0; see ``CHANGELOG.md``): importing one still works and raises a
:class:`DeprecationWarning` that names the new home.

* :data:`MOVED_MODULES`: a module that moved whole (``baselines.pairing`` ->
  ``baselines.pairing_baselines``) is the same module object under its old name, so a predictor
  named ``baselines.pairing:force_closure_baseline`` still loads.

The mechanism is the kernel's (:mod:`dg16m_core.compat`); this module is the table.
"""

from __future__ import annotations

from dg16m_core import compat
from dg16m_core.compat import REMOVED_IN

__all__ = ["MOVED_MODULES", "REMOVED_IN", "install"]

_B = "baselines"

MOVED_MODULES: dict[str, tuple[str, ...]] = {
    # the paper's pairing baselines (dataset_gen.grasps.pairing is the generator's pairing)
    f"{_B}.pairing": (f"{_B}.pairing_baselines",),
    # the `dg16m baselines` and `dg16m reproduce` commands (every package had a commands.py)
    f"{_B}.commands": (f"{_B}.baseline_commands",),
}
"""Old module name -> its new module(s); a name is looked up in them in order."""


def install() -> None:
    """Put the finder of the old module names on ``sys.meta_path`` (once)."""
    compat.install(MOVED_MODULES)
