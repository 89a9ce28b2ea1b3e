"""Hand poses as actions: a position and a continuous 6D rotation, in bounded ranges.

A hand pose (dg16m grasp frame -> object frame) is encoded as 9 numbers: the position ``p``
(m, object frame) and the first two columns of the rotation matrix, ``a = R[:, 0]`` (the closing
axis) and ``b = R[:, 1]`` (the approach axis) (Zhou et al., "On the continuity of rotation
representations in neural networks", CVPR 2019). Decoding orthonormalises them (Gram-Schmidt):
``x = a / |a|``, ``y = (b - (b . x) x) / |.|``, ``z = x × y``. Encoding a rotation and decoding
it gives it back exactly (up to rounding).

Ranges of an action row ``[p (3), a (3), b (3)]``: ``p`` in ``[-POSITION_LIMIT, POSITION_LIMIT]``
m, ``a`` and ``b`` in ``[-1, 1]``. A row whose ``a`` or ``b`` is (nearly) zero or whose ``a`` and
``b`` are (nearly) parallel encodes no rotation: :func:`poses_from_action` flags it invalid
rather than raising (a validity mask, as in a hot loop).
"""

from __future__ import annotations

import numpy as np

POSITION_LIMIT = 1.0
"""Largest absolute hand position coordinate of an action (m, object frame)."""

POSE_SIZE = 9
"""Numbers per hand pose in an action: position (3), rotation columns a (3) and b (3)."""

MIN_AXIS_NORM = 1e-3
"""Smallest norm of ``a``, and of ``b`` minus its projection on ``a``, that still encodes an
axis (an action row below it is invalid)."""


def rotation_to_6d(rotations: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations -> (..., 6): the first two columns, ``[R[:, 0], R[:, 1]]``."""
    rotations = np.asarray(rotations, dtype=np.float64)
    return np.concatenate([rotations[..., :, 0], rotations[..., :, 1]], axis=-1)


def rotation_from_6d(six: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(..., 6) -> rotations (..., 3, 3) and a validity mask (...,) (see the module docstring);
    invalid rows get the identity."""
    six = np.asarray(six, dtype=np.float64)
    a, b = six[..., :3], six[..., 3:6]
    na = np.linalg.norm(a, axis=-1, keepdims=True)
    x = a / np.maximum(na, MIN_AXIS_NORM)
    b_perp = b - np.sum(b * x, axis=-1, keepdims=True) * x
    nb = np.linalg.norm(b_perp, axis=-1, keepdims=True)
    y = b_perp / np.maximum(nb, MIN_AXIS_NORM)
    valid = (na[..., 0] >= MIN_AXIS_NORM) & (nb[..., 0] >= MIN_AXIS_NORM)
    valid &= np.isfinite(six).all(axis=-1)
    z = np.cross(x, y)
    rotations = np.stack([x, y, z], axis=-1)
    rotations[~valid] = np.eye(3)
    return rotations, valid


def action_from_poses(poses: np.ndarray) -> np.ndarray:
    """(..., 4, 4) hand poses -> (..., 9) action rows ``[p, a, b]`` (float32 is the caller's
    choice; this returns float64)."""
    poses = np.asarray(poses, dtype=np.float64)
    return np.concatenate([poses[..., :3, 3], rotation_to_6d(poses[..., :3, :3])], axis=-1)


def poses_from_action(action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(..., 9) action rows -> hand poses (..., 4, 4) and a validity mask (...,).

    A row is valid when it encodes a rotation and its position is finite and within
    ``POSITION_LIMIT``; invalid rows get the identity pose.
    """
    action = np.asarray(action, dtype=np.float64)
    rotations, valid = rotation_from_6d(action[..., 3:9])
    position = action[..., :3]
    valid &= np.isfinite(position).all(axis=-1)
    valid &= (np.abs(np.nan_to_num(position, nan=np.inf)) <= POSITION_LIMIT + 1e-6).all(axis=-1)
    poses = np.zeros((*action.shape[:-1], 4, 4))
    poses[..., :3, :3] = rotations
    poses[..., :3, 3] = np.where(valid[..., None], position, 0.0)
    poses[..., 3, 3] = 1.0
    return poses, valid


def pose_action_bounds(n_hands: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)`` float32 arrays of shape (n_hands, 9) of a pose action."""
    high = np.array([POSITION_LIMIT] * 3 + [1.0] * 6, dtype=np.float32)
    high = np.tile(high, (n_hands, 1))
    return -high, high
