"""``dg16m benchmark build`` and ``dg16m benchmark info``: the simulation benchmark on the
command line. The logic lives in :mod:`dg16m_env.benchmark`; heavy imports (MuJoCo) happen inside
the handlers so that ``dg16m --help`` stays fast."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from dataset_gen.cli import add_command

BENCHMARK_EXAMPLES = (
    "  dg16m benchmark build --out runs/bench10 --limit 10\n"
    "  dg16m benchmark info runs/bench10/benchmark.h5\n"
)

BUILD_EXAMPLES = (
    "  # the 300-object procedural benchmark on 2 local processes (about 10 minutes)\n"
    "  dg16m benchmark build --out runs/benchmark --workers 2\n"
    "  # a quick look: the first 10 objects\n"
    "  dg16m benchmark build --out runs/bench10 --limit 10\n"
    "  # your own meshes and DG16M files (e.g. the real release), objects listed in split.txt\n"
    "  dg16m benchmark build --meshes meshes/ --grasps grasps/ --split split.txt --out runs/mine\n"
    "  # rerun the same command to resume: finished objects are skipped\n"
)

INFO_EXAMPLES = (
    "  dg16m benchmark info                      # the benchmark shipped with dg16m\n"
    "  dg16m benchmark info runs/benchmark/benchmark.h5 --plot runs/benchmark/summary.png\n"
)


def register(subparsers: Any) -> None:
    """Add ``dg16m benchmark {build,info}``."""
    bench = add_command(
        subparsers,
        "benchmark",
        "Build or summarise the MuJoCo dual-grasp benchmark (sim-labelled dual grasps).",
        BENCHMARK_EXAMPLES,
        description="Dual grasps on fixed objects, each labelled by a MuJoCo trial (see "
        "'dg16m benchmark build --help').",
    )
    sub = bench.add_subparsers(dest="benchmark_command", metavar="ACTION", required=True)
    build = add_command(
        sub,
        "build",
        "Sample, pair, check force closure and simulate: one benchmark file.",
        BUILD_EXAMPLES,
        description=(
            "For each object: sample single-arm grasps, pair them, check force closure, draw "
            "the four arms (force-closure passing, failing, random and farthest pairs; about "
            "100), and label each pair by its success probability p over K + 1 MuJoCo trials "
            "(the nominal hand poses and K = 8 perturbed ones, each hand moved 1 mm and turned "
            "1 degree; a trial: close, gravity, 12 disturbances; held when the object stays "
            "within 2 cm and 10 degrees of the hands). Writes OUT/objects/<id>.h5, "
            "OUT/manifest.json and OUT/benchmark.h5 (schema version 2). Results do not depend "
            "on --workers or --backend; reruns resume."
        ),
    )
    build.add_argument("--out", type=Path, required=True, help="output folder")
    build.add_argument(
        "--limit", type=int, default=None, help="only the first N procedural objects"
    )
    build.add_argument("--meshes", type=Path, help="folder of mesh files (with --grasps)")
    build.add_argument("--grasps", type=Path, help="folder of DG16M files <id>.h5 (with --meshes)")
    build.add_argument(
        "--split", default=None, help="object ids: a file (one per line) or id1,id2,..."
    )
    build.add_argument(
        "--grasp-gripper",
        default=None,
        help="gripper frame of the files' poses (default: the file's own, else robotiq_2f85 "
        "as in the DG16M release)",
    )
    build.add_argument("--workers", type=int, default=1, help="local processes (default 1)")
    build.add_argument("--backend", choices=("local", "ray"), default="local")
    build.add_argument("--address", default=None, help="Ray address: auto or host:port")
    build.add_argument("--seed", type=int, default=0, help="global seed (default 0)")
    build.add_argument(
        "--perturbations",
        type=int,
        default=None,
        metavar="K",
        help="perturbed trials per pair besides the nominal one (default: 8, the shipped "
        "benchmark's; fewer is faster and coarser, 0 labels by the nominal trial alone)",
    )
    build.add_argument("--no-progress", action="store_true", help="no progress bar")
    build.set_defaults(handler=_build)

    info = add_command(
        sub,
        "info",
        "Summarise a benchmark file: success probabilities per arm and level, failures.",
        INFO_EXAMPLES,
        description="Per arm (pair source), at both levels (full: held through every "
        "disturbance; gravity: held under gravity, the paper's): FCE, GSR (mean success "
        "probability p) over all pairs and over pairs with a valid nominal trial, each with an "
        "object-resampled 95% confidence interval, binary label rate and uncertain fraction "
        "(0.2 < p < 0.8). Then the histogram of p, the phases where failed trials broke, "
        "invalid trials, the hands' penetration and GSR per object family. Only schema "
        "version 2 files (rebuild older ones with 'dg16m benchmark build').",
    )
    info.add_argument(
        "file", type=Path, nargs="?", default=None, help="benchmark.h5 (default: the shipped one)"
    )
    info.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object instead of the text (finite numbers or null)",
    )
    info.add_argument(
        "--plot",
        type=Path,
        default=None,
        metavar="PNG",
        help="also write a 2 x 2 summary figure (GSR per arm, p, failure phases, penetration)",
    )
    info.set_defaults(handler=_info)


def _build(args: argparse.Namespace) -> int:
    from dg16m_env.benchmark import (
        BenchmarkError,
        BenchmarkParameters,
        build_benchmark,
        file_benchmark_sources,
        procedural_benchmark_sources,
        read_benchmark,
        read_split,
    )
    from dg16m_env.benchmark_report import format_summary
    from dg16m_env.labels import LabelError, PerturbationSpec

    try:
        perturbation = (
            PerturbationSpec()
            if args.perturbations is None
            else PerturbationSpec(n_perturbations=args.perturbations)
        )
    except LabelError as exc:
        raise BenchmarkError(f"--perturbations: {exc}") from None
    if (args.meshes is None) != (args.grasps is None):
        raise BenchmarkError("--meshes and --grasps: expected both or neither, found one")
    if args.meshes is not None:
        if args.limit is not None:
            raise BenchmarkError("--limit: expected only for the procedural benchmark")
        split = read_split(args.split) if args.split else None
        items = file_benchmark_sources(
            args.meshes, args.grasps, split, grasp_gripper=args.grasp_gripper
        )
    else:
        if args.split or args.grasp_gripper:
            raise BenchmarkError(
                "--split/--grasp-gripper: expected only with --meshes and --grasps"
            )
        items = procedural_benchmark_sources(args.limit)
    path = build_benchmark(
        items,
        args.out,
        BenchmarkParameters(seed=args.seed, perturbation=perturbation),
        workers=args.workers,
        backend=args.backend,
        address=args.address,
        progress=not args.no_progress,
    )
    print(format_summary(read_benchmark(path), path=path))
    print(f"wrote {path}")
    return 0


def _info(args: argparse.Namespace) -> int:
    from dg16m_env.benchmark import EMBEDDED_BENCHMARK, BenchmarkError, read_benchmark
    from dg16m_env.benchmark_report import benchmark_report, format_summary, plot_summary

    path = args.file if args.file is not None else EMBEDDED_BENCHMARK
    if args.file is None and not path.is_file():
        raise BenchmarkError(f"expected the shipped benchmark at {path}, found none (give a file)")
    bench = read_benchmark(path)  # BenchmarkError (e.g. a version 1 file): message, exit 2
    report = benchmark_report(bench)
    if args.json:
        print(json.dumps(report, indent=2, allow_nan=False))
    else:
        print(format_summary(bench, report, path=path))
    if args.plot is not None:
        plot_summary(bench, args.plot, report)
        print(f"wrote {args.plot}")
    return 0
