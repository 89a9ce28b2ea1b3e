"""``dg16m baselines submissions`` (the reference submissions of the pairing baselines) and
``dg16m reproduce`` (the paper's tables and figure): the commands of :mod:`baselines` besides
``dg16m demo`` (:mod:`baselines.demo`).

The logic lives in :mod:`baselines.reference_submissions` and :mod:`baselines.reproduce`; this
module holds only the command line and sits above them: it imports them, nothing they import
imports it (the arguments shared with ``python -m baselines.reference_submissions`` live in
:mod:`baselines.submission_arguments`). Heavy imports happen inside the handlers so that
``dg16m --help`` stays fast.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from baselines.submission_arguments import DEFAULT_STRATEGIES, add_submission_arguments
from dg16m_core import arguments
from dg16m_core.cli import add_command
from dg16m_env.cli.evaluate import add_benchmark_arguments

BASELINES_EXAMPLES = (
    "  dg16m baselines submissions --out runs/reference --workers 2\n"
    "  dg16m evaluate runs/reference/force_closure.h5 --evaluators fce\n"
)

SUBMISSIONS_EXAMPLES = (
    "  # the four reference submissions for the shipped benchmark, on 2 processes (~2 minutes)\n"
    "  dg16m baselines submissions --out runs/reference --workers 2\n"
    "  # 20 grasps per object, only the sampled baselines, another seed\n"
    "  dg16m baselines submissions --out runs/ref20 --k 20 --seed 1 \\\n"
    "      --strategies random,farthest,force_closure\n"
    "  # a benchmark you built\n"
    "  dg16m baselines submissions --out runs/mine-ref --benchmark runs/bench10/benchmark.h5\n"
)


def register(subparsers: Any) -> None:
    """Add ``dg16m baselines {submissions}`` and ``dg16m reproduce``."""
    baselines = add_command(
        subparsers,
        "baselines",
        "Reference predictions of the baselines (the paper's pairing strategies).",
        BASELINES_EXAMPLES,
        description="Baselines to compare against (see 'dg16m baselines submissions --help').",
    )
    sub = baselines.add_subparsers(dest="baselines_command", metavar="ACTION", required=True)
    submissions = add_command(
        sub,
        "submissions",
        "Write one submission file per pairing baseline (random, farthest, force closure, "
        "the benchmark's own passing pairs).",
        SUBMISSIONS_EXAMPLES,
        description=(
            "For each benchmark object: sample single-arm grasps (the benchmark's count, a "
            "seeded stream of its own), pair them and keep K dual grasps by the paper's "
            "Table III strategies: random collision-free candidates (random.h5), farthest "
            "pairs (farthest.h5), force-closure-passing candidates (force_closure.h5, scores "
            "-loss). benchmark_fc_pass.h5 holds the benchmark's own first K stored passing "
            "pairs per object. Files are written to OUT as dg16m submissions (score them with "
            "the fce or gsr evaluators). Results do not depend on --workers."
        ),
    )
    add_submission_arguments(submissions)
    submissions.set_defaults(handler=run_submissions)
    register_reproduce(subparsers)


REPRODUCE_EXAMPLES = (
    "  dg16m reproduce table3 --out runs/table3 --workers 2        # ~20 minutes\n"
    "  dg16m reproduce table3 --out runs/t3-quick --limit 2        # 2 objects per category\n"
    "  dg16m reproduce table2 --out runs/table2                    # the shipped checkpoints\n"
    "  dg16m reproduce table2 --out runs/t2 --checkpoints runs/classifiers\n"
    "  dg16m reproduce fig4 --out runs/fig4 --objects 20 --workers 2\n"
)


def register_reproduce(subparsers: Any) -> None:
    """Add ``dg16m reproduce {table2,table3,fig4}``."""
    reproduce = add_command(
        subparsers,
        "reproduce",
        "Re-run the paper's Table II, Table III or Fig. 4 on our data, beside its numbers.",
        REPRODUCE_EXAMPLES,
        description=(
            "Each writes its table (Markdown, CSV, and JSON with every result record and seed) "
            "or figure (PNG, JSON) to --out, with the paper's numbers beside ours; rates carry "
            "object-resampled 95%% confidence intervals. See baselines/reproduce.py and "
            "baselines/RESULTS.md."
        ),
    )
    which = reproduce.add_subparsers(dest="reproduce_command", metavar="RESULT", required=True)
    t3 = add_command(
        which,
        "table3",
        "Pairing strategies (random, farthest, force closure): FCE and GSR.",
        REPRODUCE_EXAMPLES,
    )
    t2 = add_command(
        which,
        "table2",
        "Classifiers trained on our labels vs DA2-style labels: top-k FCE and GSR.",
        REPRODUCE_EXAMPLES,
    )
    f4 = add_command(
        which,
        "fig4",
        "Q(G) of passing vs failing pairs, by our labels and by DA2's.",
        REPRODUCE_EXAMPLES,
    )
    for parser in (t3, t2, f4):
        arguments.add_out_argument(parser, "output folder")
        arguments.add_progress_argument(parser, "no progress bars")
    for parser in (t3, t2):
        add_benchmark_arguments(parser)
        arguments.add_limit_argument(
            parser,
            "only the first N objects of each category (a family; a real object's catalogue "
            "category)",
        )
        parser.add_argument("--k", type=int, default=10, help="dual grasps per object (10)")
    for parser in (t3, f4):
        arguments.add_seed_argument(parser, "global seed (default 0)")
        arguments.add_parallel_arguments(parser, "local processes", ray=False)
    t2.add_argument(
        "--checkpoints", type=Path, default=None, help="folder of <model>-<labels>.pt files"
    )
    f4.add_argument("--data", type=Path, default=None, help="a 'dg16m generate' folder")
    f4.add_argument(
        "--objects", type=int, default=20, help="without --data: train objects to generate"
    )
    reproduce.set_defaults(handler=run_reproduce)


def run_reproduce(args: argparse.Namespace) -> int:
    """Handler of ``dg16m reproduce``: prints the table or the figure's summary."""
    from baselines import reproduce

    progress = not args.no_progress
    table = args.reproduce_command
    if table in ("table3", "table2"):  # the options both tables take (see register)
        common = {
            "benchmark": args.benchmark,
            "mesh_root": args.mesh_root,
            "limit": args.limit,
            "k": args.k,
            "progress": progress,
        }
        if table == "table3":
            reproduce.table3(args.out, seed=args.seed, workers=args.workers, **common)
        else:
            reproduce.table2(args.out, checkpoints=args.checkpoints, **common)
        print((args.out / f"{table}.md").read_text(encoding="utf-8"))
    else:
        payload = reproduce.fig4(
            args.out,
            data=args.data,
            objects=args.objects,
            seed=args.seed,
            workers=args.workers,
            progress=progress,
        )
        for key in ("q_by_dg16m_label", "q_by_da2_label"):
            print(f"{key}: ROC AUC {payload[key].get('auc')}")
        print(f"wrote {args.out / 'fig4.png'}")
    print(f"wrote {args.out}")
    return 0


def run_submissions(args: argparse.Namespace) -> int:
    """Handler of ``dg16m baselines submissions``: 0 when every file is written, 1 when some
    baseline failed on some object (see :func:`baselines.reference_submissions.run_submissions`;
    imported here, in the handler, so that ``dg16m --help`` stays fast)."""
    from baselines import reference_submissions

    return reference_submissions.run_submissions(args)


__all__ = [
    "DEFAULT_STRATEGIES",
    "add_submission_arguments",
    "register",
    "register_reproduce",
    "run_reproduce",
    "run_submissions",
]
