"""The generator's ``dg16m`` subcommands (the top floor of :mod:`dataset_gen`).

``objects`` (``dg16m objects ...``), ``files`` (``show``, ``inspect``, ``grippers``),
``generate`` (``generate``, ``stats``), ``verify``. :func:`register` is the package's one entry
of the ``dg16m.commands`` group and adds them in the order ``dg16m --help`` lists them. Each
command module imports only light things at its top (argparse, :mod:`dg16m_core`); its handlers
import the rest when they run.

May import: everything of :mod:`dataset_gen` and :mod:`dg16m_core`.

Until 0.3.0, the names of the old module ``dataset_gen.cli`` (now :mod:`dg16m_core.cli`) are
found here with a :class:`DeprecationWarning`.
"""

from __future__ import annotations

from typing import Any

from dataset_gen._compat import moved_names

__getattr__ = moved_names(__name__)


def register(subparsers: Any) -> None:
    """Add the generator's subcommands to the ``dg16m`` parser, in ``dg16m --help`` order."""
    from dataset_gen.cli import files, generate, objects, verify

    objects.register(subparsers)
    files.register(subparsers)
    generate.register(subparsers)
    verify.register(subparsers)
