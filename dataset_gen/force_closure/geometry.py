"""Grasp-matrix geometry for four point contacts with friction (vectorised numpy).

The paper's grasp matrix stacks, per contact k, ``G_k = [R_k; [p_k]x R_k]`` (6x3), where ``R_k`` is
a contact frame whose z-axis is the friction cone's axis and ``p_k`` the contact point in the object
frame. Forces are solved in the object frame: with ``F_k = R_k f_k`` the wrench is
``sum_k [F_k; p_k x F_k]``, so ``G G^T`` (and hence rank, singular values and Q(G)) does not
depend on the choice of tangent axes in ``R_k``. We still build ``R_k`` deterministically (the
released code draws them from ``np.random``) so that :func:`grasp_matrix` is reproducible.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Below this condition-number bound of G (upper estimate) the rank test needs no SVD: the
#: smallest singular value is at least 1e-5 of the largest, far above numpy's rank tolerance
#: (``max(M, N) * eps`` = 2.7e-15 relative).
SAFE_CONDITION = 1e5


def contact_frames(axes: FloatArray) -> FloatArray:
    """Rotation matrices whose z-axis is each given unit cone axis.

    Args:
        axes: ``(..., 3)`` unit vectors (the friction-cone axes).

    Returns:
        ``(..., 3, 3)`` rotations ``R`` with columns ``(x, y, z)``, ``z = axis``. The x-axis is the
        cross product of the axis with the world axis it is least aligned with, so it is
        well conditioned and the same input gives the same bytes.
    """
    z = np.asarray(axes, dtype=np.float64)
    helper = np.zeros_like(z)
    least = np.argmin(np.abs(z), axis=-1)
    np.put_along_axis(helper, least[..., None], 1.0, axis=-1)
    x = np.cross(helper, z)
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=-1)


def skew(v: FloatArray) -> FloatArray:
    """Cross-product matrices ``[v]x`` of ``(..., 3)`` vectors, shape ``(..., 3, 3)``."""
    v = np.asarray(v, dtype=np.float64)
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def grasp_matrix(points: FloatArray, axes: FloatArray) -> FloatArray:
    """The paper's grasp matrices ``G = [G_1 .. G_4]``, ``G_k = [R_k; [p_k]x R_k]``.

    Args:
        points: ``(N, 4, 3)`` contact points in the object frame (m).
        axes: ``(N, 4, 3)`` unit friction-cone axes.

    Returns:
        ``(N, 6, 12)`` grasp matrices (forces in N, torques in N m about the object origin).
    """
    R = contact_frames(axes)  # (N, 4, 3, 3)
    top = R
    bottom = skew(points) @ R
    blocks = np.concatenate([top, bottom], axis=-2)  # (N, 4, 6, 3)
    return np.concatenate([blocks[:, k] for k in range(blocks.shape[1])], axis=-1)


def gram_matrix(points: FloatArray) -> FloatArray:
    """``G G^T`` for each pair, ``(N, 6, 6)``; independent of the cone axes.

    ``G G^T = sum_k [[I, -[p_k]x], [[p_k]x, -[p_k]x^2]]`` with ``[p]x^T = -[p]x``.
    """
    S = skew(points)  # (N, 4, 3, 3)
    n = points.shape[0]
    H = np.zeros((n, 6, 6))
    H[:, :3, :3] = points.shape[1] * np.eye(3)
    sum_s = S.sum(axis=1)
    H[:, :3, 3:] = -sum_s
    H[:, 3:, :3] = sum_s
    H[:, 3:, 3:] = -(S @ S).sum(axis=1)
    return H


def grasp_quality(points: FloatArray) -> FloatArray:
    """The paper's stability figure ``Q(G) = sqrt(det(G G^T))`` for each pair, ``(N,)``.

    Zero for rank-deficient grasps (collinear contacts); units N^3 m^3 in the paper's G.
    """
    det = np.linalg.det(gram_matrix(np.asarray(points, dtype=np.float64)))
    return np.sqrt(np.clip(det, 0.0, None))


def full_rank(points: FloatArray, axes: FloatArray) -> NDArray[np.bool_]:
    """Whether each grasp matrix has rank 6, exactly as ``numpy.linalg.matrix_rank(G) == 6``.

    A cheap, provably safe filter settles the clear cases: with ``H = G G^T``,
    ``sigma_max^2 <= trace(H)`` and ``sigma_min^2 >= 1 / trace(H^-1)``, so when the product of
    the two traces is below ``1e10`` the singular values are within a factor 1e5 and G has full
    rank with an enormous margin. Every other pair (near-collinear contacts, failed Cholesky) goes
    through ``numpy.linalg.matrix_rank`` on the same :func:`grasp_matrix` the docs define.

    Args:
        points: ``(N, 4, 3)`` contact points.
        axes: ``(N, 4, 3)`` unit cone axes.

    Returns:
        ``(N,)`` bool.
    """
    points = np.asarray(points, dtype=np.float64)
    axes = np.asarray(axes, dtype=np.float64)
    n = points.shape[0]
    ok = np.zeros(n, dtype=bool)
    if n == 0:
        return ok
    H = gram_matrix(points)
    trace_h = np.trace(H, axis1=1, axis2=2)
    clear = np.zeros(n, dtype=bool)
    # Batched Cholesky fails for the whole stack if one matrix is not positive definite, so
    # only well-scaled candidates (positive determinant) are inverted together.
    det = np.linalg.det(H)
    candidates = np.flatnonzero(det > 0)
    if candidates.size:
        try:
            inv = np.linalg.inv(H[candidates])
            trace_inv = np.trace(inv, axis1=1, axis2=2)
            bound = trace_h[candidates] * trace_inv
            good = np.isfinite(bound) & (trace_inv > 0) & (bound < SAFE_CONDITION**2)
            clear[candidates[good]] = True
        except np.linalg.LinAlgError:
            pass  # some matrix was singular: everything goes through the exact SVD test
    ok[clear] = True
    rest = np.flatnonzero(~clear)
    if rest.size:
        G = grasp_matrix(points[rest], axes[rest])
        ok[rest] = np.linalg.matrix_rank(G) == 6
    return ok


def project_cone_ball(forces: FloatArray, axes: FloatArray, mu: float, f_high: float) -> FloatArray:
    """Euclidean projection onto ``{F : ||F - (F.a)a|| <= mu F.a, ||F|| <= f_high}``.

    For a closed convex cone K and a ball B centred at its apex, ``P_{K∩B} = P_B ∘ P_K``.

    Args:
        forces: ``(..., 3)`` forces (N).
        axes: ``(..., 3)`` unit cone axes.
        mu: friction coefficient (cone half-angle ``atan(mu)``).
        f_high: force-norm bound (N).

    Returns:
        ``(..., 3)`` projected forces.
    """
    F = np.asarray(forces, dtype=np.float64)
    a = np.asarray(axes, dtype=np.float64)
    an = np.einsum("...i,...i->...", F, a)
    t = F - an[..., None] * a
    tn = np.linalg.norm(t, axis=-1)
    c = 1.0 / np.sqrt(1.0 + mu * mu)
    s = mu * c
    inside = tn <= mu * an
    polar = mu * tn <= -an
    scale = an * c + tn * s
    with np.errstate(invalid="ignore", divide="ignore"):
        direction = c * a + s * np.where(tn[..., None] > 0, t / tn[..., None], 0.0)
    out = np.where(inside[..., None], F, scale[..., None] * direction)
    out = np.where((polar & ~inside)[..., None], 0.0, out)
    norm = np.linalg.norm(out, axis=-1)
    shrink = np.where(norm > f_high, f_high / np.where(norm > 0, norm, 1.0), 1.0)
    return out * shrink[..., None]


def apply_grasp(points: FloatArray, forces: FloatArray) -> FloatArray:
    """Net wrench ``sum_k [F_k; p_k x F_k]`` of object-frame forces, ``(N, 6)``.

    Args:
        points: ``(N, 4, 3)`` contact points (m).
        forces: ``(N, 4, 3)`` contact forces in the object frame (N).
    """
    return np.concatenate([forces.sum(axis=1), np.cross(points, forces).sum(axis=1)], axis=-1)
