"""Surface actions of ``DualGraspPose-v0`` (``action_mode="surface"``): a hand placed on a point
of the observed cloud, approaching along its inward normal.

An action row ``[point, roll, depth]`` (each in ``[-1, 1]``) stands for one Panda hand pose
(grasp frame -> object frame, :mod:`dataset_gen.grasps.gripper`: ``+x`` closing axis, ``+y`` approach
axis, origin at the flange, grasp centre at ``contact_depth`` along ``+y``):

* ``point`` -> the valid point of height rank ``i = floor((point + 1) / 2 * n)`` clipped to
  ``[0, n - 1]``: the observation's ``n`` valid points (all ``P`` in ``obs_mode="full"``; those
  whose ``mask`` is 1 in ``obs_mode="partial"``) sorted by their height (object-frame ``z``,
  ascending; equal heights keep the observation's order), so ``point = -1`` is the lowest
  observed point and ``point = 1`` the highest (:func:`height_order`). The point ``q`` (m)
  and its outward normal ``n̂`` (unit after normalising) are the ones the agent saw at reset.
  Why heights: the observation's order is random (points drawn by area), so an index into it
  means nothing shared between objects; a height rank does (measured on the training objects:
  open hands that clear the object concentrate at family-specific heights, e.g. a table's legs
  at the bottom, a ladder's rungs in the middle).
* The approach axis is the inward normal: ``y = -n̂``. The closing axis before the roll, ``x0``,
  is the object frame's ``+z`` (up) projected on the plane normal to ``y`` and normalised; where
  the approach is within about 26 degrees of vertical (``|y_z| > VERTICAL_LIMIT``) the frame's
  ``+x`` projected instead.
* ``roll`` -> angle ``theta = pi * roll`` (rad), a right-handed turn about the approach axis:
  ``x = cos(theta) x0 + sin(theta) (y × x0)``, ``z = x × y`` (``roll = 0`` closes the fingers
  vertically on a side face; ``roll = ±0.5`` horizontally).
* ``depth`` -> the flange's standoff ``s`` (m) from ``q`` along ``n̂``, linear from
  :data:`STANDOFF_MIN` (``depth = -1``) to :data:`STANDOFF_MAX` (``depth = 1``): the flange at
  ``q + s n̂``, the grasp centre at ``q + (s - contact_depth) n̂``. For the Panda the range is the
  fingers' span: at ``STANDOFF_MIN = palm_depth`` (0.066 m) the palm face touches the tangent plane
  at ``q`` and the grasp centre lies 37.4 mm inside it; at ``STANDOFF_MAX = finger_tip``
  (0.1122 m) the fingertips touch the tangent plane; ``s = contact_depth`` (0.1034 m, ``depth``
  about 0.62) puts the grasp centre on ``q``.

A row whose normal is degenerate (not finite or shorter than :data:`MIN_NORMAL_NORM`), or whose
observation has no valid point, encodes no pose: the functions flag it in a validity mask (the
identity pose in its place) rather than raising, as in a hot loop.
"""

from __future__ import annotations

import numpy as np

from dataset_gen.grasps.gripper import PANDA

SURFACE_SIZE = 3
"""Numbers per hand in a surface action: point, roll, depth."""

STANDOFF_MIN = PANDA.palm_depth
"""Flange standoff (m) along the outward normal at ``depth = -1``: the palm face on the tangent
plane (grasp centre ``contact_depth - palm_depth`` = 37.4 mm inside the surface)."""

STANDOFF_MAX = PANDA.finger_tip
"""Flange standoff (m) at ``depth = 1``: the fingertips on the tangent plane (grasp centre
``finger_tip - contact_depth`` = 8.8 mm outside the surface)."""

MIN_NORMAL_NORM = 0.5
"""Shortest observed normal (unit by construction; padding is zero) that still gives an
approach axis."""

