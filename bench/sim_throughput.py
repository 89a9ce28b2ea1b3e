"""Trial throughput of the simulation benchmark, per core, with the time of every phase.

For the first ``--procedural`` objects of the procedural benchmark split (one per family) and for
the real DG16M airplane mesh (CoACD parts, when ``../shared/data/real`` is present), chooses the
benchmark's ~100 dual grasps exactly as ``dg16m benchmark build`` does (same rng stream), compiles
the scene and runs :func:`dg16m_env.trial.run_trials` (validity check, rollout segments with early
exit for failed trials, analysis). The library's functions are wrapped with timers, so the time
splits into: validity check, building controls, each rollout segment (close+gravity, forces,
torques), analysis. trials/s = simulated (valid) trials / seconds inside ``mujoco.rollout``.

References measured in the same run (the machine is noisy): the same trials rolled out at full
length without early exit (:func:`dg16m_env.trial.simulate`), and a subsample stepped in a plain
Python loop (``mj_setState`` + ``mj_step``, the full 14-phase trial). CoACD time is reported
separately, never inside trials/s. Ends with the median trials/s against the 40 trials/s per core
target and the projected time of the 300-object benchmark on ``--cores`` cores.

    .venv/bin/python bench/sim_throughput.py                 # a few minutes
    .venv/bin/python bench/sim_throughput.py --procedural 3 --loop-pairs 5 --json runs/sim.json
"""

from __future__ import annotations

import os

# One core: no BLAS, OpenMP or numba threads (set before numpy is imported).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import contextlib
import time
import types
from collections import defaultdict
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from dataset_gen.objects import GraspObject
from dataset_gen.procedural import benchmark_specs
from dataset_gen.sources import ObjectSource, object_seed, procedural_sources
from dg16m_env import trial
from dg16m_env.benchmark import BenchmarkParameters, sampled_pairs
from dg16m_env.decomposition import object_parts
from dg16m_env.scene import Scene, compile_scene

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
MESH_ID = "dg16m_airplane"  # the id `dg16m benchmark build --meshes` gives it (the file stem)
SEGMENTS = ("close+gravity", "forces", "torques")  # trial.segments, in order
TARGET_TRIALS_PER_S = 40.0


@dataclass
class Arguments:
    procedural: int = 10
    loop_pairs: int = 10
    benchmark_objects: int = 300
    cores: int = 2
    seed: int = 0
    no_mesh: bool = False
    json: str | None = None


def parse() -> Arguments:
    defaults = Arguments()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--procedural", type=int, default=defaults.procedural)
    parser.add_argument(
        "--loop-pairs",
        type=int,
        default=defaults.loop_pairs,
        help="valid pairs per object stepped in the Python loop reference",
    )
    parser.add_argument("--benchmark-objects", type=int, default=defaults.benchmark_objects)
    parser.add_argument("--cores", type=int, default=defaults.cores)
    parser.add_argument("--seed", type=int, default=defaults.seed, help="benchmark seed")
    parser.add_argument("--no-mesh", action="store_true", help="skip the CoACD airplane row")
    parser.add_argument("--json", default=None, help="also write the results here")
    return Arguments(**vars(parser.parse_args()))


def procedural_objects(count: int) -> list[ObjectSource]:
    """The first ``count`` benchmark objects, first spec of each family first (the benchmark
    specs are seed-major, so this is also ``benchmark_specs()[:count]`` for count <= 10)."""
    specs = benchmark_specs()
    first: dict[str, tuple[str, int]] = {}
    for spec in specs:
        first.setdefault(spec[0], spec)
    ordered = list(first.values()) + [s for s in specs if s not in first.values()]
    return procedural_sources(ordered[:count])


# --------------------------------------------------------------------------------------------
# Timing wrappers around the library's functions (the library itself is unchanged)
# --------------------------------------------------------------------------------------------


class PhaseTimes:
    """Seconds accumulated per phase, and trials entering each rollout segment."""

    def __init__(self, scene: Scene, protocol: trial.TrialProtocol) -> None:
        plan = trial.schedule(scene, protocol)
        self.nstep = plan.nstep
        self.timestep = scene.model.opt.timestep
        segments = trial.trial_segments(plan)
        self.segment_of_start = {seg.start: SEGMENTS[k] for k, seg in enumerate(segments)}
        self.segment_steps = {SEGMENTS[k]: seg.stop - seg.start for k, seg in enumerate(segments)}
        self.seconds: dict[str, float] = defaultdict(float)
        self.trials: dict[str, int] = defaultdict(int)

    def segment(self, initial_state: np.ndarray, nstep: int) -> str:
        """Which segment a rollout call runs: the full trial (``trial.simulate``), else the
        segment starting at the state's time (forces and torques have the same ``nstep``)."""
        if nstep == self.nstep:
            return "full_length"
        start = round(float(np.asarray(initial_state)[0, 0]) / self.timestep)
        name = self.segment_of_start[start]
        assert self.segment_steps[name] == nstep, (name, nstep)
        return name


