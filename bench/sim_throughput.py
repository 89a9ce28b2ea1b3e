"""Trial and label throughput of the simulation benchmark (protocol v2), per core, by phase.

For the first ``--procedural`` objects of the procedural benchmark split (one per family) and for
the real DG16M airplane mesh (CoACD parts, when ``../shared/data/real`` is present), chooses the
benchmark's ~100 dual grasps exactly as ``dg16m benchmark build`` does (same rng stream, four
arms: fc_pass, fc_fail, random, farthest), compiles the scene and measures, in one run (the
machine is noisy, so every reference shares it):

* **v2 trial path**: :func:`dg16m_env.physics.trial.run_trials` on the nominal grasps (validity check,
  one ``mujoco.rollout`` call per phase, 14 phases, a failed trial stopped at the end of its
  failing phase; each phase measured once by ``measure_steps``, then ``judge``). The library's
  ``check_initial_poses``, ``trial_controls``, ``measure_steps``, ``judge`` and its reference to
  ``mujoco.rollout`` are wrapped with timers (module attributes replaced inside a context
  manager; the library itself is unchanged). Rollout time is reported per phase group (close,
  gravity, forces = the 6 force phases, torques = the 6 torque phases) with the number of trials
  entering each group; a rollout call's phase is read from its initial state's time.
  trials/s = simulated (valid) trials / seconds inside ``mujoco.rollout``.
* **v1 reference path** (implemented here, not library code): the previous runner, three rollout
  segments (close+gravity | 6 forces | 6 torques), after each segment the head of the trajectory
  re-judged with :func:`dg16m_env.physics.trial.analyse` and failed trials stopped, no contact
  requirement (``min_contacts_after_close=0``). Run on the same valid nominal grasps; reported as
  trials/s per core against the v2 path (ratio v2/v1) with the number of verdicts that differ
  (they may: contact requirement, solver restarted at other steps).
* **Labels**: :func:`dg16m_env.physics.labels.success_probability` on the object's pairs, the real v2
  benchmark work (K + 1 trials per pair: nominal + ``PerturbationSpec().n_perturbations``
  perturbed poses); pairs/s and trials/s per core.
* **References**: the same valid trials at full length (:func:`dg16m_env.physics.trial.simulate`, no
  early exit, the same per-phase segments) and a subsample stepped in a plain Python loop
  (``mj_setState`` + ``mj_step``, the full 14-phase trial, ``qacc_warmstart`` cleared at the first
  step of each segment as ``mujoco.rollout`` does), checked bit for bit against ``simulate``.

CoACD time is reported separately, never inside a rate. Ends with the median trials/s against the
40 trials/s per core target and the projected 300-object v2 rebuild on ``--cores`` cores,
``objects x median(sampling+pairing s + success_probability s) / cores``, against 45 minutes.

    nice -n 19 .venv/bin/python bench/sim_throughput.py     # 10 families + airplane: ~5-10 min
    nice -n 19 .venv/bin/python bench/sim_throughput.py --procedural 2 --loop-pairs 2 --no-mesh
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
from mujoco import rollout

from dataset_gen.objects.decomposition import object_parts
from dataset_gen.objects.grasp_object import GraspObject
from dataset_gen.sources.object_source import ObjectSource, object_seed, procedural_sources
from dataset_gen.sources.procedural import benchmark_specs
from dg16m_env.benchmark.arms import sampled_pairs
from dg16m_env.benchmark.model import BenchmarkParameters
from dg16m_env.physics import labels, trial
from dg16m_env.physics.scene import Scene, compile_scene

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
MESH_ID = "dg16m_airplane"  # the id `dg16m benchmark build --meshes` gives it (the file stem)
GROUPS = ("close", "gravity", "forces", "torques")  # v2 phase groups (14 rollout calls)
V1_SEGMENTS = ("close+gravity", "forces", "torques")  # the v1 runner's three rollout calls
TARGET_TRIALS_PER_S = 40.0
TARGET_BUILD_S = 45 * 60.0


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


def phase_group(phase: int) -> str:
    """The group of :data:`trial.PHASES` index ``phase`` (close, gravity, forces, torques)."""
    name = trial.PHASES[phase]
    if name in ("close", "gravity"):
        return name
    return "forces" if name.startswith("force") else "torques"


# --------------------------------------------------------------------------------------------
# Timing wrappers around the library's functions (the library itself is unchanged)
# --------------------------------------------------------------------------------------------


class PhaseTimes:
    """Seconds accumulated per timed function and per rollout phase group, and the trials
    entering each group (counted at the group's first phase)."""

    def __init__(self, scene: Scene, protocol: trial.TrialProtocol) -> None:
        plan = trial.schedule(scene, protocol)
        self.timestep = scene.model.opt.timestep
        # segment start step -> (phase group, steps, first phase of its group)
        self.segment_at: dict[int, tuple[str, int, bool]] = {}
        seen: set[str] = set()
        for seg in trial.trial_segments(plan):
            group = phase_group(int(plan.phase[seg.start]))
            self.segment_at[seg.start] = (group, seg.stop - seg.start, group not in seen)
            seen.add(group)
        self.seconds: dict[str, float] = defaultdict(float)
        self.trials: dict[str, int] = defaultdict(int)
        self.calls: dict[str, int] = defaultdict(int)

    def group(self, initial_state: np.ndarray, nstep: int) -> tuple[str, bool]:
        """The phase group of a rollout call (from its initial state's time) and whether the
        call runs the group's first phase."""
        start = round(float(np.asarray(initial_state)[0, 0]) / self.timestep)
        group, steps, first = self.segment_at[start]
        assert steps == nstep, (group, start, steps, nstep)
        return group, first

    def rollout_s(self) -> float:
        return sum(self.seconds.get(g, 0.0) for g in GROUPS)


@contextlib.contextmanager
def timed_library(times: PhaseTimes) -> Iterator[None]:
    """Wrap ``trial``'s check, controls, measure, judge and rollout with timers while inside."""

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
        group, first = times.group(state, kwargs["nstep"])
        times.calls[group] += 1
        if first:
            times.trials[group] += len(state)
        return group

    saved = {
        name: getattr(trial, name)
        for name in ("check_initial_poses", "trial_controls", "measure_steps", "judge", "rollout")
    }
    trial.check_initial_poses = timed(lambda *a, **k: "check", saved["check_initial_poses"])
    trial.trial_controls = timed(lambda *a, **k: "controls", saved["trial_controls"])
    trial.measure_steps = timed(lambda *a, **k: "measure", saved["measure_steps"])
    trial.judge = timed(lambda *a, **k: "judge", saved["judge"])
    # Only trial's reference to mujoco.rollout is replaced; the mujoco module stays untouched.
    trial.rollout = types.SimpleNamespace(rollout=timed(rollout_key, saved["rollout"].rollout))
    try:
        yield
    finally:
        for name, value in saved.items():
            setattr(trial, name, value)


# --------------------------------------------------------------------------------------------
# v1 reference path (the previous trial runner; a reference, not library code)
# --------------------------------------------------------------------------------------------


def v1_segments(plan: trial.Schedule) -> list[slice]:
    """close+gravity | 6 forces | 6 torques: the v1 runner's three rollout calls."""
    forces = int(np.argmax(plan.phase >= trial.PHASES.index("force+x")))
    torques = int(np.argmax(plan.phase >= trial.PHASES.index("torque+x")))
    return [slice(0, forces), slice(forces, torques), slice(torques, plan.nstep)]


def v1_run_trials(
    scene: Scene, grasps: np.ndarray, protocol: trial.TrialProtocol
) -> tuple[trial.TrialResults, dict[str, float], dict[str, int]]:
    """The v1 runner on valid grasps (no validity check): batches of ``protocol.batch_size``,
    three rollout segments, after each one the trajectory so far re-judged with
    :func:`trial.analyse` and the trials that left the protocol stopped; no contact
    requirement. Returns (results, seconds per part, trials entering each segment)."""
    protocol = replace(protocol, min_contacts_after_close=0)
    plan = trial.schedule(scene, protocol)
    model = scene.model
    data = mujoco.MjData(model)
    start = trial.initial_state(scene)
    n = len(grasps)
    results = trial.TrialResults.empty(n, protocol)
    seconds: dict[str, float] = defaultdict(float)
    entered: dict[str, int] = defaultdict(int)
    for first in range(0, n, protocol.batch_size):  # run_trials' batches
        rows = np.arange(first, min(first + protocol.batch_size, n))
        began = time.perf_counter()
        controls = trial.trial_controls(scene, grasps[rows], plan)
        seconds["controls"] += time.perf_counter() - began
        anchors = trial.grasp_centres(scene, grasps[rows])
        states = np.empty((len(rows), plan.nstep, start.size))
        sensors = np.empty((len(rows), plan.nstep, model.nsensordata))
        state = np.repeat(start[None], len(rows), axis=0)
        active = np.arange(len(rows))
        for name, seg in zip(V1_SEGMENTS, v1_segments(plan), strict=True):
            entered[name] += active.size
            began = time.perf_counter()
            seg_states, seg_sensors = rollout.rollout(
                model,
                data,
                state[active],
                controls[active, seg],
                control_spec=trial.CONTROL_SPEC,
                nstep=seg.stop - seg.start,
            )
            seconds[name] += time.perf_counter() - began
            states[active, seg], sensors[active, seg] = seg_states, seg_sensors
            state[active] = seg_states[:, -1]
            head = trial.Schedule(
                phase=plan.phase[: seg.stop],
                wrench=plan.wrench[: seg.stop],
                close_end=plan.close_end,
            )
            began = time.perf_counter()
            verdict = trial.analyse(
                scene,
                states[active, : seg.stop],
                sensors[active, : seg.stop],
                head,
                protocol,
                anchors[active],
            )
            seconds["analysis"] += time.perf_counter() - began
            for field in trial.TrialResults.ARRAY_FIELDS:
                getattr(results, field)[rows[active]] = getattr(verdict, field)
            active = active[verdict.status == trial.TrialStatus.SUCCESS]
            if active.size == 0:
                break
    return results, dict(seconds), dict(entered)


# --------------------------------------------------------------------------------------------
# Python-loop reference
# --------------------------------------------------------------------------------------------


def python_loop(scene: Scene, grasps: np.ndarray, protocol: trial.TrialProtocol) -> tuple:
    """Full-length trials stepped one ``mj_step`` at a time from Python, recording what
    ``mujoco.rollout`` records (state and sensors after every step), with the solver's warm start
    cleared at the first step of each segment (:func:`trial.trial_segments`), as the rollout
    does. Returns (states, sensors, seconds of the stepping loop)."""
    model = scene.model
    plan = trial.schedule(scene, protocol)
    controls = trial.trial_controls(scene, grasps, plan)
    start = trial.initial_state(scene)
    restarts = {seg.start for seg in trial.trial_segments(plan)}
    states = np.empty((len(grasps), plan.nstep, start.size))
    sensors = np.empty((len(grasps), plan.nstep, model.nsensordata))
    data = mujoco.MjData(model)
    full, spec = trial.STATE_SPEC, trial.CONTROL_SPEC
    began = time.perf_counter()
    for i in range(len(grasps)):
        mujoco.mj_resetData(model, data)
        mujoco.mj_setState(model, data, start, full)
        for t in range(plan.nstep):
            if t in restarts:
                data.qacc_warmstart[:] = 0.0
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


def ratio(a: float, b: float) -> float:
    return a / b if b and np.isfinite(b) else float("nan")


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
    protocol = params.protocol

    # v2 trial path: run_trials on the nominal grasps.
    times = PhaseTimes(scene, protocol)
    with timed_library(times):
        began = time.perf_counter()
        results = trial.run_trials(scene, grasps, protocol)
        run_trials_s = time.perf_counter() - began
    v2 = dict(times.seconds)
    valid = np.flatnonzero(results.valid)
    n_valid = int(valid.size)
    rollout_s = times.rollout_s()
    v2_path_s = run_trials_s - v2.get("check", 0.0)  # the same work as the v1 reference
    no_contact = (
        (results.status == trial.TrialStatus.FAILED)
        & (results.failing_phase == 0)
        & (results.contacts_after_close < protocol.min_contacts_after_close).any(axis=1)
    )

    # v1 reference path on the same valid nominal grasps.
    v1_s = float("nan")
    v1: dict[str, float] = {}
    v1_entered: dict[str, int] = {}
    differ = differ_contact = differ_phase = 0
    v1_success = 0
    if n_valid:
        began = time.perf_counter()
        v1_results, v1, v1_entered = v1_run_trials(scene, grasps[valid], protocol)
        v1_s = time.perf_counter() - began
        status_v2 = results.status[valid]
        other = v1_results.status != status_v2
        differ = int(other.sum())
        differ_contact = int((other & no_contact[valid]).sum())
        differ_phase = int(
            (~other & (v1_results.failing_phase != results.failing_phase[valid])).sum()
        )
        v1_success = int(v1_results.success.sum())
    v1_rollout_s = sum(v1.get(name, 0.0) for name in V1_SEGMENTS)

    # Labels: the real v2 benchmark work, K + 1 trials per pair.
    label_times = PhaseTimes(scene, protocol)
    with timed_library(label_times):
        began = time.perf_counter()
        grasp_labels = labels.success_probability(
            scene, grasps, spec=params.perturbation, protocol=protocol
        )
        labels_s = time.perf_counter() - began
    label_trials = grasp_labels.n * grasp_labels.spec.trials
    label_simulated = int(label_times.trials.get("close", 0))

    # Reference 1: the same valid trials at full length (no early exit).
    full_times = PhaseTimes(scene, protocol)
    if n_valid:
        with timed_library(full_times):
            trial.simulate(scene, grasps[valid], protocol)
    full_s = full_times.rollout_s()

    # Reference 2: a spread subsample (all arms) in a Python loop, and the same trials through
    # rollout at full length (same work, so this ratio is the engine's alone).
    sub = valid[
        np.unique(np.linspace(0, n_valid - 1, min(loop_pairs, n_valid)).round().astype(int))
    ]
    loop_s = sub_rollout_s = float("nan")
    identical = None
    if sub.size:
        loop_states, loop_sensors, loop_s = python_loop(scene, grasps[sub], protocol)
        sub_times = PhaseTimes(scene, protocol)
        with timed_library(sub_times):
            ref_states, ref_sensors, _ = trial.simulate(scene, grasps[sub], protocol)
        sub_rollout_s = sub_times.rollout_s()
        identical = bool(
            np.array_equal(loop_states, ref_states, equal_nan=True)
            and np.array_equal(loop_sensors, ref_sensors, equal_nan=True)
        )

    summary = results.summary()
    accounted = sum(v2.values())
    per_trial = max(n_valid, 1)
    v2_trials_per_s = per_s(n_valid, v2_path_s)
    v1_trials_per_s = per_s(n_valid, v1_s)
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
        "no_contact_after_close": int(no_contact.sum()),
        "load_s": load_s,
        "sampling_pairing_s": sampling_s,
        "compile_s": compile_s,
        # v2 trial path
        "run_trials_s": run_trials_s,
        "phase_s": {**v2, "other": run_trials_s - accounted},
        "group_trials": {g: int(times.trials.get(g, 0)) for g in GROUPS},
        "group_rollout_calls": {g: int(times.calls.get(g, 0)) for g in GROUPS},
        "check_ms_per_pair": 1e3 * v2.get("check", 0.0) / max(results.n, 1),
        "controls_ms_per_trial": 1e3 * v2.get("controls", 0.0) / per_trial,
        "group_ms_per_trial": {g: 1e3 * v2.get(g, 0.0) / per_trial for g in GROUPS},
        "measure_ms_per_trial": 1e3 * v2.get("measure", 0.0) / per_trial,
        "judge_ms_per_trial": 1e3 * v2.get("judge", 0.0) / per_trial,
        "rollout_s": rollout_s,
        "trials_per_s": per_s(n_valid, rollout_s),
        "rollout_ms_per_trial": 1e3 * rollout_s / per_trial,
        "end_to_end_trials_per_s": per_s(n_valid, run_trials_s),
        # v1 reference path vs v2 path (same valid trials, no validity check in either)
        "v2_path_s": v2_path_s,
        "v2_path_trials_per_s": v2_trials_per_s,
        "v1_path_s": v1_s,
        "v1_phase_s": {**v1, "other": v1_s - sum(v1.values())} if v1 else {},
        "v1_segment_trials": v1_entered,
        "v1_path_trials_per_s": v1_trials_per_s,
        "v1_rollout_trials_per_s": per_s(n_valid, v1_rollout_s),
        "v1_analysis_ms_per_trial": 1e3 * v1.get("analysis", 0.0) / per_trial,
        "v2_over_v1_path": ratio(v2_trials_per_s, v1_trials_per_s),
        "v2_over_v1_rollout": ratio(per_s(n_valid, rollout_s), per_s(n_valid, v1_rollout_s)),
        "v1_success": v1_success,
        "verdicts_differ": differ,
        "verdicts_differ_v2_no_contact": differ_contact,
        "same_status_other_failing_phase": differ_phase,
        # labels (success_probability, K + 1 trials per pair)
        "labels_s": labels_s,
        "label_pairs": grasp_labels.n,
        "label_trials": label_trials,
        "label_simulated": label_simulated,
        "label_group_trials": {g: int(label_times.trials.get(g, 0)) for g in GROUPS},
        "label_rollout_s": label_times.rollout_s(),
        "labels_pairs_per_s": per_s(grasp_labels.n, labels_s),
        "labels_trials_per_s": per_s(label_trials, labels_s),
        "labels_simulated_trials_per_s": per_s(label_simulated, labels_s),
        "label_rate": float(grasp_labels.label().mean()) if grasp_labels.n else float("nan"),
        "object_build_s": sampling_s + labels_s,
        # references
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


def fmt(value: float | None, digits: int = 1) -> str:
    return "-" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def markdown(head: list[str], body: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    return lines + ["| " + " | ".join(cells) + " |" for cells in body]


def phase_table(rows: list[dict[str, Any]]) -> str:
    """The v2 trial path (run_trials on the nominal grasps), phase by phase."""
    head = [
        "object",
        "parts",
        "trials (valid)",
        "success",
        "no contact",
        "compile s",
        "check ms/pair",
        "controls ms/trial",
        "rollout close / gravity / forces / torques ms/trial",
        "trials entering close / gravity / forces / torques",
        "measure + judge ms/trial",
        "trials/s (rollout)",
        "run_trials trials/s",
    ]
    body = []
    for r in rows:
        group = r["group_ms_per_trial"]
        body.append(
            [
                r["object"],
                str(r["parts"]),
                f"{r['pairs']} ({r['valid']})",
                str(r["success"]),
                str(r["no_contact_after_close"]),
                f"{r['compile_s']:.2f}",
                fmt(r["check_ms_per_pair"], 2),
                fmt(r["controls_ms_per_trial"], 2),
                " / ".join(fmt(group[g]) for g in GROUPS),
                " / ".join(str(r["group_trials"][g]) for g in GROUPS),
                f"{fmt(r['measure_ms_per_trial'], 2)} + {fmt(r['judge_ms_per_trial'], 2)}",
                fmt(r["trials_per_s"]),
                fmt(r["end_to_end_trials_per_s"]),
            ]
        )
    return "\n".join(markdown(head, body))


def comparison_table(rows: list[dict[str, Any]]) -> str:
    """v1 vs v2 path, labels, full-length and Python-loop references."""
    head = [
        "object",
        "v1 path trials/s",
        "v2 path trials/s",
        "v2/v1",
        "rollout v1 / v2 trials/s",
        "success v1 / v2",
        "verdicts differ (v2 no contact)",
        "labels pairs/s",
        "labels trials/s",
        "sampling+pairing s",
        "labels s",
        "full length trials/s",
        "python loop trials/s",
        "ratio same work",
        "loop == rollout",
    ]
    body = []
    for r in rows:
        rollout_v1, rollout_v2 = r["v1_rollout_trials_per_s"], r["trials_per_s"]
        loop = r["loop_trials_per_s"]
        body.append(
            [
                r["object"],
                fmt(r["v1_path_trials_per_s"]),
                fmt(r["v2_path_trials_per_s"]),
                f"{fmt(r['v2_over_v1_path'], 2)}x",
                f"{fmt(rollout_v1)} / {fmt(rollout_v2)}",
                f"{r['v1_success']} / {r['success']}",
                f"{r['verdicts_differ']} ({r['verdicts_differ_v2_no_contact']})",
                fmt(r["labels_pairs_per_s"]),
                fmt(r["labels_trials_per_s"]),
                f"{r['sampling_pairing_s']:.2f}",
                f"{r['labels_s']:.2f}",
                fmt(r["full_length_trials_per_s"]),
                fmt(loop),
                f"{fmt(ratio(r['same_pairs_rollout_trials_per_s'], loop), 2)}x",
                str(r["loop_bit_identical_to_rollout"]),
            ]
        )
    return "\n".join(markdown(head, body))


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
        f"{params.n_grasps} grasps sampled per object, {params.perturbation.trials} trials per "
        f"pair (nominal + {params.perturbation.n_perturbations} perturbed), protocol "
        f"min_contacts_after_close={params.protocol.min_contacts_after_close}"
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
            f"{row['run_trials_s']:.2f} s (unaccounted {row['phase_s']['other']:.2f} s), v1 path "
            f"{row['v1_path_s']:.2f} s (v1 trials entering {row['v1_segment_trials']}), "
            f"success_probability {row['labels_s']:.2f} s ({row['label_pairs']} pairs, "
            f"{row['label_trials']} trials, {row['label_simulated']} simulated), "
            f"loop == rollout bit for bit: {row['loop_bit_identical_to_rollout']}",
            flush=True,
        )

    report(rows, args, mesh_note)


def report(rows: list[dict[str, Any]], args: Arguments, mesh_note: str | None) -> None:
    """Print the tables, the medians and the projection; write ``--json`` when asked."""
    print()
    print("v2 trial path (run_trials on the nominal grasps):")
    print()
    print(phase_table(rows))
    print()
    print("v1 vs v2 path, labels and references:")
    print()
    print(comparison_table(rows))
    print()
    print(
        "Phase table: check = ms per checked pair (invalid ones included); controls, rollout per "
        "phase group, measure + judge = ms per simulated (valid) nominal trial; close and gravity "
        "are one rollout call each, forces and torques six each; trials entering a group = "
        "trials rolled out in its first phase; no contact = failed at the end of close with a "
        "hand touching nothing (v2 only). trials/s (rollout) = valid trials / seconds inside "
        "mujoco.rollout; run_trials trials/s = valid trials / whole run_trials seconds."
    )
    print(
        "Comparison table: v1 path = the previous runner (three segments close+gravity | forces "
        "| torques, trial.analyse re-judging the trajectory so far after each, no contact "
        "requirement) and v2 path = run_trials less its validity check, both on the same valid "
        "nominal grasps: trials/s = valid trials / seconds of the path (controls, rollout, "
        "judging). Verdicts differ = statuses that differ (the contact requirement, and the solver "
        "warm start restarted at other steps, change trajectories after chaotic contact); in "
        "brackets those where v2 failed for lack of contact. labels = success_probability on "
        "all pairs (K + 1 trials each, invalid ones included in trials/s). full length = "
        "trial.simulate on the valid trials (14 segments, no early exit). python loop: "
        f"full-length trials on a spread subsample of {args.loop_pairs} valid pairs; ratio same "
        "work = rollout at full length on the same subsample / loop; loop == rollout: states and "
        "sensors bit for bit (qacc_warmstart cleared at each segment start)."
    )
    if mesh_note:
        print(mesh_note)
    procedural = [r for r in rows if r["kind"] == "procedural"]
    if not procedural:
        return

    def median(key: str) -> float:
        return float(np.nanmedian([r[key] for r in procedural]))

    medians = {
        key: median(key)
        for key in (
            "trials_per_s",
            "end_to_end_trials_per_s",
            "full_length_trials_per_s",
            "loop_trials_per_s",
            "v1_path_trials_per_s",
            "v2_path_trials_per_s",
            "v2_over_v1_path",
            "labels_pairs_per_s",
            "labels_trials_per_s",
            "sampling_pairing_s",
            "labels_s",
            "object_build_s",
        )
    }
    verdict = "meets" if medians["trials_per_s"] >= TARGET_TRIALS_PER_S else "misses"
    print(
        f"procedural median: {medians['trials_per_s']:.1f} trials/s per core (v2 rollout, early "
        f"exit) -> {verdict} the target of {TARGET_TRIALS_PER_S:.0f}; whole run_trials "
        f"{medians['end_to_end_trials_per_s']:.1f} trials/s; full length "
        f"{medians['full_length_trials_per_s']:.1f} trials/s (early exit gain "
        f"{medians['trials_per_s'] / medians['full_length_trials_per_s']:.2f}x); python loop "
        f"{medians['loop_trials_per_s']:.1f} trials/s"
    )
    differ = sum(r["verdicts_differ"] for r in procedural)
    compared = sum(r["valid"] for r in procedural)
    print(
        f"v1 path {medians['v1_path_trials_per_s']:.1f} vs v2 path "
        f"{medians['v2_path_trials_per_s']:.1f} trials/s per core (median ratio v2/v1 "
        f"{medians['v2_over_v1_path']:.2f}x); verdicts differ on {differ} of {compared} valid "
        f"nominal trials ({sum(r['verdicts_differ_v2_no_contact'] for r in procedural)} of them "
        "v2 failures for lack of contact)"
    )
    print(
        f"labels (success_probability): median {medians['labels_pairs_per_s']:.2f} pairs/s = "
        f"{medians['labels_trials_per_s']:.1f} trials/s per core"
    )
    n, cores = args.benchmark_objects, args.cores
    per_object = medians["object_build_s"]
    projected = n * per_object / cores
    load_compile = float(np.median([r["load_s"] + r["compile_s"] for r in procedural]))
    with_load = n * (per_object + load_compile) / cores
    target = "within" if projected <= TARGET_BUILD_S else "over"
    print(
        f"projection (v2 rebuild): {n} objects x {per_object:.2f} s median per object "
        f"({medians['sampling_pairing_s']:.2f} s sampling+pairing + {medians['labels_s']:.2f} s "
        f"success_probability) / {cores} cores = {projected:.0f} s ({projected / 60:.1f} min) -> "
        f"{target} the {TARGET_BUILD_S / 60:.0f}-minute target "
        f"({projected / TARGET_BUILD_S:.2f}x of it); with load and compile "
        f"(+{load_compile:.2f} s per object): {with_load:.0f} s ({with_load / 60:.1f} min)"
    )
    if args.json:
        from dg16m_core.atomic import write_json_atomic

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
                    "medians": medians,
                    "median_trials_per_s": medians["trials_per_s"],
                    "target_trials_per_s": TARGET_TRIALS_PER_S,
                    "projected_seconds": projected,
                    "projected_seconds_with_load_compile": with_load,
                    "target_build_seconds": TARGET_BUILD_S,
                    "mesh_note": mesh_note,
                }
            ),
        )


if __name__ == "__main__":
    main()
