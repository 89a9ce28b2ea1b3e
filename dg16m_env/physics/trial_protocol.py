"""The dual-grasp trial protocol (DG16M paper, Section IV): what a trial is, for every engine.

One trial, for one dual grasp (two hand poses in the object frame):

1. **Check** (not simulated): both hands at their poses with fingers fully open and the object at
   rest at the origin. If an open hand penetrates the object deeper than
   :attr:`TrialProtocol.invalid_penetration`, or the two hands overlap, the trial is
   ``INVALID`` and is not run (the grasp cannot be reached).
2. **close** (:attr:`TrialProtocol.close_time` s, gravity off): every finger pushes with the
   scene's squeeze force (``PAPER.f_high``, 70 N) and the fingers close on the object.
3. **gravity** (:attr:`TrialProtocol.gravity_time` s): the object's weight ``m g`` acts at its
   centre of mass.
4. **Disturbances**, one after the other, each for :attr:`TrialProtocol.disturbance_time` s on
   top of gravity: a force of ``disturbance_force_fraction * m g`` along ``+x, -x, +y, -y, +z,
   -z`` (world = initial object frame), then a torque of ``disturbance_force_fraction * m g *
   disturbance_torque_arm`` about the same six directions.

The hands never move (they stand for arms holding their pose). **Success** when each hand
touches the object at the end of *close* (at least :attr:`TrialProtocol.min_contacts_after_close`
contacts; benchmark protocol v2) and, at every step after the fingers closed, the object moves
less than :attr:`TrialProtocol.max_displacement` at each hand's grasp centre (slip relative to
the hands) and turns less than :attr:`TrialProtocol.max_rotation_deg`, both measured from its pose
at the end of *close* (and within the same bounds of its initial pose during *close*). The first
step outside the bounds (or the end of *close* without contact) names the failing phase. A trial
whose state turns non-finite or whose object moves faster than :attr:`TrialProtocol.max_speed` is
``UNSTABLE`` (never seen with the default settings; it is reported, not hidden);
:attr:`TrialResults.ejected` tells the second cause from the first.
Penetration is the deepest object contact while the object is held
(before it first leaves the bounds; once it slips out, fingers closing on its edges mean nothing).

Slip and rotation are measured by one function,
:func:`~dg16m_env.physics.trial_measures.object_motion`, and judged against the bounds by
:meth:`TrialProtocol.out_of_bounds`; the step-by-step replay (:mod:`dg16m_env.physics.replay`)
uses the same two.

What lives here is shared by the engines that run trials: the validity check
(:func:`check_initial_poses`, always in C MuJoCo), the :func:`schedule`, the controls, the phase
segments (:func:`trial_segments`) and :func:`simulate` (full C rollouts, for replay). The
measures (:func:`~dg16m_env.physics.trial_measures.measure_steps` of C MuJoCo states,
:func:`~dg16m_env.physics.trial_measures.step_measures` of measured numbers),
:func:`~dg16m_env.physics.trial_measures.out_steps` and the judge
(:func:`~dg16m_env.physics.trial_measures.judge`, :func:`~dg16m_env.physics.trial_measures.analyse`)
are in :mod:`dg16m_env.physics.trial_measures`. Running trials sits above:
:func:`dg16m_env.physics.trial.run_trials` picks the engine, its own C MuJoCo batches or MuJoCo Warp
(:mod:`dg16m_env.physics.warp_trials`). Imports point one way, ``trial_protocol <- warp_trials <- trial``;
:mod:`dg16m_env.physics.trial` re-exports every name defined here.

Each ``mujoco.rollout`` call starts the solver without a warm start; :func:`simulate` and the
step-by-step replay restart it at the same steps as ``run_trials``, so they reproduce it bit for
bit.
"""

from __future__ import annotations

import enum
import itertools
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import mujoco
import numpy as np
from mujoco import rollout

