"""The observation modes of ``dg16m_env/DualGraspLift-v1``: the state vector's named parts
(:data:`STATE_LAYOUT`, :data:`STATE_SLICES`), the spaces of each ``obs_mode``
(:func:`observation_space`) and the relative features a policy needs
(:func:`rotation_errors`, :func:`goal_frames`), and :func:`state_vector`, the flat state of
any observation mode. The env computes the values
(:meth:`dg16m_env.envs.lift.task.LiftEnv.state_parts`); this module only
says their names, sizes and bounds.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from dataset_gen.grasps.gripper import PANDA
from dg16m_env.envs.lift.spaces import (
    ACTION_SIZE,
    POSITION_BOUND,
    VELOCITY_BOUND,
    layout_slices,
    rotation_vector,
)
from dg16m_env.envs.spaces import rotation_from_6d

OBS_MODES = ("state", "state_dict", "pointcloud")
"""The ``obs_mode`` values of ``dg16m_env/DualGraspLift-v1``."""

POINTCLOUD_SIZE = 512
"""Points in the ``"pointcloud"`` mode's object cloud unless asked otherwise."""

STATE_LAYOUT: tuple[tuple[str, int, float, float], ...] = (
    ("centre_errors", 6, -POSITION_BOUND, POSITION_BOUND),
    ("rotation_errors", 6, -np.pi, np.pi),
    ("grasp_centres", 6, -POSITION_BOUND, POSITION_BOUND),
    ("hand_poses", 18, -POSITION_BOUND, POSITION_BOUND),
    ("commanded_poses", 18, -POSITION_BOUND, POSITION_BOUND),
    ("finger_openings", 2, 0.0, 1.0),
    ("finger_contacts", 4, 0.0, 1.0),
    ("object_position", 3, -POSITION_BOUND, POSITION_BOUND),
    ("object_rotation", 6, -1.0, 1.0),
    ("object_linear_velocity", 3, -VELOCITY_BOUND, VELOCITY_BOUND),
    ("object_angular_velocity", 3, -VELOCITY_BOUND, VELOCITY_BOUND),
    ("object_size", 3, 0.0, POSITION_BOUND),
    ("object_box_centre", 3, -POSITION_BOUND, POSITION_BOUND),
    ("lift", 1, -POSITION_BOUND, POSITION_BOUND),
    ("target_poses", 18, -POSITION_BOUND, POSITION_BOUND),
    ("target_flag", 1, 0.0, 1.0),
    ("previous_action", ACTION_SIZE, -1.0, 1.0),
    ("elapsed", 1, 0.0, 1.0),
    ("hold", 1, 0.0, 1.0),
)
"""Name, size, lower and upper bound of each part of the v1 state, in the flat vector's order
(documented in :mod:`dg16m_env.envs.lift.v1`, *Observation modes*)."""


STATE_SLICES: dict[str, slice] = layout_slices(STATE_LAYOUT)
"""Name -> slice of the flat ``"state"`` vector."""

STATE_SIZE = sum(size for _, size, _, _ in STATE_LAYOUT)
"""Length of the flat ``"state"`` vector (117)."""

STATE_LOW = np.concatenate([np.full(size, lo) for _, size, lo, _ in STATE_LAYOUT]).astype(
    np.float32
)
STATE_HIGH = np.concatenate([np.full(size, hi) for _, size, _, hi in STATE_LAYOUT]).astype(
    np.float32
)


def observation_space(
    obs_mode: str, n_points: int = POINTCLOUD_SIZE, flat_cloud: bool = False
) -> spaces.Space:
    """The observation space of ``obs_mode`` (one of :data:`OBS_MODES`).

    * ``"state"``: ``Box(STATE_LOW, STATE_HIGH, (STATE_SIZE,), float32)``;
    * ``"state_dict"``: ``Dict`` of one ``Box`` per part of :data:`STATE_LAYOUT`;
    * ``"pointcloud"``: ``Dict(state=<the "state" Box>, points=Box(-5, 5, (n_points, 3)),
      normals=Box(-1, 1, (n_points, 3)), mask=Box(0, 1, (n_points,)))``; with ``flat_cloud``
      (:attr:`~.versions.LiftVersion.flat_cloud`, v3) ``points`` and ``normals`` are
      ``(3 n_points,)`` vectors, the same numbers row by row (``reshape(-1, 3)`` gives the
      rows), as the one-step environments' clouds.
    """
    if obs_mode == "state":
        return spaces.Box(STATE_LOW, STATE_HIGH, dtype=np.float32)
    if obs_mode == "state_dict":
        return spaces.Dict(
            {
                name: spaces.Box(np.float32(lo), np.float32(hi), (size,), dtype=np.float32)
                for name, size, lo, hi in STATE_LAYOUT
            }
        )
    if obs_mode == "pointcloud":
        bound = np.float32(POSITION_BOUND)
        shape = (3 * n_points,) if flat_cloud else (n_points, 3)
        return spaces.Dict(
            {
                "state": spaces.Box(STATE_LOW, STATE_HIGH, dtype=np.float32),
                "points": spaces.Box(-bound, bound, shape, dtype=np.float32),
                "normals": spaces.Box(-1.0, 1.0, shape, dtype=np.float32),
                "mask": spaces.Box(0.0, 1.0, (n_points,), dtype=np.float32),
            }
        )
    raise ValueError(f"obs_mode: expected one of {OBS_MODES}, found {obs_mode!r}")


