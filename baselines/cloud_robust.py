"""The robust criterion (:mod:`dataset_gen.grasps.robust`) on dual candidates sampled on a point cloud.

The paper's check keeps a dual grasp whose four point contacts cancel gravity at the centre of
mass. Two parallel-jaw grasps are weak against turning about the line joining the hands, which
that check does not see and the benchmark's sideways pushes and twists do: on the shipped
procedural benchmark, passing pairs whose disturbance motion ratio is at most 1 hold with a mean
success probability of 0.978 against 0.570 for the other passing pairs (``BENCHMARKS.md``, "The
robust criterion"). :func:`robust_first` gives a predictor that sees only a cloud the same
criterion: it ranks candidates whose cloud contacts pass it above the others, then the nearly
robust ones level by level (:data:`MOTION_RATIO_LEVELS`: success falls as the ratio grows),
without changing the order within each level.

What the criterion needs besides the contacts is the object's mass properties, which a cloud does
not carry:

* the **centre of mass** is the observation frame's origin (the benchmark's object frame is
  centred at the centre of mass, :mod:`dg16m_env.subjects.observation`), the same assumption as the
  cloud force-closure check (:func:`baselines.cloud_predictor.cloud_force_closure`);
* the **inertia** is estimated by :func:`cloud_inertia`: a solid of uniform density filling the
  cloud's convex hull, scaled to the paper's 6 kg. It is a guess: a completed cloud
  (:mod:`baselines.shape_completion`) has about the object's hull, but the object's own mass
  sits elsewhere in it (a thin-walled tub's farther out, so its inertia is larger and the
  estimate stricter than the truth). The angular part of the ratio scales with the inverse
  inertia, so an error of x% moves it by at most about x%; the levels of
  :data:`MOTION_RATIO_LEVELS`, not one cut, keep such a shift from deciding a rank alone.

The ratio costs 13 force-closure solves per candidate (about 0.5 ms), so :func:`robust_first`
evaluates the passing candidates in descending score order, a chunk at a time, and stops as soon
as no candidate not yet evaluated could reach the top ``k``: the result is the one of evaluating
every candidate, at a fraction of the cost.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import QhullError

from baselines.cloud_grasps import CloudError, DualCandidates
from dataset_gen.grasps.robust import disturbance_motion
from dg16m_core.checks import check_integer, check_number
from dg16m_core.parameters import PAPER

ROBUST_CHUNK = 64
"""Candidates per call of :func:`dataset_gen.grasps.robust.disturbance_motion` in :func:`robust_first`."""

MOTION_RATIO_LEVELS = (1.0, 2.0, 4.0)
"""Default levels of :func:`robust_first`: robust (the protocol's bounds), then within twice and
four times them. On the shipped procedural benchmark, passing pairs hold with mean success 0.98
up to ratio 1, then 0.85 (1-2), 0.63 (2-4) and 0.38 beyond (``BENCHMARKS.md``)."""

MIN_SIDE = 0.01
"""Smallest side of the box that stands in for a cloud without a solid hull (m)."""


def cloud_inertia(points: np.ndarray, mass: float = PAPER.mass) -> np.ndarray:
    """(3, 3) inertia (kg m^2) of a solid of uniform density and total ``mass`` (kg) filling the
    convex hull of ``points`` (P, 3) (m), about its own centre of mass, object-frame axes.

    A cloud without a solid hull (fewer than four points off one plane) stands in as the solid
    box of its axis-aligned bounds, each side at least :data:`MIN_SIDE`.

    Raises:
        CloudError: ``points`` not (P, 3) with P >= 1, non-finite values, or a mass that is not
            a positive finite number.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or points.shape[0] < 1:
        raise CloudError(f"points: expected shape (P, 3) with P >= 1, found {points.shape}")
    if not np.all(np.isfinite(points)):
        raise CloudError("points: expected finite values, found NaN or inf")
    mass = check_number("mass", mass, error=CloudError)
    centred = points - points.mean(axis=0)
    solid = points.shape[0] >= 4 and np.linalg.svd(centred, compute_uv=False)[-1] > 1e-9
    if solid:
        try:
            hull = trimesh.convex.convex_hull(points)
        except QhullError:  # numerically flat after all: no solid
            hull = None
        if hull is not None and hull.volume > 1e-12:
            return np.asarray(hull.moment_inertia) * (mass / hull.mass)
    side = np.maximum(np.ptp(points, axis=0), MIN_SIDE)
    squares = side**2
    return np.diag(mass / 12.0 * (squares.sum() - squares))


def check_ratio_levels(max_ratios: Sequence[float]) -> np.ndarray:
    """(L,) float64 ``max_ratios`` once checked: a non-empty ascending sequence of distinct
    positive finite numbers.

    Raises:
        CloudError: anything else.
    """
    try:
        levels = np.asarray(max_ratios, dtype=np.float64)
    except (TypeError, ValueError):
        levels = np.zeros(0)
    if (
        levels.ndim != 1
        or levels.size == 0
        or not np.all(np.isfinite(levels))
        or np.any(levels <= 0)
        or np.any(np.diff(levels) <= 0)
    ):
        raise CloudError(
            "max_ratios: expected an ascending sequence of distinct positive finite numbers, "
            f"found {max_ratios!r}"
        )
    return levels


@dataclass(frozen=True)
class RobustRanking:
    """What :func:`robust_first` decided for N candidates.

    Attributes:
        scores: (N,) the input scores plus each candidate's gain (``bonus`` for a robust one).
        robust: (N,) bool: the candidate passed force closure on the cloud and its motion ratio
            is at most ``max_ratios[0]``.
        ratio: (N,) the motion ratio where it was computed, NaN elsewhere (``inf`` for
            rank-deficient contacts).
        evaluated: how many ratios were computed.
    """

    scores: np.ndarray
    robust: np.ndarray
    ratio: np.ndarray
    evaluated: int


def robust_first(
    scores: np.ndarray,
    passed: np.ndarray,
    contact_points: np.ndarray,
    contact_normals: np.ndarray,
    *,
    k: int,
    bonus: float,
    inertia: np.ndarray,
    max_ratios: Sequence[float] = MOTION_RATIO_LEVELS,
    chunk_size: int = ROBUST_CHUNK,
) -> RobustRanking:
    """Rank passing candidates by their disturbance motion ratio
    (:func:`dataset_gen.grasps.robust.disturbance_motion`: the paper's mass, friction, force bound and
    threshold, the protocol's loads; centre of mass at the origin) before their scores: each
    candidate gains ``bonus / len(max_ratios)`` for every level of ``max_ratios`` its ratio is
    within, so a robust candidate (ratio <= ``max_ratios[0]``) gains ``bonus`` and ranks first,
    then the nearly robust ones level by level; ratios are computed only where the top ``k`` of
    the new scores could depend on them.

    Passing candidates are evaluated in descending ``scores`` (ties in index order), a chunk at a
    time; the loop stops once the ``k``-th best new score is above the best score a candidate not
    yet evaluated could reach (its score plus ``bonus``). The top ``k`` of the returned scores are
    then those of evaluating every passing candidate.

    Args:
        scores: (N,) float scores (higher = better).
        passed: (N,) bool: force closure on the cloud (only these gain).
        contact_points, contact_normals: (N, 4, 3) the candidates' cloud contacts (object frame,
            m) and unit outward normals.
        k: the number of candidates that will be kept (>= 1).
        bonus: what a robust candidate gains (> 0; above the spread of ``scores`` within a
            group for the levels to order first).
        inertia: (3, 3) kg m^2 about the centre of mass (:func:`cloud_inertia`).
        max_ratios: ascending positive motion ratios; the first is the robust criterion's bound
            (1: the protocol's bounds).
        chunk_size: candidates per batched solve.

    Raises:
        CloudError: shapes other than documented, or bad ``k``, ``bonus``, ``max_ratios``.
        dataset_gen.grasps.robust.RobustError: an inertia that is not a finite (3, 3) positive
            definite matrix.
    """
    scores = np.asarray(scores, dtype=np.float64)
    passed = np.asarray(passed, dtype=bool)
    contact_points = np.asarray(contact_points, dtype=np.float64)
    contact_normals = np.asarray(contact_normals, dtype=np.float64)
    n = scores.shape[0] if scores.ndim else 0
    if scores.ndim != 1 or passed.shape != (n,):
        raise CloudError(
            f"scores, passed: expected shapes (N,) and (N,), found {scores.shape} and "
            f"{passed.shape}"
        )
    if contact_points.shape != (n, 4, 3) or contact_normals.shape != (n, 4, 3):
        raise CloudError(
            f"contacts: expected points and normals of shape ({n}, 4, 3), found "
            f"{contact_points.shape} and {contact_normals.shape}"
        )
    check_integer("k", k, minimum=1, error=CloudError)
    check_integer("chunk_size", chunk_size, minimum=1, error=CloudError)
    bonus = check_number("bonus", bonus, error=CloudError)
    levels = check_ratio_levels(max_ratios)
    step = bonus / len(levels)
    order = np.flatnonzero(passed)
    order = order[np.argsort(-scores[order], kind="stable")]
    robust = np.zeros(n, dtype=bool)
    ratio = np.full(n, np.nan)
    new = scores.copy()
    evaluated = 0
    while evaluated < order.size:
        rows = order[evaluated : evaluated + chunk_size]
        motion = disturbance_motion(
            contact_points[rows],
            contact_normals[rows],
            center_of_mass=np.zeros(3),
            inertia=inertia,
        )  # the paper's mass, gravity, mu, f_high and threshold: its defaults
        ratio[rows] = motion.ratio
        robust[rows] = motion.ratio <= levels[0]
        within = (motion.ratio[:, None] <= levels[None, :]).sum(axis=1)
        new[rows] = scores[rows] + step * within
        evaluated += rows.size
        if evaluated < order.size and n >= k:
            kth = np.partition(new, n - k)[n - k]
            if kth > scores[order[evaluated]] + bonus:
                break
    return RobustRanking(scores=new, robust=robust, ratio=ratio, evaluated=evaluated)


def candidates_robust_first(
    scores: np.ndarray,
    passed: np.ndarray,
    candidates: DualCandidates,
    cloud_points: np.ndarray,
    *,
    k: int,
    bonus: float,
    max_ratios: Sequence[float] = MOTION_RATIO_LEVELS,
) -> np.ndarray:
    """(N,) :func:`robust_first`'s new scores of dual ``candidates`` on a cloud: their cloud
    contacts, the centre of mass at the origin, the inertia of a solid filling the hull of
    ``cloud_points`` (P, 3) (m) at the paper's mass (:func:`cloud_inertia`)."""
    return robust_first(
        scores,
        passed,
        candidates.contact_points,
        candidates.contact_normals,
        k=k,
        bonus=bonus,
        inertia=cloud_inertia(cloud_points),
        max_ratios=max_ratios,
    ).scores


__all__ = [
    "MIN_SIDE",
    "MOTION_RATIO_LEVELS",
    "ROBUST_CHUNK",
    "RobustRanking",
    "candidates_robust_first",
    "check_ratio_levels",
    "cloud_inertia",
    "robust_first",
]
