"""Fast path: a batched, compiled first-order method with certificates in both directions.

For one pair (contact points ``p_k``, unit cone axes ``a_k``) and one external wrench ``w`` the loss
is ``L = min_{F in C} ||G F + w||`` with ``C = prod_k (K_k ∩ B)``, ``K_k`` the friction cone about
``a_k`` and ``B`` the ball of radius ``f_high``. Forces are object-frame 3-vectors, so
``G F = sum_k [F_k; p_k x F_k]``.

Phase 1 (verdict). Accelerated projected gradient (FISTA with gradient restart) on
``h(F) = 1/2 ||G F + w||^2_M`` with ``M = (G G^T)^-1``. The Hessian ``G^T M G`` is the orthogonal
projector onto G's row space, so the Lipschitz constant is exactly 1 and a unit step is the
projection onto the affine set ``{G F = -w}``: the method is accelerated alternating projection
between that set and ``C``, and it is as well conditioned as the problem allows. ``h`` has the same
zero set as the loss, so it decides the verdict; the certificates are on the true loss:

* PASS when the (exactly feasible) iterate has ``||G F + w|| <= threshold * (1 - margin)``.
* FAIL when a dual bound proves ``L > threshold * (1 + margin)``. For ``||y|| <= 1``,
  ``L >= y.w + sum_k min_{f in K_k ∩ B} (G_k^T y).f`` and
  ``min_{f in K ∩ B} c.f = -f_high ||P_K(-c)||``. We try ``y = r/||r||`` and ``y = M r/||M r||``
  with ``r`` the current residual; the second is exact at the optimum of ``h``.

Phase 2 (loss, failing pairs only). FISTA on the plain ``1/2 ||G F + w||^2`` (step
``1/lambda_max(G G^T)``) from the phase-1 point until upper and lower bounds on L agree to
``loss_rtol * L + loss_atol``; the reported loss is the upper bound (attained by the returned
forces) and the lower bound is returned too.

Pairs decided by neither certificate within ``max_iterations`` are reported undecided; the caller
sends them to the Clarabel reference solver.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .geometry import FloatArray

UNDECIDED = 0
CERTIFIED_PASS = 1
CERTIFIED_FAIL = 2


@njit(cache=True, inline="always")
def _matvec6(M, v, out):
    """out = M v for a 6x6 matrix."""
    for a in range(6):
        acc = 0.0
        for b in range(6):
            acc += M[a, b] * v[b]
        out[a] = acc


@njit(cache=True, inline="always")
def _norm6(v):
    """Euclidean norm of a length-6 vector."""
    total = 0.0
    for a in range(6):
        total += v[a] * v[a]
    return math.sqrt(total)


@njit(cache=True, inline="always")
def _apply_g(P, i, F, w, out):
    """out = G F + w for pair i."""
    for j in range(6):
        out[j] = w[j]
    for k in range(4):
        fx = F[3 * k]
        fy = F[3 * k + 1]
        fz = F[3 * k + 2]
        px = P[i, k, 0]
        py = P[i, k, 1]
        pz = P[i, k, 2]
        out[0] += fx
        out[1] += fy
        out[2] += fz
        out[3] += py * fz - pz * fy
        out[4] += pz * fx - px * fz
        out[5] += px * fy - py * fx


@njit(cache=True, inline="always")
def _apply_gt(P, i, y, out):
    """out = G^T y for pair i: per contact ``y_f + y_tau x p_k``."""
    for k in range(4):
        px = P[i, k, 0]
        py = P[i, k, 1]
        pz = P[i, k, 2]
        out[3 * k] = y[0] + y[4] * pz - y[5] * py
        out[3 * k + 1] = y[1] + y[5] * px - y[3] * pz
        out[3 * k + 2] = y[2] + y[3] * py - y[4] * px


@njit(cache=True, inline="always")
def _split(vx, vy, vz, ax, ay, az):
    """Split ``v`` along a unit cone axis ``a``: ``(v.a, t = v - (v.a) a, ||t||)``."""
    vn = vx * ax + vy * ay + vz * az
    tx = vx - vn * ax
    ty = vy - vn * ay
    tz = vz - vn * az
    return vn, tx, ty, tz, math.sqrt(tx * tx + ty * ty + tz * tz)


@njit(cache=True, inline="always")
def _project(F, A, i, mu, c, s, f_high):
    """Project each 3-block of F onto (cone about A[i, k]) ∩ (ball f_high), in place."""
    for k in range(4):
        ax = A[i, k, 0]
        ay = A[i, k, 1]
        az = A[i, k, 2]
        fx = F[3 * k]
        fy = F[3 * k + 1]
        fz = F[3 * k + 2]
        an, tx, ty, tz, tn = _split(fx, fy, fz, ax, ay, az)
        if tn <= mu * an:
            pass
        elif mu * tn <= -an:
            fx = 0.0
            fy = 0.0
            fz = 0.0
        else:
            scale = an * c + tn * s
            fx = scale * (c * ax + s * tx / tn)
            fy = scale * (c * ay + s * ty / tn)
            fz = scale * (c * az + s * tz / tn)
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        if norm > f_high:
            shrink = f_high / norm
            fx *= shrink
            fy *= shrink
            fz *= shrink
        F[3 * k] = fx
        F[3 * k + 1] = fy
        F[3 * k + 2] = fz


@njit(cache=True, inline="always")
def _momentum(x, xn, y, t):
    """FISTA extrapolation with gradient restart (O'Donoghue and Candes): set ``y`` from the new
    projected point ``xn`` and the previous ``x``, then ``x = xn``; returns the new ``t``."""
    restart = 0.0
    for a in range(12):
        restart += (y[a] - xn[a]) * (xn[a] - x[a])
    if restart > 0.0:
        t = 1.0
        for a in range(12):
            y[a] = xn[a]
    else:
        t_next = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * t * t))
        beta = (t - 1.0) / t_next
        for a in range(12):
            y[a] = xn[a] + beta * (xn[a] - x[a])
        t = t_next
    for a in range(12):
        x[a] = xn[a]
    return t


@njit(cache=True, inline="always")
def _dual_bound(P, A, i, w, y, mu, c, s, f_high):
    """Lower bound on L from a direction y (normalised here):
    ``y.w - f_high sum_k ||P_K(-G_k^T y)||``."""
    norm = _norm6(y)
    if norm == 0.0:
        return -np.inf
    value = 0.0
    for j in range(6):
        value += y[j] * w[j]
    total = 0.0
    for k in range(4):
        px = P[i, k, 0]
        py = P[i, k, 1]
        pz = P[i, k, 2]
        # d = -(G_k^T y)
        dx = -(y[0] + y[4] * pz - y[5] * py)
        dy = -(y[1] + y[5] * px - y[3] * pz)
        dz = -(y[2] + y[3] * py - y[4] * px)
        dn, _, _, _, tn = _split(dx, dy, dz, A[i, k, 0], A[i, k, 1], A[i, k, 2])
        if tn <= mu * dn:
            total += math.sqrt(dx * dx + dy * dy + dz * dz)
        elif mu * tn <= -dn:
            pass
        else:
            total += dn * c + tn * s
    return (value - f_high * total) / norm


@njit(cache=True, inline="always")
def _gram(P, i, H):
    """H = G G^T for pair i (6x6, symmetric)."""
    for a in range(6):
        for b in range(6):
            H[a, b] = 0.0
    for k in range(4):
        px = P[i, k, 0]
        py = P[i, k, 1]
        pz = P[i, k, 2]
        # G_k G_k^T = [[I, S^T], [S, S S^T]] with S = [p]x
        H[3, 1] += -pz
        H[3, 2] += py
        H[4, 0] += pz
        H[4, 2] += -px
        H[5, 0] += -py
        H[5, 1] += px
        H[3, 3] += py * py + pz * pz
        H[4, 4] += px * px + pz * pz
        H[5, 5] += px * px + py * py
        H[3, 4] += -px * py
        H[3, 5] += -px * pz
        H[4, 5] += -py * pz
    H[0, 0] = 4.0
    H[1, 1] = 4.0
    H[2, 2] = 4.0
    for a in range(3, 6):
        for b in range(3):
            H[b, a] = H[a, b]
    H[4, 3] = H[3, 4]
    H[5, 3] = H[3, 5]
    H[5, 4] = H[4, 5]


@njit(cache=True)
def _cholesky_inverse(H, L, M, v):
    """M = H^-1 via Cholesky ``H = L L^T``; False when a pivot is not clearly positive.

    ``v`` is a length-6 work array. On success ``prod(diag(L))^2 = det(H)``.
    """
    for a in range(6):
        for b in range(a + 1):
            acc = H[a, b]
            for m in range(b):
                acc -= L[a, m] * L[b, m]
            if a == b:
                if not acc > 1e-14 * H[a, a]:
                    return False
                L[a, a] = math.sqrt(acc)
            else:
                L[a, b] = acc / L[b, b]
        for b in range(a + 1, 6):
            L[a, b] = 0.0
    for col in range(6):
        for a in range(6):
            acc = 1.0 if a == col else 0.0
            for m in range(a):
                acc -= L[a, m] * v[m]
            v[a] = acc / L[a, a]
        for a in range(5, -1, -1):
            acc = v[a]
            for m in range(a + 1, 6):
                acc -= L[m, a] * M[m, col]
            M[a, col] = acc / L[a, a]
    return True


@njit(cache=True)
def gram_statistics(P, clearly_full_rank, quality, safe_condition_squared):
    """Per pair: whether G certainly has rank 6, and ``Q(G) = sqrt(det(G G^T))``.

    With ``H = G G^T``: ``sigma_max^2 <= trace(H)`` and ``sigma_min^2 >= 1/trace(H^-1)``; when
    ``trace(H) * trace(H^-1) < safe_condition_squared`` the rank is 6 with a wide margin. Pairs
    not settled here (``clearly_full_rank`` False) need the exact SVD test; their ``quality`` is
    NaN and must be computed by the caller.
    """
    H = np.zeros((6, 6))
    L = np.zeros((6, 6))
    M = np.zeros((6, 6))
    v = np.zeros(6)
    for i in range(P.shape[0]):
        _gram(P, i, H)
        clearly_full_rank[i] = False
        quality[i] = np.nan
        if not _cholesky_inverse(H, L, M, v):
            continue
        trace_h = 0.0
        trace_m = 0.0
        det_root = 1.0
        for a in range(6):
            trace_h += H[a, a]
            trace_m += M[a, a]
            det_root *= L[a, a]
        if trace_m > 0.0 and trace_h * trace_m < safe_condition_squared:
            clearly_full_rank[i] = True
            quality[i] = det_root


@njit(cache=True)
def _largest_eigenvalue(H):
    """Upper bound on lambda_max(H) for a 6x6 SPD matrix: power iteration, then +2 % margin,
    capped by the trace (which is always an upper bound)."""
    v = np.ones(6) / math.sqrt(6.0)
    lam = 0.0
    u = np.zeros(6)
    for _ in range(30):
        _matvec6(H, v, u)
        norm = _norm6(u)
        if norm == 0.0:
            break
        lam = norm
        for a in range(6):
            v[a] = u[a] / norm
    trace = 0.0
    for a in range(6):
        trace += H[a, a]
    return min(lam * 1.02, trace)


# The steps of :func:`solve_batch` allocate nothing, so they are compiled without numba's
# reference counting (``_nrt=False``, a private numba option): a call then passes its work arrays
# without atomic reference-count updates. Why: in a one-off comparison with the previous
# monolithic loop (40,000 synthetic pairs, one core; not a bench script, so not a recorded claim)
# the same split cost 7-18 % with reference counting and none without it, with bit-identical
# outputs. The recorded throughput is bench/fc_throughput.py's (BENCHMARKS.md). Should a numba
# release drop the option, removing it costs only that speed.


@njit(cache=True, _nrt=False)
def _prepare(P, i, H, L, M, v):
    """``H = G G^T`` plus a tiny ridge and ``M = H^-1`` for pair i; False when not invertible.

    The ridge keeps near-collinear pairs (rank 6 but badly conditioned) invertible:
    ``G^T (H + eps I)^-1 G`` has eigenvalues below 1, so the unit step stays valid, and the
    certificates are computed on the true loss, so they stay exact.
    """
    _gram(P, i, H)
    ridge = 1e-12 * (H[0, 0] + H[1, 1] + H[2, 2] + H[3, 3] + H[4, 4] + H[5, 5])
    for a in range(6):
        H[a, a] += ridge
    return _cholesky_inverse(H, L, M, v)


@njit(cache=True, _nrt=False)
def _start(P, A, i, w, M, squeeze, mu, c, s, f_high, x, y, g, z):
    """``x = y`` = the minimum-norm solution of ``G F = -w`` plus ``squeeze`` along each cone
    axis, projected onto C."""
    _matvec6(M, w, z)
    _apply_gt(P, i, z, g)
    for k in range(4):
        for a in range(3):
            x[3 * k + a] = -g[3 * k + a] + squeeze * A[i, k, a]
    _project(x, A, i, mu, c, s, f_high)
    for a in range(12):
        y[a] = x[a]


@njit(cache=True, _nrt=False)
def _certify(
    P,
    A,
    i,
    w,
    M,
    mu,
    c,
    s,
    f_high,
    thr_pass,
    thr_fail,
    max_iterations,
    check_every,
    x,
    xn,
    y,
    g,
    r,
    z,
):
    """Phase 1 from ``x = y``: preconditioned FISTA until a certificate either way.

    Returns ``(verdict, ub, lb, iterations)``: ``ub`` the residual attained by ``x`` at the last
    check, ``lb`` the best dual bound found.
    """
    t = 1.0
    best_lb = -np.inf
    ub = np.inf
    verdict = UNDECIDED
    it = 0
    while it < max_iterations:
        it += 1
        _apply_g(P, i, y, w, r)
        _matvec6(M, r, z)
        _apply_gt(P, i, z, g)
        for a in range(12):
            xn[a] = y[a] - g[a]
        _project(xn, A, i, mu, c, s, f_high)
        t = _momentum(x, xn, y, t)
        if it % check_every == 0 or it == 1:
            _apply_g(P, i, x, w, r)
            ub = _norm6(r)
            if ub <= thr_pass:
                verdict = CERTIFIED_PASS
                break
            lb = _dual_bound(P, A, i, w, r, mu, c, s, f_high)
            if lb > best_lb:
                best_lb = lb
            _matvec6(M, r, z)
            lb = _dual_bound(P, A, i, w, z, mu, c, s, f_high)
            if lb > best_lb:
                best_lb = lb
            if best_lb > thr_fail:
                verdict = CERTIFIED_FAIL
                break
    return verdict, ub, best_lb, it


@njit(cache=True, _nrt=False)
def _refine(
    P,
    A,
    i,
    w,
    step,
    mu,
    c,
    s,
    f_high,
    loss_rtol,
    loss_atol,
    max_refine,
    check_every,
    ub,
    lb,
    x,
    xn,
    y,
    g,
    r,
    best,
):
    """Phase 2 from ``x``: FISTA on the plain objective until the bounds meet the accuracy.

    Returns ``(ub, lb, iterations)``; ``best`` holds the forces attaining ``ub``.
    """
    for a in range(12):
        best[a] = x[a]
        y[a] = x[a]
    t = 1.0
    refine = 0
    while ub - lb > loss_rtol * ub + loss_atol and refine < max_refine:
        refine += 1
        _apply_g(P, i, y, w, r)
        _apply_gt(P, i, r, g)
        for a in range(12):
            xn[a] = y[a] - step * g[a]
        _project(xn, A, i, mu, c, s, f_high)
        t = _momentum(x, xn, y, t)
        if refine % check_every == 0:
            _apply_g(P, i, x, w, r)
            value = _norm6(r)
            if value < ub:
                ub = value
                for a in range(12):
                    best[a] = x[a]
            bound = _dual_bound(P, A, i, w, r, mu, c, s, f_high)
            if bound > lb:
                lb = bound
    return ub, lb, refine


@njit(cache=True)
def solve_batch(
    P,
    A,
    W,
    mu,
    f_high,
    thr_pass,
    thr_fail,
    loss_rtol,
    loss_atol,
    max_iterations,
    max_refine,
    check_every,
    squeeze,
    forces,
    losses,
    lower,
    status,
    iterations,
):
    """Run both phases on every pair and wrench.

    Args:
        P: ``(N, 4, 3)`` contact points.
        A: ``(N, 4, 3)`` unit cone axes.
        W: ``(K, 6)`` wrenches.
        forces: out ``(N, K, 12)``.
        losses: out ``(N, K)``.
        lower: out ``(N, K)``.
        status: out ``(N, K)`` int8, 0 undecided, 1 certified pass, 2 certified fail.
        iterations: out ``(N, K)`` int32.
    """
    n_w = W.shape[0]
    c = 1.0 / math.sqrt(1.0 + mu * mu)
    s = mu * c
    H = np.zeros((6, 6))
    L = np.zeros((6, 6))
    M = np.zeros((6, 6))
    v = np.zeros(6)
    x = np.zeros(12)
    xn = np.zeros(12)
    y = np.zeros(12)
    g = np.zeros(12)
    best = np.zeros(12)
    r = np.zeros(6)
    z = np.zeros(6)
    for i in range(P.shape[0]):
        if not _prepare(P, i, H, L, M, v):
            for j in range(n_w):
                status[i, j] = UNDECIDED
                losses[i, j] = np.nan
                lower[i, j] = -np.inf
            continue
        lam = -1.0  # lambda_max(H), computed on first need (phase 2)
        for j in range(n_w):
            w = W[j]
            _start(P, A, i, w, M, squeeze, mu, c, s, f_high, x, y, g, z)
            verdict, ub, lb, it = _certify(
                P, A, i, w, M, mu, c, s, f_high, thr_pass, thr_fail, max_iterations,
                check_every, x, xn, y, g, r, z,
            )  # fmt: skip
            status[i, j] = verdict
            iterations[i, j] = it
            if verdict != CERTIFIED_FAIL:
                for a in range(12):
                    forces[i, j, a] = x[a]
                losses[i, j] = ub
                lower[i, j] = max(lb, 0.0) if verdict == UNDECIDED else 0.0
                continue
            if lam < 0.0 and max_refine > 0:
                lam = _largest_eigenvalue(H)
            step = 1.0 / lam if lam > 0.0 else 0.0
            ub, lb, refine = _refine(
                P, A, i, w, step, mu, c, s, f_high, loss_rtol, loss_atol, max_refine,
                check_every, ub, lb, x, xn, y, g, r, best,
            )  # fmt: skip
            for a in range(12):
                forces[i, j, a] = best[a]
            losses[i, j] = ub
            lower[i, j] = lb
            iterations[i, j] += refine


@njit(cache=True)
def dual_bounds(P, A, W, Y, mu, f_high, out):
    """``out[i]`` = the dual lower bound on problem i's loss from direction ``Y[i]`` (any
    non-zero 6-vector; -inf for a zero one): ``L_i >= y.w_i - f_high sum_k ||P_K(-G_k^T y)||``
    with ``y = Y[i] / ||Y[i]||``. Valid for any direction, tight at the optimal one."""
    c = 1.0 / math.sqrt(1.0 + mu * mu)
    s = mu * c
    for i in range(P.shape[0]):
        out[i] = _dual_bound(P, A, i, W[i], Y[i], mu, c, s, f_high)


def run(
    points: FloatArray,
    axes: FloatArray,
    wrenches: FloatArray,
    *,
    mu: float,
    f_high: float,
    threshold: float,
    margin: float,
    loss_rtol: float,
    loss_atol: float,
    max_iterations: int,
    max_refine: int,
    check_every: int = 4,
    squeeze: float = 0.0,
) -> tuple[FloatArray, FloatArray, FloatArray, np.ndarray, np.ndarray]:
    """Call the compiled kernel; returns forces ``(N, K, 4, 3)``, losses, lower bounds ``(N, K)``,
    status ``(N, K)`` int8 and iteration counts ``(N, K)``."""
    n = points.shape[0]
    k = wrenches.shape[0]
    forces = np.zeros((n, k, 12))
    losses = np.zeros((n, k))
    lower = np.zeros((n, k))
    status = np.zeros((n, k), dtype=np.int8)
    iterations = np.zeros((n, k), dtype=np.int32)
    solve_batch(
        np.ascontiguousarray(points, dtype=np.float64),
        np.ascontiguousarray(axes, dtype=np.float64),
        np.ascontiguousarray(wrenches, dtype=np.float64),
        float(mu),
        float(f_high),
        float(threshold * (1.0 - margin)),
        float(threshold * (1.0 + margin)),
        float(loss_rtol),
        float(loss_atol),
        int(max_iterations),
        int(max_refine),
        int(check_every),
        float(squeeze),
        forces,
        losses,
        lower,
        status,
        iterations,
    )
    return forces.reshape(n, k, 4, 3), losses, lower, status, iterations
