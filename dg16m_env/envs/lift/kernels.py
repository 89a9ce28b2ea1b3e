"""Compiled per-step arithmetic of ``dg16m_env/DualGraspLift-v2``.

v1 computes a control step's hand targets and its observation with a few hundred small numpy
operations (about 350 us a step, more than the physics at v2's timestep); these two functions
do the same arithmetic in one compiled call each (numba, cached on disk after the first
compile). They are the formulas of :mod:`dg16m_env.envs.lift.v0` (the substep targets)
and :meth:`dg16m_env.envs.lift.task.LiftEnv.state_parts` (the state), in
scalar form; the results agree with them to rounding (``tests/test_lift_v2.py`` compares the two
on the same states, within 1e-9), not bit for bit, which is why only v2 (and v3, v2 with
another success rule) uses them.

Units: m, rad, world frame; quaternions (w, x, y, z); a 6D rotation is ``[R[:, 0], R[:, 1]]``.
Compiled with numpy's error model: a diverged state gives NaN values (the env reports the step
as unstable), never an exception from inside the compiled code.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dg16m_env.envs.lift.observations import STATE_SLICES

STATE_PARTS = (
    "centre_errors",
    "rotation_errors",
    "grasp_centres",
    "hand_poses",
    "commanded_poses",
    "finger_openings",
    "finger_contacts",
    "object_position",
    "object_rotation",
    "object_linear_velocity",
    "object_angular_velocity",
    "object_size",
    "object_box_centre",
    "lift",
    "target_poses",
    "target_flag",
)
"""The parts :func:`observe` writes (the rest, ``previous_action``, ``elapsed`` and ``hold``,
are the env's own counters)."""

STATE_OFFSETS = np.array([STATE_SLICES[name].start for name in STATE_PARTS], dtype=np.int64)
"""Where each of :data:`STATE_PARTS` starts in the flat state vector."""


@numba.njit(cache=True, error_model="numpy")
def _quat_to_matrix(q: np.ndarray, out: np.ndarray) -> None:
    """(3, 3) ``out`` the rotation of the unit quaternion ``q`` (4,)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    out[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    out[0, 1] = 2.0 * (x * y - w * z)
    out[0, 2] = 2.0 * (x * z + w * y)
    out[1, 0] = 2.0 * (x * y + w * z)
    out[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    out[1, 2] = 2.0 * (y * z - w * x)
    out[2, 0] = 2.0 * (x * z - w * y)
    out[2, 1] = 2.0 * (y * z + w * x)
    out[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@numba.njit(cache=True, error_model="numpy")
def substep_targets(
    values: np.ndarray,
    start_centres: np.ndarray,
    start_quat: np.ndarray,
    fractions: np.ndarray,
    max_translation: float,
    max_rotation: float,
    depth: float,
    workspace_xy: float,
    workspace_top: float,
    table_margin: float,
    clip_points: np.ndarray,
    targets: np.ndarray,
    centres: np.ndarray,
    rotations: np.ndarray,
    final: np.ndarray,
) -> None:
    """One control step's hand targets (v0's *Actions*: centres linear in time, rotations at a
    constant rate, the commanded centres clipped to the workspace and above the table).

    Args:
        values: (14,) the action in [-1, 1] (per hand: translation (3), rotation vector (3),
            squeeze (1)).
        start_centres: (2, 3) commanded grasp centres before the step (m).
        start_quat: (2, 4) commanded hand quaternions before the step.
        fractions: (n,) ``k / n`` for the substeps ``k = 1 .. n``.
        max_translation, max_rotation: an action's full scale (m, rad, per axis).
        depth: the gripper's contact depth (m: flange to grasp centre along the approach axis).
        workspace_xy, workspace_top: the commanded centres' bounds (m).
        table_margin: the lowest a hand point may be commanded (m).
        clip_points: (m, 3) hand points relative to the grasp centre, hand frame (m).
        targets: out, (n, 14): per substep both flanges (m), then both quaternions (the
            ``mjSTATE_MOCAP_POS | mjSTATE_MOCAP_QUAT`` state of the two hand targets).
        centres: out, (2, 3) the commanded grasp centres after the step (m).
        rotations: out, (2, 3, 3) the commanded rotations after the step.
        final: out, (2, 4) their unit quaternions.
    """
    n = fractions.shape[0]
    for k in range(2):
        base = 7 * k
        tx = values[base + 3] * max_rotation
        ty = values[base + 4] * max_rotation
        tz = values[base + 5] * max_rotation
        angle = math.sqrt(tx * tx + ty * ty + tz * tz)
        scale = 1.0 / max(angle, 1e-300)
        ax, ay, az = tx * scale, ty * scale, tz * scale
        w, x, y, z = start_quat[k, 0], start_quat[k, 1], start_quat[k, 2], start_quat[k, 3]
        for i in range(n):  # delta (a turn by fraction * angle about axis) ⊗ start
            half = fractions[i] * 0.5 * angle
            c, s = math.cos(half), math.sin(half)
            p0, p1, p2, p3 = c, s * ax, s * ay, s * az
            qw = w * p0 - x * p1 - y * p2 - z * p3
            qx = x * p0 + w * p1 + z * p2 - y * p3
            qy = y * p0 - z * p1 + w * p2 + x * p3
            qz = z * p0 + y * p1 - x * p2 + w * p3
            targets[i, 6 + 4 * k] = qw
            targets[i, 7 + 4 * k] = qx
            targets[i, 8 + 4 * k] = qy
            targets[i, 9 + 4 * k] = qz
        qw, qx = targets[n - 1, 6 + 4 * k], targets[n - 1, 7 + 4 * k]
        qy, qz = targets[n - 1, 8 + 4 * k], targets[n - 1, 9 + 4 * k]
        norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        final[k, 0], final[k, 1] = qw / norm, qx / norm
        final[k, 2], final[k, 3] = qy / norm, qz / norm
        _quat_to_matrix(final[k], rotations[k])
        for a in range(3):
            centres[k, a] = start_centres[k, a] + values[base + a] * max_translation
        for a in range(2):
            centres[k, a] = min(max(centres[k, a], -workspace_xy), workspace_xy)
        centres[k, 2] = min(centres[k, 2], workspace_top)
        lowest = math.inf
        for j in range(clip_points.shape[0]):
            height = (
                rotations[k, 2, 0] * clip_points[j, 0]
                + rotations[k, 2, 1] * clip_points[j, 1]
                + rotations[k, 2, 2] * clip_points[j, 2]
            )
            lowest = min(lowest, height)
        centres[k, 2] = max(centres[k, 2], table_margin - lowest)
        for i in range(n):
            qw, qx = targets[i, 6 + 4 * k], targets[i, 7 + 4 * k]
            qy, qz = targets[i, 8 + 4 * k], targets[i, 9 + 4 * k]
            approach_x = 2.0 * (qx * qy - qw * qz)
            approach_y = 1.0 - 2.0 * (qx * qx + qz * qz)
            approach_z = 2.0 * (qy * qz + qw * qx)
            f = fractions[i]
            for a in range(3):
                along = approach_x if a == 0 else (approach_y if a == 1 else approach_z)
                path = start_centres[k, a] + f * (centres[k, a] - start_centres[k, a])
                targets[i, 3 * k + a] = path - depth * along


@numba.njit(cache=True, error_model="numpy")
def _rotation_vector(r: np.ndarray, out: np.ndarray, at: int) -> None:
    """Write the rotation vector (axis * angle, rad, angle in [-pi, pi]) of the (3, 3) rotation
    ``r`` to ``out[at:at + 3]`` (MuJoCo's ``mju_mat2Quat`` then ``mju_quat2Vel``)."""
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    if trace > 0.0:
        s = 0.5 / math.sqrt(trace + 1.0)
        w = 0.25 / s
        x = (r[2, 1] - r[1, 2]) * s
        y = (r[0, 2] - r[2, 0]) * s
        z = (r[1, 0] - r[0, 1]) * s
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        w = (r[2, 1] - r[1, 2]) / s
        x = 0.25 * s
        y = (r[0, 1] + r[1, 0]) / s
        z = (r[0, 2] + r[2, 0]) / s
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        w = (r[0, 2] - r[2, 0]) / s
        x = (r[0, 1] + r[1, 0]) / s
        y = 0.25 * s
        z = (r[1, 2] + r[2, 1]) / s
    else:
        s = 2.0 * math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        w = (r[1, 0] - r[0, 1]) / s
        x = (r[0, 2] + r[2, 0]) / s
        y = (r[1, 2] + r[2, 1]) / s
        z = 0.25 * s
    if w < 0.0:  # the same rotation; keeps the angle in [0, pi]
        w, x, y, z = -w, -x, -y, -z
    sine = math.sqrt(x * x + y * y + z * z)
    if sine < 1e-15:
        out[at], out[at + 1], out[at + 2] = 0.0, 0.0, 0.0
        return
    angle = 2.0 * math.atan2(sine, w)
    if angle > math.pi:
        angle -= 2.0 * math.pi
    out[at] = x / sine * angle
    out[at + 1] = y / sine * angle
    out[at + 2] = z / sine * angle


@numba.njit(cache=True, error_model="numpy")
def _target_errors(
    k: int,
    hand: np.ndarray,
    centres: np.ndarray,
    pos: np.ndarray,
    rot: np.ndarray,
    grasp: np.ndarray,
    depth: float,
    o: np.ndarray,
    state: np.ndarray,
) -> tuple[float, float]:
    """Hand ``k``'s errors to its target grasp (part of :func:`observe`): writes its
    ``centre_errors``, ``target_poses`` and ``rotation_errors`` to ``state`` and returns its
    reach distance (m) and jaw angle (rad).

    Args:
        k: the hand (0, 1); hand: (3, 3) its rotation; centres: (2, 3) the grasp centres (m).
        pos, rot: the object's position (3,) and rotation (3, 3).
        grasp: (2, 4, 4) the target grasp, object frame; depth: the contact depth (m).
        o: :data:`STATE_OFFSETS`; state: out, the flat state vector.
    """
    goal = np.empty((3, 3))
    goal_pos = np.empty(3)
    for a in range(3):
        goal_pos[a] = pos[a]
        for b in range(3):
            goal_pos[a] += rot[a, b] * grasp[k, b, 3]
            total = 0.0
            for c in range(3):
                total += rot[a, c] * grasp[k, c, b]
            goal[a, b] = total
    distance = 0.0
    for a in range(3):
        error = centres[k, a] - (goal_pos[a] + depth * goal[a, 1])
        state[o[0] + 3 * k + a] = error  # centre_errors
        distance += error * error
        state[o[14] + 9 * k + a] = goal_pos[a]  # target_poses
        state[o[14] + 9 * k + 3 + a] = goal[a, 0]
        state[o[14] + 9 * k + 6 + a] = goal[a, 1]
    reach = math.sqrt(distance)
    # R_t^T R and its trace, with the target and its jaw flip (turned by pi about y).
    relative = np.zeros((3, 3))
    for a in range(3):
        for b in range(3):
            for c in range(3):
                relative[a, b] += goal[c, a] * hand[c, b]
    trace = relative[0, 0] + relative[1, 1] + relative[2, 2]
    flipped = -relative[0, 0] + relative[1, 1] - relative[2, 2]
    if flipped > trace:
        for a in range(3):
            goal[a, 0] = -goal[a, 0]
            goal[a, 2] = -goal[a, 2]
    best = max(trace, flipped)
    jaw = math.acos(min(max((best - 1.0) / 2.0, -1.0), 1.0))
    turn = np.zeros((3, 3))  # goal R^T: turns the hand onto its goal
    for a in range(3):
        for b in range(3):
            for c in range(3):
                turn[a, b] += goal[a, c] * hand[b, c]
    _rotation_vector(turn, state, o[1] + 3 * k)  # rotation_errors
    return reach, jaw


@numba.njit(cache=True, error_model="numpy")
def observe(
    xpos: np.ndarray,
    xmat: np.ndarray,
    xipos: np.ndarray,
    qpos: np.ndarray,
    qvel: np.ndarray,
    sensordata: np.ndarray,
    object_body: int,
    hand_bodies: np.ndarray,
    object_qvel: int,
    finger_qpos: np.ndarray,
    finger_contacts: np.ndarray,
    grasp: np.ndarray,
    has_grasp: bool,
    commanded_centres: np.ndarray,
    commanded_rotations: np.ndarray,
    box_low: np.ndarray,
    box_high: np.ndarray,
    rest_com_z: float,
    depth: float,
    max_opening: float,
    offsets: np.ndarray,
    state: np.ndarray,
    centres: np.ndarray,
) -> tuple[float, bool, bool, float, float, float]:
    """The state parts of :data:`STATE_PARTS` and the step's measures from MuJoCo's arrays.

    Args:
        xpos, xmat, xipos, qpos, qvel, sensordata: ``MjData``'s arrays after ``mj_forward``.
        object_body: the object's body id; hand_bodies: (2,) the hands' body ids.
        object_qvel: where the object's free-joint velocity starts in ``qvel`` (linear (3) of
            the body origin, world; angular (3), body frame).
        finger_qpos: (2, 2) ``qpos`` addresses of each hand's finger joints.
        finger_contacts: (2, 2) ``sensordata`` addresses of the finger-object contact counts.
        grasp: (2, 4, 4) the target grasp, object frame (ignored unless ``has_grasp``).
        commanded_centres: (2, 3); commanded_rotations: (2, 3, 3).
        box_low, box_high: (3,) the object's bounding box, object frame (m).
        rest_com_z: the centre of mass's resting height (m).
        depth: the gripper's contact depth (m); max_opening: its finger opening (m).
        offsets: :data:`STATE_OFFSETS`.
        state: out, the flat state vector (float64; the parts of :data:`STATE_PARTS`).
        centres: out, (2, 3) the hands' grasp centres (m).

    Returns:
        ``lift`` (m), whether hand 0 and hand 1 grasp with both fingers, the mean reach distance
        (m: to the target's grasp centres, or to the object's box without a target), the mean
        jaw angle to the target (rad; 0 without one) and the object's linear speed (m/s).
    """
    o = offsets
    rot = xmat[object_body].reshape((3, 3))
    pos = xpos[object_body]
    reach = 0.0
    jaw = 0.0
    for k in range(2):
        hand = xmat[hand_bodies[k]].reshape((3, 3))
        hand_pos = xpos[hand_bodies[k]]
        for a in range(3):
            centres[k, a] = hand_pos[a] + depth * hand[a, 1]
            state[o[2] + 3 * k + a] = centres[k, a] - pos[a]  # grasp_centres
            state[o[3] + 9 * k + a] = hand_pos[a]  # hand_poses
            state[o[3] + 9 * k + 3 + a] = hand[a, 0]
            state[o[3] + 9 * k + 6 + a] = hand[a, 1]
            state[o[4] + 9 * k + a] = commanded_centres[k, a]  # commanded_poses
            state[o[4] + 9 * k + 3 + a] = commanded_rotations[k, a, 0]
            state[o[4] + 9 * k + 6 + a] = commanded_rotations[k, a, 1]
        travel = qpos[finger_qpos[k, 0]] + qpos[finger_qpos[k, 1]]
        state[o[5] + k] = max_opening - travel  # finger_openings
        if has_grasp:
            distance, angle = _target_errors(k, hand, centres, pos, rot, grasp, depth, o, state)
            reach += distance
            jaw += angle
        else:
            for a in range(3):
                state[o[0] + 3 * k + a] = 0.0
                state[o[1] + 3 * k + a] = 0.0
            for a in range(9):
                state[o[14] + 9 * k + a] = 0.0
            distance = 0.0
            for b in range(3):  # to the box, object frame
                local = 0.0
                for a in range(3):
                    local += (centres[k, a] - pos[a]) * rot[a, b]
                outside = local - min(max(local, box_low[b]), box_high[b])
                distance += outside * outside
            reach += math.sqrt(distance)
    state[o[15]] = 1.0 if has_grasp else 0.0  # target_flag
    grasping = np.zeros(2, dtype=np.bool_)
    for k in range(2):
        first = sensordata[finger_contacts[k, 0]] > 0.0
        second = sensordata[finger_contacts[k, 1]] > 0.0
        state[o[6] + 2 * k] = 1.0 if first else 0.0  # finger_contacts
        state[o[6] + 2 * k + 1] = 1.0 if second else 0.0
        grasping[k] = first and second
    speed = 0.0
    for a in range(3):
        state[o[7] + a] = pos[a]  # object_position
        state[o[8] + a] = rot[a, 0]  # object_rotation
        state[o[8] + 3 + a] = rot[a, 1]
        velocity = qvel[object_qvel + a]
        state[o[9] + a] = velocity  # object_linear_velocity
        speed += velocity * velocity
        spin = 0.0
        for b in range(3):
            spin += rot[a, b] * qvel[object_qvel + 3 + b]
        state[o[10] + a] = spin  # object_angular_velocity
        state[o[11] + a] = box_high[a] - box_low[a]  # object_size
        state[o[12] + a] = 0.5 * (box_high[a] + box_low[a])  # object_box_centre
    lift = xipos[object_body, 2] - rest_com_z
    state[o[13]] = lift
    return lift, grasping[0], grasping[1], 0.5 * reach, 0.5 * jaw, math.sqrt(speed)
