"""``dg16m sim``: run the MuJoCo trial protocol on dual grasps and replay one trial as pictures.

``dg16m sim replay`` renders one trial (a benchmark row, or a pair of a DG16M grasp file) to a PNG
strip or an animated GIF (:mod:`dg16m_env.physics.replay`); ``dg16m sim run`` runs the trials of a DG16M
grasp file's pairs and compares the success rates of its force-closure passing and failing pairs.

Heavy imports (MuJoCo, the benchmark, CoACD, numpy) happen inside the handlers so that ``dg16m
--help`` stays fast; ``replay`` and ``run``, whose ``--coacd-threshold`` help reads the default of
:mod:`dataset_gen.objects.decomposition` (trimesh), add their arguments when they are used.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dg16m_core.arguments import add_limit_argument, add_seed_argument
from dg16m_core.cli import add_command
from dg16m_core.errors import Dg16mError
from dg16m_core.parameters import PAPER
from dg16m_env.physics.simulator import add_simulator_arguments, simulator_from_args

if TYPE_CHECKING:
    import numpy as np


class SimCommandError(Dg16mError, ValueError):
    """Bad ``dg16m sim`` arguments (row or index out of range, missing or conflicting options)."""


SIM_EXAMPLES = (
    "  dg16m sim replay runs/bench/benchmark.h5 --row 12 --out row12.png\n"
    "  dg16m sim run runs/dataset/grasps/table-0000001.h5 --procedural table-0000001 --limit 50\n"
)

REPLAY_EXAMPLES = (
    "  # row 0 of the benchmark shipped with dg16m\n"
    "  dg16m sim replay --row 0 --out row0.png\n"
    "  # a benchmark row (procedural objects need nothing else) as a strip of 8 frames\n"
    "  dg16m sim replay runs/bench/benchmark.h5 --row 12 --out row12.png\n"
    "  # the same trial as an animated GIF of 40 frames, smaller, seen from another side\n"
    "  dg16m sim replay runs/bench/benchmark.h5 --row 12 --out row12.gif --size 320x240 \\\n"
    "      --frames 40 --view 45,-15\n"
    "  # a benchmark built from your meshes: give the mesh folder it was built from\n"
    "  dg16m sim replay runs/mybench/benchmark.h5 --row 3 --meshes my_meshes --out row3.png\n"
    "  # pair 7 of a DG16M grasp file, on a procedural object or on a mesh (CoACD parts, cached)\n"
    "  dg16m sim replay --grasps runs/dataset/grasps/table-0000001.h5 --index 7 \\\n"
    "      --procedural table-0000001 --out pair7.png\n"
    "  dg16m sim replay --grasps ../shared/data/real/dg16m_airplane.h5 --index 0 \\\n"
    "      --mesh ../shared/data/real/dg16m_airplane.obj --out airplane0.png\n"
)

RUN_EXAMPLES = (
    "  dg16m sim run runs/dataset/grasps/table-0000001.h5 --procedural table-0000001\n"
    "  dg16m sim run ../shared/data/real/dg16m_airplane.h5 \\\n"
    "      --mesh ../shared/data/real/dg16m_airplane.obj --limit 50 --json\n"
)


def _object_options(parser: Any, *, required: bool) -> None:
    from dataset_gen.objects.decomposition import DecompositionParameters  # trimesh: on use only

    group = parser.add_mutually_exclusive_group(required=required)
    group.add_argument("--mesh", type=Path, help="the grasp file's object mesh")
    group.add_argument(
        "--procedural", metavar="ID", help="a procedural object id, e.g. table-0000001"
    )
    parser.add_argument(
        "--gripper",
        default=None,
        help="gripper frame of the file's poses: panda or robotiq_2f85 (default: the file's "
        "recorded gripper, else robotiq_2f85 as in the release); poses are moved to the Panda "
        "hand that is simulated",
    )
    parser.add_argument(
        "--mass",
        type=float,
        default=PAPER.mass,
        help=f"object mass in kg (default: {PAPER.mass:g}, the release value)",
    )
    parser.add_argument(
        "--coacd-threshold",
        type=float,
        default=None,
        metavar="T",
        help="CoACD concavity threshold in (0, 1] for --mesh (default: "
        f"{DecompositionParameters().threshold:g}); smaller hugs thin parts (wings, rims) "
        "more tightly, so fewer open hands start inside a hull (slower the first time; cached)",
    )


def register(subparsers: Any) -> None:
    """Add ``dg16m sim`` (``replay``, ``run``)."""
    sim = add_command(
        subparsers,
        "sim",
        "Simulate dual grasps in MuJoCo: replay one trial as pictures, or run a grasp file.",
        SIM_EXAMPLES,
        description="Simulate dual grasps with the trial protocol of dg16m_env.physics.trial (two "
        "floating Panda hands close on the object, then gravity and twelve disturbances; "
        "success when the object stays put relative to the hands).",
    )
    actions = sim.add_subparsers(dest="action", metavar="ACTION", required=True)

    add_command(
        actions,
        "replay",
        "Render one trial (a benchmark row or a pair of a DG16M file) to a PNG strip or a GIF.",
        REPLAY_EXAMPLES,
        description=(
            "Replay one trial step by step and render it offscreen, over the part of the trial "
            "that decides the verdict (all of it when the grasp held, up to the end of the "
            "failing phase when it failed). Its 14 phases (close, gravity, 6 forces, 6 torques) "
            "give the start and the end of each phase as candidate frames: N frames up to that "
            "many (a PNG strip) are candidates chosen evenly among them, at most one frame per "
            "phase, so no two pictures show the same phase; more frames (a GIF) are spread "
            "evenly in time. The end of the close phase, the first step out of bounds and the "
            "end of the failing phase are always added, so a picture may hold a few frames "
            "more than N. Each frame is "
            "captioned with time, phase and slip (the object's displacement at the hands' grasp "
            "centres). The object is drawn translucent; hand 0 is orange, hand 1 blue, contacts "
            "are red. Prints the stored label and the replayed outcome. Rendering needs "
            "MUJOCO_GL=egl (default) or osmesa."
        ),
        arguments=_replay_arguments,
    )
    add_command(
        actions,
        "run",
        "Run the trial protocol on a DG16M file's pairs; success of passing vs failing pairs.",
        RUN_EXAMPLES,
        description="Run the MuJoCo trial on the force-closure passing and failing pairs of a "
        "DG16M grasp file, at each pair's nominal pose and at K perturbed poses (1 mm / 1 degree "
        "per hand, the benchmark's protocol v2), and print a summary of the nominal trials "
        "(invalid ones with their reasons, success, failing phases, penetration) and the mean "
        "success probability of the passing and of the failing pairs, held through every "
        "disturbance and held under gravity. A trial is invalid, and not run, when an open hand "
        "already penetrates the object's convex parts or the two hands overlap; it counts as a "
        "failure.",
        arguments=_run_arguments,
    )


def _replay_arguments(replay: argparse.ArgumentParser) -> None:
    row = replay.add_argument_group("a benchmark row")
    row.add_argument(
        "benchmark",
        nargs="?",
        type=Path,
        metavar="BENCHMARK.h5",
        help="a benchmark file (default: the one shipped with dg16m)",
    )
    row.add_argument("--row", type=int, default=None, metavar="N", help="the row to replay")
    row.add_argument(
        "--trial",
        type=int,
        default=0,
        metavar="T",
        help="which of the row's K + 1 trials: 0 the nominal pose (default), 1..K the perturbed "
        "poses its success probability was measured with (rebuilt from the stored seed)",
    )
    row.add_argument(
        "--meshes",
        type=Path,
        default=None,
        metavar="DIR",
        help="mesh folder of a benchmark built from meshes",
    )
    pair = replay.add_argument_group("or a pair of a DG16M grasp file")
    pair.add_argument("--grasps", type=Path, default=None, metavar="FILE.h5", help="the file")
    pair.add_argument("--index", type=int, default=None, metavar="I", help="the pair to replay")
    _object_options(pair, required=False)
    output = replay.add_argument_group("output")
    output.add_argument(
        "--out", type=Path, required=True, help="strip.png (frames side by side) or anim.gif"
    )
    output.add_argument(
        "--frames",
        type=int,
        default=None,
        metavar="N",
        help="frames: up to the number of phase ends, ends of distinct phases (one frame per "
        "phase); more, spread evenly in time; the key frames come on top (default: 8 for PNG, "
        "40 for GIF)",
    )
    output.add_argument("--size", default="480x360", help="frame size WxH (default: 480x360)")
    output.add_argument(
        "--view",
        default=None,
        metavar="AZ,EL",
        help="camera azimuth,elevation in degrees (default: looking across the line between "
        "the two hands, from their side, elevation -25)",
    )
    output.add_argument("--fps", type=float, default=10.0, help="GIF frame rate (default: 10)")
    replay.set_defaults(handler=_replay)


def _run_arguments(run: argparse.ArgumentParser) -> None:
    run.add_argument("file", type=Path, metavar="FILE.h5", help="a DG16M grasp file")
    _object_options(run, required=True)
    add_limit_argument(
        run, "at most K passing and K failing pairs (seeded sample; default: all)", metavar="K"
    )
    add_seed_argument(run, "seed of the --limit sample")
    run.add_argument(
        "--perturbations",
        type=int,
        default=None,
        metavar="K",
        help="perturbed trials per pair besides the nominal one, for its success probability "
        "(benchmark protocol v2; default: 8, the benchmark's; 0: the nominal trial only)",
    )
    run.add_argument(
        "--perturbation-seed", type=int, default=0, help="seed of the perturbations (default 0)"
    )
    run.add_argument("--json", action="store_true", help="print JSON instead of text")
    add_simulator_arguments(run)
    run.set_defaults(handler=_run)


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------


def _parse_size(text: str) -> tuple[int, int]:
    from dg16m_env.physics.replay import check_size

    parts = text.lower().split("x")
    try:
        width, height = (int(p) for p in parts)
    except ValueError:
        raise SimCommandError(
            f"--size: expected WxH in pixels like 480x360, found {text!r}"
        ) from None
    try:
        return check_size(width, height)
    except Dg16mError as exc:
        raise SimCommandError(f"--size {text}: {exc}") from None


def _parse_view(text: str | None) -> dict[str, float] | None:
    if text is None:
        return None
    try:
        azimuth, elevation = (float(p) for p in text.split(","))
    except ValueError:
        raise SimCommandError(
            f"--view: expected azimuth,elevation in degrees like 135,-25, found {text!r}"
        ) from None
    return {"azimuth": azimuth, "elevation": elevation}


def _output_kind(path: Path) -> str:
    kind = path.suffix.lower()
    if kind not in (".png", ".gif"):
        raise SimCommandError(f"--out: expected a .png or .gif path, found {str(path)!r}")
    return kind


def _check_range(option: str, value: int | None, n: int, what: str) -> int:
    if value is None:
        raise SimCommandError(f"{option}: expected the {what} to replay, found none given")
    if not 0 <= value < n:
        raise SimCommandError(f"{option}: expected a {what} in [0, {n}), found {value}")
    return value


def _grasp_object(args: argparse.Namespace, object_scale: float):
    """The GraspObject and its convex parts for ``--mesh`` / ``--procedural``."""
    if args.coacd_threshold is not None and args.mesh is None:
        raise SimCommandError(
            "--coacd-threshold: expected only with --mesh (a procedural object has exact parts)"
        )
    if args.procedural is not None:
        from dataset_gen.sources.procedural import make_procedural_object, parse_object_id

        family, seed = parse_object_id(args.procedural)
        obj = make_procedural_object(family, seed, mass=args.mass)
        return obj, obj.parts
    from dataset_gen.objects.decomposition import DecompositionParameters, object_parts
    from dataset_gen.objects.grasp_object import load_object

    # The grasp file's scale is authoritative: no plausibility check on the object's size.
    obj = load_object(args.mesh, scale=object_scale, mass=args.mass, allow_any_size=True)
    params = DecompositionParameters(
        **({} if args.coacd_threshold is None else {"threshold": args.coacd_threshold})
    )
    print(
        f"convex parts of {args.mesh} (CoACD, threshold {params.threshold:g}; cached after the "
        "first run) ...",
        file=sys.stderr,
        flush=True,
    )
    return obj, object_parts(obj, params=params, stoppable=True)  # Ctrl-C stops CoACD


def _write(replay, args: argparse.Namespace, title: str) -> None:
    from dg16m_env.physics.replay import HAND_COLOR_NAMES, slip_curve, write_gif, write_strip

    if args.out.suffix.lower() == ".gif":
        write_gif(replay.frames, args.out, fps=args.fps, captions=replay.captions)
    else:
        hands = " and ".join(HAND_COLOR_NAMES)
        title = f"{title}; hands {hands}, contacts red"
        if replay.layout:
            title = f"{title}; {replay.layout}"
        write_strip(replay.frames, replay.captions, args.out, title=title, curve=slip_curve(replay))
    height, width = replay.frames[0].shape[:2]
    count = len(replay.frames)
    print(f"wrote {args.out} ({count} frame{'s' if count != 1 else ''}, {width}x{height})")


# --------------------------------------------------------------------------------------------
# Handlers
# --------------------------------------------------------------------------------------------


def _replay(args: argparse.Namespace) -> int:
    kind = _output_kind(args.out)
    width, height = _parse_size(args.size)
    camera = _parse_view(args.view)
    n_frames = args.frames if args.frames is not None else (40 if kind == ".gif" else 8)
    if n_frames < 1:
        raise SimCommandError(f"--frames: expected an integer >= 1, found {n_frames}")
    if args.benchmark is not None and args.grasps is not None:
        raise SimCommandError(
            "expected either BENCHMARK.h5 with --row or --grasps FILE.h5 with --index, found both"
        )
    if args.benchmark is None and args.grasps is None:
        from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK

        if not EMBEDDED_BENCHMARK.is_file():
            raise SimCommandError(
                "expected BENCHMARK.h5 with --row or --grasps FILE.h5 with --index, found neither "
                f"(and no shipped benchmark at {EMBEDDED_BENCHMARK})"
            )
        args.benchmark = EMBEDDED_BENCHMARK
    if args.benchmark is not None:
        stray = [
            name
            for name, value in (
                ("--index", args.index),
                ("--mesh", args.mesh),
                ("--procedural", args.procedural),
            )
            if value is not None
        ]
        if stray:
            raise SimCommandError(
                f"{', '.join(stray)}: expected only with --grasps, found with BENCHMARK.h5"
            )
        return _replay_benchmark(args, n_frames, width, height, camera)
    if args.row is not None or args.meshes is not None:
        raise SimCommandError(
            "--row/--meshes: expected only with BENCHMARK.h5, found with --grasps"
        )
    if args.mesh is None and args.procedural is None:
        raise SimCommandError(
            "--grasps: expected its object with --mesh MESH or --procedural ID, found neither"
        )
    return _replay_grasps(args, n_frames, width, height, camera)


def _replay_benchmark(args, n_frames: int, width: int, height: int, camera) -> int:
    from dg16m_env.benchmark.file import read_benchmark
    from dg16m_env.benchmark.model import SOURCES
    from dg16m_env.physics.labels import trial_poses
    from dg16m_env.physics.replay import describe_result, replay_trial
    from dg16m_env.physics.scene import compile_scene
    from dg16m_env.physics.trial_protocol import PHASES, TrialStatus

    bench = read_benchmark(args.benchmark)
    row = _check_range("--row", args.row, bench.n, "row")
    item = bench.objects[int(bench.object_index[row])]
    if not item.family and not item.has_mesh and args.meshes is None:
        raise SimCommandError(
            f"{item.object_id}: expected --meshes DIR holding {item.file!r} (the benchmark's "
            "object is a mesh), found none given"
        )
    trials = bench.labels.spec.trials
    trial = _check_range("--trial", args.trial, trials, "trial (0 nominal, 1..K perturbed)")
    obj = item.load(args.meshes)
    scene = compile_scene(obj, params=bench.parameters().scene, parts=item.parts)
    seeds = bench.labels.seeds[[row]]
    pose = trial_poses(scene, bench.poses[[row]], seeds, bench.labels.spec)[0, trial]
    replay = replay_trial(
        scene,
        pose,
        bench.trials.protocol,
        n_frames=n_frames,
        width=width,
        height=height,
        camera=camera,
    )
    verdict = "pass" if bench.fc_passed[row] else "fail"
    print(
        f"{args.benchmark} row {row}: object {item.object_id}, source "
        f"{SOURCES[int(bench.source[row])]} (force closure {verdict}, loss "
        f"{bench.fc_loss[row]:.3g} N)"
    )
    print(
        f"  success probability: {bench.p()[row]:.2f} through every disturbance, "
        f"{bench.p('gravity')[row]:.2f} under gravity ({trials} trials: nominal + "
        f"{trials - 1} perturbed)"
    )
    if trial == 0:
        print(f"  stored nominal trial: {describe_result(bench.trials, row)}")
    else:
        stored = TrialStatus(int(bench.labels.status[row, trial])).name.lower()
        phase = int(bench.labels.failing_phase[row, trial])
        where = f" in {PHASES[phase]}" if phase >= 0 else ""
        print(f"  stored perturbed trial {trial}: {stored}{where}")
    print(f"  replayed: {replay.trial.describe()}")
    same = int(bench.labels.status[row, trial]) == int(replay.trial.results.status[0]) and int(
        bench.labels.failing_phase[row, trial]
    ) == int(replay.trial.results.failing_phase[0])
    if not same:
        print(
            "  note: the replay differs from the stored label (a benchmark built with another "
            "dg16m or MuJoCo version?)"
        )
    what = f"row {row}" if trial == 0 else f"row {row}, perturbed trial {trial}"
    _write(replay, args, f"{item.object_id}, {what}: {replay.trial.describe()}")
    return 0


def _replay_grasps(args, n_frames: int, width: int, height: int, camera) -> int:
    from dataset_gen.io import read_dg16m
    from dg16m_env.benchmark.sources import file_poses
    from dg16m_env.physics.replay import replay_trial
    from dg16m_env.physics.scene import compile_scene

    data = read_dg16m(args.grasps)
    index = _check_range("--index", args.index, data.n, "pair index")
    obj, parts = _grasp_object(args, data.object_scale)
    scene = compile_scene(obj, parts=parts)
    pose = file_poses(data, [index], args.gripper)[0]
    replay = replay_trial(scene, pose, n_frames=n_frames, width=width, height=height, camera=camera)
    verdict = "pass" if data.passed[index] else "fail"
    print(
        f"{args.grasps} pair {index}: object {obj.object_id} (force closure {verdict}, loss "
        f"{data.loss_values[index]:.3g} N)"
    )
    print(f"  replayed: {replay.trial.describe()}")
    _write(replay, args, f"{obj.object_id}, pair {index}: {replay.trial.describe()}")
    return 0


INVALID_MEANING = {
    "hand0_penetrates": "the open hand 0 already sits inside the object",
    "hand1_penetrates": "the open hand 1 already sits inside the object",
    "hands_overlap": "the two hands overlap each other",
}
"""What each :class:`~dg16m_env.physics.trial.InvalidReason` means, for people."""


def _sim_run_report(
    file: Path, object_id: str, labels: Any, n_passing: int, hits: dict[str, int]
) -> list[str]:
    """The text report of ``dg16m sim run``: counts, rates, phases, and the invalid trials'
    reasons with what to do about them."""
    from dg16m_env.benchmark.report_text import percent, trial_lines

    results = labels.nominal
    n = results.n
    spec = labels.spec
    lines = [
        f"{file}: {n} pairs on {object_id} ({n_passing} passing, {n - n_passing} failing force "
        "closure)",
        "  nominal trials:",
        *(f"  {line}" for line in trial_lines(results.summary())),
        f"  success probability over {spec.trials} trials per pair (nominal + "
        f"{spec.n_perturbations} perturbed by {1e3 * spec.translation:g} mm / "
        f"{spec.rotation_deg:g} deg; invalid = failure):",
    ]
    for name, rate in _force_closure_rates(labels, n_passing).items():
        lines.append(
            f"    fc {name}: {percent(rate['p_full']).strip()} held through every disturbance, "
            f"{percent(rate['p_gravity']).strip()} under gravity ({rate['pairs']} pairs, "
            f"{rate['uncertain']} uncertain); nominal trial alone "
            f"{percent(rate['nominal_success_rate']).strip()} of {rate['valid']} simulated"
        )
    return lines + _invalid_report(results, hits)


def _open_hand_hits(scene: Any, poses: np.ndarray, results: Any) -> dict[str, int]:
    """In how many trials invalid because an open hand penetrates, the palm / a finger does."""
    import numpy as np

    from dg16m_env.physics.trial_protocol import InvalidReason, open_hand_penetration

    rows = np.flatnonzero(
        np.isin(
            results.invalid_reason, [InvalidReason.HAND0_PENETRATES, InvalidReason.HAND1_PENETRATES]
        )
    )
    if rows.size == 0:
        return {}
    inside = open_hand_penetration(scene, poses[rows]) > results.protocol.invalid_penetration
    return {
        "palm": int(inside[:, :, 0].any(axis=1).sum()),
        "fingers": int(inside[:, :, 1:].any(axis=(1, 2)).sum()),
    }


def _invalid_report(results: Any, hits: dict[str, int]) -> list[str]:
    reasons = results.invalid_reasons()
    if not reasons:
        return []
    invalid = sum(reasons.values())
    lines = [f"  invalid trials ({invalid} of {results.n}; not run), by reason:"]
    for name, count in reasons.items():
        lines.append(f"    {count:5d}  {name.replace('_', ' ')}: {INVALID_MEANING[name]}")
    if hits:
        import numpy as np

        depth = results.max_penetration[results.invalid_reason > 0]
        lines += [
            f"  inside the object: the open hand's palm in {hits['palm']} of them, a finger in "
            f"{hits['fingers']};",
            f"  depth median {1e3 * np.median(depth):.1f} mm, max {1e3 * depth.max():.1f} mm "
            f"(allowed: {1e3 * results.protocol.invalid_penetration:.1f} mm)",
        ]
    return lines


def _penetration_advice(args: argparse.Namespace, gripper: str) -> list[str]:
    """What to do when open hands start inside the object (printed after the report)."""
    from dataset_gen.grasps.gripper import PANDA

    palm = 2e3 * PANDA.palm_half_extents[0]
    lines = ["  what to do (an open hand inside the object cannot reach its grasp):"]
    if gripper != PANDA.name:
        lines += [
            f"  - the file's poses are for the {gripper} hand (see --gripper), moved here to the",
            f"    simulated Panda hand, whose palm ({palm:.0f} mm wide) and fingers differ: at the",
            "    same contacts they can hit the object. Grasps made for the Panda avoid this",
            "    (dg16m generate --gripper panda).",
        ]
    if args.mesh is not None:
        lines += [
            "  - the hands collide with the mesh's convex parts (CoACD); where the hulls overhang",
            "    the mesh, a finer --coacd-threshold (e.g. 0.02) gives tighter parts.",
        ]
    lines.append(
        "  - look at one: dg16m sim replay --grasps FILE --index I (--mesh MESH | --procedural "
        "ID) --out pair.png"
    )
    return lines


def _force_closure_rates(labels: Any, n_passing: int) -> dict[str, dict[str, Any]]:
    """Of the passing rows (the first ``n_passing``) and of the failing rows: pairs, mean
    success probability at both levels (over all pairs), uncertain pairs, and the nominal
    trials' success rate over the valid ones."""
    import numpy as np

    rates = {}
    n = labels.n
    for name, rows in (("passing", slice(0, n_passing)), ("failing", slice(n_passing, n))):
        part = labels.select(np.arange(n)[rows])
        valid = int(part.nominal.valid.sum())
        rates[name] = {
            "pairs": part.n,
            "p_full": float(part.p_success.mean()) if part.n else None,
            "p_gravity": float(part.p_gravity.mean()) if part.n else None,
            "uncertain": int(part.uncertain().sum()),
            "valid": valid,
            "nominal_success_rate": (float(part.nominal.success.sum() / valid) if valid else None),
        }
    return rates


