"""Command-line options that many ``dg16m`` commands share, each written once.

Every package's command modules (``dataset_gen.cli``, ``dg16m_env.cli``, the baselines' and the
leaderboard's commands) add these options with the helpers below rather than spelling the same
``add_argument`` calls again, so an option reads alike wherever it appears. The help text stays
each caller's (it names what the option means for that command), so ``--help`` output is the
caller's own.

A light module: argparse and :mod:`pathlib` only, safe to import when the ``dg16m`` parser is
built (see :mod:`dg16m_core.cli`).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

BACKENDS: tuple[str, ...] = ("local", "ray")
"""The values of ``--backend``: local processes or a Ray cluster."""


def add_parallel_arguments(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    workers_help: str = "local processes (default: 1)",
    *,
    ray: bool = True,
) -> None:
    """``--workers N`` (default 1) and, with ``ray``, ``--backend {local,ray}`` and
    ``--address`` (a Ray head), in this order."""
    parser.add_argument("--workers", type=int, default=1, help=workers_help)
    if ray:
        parser.add_argument("--backend", choices=BACKENDS, default="local")
        parser.add_argument("--address", default=None, help="Ray address: auto or host:port")


def parallel_options(args: argparse.Namespace) -> dict[str, Any]:
    """What :func:`add_parallel_arguments` parsed, as keywords of the runners
    (``workers``, ``backend``, ``address``)."""
    return {"workers": args.workers, "backend": args.backend, "address": args.address}


def add_progress_argument(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup, help_text: str = "no progress bar"
) -> None:
    """``--no-progress``: a flag that turns the progress bar off (read as
    ``not args.no_progress``)."""
    parser.add_argument("--no-progress", action="store_true", help=help_text)


def add_seed_argument(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    help_text: str = "global seed (default: 0)",
    **kwargs: object,
) -> None:
    """``--seed S``: an integer seed, default 0 (``kwargs``: more ``add_argument`` keywords,
    e.g. ``metavar``)."""
    parser.add_argument("--seed", type=int, default=0, help=help_text, **kwargs)  # type: ignore[arg-type]


def add_out_argument(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    help_text: str,
    *,
    required: bool = True,
) -> None:
    """``--out PATH``: where the command writes (a path; required unless ``required=False``)."""
    if required:
        parser.add_argument("--out", type=Path, required=True, help=help_text)
    else:
        parser.add_argument("--out", type=Path, help=help_text)


def add_limit_argument(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    help_text: str,
    default: int | None = None,
    **kwargs: object,
) -> None:
    """``--limit N``: at most N of the command's items (default ``default``; ``kwargs``: more
    ``add_argument`` keywords, e.g. ``metavar``)."""
    parser.add_argument("--limit", type=int, default=default, help=help_text, **kwargs)  # type: ignore[arg-type]


def listed_ids(text: str, file: Path | None = None) -> list[str]:
    """The ids an option lists: those of ``file`` when given (one a line; blank lines and ``#``
    comments skipped), else ``text`` read as ``a,b,c``; empty entries dropped (the list may be
    empty: the caller says what it expected)."""
    if file is not None:
        ids = [line.split("#", 1)[0].strip() for line in file.read_text("utf-8").splitlines()]
    else:
        ids = [part.strip() for part in text.split(",")]
    return [i for i in ids if i]


__all__ = [
    "BACKENDS",
    "add_limit_argument",
    "add_out_argument",
    "add_parallel_arguments",
    "add_progress_argument",
    "add_seed_argument",
    "listed_ids",
    "parallel_options",
]