@contextlib.contextmanager
def timed_library(times: PhaseTimes) -> Iterator[None]:
    """Wrap ``trial``'s check, controls, analysis and rollout with timers while inside."""

    def timed(key: Callable[..., str], fn: Callable[..., Any]) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            name = key(*args, **kwargs)
            start = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                times.seconds[name] += time.perf_counter() - start

        return wrapper

    def rollout_key(model: Any, data: Any, state: np.ndarray, *args: Any, **kwargs: Any) -> str:
        assert isinstance(data, mujoco.MjData), "expected a single MjData (one thread)"
        name = times.segment(state, kwargs["nstep"])
        times.trials[name] += len(state)
        return name

    def analyse_key(scene: Any, states: Any, sensors: Any, plan: trial.Schedule, *a: Any) -> str:
        return "analysis_final" if plan.nstep == times.nstep else "analysis_partial"

    saved = {
        name: getattr(trial, name)
        for name in ("check_initial_poses", "trial_controls", "analyse", "rollout")
    }
    trial.check_initial_poses = timed(lambda *a, **k: "check", saved["check_initial_poses"])
    trial.trial_controls = timed(lambda *a, **k: "controls", saved["trial_controls"])
    trial.analyse = timed(analyse_key, saved["analyse"])
    # Only trial's reference to mujoco.rollout is replaced; the mujoco module stays untouched.
    trial.rollout = types.SimpleNamespace(rollout=timed(rollout_key, saved["rollout"].rollout))
    try:
        yield
    finally:
        for name, value in saved.items():
            setattr(trial, name, value)


# --------------------------------------------------------------------------------------------
# Python-loop reference
# --------------------------------------------------------------------------------------------


def python_loop(scene: Scene, grasps: np.ndarray, protocol: trial.TrialProtocol) -> tuple:
    """Full-length trials stepped one ``mj_step`` at a time from Python, recording what
    ``mujoco.rollout`` records (state and sensors after every step). Returns (states, sensors,
    seconds of the stepping loop)."""
    model = scene.model
    plan = trial.schedule(scene, protocol)
    controls = trial.trial_controls(scene, grasps, plan)
    start = trial.initial_state(scene)
    states = np.empty((len(grasps), plan.nstep, start.size))
    sensors = np.empty((len(grasps), plan.nstep, model.nsensordata))
    data = mujoco.MjData(model)
    full, spec = trial.STATE_SPEC, trial.CONTROL_SPEC
    began = time.perf_counter()
    for i in range(len(grasps)):
        mujoco.mj_resetData(model, data)
        mujoco.mj_setState(model, data, start, full)
        for t in range(plan.nstep):
            mujoco.mj_setState(model, data, controls[i, t], spec)
            mujoco.mj_step(model, data)
            mujoco.mj_getState(model, data, states[i, t], full)
            sensors[i, t] = data.sensordata
    return states, sensors, time.perf_counter() - began


# --------------------------------------------------------------------------------------------
# One object
# --------------------------------------------------------------------------------------------


def per_s(count: float, seconds: float) -> float:
    return count / seconds if seconds > 0 else float("nan")


