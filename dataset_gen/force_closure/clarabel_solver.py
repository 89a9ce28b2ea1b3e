"""Reference solver: the force-closure SOCP solved pair by pair with Clarabel's Python API.

For one pair and one external wrench ``w`` the problem is (paper eqs. 1-4, object frame)::

    minimise    ||sum_k [F_k; p_k x F_k] + w||_2
    subject to  ||F_k - (F_k.a_k) a_k|| <= mu (F_k.a_k)      (friction cone about axis a_k)
                ||F_k|| <= f_high                             (force bound)

written for Clarabel as ``min t`` over ``x = (t, F_1..F_4)`` with ``b - A x`` in a product of
second-order cones: SOC(7) ``(t, G F + w)``, four SOC(4) ``(f_high, F_k)`` and four SOC(3)
``(mu a_k.F_k, T_k F_k)`` with ``T_k`` the two tangent axes. This is the released code's problem in
the object frame (``F_k = R_k f_k``), so its optimum is the same.

Every solver status is handled explicitly: ``Solved`` is used; ``AlmostSolved`` is used and
reported. The problem is always feasible (F = 0 is) and bounded, so any other status
(``NumericalError``, ``InsufficientProgress``, ``MaxIterations``, an infeasibility claim ...) is a
numerical failure, never a verdict: the pair is solved again with the next settings of
:data:`RETRY_SETTINGS` (stronger static regularisation, then no equilibration; measured: about 1 in
10,000 real pairs ends in ``NumericalError`` at the optimum with the defaults), and when every
attempt fails :class:`~dg16m_core.errors.SolverError` is raised. A tight re-solve
(``tight=True``) only sharpens a solve that succeeded, so its failures are kept as attained
bounds instead.

What a solve proves: the returned forces are projected exactly onto the feasible set, so the
loss they give is ATTAINED, an upper bound on the optimum. A lower bound comes from duality:
for any direction ``y``, ``L >= y.w - f_high sum_k ||P_K(-G_k^T y)||`` (``||y|| = 1``); it is
evaluated (:func:`~dataset_gen.force_closure.fast_solver.dual_bounds`) at the residual's
direction and at Clarabel's dual variable of the residual cone, both optimal at the optimum.
At the default tolerances the two bounds can straddle the force-closure threshold (Clarabel
stops at a duality gap of 1e-8 relative, and "AlmostSolved" accepts 5e-5, five times the
threshold): ``tight=True`` uses :data:`TIGHT_SETTINGS` for the problems whose verdict must be
settled.
"""

from __future__ import annotations

from dataclasses import dataclass

import clarabel
import numpy as np
import scipy.sparse as sp

from dg16m_core.errors import SolverError

from .geometry import FloatArray, apply_grasp, contact_frames, project_cone_ball

_N_VAR = 13  # t and four 3-vectors
_N_ROW = 7 + 4 * 4 + 4 * 3  # 35


@dataclass(frozen=True)
class ClarabelBatch:
    """Clarabel solves of n (pair, wrench) problems.

    Attributes:
        forces: ``(n, 4, 3)`` optimal forces, object frame, projected exactly onto the feasible
            set (interior-point iterates may leave a cone by ~1e-9).
        losses: ``(n,)`` the residual ``||G F + w||`` those forces give: attainable, honest values.
        lower: ``(n,)`` a proven lower bound on each optimum (the dual bound above; may be
            negative, the loss itself is >= 0).
        statuses: the solver status name per problem ("Solved", "AlmostSolved", with the retry
            number when default settings failed).
    """

    forces: FloatArray
    losses: FloatArray
    lower: FloatArray
    statuses: list[str]


#: Settings changes tried in order, the first being Clarabel's defaults.
RETRY_SETTINGS: tuple[dict[str, object], ...] = (
    {},
    {"static_regularization_constant": 1e-7},
    {"equilibrate_enable": False, "max_iter": 400},
)


