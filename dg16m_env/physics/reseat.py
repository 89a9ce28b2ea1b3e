"""Re-seating: move open hands that start inside the object back along their approach axis.

A DG16M release file stores poses of the Robotiq 2F-85; moved to the Panda hand's frame
(:func:`dg16m_env.benchmark.sources.retarget_poses`), many of them leave an open Panda hand inside one of
the object's convex parts, and the simulator refuses such a trial (INVALID, counted as a failure;
measured on the release airplane: 96 of 100 pairs). Re-seating is an option beyond the paper: each
hand whose open palm or fingers penetrate the object deeper than the protocol's
``invalid_penetration`` is moved back (along ``-approach``, the grasp frame's ``-y``: away from
the fingertips) in steps of ``step`` (1 mm) up to ``max_shift``, and kept at the first step where
it clears. A hand that cannot clear stays where it was (its trial stays invalid). The rule is the
simulator's own (:func:`dg16m_env.physics.trial.open_hand_penetration`, judged as
:func:`~dg16m_env.physics.trial.check_initial_poses` judges it), so a re-seated hand is exactly one the
trial accepts.

Re-seating changes the grasp: the fingers close further out along the approach axis than the
file's contacts. How many hands moved, and how far, is always reported (the benchmark stores each
hand's shift as ``grasps/reseat_shift``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # MuJoCo is imported by the functions, so the constants import cheaply
    from dg16m_env.physics.scene import Scene

RESEAT_STEP = 1e-3
"""Step of the search along ``-approach`` (m)."""

DEFAULT_RESEAT_MAX = 0.03
"""Default largest shift (m) of ``dg16m benchmark build --reseat``."""


def open_hand_depth(scene: Scene, grasps: np.ndarray) -> np.ndarray:
    """(N, 2) how deep each open hand (palm or either finger, whichever is deepest) sits in the
    object at ``grasps`` (m, >= 0). Hands do not collide with each other in the scene, so each
    hand's depth depends on its own pose only."""
    from dg16m_env.physics.trial_protocol import open_hand_penetration

    return open_hand_penetration(scene, grasps).max(axis=2)


def shift_back(grasps: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """``grasps`` (N, 2, 4, 4) with each hand moved by ``shift`` (N, 2) m along ``-approach``
    (its frame's ``-y``): a copy."""
    out = np.array(grasps, dtype=np.float64, copy=True)
    out[..., :3, 3] -= shift[..., None] * out[..., :3, 1]
    return out


@dataclass(frozen=True, eq=False)
class Reseat:
    """The result of :func:`reseat_poses` for N dual grasps.

    Attributes:
        poses: (N, 2, 4, 4) the poses after re-seating (unmoved hands are unchanged).
        shift: (N, 2) how far each hand moved back (m; 0 for hands not moved).
        depth_before: (N, 2) open-hand depth at the given poses (m).
        depth_after: (N, 2) open-hand depth at ``poses`` (m).
        max_shift: the largest shift tried (m).
        limit: the depth an open hand may have (the protocol's ``invalid_penetration``, m).
    """

    poses: np.ndarray
    shift: np.ndarray
    depth_before: np.ndarray
    depth_after: np.ndarray
    max_shift: float
    limit: float

    @property
    def moved(self) -> np.ndarray:
        """(N, 2) bool, True for the hands that moved."""
        return self.shift > 0

    @property
    def penetrating(self) -> np.ndarray:
        """(N, 2) bool, True for the hands deeper than ``limit`` before re-seating."""
        return self.depth_before > self.limit

    @property
    def not_cleared(self) -> np.ndarray:
        """(N, 2) bool, True for the hands still deeper than ``limit`` (they could not clear;
        not moved)."""
        return self.depth_after > self.limit

    def summary(self) -> dict[str, Any]:
        """JSON-ready counts: ``max_shift_m``, ``hands``, ``penetrating`` (before),
        ``not_cleared``, and :func:`shift_summary` of the moved hands."""
        return {
            "max_shift_m": float(self.max_shift),
            "hands": int(self.shift.size),
            "penetrating": int(self.penetrating.sum()),
            "not_cleared": int(self.not_cleared.sum()),
            **shift_summary(self.shift),
        }

    def __repr__(self) -> str:
        return (
            f"Reseat({len(self.shift)} dual grasps, {int(self.penetrating.sum())} hands "
            f"penetrating, {int(self.moved.sum())} moved, {int(self.not_cleared.sum())} not "
            f"cleared, max shift {1000 * self.max_shift:g} mm)"
        )


def shift_summary(shift: np.ndarray) -> dict[str, Any]:
    """How many hands moved and how far: ``{"moved", "median_m", "max_m"}`` over the hands
    with a positive ``shift`` (``None`` when none moved)."""
    values = np.asarray(shift, dtype=np.float64).ravel()
    values = values[values > 0]
    return {
        "moved": int(values.size),
        "median_m": float(np.median(values)) if values.size else None,
        "max_m": float(values.max()) if values.size else None,
    }


def reseat_poses(
    scene: Scene,
    grasps: np.ndarray,
    *,
    max_shift: float,
    limit: float,
    step: float = RESEAT_STEP,
) -> Reseat:
    """Move each open hand that penetrates the object deeper than ``limit`` back along its
    approach axis, ``step`` at a time up to ``max_shift``, to the first position where it
    clears (see the module docstring).

    Args:
        scene: the object's compiled scene (the geometry trials are judged against).
        grasps: (N, 2, 4, 4) Panda hand poses (object frame, m).
        max_shift: the largest shift (m, >= 0; 0 moves nothing).
        limit: allowed open-hand depth (m): the protocol's ``invalid_penetration``.
        step: search step (m, > 0).

    Raises:
        TrialError: malformed grasps or a bad ``max_shift`` / ``limit`` / ``step``.
    """
    from dg16m_env.physics.trial_protocol import TrialError, check_dual_grasps

    grasps = check_dual_grasps(grasps)
    for name, value, low in (("max_shift", max_shift, 0.0), ("limit", limit, 0.0)):
        if not (math.isfinite(value) and value >= low):
            raise TrialError(f"{name}: expected a finite number >= {low:g} m, found {value!r}")
    if not (math.isfinite(step) and step > 0):
        raise TrialError(f"step: expected a positive finite number of m, found {step!r}")
    depth = open_hand_depth(scene, grasps) if len(grasps) else np.zeros((0, 2))
    poses = grasps.copy()
    shift = np.zeros(depth.shape)
    after = depth.copy()
    pending = depth > limit
    for k in range(1, math.floor(max_shift / step + 1e-9) + 1):
        rows = np.flatnonzero(pending.any(axis=1))
        if not rows.size:
            break
        distance = round(k * step, 12)  # 0.018, not 0.018000000000000002
        tried = shift_back(grasps[rows], np.where(pending[rows], distance, 0.0))
        depth_k = open_hand_depth(scene, tried)
        cleared = pending[rows] & (depth_k <= limit)
        for hand in range(2):
            hit = rows[cleared[:, hand]]
            poses[hit, hand] = tried[cleared[:, hand], hand]
            shift[hit, hand] = distance
            after[hit, hand] = depth_k[cleared[:, hand], hand]
        pending[rows] &= ~cleared
    return Reseat(
        poses=poses,
        shift=shift,
        depth_before=depth,
        depth_after=after,
        max_shift=float(max_shift),
        limit=float(limit),
    )