JAW_FLIP = np.diag([-1.0, 1.0, -1.0])
"""A parallel jaw turned by pi about its approach axis ``+y``: the same grasp."""


def nearest_jaw_targets(rotations: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(..., 3, 3) each target rotation or the target turned by pi about its approach axis,
    whichever is nearer the hand rotation (both (..., 3, 3))."""
    relative = np.einsum("...ji,...jk->...ik", targets, rotations)  # R_t^T R
    trace = relative[..., 0, 0] + relative[..., 1, 1] + relative[..., 2, 2]
    flipped = -relative[..., 0, 0] + relative[..., 1, 1] - relative[..., 2, 2]
    use_flip = flipped > trace
    return np.where(use_flip[..., None, None], targets @ JAW_FLIP, targets)


def rotation_errors(rotations: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(..., 3) world-frame rotation vectors (rad) that turn each hand rotation onto its nearer
    jaw-symmetric target (:func:`nearest_jaw_targets`): the action's rotation part, before
    scaling, that would align the hand in one step."""
    goal = nearest_jaw_targets(rotations, targets)
    return rotation_vector(goal @ np.swapaxes(rotations, -1, -2))


def state_vector(obs: Any, who: str = "DualGraspLift-v1 policy") -> np.ndarray:
    """The flat ``"state"`` vector (float64, (:data:`STATE_SIZE`,)) of a state, state_dict or
    pointcloud observation: the ``"state"`` entry of a dictionary, or the named parts of a
    state_dict in :data:`STATE_LAYOUT`'s order. ``ValueError`` naming ``who`` for anything
    else."""
    if isinstance(obs, Mapping):
        if "state" in obs:
            obs = obs["state"]
        else:
            missing = [name for name, _, _, _ in STATE_LAYOUT if name not in obs]
            if missing:
                raise ValueError(
                    f"{who}: expected a DualGraspLift-v1 observation ('state' vector or "
                    f"dictionary), found a dictionary without {missing[:3]}"
                )
            obs = np.concatenate([np.asarray(obs[name]).ravel() for name, _, _, _ in STATE_LAYOUT])
    state = np.asarray(obs, dtype=np.float64)
    if state.shape != (STATE_SIZE,):
        raise ValueError(
            f"{who}: expected a DualGraspLift-v1 state of shape ({STATE_SIZE},), found shape "
            f"{state.shape}"
        )
    return state


def goal_frames(states: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each hand's goal from ``(N, STATE_SIZE)`` states.

    Returns ``goal_rotations`` (N, 2, 3, 3): the target rotation or its jaw flip, whichever is
    nearer the commanded rotation (:func:`nearest_jaw_targets`); ``goal_centres`` (N, 2, 3): the
    target's grasp centre (m, world), ``contact_depth`` along its approach axis from the target
    flange; and the commanded ``centres`` (N, 2, 3) and ``rotations`` (N, 2, 3, 3) they were
    measured against.
    """
    n = len(states)
    command = states[:, STATE_SLICES["commanded_poses"]].reshape(n, 2, 9)
    rotations = rotation_from_6d(command[:, :, 3:])[0]
    target = states[:, STATE_SLICES["target_poses"]].reshape(n, 2, 9)
    goal_rotations = nearest_jaw_targets(rotations, rotation_from_6d(target[:, :, 3:])[0])
    goal_centres = target[:, :, :3] + PANDA.contact_depth * goal_rotations[:, :, :, 1]
    return goal_rotations, goal_centres, command[:, :, :3], rotations