#: Applied on top of every entry of :data:`RETRY_SETTINGS` by ``solve_batch(..., tight=True)``:
#: an absolute duality gap of 1e-11 (1e-6 of the paper's threshold; the default is 1e-8),
#: relative gap and feasibility 1e-10, and an "AlmostSolved" that means the default's 1e-8.
#: Tighter settings end in ``InsufficientProgress`` on some problems (measured).
TIGHT_SETTINGS: dict[str, object] = {
    "tol_gap_abs": 1e-11,
    "tol_gap_rel": 1e-10,
    "tol_feas": 1e-10,
    "tol_ktratio": 1e-8,
    "reduced_tol_gap_abs": 1e-8,
    "reduced_tol_gap_rel": 1e-8,
    "reduced_tol_feas": 1e-8,
    "reduced_tol_ktratio": 1e-6,
    "max_iter": 400,
}


def _settings(changes: dict[str, object]) -> clarabel.DefaultSettings:
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.max_threads = 1
    for name, value in changes.items():
        setattr(settings, name, value)
    return settings


def _sparsity() -> tuple[np.ndarray, np.ndarray]:
    """Row indices and column pointers of ``A`` (CSC, fixed pattern, 97 entries).

    Column 0 (t) has row 0. The column of force component j of contact k has: force row 1+j,
    the three torque rows 4..6 (one is a structural zero), ball row 8+4k+j and cone rows
    23+3k..25+3k.
    """
    rows = [0]
    indptr = [0, 1]
    for k in range(4):
        for j in range(3):
            rows += [1 + j, 4, 5, 6, 8 + 4 * k + j, 23 + 3 * k, 24 + 3 * k, 25 + 3 * k]
            indptr.append(len(rows))
    return np.array(rows, dtype=np.int64), np.array(indptr, dtype=np.int64)


_ROWS, _INDPTR = _sparsity()
_CONES = [clarabel.SecondOrderConeT(7)] + [clarabel.SecondOrderConeT(4)] * 4
_CONES += [clarabel.SecondOrderConeT(3)] * 4
_P = sp.csc_matrix((_N_VAR, _N_VAR))
_Q = np.zeros(_N_VAR)
_Q[0] = 1.0


def _matrix_values(points: FloatArray, axes: FloatArray, mu: float) -> FloatArray:
    """CSC values of ``A`` for n problems, ``(n, 97)``, matching :func:`_sparsity`."""
    n = points.shape[0]
    R = contact_frames(axes)  # (n, 4, 3, 3): columns tangent1, tangent2, axis
    # torque p x F: column j of [p]x is e_j x p reversed: [p]x e_j = p x e_j
    eye = np.eye(3)
    torque = np.cross(points[:, :, None, :], eye[None, None, :, :])  # (n, 4, 3 j, 3 rows)
    values = np.empty((n, 4, 3, 8))
    values[..., 0] = -1.0
    values[..., 1:4] = -torque
    values[..., 4] = -1.0
    values[..., 5] = -mu * R[..., :, 2]
    values[..., 6] = -R[..., :, 0]
    values[..., 7] = -R[..., :, 1]
    out = np.empty((n, 1 + 96))
    out[:, 0] = -1.0
    out[:, 1:] = values.reshape(n, 96)
    return out


