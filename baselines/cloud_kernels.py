"""Compiled loops of the cloud grasp sampler (:mod:`baselines.cloud_grasps`): each visits every
(hand or seed, cloud point) pair once, in point order, without the flat lists of (hand, point)
entries a k-d tree search hands to numpy, and a hand's collision test stops at its first hit.

On a small object every point lies within reach of every hand, and the flat lists held millions
of entries per object; these loops hold none. Each computes what the numpy code it replaced
computed, with the same tests on the same coordinates (a point's in a hand's frame are
``R[0, i] v0 + R[1, i] v1 + R[2, i] v2`` for ``v = p - t``), summed in index order where
numpy's ``einsum`` sums in an order its vector instructions choose: the values agree to the
last place or two, the choices (which points, which hands, which partner) are the same
(``tests/test_cloud_search.py`` checks each against the numpy code; ``BENCHMARKS.md`` records
the predictors' outputs before and after on both benchmarks). Units: metres; poses are the
dg16m grasp frame (grasp frame -> object frame).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _in_hand(r: np.ndarray, axis: int, v0: float, v1: float, v2: float) -> float:
    """The coordinate along the hand's ``axis`` (0: closing ``x``, 1: approach ``y``, 2: ``z``)
    of a point at ``(v0, v1, v2)`` from the hand's origin, ``r`` the hand's rotation: the sum
    in index order, ``R[0, axis] v0 + R[1, axis] v1 + R[2, axis] v2``."""
    return r[0, axis] * v0 + r[1, axis] * v1 + r[2, axis] * v2


@njit(cache=True)
def hands_hit_points(
    points: np.ndarray,
    poses: np.ndarray,
    contact_x: np.ndarray,
    palm_lo: np.ndarray,
    palm_hi: np.ndarray,
    foot_y: np.ndarray,
    half_z: float,
    outer: float,
    tolerance: float,
) -> np.ndarray:
    """(N,) bool: a point lies in a hand's palm or finger volumes
    (:func:`baselines.cloud_hand.hand_hits_cloud`'s test).

    Args:
        points: (P, 3) float64 cloud points. poses: (N, 4, 4) float64 hands.
        contact_x: (N, 2) float64 the fingers' contact ``x`` in each hand's frame.
        palm_lo, palm_hi: (3,) the palm box (already grown or shrunk), open bounds.
        foot_y: (2,) the fingers' footprint along ``y``, closed bounds; ``half_z`` its half
            width along ``z``; ``outer`` the open fingers' outer faces along ``x``.
        tolerance: how far a point may reach past a finger's contact.
    """
    n = poses.shape[0]
    hit = np.zeros(n, dtype=np.bool_)
    y_lo = min(palm_lo[1], foot_y[0])
    y_hi = max(palm_hi[1], foot_y[1])
    for h in range(n):
        r = poses[h, :3, :3]
        t0, t1, t2 = poses[h, 0, 3], poses[h, 1, 3], poses[h, 2, 3]
        x0 = contact_x[h, 0] + tolerance
        x1 = contact_x[h, 1] - tolerance
        for j in range(points.shape[0]):
            v0 = points[j, 0] - t0
            v1 = points[j, 1] - t1
            v2 = points[j, 2] - t2
            gy = _in_hand(r, 1, v0, v1, v2)
            if gy < y_lo or gy > y_hi:
                continue
            gz = _in_hand(r, 2, v0, v1, v2)
            gx = _in_hand(r, 0, v0, v1, v2)
            in_palm = (
                gx > palm_lo[0]
                and gx < palm_hi[0]
                and gy > palm_lo[1]
                and gy < palm_hi[1]
                and gz > palm_lo[2]
                and gz < palm_hi[2]
            )
            if in_palm:
                hit[h] = True
                break
            in_foot = gy >= foot_y[0] and gy <= foot_y[1] and abs(gz) <= half_z
            if in_foot and ((gx > x0 and gx <= outer) or (gx < x1 and gx >= -outer)):
                hit[h] = True
                break
    return hit


@njit(cache=True)
def held_extremes(
    points: np.ndarray,
    poses: np.ndarray,
    y_lo: float,
    y_hi: float,
    half_z: float,
    half_x: float,
) -> tuple[np.ndarray, np.ndarray]:
    """What each hand's jaws would hold (:func:`baselines.cloud_enclosing.enclose`'s test): the
    points with ``y_lo <= y <= y_hi``, ``|z| <= half_z``, ``|x| <= half_x`` in the hand's frame;
    ``(index (N, 2), local_x (N, 2))``: the last point (in cloud order) at the largest ``x``
    and the first at the smallest, -1 and 0 where fewer than two points are held."""
    n = poses.shape[0]
    index = np.full((n, 2), -1, dtype=np.int64)
    local_x = np.zeros((n, 2))
    for h in range(n):
        r = poses[h, :3, :3]
        t0, t1, t2 = poses[h, 0, 3], poses[h, 1, 3], poses[h, 2, 3]
        count = 0
        top = bottom = -1
        top_x = bottom_x = 0.0
        for j in range(points.shape[0]):
            v0 = points[j, 0] - t0
            v1 = points[j, 1] - t1
            v2 = points[j, 2] - t2
            gy = _in_hand(r, 1, v0, v1, v2)
            if gy < y_lo or gy > y_hi:
                continue
            gz = _in_hand(r, 2, v0, v1, v2)
            if abs(gz) > half_z:
                continue
            gx = _in_hand(r, 0, v0, v1, v2)
            if abs(gx) > half_x:
                continue
            if count == 0 or gx >= top_x:
                top, top_x = j, gx
            if count == 0 or gx < bottom_x:
                bottom, bottom_x = j, gx
            count += 1
        if count >= 2:
            index[h, 0], index[h, 1] = top, bottom
            local_x[h, 0], local_x[h, 1] = top_x, bottom_x
    return index, local_x


@njit(cache=True)
def best_partners(
    points: np.ndarray,
    normals: np.ndarray,
    seeds: np.ndarray,
    cos_cone: float,
    min_width: float,
    max_width: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Each seed's most antipodal partner (:func:`baselines.cloud_grasps.cloud_contact_pairs`'s
    step before duplicates are dropped): the point ``j`` with ``min_width < |d| <= max_width``
    (``d = p_j - p_seed``) whose smaller cone cosine ``min(-d . n_seed, d . n_j) / |d|`` is
    largest and at least ``cos_cone``, the lowest ``j`` among equals; ``(partner (S,),
    cosine (S,))``, -1 and 0 for a seed without one."""
    s_count = seeds.shape[0]
    partner = np.full(s_count, -1, dtype=np.int64)
    cosine = np.zeros(s_count)
    for s in range(s_count):
        i = seeds[s]
        p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
        m0, m1, m2 = normals[i, 0], normals[i, 1], normals[i, 2]
        best = -np.inf
        for j in range(points.shape[0]):
            d0 = points[j, 0] - p0
            d1 = points[j, 1] - p1
            d2 = points[j, 2] - p2
            dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if not (dist > min_width and dist <= max_width):
                continue
            cos0 = -(d0 * m0 + d1 * m1 + d2 * m2) / dist
            cos1 = (d0 * normals[j, 0] + d1 * normals[j, 1] + d2 * normals[j, 2]) / dist
            both = min(cos0, cos1)
            if both >= cos_cone and both > best:
                best = both
                partner[s] = j
        if partner[s] >= 0:
            cosine[s] = best
    return partner, cosine


__all__ = ["best_partners", "hands_hit_points", "held_extremes"]