def run_object(
    source: ObjectSource, params: BenchmarkParameters, loop_pairs: int
) -> dict[str, Any]:
    began = time.perf_counter()
    obj: GraspObject = source.load(params.mass)
    load_s = time.perf_counter() - began
    stats: dict[str, Any] = {}
    parts = object_parts(obj, stats=stats)  # procedural: obj.parts, no CoACD (stats untouched)
    # The builder's stream: benchmark_object derives it from (seed, "benchmark:<id>").
    rng = np.random.default_rng(object_seed(params.seed, f"benchmark:{obj.object_id}"))
    began = time.perf_counter()
    rows = sampled_pairs(obj, params, rng)
    sampling_s = time.perf_counter() - began
    began = time.perf_counter()
    scene = compile_scene(obj, params=params.scene, parts=parts)
    compile_s = time.perf_counter() - began
    grasps = rows["poses"]

    times = PhaseTimes(scene, params.protocol)
    with timed_library(times):
        began = time.perf_counter()
        results = trial.run_trials(scene, grasps, params.protocol)
        run_trials_s = time.perf_counter() - began
    early = dict(times.seconds)
    entered = dict(times.trials)
    valid = np.flatnonzero(results.valid)
    n_valid = int(valid.size)

    # Reference 1: the same valid trials at full length (no early exit).
    full_times = PhaseTimes(scene, params.protocol)
    if n_valid:
        with timed_library(full_times):
            trial.simulate(scene, grasps[valid], params.protocol)
    full_s = full_times.seconds["full_length"]

    # Reference 2: a spread subsample (all sources) in a Python loop, and the same trials
    # through rollout at full length (same work, so this ratio is the engine's alone).
    sub = valid[
        np.unique(np.linspace(0, n_valid - 1, min(loop_pairs, n_valid)).round().astype(int))
    ]
    loop_s = sub_rollout_s = float("nan")
    identical = None
    if sub.size:
        loop_states, loop_sensors, loop_s = python_loop(scene, grasps[sub], params.protocol)
        sub_times = PhaseTimes(scene, params.protocol)
        with timed_library(sub_times):
            ref_states, ref_sensors, _ = trial.simulate(scene, grasps[sub], params.protocol)
        sub_rollout_s = sub_times.seconds["full_length"]
        identical = bool(
            np.array_equal(loop_states, ref_states, equal_nan=True)
            and np.array_equal(loop_sensors, ref_sensors, equal_nan=True)
        )

    rollout_s = sum(early.get(name, 0.0) for name in SEGMENTS)
    summary = results.summary()
    accounted = sum(early.values())
    per_trial = max(n_valid, 1)
    return {
        "object": obj.object_id,
        "kind": "mesh" if source.mesh is not None else "procedural",
        "parts": len(parts),
        "coacd": (
            {"cache_hit": bool(stats["cache_hit"]), "seconds": stats["seconds"]} if stats else None
        ),
        "pairs": int(results.n),
        "valid": n_valid,
        "success": summary["success"],
        "failed": summary["failed"],
        "unstable": summary["unstable"],
        "load_s": load_s,
        "sampling_pairing_s": sampling_s,
        "compile_s": compile_s,
        "run_trials_s": run_trials_s,
        "phase_s": {**early, "other": run_trials_s - accounted},
        "segment_trials": entered,
        "check_ms_per_pair": 1e3 * early.get("check", 0.0) / max(results.n, 1),
        "controls_ms_per_trial": 1e3 * early.get("controls", 0.0) / per_trial,
        "segment_ms_per_trial": {k: 1e3 * early.get(k, 0.0) / per_trial for k in SEGMENTS},
        "analysis_ms_per_trial": 1e3
        * (early.get("analysis_partial", 0.0) + early.get("analysis_final", 0.0))
        / per_trial,
        "rollout_s": rollout_s,
        "trials_per_s": per_s(n_valid, rollout_s),
        "rollout_ms_per_trial": 1e3 * rollout_s / per_trial,
        "end_to_end_trials_per_s": per_s(n_valid, run_trials_s),
        "full_length_s": full_s,
        "full_length_trials_per_s": per_s(n_valid, full_s),
        "loop_pairs": int(sub.size),
        "loop_s": loop_s,
        "loop_trials_per_s": per_s(sub.size, loop_s),
        "same_pairs_rollout_trials_per_s": per_s(sub.size, sub_rollout_s),
        "loop_bit_identical_to_rollout": identical,
    }


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------


def fmt(value: float, digits: int = 1) -> str:
    return "-" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def table(rows: list[dict[str, Any]]) -> str:
    head = (
        "| object | parts | trials (valid) | success | compile s | check ms/pair | controls "
        "ms/trial | rollout close+gravity / forces / torques ms/trial | analysis ms/trial | "
        "trials/s (early exit) | trials/s (full length) | python loop trials/s | ratio | "
        "ratio same work | run_trials trials/s |"
    )
    lines = [head, "|" + "---|" * head.count(" | ") + "---|"]
    for r in rows:
        seg = r["segment_ms_per_trial"]
        loop = r["loop_trials_per_s"]
        lines.append(
            f"| {r['object']} | {r['parts']} | {r['pairs']} ({r['valid']}) | {r['success']} | "
            f"{r['compile_s']:.2f} | {fmt(r['check_ms_per_pair'], 2)} | "
            f"{fmt(r['controls_ms_per_trial'], 2)} | "
            + " / ".join(fmt(seg[k]) for k in SEGMENTS)
            + f" | {fmt(r['analysis_ms_per_trial'], 2)} | {fmt(r['trials_per_s'])} | "
            f"{fmt(r['full_length_trials_per_s'])} | {fmt(loop)} | "
            f"{fmt(r['trials_per_s'] / loop, 2)}x | "
            f"{fmt(r['same_pairs_rollout_trials_per_s'] / loop, 2)}x | "
            f"{fmt(r['end_to_end_trials_per_s'])} |"
        )
    return "\n".join(lines)