def _run_payload(
    file: Path,
    object_id: str,
    labels: Any,
    n_passing: int,
    hits: dict[str, int],
    simulator: dict[str, Any],
) -> dict[str, Any]:
    """The JSON report of ``dg16m sim run`` (machine-readable: full precision, NaN as null)."""
    from dg16m_core.json_values import json_ready

    return {
        "file": str(file),
        "object": object_id,
        "perturbation": labels.spec.to_dict(),
        "summary": json_ready(labels.nominal.summary()),
        "invalid_reasons": labels.nominal.invalid_reasons(),
        "open_hand_inside": hits,
        "force_closure": _force_closure_rates(labels, n_passing),
        "p_success": labels.p_success.tolist(),
        "p_gravity": labels.p_gravity.tolist(),
        "simulator": simulator,
    }


def _run(args: argparse.Namespace) -> int:
    import numpy as np

    from dataset_gen.io import read_dg16m
    from dg16m_env.benchmark.arms import choose_file_pairs
    from dg16m_env.benchmark.sources import file_gripper, file_poses
    from dg16m_env.physics.labels import PerturbationSpec, success_probability
    from dg16m_env.physics.scene import compile_scene

    if args.limit is not None and args.limit < 1:
        raise SimCommandError(f"--limit: expected an integer >= 1, found {args.limit}")
    simulator = simulator_from_args(args)
    simulator.check_available()
    defaults = PerturbationSpec()
    spec = PerturbationSpec(
        n_perturbations=(
            defaults.n_perturbations if args.perturbations is None else args.perturbations
        ),
        seed=args.perturbation_seed,
    )
    data = read_dg16m(args.file)
    rng = np.random.default_rng(args.seed)
    passing, failing = choose_file_pairs(data, args.limit, args.limit, rng, fill=False)
    rows = np.concatenate([passing, failing])
    if rows.size == 0:
        raise SimCommandError(f"{args.file}: expected passing or failing pairs, found none")
    obj, parts = _grasp_object(args, data.object_scale)
    scene = compile_scene(obj, parts=parts)
    poses = file_poses(data, rows, args.gripper)
    labels = success_probability(
        scene,
        poses,
        spec=spec,
        progress=not args.json and sys.stderr.isatty(),
        simulator=simulator,
    )
    hits = _open_hand_hits(scene, poses, labels.nominal)
    if args.json:
        payload = _run_payload(
            args.file, obj.object_id, labels, passing.size, hits, simulator.describe()
        )
        print(json.dumps(payload, indent=2))
        return 0
    lines = _sim_run_report(args.file, obj.object_id, labels, passing.size, hits)
    if not simulator.is_default:
        lines.insert(1, f"  trials on MuJoCo Warp, device {simulator.warp_device}")
    if hits:
        lines += _penetration_advice(args, file_gripper(data, args.gripper))
    print("\n".join(lines))
    return 0
