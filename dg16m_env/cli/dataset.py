"""``dg16m dataset``: build a training dataset at DG16M's scale, and print its card.

``dg16m dataset build`` imports the open shape sources, generates every object's dual grasps
(:mod:`dataset_gen.collection`), checks by hash that no object is one of the shipped
benchmarks' (:mod:`dg16m_env.benchmark.exclusion`) and writes the card; ``dg16m dataset info``
prints a dataset's card. The command lives in ``dg16m_env`` because the benchmarks it keeps
apart are here.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from dg16m_core import arguments
from dg16m_core.cli import add_command
from dg16m_core.errors import Dg16mError

BUILD_EXAMPLES = (
    "  # DG16M's scale: 4,143 objects (Sweet Home 3D furniture not in a benchmark, the rest\n"
    "  # procedural), about 15 million dual grasps, on 2 cores\n"
    "  dg16m dataset build --out runs/dg16m --workers 2\n"
    "  # a small one to look at first (procedural objects only)\n"
    "  dg16m dataset build --out runs/small --objects 40 --sources procedural --workers 2\n"
    "  # with pybullet's random_urdfs too (pip install pybullet), on a Ray cluster\n"
    "  dg16m dataset build --out runs/dg16m --sources procedural,sweethome3d,pybullet \\\n"
    "      --backend ray --address auto\n"
    "  # after Ctrl-C: the same command goes on where it stopped\n"
)

INFO_EXAMPLES = "  dg16m dataset info runs/dg16m\n  dg16m dataset info runs/dg16m --json\n"


class DatasetCommandError(Dg16mError, ValueError):
    """Bad ``dg16m dataset`` arguments."""


def register(subparsers: Any) -> None:
    """Add ``dg16m dataset`` (``build``, ``info``)."""
    dataset = add_command(
        subparsers,
        "dataset",
        "A training dataset at DG16M's scale: build it (resumable), print its card.",
        BUILD_EXAMPLES + INFO_EXAMPLES,
        description=(
            "Build a dual-grasp dataset from every open shape source the project can install "
            "(procedural families, Sweet Home 3D furniture that is not in the real benchmark, "
            "optionally pybullet's random_urdfs), with object-level train/validation splits "
            "checked by geometry hash against both shipped benchmarks, a dataset card and "
            "Croissant metadata."
        ),
    )
    actions = dataset.add_subparsers(dest="action", metavar="ACTION", required=True)
    build = add_command(
        actions,
        "build",
        "Build (or resume) a dataset folder: sources, grasps, split check, card.",
        BUILD_EXAMPLES,
        description=(
            "Import the sources, generate every object's dual grasps (the release's parameters: "
            "500 single-arm grasps, up to 2,000 passing and 2,000 failing pairs per object; open "
            "hands checked against the exact mesh), check that no object is a benchmark object "
            "(by id, geometry sha256 and source-file sha256) and that no geometry is in both "
            "splits, and write croissant.json and card/. Each object is written atomically and "
            "recorded in manifest.json, so the same command after Ctrl-C, SIGTERM or a kill "
            "does only the rest; local workers and Ray give the same bytes. Exit status 1 when "
            "fewer than --objects objects could be built."
        ),
    )
    _build_arguments(build)
    build.set_defaults(handler=_build)
    info = add_command(
        actions,
        "info",
        "Print a dataset's card (counts per source and split, licences, parameters).",
        INFO_EXAMPLES,
    )
    info.add_argument("folder", type=Path, help="a folder written by 'dg16m dataset build'")
    info.add_argument("--json", action="store_true", help="print card/summary.json")
    info.set_defaults(handler=_info)


def _sources(text: str) -> tuple[str, ...]:
    names = tuple(arguments.listed_ids(text))
    if not names:
        raise argparse.ArgumentTypeError(
            f"expected names like procedural,sweethome3d, found {text!r}"
        )
    return names


def _model_ids(text: str) -> list[str]:
    ids = arguments.listed_ids(text)
    if not ids:
        raise argparse.ArgumentTypeError(f"expected model ids like a,b,c, found {text!r}")
    return ids


def _build_arguments(build: argparse.ArgumentParser) -> None:
    arguments.add_out_argument(build, "the dataset folder (a rerun resumes it)")
    build.add_argument(
        "--objects",
        type=int,
        default=4143,
        help="objects to build, at least (default: 4143, the DG16M release's)",
    )
    build.add_argument(
        "--sources",
        type=_sources,
        default=("procedural", "sweethome3d"),
        help="comma-separated among procedural, sweethome3d, pybullet (default: "
        "procedural,sweethome3d; procedural objects make up the count)",
    )
    build.add_argument(
        "--validation-fraction",
        type=float,
        default=0.05,
        help="share of objects in the validation split (default: 0.05)",
    )
    build.add_argument("--split-seed", type=int, default=0, help="seed of the split (default: 0)")
    build.add_argument(
        "--procedural-seed",
        type=int,
        default=0,
        help="first train seed of each procedural family (default: 0)",
    )
    build.add_argument(
        "--import-seed",
        type=int,
        default=0,
        help="seed of the sizes drawn for imported models (default: 0)",
    )
    build.add_argument(
        "--sweethome3d-ids",
        type=_model_ids,
        default=None,
        help="only these Sweet Home 3D models, comma-separated (default: every usable one "
        "that is not in a benchmark; 'dg16m objects import-sweethome3d --list' lists them)",
    )
    build.add_argument(
        "--pybullet-limit",
        type=int,
        default=None,
        help="only the first N of pybullet's 1,000 random_urdfs (default: all)",
    )
    build.add_argument(
        "--retry-failed",
        action="store_true",
        help="try again the imports and objects that failed in an earlier run (by default a "
        "rerun keeps their verdicts: with the same options they fail the same way)",
    )
    arguments.add_parallel_arguments(build, "local processes (default: 1)")
    arguments.add_progress_argument(build)


def _build(args: argparse.Namespace) -> int:
    from dataset_gen.collection.build import EXCLUSION_FILE, build_dataset
    from dataset_gen.collection.recipe import DatasetRecipe
    from dg16m_core.stopping import sigterm_interrupts
    from dg16m_env.benchmark.exclusion import benchmark_exclusion

    recipe = DatasetRecipe(
        objects=args.objects,
        sources=args.sources,
        validation_fraction=args.validation_fraction,
        split_seed=args.split_seed,
        procedural_seed=args.procedural_seed,
        import_seed=args.import_seed,
        sweethome3d_ids=args.sweethome3d_ids,
        pybullet_limit=args.pybullet_limit,
    )
    started = time.perf_counter()
    print("reading the shipped benchmarks' objects (to keep them out) ...")
    with sigterm_interrupts():
        exclusion = benchmark_exclusion(cached=args.out / EXCLUSION_FILE)
        try:
            build = build_dataset(
                args.out,
                recipe,
                exclusion,
                progress=not args.no_progress,
                retry_failed=args.retry_failed,
                **arguments.parallel_options(args),
            )
        except KeyboardInterrupt:
            print(
                f"interrupted: the finished objects are recorded in {args.out}/manifest.json; "
                "the same command goes on from there"
            )
            raise
    print("\n".join(_card_lines(build.summary)))
    print(f"built in {time.perf_counter() - started:.0f} s; the card: {args.out}/card/README.md")
    built = len(build.ok_entries())
    if built < recipe.objects:
        print(f"SHORT: {built} of {recipe.objects} objects have dual grasps (failures in the card)")
        return 1
    return 0


def _card_lines(summary: dict[str, Any]) -> list[str]:
    t = summary["totals"]
    size = sum(summary["bytes"].values())
    lines = [
        f"{t['objects']:,} objects, {t['dual_grasps']:,} dual grasps ({t['passing']:,} passing, "
        f"{t['failing']:,} failing; {100 * summary['passing_share']:.1f}% passing), "
        f"{size / 1e9:.2f} GB; {summary['generator']}",
        f"{'source':<12} {'split':<11} {'objects':>8} {'dual grasps':>12} {'passing':>10}",
    ]
    for source, splits in summary["per_source"].items():
        for split, cell in splits.items():
            lines.append(
                f"{source:<12} {split:<11} {cell['objects']:>8,} {cell['dual_grasps']:>12,} "
                f"{cell['passing']:>10,}"
            )
    check = summary["splits_check"]
    lines.append(
        f"splits: checked {check['objects_checked']:,} objects against "
        f"{check['benchmark_objects']:,} benchmark objects by geometry sha256: "
        f"{check['shared']} shared; {check['splits_shared']} geometries in both splits"
    )
    for source, counts in summary["licences"].items():
        lines.append(f"licences of {source}: " + ", ".join(f"{k} {v:,}" for k, v in counts.items()))
    if summary["failed_objects"]:
        lines.append(f"{summary['failed_objects']} objects failed (reasons in card/summary.json)")
    return lines


def _info(args: argparse.Namespace) -> int:
    from dataset_gen.collection.card import read_summary

    summary = read_summary(args.folder)
    if args.json:
        print(json.dumps(summary, indent=1, sort_keys=True))
    else:
        print("\n".join(_card_lines(summary)))
        print(f"the card: {args.folder}/card/README.md; metadata: {args.folder}/croissant.json")
    return 0
