"""A Lift control step's arithmetic: the substep hand targets of an action, the step's measures
(lift, grasps, reach, jaw angle; the hold and termination by :mod:`.measures`) and the
observation, from the env's simulated state.

Each has two forms, and a version uses the one it was registered with
(:attr:`~.versions.LiftVersion.compiled_arithmetic`): numpy (v0, v1: :func:`hand_targets`,
:func:`measure`, :func:`vector_observation`, :func:`state_parts`) and compiled (v2:
:func:`compiled_hand_targets`, :func:`compiled_measure`, :func:`compiled_state_values`, by the
numba functions of :mod:`.kernels`). The two agree to rounding (within 1e-9,
``tests/test_lift_v2.py``), not bit for bit: one form alone cannot give both v1's and v2's
registered episodes their bytes (v1 on the compiled form, or v2 on numpy, changes every
``bench/layout_digest.py`` episode of that version), so both stay, each frozen with its version.

The functions take the env (a :class:`~dg16m_env.envs.lift.task.LiftEnv`, typed ``Any``: this
module sits below the task) and read and update its episode attributes (``env._current``,
``env._target_pos``, ``env._hold_anchor``, ...).
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from dg16m_env.envs.lift.measures import Hold, LiftStepMeasures, measure_step
from dg16m_env.envs.lift.observations import STATE_LAYOUT, STATE_SLICES, rotation_errors
from dg16m_env.envs.lift.reward import jaw_angle
from dg16m_env.envs.lift.scenes import HAND_WORKSPACE_TOP, HAND_WORKSPACE_XY, TABLE_MARGIN
from dg16m_env.envs.lift.spaces import (
    MAX_ROTATION,
    MAX_TRANSLATION,
    OBS_LAYOUT,
    _right_matrix,
)
from dg16m_env.envs.spaces import rotation_to_6d
from dg16m_env.physics.lift_scene import LiftScene

_PREVIOUS = STATE_SLICES["previous_action"]
_ELAPSED = STATE_SLICES["elapsed"].start
_HOLD = STATE_SLICES["hold"].start
_NO_GRASP = np.zeros((2, 4, 4))
_kernels: Any = None  # dg16m_env.envs.lift.kernels, imported at the first use (numba: 0.4 s)


def lift_kernels() -> Any:
    """:mod:`dg16m_env.envs.lift.kernels`, imported on first use (so that ``gym.make`` does
    not wait for numba)."""
    global _kernels
    if _kernels is None:
        from dg16m_env.envs.lift import kernels as module

        _kernels = module
    return _kernels


# --------------------------------------------------------------------------------------------
# Helpers shared by both forms
# --------------------------------------------------------------------------------------------


def hand_centres(data: mujoco.MjData, scene: LiftScene) -> np.ndarray:
    """(2, 3) the hands' grasp centres, world (m)."""
    rotations = data.xmat[scene.hand_bodies].reshape(2, 3, 3)
    return data.xpos[scene.hand_bodies] + scene.gripper.contact_depth * rotations[:, :, 1]


def target_world(grasp: np.ndarray, obj_pos: np.ndarray, obj_rot: np.ndarray) -> np.ndarray:
    """(2, 4, 4) the target grasp (object frame) at the object's current pose."""
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = obj_rot, obj_pos
    return pose @ grasp


