"""The ``dg16m`` command line.

Commands belong to their packages. Each package lists its command modules in the entry-point
group :data:`COMMAND_GROUP` of its ``pyproject.toml``, one entry per module::

    [project.entry-points."dg16m.commands"]
    "dataset_gen.cli.objects" = "dataset_gen.cli.objects:register"
    "mypackage.commands" = "mypackage.commands:register"

where ``register(subparsers)`` adds the module's subcommands (built with :func:`add_command`).
The CLI discovers the group with :func:`importlib.metadata.entry_points`, so ``dataset_gen``
names no package above it and a new package adds commands without touching it.

Order in ``dg16m --help``: ``dataset_gen``'s entries first (the base layer), then every other
entry; each part sorted by entry-point name (by convention the module path, so commands group
by package). A plugin that cannot be imported or whose ``register`` fails is reported on stderr
by its entry-point name and value, and the other commands keep working.

Start-up: building the parser imports every command module, so a command module imports only
light things at its top (argparse, this module, :mod:`dg16m_core.errors`, small modules of
constants) and its handlers import the rest when they run; a command whose options need a value
of a heavy module adds them on first use (``add_command(..., arguments=...)``). ``dg16m --help``
and ``dg16m --version`` then import no trimesh, SciPy, h5py, MuJoCo, torch or Ray; Gymnasium
(with numpy) comes in with the environments' package, which registers them on import
(``tests/test_cli_startup.py``; ``bench/cli_startup.py`` times them).

Exit status: 0 on success; ``dg16m`` without arguments prints this help and exits 0; errors
caused by input (:class:`~dg16m_core.errors.Dg16mError`, and the operating system's errors about
a path the user gave, :data:`PATH_ERRORS`: a file where a folder must go, a missing file) print
one line and exit 2 (so do argparse's usage errors): a path that is missing or that cannot be
read as the expected kind of file is bad input for every command; a command returns 1 when it
read its input and finished with failures it lists (a run with failed objects, meshes that fail
``objects check``, a submission with problems); 130 on Ctrl-C; a closed output pipe (``dg16m ... | head``) ends quietly with 141, as a
process killed by SIGPIPE. Anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
import textwrap
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import metadata
from typing import Any

from dg16m_core.errors import Dg16mError

COMMAND_GROUP = "dg16m.commands"
"""Entry-point group of the modules that add ``dg16m`` subcommands."""

BASE_PACKAGE = "dataset_gen"
"""This package: its commands come first in ``dg16m --help``."""

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE, what a shell reports for a process killed by the signal


@dataclass(frozen=True)
class CommandPlugin:
    """One entry of :data:`COMMAND_GROUP`: ``name = "module:function"``."""

    name: str
    value: str

    @property
    def is_base(self) -> bool:
        return self.value.split(":", 1)[0].split(".", 1)[0] == BASE_PACKAGE

    def load(self) -> Callable[[Any], None]:
        """The ``register`` function; raises whatever importing the module raises."""
        module_name, _, attr = self.value.partition(":")
        if not module_name or not attr:
            raise Dg16mError(f"expected 'module:function', found {self.value!r}")
        return metadata.EntryPoint(self.name, self.value, COMMAND_GROUP).load()


def command_plugins() -> list[CommandPlugin]:
    """The installed command plugins in ``dg16m --help`` order (see the module docstring).

    An entry installed twice (the same name and value from two copies of a distribution) is
    listed once.
    """
    found = {
        (ep.name, ep.value): CommandPlugin(ep.name, ep.value)
        for ep in metadata.entry_points(group=COMMAND_GROUP)
    }
    return sorted(found.values(), key=lambda p: (not p.is_base, p.name, p.value))


def add_command(
    subparsers: Any,
    name: str,
    help_text: str,
    examples: str,
    *,
    description: str | Callable[[], str] | None = None,
    arguments: Callable[[argparse.ArgumentParser], None] | None = None,
    **kwargs: Any,
) -> argparse.ArgumentParser:
    """Add one ``dg16m`` subcommand with its one-line help, a wrapped description and examples.

    Every package's command module builds its parsers with this, so all commands look alike.
    ``examples`` is a block of indented command lines shown under "examples:" in ``--help``.

    ``arguments``, when given, adds the command's arguments the first time the command is used
    (parsed, or its help or usage shown) rather than now, and ``description`` may then be a
    function that returns the text: for a command whose options or description need a value
    defined in a heavy module (one that imports trimesh or MuJoCo), so that building the
    ``dg16m`` parser, and with it ``dg16m --help``, imports none of them.
    """
    if callable(description) and arguments is None:
        raise TypeError("add_command: a description function needs arguments= (added on use)")

    def fill(text: str) -> str:
        # argparse %-formats help strings but not descriptions: "95%%" in either reads "95%"
        return textwrap.fill(text.replace("%%", "%"), 88)

    parser = subparsers.add_parser(
        name,
        help=help_text,
        description=None if callable(description) else fill(description or help_text),
        epilog="examples:\n" + examples,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        **kwargs,
    )
    if arguments is None:
        return parser

    def complete() -> None:
        if callable(description):
            parser.description = fill(description())
        arguments(parser)

    if type(parser) is argparse.ArgumentParser:
        parser.__class__ = _DeferredParser
        parser._pending = complete  # type: ignore[attr-defined]
    else:  # a parser class of someone else's: no deferring, the arguments are added now
        complete()
    return parser


class _DeferredParser(argparse.ArgumentParser):
    """A subcommand's parser whose arguments are added when it is first used: parsed (argparse
    hands a subcommand's arguments to its parser's ``parse_known_args``) or its help or usage
    formatted (``print_help``, ``print_usage`` and ``error`` go through these)."""

    _pending: Callable[[], None] | None = None

    def _complete(self) -> None:
        pending, self._pending = self._pending, None
        if pending is not None:
            pending()

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        self._complete()
        return super().parse_known_args(args, namespace)

    def parse_known_intermixed_args(self, args: Any = None, namespace: Any = None) -> Any:
        self._complete()
        return super().parse_known_intermixed_args(args, namespace)

    def format_usage(self) -> str:
        self._complete()
        return super().format_usage()

    def format_help(self) -> str:
        self._complete()
        return super().format_help()


def build_parser(
    plugins: Sequence[CommandPlugin] | None = None,
    on_broken: Callable[[CommandPlugin, BaseException], None] | None = None,
) -> argparse.ArgumentParser:
    """The ``dg16m`` parser with the subcommands of every plugin that loads.

    Args:
        plugins: the command plugins (default: :func:`command_plugins`).
        on_broken: called with a plugin that cannot be imported or registered and the error
            (default: a warning on stderr). Its commands are left out; the others still work.

    Raises:
        Dg16mError: no plugin registered any command (the package is not installed).
    """
    parser = argparse.ArgumentParser(
        prog="dg16m",
        description=textwrap.fill(
            "Make, check and benchmark dual-arm grasps (a reproduction of the DG16M dataset "
            "and benchmark). Run 'dg16m COMMAND --help' for each command's options and examples.",
            88,
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "examples:\n"
            "  dg16m objects make --count 20 --seed 0 --out runs/objects\n"
            "  dg16m generate --procedural 20 --out runs/dataset --workers 2\n"
            "  dg16m show runs/dataset/grasps/table-0000000.h5 \\\n"
            "      --mesh runs/dataset/meshes/table-0000000.obj --out table.png\n"
        ),
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    report = on_broken or _warn_broken
    for plugin in command_plugins() if plugins is None else plugins:
        before = dict(subparsers.choices)
        try:
            plugin.load()(subparsers)
        except Exception as exc:  # a broken plugin must not take the other commands down
            _forget_commands(subparsers, before)
            report(plugin, exc)
    if not subparsers.choices:
        raise Dg16mError(
            f"expected subcommands registered in the entry-point group {COMMAND_GROUP!r}, found "
            "none (is the dg16m package installed? run: pip install -e .)"
        )
    return parser


def _forget_commands(subparsers: Any, before: dict[str, argparse.ArgumentParser]) -> None:
    """Remove the subcommands a failing plugin added before it failed."""
    added = set(subparsers.choices) - set(before)
    for name in added:
        del subparsers.choices[name]
    subparsers._choices_actions[:] = [a for a in subparsers._choices_actions if a.dest not in added]


def _warn_broken(plugin: CommandPlugin, exc: BaseException) -> None:
    print(
        f"dg16m: warning: command plugin {plugin.name!r} ({plugin.value}, entry-point group "
        f"{COMMAND_GROUP!r}) failed to load and its commands are unavailable: "
        f"{type(exc).__name__}: {exc} (reinstall with: pip install -e .)",
        file=sys.stderr,
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``dg16m`` with ``argv`` (default: the process arguments); returns the exit status."""
    try:
        code = _run(sys.argv[1:] if argv is None else list(argv))
        sys.stdout.flush()  # a closed pipe shows up here, not at interpreter exit
        return code
    except SystemExit as exit_:  # argparse's --help, --version and usage errors
        try:
            sys.stdout.flush()
        except BrokenPipeError:
            return _quiet_broken_pipe()
        raise exit_ from None
    except BrokenPipeError:
        if not _stdout_is_broken():
            raise  # some other pipe (a worker, a socket): a real error
        return _quiet_broken_pipe()


