"""Running the dual-grasp trial protocol: :func:`run_trials` picks the engine.

The protocol itself (phases, validity check, schedule, measures, judge) is defined once, in
:mod:`dg16m_env.physics.trial_protocol`, for every engine. This module runs it: :func:`run_trials` checks
the grasps' validity (always in C MuJoCo), then steps the valid trials on the engine its
``simulator`` names and judges them with the protocol's judge:

* **C MuJoCo** (default): every trial of one object shares one compiled model; trials run in
  batches of :attr:`TrialProtocol.batch_size` through ``mujoco.rollout`` (single thread per
  process), one rollout call per phase (:func:`trial_segments`): a trial that failed in a phase
  is not simulated further, since its verdict at both levels of the benchmark (held under
  gravity, held through everything) is then certain. Each rollout call starts the solver without
  a warm start; :func:`simulate` and the step-by-step replay restart it at the same steps, so
  they reproduce ``run_trials`` bit for bit. On one machine results are bit-for-bit reproducible
  (any batch size, worker count or backend); on another CPU MuJoCo's floating-point results can
  differ in the last bits, and after contact chaos by more (see BENCHMARKS.md).
* **MuJoCo Warp** (``simulator="warp"``, optional extra): one object's trials as Warp worlds on a
  GPU (:class:`dg16m_env.physics.warp_trials.WarpRunner`): the same validity check, schedule, segments,
  :func:`step_measures`, :func:`out_steps` and :func:`judge`, in float32.

Imports point one way: ``trial_protocol <- warp_trials <- trial`` (and ``trial_protocol <-
trial``); the engine choice sits above both engines and neither engine imports it. Every name of
:mod:`dg16m_env.physics.trial_protocol` is re-exported here, so ``from dg16m_env.physics.trial import judge``
keeps working, and the C path looks its helpers up in this module (``bench/sim_throughput.py``
wraps them with timers here).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

import mujoco
import numpy as np
from mujoco import rollout

from dg16m_env.physics.scene import Scene
from dg16m_env.physics.simulator import Simulator, check_simulator
from dg16m_env.physics.trial_measures import (
    StepMeasures,
    analyse,
    body_points,
    grasp_centres,
    judge,
    measure_steps,
    motion_from,
    object_motion,
    object_states,
    out_steps,
    rotation_deg,
    sensor_slices,
    step_measures,
)
from dg16m_env.physics.trial_protocol import (
    CONTROL_SPEC,
    DIRECTIONS,
    HAND_PARTS,
    PHASES,
    STATE_SPEC,
    InvalidReason,
    Schedule,
    TrialError,
    TrialProtocol,
    TrialResults,
    TrialStatus,
    check_dual_grasps,
    check_initial_poses,
    initial_state,
    open_hand_penetration,
    schedule,
    simulate,
    trial_control_vectors,
    trial_controls,
    trial_segments,
)
from dg16m_env.physics.warp_trials import WarpRunner


def _batches(indices: np.ndarray, size: int) -> Iterator[np.ndarray]:
    for start in range(0, len(indices), size):
        yield indices[start : start + size]


def run_trials(
    scene: Scene,
    grasps: np.ndarray | Sequence[np.ndarray],
    protocol: TrialProtocol | None = None,
    *,
    progress: bool = False,
    early_exit: bool = True,
    simulator: Simulator | str | None = None,
) -> TrialResults:
    """Run the trial protocol on N dual grasps of one object.

    Args:
        scene: the object's compiled scene (:func:`dg16m_env.physics.scene.compile_scene`).
        grasps: (N, 2, 4, 4) hand poses, gripper frame -> object frame (m).
        protocol: timing, loads and thresholds.
        progress: show a progress bar over batches.
        early_exit: stop simulating a trial at the end of the phase where it failed (its verdict
            is then certain; ``False`` runs every trial to the end, for checking that claim).
        simulator: the physics engine (:class:`~dg16m_env.physics.simulator.Simulator` or its name;
            default C MuJoCo). With ``"warp"`` batches hold up to ``simulator.worlds`` trials
            (:mod:`dg16m_env.physics.warp_trials`); the validity check always runs in C MuJoCo.

    Returns:
        :class:`TrialResults` in the order of ``grasps``.

    Raises:
        TrialError: malformed grasps.
        SimulatorError: ``"warp"`` without its optional extra or device.
    """
    protocol = protocol or TrialProtocol()
    simulator = check_simulator(simulator)
    grasps = check_dual_grasps(grasps)
    n = len(grasps)
    results = TrialResults.empty(n, protocol)
    reason, open_penetration = check_initial_poses(scene, grasps, protocol)
    results.invalid_reason[:] = reason
    results.max_penetration[:] = open_penetration
    runnable = np.flatnonzero(reason == InvalidReason.NONE)
    if runnable.size == 0:
        return results
    plan = schedule(scene, protocol)
    if simulator.is_default:
        data = mujoco.MjData(scene.model)
        size = protocol.batch_size

        def run_batch(poses: np.ndarray) -> TrialResults:
            return _run_batch(scene, poses, plan, protocol, data, early_exit)
    else:
        runner = WarpRunner(scene, plan, simulator)
        size = simulator.worlds

        def run_batch(poses: np.ndarray) -> TrialResults:
            return runner.run_batch(poses, protocol, early_exit)

    batches = list(_batches(runnable, size))
    iterator: Any = batches
    if progress:
        from dg16m_core.progress import progress_bar

        iterator = progress_bar(batches, unit="batch", desc=f"trials {scene.object_id}")
    for rows in iterator:
        batch = run_batch(grasps[rows])
        for name in TrialResults.ARRAY_FIELDS:
            if name != "invalid_reason":
                getattr(results, name)[rows] = getattr(batch, name)
    return results


def _run_batch(
    scene: Scene,
    grasps: np.ndarray,
    plan: Schedule,
    protocol: TrialProtocol,
    data: mujoco.MjData,
    early_exit: bool = True,
) -> TrialResults:
    """Roll out and judge one batch of valid trials, phase by phase (:func:`trial_segments`);
    a trial that left the protocol in a phase is not run further (its verdict is certain).
    Each phase is measured once, as it is rolled out, and the judge reads those measures."""
    controls = trial_controls(scene, grasps, plan)
    anchors = grasp_centres(scene, grasps)
    n = len(grasps)
    state = np.repeat(initial_state(scene)[None], n, axis=0)
    reference = None  # the state at the end of close, once it is simulated
    measures = StepMeasures.empty(n, plan.nstep)
    active = np.arange(n)
    for seg in trial_segments(plan):
        seg_states, seg_sensors = rollout.rollout(
            scene.model,
            data,
            state[active],
            controls[active, seg],
            control_spec=CONTROL_SPEC,
            nstep=seg.stop - seg.start,
        )
        state[active] = seg_states[:, -1]
        ref = None if reference is None else reference[active]
        seg_measures = measure_steps(
            scene, seg_states, seg_sensors, seg.start, protocol, anchors[active], ref
        )
        measures.store(active, seg, seg_measures)
        if seg.stop == plan.close_end:
            reference = state.copy()
        if early_exit:
            left = out_steps(seg_measures, seg.start, plan, protocol).any(axis=1)
            active = active[~left]
            if active.size == 0:
                break
    return judge(measures, plan, protocol)


__all__ = [
    "CONTROL_SPEC",
    "DIRECTIONS",
    "HAND_PARTS",
    "PHASES",
    "STATE_SPEC",
    "InvalidReason",
    "Schedule",
    "StepMeasures",
    "TrialError",
    "TrialProtocol",
    "TrialResults",
    "TrialStatus",
    "analyse",
    "body_points",
    "check_dual_grasps",
    "check_initial_poses",
    "grasp_centres",
    "initial_state",
    "judge",
    "measure_steps",
    "motion_from",
    "object_motion",
    "object_states",
    "open_hand_penetration",
    "out_steps",
    "rotation_deg",
    "run_trials",
    "schedule",
    "sensor_slices",
    "simulate",
    "step_measures",
    "trial_control_vectors",
    "trial_controls",
    "trial_segments",
]