VERTICAL_LIMIT = 0.9
"""Approach axes with ``|y_z|`` above this take the object frame's ``+x``, not ``+z``, as the
closing axis before the roll."""

INVALID_NO_POINT = "no_valid_point"
"""``invalid_reason`` of a surface action on an observation without a valid point."""

INVALID_NORMAL = "degenerate_normal"
"""``invalid_reason`` of a surface action whose chosen point has a degenerate normal."""


def surface_action_bounds(n_hands: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)`` float32 arrays of shape (n_hands, 3) of a surface action: -1 and 1."""
    high = np.ones((n_hands, SURFACE_SIZE), dtype=np.float32)
    return -high, high


def point_indices(point: np.ndarray, n_valid: int) -> np.ndarray:
    """(...,) ``point`` values in [-1, 1] -> (...,) int64 ranks among ``n_valid`` points:
    ``floor((point + 1) / 2 * n_valid)`` clipped to ``[0, n_valid - 1]``; -1 everywhere when
    ``n_valid`` is 0. NaN maps to 0 (actions are checked before this)."""
    point = np.nan_to_num(np.asarray(point, dtype=np.float64))
    if n_valid <= 0:
        return np.full(point.shape, -1, dtype=np.int64)
    index = np.floor((point + 1.0) / 2.0 * n_valid)
    return np.clip(index, 0, n_valid - 1).astype(np.int64)


def height_order(points: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """(n,) int64 indices into ``points`` (P, 3) of the valid points (``mask`` (P,) > 0.5, all
    when None), sorted by height ``points[:, 2]`` ascending (a stable sort: equal heights keep
    their order). Non-finite heights sort last."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    real = np.ones(len(points), dtype=bool) if mask is None else np.asarray(mask).reshape(-1) > 0.5
    candidates = np.flatnonzero(real)
    heights = np.nan_to_num(points[candidates, 2], nan=np.inf)
    return candidates[np.argsort(heights, kind="stable")].astype(np.int64)


def roll_angles(roll: np.ndarray) -> np.ndarray:
    """(...,) ``roll`` in [-1, 1] -> (...,) angles ``pi * roll`` (rad) about the approach axis."""
    return np.pi * np.asarray(roll, dtype=np.float64)


def standoffs(depth: np.ndarray) -> np.ndarray:
    """(...,) ``depth`` in [-1, 1] -> (...,) flange standoffs (m) along the outward normal,
    linear from :data:`STANDOFF_MIN` (-1) to :data:`STANDOFF_MAX` (1)."""
    depth = np.asarray(depth, dtype=np.float64)
    return STANDOFF_MIN + (depth + 1.0) / 2.0 * (STANDOFF_MAX - STANDOFF_MIN)


