"""What a trial measures and how it is judged, for every engine: the object's motion relative to
the hands (:func:`object_motion`, :func:`rotation_deg`, :func:`grasp_centres`), the per-step
measures of C MuJoCo states (:func:`measure_steps`) or of numbers an engine measured
(:func:`step_measures`), the steps out of bounds (:func:`out_steps`) and the verdict
(:func:`judge`, :func:`analyse`). The protocol they judge is
:mod:`dg16m_env.physics.trial_protocol`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import mujoco
import numpy as np

from dg16m_env.physics.scene import HAND_NAMES, OBJECT_CONTACTS_SENSOR, Scene, quat_to_matrix
from dg16m_env.physics.trial_protocol import (
    PHASES,
    Schedule,
    TrialProtocol,
    TrialResults,
    TrialStatus,
)

__all__ = [
    "StepMeasures",
    "analyse",
    "body_points",
    "grasp_centres",
    "judge",
    "measure_steps",
    "motion_from",
    "object_motion",
    "object_states",
    "out_steps",
    "rotation_deg",
    "sensor_slices",
    "step_measures",
]


# --------------------------------------------------------------------------------------------
# Analysis
# --------------------------------------------------------------------------------------------


def rotation_deg(quat: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Angle (degrees) between unit quaternions ``quat`` (..., 4) and ``ref`` (..., 4)."""
    dot = np.abs(np.sum(quat * ref, axis=-1) / np.linalg.norm(quat, axis=-1))
    return np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))


_IDENTITY_QUAT = np.array([1.0, 0.0, 0.0, 0.0])


def body_points(
    anchors: np.ndarray, ref_pos: np.ndarray | None = None, ref_quat: np.ndarray | None = None
) -> np.ndarray:
    """(N, K, 3) the material points whose slip is measured, in the object frame: the anchors
    (N, K, 3; world, where the points sat at the reference pose ``ref_pos`` (N, 3), ``ref_quat``
    (N, 4)) carried into the object frame; the anchors themselves when the reference is the
    initial pose (``None``: the origin, identity)."""
    if ref_pos is None or ref_quat is None:
        return anchors
    return np.einsum("nji,nkj->nki", quat_to_matrix(ref_quat), anchors - ref_pos[:, None])


