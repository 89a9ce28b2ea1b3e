"""``dg16m benchmark build`` and ``dg16m benchmark info``: the simulation benchmark on the
command line. The logic lives in :mod:`dg16m_env.benchmark`; heavy imports (MuJoCo) happen inside
the handlers so that ``dg16m --help`` stays fast, and ``split-real`` and ``build-real``, whose
numbers live in :mod:`dg16m_env.benchmark.real`, add their arguments when they are used."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from dg16m_core import arguments
from dg16m_core.cli import add_command
from dg16m_core.parameters import PROTOCOL
from dg16m_env.cli.evaluate import benchmark_argument
from dg16m_env.physics.reseat import DEFAULT_RESEAT_MAX, RESEAT_STEP
from dg16m_env.physics.simulator import add_simulator_arguments, simulator_from_args

BENCHMARK_EXAMPLES = (
    "  dg16m benchmark build --out runs/bench10 --limit 10\n"
    "  dg16m benchmark build --meshes my_meshes/ --out runs/mine\n"
    "  dg16m benchmark info runs/bench10/benchmark.h5\n"
)

BUILD_EXAMPLES = (
    "  # the 300-object procedural benchmark on 2 local processes (about 36 minutes on 2 cores)\n"
    "  dg16m benchmark build --out runs/benchmark --workers 2\n"
    "  # a quick look: the first 10 objects\n"
    "  dg16m benchmark build --out runs/bench10 --limit 10\n"
    "  # your own meshes, made ready by 'dg16m objects repair' (watertight, in metres): built\n"
    "  # with the real-object settings, every mesh admitted or rejected with its reason\n"
    "  dg16m objects repair raw_meshes/ --units cm --out my_meshes\n"
    "  dg16m benchmark build --meshes my_meshes/ --out runs/mine --workers 2\n"
    "  # a folder written by 'dg16m objects import-sweethome3d' is read the same way\n"
    "  dg16m benchmark build --meshes runs/real_meshes --out runs/real_some --split chair_1,bed_3\n"
    "  # the shipped test meshes as before 2026-12-05: no screen, no budgets, no robust pairs\n"
    "  dg16m benchmark build --meshes tests/data/meshes --mesh-settings plain --out runs/plain\n"
    "  # a folder written by 'dg16m generate' (grasps/<id>.h5; --meshes where it has no meshes/)\n"
    "  dg16m benchmark build --grasps runs/dataset --meshes my_meshes/ --out runs/mine_dg16m\n"
    "  # release DG16M files (Robotiq 2F-85 poses), objects listed in split.txt, hands that\n"
    "  # start inside the object moved back up to 30 mm along their approach axis\n"
    "  dg16m benchmark build --meshes meshes/ --grasps grasps/ --split split.txt --reseat \\\n"
    "      --out runs/release\n"
    "  # rerun the same command to resume: finished objects are skipped\n"
    "  # on a GPU with MuJoCo Warp (pip install 'dg16m[warp]'): one object's trials at once\n"
    "  dg16m benchmark build --out runs/benchmark_gpu --simulator warp --device cuda:0\n"
)

INFO_EXAMPLES = (
    "  dg16m benchmark info                      # the benchmark shipped with dg16m\n"
    "  dg16m benchmark info runs/benchmark/benchmark.h5 --plot runs/benchmark/summary.png\n"
)


def register(subparsers: Any) -> None:
    """Add ``dg16m benchmark {build,info,split-real,build-real}``."""
    bench = add_command(
        subparsers,
        "benchmark",
        "Build or summarise the MuJoCo dual-grasp benchmark (sim-labelled dual grasps).",
        BENCHMARK_EXAMPLES,
        description="Dual grasps on fixed objects, each labelled by a MuJoCo trial (see "
        "'dg16m benchmark build --help').",
    )
    sub = bench.add_subparsers(dest="benchmark_command", metavar="ACTION", required=True)
    _register_build(sub)
    _register_info(sub)
    _register_real(sub)


def _register_build(sub: Any) -> None:
    """Add ``dg16m benchmark build``."""
    build = add_command(
        sub,
        "build",
        "Sample, pair, check force closure and simulate: one benchmark file.",
        BUILD_EXAMPLES,
        description=(
            "For each object (the procedural benchmark, or each mesh file of --meshes): sample "
            "single-arm grasps, pair them, check force closure, draw the four arms "
            "(force-closure passing, failing, random and farthest pairs; about 100), and label "
            "each pair by its success probability p over K + 1 MuJoCo trials (the nominal hand "
            "poses and K = 8 perturbed ones, each hand moved 1 mm and turned 1 degree; a trial: "
            "close, gravity, 12 disturbances; held when the object stays within 2 cm and 10 "
            "degrees of the hands). Meshes are simulated through their CoACD convex parts "
            "(cached in $DG16M_CACHE_DIR/coacd). With --grasps, the DG16M files' stored passing "
            "and failing pairs are simulated instead of sampled ones, their poses moved from "
            "the files' gripper to the Panda hand. --reseat moves each such hand whose open "
            "palm or fingers start inside the object (deeper than "
            f"{1000 * PROTOCOL.invalid_penetration:g} mm, the rule that makes a trial invalid) "
            f"back along its approach axis in {1000 * RESEAT_STEP:g} mm steps until it clears "
            "(at most MM mm; a hand that cannot clear stays and its trial counts as a failure): "
            "this "
            "changes the grasps, and how many hands moved and how far is always reported "
            "(manifest, benchmark info). Writes OUT/objects/<id>.h5, OUT/manifest.json and "
            "OUT/benchmark.h5 (schema version 2). Results do not depend on --workers or "
            "--backend; reruns resume. Mesh files without --grasps are built with the real-object "
            "settings (--mesh-settings real, the default): a screen of 40 force-closure pairs "
            "before the decomposition, CPU budgets per stage (--stage-budget; the same verdict "
            "at any machine load), each rejected mesh, or mesh whose CoACD or MuJoCo crashed, "
            "listed with its stage and the reason in words; a resume keeps those verdicts "
            "(--retry-rejected redoes them). "
            "Ctrl-C or SIGTERM stops the build and every process it started within seconds; "
            "finished objects stay done."
        ),
    )
    _build_arguments(build)
    build.set_defaults(handler=_build)


def _build_arguments(build: argparse.ArgumentParser) -> None:
    """The options of ``dg16m benchmark build``."""
    arguments.add_out_argument(build, "output folder")
    arguments.add_limit_argument(build, "only the first N objects (of the split)")
    build.add_argument(
        "--meshes",
        type=Path,
        help="folder of mesh files, one object each (id = file stem); alone: pairs are sampled",
    )
    build.add_argument(
        "--grasps",
        type=Path,
        help="folder of DG16M files <id>.h5, or a folder written by 'dg16m generate' (its "
        "grasps/ is used, and its meshes/ when --meshes is not given)",
    )
    build.add_argument(
        "--split",
        default=None,
        help="object ids: a file (one per line) or id1,id2,...; file stems or file names "
        "(couch, couch.obj, couch.h5)",
    )
    build.add_argument(
        "--scale",
        type=float,
        default=None,
        help="factor applied to --meshes coordinates without --grasps (default: the files are "
        "in metres; 0.001 for millimetres); a DG16M file records its own",
    )
    build.add_argument(
        "--allow-any-size",
        action="store_true",
        help="accept --meshes objects whose longest side is outside 0.05-5 m",
    )
    build.add_argument(
        "--reseat",
        type=float,
        nargs="?",
        const=1000 * DEFAULT_RESEAT_MAX,
        default=None,
        metavar="MM",
        help="with --grasps: move open hands that start inside the object back along their "
        f"approach axis, at most MM mm (default {1000 * DEFAULT_RESEAT_MAX:g}); changes the "
        "grasps, every shift is stored and reported",
    )
    build.add_argument(
        "--grasp-gripper",
        default=None,
        help="gripper frame of the files' poses (default: the file's own, else robotiq_2f85 "
        "as in the DG16M release)",
    )
    arguments.add_parallel_arguments(build, "local processes (default 1)")
    arguments.add_seed_argument(build, "global seed (default 0)")
    build.add_argument(
        "--perturbations",
        type=int,
        default=None,
        metavar="K",
        help="perturbed trials per pair besides the nominal one (default: 8, the shipped "
        "benchmark's; fewer is faster and coarser, 0 labels by the nominal trial alone)",
    )
    build.add_argument(
        "--robust",
        type=int,
        default=None,
        metavar="N",
        help="also draw N robust pairs per object (arm fc_robust, beyond the paper: force-closure "
        "passing and a disturbance motion ratio <= 1 against every protocol load, see "
        "dataset_gen.grasps.robust; default 20 for --meshes with the real settings, else 0: the "
        "paper's four arms only)",
    )
    build.add_argument(
        "--mesh-settings",
        choices=("real", "plain"),
        default=None,
        help="--meshes without --grasps: 'real' (default) builds them as the real benchmark's "
        "furniture: a screen that rejects objects giving fewer than 40 force-closure pairs "
        "before their decomposition, the real CoACD settings, budgets of CPU time per stage "
        "(--stage-budget), each rejection with its stage and "
        "reason; 'plain': the procedural objects' settings, no screen and no budgets",
    )
    _add_stage_budget_argument(build)
    build.add_argument(
        "--retry-rejected",
        action="store_true",
        help="on resume, build again the objects the folder already rejected (by default a "
        "rejection stays while the object's files and the build's settings are unchanged; one "
        "stopped by the wall-time safety net is always retried)",
    )
    add_simulator_arguments(build)
    arguments.add_progress_argument(build)


def _add_stage_budget_argument(build: argparse.ArgumentParser) -> None:
    """``--stage-budget STAGE=SECONDS`` (repeatable) of ``build`` and ``build-real``."""
    build.add_argument(
        "--stage-budget",
        action="append",
        default=[],
        metavar="STAGE=SECONDS",
        help="CPU seconds one object may spend in a stage: decompose (CoACD), sample (the "
        "screen and the sampling) or label (the trials); repeatable (e.g. --stage-budget "
        "decompose=600). Defaults with the real settings: decompose 180, sample 120, label 240; "
        "without, none. A stage also stops at 10 times its budget in wall time, a safety net "
        "for a stage that hangs. Recorded in the manifest: a resume needs the same budgets",
    )


def _register_info(sub: Any) -> None:
    """Add ``dg16m benchmark info``."""
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
        "invalid trials (with their reasons per object), the hands' penetration, re-seated "
        "hands (how many moved, median and max shift), per arm the distance from the centre "
        "of mass to the line through the hands' grasp centres (median, GSR per distance bin; "
        "'not stored' for files built before it) and the share of pairs with a hand without "
        "contact after close, and GSR per object family. Only schema version 2 files "
        "(rebuild older ones with 'dg16m benchmark build').",
    )
    info.add_argument(
        "file",
        type=benchmark_argument,
        nargs="?",
        default=None,
        help="benchmark.h5, or a shipped benchmark by name: 'procedural' (the default) or 'real'",
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
        help="also write a 2 x 3 summary figure (GSR per arm, p, failure phases, penetration, "
        "GSR by hand-line distance, hands without contact after close)",
    )
    info.set_defaults(handler=_info)


REAL_EXAMPLES = (
    "  apt-get install -y sweethome3d-furniture\n"
    "  dg16m objects import-sweethome3d --out runs/real_meshes --workers 2\n"
    "  # a pilot: 14 objects, 2 per category\n"
    "  dg16m benchmark build-real --meshes runs/real_meshes --out runs/real_pilot --limit 14\n"
    "  # the whole benchmark (resumable: rerun to continue)\n"
    "  dg16m benchmark build-real --meshes runs/real_meshes --out runs/real --workers 2\n"
)


def _register_real(sub: Any) -> None:
    """Add ``dg16m benchmark {split-real,build-real}`` (their arguments on use)."""
    add_command(
        sub,
        "split-real",
        "Make the real benchmark's split from an import folder (stratified by category).",
        "  dg16m benchmark split-real --meshes runs/real_meshes --out real_split.json\n"
        "  # bring a split up to date with a revised import, keeping its orders\n"
        "  dg16m benchmark split-real --meshes runs/real_meshes --revise real_split.json \\\n"
        "      --note 'filter v2: lamps kept' --out real_split.json\n",
        description=_split_real_description,
        arguments=_split_real_arguments,
    )
    add_command(
        sub,
        "build-real",
        "Build the real-object benchmark from imported furniture, replacing objects that fail.",
        REAL_EXAMPLES,
        description=_build_real_description,
        arguments=_build_real_arguments,
    )


def _split_real_description() -> str:
    from dg16m_env.benchmark.real import REAL_SIZE  # the builder, MuJoCo: on use only

    return (
        f"Order each category's imported objects by a seeded permutation and give each "
        f"category its share of the {REAL_SIZE} benchmark objects; the rest is the training "
        "split. Records every object's OBJ sha256 (the build refuses a changed mesh). With "
        "--revise, an existing split is updated instead: ids the import no longer has are "
        "rejected at stage 'import', new ones are appended to their category's order "
        "(seeded), quotas are shared again, and the revision is recorded."
    )


def _split_real_arguments(split: argparse.ArgumentParser) -> None:
    from dg16m_env.benchmark.real import REAL_SIZE

    split.add_argument("--meshes", type=Path, required=True, help="an import-sweethome3d folder")
    arguments.add_out_argument(split, "the split file to write (JSON)")
    split.add_argument("--size", type=int, default=REAL_SIZE, help=f"default: {REAL_SIZE}")
    arguments.add_seed_argument(split, "default: 0")
    split.add_argument("--revise", type=Path, help="a split to bring up to date (keeps its orders)")
    split.add_argument("--note", default="", help="--revise: why (recorded in the split)")
    split.set_defaults(handler=_split_real)


def _build_real_description() -> str:
    from dg16m_env.benchmark.real import REAL_LIMITS  # the builder, MuJoCo: on use only

    return (
        "Build the benchmark split (the shipped dg16m_env/data/real_split.json, or --split) "
        "of an import folder with the paper's four arms, 20 fc_robust pairs and K = 8. An "
        f"object with fewer than {REAL_LIMITS.min_passing} force-closure-passing pairs "
        "(screened before its decomposition, checked again before its trials), or whose "
        f"decomposition ({REAL_LIMITS.decompose_s:g} s), sampling ({REAL_LIMITS.sample_s:g} "
        f"s) or trials ({REAL_LIMITS.label_s:g} s) run past their budgets, is rejected with "
        "its stage and replaced by the next object of its category. Resumable. Writes "
        "OUT/benchmark.h5 (carrying every mesh and its convex parts) and OUT/real_split.json "
        "(the split the build ended with)."
    )


def _build_real_arguments(build: argparse.ArgumentParser) -> None:
    build.add_argument("--meshes", type=Path, required=True, help="an import-sweethome3d folder")
    arguments.add_out_argument(build, "build folder")
    build.add_argument("--split", type=Path, default=None, help="split file (default: shipped)")
    arguments.add_limit_argument(build, "a pilot of N objects")
    arguments.add_parallel_arguments(build, "processes (default: 1)", ray=False)
    arguments.add_progress_argument(build)
    _add_stage_budget_argument(build)
    add_simulator_arguments(build)
    build.set_defaults(handler=_build_real)


def _split_real(args: argparse.Namespace) -> int:
    from dg16m_env.benchmark.model import BenchmarkError
    from dg16m_env.benchmark.real import (
        import_entries,
        make_split,
        read_split,
        revise_split,
        write_split,
    )

    entries = import_entries(args.meshes)
    if args.revise is not None:
        if not args.note:
            raise BenchmarkError("--revise: expected --note saying why, found none")
        split = revise_split(read_split(args.revise), entries, note=args.note)
        last = split["revisions"][-1]
        print(
            f"revision {last['revision']}: {len(last['added'])} added, {len(last['removed'])} "
            f"rejected at stage 'import', {len(last['changed_sha256'])} with new bytes"
        )
    else:
        split = make_split(entries, size=args.size, seed=args.seed)
    write_split(args.out, split)
    quotas = ", ".join(f"{c} {v['quota']}" for c, v in split["categories"].items())
    print(
        f"wrote {args.out}: {len(split['benchmark'])} benchmark and {len(split['train'])} "
        f"training objects ({quotas})"
    )
    return 0


def _build_real(args: argparse.Namespace) -> int:
    from dg16m_env.benchmark.file import read_benchmark
    from dg16m_env.benchmark.real import REAL_LIMITS, build_real_benchmark, read_split
    from dg16m_env.benchmark.report_text import format_summary

    split = read_split(args.split) if args.split is not None else None
    path, final = build_real_benchmark(
        args.meshes,
        args.out,
        split=split,
        limits=REAL_LIMITS.with_stage_budgets(args.stage_budget),
        limit=args.limit,
        workers=args.workers,
        progress=not args.no_progress,
        simulator=simulator_from_args(args),
    )
    print(format_summary(read_benchmark(path), path=path))
    for object_id, why in sorted(final["rejected"].items()):
        print(f"rejected {object_id} ({why['reason']}, stage {why['stage']}): {why['error']}")
    print(f"wrote {path} and {args.out / 'real_split.json'}")
    return 0


def _sources(args: argparse.Namespace) -> list[Any]:
    """The objects of ``dg16m benchmark build``: procedural, a mesh folder, or DG16M files."""
    import math

    from dg16m_env.benchmark.model import BenchmarkError
    from dg16m_env.benchmark.sources import (
        file_benchmark_sources,
        mesh_benchmark_sources,
        procedural_benchmark_sources,
        read_split,
    )

    if args.limit is not None and args.limit < 1:
        raise BenchmarkError(f"--limit: expected an integer >= 1, found {args.limit}")
    if args.meshes is None and args.grasps is None:
        if args.split or args.grasp_gripper or args.scale is not None or args.allow_any_size:
            raise BenchmarkError(
                "--split/--grasp-gripper/--scale/--allow-any-size: expected only with --meshes "
                "or --grasps, found them without"
            )
        if args.reseat is not None:
            raise BenchmarkError("--reseat: expected only with --grasps (DG16M files)")
        return procedural_benchmark_sources(args.limit)
    reseat_max = 0.0
    if args.reseat is not None:
        if args.grasps is None:
            raise BenchmarkError(
                "--reseat: expected only with --grasps (DG16M files made for another gripper), "
                "found --meshes alone (sampled pairs are already clear of the object)"
            )
        if not (math.isfinite(args.reseat) and args.reseat > 0):
            raise BenchmarkError(f"--reseat: expected a positive number of mm, found {args.reseat}")
        reseat_max = args.reseat / 1000.0
    split = read_split(args.split) if args.split else None
    if args.grasps is not None:
        if args.scale is not None or args.allow_any_size:
            raise BenchmarkError(
                "--scale/--allow-any-size: expected only without --grasps (a DG16M file records "
                "its mesh's scale), found them with --grasps"
            )
        items = file_benchmark_sources(
            args.meshes,
            args.grasps,
            split,
            grasp_gripper=args.grasp_gripper,
            reseat_max=reseat_max,
        )
    else:
        if args.grasp_gripper:
            raise BenchmarkError("--grasp-gripper: expected only with --grasps")
        items = mesh_benchmark_sources(
            args.meshes, split, scale=args.scale, allow_any_size=args.allow_any_size
        )
    return items if args.limit is None else items[: args.limit]


def _build(args: argparse.Namespace) -> int:
    from dataset_gen.io import failed_entries, failure_lines, read_manifest
    from dg16m_core.budget import WALL_FACTOR
    from dg16m_env.benchmark.build import (
        BuildLimits,
        NothingBuiltError,
        build_benchmark,
        build_parameters,
    )
    from dg16m_env.benchmark.file import read_benchmark
    from dg16m_env.benchmark.model import BenchmarkError, BenchmarkParameters
    from dg16m_env.benchmark.report_text import format_summary
    from dg16m_env.benchmark.verdicts import kept_rejections
    from dg16m_env.physics.labels import LabelError, PerturbationSpec
    from dg16m_env.physics.simulator import check_simulator

    try:
        perturbation = (
            PerturbationSpec()
            if args.perturbations is None
            else PerturbationSpec(n_perturbations=args.perturbations)
        )
    except LabelError as exc:
        raise BenchmarkError(f"--perturbations: {exc}") from None
    if args.robust is not None and args.robust < 0:
        raise BenchmarkError(f"--robust: expected an integer >= 0, found {args.robust}")
    real_settings = args.meshes is not None and args.grasps is None
    if args.mesh_settings is not None and not real_settings:
        raise BenchmarkError(
            "--mesh-settings: expected only with --meshes and without --grasps (sampled "
            "pairs on mesh files), found it without"
        )
    real_settings &= args.mesh_settings in (None, "real")
    simulator = simulator_from_args(args)
    items = _sources(args)
    if args.meshes is not None and args.grasps is None:  # read z up: say so, and which may not
        from dataset_gen.real.orientation import build_up_note

        print(build_up_note(args.meshes))
    limits = None
    if real_settings:
        from dataclasses import replace

        from dg16m_env.benchmark.real import MESH_LIMITS, REAL_PARAMETERS

        params = replace(
            REAL_PARAMETERS,
            seed=args.seed,
            perturbation=perturbation,
            n_robust=REAL_PARAMETERS.n_robust if args.robust is None else args.robust,
        )
        limits = MESH_LIMITS.with_stage_budgets(args.stage_budget)
        print(
            f"{len(items)} meshes with the real-object settings (--mesh-settings real): each "
            f"needs {limits.min_passing} force-closure pairs; CPU budgets decomposition "
            f"{limits.decompose_s:g} s, sampling {limits.sample_s:g} s, trials "
            f"{limits.label_s:g} s (--stage-budget STAGE=SECONDS), the same at any machine "
            f"load; a stage that hangs stops at {WALL_FACTOR:g} times its budget in wall time"
        )
    else:
        params = BenchmarkParameters(
            seed=args.seed, perturbation=perturbation, n_robust=args.robust or 0
        )
        if args.stage_budget:
            limits = BuildLimits().with_stage_budgets(args.stage_budget)
    if not args.retry_rejected:
        parameters = build_parameters(items, params, check_simulator(simulator), limits)
        kept = kept_rejections(Path(args.out), items, parameters)
        if kept:
            print(
                f"kept the verdict of {len(kept)} objects from the earlier run (files and "
                f"settings unchanged: {', '.join(sorted(kept))}); --retry-rejected to redo them"
            )
    try:
        path = build_benchmark(
            items,
            args.out,
            params,
            **arguments.parallel_options(args),
            progress=not args.no_progress,
            simulator=simulator,
            limits=limits,
            retry_rejected=args.retry_rejected,
        )
    except NothingBuiltError as exc:
        if len(exc.failed) != len(items):
            raise
        # every object ran and failed (e.g. meshes in millimetres): failures it lists, exit 1
        print(f"{args.out}: 0 objects ok, {len(exc.failed)} failed; no benchmark written")
        print("\n".join(failure_lines(exc.failed)))
        return 1
    print(format_summary(read_benchmark(path), path=path))
    print(f"wrote {path}")
    failed = failed_entries(read_manifest(args.out), [item.object_id for item in items])
    if failed:
        print(f"{len(failed)} objects failed and are left out of the benchmark:")
        print("\n".join(failure_lines(failed)))
    return 1 if failed else 0


def _info(args: argparse.Namespace) -> int:
    from dg16m_env.benchmark.file import read_benchmark
    from dg16m_env.benchmark.model import BenchmarkError
    from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
    from dg16m_env.benchmark.report import benchmark_report
    from dg16m_env.benchmark.report_plot import plot_summary
    from dg16m_env.benchmark.report_text import format_summary

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
