"""``dg16m generate`` and ``dg16m stats``: make a DG16M-style dataset and summarise it.

The logic lives in :mod:`dataset_gen.generate` and :mod:`dataset_gen.stats`; heavy imports
happen inside the handlers so that ``dg16m --help`` stays fast.
"""

from __future__ import annotations

import argparse
from pathlib import Path

GENERATE_EXAMPLES = (
    "  # 20 procedural training objects on 2 local processes\n"
    "  dg16m generate --procedural 20 --out runs/dataset --workers 2\n"
    "  # your own meshes (files in millimetres), physical force closure\n"
    "  dg16m generate --meshes path/to/meshes --scale 0.001 --out runs/mine\n"
    "  # the same task on a Ray cluster (or a local Ray on loopback without --address)\n"
    "  dg16m generate --procedural 4000 --out runs/dg16m --backend ray --address auto\n"
    "  # rerun the same command to resume an interrupted run: finished objects are skipped\n"
)

STATS_EXAMPLES = "  dg16m stats runs/dataset --out runs/dataset_stats\n"


def register(subparsers) -> None:
    """Add ``dg16m generate`` and ``dg16m stats``."""
    gen = subparsers.add_parser(
        "generate",
        help="Generate dual-arm grasps (one release-schema HDF5 per object) from meshes or "
        "procedural objects.",
        description=(
            "Sample antipodal single-arm grasps, pair them (all unique pairs, 0.1 m centre "
            "pruning, gripper-gripper collision), check force closure on every candidate and keep "
            "up to 2000 passing and 2000 failing pairs per object. Writes OUT/grasps/<id>.h5 and "
            "OUT/manifest.json. Results do not depend on --workers or --backend; reruns skip "
            "finished objects; a broken mesh fails only its own object (recorded in the manifest)."
        ),
        epilog="examples:\n" + GENERATE_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
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
    gen.add_argument("--scale", type=float, default=None, help="scale for --meshes files")
    gen.add_argument("--out", type=Path, required=True, help="dataset folder")
    gen.add_argument("--workers", type=int, default=1, help="local processes (default 1)")
    gen.add_argument("--backend", choices=("local", "ray"), default="local")
    gen.add_argument("--address", default=None, help="Ray address: auto or host:port")
    gen.add_argument("--seed", type=int, default=0, help="global seed (default 0)")
    gen.add_argument("--grasps", type=int, default=500, help="single-arm grasps per object")
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
    gen.add_argument("--max-passing", type=int, default=2000)
    gen.add_argument("--max-failing", type=int, default=2000)
    gen.add_argument("--no-progress", action="store_true", help="no progress bar")
    gen.set_defaults(handler=_generate)

    stats = subparsers.add_parser(
        "stats",
        help="Counts and plots of a generated dataset (Q(G) histogram, passes per object, losses).",
        description=(
            "Print per-dataset counts and write quality_hist.png (the paper's Fig. 4: Q(G) of "
            "passing vs failing pairs), passes_per_object.png, loss_hist.png and stats.json."
        ),
        epilog="examples:\n" + STATS_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    stats.add_argument("folder", type=Path, metavar="DIR", help="a folder made by dg16m generate")
    stats.add_argument("--out", type=Path, required=True, help="folder for the plots")
    stats.set_defaults(handler=_stats)


def _generate(args: argparse.Namespace) -> int:
    from .generate import GenerationParameters, generate_dataset
    from .procedural import benchmark_specs, object_specs
    from .sources import mesh_sources, procedural_sources

    params = GenerationParameters(
        seed=args.seed,
        gripper=args.gripper,
        n_grasps=args.grasps,
        convention=args.convention,
        check_gripper_collision=not args.no_gripper_collision,
        max_passing=args.max_passing,
        max_failing=args.max_failing,
    )
    if args.meshes is not None:
        sources = mesh_sources(args.meshes, scale=args.scale)
    else:
        if args.procedural < 1:
            from .generate import GenerationError

            raise GenerationError(f"--procedural: expected N >= 1, found {args.procedural}")
        if args.split == "benchmark":
            specs = benchmark_specs()[: args.procedural]
        else:
            specs = object_specs(args.procedural, seed=args.seed, split="train")
        sources = procedural_sources(specs)
    manifest = generate_dataset(
        sources,
        args.out,
        params,
        workers=args.workers,
        backend=args.backend,
        address=args.address,
        progress=not args.no_progress,
    )
    entries = manifest["entries"]
    ok = [e for e in entries.values() if e["status"] == "ok"]
    failed = {k: e for k, e in entries.items() if e["status"] == "failed"}
    print(
        f"{args.out}: {len(ok)} objects ok, {len(failed)} failed; "
        f"{sum(e['passing'] for e in ok)} passing and {sum(e['failing'] for e in ok)} failing pairs"
    )
    for object_id, entry in failed.items():
        print(f"  failed {object_id}: {entry['error']}")
    return 0


def _stats(args: argparse.Namespace) -> int:
    from .atomic import write_json_atomic
    from .stats import collect_stats, plot_stats

    stats = collect_stats(args.folder)
    summary = stats.summary()
    for key, value in summary.items():
        print(f"  {key:26s} {value}")
    for path in plot_stats(stats, args.out):
        print(f"  wrote {path}")
    write_json_atomic(args.out / "stats.json", summary)
    print(f"  wrote {args.out / 'stats.json'}")
    return 0