def _run(argv: list[str]) -> int:
    try:
        parser = build_parser()
    except Dg16mError as exc:
        print(f"dg16m: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if not argv:
        parser.print_help()
        return 0
    args = parser.parse_args(argv)
    if getattr(args, "handler", None) is None:  # e.g. only global options were given
        parser.print_help()
        return 0
    try:
        return int(args.handler(args) or 0)
    except Dg16mError as exc:
        print(f"dg16m {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except PATH_ERRORS as exc:  # a path the user gave that is not what the command needs
        print(f"dg16m {args.command}: error: {path_error_message(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"dg16m {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


PATH_ERRORS = (
    FileExistsError,
    NotADirectoryError,
    IsADirectoryError,
    PermissionError,
    FileNotFoundError,
)
"""Errors of the operating system about a path, which a command reports as bad input."""


def path_error_message(exc: OSError) -> str:
    """One line for an operating-system error about a path: what was expected, what was found."""
    where = exc.filename if exc.filename is not None else "a path"
    reason = exc.strerror or type(exc).__name__
    if isinstance(exc, FileExistsError):
        return f"{where}: expected a folder or nothing there, found a file ({reason})"
    if isinstance(exc, NotADirectoryError):
        return f"{where}: expected a folder, found a file on the way ({reason})"
    if isinstance(exc, IsADirectoryError):
        return f"{where}: expected a file, found a folder ({reason})"
    if isinstance(exc, PermissionError):
        return f"{where}: expected a path this user may use, found it forbidden ({reason})"
    return f"{where}: expected it to exist, found nothing there ({reason})"


def _stdout_is_broken() -> bool:
    """Whether standard output is a pipe whose reader has gone (POLLERR on its write end)."""
    try:
        import select

        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(event & select.POLLERR for _, event in poller.poll(0))
    except (AttributeError, OSError, ValueError):  # no poll() (Windows) or no real stdout
        return True


def _quiet_broken_pipe() -> int:
    """Point stdout at /dev/null so the interpreter's final flush does not raise again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # stdout is not a real file (a test's capture)
        pass
    return EXIT_BROKEN_PIPE


def _version() -> str:
    # the light module, not dataset_gen.io (whose formats import h5py and trimesh: ~1 s)
    from dg16m_core.distribution import package_version

    return package_version()


if __name__ == "__main__":
    sys.exit(main())