def motion_from(
    pos: np.ndarray,
    quat: np.ndarray,
    anchors: np.ndarray,
    ref_pos: np.ndarray | None = None,
    ref_quat: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Slip at the anchors and rotation of the object, measured from a reference pose.

    Args:
        pos: (N, T, 3) object positions, world = initial object frame (m).
        quat: (N, T, 4) object orientations (w, x, y, z).
        anchors: (N, K, 3) world points where slip is measured: slip is the displacement of the
            material point that sat at an anchor when the object was at the reference pose.
        ref_pos: (N, 3) reference position (default: the origin).
        ref_quat: (N, 4) reference orientation (default: identity).

    Returns:
        displacement: (N, T) the largest slip over the K anchors (m).
        rotation: (N, T) rotation from the reference orientation (degrees).
    """
    rot = quat_to_matrix(quat)  # (N, T, 3, 3)
    if ref_pos is None or ref_quat is None:
        rotation = rotation_deg(quat, _IDENTITY_QUAT)
    else:
        rotation = rotation_deg(quat, ref_quat[:, None])
    points = np.einsum("ntij,nkj->ntki", rot, body_points(anchors, ref_pos, ref_quat))
    points = points + pos[:, :, None]
    moved = points - anchors[:, None]
    return np.linalg.norm(moved, axis=-1).max(axis=-1), rotation


def object_motion(
    pos: np.ndarray, quat: np.ndarray, anchors: np.ndarray, close: int
) -> tuple[np.ndarray, np.ndarray]:
    """The protocol's measure of motion: slip at the anchors and rotation of the object.

    The first ``close`` states belong to the *close* phase and are measured from the object's
    initial pose (at the origin, identity orientation); later states from its pose in state
    ``close - 1`` (the end of *close*), i.e. relative to where the hands hold it
    (:func:`motion_from` with each reference).

    Args:
        pos: (N, T, 3) object positions, world = initial object frame (m).
        quat: (N, T, 4) object orientations (w, x, y, z).
        anchors: (N, K, 3) world points where slip is measured (the hands' grasp centres,
            :func:`grasp_centres`).
        close: number of leading states in the *close* phase (>= 1).

    Returns:
        displacement: (N, T) the largest slip over the K anchors (m).
        rotation: (N, T) rotation (degrees).
    """
    slip, rotation = motion_from(pos[:, :close], quat[:, :close], anchors)
    if pos.shape[1] <= close:
        return slip, rotation
    later = motion_from(
        pos[:, close:], quat[:, close:], anchors, pos[:, close - 1], quat[:, close - 1]
    )
    return np.concatenate([slip, later[0]], axis=1), np.concatenate([rotation, later[1]], axis=1)


def grasp_centres(scene: Scene, grasps: np.ndarray) -> np.ndarray:
    """(N, 2, 3) each hand's grasp centre (between the pads at ``contact_depth``, m) in the
    object frame: the points where slip relative to the hands is measured."""
    depth = scene.gripper.contact_depth
    return grasps[:, :, :3, 3] + depth * grasps[:, :, :3, 1]


def sensor_slices(scene: Scene) -> tuple[int, int, np.ndarray]:
    """Addresses in ``sensordata`` of the object's contact count, its deepest contact distance,
    and (2,) the contact count with each hand."""
    model = scene.model
    sensor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, OBJECT_CONTACTS_SENSOR)
    start = int(model.sensor_adr[sensor])
    hands = np.array(
        [
            model.sensor_adr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, f"{h}_contacts")]
            for h in HAND_NAMES
        ]
    )
    return start, start + 1, hands


def object_states(scene: Scene, states: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position (..., 3), orientation (..., 4) and linear velocity (..., 3) of the object in
    full physics states (..., S) (``[time, qpos, qvel, ...]``; addresses from the model)."""
    q0 = 1 + scene.object_qpos.start
    v0 = 1 + scene.model.nq + scene.object_qvel.start
    return states[..., q0 : q0 + 3], states[..., q0 + 3 : q0 + 7], states[..., v0 : v0 + 3]


@dataclass
class StepMeasures:
    """What the judge needs from a trajectory, step by step ((N, T) unless noted; steps never
    simulated hold NaN / False / 0).

    Attributes:
        displacement: slip at the hands' grasp centres (m), measured like :func:`object_motion`.
        rotation: rotation of the object (degrees), measured like :func:`object_motion`.
        finite: the state is finite.
        broken: non-finite, stalled (time does not advance: ``mujoco.rollout`` stopped at a
            simulation warning) or faster than ``max_speed``.
        fast: the object moves faster than ``max_speed`` (m/s).
        depth: deepest object contact penetration (m, >= 0).
        hand_contacts: (N, T, 2) contacts between the object and each hand.
    """

    displacement: np.ndarray
    rotation: np.ndarray
    finite: np.ndarray
    broken: np.ndarray
    fast: np.ndarray
    depth: np.ndarray
    hand_contacts: np.ndarray

    @classmethod
    def empty(cls, n: int, nstep: int) -> StepMeasures:
        return cls(
            displacement=np.full((n, nstep), np.nan),
            rotation=np.full((n, nstep), np.nan),
            finite=np.zeros((n, nstep), dtype=bool),
            broken=np.zeros((n, nstep), dtype=bool),
            fast=np.zeros((n, nstep), dtype=bool),
            depth=np.zeros((n, nstep)),
            hand_contacts=np.zeros((n, nstep, 2)),
        )

    def store(self, rows: np.ndarray | slice, steps: slice, other: StepMeasures) -> None:
        """Write ``other`` (measures of ``rows`` over ``steps``) into these arrays."""
        for f in fields(self):
            getattr(self, f.name)[rows, steps] = getattr(other, f.name)


def measure_steps(
    scene: Scene,
    states: np.ndarray,
    sensors: np.ndarray,
    first_step: int,
    protocol: TrialProtocol,
    anchors: np.ndarray,
    reference: np.ndarray | None = None,
) -> StepMeasures:
    """Measure a stretch of trajectories.

    Args:
        states: (N, W, S) full physics states after steps ``first_step .. first_step + W - 1``.
        sensors: (N, W, D) sensor data after the same steps.
        first_step: index of the first step (0 = the first step of the trial).
        protocol: ``max_speed``.
        anchors: (N, K, 3) where slip is measured (:func:`grasp_centres`).
        reference: (N, S) the state slip and rotation are measured from (the state at the end of
            *close*); ``None`` for steps of *close* (measured from the initial pose).
    """
    pos, quat, vel = object_states(scene, states)
    if reference is None:
        displacement, rotation = motion_from(pos, quat, anchors)
    else:
        ref_pos, ref_quat, _ = object_states(scene, reference)
        displacement, rotation = motion_from(pos, quat, anchors, ref_pos, ref_quat)
    count_at, dist_at, hand_at = sensor_slices(scene)
    with np.errstate(invalid="ignore"):
        depth = np.where(sensors[:, :, count_at] > 0, -sensors[:, :, dist_at], 0.0)
    return step_measures(
        scene,
        first_step,
        protocol,
        time=states[:, :, 0],
        displacement=displacement,
        rotation=rotation,
        finite=np.isfinite(states).all(axis=2),
        speed=np.linalg.norm(vel, axis=-1),
        depth=depth,
        hand_contacts=sensors[:, :, hand_at],
    )


def step_measures(
    scene: Scene,
    first_step: int,
    protocol: TrialProtocol,
    *,
    time: np.ndarray,
    displacement: np.ndarray,
    rotation: np.ndarray,
    finite: np.ndarray,
    speed: np.ndarray,
    depth: np.ndarray,
    hand_contacts: np.ndarray,
) -> StepMeasures:
    """:class:`StepMeasures` from per-step quantities ((N, W) unless noted), judging what
    breaks a trial: a non-finite state, a stalled clock, a speed over ``max_speed``.

    Args:
        first_step: index of the first of the W steps.
        time: simulation time after each step (s).
        displacement, rotation: slip (m) and rotation (degrees), as :func:`motion_from`.
        finite: the whole state is finite.
        speed: the object's linear speed (m/s).
        depth: deepest object contact penetration (m, >= 0).
        hand_contacts: (N, W, 2) contacts between the object and each hand.
    """
    timestep = scene.model.opt.timestep
    expected_time = timestep * np.arange(first_step + 1, first_step + time.shape[1] + 1)
    with np.errstate(invalid="ignore"):
        stalled = np.abs(time - expected_time) > 0.5 * timestep
        fast = speed > protocol.max_speed
    return StepMeasures(
        displacement=displacement,
        rotation=rotation,
        finite=finite,
        broken=~finite | stalled | fast,
        fast=fast,
        depth=depth,
        hand_contacts=hand_contacts,
    )


def out_steps(
    measures: StepMeasures, first_step: int, plan: Schedule, protocol: TrialProtocol
) -> np.ndarray:
    """(N, W) bool: steps ``first_step ..`` where the trial leaves the protocol: slip or rotation
    out of bounds, a broken state, or (at the last step of *close*) a hand with fewer than
    :attr:`TrialProtocol.min_contacts_after_close` contacts on the object."""
    out = protocol.out_of_bounds(measures.displacement, measures.rotation) | measures.broken
    at = plan.close_end - 1 - first_step
    if protocol.min_contacts_after_close > 0 and 0 <= at < out.shape[1]:
        few = (measures.hand_contacts[:, at] < protocol.min_contacts_after_close).any(axis=1)
        out[:, at] |= few
    return out


def judge(measures: StepMeasures, plan: Schedule, protocol: TrialProtocol) -> TrialResults:
    """Verdicts from the measures of whole trials (steps after the end of a failing phase may
    be missing)."""
    n, steps = measures.displacement.shape
    out = out_steps(measures, 0, plan, protocol)
    first_out = np.where(out.any(axis=1), out.argmax(axis=1), steps)
    phase_end = np.cumsum(np.bincount(plan.phase, minlength=len(PHASES)))
    results = TrialResults.empty(n, protocol)
    for i in range(n):
        failed = first_out[i] < steps
        phase = int(plan.phase[first_out[i]]) if failed else -1
        last = int(phase_end[phase]) if failed else steps
        window = slice(0, last)
        unstable = bool(measures.broken[i, window].any())
        results.status[i] = (
            TrialStatus.UNSTABLE
            if unstable
            else (TrialStatus.FAILED if failed else TrialStatus.SUCCESS)
        )
        results.failing_phase[i] = phase
        ok = measures.finite[i, window]
        results.max_displacement[i] = np.max(np.where(ok, measures.displacement[i, window], np.inf))
        results.max_rotation_deg[i] = np.max(np.where(ok, measures.rotation[i, window], np.inf))
        held = slice(0, max(1, int(first_out[i])))  # while the object is held (within bounds)
        results.max_penetration[i] = (
            np.inf if unstable else max(0.0, float(np.max(measures.depth[i, held])))
        )
        results.contacts_after_close[i] = measures.hand_contacts[i, plan.close_end - 1]
        results.contacts_final[i] = measures.hand_contacts[i, last - 1]
        results.ejected[i] = bool(measures.fast[i, window].any())
    return results


def analyse(
    scene: Scene,
    states: np.ndarray,
    sensors: np.ndarray,
    plan: Schedule,
    protocol: TrialProtocol,
    anchors: np.ndarray | None = None,
) -> TrialResults:
    """Judge rolled-out trials (see the module docstring for the criteria).

    Args:
        states: (N, T, S) full physics states after each step.
        sensors: (N, T, D) sensor data after each step.
        plan: the trial's schedule (T steps).
        protocol: thresholds.
        anchors: (N, K, 3) world points where displacement is measured (the hands' grasp
            centres, :func:`grasp_centres`); default the object's origin.
    """
    n = len(states)
    anchors = np.zeros((n, 1, 3)) if anchors is None else np.asarray(anchors, dtype=np.float64)
    close = plan.close_end
    measures = StepMeasures.empty(n, states.shape[1])
    measures.store(
        slice(None),
        slice(0, close),
        measure_steps(scene, states[:, :close], sensors[:, :close], 0, protocol, anchors),
    )
    if states.shape[1] > close:
        measures.store(
            slice(None),
            slice(close, None),
            measure_steps(
                scene,
                states[:, close:],
                sensors[:, close:],
                close,
                protocol,
                anchors,
                states[:, close - 1],
            ),
        )
    return judge(measures, plan, protocol)