from dataset_gen.grasps.robust import protocol_loads
from dataset_gen.objects.grasp_object import is_rigid
from dg16m_core.checks import check_fields, known_fields
from dg16m_core.errors import Dg16mError
from dg16m_core.parameters import PAPER, PROTOCOL, DisturbanceProtocol
from dg16m_env.physics.scene import Scene, quat_from_matrix

__all__ = [
    "CONTROL_SPEC",
    "DIRECTIONS",
    "HAND_PARTS",
    "PHASES",
    "STATE_SPEC",
    "InvalidReason",
    "Schedule",
    "TrialError",
    "TrialProtocol",
    "TrialResults",
    "TrialStatus",
    "check_dual_grasps",
    "check_initial_poses",
    "initial_state",
    "open_hand_penetration",
    "schedule",
    "simulate",
    "trial_control_vectors",
    "trial_controls",
    "trial_segments",
]


DIRECTIONS = ("+x", "-x", "+y", "-y", "+z", "-z")
"""Disturbance directions, world axes = the object's initial frame."""

PHASES: tuple[str, ...] = (
    "close",
    "gravity",
    *(f"force{d}" for d in DIRECTIONS),
    *(f"torque{d}" for d in DIRECTIONS),
)
"""Trial phases in order; :attr:`TrialResults.failing_phase` indexes this tuple (-1: none)."""

CONTROL_SPEC = (
    mujoco.mjtState.mjSTATE_CTRL
    | mujoco.mjtState.mjSTATE_XFRC_APPLIED
    | mujoco.mjtState.mjSTATE_MOCAP_POS
    | mujoco.mjtState.mjSTATE_MOCAP_QUAT
)
STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS


class TrialError(Dg16mError, ValueError):
    """Bad trial input: grasp array shapes, non-finite or non-rigid poses, bad protocol values."""


class TrialStatus(enum.IntEnum):
    """Outcome of one trial."""

    SUCCESS = 0
    """The object stayed within the bounds through every phase."""
    FAILED = 1
    """The object left the bounds; see the failing phase."""
    INVALID = 2
    """Not run: an open hand penetrates the object, or the hands overlap."""
    UNSTABLE = 3
    """The simulation produced non-finite numbers or an implausible speed."""


class InvalidReason(enum.IntEnum):
    """Why a trial was not run (``NONE`` for trials that ran)."""

    NONE = 0
    HAND0_PENETRATES = 1
    HAND1_PENETRATES = 2
    HANDS_OVERLAP = 3