def solve_batch(
    points: FloatArray,
    axes: FloatArray,
    wrenches: FloatArray,
    *,
    mu: float,
    f_high: float,
    tight: bool = False,
) -> ClarabelBatch:
    """Solve n problems one by one.

    Args:
        points: ``(n, 4, 3)`` contact points (m), object frame.
        axes: ``(n, 4, 3)`` unit friction-cone axes (the direction each force may push).
        wrenches: ``(n, 6)`` the external wrench of each problem (N, N m).
        mu: friction coefficient.
        f_high: bound on each contact force's norm (N).
        tight: solve to :data:`TIGHT_SETTINGS`. A problem on which every attempt then ends
            with a failure status is not an error (its bounds hold whatever the status): it
            keeps the attempt whose forces attain the lowest loss, and its status says so. Use
            it to sharpen a default solve (:func:`best_of`).

    Raises:
        SolverError: without ``tight``, every entry of :data:`RETRY_SETTINGS` ended with a
            failure status.
    """
    points = np.asarray(points, dtype=np.float64)
    axes = np.asarray(axes, dtype=np.float64)
    wrenches = np.ascontiguousarray(wrenches, dtype=np.float64)
    n = points.shape[0]
    values = _matrix_values(points, axes, mu)
    b = np.zeros((n, _N_ROW))
    b[:, 1:7] = wrenches
    b[:, 7:23:4] = f_high
    extra = TIGHT_SETTINGS if tight else {}
    settings = [_settings({**changes, **extra}) for changes in RETRY_SETTINGS]
    x = np.zeros((n, _N_VAR))
    dual = np.zeros((n, 6))
    statuses: list[str] = []
    for i in range(n):
        A = sp.csc_matrix((values[i], _ROWS, _INDPTR), shape=(_N_ROW, _N_VAR))
        failures = []
        tries: list[tuple[np.ndarray, np.ndarray]] = []
        for attempt, setting in enumerate(settings):
            solution = clarabel.DefaultSolver(_P, _Q, A, b[i], _CONES, setting).solve()
            status = solution.status
            if status in (clarabel.SolverStatus.Solved, clarabel.SolverStatus.AlmostSolved):
                name = "Solved" if status == clarabel.SolverStatus.Solved else "AlmostSolved"
                statuses.append(name if attempt == 0 else f"{name} (retry {attempt})")
                x[i] = solution.x
                dual[i] = solution.z[1:7]
                break
            failures.append(
                f"{status} after {solution.iterations} iterations with "
                f"{RETRY_SETTINGS[attempt] or 'default settings'}"
            )
            tries.append((np.asarray(solution.x, dtype=np.float64), np.asarray(solution.z)[1:7]))
        else:
            if not tight:
                raise SolverError(
                    "Clarabel could not solve a force-closure problem: expected status Solved or "
                    f"AlmostSolved, found {'; '.join(failures)} "
                    f"(points {points[i].tolist()}, axes {axes[i].tolist()})"
                )
            attained = [
                _attained(points[i : i + 1], axes[i : i + 1], wrenches[i : i + 1], t[0], mu, f_high)
                for t in tries
            ]
            best = int(np.argmin(np.nan_to_num(attained, nan=np.inf)))
            x[i], dual[i] = tries[best]
            statuses.append(f"unconverged: {failures[best]}")
    forces = project_cone_ball(x[:, 1:].reshape(n, 4, 3), axes, mu, f_high)
    residual = apply_grasp(points, forces) + wrenches
    lower = np.fmax(
        _dual_bounds(points, axes, wrenches, residual, mu, f_high),
        _dual_bounds(points, axes, wrenches, -dual, mu, f_high),
    )
    return ClarabelBatch(
        forces=forces, losses=np.linalg.norm(residual, axis=1), lower=lower, statuses=statuses
    )


def best_of(first: ClarabelBatch, second: ClarabelBatch) -> ClarabelBatch:
    """Per problem, the forces that attain the lower loss (``second``'s on ties) and the higher
    of the two lower bounds (NaN ignored); statuses are ``second``'s. Both must solve the same
    problems."""
    take = second.losses <= first.losses  # a NaN (failed) second solve is never taken
    return ClarabelBatch(
        forces=np.where(take[:, None, None], second.forces, first.forces),
        losses=np.where(take, second.losses, first.losses),
        lower=np.fmax(first.lower, second.lower),
        statuses=list(second.statuses),
    )


def _attained(
    points: FloatArray,
    axes: FloatArray,
    wrench: FloatArray,
    x: FloatArray,
    mu: float,
    f_high: float,
) -> float:
    """The loss attained by one solver iterate ``x`` after projection onto the feasible set."""
    forces = project_cone_ball(x[1:].reshape(1, 4, 3), axes, mu, f_high)
    return float(np.linalg.norm(apply_grasp(points, forces) + wrench))


def _dual_bounds(
    points: FloatArray,
    axes: FloatArray,
    wrenches: FloatArray,
    directions: FloatArray,
    mu: float,
    f_high: float,
) -> FloatArray:
    """The dual lower bound of each problem from one direction each (compiled)."""
    from .fast_solver import dual_bounds

    out = np.empty(points.shape[0])
    dual_bounds(
        np.ascontiguousarray(points),
        np.ascontiguousarray(axes),
        wrenches,
        np.ascontiguousarray(directions, dtype=np.float64),
        float(mu),
        float(f_high),
        out,
    )
    return out