def approach_rotations(normals: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grasp-frame rotations approaching along the inward normals, turned by ``angles``.

    Args:
        normals: (..., 3) outward normals (any length; normalised here).
        angles: (...,) roll angles (rad) about the approach axis.

    Returns:
        ``rotations`` (..., 3, 3) with columns ``x`` (closing), ``y = -n̂`` (approach),
        ``z = x × y`` (see the module docstring), and ``valid`` (...,) bool: the normal is finite
        and at least :data:`MIN_NORMAL_NORM` long. Invalid rows get the identity.
    """
    normals = np.asarray(normals, dtype=np.float64)
    angles = np.asarray(angles, dtype=np.float64)
    length = np.linalg.norm(np.nan_to_num(normals, nan=0.0, posinf=0.0, neginf=0.0), axis=-1)
    valid = np.isfinite(normals).all(axis=-1) & (length >= MIN_NORMAL_NORM)
    valid &= np.isfinite(angles)
    safe = np.where(valid[..., None], normals, [0.0, 0.0, 1.0])
    y = -safe / np.linalg.norm(safe, axis=-1, keepdims=True)
    vertical = np.abs(y[..., 2]) > VERTICAL_LIMIT
    reference = np.where(vertical[..., None], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    x0 = reference - np.sum(reference * y, axis=-1, keepdims=True) * y
    x0 /= np.linalg.norm(x0, axis=-1, keepdims=True)  # >= sqrt(1 - 0.9^2) > 0.43
    theta = np.where(valid, angles, 0.0)[..., None]
    x = np.cos(theta) * x0 + np.sin(theta) * np.cross(y, x0)  # Rodrigues, x0 ⟂ y
    rotations = np.stack([x, y, np.cross(x, y)], axis=-1)
    rotations[~valid] = np.eye(3)
    return rotations, valid


def surface_poses(
    points: np.ndarray,
    normals: np.ndarray,
    angles: np.ndarray,
    standoff: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Hand poses on surface points.

    Args:
        points: (..., 3) surface points (m, object frame).
        normals: (..., 3) their outward normals.
        angles: (...,) roll angles (rad).
        standoff: (...,) flange standoffs (m) along the unit outward normal.

    Returns:
        ``poses`` (..., 4, 4) grasp frame -> object frame, flange at ``q + s n̂``, and ``valid``
        (...,) (:func:`approach_rotations`; a non-finite point or standoff is invalid too).
        Invalid rows get the identity pose.
    """
    points = np.asarray(points, dtype=np.float64)
    standoff = np.asarray(standoff, dtype=np.float64)
    rotations, valid = approach_rotations(normals, angles)
    valid &= np.isfinite(points).all(axis=-1) & np.isfinite(standoff)
    flange = points - standoff[..., None] * rotations[..., :, 1]  # y = -n̂
    poses = np.zeros((*valid.shape, 4, 4))
    poses[..., :3, :3] = rotations
    poses[..., :3, 3] = np.where(valid[..., None], flange, 0.0)
    poses[..., 3, 3] = 1.0
    poses[~valid] = np.eye(4)
    return poses, valid


def poses_from_surface_action(
    action: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    mask: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str | None]]:
    """Surface action rows -> hand poses (see the module docstring).

    Args:
        action: (H, 3) rows ``[point, roll, depth]`` in [-1, 1].
        points: (P, 3) the observed cloud (m, object frame).
        normals: (P, 3) its outward normals.
        mask: (P,) 1 for a real point, 0 for padding (None: every point is real).

    Returns:
        ``poses`` (H, 4, 4), ``valid`` (H,) bool, ``indices`` (H,) int64 (the chosen point's
        index into ``points``, -1 when there is none) and ``reasons`` (H,): None for a valid
        row, else :data:`INVALID_NO_POINT` or :data:`INVALID_NORMAL`.
    """
    action = np.asarray(action, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    candidates = height_order(points, mask)
    chosen = point_indices(action[:, 0], candidates.size)
    has_point = chosen >= 0
    indices = candidates[chosen] if candidates.size else chosen  # (H,), -1 without points
    q = points[indices] if candidates.size else np.zeros((len(action), 3))
    n = normals[indices] if candidates.size else np.zeros((len(action), 3))
    poses, valid = surface_poses(q, n, roll_angles(action[:, 1]), standoffs(action[:, 2]))
    valid &= has_point
    poses[~valid] = np.eye(4)
    reasons: list[str | None] = [
        None if ok else (INVALID_NORMAL if found else INVALID_NO_POINT)
        for ok, found in zip(valid.tolist(), has_point.tolist(), strict=True)
    ]
    return poses, valid, np.asarray(indices, dtype=np.int64), reasons


__all__ = [
    "INVALID_NORMAL",
    "INVALID_NO_POINT",
    "MIN_NORMAL_NORM",
    "STANDOFF_MAX",
    "STANDOFF_MIN",
    "SURFACE_SIZE",
    "VERTICAL_LIMIT",
    "approach_rotations",
    "height_order",
    "point_indices",
    "poses_from_surface_action",
    "roll_angles",
    "standoffs",
    "surface_action_bounds",
    "surface_poses",
]
