"""The trial protocol on MuJoCo Warp: one object's trials stepped together as Warp worlds.

Same scene, same protocol, same judge as the C path (:mod:`dg16m_env.physics.trial_protocol`, run by
:func:`dg16m_env.physics.trial.run_trials`, which picks this engine for ``simulator="warp"``; this module
imports the protocol, never the module that chooses the engine); only the stepping moves to
MuJoCo Warp (optional extra ``warp``; :class:`~dg16m_env.physics.simulator.Simulator`):

* The compiled :class:`~dg16m_env.physics.scene.Scene` model goes to the device once per object
  (``mujoco_warp.put_model``); a batch of up to :attr:`Simulator.worlds` trials becomes one
  ``Data`` with one world per trial. Each world's squeeze controls and hand (mocap) poses are set
  once; the object's wrench schedule (the same for every trial of an object) lives on the device
  and a kernel writes step ``t``'s wrench before each step.
* Phases run as in ``dg16m_env.physics.trial._run_batch``: one segment per phase
  (:func:`~dg16m_env.physics.trial_protocol.trial_segments`), every segment starting from the previous
  one's last state with the solver's warm start cleared (as each ``mujoco.rollout`` call does on
  the CPU).
* **Measured on the device**: after each step a kernel (``warp_kernels.measure``) computes what
  the judge needs (:data:`MEASURES`: time, slip at the hands' grasp centres, rotation, a
  finiteness flag, the object's speed, the deepest contact, each hand's contact count), the
  float32 twin of :func:`~dg16m_env.physics.trial_measures.measure_steps`; the host reads eight numbers
  per world and step instead of whole states, turns them into
  :class:`~dg16m_env.physics.trial_measures.StepMeasures` with the same
  :func:`~dg16m_env.physics.trial_measures.step_measures` and judges them with the same
  :func:`~dg16m_env.physics.trial_measures.out_steps` and :func:`~dg16m_env.physics.trial_measures.judge`.
  (Measuring whole trajectories on the host runs at about 650 trials/s on one core: it would cap
  a GPU.)
* **Early exit**: a trial that left the protocol in a phase is not run further. When the
  trials still running fill at most :data:`COMPACT_BELOW` of the worlds, they move to a smaller
  ``Data`` (their state copied from the host); otherwise the decided worlds keep stepping and are
  ignored (re-allocating would cost more than it saves).
* **Overflow**: a world whose contacts or constraint rows overflow the allocation (``nconmax``,
  ``njmax``), or whose broadphase, narrowphase, EPA or contact-sensor buffers overflow, has
  wrong physics: every step of that phase is marked non-finite, so the judge calls the trial
  ``UNSTABLE`` in that phase (a failure, counted, never dropped). :attr:`WarpRunner.overflowed` counts
  them. Hitting the solver's iteration limit is not an overflow (C MuJoCo stops there too).
* On CUDA each step (wrench, ``mujoco_warp.step``, measures) is captured once per ``Data`` as a
  CUDA graph and replayed (:attr:`Simulator.graph`).

Precision: MuJoCo Warp computes in float32 (C MuJoCo: float64) and raises the solver tolerance to
at least 1e-6, so trajectories differ from the CPU path's from the first step, and a trial on the
edge of the bounds can get the other verdict. On a GPU, atomic sums make results vary from run to
run unless :attr:`Simulator.deterministic` is set. BENCHMARKS.md has the measured agreement.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from dg16m_env.physics.scene import Scene
from dg16m_env.physics.simulator import Simulator, SimulatorError, import_warp
from dg16m_env.physics.trial_measures import (
    StepMeasures,
    body_points,
    grasp_centres,
    judge,
    object_states,
    out_steps,
    sensor_slices,
    step_measures,
)
from dg16m_env.physics.trial_protocol import (
    CONTROL_SPEC,
    STATE_SPEC,
    Schedule,
    TrialProtocol,
    TrialResults,
    initial_state,
    trial_control_vectors,
    trial_segments,
)

log = logging.getLogger(__name__)

MEASURES = ("time", "displacement", "rotation", "finite", "speed", "depth", "hand0", "hand1")
"""What the device measures after every step, per world (``warp_kernels.measure``): the inputs
of :func:`dg16m_env.physics.trial_measures.step_measures`."""
MEASURE_COLUMN = {name: k for k, name in enumerate(MEASURES)}
_IDENTITY_WXYZ = np.array([1.0, 0.0, 0.0, 0.0])

COMPACT_BELOW = 0.75
"""Move the running trials to a smaller ``Data`` when they fill at most this share of it."""

RECORDED_SPEC = (
    mujoco.mjtState.mjSTATE_TIME
    | mujoco.mjtState.mjSTATE_QPOS
    | mujoco.mjtState.mjSTATE_QVEL
    | mujoco.mjtState.mjSTATE_ACT
)
"""What changes during a trial: ``[time, qpos, qvel, act]``, the leading columns of a full
physics state (the rest, the hands' mocap poses and the equality flags, stays constant)."""


@dataclass
class _Worlds:
    """One ``Data`` of ``n`` worlds, its per-world inputs and measures, and (on CUDA) the
    captured graph of one step."""

    data: Any
    trial: np.ndarray  # (n,) the batch row each world simulates
    measures: Any  # (max segment steps, n, len(MEASURES)) float32
    anchors: Any  # (n, K) vec3: the hands' grasp centres (world frame at the reference pose)
    body_points: Any  # (n, K) vec3: the same points in the object frame of the reference pose
    reference: Any  # (n,) quat (x, y, z, w): the reference orientation
    last: Any  # (n, P) float32: [time, qpos, qvel, act] after the segment's last step
    counter: Any  # (2,) int: [step within the segment, first step of the segment]
    graph: Any = None

    @property
    def n(self) -> int:
        return int(self.trial.size)


class WarpRunner:
    """One object's scene on a Warp device; runs batches of trials (:meth:`run_batch`).

    Args:
        scene: the object's compiled scene.
        plan: the trial's schedule (its wrench goes to the device once).
        simulator: a ``"warp"`` :class:`Simulator`.

    Attributes:
        overflowed: how many trials a buffer overflow made ``UNSTABLE`` so far (see the module
            docstring).

    Raises:
        SimulatorError: the optional extra is missing or the device does not exist.
    """

    def __init__(self, scene: Scene, plan: Schedule, simulator: Simulator) -> None:
        self.mjw, self.wp = import_warp()
        from dg16m_env.physics import warp_kernels

        self.kernels = warp_kernels
        self.scene, self.plan, self.simulator = scene, plan, simulator
        try:
            self.device = self.wp.get_device(simulator.warp_device)
        except (RuntimeError, ValueError) as exc:
            raise SimulatorError(
                f"device: expected a Warp device that exists here, found "
                f"{simulator.warp_device!r} ({exc})"
            ) from None
        model = scene.model
        self.recorded = mujoco.mj_stateSize(model, RECORDED_SPEC)
        if self.recorded != 1 + model.nq + model.nv + model.na:
            raise AssertionError("unexpected MuJoCo state layout: [time, qpos, qvel, act] first")
        count_at, dist_at, hand_at = sensor_slices(scene)
        self.sensor_adr = self.wp.vec4i(count_at, dist_at, int(hand_at[0]), int(hand_at[1]))
        self.max_steps = max(s.stop - s.start for s in trial_segments(plan))
        self.overflowed = 0
        types = self.mjw.OverflowType
        self.overflow_mask = int(types.ALL) & ~int(types.ITERATIONS) & ~int(types.LS_ITERATIONS)
        with self.wp.ScopedDevice(self.device):
            self.model = self.mjw.put_model(model)
            self.model.opt.deterministic = (
                int(self.mjw.DeterminismType.ALL)
                if simulator.deterministic
                else int(self.mjw.DeterminismType.NONE)
            )
            self.model.opt.warn_overflow = 0  # counted and reported here instead
            self.wrench = self.wp.array(plan.wrench.astype(np.float32), dtype=float)
        self.host_data = mujoco.MjData(model)
        mujoco.mj_resetData(model, self.host_data)

    # ------------------------------------------------------------------------------------

    def _worlds(self, trial: np.ndarray, controls: np.ndarray, anchors: np.ndarray) -> _Worlds:
        """A fresh ``Data`` with one world per batch row in ``trial``: its controls ((n, C):
        squeeze and hand poses) set once, its anchors ((n, K, 3)) on the device."""
        wp, mjw = self.wp, self.mjw
        n, k = len(trial), anchors.shape[1]
        sim = self.simulator
        with wp.ScopedDevice(self.device):
            data = mjw.put_data(
                self.scene.model, self.host_data, nworld=n, nconmax=sim.nconmax, njmax=sim.njmax
            )
            mjw.set_state(
                self.model,
                data,
                wp.array(controls[trial].astype(np.float32), dtype=float),
                int(CONTROL_SPEC),
            )
            worlds = _Worlds(
                data=data,
                trial=trial,
                measures=wp.zeros((self.max_steps, n, len(MEASURES)), dtype=float),
                anchors=wp.array(anchors[trial].astype(np.float32), dtype=wp.vec3),
                body_points=wp.zeros((n, k), dtype=wp.vec3),
                reference=wp.zeros(n, dtype=wp.quat),
                last=wp.zeros((n, self.recorded), dtype=float),
                counter=wp.zeros(2, dtype=int),
            )
            if sim.graph and self.device.is_cuda:
                self._step(worlds)  # compile every kernel before the capture
                try:
                    with wp.ScopedCapture() as capture:
                        self._step(worlds)
                    worlds.graph = capture.graph
                except RuntimeError as exc:  # Warp's capture errors; the steps still run
                    log.warning(
                        "%s: CUDA graph capture failed (%s); stepping without graphs "
                        "(Simulator(graph=False) skips the attempt)",
                        self.scene.object_id,
                        exc,
                    )
        return worlds

    def _step(self, worlds: _Worlds) -> None:
        wp, k, d = self.wp, self.kernels, worlds.data
        wp.launch(
            k.set_wrench,
            dim=worlds.n,
            inputs=[self.wrench, worlds.counter, int(self.scene.object_body)],
            outputs=[d.xfrc_applied],
        )
        self.mjw.step(self.model, d)
        wp.launch(
            k.measure,
            dim=worlds.n,
            inputs=[
                worlds.counter,
                d.time,
                d.qpos,
                d.qvel,
                d.act,
                d.sensordata,
                int(self.scene.object_qpos.start),
                int(self.scene.object_qvel.start),
                self.sensor_adr,
                worlds.anchors,
                worlds.body_points,
                worlds.reference,
            ],
            outputs=[worlds.measures],
        )
        wp.launch(k.advance, dim=1, inputs=[], outputs=[worlds.counter])

    def _segment(
        self,
        worlds: _Worlds,
        start: np.ndarray,
        reference: np.ndarray | None,
        anchors: np.ndarray,
        seg: slice,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Run ``seg`` on every world from ``start`` ((n, S) full physics states), motion
        measured from ``reference`` ((n, S) states; ``None``: the initial pose) at ``anchors``
        ((n, K, 3), world frame).

        Returns:
            measures: (n, W, len(MEASURES)) float64 per step (an overflowed world's steps are
                non-finite).
            last: (n, P) ``[time, qpos, qvel, act]`` after the last step.
        """
        wp, mjw = self.wp, self.mjw
        nstep = seg.stop - seg.start
        if reference is None:
            points = body_points(anchors)
            ref_quat = np.tile(_IDENTITY_WXYZ, (len(start), 1))
        else:
            ref_pos, ref_quat, _ = object_states(self.scene, reference)
            points = body_points(anchors, ref_pos, ref_quat)
        with wp.ScopedDevice(self.device):
            d = worlds.data
            mjw.set_state(
                self.model, d, wp.array(start.astype(np.float32), dtype=float), int(STATE_SPEC)
            )
            d.qacc_warmstart.zero_()  # each segment starts the solver cold, as on the CPU
            d.overflow.zero_()
            worlds.body_points.assign(points.astype(np.float32))
            worlds.reference.assign(ref_quat[:, [1, 2, 3, 0]].astype(np.float32))  # x y z w
            worlds.counter.assign(np.array([0, seg.start], dtype=np.int32))
            for _ in range(nstep):
                if worlds.graph is not None:
                    wp.capture_launch(worlds.graph)
                else:
                    self._step(worlds)
            mjw.get_state(self.model, d, worlds.last, int(RECORDED_SPEC))
            measures = worlds.measures.numpy()[:nstep].transpose(1, 0, 2).astype(np.float64)
            last = worlds.last.numpy().astype(np.float64)
            overflow = (d.overflow.numpy() & self.overflow_mask) != 0
        if overflow.any():
            self.overflowed += int(overflow.sum())
            log.warning(
                "%s: %d world(s) overflowed MuJoCo Warp's buffers in steps %d-%d; their trials "
                "count as UNSTABLE (raise nconmax=%d / njmax=%d)",
                self.scene.object_id,
                int(overflow.sum()),
                seg.start,
                seg.stop - 1,
                self.simulator.nconmax,
                self.simulator.njmax,
            )
            measures[overflow, :, MEASURE_COLUMN["finite"]] = 0.0
            last[overflow] = np.nan
        return measures, last

    # ------------------------------------------------------------------------------------

    def run_batch(
        self, grasps: np.ndarray, protocol: TrialProtocol, early_exit: bool = True
    ) -> TrialResults:
        """Roll out and judge one batch of valid trials (at most :attr:`Simulator.worlds`), phase
        by phase, exactly as ``dg16m_env.physics.trial._run_batch`` does on the CPU."""
        scene, plan = self.scene, self.plan
        n = len(grasps)
        controls = trial_control_vectors(scene, grasps)
        anchors = grasp_centres(scene, grasps)
        state0 = initial_state(scene)
        state = np.repeat(state0[None], n, axis=0)
        reference = None
        measures = StepMeasures.empty(n, plan.nstep)
        active = np.arange(n)
        worlds = self._worlds(active, controls, anchors)
        world_of = np.arange(n)  # the world simulating each active trial
        p = self.recorded
        column = MEASURE_COLUMN
        for seg in trial_segments(plan):
            if active.size <= COMPACT_BELOW * worlds.n:
                worlds = self._worlds(active, controls, anchors)
                world_of = np.arange(active.size)
            rows = worlds.trial
            start = state[rows]
            idle = np.ones(worlds.n, dtype=bool)
            idle[world_of] = False
            start[idle] = state0  # decided trials restart from rest, never from a broken state
            seg_all, last = self._segment(
                worlds,
                start,
                None if reference is None else reference[rows],
                anchors[rows],
                seg,
            )
            seg_values = seg_all[world_of]
            state[active, :p] = last[world_of]
            seg_measures = step_measures(
                scene,
                seg.start,
                protocol,
                time=seg_values[:, :, column["time"]],
                displacement=seg_values[:, :, column["displacement"]],
                rotation=seg_values[:, :, column["rotation"]],
                finite=seg_values[:, :, column["finite"]] > 0.5,
                speed=seg_values[:, :, column["speed"]],
                depth=seg_values[:, :, column["depth"]],
                hand_contacts=seg_values[:, :, [column["hand0"], column["hand1"]]],
            )
            measures.store(active, seg, seg_measures)
            if seg.stop == plan.close_end:
                reference = state.copy()
            if early_exit:
                keep = ~out_steps(seg_measures, seg.start, plan, protocol).any(axis=1)
                active, world_of = active[keep], world_of[keep]
                if active.size == 0:
                    break
        return judge(measures, plan, protocol)
