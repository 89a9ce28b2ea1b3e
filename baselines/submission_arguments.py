"""Arguments of ``dg16m baselines submissions`` and ``python -m baselines.reference_submissions``.

A light module (argparse and the benchmark arguments only) below both users: the command
module (:mod:`baselines.baseline_commands`) adds them to ``dg16m``'s parser without importing the
baselines' heavy dependencies (so ``dg16m --help`` stays fast), and
:mod:`baselines.reference_submissions` adds them to its own ``main``. Neither imports the other
back.
"""

from __future__ import annotations

import argparse

from dg16m_core import arguments
from dg16m_env.cli.evaluate import add_benchmark_arguments

DEFAULT_STRATEGIES: tuple[str, ...] = ("random", "farthest", "force_closure", "benchmark_fc_pass")
"""The reference submissions written by default, one file ``<name>.h5`` each (names among
:data:`baselines.reference_submissions.STRATEGIES`)."""


def add_submission_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``dg16m baselines submissions`` (also
    ``python -m baselines.reference_submissions``)."""
    arguments.add_out_argument(parser, "output folder")
    parser.add_argument(
        "--k", type=int, default=10, help="dual grasps per object and baseline (default 10)"
    )
    arguments.add_seed_argument(parser, "global seed (default 0)")
    arguments.add_parallel_arguments(parser, "local processes (default 1)", ray=False)
    add_benchmark_arguments(parser)
    parser.add_argument(
        "--strategies",
        default=",".join(DEFAULT_STRATEGIES),
        help=f"comma-separated baselines (default {','.join(DEFAULT_STRATEGIES)})",
    )
    arguments.add_progress_argument(parser)


__all__ = ["DEFAULT_STRATEGIES", "add_submission_arguments"]