def clip_command(env: Any, centres: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """Grasp centres inside the workspace and hands above the table (v0's *Action space*)."""
    centres = centres.copy()
    centres[:, :2] = np.clip(centres[:, :2], -HAND_WORKSPACE_XY, HAND_WORKSPACE_XY)
    centres[:, 2] = np.minimum(centres[:, 2], HAND_WORKSPACE_TOP)
    local = env._clip_local_points()
    lowest = (rotations[:, 2, :] @ local.T).min(axis=1)
    centres[:, 2] = np.maximum(centres[:, 2], TABLE_MARGIN - lowest)
    return centres


def _finish_measure(
    env: Any,
    unstable: bool,
    *,
    lift: float,
    grasping: np.ndarray,
    centres: np.ndarray,
    speed: float,
    reach_distance: float,
    angle: float | None,
) -> LiftStepMeasures:
    """The step's hold, success and termination (v0's *Success*, *Termination*); updates the
    env's hold."""
    assert env._current is not None
    data, body = env._current.data, env._current.scene.object_body
    hold, measures = measure_step(
        Hold(env._hold_anchor, env._hold_count),
        unstable=unstable,
        lift=lift,
        lift_height=env.lift_height,
        hold_steps=env.hold_steps,
        max_slip=env.max_slip,
        grasping=grasping,
        centres=centres,
        obj_pos=data.xpos[body],
        obj_rot=data.xmat[body].reshape(3, 3),
        com=data.xipos[body],
        speed=speed,
        reach_distance=reach_distance,
        jaw_angle=angle,
        success_needs_grasp=env.version.success_needs_grasp,
    )
    env._hold_anchor, env._hold_count = hold.anchor, hold.count
    return measures


# --------------------------------------------------------------------------------------------
# numpy (v0, v1)
# --------------------------------------------------------------------------------------------


def hand_targets(
    env: Any, values: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One control step's hand targets (v0's *Action space*): ``(n, 14)`` substep rows for
    :func:`~dg16m_env.physics.lift_scene.step_hand_targets`, and the commanded grasp centres
    (2, 3), rotations (2, 3, 3) and unit quaternions (2, 4) after the step."""
    assert env._current is not None
    scene = env._current.scene

    # The same operations as the plain formulas in the comments, on views and reused
    # arrays (bit for bit the same; bench/env_lift.py measures the difference).
    pairs = values.reshape(2, 7)  # one row per hand
    moves = pairs[:, 0:3] * MAX_TRANSLATION  # values[[0, 1, 2, 7, 8, 9]].reshape(2, 3) * ..
    turns = pairs[:, 3:6] * MAX_ROTATION  # values[[3, 4, 5, 10, 11, 12]].reshape(2, 3) * ..
    start_centres, start_quat = env._target_pos, env._target_quat

    # Substep targets: rotations at a constant rate (the quaternion is the commanded
    # rotation's one source), grasp centres linear in time.
    n, fraction = env.substeps, env._fractions
    angle = np.sqrt(np.sum(turns * turns, axis=1))  # (2,)
    axis = turns / np.maximum(angle, 1e-300)[:, None]
    half = np.multiply.outer(fraction, 0.5 * angle)  # (n, 2)
    delta = np.empty((n, 2, 4))
    delta[..., 0] = np.cos(half)
    delta[..., 1:] = np.sin(half)[..., None] * axis
    quats = np.empty((n, 2, 4))
    for k in range(2):  # delta ⊗ q0, with q0's right-multiplication matrix
        quats[:, k] = delta[:, k] @ _right_matrix(start_quat[k]).T
    final = quats[-1] / np.sqrt(np.sum(quats[-1] * quats[-1], axis=1))[:, None]
    rotations = np.empty((2, 9))
    for k in range(2):
        mujoco.mju_quat2Mat(rotations[k], final[k])
    rotations = rotations.reshape(2, 3, 3)
    centres = clip_command(env, start_centres + moves, rotations)
    path = start_centres + env._fraction_column * (centres - start_centres)  # (n, 2, 3)
    # Approach axis R[:, 1] of each substep quaternion (w, x, y, z); MuJoCo normalises
    # mocap quaternions itself. Each substep's hand targets (mocap ids 0, 1 = hands) are
    # one row of ``targets``: both flanges, then both quaternions (mjSTATE_MOCAP_POS, _QUAT).
    w, x, y, z = quats[..., 0], quats[..., 1], quats[..., 2], quats[..., 3]
    approach = np.empty((n, 2, 3))
    approach[..., 0] = 2.0 * (x * y - w * z)
    approach[..., 1] = 1.0 - 2.0 * (x * x + z * z)
    approach[..., 2] = 2.0 * (y * z + w * x)
    flanges = path - scene.gripper.contact_depth * approach
    targets = np.concatenate([flanges.reshape(n, 6), quats.reshape(n, 8)], axis=1)
    return targets, centres, rotations, final


def measure(env: Any, unstable: bool) -> LiftStepMeasures:
    """What the step did: lift, grasps, hold (updated here), termination, reach and angle."""
    assert env._current is not None
    scene, data = env._current.scene, env._current.data
    body = scene.object_body
    com = data.xipos[body]
    lift = float(com[2] - env._rest_com_z)
    grasping = (data.sensordata[scene.finger_contacts] > 0).all(axis=1)  # (2,)
    centres = hand_centres(data, scene)
    obj_pos, obj_rot = data.xpos[body], data.xmat[body].reshape(3, 3)
    speed = float(np.linalg.norm(data.qvel[scene.object_qvel][:3])) if not unstable else 0.0
    if env._grasp is not None:
        goal = target_world(env._grasp, obj_pos, obj_rot)
        depth = scene.gripper.contact_depth
        goal_centres = goal[:, :3, 3] + depth * goal[:, :3, 1]
        distance = np.linalg.norm(centres - goal_centres, axis=1)
        hands = data.xmat[scene.hand_bodies].reshape(2, 3, 3)
        angle: float | None = float(jaw_angle(hands, goal[:, :3, :3]).mean())
    else:
        local = (centres - obj_pos) @ obj_rot
        nearest = np.clip(local, env._current.box_low, env._current.box_high)
        distance = np.linalg.norm(local - nearest, axis=1)
        angle = None
    return _finish_measure(
        env,
        unstable,
        lift=lift,
        grasping=grasping,
        centres=centres,
        speed=speed,
        reach_distance=float(distance.mean()),
        angle=angle,
    )


def _shared_parts(
    env: Any,
) -> tuple[dict[str, np.ndarray], np.ndarray | None, np.ndarray, np.ndarray]:
    """The parts of v0's observation (:data:`~.spaces.OBS_LAYOUT`, float64), which v1's state
    also holds, with the target grasp at the object's pose ((2, 4, 4), None without one), the
    hands' rotations (2, 3, 3) and their grasp centres (2, 3)."""
    assert env._current is not None
    scene, data = env._current.scene, env._current.data
    body = scene.object_body
    obj_pos, obj_rot = data.xpos[body], data.xmat[body].reshape(3, 3)
    velocity = data.qvel[scene.object_qvel]
    hands = data.xmat[scene.hand_bodies].reshape(2, 3, 3)
    hand_pos = data.xpos[scene.hand_bodies]
    centres = hand_pos + scene.gripper.contact_depth * hands[:, :, 1]
    travel = data.qpos[scene.finger_qpos].sum(axis=1)
    parts = {
        "object_position": obj_pos.copy(),
        "object_rotation": rotation_to_6d(obj_rot),
        "object_linear_velocity": velocity[:3].copy(),
        "object_angular_velocity": obj_rot @ velocity[3:],
        "hand_poses": np.concatenate([hand_pos, rotation_to_6d(hands)], axis=1).ravel(),
        "finger_openings": scene.gripper.max_opening - travel,
        "grasp_centres": (centres - obj_pos).ravel(),
        "finger_contacts": (data.sensordata[scene.finger_contacts] > 0).ravel() * 1.0,
        "object_size": env._current.box_high - env._current.box_low,
        "object_box_centre": 0.5 * (env._current.box_high + env._current.box_low),
        "lift": np.array([data.xipos[body, 2] - env._rest_com_z]),
        "target_poses": np.zeros(18),
        "target_flag": np.zeros(1),
    }
    goal = None
    if env._grasp is not None:
        goal = target_world(env._grasp, obj_pos, obj_rot)
        parts["target_poses"] = np.concatenate(
            [goal[:, :3, 3], rotation_to_6d(goal[:, :3, :3])], axis=1
        ).ravel()
        parts["target_flag"][0] = 1.0
    return parts, goal, hands, centres


def vector_observation(env: Any) -> np.ndarray:
    """v0's observation (71 numbers, :data:`~.spaces.OBS_LAYOUT`; float32, clipped)."""
    parts, _, _, _ = _shared_parts(env)
    obs = np.concatenate([parts[name] for name, _, _, _ in OBS_LAYOUT])
    return np.clip(obs.astype(np.float32), env._obs_low, env._obs_high)


def state_parts(env: Any) -> dict[str, np.ndarray]:
    """The named parts of v1's ``"state"`` (float64, unclipped; :mod:`.v1`, *Observation
    modes*): v0's observation's parts and the relative features, commands and counters."""
    shared, goal, hands, centres = _shared_parts(env)
    parts = {name: np.zeros(size) for name, size, _, _ in STATE_LAYOUT}
    parts.update(shared)
    if goal is not None:
        depth = env._current.scene.gripper.contact_depth
        goal_centres = goal[:, :3, 3] + depth * goal[:, :3, 1]
        parts["centre_errors"] = (centres - goal_centres).ravel()
        parts["rotation_errors"] = rotation_errors(hands, goal[:, :3, :3]).ravel()
    parts["commanded_poses"] = np.concatenate(
        [env._target_pos, rotation_to_6d(env._target_rot)], axis=1
    ).ravel()
    parts["previous_action"] = env._previous_action.copy()
    parts["elapsed"][0] = min(env._elapsed / env._steps_total, 1.0)
    parts["hold"][0] = min(env._hold_count / max(env.hold_steps, 1), 1.0)
    return parts


# --------------------------------------------------------------------------------------------
# Compiled (v2)
# --------------------------------------------------------------------------------------------


def compiled_hand_targets(
    env: Any, values: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`hand_targets` by :func:`~dg16m_env.envs.lift.kernels.substep_targets` (into the
    env's reused ``(n, 14)`` array)."""
    assert env._current is not None
    centres, rotations, final = np.empty((2, 3)), np.empty((2, 3, 3)), np.empty((2, 4))
    lift_kernels().substep_targets(
        values,
        env._target_pos,
        env._target_quat,
        env._fractions,
        MAX_TRANSLATION,
        MAX_ROTATION,
        env._current.scene.gripper.contact_depth,
        HAND_WORKSPACE_XY,
        HAND_WORKSPACE_TOP,
        TABLE_MARGIN,
        env._clip_local_points(),
        env._targets,
        centres,
        rotations,
        final,
    )
    return env._targets, centres, rotations, final


def observe(env: Any) -> tuple[float, bool, bool, float, float, float]:
    """:func:`~dg16m_env.envs.lift.kernels.observe` on the current state (into
    ``env._state`` and ``env._centres``)."""
    assert env._current is not None
    scene, data, item = env._current.scene, env._current.data, env._current
    grasp = env._grasp
    kernels = lift_kernels()
    return kernels.observe(  # type: ignore[no-any-return]
        data.xpos,
        data.xmat,
        data.xipos,
        data.qpos,
        data.qvel,
        data.sensordata,
        scene.object_body,
        scene.hand_bodies,
        scene.object_qvel.start,
        scene.finger_qpos,
        scene.finger_contacts,
        _NO_GRASP if grasp is None else grasp,
        grasp is not None,
        env._target_pos,
        env._target_rot,
        item.box_low,
        item.box_high,
        env._rest_com_z,
        scene.gripper.contact_depth,
        scene.gripper.max_opening,
        kernels.STATE_OFFSETS,
        env._state,
        env._centres,
    )


def compiled_measure(env: Any, unstable: bool) -> LiftStepMeasures:
    """:func:`measure` from one :func:`observe`, which also leaves the step's state for
    :func:`compiled_state_values`."""
    lift, grasp0, grasp1, reach, angle, speed = observe(env)
    env._state_fresh = True
    return _finish_measure(
        env,
        unstable,
        lift=lift,
        grasping=np.array([grasp0, grasp1]),
        centres=env._centres.copy(),
        speed=speed,
        reach_distance=reach,
        angle=angle if env._grasp is not None else None,
    )


def compiled_state_values(env: Any) -> np.ndarray:
    """The flat state (float64, unclipped) of :func:`observe` (the step's, if fresh) and the
    env's counters."""
    if not env._state_fresh:
        observe(env)
    env._state_fresh = False
    state = env._state
    state[_PREVIOUS] = env._previous_action
    state[_ELAPSED] = min(env._elapsed / env._steps_total, 1.0)
    state[_HOLD] = min(env._hold_count / max(env.hold_steps, 1), 1.0)
    return state.copy()
