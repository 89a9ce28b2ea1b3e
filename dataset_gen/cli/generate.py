"""``dg16m generate`` and ``dg16m stats``: make a DG16M-style dataset and summarise it.

The logic lives in :mod:`dataset_gen.pipeline.generate` and :mod:`dataset_gen.pipeline.stats`; heavy imports
happen inside the handlers so that ``dg16m --help`` stays fast.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from dg16m_core import arguments
from dg16m_core.cli import add_command
from dg16m_core.parameters import PAPER, SELECTIONS

GENERATE_EXAMPLES = (
    "  # 20 procedural training objects on 2 local processes\n"
    "  dg16m generate --procedural 20 --out runs/dataset --workers 2\n"
    "  # your own meshes (files in millimetres), physical force closure\n"
    "  dg16m generate --meshes path/to/meshes --scale 0.001 --out runs/mine\n"
    "  # pairs that also withstand the simulation protocol's pushes (beyond the paper)\n"
    "  dg16m generate --meshes tests/data/meshes --out runs/robust --selection robust\n"
    "  # a subset of a mesh folder, e.g. the real benchmark's training objects\n"
    "  dg16m generate --meshes runs/real_meshes --ids real_split.json:train \\\n"
    "      --out runs/real_train\n"
    "  # the same task on a Ray cluster (or a local Ray on loopback without --address)\n"
    "  dg16m generate --procedural 4000 --out runs/dg16m --backend ray --address auto\n"
    "  # rerun the same command to resume an interrupted run: finished objects are skipped\n"
)

GENERATE_DESCRIPTION = (
    "Sample antipodal single-arm grasps, pair them (all unique pairs, "
    f"{PAPER.min_center_distance:g} m centre pruning, gripper-gripper collision), check force "
    f"closure on every candidate and keep up to {PAPER.max_passing} passing and "
    f"{PAPER.max_failing} failing pairs per object (the release's values). Writes "
    "OUT/grasps/<id>.h5 (and OUT/meshes/<id>.obj for procedural objects) and OUT/manifest.json. "
    "Mesh files are decomposed into convex parts (CoACD, cached) and a grasp is kept only if its "
    "open hand is also clear of those parts by the simulator's rule (dataset_gen.grasps.clearance), so "
    "it is valid in simulation. "
    "Results do not depend on --workers or --backend; reruns skip finished objects. An object "
    "that cannot be loaded (a broken mesh, an implausible size) or yields no dual grasp fails "
    "only itself: it is recorded as failed in the manifest with its reason and retried by a "
    "rerun. Exit status: 0 when every object is ok, 1 when any object failed (each is listed), "
    "2 for unusable input."
)

STATS_EXAMPLES = "  dg16m stats runs/dataset --out runs/dataset_stats\n"


def register(subparsers: Any) -> None:
    """Add ``dg16m generate`` and ``dg16m stats``."""
    _register_generate(subparsers)
    stats = add_command(
        subparsers,
        "stats",
        "Counts and plots of a generated dataset (Q(G) histogram, passes per object, losses).",
        STATS_EXAMPLES,
        description=(
            "Print per-dataset counts and write quality_hist.png (the paper's Fig. 4: Q(G) of "
            "passing vs failing pairs), passes_per_object.png, loss_hist.png and stats.json."
        ),
    )
    stats.add_argument("folder", type=Path, metavar="DIR", help="a folder made by dg16m generate")
    arguments.add_out_argument(stats, "folder for the plots")
    stats.set_defaults(handler=_stats)


def _register_generate(subparsers: Any) -> None:
    gen = add_command(
        subparsers,
        "generate",
        "Generate dual-arm grasps (one release-schema HDF5 per object) from meshes or "
        "procedural objects.",
        GENERATE_EXAMPLES,
        description=GENERATE_DESCRIPTION,
    )
    source = gen.add_mutually_exclusive_group(required=True)
    source.add_argument("--meshes", type=Path, help="folder of mesh files (one object each)")
    source.add_argument(
        "--procedural", type=int, metavar="N", help="N objects of the embedded procedural library"
    )
    gen.add_argument(
        "--split",
        choices=("train", "benchmark"),
        default="train",
        help="procedural split (benchmark: the fixed 300 objects; N then takes the first N)",
    )
    gen.add_argument(
        "--ids",
        default=None,
        metavar="FILE|a,b,c",
        help="with --meshes: only these objects (file stems), from a file of ids (one per line) "
        "or a comma-separated list",
    )
    gen.add_argument("--scale", type=float, default=None, help="scale for --meshes files")
    gen.add_argument(
        "--allow-any-size",
        action="store_true",
        help="accept --meshes objects whose longest side is outside 0.05-5 m",
    )
    arguments.add_out_argument(gen, "dataset folder")
    arguments.add_parallel_arguments(gen)
    arguments.add_seed_argument(gen)
    gen.add_argument(
        "--grasps",
        type=int,
        default=PAPER.n_grasps,
        help=f"single-arm grasps per object (default: {PAPER.n_grasps})",
    )
    gen.add_argument("--gripper", default="panda", help="gripper model (see dg16m grippers)")
    gen.add_argument(
        "--convention",
        choices=("physical", "release"),
        default="physical",
        help="force-closure convention (release: the released code's outward cones)",
    )
    gen.add_argument(
        "--no-gripper-collision",
        action="store_true",
        help="keep pairs whose two grippers intersect (as the release does)",
    )
    gen.add_argument(
        "--max-passing",
        type=int,
        default=PAPER.max_passing,
        help=f"passing pairs kept per object (default: {PAPER.max_passing})",
    )
    gen.add_argument(
        "--max-failing",
        type=int,
        default=PAPER.max_failing,
        help=f"failing pairs kept per object (default: {PAPER.max_failing})",
    )
    gen.add_argument(
        "--selection",
        choices=SELECTIONS,
        default="paper",
        help="passing pairs kept: paper (gravity-only force closure, the default) or robust "
        "(also a disturbance motion ratio <= 1 against every load of the simulation protocol; "
        "see dataset_gen.grasps.robust)",
    )
    arguments.add_progress_argument(gen)
    gen.set_defaults(handler=_generate)


def _generate(args: argparse.Namespace) -> int:
    from dataset_gen.pipeline.generate import GenerationParameters, generate_dataset

    params = GenerationParameters(
        seed=args.seed,
        gripper=args.gripper,
        n_grasps=args.grasps,
        convention=args.convention,
        check_gripper_collision=not args.no_gripper_collision,
        max_passing=args.max_passing,
        max_failing=args.max_failing,
        selection=args.selection,
    )
    manifest = generate_dataset(
        _sources(args),
        args.out,
        params,
        **arguments.parallel_options(args),
        progress=not args.no_progress,
    )
    return _report(args.out, manifest)


def _sources(args: argparse.Namespace) -> list[Any]:
    from dataset_gen.objects.grasp_object import check_mesh_folder
    from dataset_gen.pipeline.generate import GenerationError
    from dataset_gen.sources.object_source import (
        mesh_sources,
        procedural_sources,
        read_ids,
        select_sources,
    )
    from dataset_gen.sources.procedural import benchmark_specs, object_specs

    if args.meshes is not None:
        check_mesh_folder(args.meshes)
        sources = mesh_sources(args.meshes, scale=args.scale, allow_any_size=args.allow_any_size)
        return sources if args.ids is None else select_sources(sources, read_ids(args.ids))
    if args.ids is not None:
        raise GenerationError(
            "--ids: expected --meshes (it selects mesh files), found --procedural"
        )
    if args.procedural < 1:
        raise GenerationError(f"--procedural: expected N >= 1, found {args.procedural}")
    if args.split == "benchmark":
        specs = benchmark_specs()[: args.procedural]
    else:
        specs = object_specs(args.procedural, seed=args.seed, split="train")
    return procedural_sources(specs)


def _report(out: Path, manifest: dict[str, Any]) -> int:
    """Print the run's totals and every failed object; 1 when any object failed, else 0."""
    from dataset_gen.io import failed_entries, failure_lines

    entries = manifest["entries"]
    ok = {k: e for k, e in entries.items() if e["status"] == "ok"}
    failed = failed_entries(manifest)
    print(
        f"{out}: {len(ok)} objects ok, {len(failed)} failed; "
        f"{sum(e['passing'] for e in ok.values())} passing and "
        f"{sum(e['failing'] for e in ok.values())} failing pairs"
    )
    no_pass = sorted(k for k, e in ok.items() if e["passing"] == 0)
    if no_pass:
        print(f"  {len(no_pass)} ok objects have no passing pair: {', '.join(no_pass)}")
    for line in failure_lines(failed):
        print(line)
    return 1 if failed else 0


def _stats(args: argparse.Namespace) -> int:
    from dataset_gen.pipeline.stats import collect_stats, format_summary, plot_stats
    from dg16m_core.atomic import write_json_atomic

    stats = collect_stats(args.folder)
    summary = stats.summary()
    for line in format_summary(summary):
        print(f"  {line}")
    for path in plot_stats(stats, args.out):
        print(f"  wrote {path}")
    write_json_atomic(args.out / "stats.json", summary)
    print(f"  wrote {args.out / 'stats.json'}")
    return 0