@dataclass(frozen=True)
class TrialProtocol:
    """Timing, loads and success thresholds of a trial (SI units; see the module docstring).

    Attributes:
        gravity: gravitational acceleration (m/s^2; default ``PAPER.gravity``, the release's).
        close_time: duration of the closing phase, gravity off (s).
        gravity_time: duration of the gravity phase (s).
        disturbance_time: duration of each of the 12 disturbances (s).
        ramp_time: at the start of each phase the load moves linearly from the previous phase's
            to the new one over this time (s); a step load would shake the grasp.
        disturbance_force_fraction: disturbance force as a fraction of the object's weight.
        disturbance_torque_arm: lever arm turning the disturbance force into a torque (m).
        max_displacement: allowed displacement of the object at either hand's grasp centre,
            i.e. slip relative to the hands (m).
        max_rotation_deg: allowed rotation of the object (degrees).
        invalid_penetration: an open hand deeper than this in the object makes the trial
            invalid (m).
        max_speed: an object faster than this is a simulation failure (m/s).
        min_contacts_after_close: each hand must touch the object with at least this many
            contacts at the end of *close*, or the trial fails in *close* (0 turns the
            requirement off; benchmark protocol v2).
        batch_size: trials per ``mujoco.rollout`` call (memory vs. overhead).
    """

    gravity: float = PAPER.gravity
    close_time: float = PROTOCOL.close_time
    gravity_time: float = PROTOCOL.gravity_time
    disturbance_time: float = PROTOCOL.disturbance_time
    ramp_time: float = PROTOCOL.ramp_time
    disturbance_force_fraction: float = PROTOCOL.disturbance_force_fraction
    disturbance_torque_arm: float = PROTOCOL.disturbance_torque_arm
    max_displacement: float = PROTOCOL.max_displacement
    max_rotation_deg: float = PROTOCOL.max_rotation_deg
    invalid_penetration: float = PROTOCOL.invalid_penetration
    max_speed: float = 50.0
    min_contacts_after_close: int = 1
    batch_size: int = 64

    def __post_init__(self) -> None:
        check_fields(
            self,
            error=TrialError,
            integers={"batch_size": 1, "min_contacts_after_close": 0},
            zero_allowed=("disturbance_force_fraction", "disturbance_torque_arm"),
        )

    def to_dict(self) -> dict[str, Any]:
        """The fields as a dict (:meth:`from_dict` reads it back)."""
        return asdict(self)

    def disturbances(self) -> DisturbanceProtocol:
        """The loads, durations, bounds and open-hand tolerance of this protocol, as the
        generator-side modules (:mod:`dataset_gen.grasps.robust`, :mod:`dataset_gen.grasps.clearance`) take
        them."""
        return DisturbanceProtocol(
            **{f.name: getattr(self, f.name) for f in fields(DisturbanceProtocol)}
        )

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrialProtocol:
        """The protocol :meth:`to_dict` wrote (missing keys take their defaults).

        Raises:
            TrialError: ``data`` is not a mapping, has unknown keys or bad values.
        """
        return cls(**known_fields(cls, data, what="protocol", error=TrialError))

    def out_of_bounds(self, displacement: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        """Where the object has left the bounds: slip over :attr:`max_displacement` or rotation
        over :attr:`max_rotation_deg` (NaN compares as inside; callers treat it as broken)."""
        with np.errstate(invalid="ignore"):
            return (displacement > self.max_displacement) | (rotation > self.max_rotation_deg)

    def phase_steps(self, timestep: float) -> np.ndarray:
        """(len(PHASES),) number of steps of each phase at ``timestep`` (s)."""
        times = [self.close_time, self.gravity_time] + [self.disturbance_time] * 12
        return np.array([max(1, round(t / timestep)) for t in times], dtype=np.int64)


@dataclass
class TrialResults:
    """Per-trial results for N dual grasps (arrays of length N unless noted).

    Attributes:
        status: :class:`TrialStatus` codes (int8).
        failing_phase: index into :data:`PHASES` of the first phase that broke the bounds,
            -1 when none (int8).
        invalid_reason: :class:`InvalidReason` codes (int8).
        max_displacement: largest displacement of the object at the hands' grasp centres (the
            slip relative to the hands) up to the end of the
            failing phase, or over the whole trial (m; NaN for invalid trials).
        max_rotation_deg: the same for the rotation (degrees).
        max_penetration: deepest object contact while the object is held, i.e. over the steps
            before it first leaves the bounds (m, >= 0; for invalid trials the open hands'
            penetration at the check).
        contacts_after_close: (N, 2) contacts between the object and each hand at the end of
            *close* (int16).
        contacts_final: (N, 2) the same at the end of the trial.
        ejected: the object moved faster than ``max_speed`` (m/s) before the end of the judged
            window: it was thrown out of the hands (typically by the contact solver pushing out
            a deep penetration). One of the two causes of ``UNSTABLE``; the other, a state that
            turns non-finite or stops advancing, leaves it False. Always False for trials that
            are not ``UNSTABLE``.
        protocol: the protocol used.
    """

    status: np.ndarray
    failing_phase: np.ndarray
    invalid_reason: np.ndarray
    max_displacement: np.ndarray
    max_rotation_deg: np.ndarray
    max_penetration: np.ndarray
    contacts_after_close: np.ndarray
    contacts_final: np.ndarray
    ejected: np.ndarray
    protocol: TrialProtocol = field(default_factory=TrialProtocol)

    ARRAY_FIELDS = (
        "status",
        "failing_phase",
        "invalid_reason",
        "max_displacement",
        "max_rotation_deg",
        "max_penetration",
        "contacts_after_close",
        "contacts_final",
        "ejected",
    )

    @classmethod
    def empty(cls, n: int, protocol: TrialProtocol) -> TrialResults:
        return cls(
            status=np.full(n, TrialStatus.INVALID, dtype=np.int8),
            failing_phase=np.full(n, -1, dtype=np.int8),
            invalid_reason=np.zeros(n, dtype=np.int8),
            max_displacement=np.full(n, np.nan),
            max_rotation_deg=np.full(n, np.nan),
            max_penetration=np.zeros(n),
            contacts_after_close=np.zeros((n, 2), dtype=np.int16),
            contacts_final=np.zeros((n, 2), dtype=np.int16),
            ejected=np.zeros(n, dtype=bool),
            protocol=protocol,
        )

    @property
    def n(self) -> int:
        return int(self.status.size)

    @property
    def success(self) -> np.ndarray:
        """(N,) bool, True where the grasp held through every phase."""
        return self.status == TrialStatus.SUCCESS

    @property
    def valid(self) -> np.ndarray:
        """(N,) bool, True where the trial ran (not invalid)."""
        return self.status != TrialStatus.INVALID

    def phase_name(self, index: int) -> str:
        """The failing phase of trial ``index`` ('' when none)."""
        phase = int(self.failing_phase[index])
        return PHASES[phase] if phase >= 0 else ""

    def summary(self) -> dict[str, Any]:
        """Counts and rates (JSON-ready)."""
        valid = self.valid
        ran = int(valid.sum())
        phases = {PHASES[p]: int(np.sum(self.failing_phase == p)) for p in range(len(PHASES))}
        return {
            "trials": self.n,
            "invalid": int(self.n - ran),
            "success": int(self.success.sum()),
            "failed": int(np.sum(self.status == TrialStatus.FAILED)),
            "unstable": int(np.sum(self.status == TrialStatus.UNSTABLE)),
            "success_rate_valid": float(self.success.sum() / ran) if ran else float("nan"),
            "max_penetration_m": float(self.max_penetration[valid].max()) if ran else 0.0,
            "ejected": int(self.ejected.sum()),
            "failing_phases": {k: v for k, v in phases.items() if v},
        }

    def select(self, rows: np.ndarray) -> TrialResults:
        """The results of trials ``rows``."""
        return TrialResults(
            **{k: getattr(self, k)[rows] for k in self.ARRAY_FIELDS}, protocol=self.protocol
        )

    def invalid_reasons(self) -> dict[str, int]:
        """``{reason name: count}`` over the invalid trials, most frequent first."""
        counts = np.bincount(self.invalid_reason.astype(np.int64), minlength=len(InvalidReason))
        named = {
            InvalidReason(k).name.lower(): int(c)
            for k, c in enumerate(counts)
            if k != InvalidReason.NONE and c
        }
        return dict(sorted(named.items(), key=lambda kv: -kv[1]))

    def __repr__(self) -> str:  # arrays of N rows: counts, not contents
        s = self.summary()
        return (
            f"TrialResults({s['trials']} trials: {s['success']} success, {s['failed']} failed, "
            f"{s['invalid']} invalid, {s['unstable']} unstable)"
        )


# --------------------------------------------------------------------------------------------
# Inputs
# --------------------------------------------------------------------------------------------


def check_dual_grasps(grasps: object) -> np.ndarray:
    """Validate dual grasps: (N, 2, 4, 4) finite rigid transforms (gripper -> object frame, m)."""
    arr = np.asarray(grasps, dtype=np.float64) if not isinstance(grasps, np.ndarray) else grasps
    if arr.ndim == 3 and arr.shape == (2, 4, 4):
        arr = arr[None]
    if arr.ndim != 4 or arr.shape[1:] != (2, 4, 4):
        raise TrialError(f"grasps: expected an (N, 2, 4, 4) array of hand poses, found {arr.shape}")
    arr = np.asarray(arr, dtype=np.float64)
    finite = np.isfinite(arr).all(axis=(1, 2, 3))
    if not finite.all():
        raise TrialError(
            f"grasps: expected finite poses, found NaN/inf in dual grasp {int(np.argmin(finite))}"
        )
    rigid = np.asarray(is_rigid(arr.reshape(-1, 4, 4), atol=1e-5)).reshape(-1, 2).all(axis=1)
    if not rigid.all():
        raise TrialError(
            "grasps: expected rigid transforms (orthonormal rotation, last row 0 0 0 1), found "
            f"a non-rigid pose in dual grasp {int(np.argmin(rigid))}"
        )
    return arr


def _place_hands(scene: Scene, data: mujoco.MjData, pose_pair: np.ndarray) -> None:
    data.mocap_pos[scene.hand_mocap] = pose_pair[:, :3, 3]
    data.mocap_quat[scene.hand_mocap] = quat_from_matrix(pose_pair[:, :3, :3])


def _initial_data(scene: Scene) -> mujoco.MjData:
    data = mujoco.MjData(scene.model)
    mujoco.mj_resetData(scene.model, data)
    return data


HAND_PARTS = ("palm", "finger0", "finger1")
"""The geoms of a hand, in the order of :attr:`~dg16m_env.physics.scene.SceneIndices.hand_geoms`."""


def _open_hand_depths(
    scene: Scene, data: mujoco.MjData, slot_of_geom: np.ndarray, pose_pair: np.ndarray
) -> np.ndarray:
    """(2, 3) deepest penetration (m, >= 0) of each hand's palm and fingers into the object,
    hands at ``pose_pair`` with open fingers (leaves ``data`` at that configuration)."""
    _place_hands(scene, data, pose_pair)
    mujoco.mj_forward(scene.model, data)
    deepest = np.zeros((2, len(HAND_PARTS)))
    for c in range(data.ncon):
        contact = data.contact[c]
        slot = max(slot_of_geom[contact.geom1], slot_of_geom[contact.geom2])
        if slot >= 0:
            hand, part = divmod(int(slot), len(HAND_PARTS))
            deepest[hand, part] = max(deepest[hand, part], -contact.dist)
    return deepest


def _hand_slots(scene: Scene) -> np.ndarray:
    """(ngeom,) ``hand * 3 + part`` for each hand geom (part in :data:`HAND_PARTS`), -1 else."""
    slot_of_geom = np.full(scene.model.ngeom, -1)
    for hand, geoms in enumerate(scene.hand_geoms):
        slot_of_geom[geoms] = hand * len(HAND_PARTS) + np.arange(len(geoms))
    return slot_of_geom


def open_hand_penetration(scene: Scene, grasps: np.ndarray) -> np.ndarray:
    """(N, 2, 3) how deep each hand's palm and two fingers (:data:`HAND_PARTS`) sit in the
    object when the hands are at their poses with open fingers (m, >= 0): what
    :func:`check_initial_poses` judges, part by part (to tell a palm that hits the object from
    fingers that do)."""
    grasps = check_dual_grasps(grasps)
    data = _initial_data(scene)
    slots = _hand_slots(scene)
    return np.stack([_open_hand_depths(scene, data, slots, pair) for pair in grasps])


def check_initial_poses(
    scene: Scene, grasps: np.ndarray, protocol: TrialProtocol
) -> tuple[np.ndarray, np.ndarray]:
    """Which dual grasps can be run: open hands clear of the object and of each other.

    Returns:
        reason: (N,) :class:`InvalidReason` codes (``NONE`` = valid).
        penetration: (N,) deepest open-hand penetration into the object (m, >= 0).
    """
    model = scene.model
    data = _initial_data(scene)
    n = len(grasps)
    reason = np.zeros(n, dtype=np.int8)
    penetration = np.zeros(n)
    slots = _hand_slots(scene)
    fromto = np.zeros(6)
    for i in range(n):
        deepest = _open_hand_depths(scene, data, slots, grasps[i]).max(axis=1)
        penetration[i] = deepest.max()
        if deepest[0] > protocol.invalid_penetration:
            reason[i] = InvalidReason.HAND0_PENETRATES
            continue
        if deepest[1] > protocol.invalid_penetration:
            reason[i] = InvalidReason.HAND1_PENETRATES
            continue
        for g0 in scene.hand_geoms[0]:
            for g1 in scene.hand_geoms[1]:
                gap = mujoco.mj_geomDistance(model, data, int(g0), int(g1), 0.01, fromto)
                if gap < -protocol.invalid_penetration:
                    reason[i] = InvalidReason.HANDS_OVERLAP
                    break
            if reason[i]:
                break
    return reason, penetration


# --------------------------------------------------------------------------------------------
# Schedule and controls
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Schedule:
    """Per-step phase index and external wrench on the object for one protocol and scene.

    Attributes:
        phase: (T,) index into :data:`PHASES` of each step.
        wrench: (T, 6) force (N) and torque (N m) on the object's centre of mass, world frame.
        close_end: number of steps of the close phase.
    """

    phase: np.ndarray
    wrench: np.ndarray
    close_end: int

    @property
    def nstep(self) -> int:
        return int(self.phase.size)


def schedule(scene: Scene, protocol: TrialProtocol) -> Schedule:
    """The step-by-step phases and loads of a trial (see the module docstring)."""
    steps = protocol.phase_steps(scene.model.opt.timestep)
    phase = np.repeat(np.arange(len(PHASES)), steps)
    per_phase = np.zeros((len(PHASES), 6))  # close: no load
    per_phase[1:] = protocol_loads(scene.object_mass, protocol.gravity, protocol.disturbances())[0]
    wrench = per_phase[phase]
    ramp = max(1, round(protocol.ramp_time / scene.model.opt.timestep))
    starts = np.concatenate([[0], np.cumsum(steps)[:-1]])
    for p in range(1, len(PHASES)):
        n = min(ramp, int(steps[p]))
        alpha = (np.arange(1, n + 1) / n)[:, None]
        wrench[starts[p] : starts[p] + n] = (1 - alpha) * per_phase[p - 1] + alpha * per_phase[p]
    return Schedule(phase=phase, wrench=wrench, close_end=int(steps[0]))


def _control_layout(scene: Scene) -> tuple[int, dict[str, np.ndarray]]:
    """Size of a control vector and where ctrl / xfrc / mocap go in it (found by probing)."""
    model = scene.model
    size = mujoco.mj_stateSize(model, CONTROL_SPEC)
    data = mujoco.MjData(model)
    probe = {
        "ctrl": data.ctrl,
        "xfrc_applied": data.xfrc_applied,
        "mocap_pos": data.mocap_pos,
        "mocap_quat": data.mocap_quat,
    }
    layout: dict[str, np.ndarray] = {}
    for name, array in probe.items():
        for other in probe.values():
            other[...] = 0.0
        array.reshape(-1)[:] = np.arange(1, array.size + 1)
        vec = np.zeros(size)
        mujoco.mj_getState(model, data, vec, CONTROL_SPEC)
        where = np.zeros(array.size, dtype=np.int64)
        for value in range(1, array.size + 1):
            (hits,) = np.nonzero(vec == value)
            where[value - 1] = hits[0]
        layout[name] = where
    return size, layout


def trial_control_vectors(
    scene: Scene, grasps: np.ndarray, *, squeeze: float | None = None
) -> np.ndarray:
    """(N, C) each trial's constant controls (``CONTROL_SPEC`` layout): the squeeze force and
    the hands' poses, with no wrench on the object."""
    size, layout = _control_layout(scene)
    n = len(grasps)
    controls = np.zeros((n, size))
    force = scene.params.squeeze_force if squeeze is None else squeeze
    controls[:, layout["ctrl"][scene.squeeze_actuators]] = force
    mocap_pos = np.zeros((n, scene.model.nmocap, 3))
    mocap_quat = np.zeros((n, scene.model.nmocap, 4))
    mocap_pos[:, scene.hand_mocap] = grasps[:, :, :3, 3]
    mocap_quat[:, scene.hand_mocap] = quat_from_matrix(grasps[:, :, :3, :3])
    controls[:, layout["mocap_pos"]] = mocap_pos.reshape(n, -1)
    controls[:, layout["mocap_quat"]] = mocap_quat.reshape(n, -1)
    return controls


def trial_controls(
    scene: Scene, grasps: np.ndarray, plan: Schedule, *, squeeze: float | None = None
) -> np.ndarray:
    """(N, T, C) open-loop controls: squeeze, hand poses and object wrench at every step."""
    _, layout = _control_layout(scene)
    constant = trial_control_vectors(scene, grasps, squeeze=squeeze)
    controls = np.repeat(constant[:, None], plan.nstep, axis=1)
    xfrc = layout["xfrc_applied"].reshape(scene.model.nbody, 6)[scene.object_body]
    controls[:, :, xfrc] = plan.wrench[None]
    return controls


def initial_state(scene: Scene) -> np.ndarray:
    """(S,) full physics state at the start of a trial: object at rest at the origin, fingers
    open."""
    data = _initial_data(scene)
    state = np.zeros(mujoco.mj_stateSize(scene.model, STATE_SPEC))
    mujoco.mj_getState(scene.model, data, state, STATE_SPEC)
    return state


def simulate(
    scene: Scene, grasps: np.ndarray, protocol: TrialProtocol | None = None
) -> tuple[np.ndarray, np.ndarray, Schedule]:
    """Roll out full trials (no validity check, no early exit) and return their trajectories.

    The rollout restarts at every phase (:func:`trial_segments`) exactly as
    :func:`~dg16m_env.physics.trial.run_trials` does, so the trajectories are bit for bit the ones it
    judged (up to the step where it stopped a failed trial).

    Returns:
        states: (N, T, S) full physics states after each step (``mjSTATE_FULLPHYSICS``).
        sensors: (N, T, D) sensor data after each step.
        plan: the :class:`Schedule`.
    """
    protocol = protocol or TrialProtocol()
    grasps = check_dual_grasps(grasps)
    plan = schedule(scene, protocol)
    controls = trial_controls(scene, grasps, plan)
    data = mujoco.MjData(scene.model)
    n = len(grasps)
    start = initial_state(scene)
    states = np.empty((n, plan.nstep, start.size))
    sensors = np.empty((n, plan.nstep, scene.model.nsensordata))
    state = np.repeat(start[None], n, axis=0)
    for seg in trial_segments(plan):
        states[:, seg], sensors[:, seg] = rollout.rollout(
            scene.model,
            data,
            state,
            controls[:, seg],
            control_spec=CONTROL_SPEC,
            nstep=seg.stop - seg.start,
        )
        state = states[:, seg.stop - 1]
    return states, sensors, plan


def trial_segments(plan: Schedule) -> list[slice]:
    """Step ranges run by one ``mujoco.rollout`` call each: one per phase. A failed trial stops
    at the end of its failing phase. The rollout restarts the solver's warm start
    (``qacc_warmstart``) at each segment; that is part of the trial's definition
    (:func:`simulate` and the step-by-step replay restart it at the same steps)."""
    bounds = [0, *np.flatnonzero(np.diff(plan.phase)) + 1, plan.nstep]
    return [slice(int(a), int(b)) for a, b in itertools.pairwise(bounds) if b > a]