def main() -> None:
    args = parse()
    params = BenchmarkParameters(seed=args.seed)
    sources = procedural_objects(args.procedural)
    airplane = REAL / "dg16m_airplane.obj"
    mesh_note = None
    if args.no_mesh:
        mesh_note = "mesh row skipped (--no-mesh)"
    elif airplane.is_file():
        sources.append(ObjectSource(MESH_ID, mesh=airplane))
    else:
        mesh_note = f"mesh row skipped: {airplane} not found (../shared absent)"
    print(
        f"mujoco {mujoco.__version__}, one core, benchmark seed {args.seed}, "
        f"{params.n_grasps} grasps sampled per object"
    )
    # Warm up compiled kernels (numba) and the scene compiler outside the timings.
    warm = sources[0].load(params.mass)
    sampled_pairs(warm, replace(params, n_grasps=20), np.random.default_rng(0))
    compile_scene(warm, params=params.scene)

    rows = []
    for source in sources:
        row = run_object(source, params, args.loop_pairs)
        rows.append(row)
        coacd = row["coacd"]
        extra = (
            f", CoACD {coacd['seconds']:.1f} s ({'cache hit' if coacd['cache_hit'] else 'computed'})"
            if coacd
            else ""
        )
        print(
            f"{row['object']:26s} load {row['load_s']:.2f} s{extra}, sampling+pairing "
            f"{row['sampling_pairing_s']:.2f} s, compile {row['compile_s']:.2f} s, run_trials "
            f"{row['run_trials_s']:.2f} s (unaccounted {row['phase_s']['other']:.2f} s), trials "
            f"entering segments {row['segment_trials']}, "
            f"loop == rollout bit for bit: {row['loop_bit_identical_to_rollout']}",
            flush=True,
        )

    report(rows, args, mesh_note)


def report(rows: list[dict[str, Any]], args: Arguments, mesh_note: str | None) -> None:
    """Print the table, the medians and the projection; write ``--json`` when asked."""
    print()
    print(table(rows))
    print()
    print(
        "check: ms per checked pair (invalid ones included); controls, rollout segments, analysis "
        "(between segments + final): ms per simulated (valid) trial. trials/s = valid trials / "
        "seconds inside mujoco.rollout (early exit: run_trials' segments; full length: "
        "trial.simulate on the same trials). python loop: full-length trials on a spread "
        f"subsample of {args.loop_pairs} valid pairs; ratio = trials/s (early exit) / loop; ratio "
        "same work = rollout at full length on the same subsample / loop. run_trials trials/s = "
        "valid trials / whole run_trials seconds."
    )
    if mesh_note:
        print(mesh_note)
    procedural = [r for r in rows if r["kind"] == "procedural"]
    if not procedural:
        return
    median = float(np.median([r["trials_per_s"] for r in procedural]))
    median_e2e = float(np.median([r["end_to_end_trials_per_s"] for r in procedural]))
    median_full = float(np.median([r["full_length_trials_per_s"] for r in procedural]))
    median_loop = float(np.median([r["loop_trials_per_s"] for r in procedural]))
    verdict = "meets" if median >= TARGET_TRIALS_PER_S else "misses"
    print(
        f"procedural median: {median:.1f} trials/s per core (rollout, early exit) -> {verdict} "
        f"the target of {TARGET_TRIALS_PER_S:.0f}; whole run_trials {median_e2e:.1f} trials/s; "
        f"full length {median_full:.1f} trials/s (early exit gain {median / median_full:.2f}x); "
        f"python loop {median_loop:.1f} trials/s"
    )
    sampling = float(np.mean([r["sampling_pairing_s"] for r in procedural]))
    trials_s = float(np.mean([r["run_trials_s"] for r in procedural]))
    load_compile = float(np.mean([r["load_s"] + r["compile_s"] for r in procedural]))
    n, cores = args.benchmark_objects, args.cores
    projected = n * (sampling + trials_s) / cores
    print(
        f"projection: {n} objects x ({sampling:.2f} s sampling+pairing + {trials_s:.2f} s "
        f"run_trials) / {cores} cores = {projected:.0f} s ({projected / 3600:.2f} h); with load and "
        f"compile (+{load_compile:.2f} s per object): "
        f"{n * (sampling + trials_s + load_compile) / cores:.0f} s"
    )
    if args.json:
        from dataset_gen.atomic import write_json_atomic

        def clean(value: Any) -> Any:
            if isinstance(value, dict):
                return {k: clean(v) for k, v in value.items()}
            if isinstance(value, float) and not np.isfinite(value):
                return None
            return value

        write_json_atomic(
            Path(args.json),
            clean(
                {
                    "rows": rows,
                    "median_trials_per_s": median,
                    "median_run_trials_trials_per_s": median_e2e,
                    "median_full_length_trials_per_s": median_full,
                    "median_loop_trials_per_s": median_loop,
                    "target_trials_per_s": TARGET_TRIALS_PER_S,
                    "projected_seconds": projected,
                    "mesh_note": mesh_note,
                }
            ),
        )


if __name__ == "__main__":
    main()
