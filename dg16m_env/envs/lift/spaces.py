"""The spaces of ``dg16m_env/DualGraspLift-v0``: the observation vector's layout
(:data:`OBS_LAYOUT`, :data:`OBS_SLICES`, documented in :mod:`dg16m_env.envs.lift.v0`),
the action's size and scaling (:data:`MAX_TRANSLATION`, :data:`MAX_ROTATION`), and the rotation
helpers the task and its expert share (:func:`rotation_vector`).
"""

from __future__ import annotations

import mujoco
import numpy as np

MAX_TRANSLATION = 0.02
"""Largest translation of a hand's grasp centre per step and axis (m)."""

MAX_ROTATION = 0.1
"""Largest rotation-vector component of a hand per step (rad)."""

POSITION_BOUND = 5.0
"""Bound of position-like observations (m)."""

VELOCITY_BOUND = 50.0
"""Bound of velocity observations (m/s, rad/s)."""

OBS_LAYOUT: tuple[tuple[str, int, float, float], ...] = (
    ("object_position", 3, -POSITION_BOUND, POSITION_BOUND),
    ("object_rotation", 6, -1.0, 1.0),
    ("object_linear_velocity", 3, -VELOCITY_BOUND, VELOCITY_BOUND),
    ("object_angular_velocity", 3, -VELOCITY_BOUND, VELOCITY_BOUND),
    ("hand_poses", 18, -POSITION_BOUND, POSITION_BOUND),
    ("finger_openings", 2, 0.0, 1.0),
    ("grasp_centres", 6, -POSITION_BOUND, POSITION_BOUND),
    ("finger_contacts", 4, 0.0, 1.0),
    ("object_size", 3, 0.0, POSITION_BOUND),
    ("object_box_centre", 3, -POSITION_BOUND, POSITION_BOUND),
    ("lift", 1, -POSITION_BOUND, POSITION_BOUND),
    ("target_poses", 18, -POSITION_BOUND, POSITION_BOUND),
    ("target_flag", 1, 0.0, 1.0),
)


def layout_slices(layout: tuple[tuple[str, int, float, float], ...]) -> dict[str, slice]:
    """Name -> slice of a flat vector laid out as ``layout`` (name, size, low, high)."""
    out, start = {}, 0
    for name, size, _, _ in layout:
        out[name] = slice(start, start + size)
        start += size
    return out


OBS_SLICES: dict[str, slice] = layout_slices(OBS_LAYOUT)
"""Name -> slice of the observation vector (see the module docstring)."""

OBS_SIZE = sum(size for _, size, _, _ in OBS_LAYOUT)
"""Length of the observation vector (71)."""

ACTION_SIZE = 14
"""Length of the action vector: 7 per hand."""

MOTION_COMPONENTS = np.r_[0:6, 7:13]  # the action's motion components (not the finger forces)


# --------------------------------------------------------------------------------------------
# Small rotation helpers (numpy, no allocation-heavy libraries in the step loop)
# --------------------------------------------------------------------------------------------


def _right_matrix(q: np.ndarray) -> np.ndarray:
    """(4, 4) matrix ``M`` with ``p ⊗ q = M p`` for quaternions (w, x, y, z)."""
    w, x, y, z = q
    return np.array([[w, -x, -y, -z], [x, w, z, -y], [y, -z, w, x], [z, y, -x, w]])


def rotation_vector(rotations: np.ndarray) -> np.ndarray:
    """(..., 3) rotation vectors (axis * angle, rad) of (..., 3, 3) rotations."""
    rotations = np.asarray(rotations, dtype=np.float64)
    out = np.empty((*rotations.shape[:-2], 3))
    quat = np.empty(4)
    for index in np.ndindex(rotations.shape[:-2]):
        mujoco.mju_mat2Quat(quat, np.ascontiguousarray(rotations[index]).ravel())
        mujoco.mju_quat2Vel(out[index], quat, 1.0)
    return out


def check_lift_action(action: object, space: object) -> np.ndarray:
    """``action`` as a float64 (14,) array, or ``ValueError`` naming ``space`` and what was
    wrong: not an array of floats, another shape, NaN or inf, or a value outside [-1, 1]."""

    def bad(found: str) -> ValueError:
        return ValueError(
            f"action: expected an action in {space} (shape ({ACTION_SIZE},), "
            f"finite floats in [-1, 1]), found {found}"
        )

    if not isinstance(action, np.ndarray):
        try:
            action = np.asarray(action)
        except (TypeError, ValueError):
            raise bad(type(action).__name__) from None
    assert isinstance(action, np.ndarray)
    if action.dtype.kind != "f":
        raise bad(f"dtype {action.dtype}")
    if action.shape != (ACTION_SIZE,):
        raise bad(f"shape {action.shape}")
    values = action.astype(np.float64)
    if not np.abs(values).max() <= 1.0:  # False for NaN too
        broken = np.flatnonzero(~np.isfinite(values))
        if broken.size:
            raise bad(f"NaN or inf at index {broken.tolist()}")
        worst = int(np.argmax(np.abs(values)))
        raise bad(f"{values[worst]!r} at index {worst}")
    return values
