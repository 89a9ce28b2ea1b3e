"""The ``dg16m`` command line.

Each package contributes subcommands through a module with ``register(subparsers)``; the modules
are listed in :data:`COMMAND_MODULES` (imported by name, so ``dataset_gen`` does not depend on
the packages layered above it). Errors caused by input (:class:`~dataset_gen.errors.Dg16mError`)
print one line and exit with status 2; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import textwrap
from collections.abc import Sequence
from typing import Any

from dataset_gen.errors import Dg16mError

COMMAND_MODULES: tuple[str, ...] = (
    "dataset_gen.commands",
    "dataset_gen.verify_command",
    "dataset_gen.generate_command",
    "dg16m_env.benchmark_command",
    "dg16m_env.sim_command",
)
"""Modules that add subcommands, in the order they appear in ``dg16m --help``."""


def add_command(
    subparsers: Any,
    name: str,
    help_text: str,
    examples: str,
    *,
    description: str | None = None,
    **kwargs: Any,
) -> argparse.ArgumentParser:
    """Add one ``dg16m`` subcommand with its one-line help, a wrapped description and examples.

    Every package's command module builds its parsers with this, so all commands look alike.
    ``examples`` is a block of indented command lines shown under "examples:" in ``--help``.
    """
    return subparsers.add_parser(
        name,
        help=help_text,
        description=textwrap.fill(description or help_text, 88),
        epilog="examples:\n" + examples,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        **kwargs,
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="dg16m",
        description=(
            "Make, check and benchmark dual-arm grasps (a reproduction of the DG16M dataset "
            "and benchmark). Run 'dg16m COMMAND --help' for each command's options and examples."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "examples:\n"
            "  dg16m objects make --count 20 --seed 0 --out runs/objects\n"
            "  dg16m show grasps.h5 --mesh airplane.obj --out grasps.png\n"
        ),
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args) or 0)
    except Dg16mError as exc:
        print(f"dg16m {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"dg16m {args.command}: interrupted", file=sys.stderr)
        return 130


def _version() -> str:
    from dataset_gen.io import package_version

    return package_version()


if __name__ == "__main__":
    sys.exit(main())
