"""The force-closure check of DG16M (paper eqs. 1-4), exact and batched.

A dual-arm grasp gives four point contacts with friction. The grasp passes when the contact
matrix has full rank and the contacts can cancel the external wrench: with
``L = min ||sum_k G_k f_k + w_ext||_2`` over forces inside the friction cones and below
``f_high``, the grasp passes when ``L <= threshold``.

Conventions
-----------
``contact_normals`` are the surface's OUTWARD normals (trimesh face normals). The two conventions
differ only in the friction cone's axis:

* ``"physical"`` (default): a finger can only push, so each cone is about the INWARD normal
  ``-n``; gravity pulls down (``w_ext = (0, 0, -m g, 0, 0, 0)``), so the contacts must supply
  ``+m g`` upwards.
* ``"release"``: the released DG16M code uses the outward normal as the cone axis, so its forces
  pull on the surface. Its verdicts equal those of the physical check with the load reversed (an
  upward ``m g``). Use it only to verify release files.

Worked example: a 6 kg box, four fingertips on its bottom face at ``z = -0.05`` m around the
centroid (outward normal ``(0, 0, -1)``). Physically the fingers push up (axis ``+z``), 15 N each
cancels gravity and the grasp passes (``L = 0``): the box rests on the fingers. In the release
convention the cone axis is ``-z``: the fingers can only pull down, the best they can do is
nothing, and ``L = 60`` (fail). Put the four contacts on the top face instead and the verdicts
swap: physical fails with ``L = 60``, release passes. A plank squeezed between fingers on its two
end faces (opposing normals, ``mu = 0.4``) passes in both conventions: friction carries the weight
and the squeeze force is internal.

Robustness
----------
``wrenches`` may hold several external wrenches; a grasp then passes only if it resists every one
of them (one solve per wrench). :func:`axis_gravity_wrenches` gives the object's weight along
each of the six axis directions.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..errors import ForceClosureError
from .geometry import SAFE_CONDITION, FloatArray, full_rank, grasp_quality

log = logging.getLogger(__name__)

Convention = Literal["physical", "release"]
Method = Literal["auto", "fast", "clarabel"]
CONVENTIONS: tuple[str, ...] = ("physical", "release")
METHODS: tuple[str, ...] = ("auto", "fast", "clarabel")

#: Release parameters (DESIGN.md): 6 kg under g = 10, mu = 0.4, 70 N per contact, threshold 1e-5
#: on the norm of the residual wrench.
DEFAULT_MASS = 6.0
DEFAULT_GRAVITY = 10.0
DEFAULT_MU = 0.4
DEFAULT_F_HIGH = 70.0
DEFAULT_THRESHOLD = 1e-5

#: How each (pair, wrench) verdict was reached.
SOLVED_NONE = 0  # rank-deficient: not solved, fails by the rank test
SOLVED_FAST = 1  # certified by the compiled fast path
SOLVED_CLARABEL = 2  # solved by the Clarabel reference solver

#: Fast-path certificates keep this relative distance from the threshold; pairs whose loss lies
#: within it are decided by Clarabel, so fast and reference verdicts cannot disagree through
#: rounding.
CERTIFICATE_MARGIN = 1e-2

_MIN_NORMAL = 1e-9


@dataclass(frozen=True)
class ForceClosureResult:
    """Per-pair force-closure outcome. N pairs, K external wrenches.

    Attributes:
        loss: ``(N,)`` the largest loss over the wrenches (N); NaN when the rank test failed.
        losses: ``(N, K)`` loss per wrench. For certified passes it is the attained residual
            (at most ``threshold``), for failures the optimum to ``loss_rtol``.
        loss_lower: ``(N, K)`` a proven lower bound on each loss from the fast path's dual
            certificate (0 for its passes, NaN where Clarabel solved the problem).
        loss_converged: ``(N, K)`` True where ``losses`` is the optimum (to ``loss_rtol``):
            Clarabel solves, fast-path passes and refined failures. False only in verdict-only
            mode (``loss_rtol=None``) for failures, whose loss is then an attained upper bound.
        passed: ``(N,)`` full rank and every loss ``<= threshold``.
        rank_ok: ``(N,)`` ``numpy.linalg.matrix_rank(G) == 6``.
        contact_forces: ``(N, K, 4, 3)`` the optimal contact forces per wrench, object frame (N);
            zero for rank-deficient pairs.
        solved_by: ``(N, K)`` uint8: ``SOLVED_NONE``, ``SOLVED_FAST`` or ``SOLVED_CLARABEL``.
        quality: ``(N,)`` ``Q(G) = sqrt(det(G G^T))``.
        wrenches: ``(K, 6)`` the external wrenches.
        parameters: the settings used (convention, mu, f_high, threshold, method ...).
    """

    loss: FloatArray
    losses: FloatArray
    loss_lower: FloatArray
    loss_converged: NDArray[np.bool_]
    passed: NDArray[np.bool_]
    rank_ok: NDArray[np.bool_]
    contact_forces: FloatArray
    solved_by: NDArray[np.uint8]
    quality: FloatArray
    wrenches: FloatArray
    parameters: dict[str, object] = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of pairs."""
        return int(self.passed.shape[0])

    @property
    def forces(self) -> FloatArray:
        """``(N, 4, 3)`` forces for the first wrench (the only one by default)."""
        return self.contact_forces[:, 0]

    @property
    def fallback_fraction(self) -> float:
        """Share of solved (pair, wrench) problems that needed Clarabel."""
        solved = self.solved_by != SOLVED_NONE
        total = int(solved.sum())
        return float((self.solved_by == SOLVED_CLARABEL).sum() / total) if total else 0.0


def gravity_wrench(mass: float = DEFAULT_MASS, gravity: float = DEFAULT_GRAVITY) -> FloatArray:
    """The object's weight as an external wrench about its centroid, ``(6,)``: ``(0,0,-m g,0,0,0)``."""
    return np.array([0.0, 0.0, -mass * gravity, 0.0, 0.0, 0.0])


def axis_gravity_wrenches(
    mass: float = DEFAULT_MASS, gravity: float = DEFAULT_GRAVITY
) -> FloatArray:
    """The weight pulling along each of ``-z, +z, -x, +x, -y, +y``, ``(6, 6)``.

    The first row is ordinary gravity, so ``result.forces`` stays the gravity solution.
    """
    weight = mass * gravity
    out = np.zeros((6, 6))
    for row, (axis, sign) in enumerate([(2, -1), (2, 1), (0, -1), (0, 1), (1, -1), (1, 1)]):
        out[row, axis] = sign * weight
    return out


def _check_positive(name: str, value: float, *, allow_zero: bool = False) -> float:
    value = float(value)
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ForceClosureError(f"{name}: expected a finite number {bound}, found {value!r}")
    return value


def _validate_contacts(points: object, normals: object) -> tuple[FloatArray, FloatArray]:
    """Shapes ``(N, 4, 3)``, finite values, non-zero normals; returns float64 copies with unit
    normals."""
    arrays = []
    for name, value in (("contact_points", points), ("contact_normals", normals)):
        try:
            array = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ForceClosureError(
                f"{name}: expected a numeric array of shape (N, 4, 3), found {type(value).__name__}"
            ) from exc
        if array.ndim != 3 or array.shape[1:] != (4, 3):
            raise ForceClosureError(
                f"{name}: expected shape (N, 4, 3) (four 3-D contacts per pair), found {array.shape}"
            )
        bad = ~np.isfinite(array).all(axis=(1, 2))
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            raise ForceClosureError(
                f"{name}: expected finite values, found NaN or inf in {int(bad.sum())} pair(s), "
                f"first at pair {first}: {array[first].tolist()}"
            )
        arrays.append(array)
    p, n = arrays
    if p.shape[0] != n.shape[0]:
        raise ForceClosureError(
            f"contact_normals: expected one set per pair ({p.shape[0]}), found {n.shape[0]}"
        )
    length = np.linalg.norm(n, axis=-1)
    short = length < _MIN_NORMAL
    if short.any():
        pair, contact = (int(v) for v in np.argwhere(short)[0])
        raise ForceClosureError(
            f"contact_normals: expected non-zero normals, found {int(short.sum())} of length "
            f"< {_MIN_NORMAL:g}, first at pair {pair} contact {contact}: {n[pair, contact].tolist()}"
        )
    return p, n / length[..., None]


def _validate_wrenches(wrenches: object, mass: float, gravity: float) -> FloatArray:
    if wrenches is None or (isinstance(wrenches, str) and wrenches == "gravity"):
        return gravity_wrench(mass, gravity)[None]
    if isinstance(wrenches, str):
        if wrenches == "axis_gravity":
            return axis_gravity_wrenches(mass, gravity)
        raise ForceClosureError(
            f"wrenches: expected None, 'gravity', 'axis_gravity' or a (K, 6) array, found {wrenches!r}"
        )
    array = np.asarray(wrenches, dtype=np.float64)
    if array.ndim == 1:
        array = array[None]
    if array.ndim != 2 or array.shape[1] != 6 or array.shape[0] == 0:
        raise ForceClosureError(
            f"wrenches: expected shape (K, 6) with K >= 1 (force, torque), found {array.shape}"
        )
    if not np.isfinite(array).all():
        raise ForceClosureError("wrenches: expected finite values, found NaN or inf")
    return array


def evaluate(
    contact_points: FloatArray,
    contact_normals: FloatArray,
    *,
    mass: float = DEFAULT_MASS,
    gravity: float = DEFAULT_GRAVITY,
    mu: float = DEFAULT_MU,
    f_high: float = DEFAULT_F_HIGH,
    threshold: float = DEFAULT_THRESHOLD,
    convention: Convention = "physical",
    wrenches: FloatArray | str | None = None,
    method: Method = "auto",
    loss_rtol: float | None = 1e-3,
    loss_atol: float = 1e-9,
    max_iterations: int = 400,
    max_refine: int = 4000,
    chunk_size: int = 65536,
    progress: bool = False,
) -> ForceClosureResult:
    """Force-closure verdicts, losses, optimal forces and Q(G) for N dual-arm grasps.

    Args:
        contact_points: ``(N, 4, 3)`` contacts in the object frame (m), origin at the centre of
            mass (the release uses the mesh centroid).
        contact_normals: ``(N, 4, 3)`` OUTWARD surface normals at the contacts (any length > 0;
            normalised here).
        mass: object mass (kg) for the default gravity wrench.
        gravity: gravitational acceleration (m/s^2).
        mu: Coulomb friction coefficient (cone half-angle ``atan(mu)``).
        f_high: bound on each contact force's norm (N); 70 N is the Franka hand's continuous force.
        threshold: a pair passes when the residual-wrench norm ``L <= threshold``.
        convention: ``"physical"`` (push along the inward normal) or ``"release"`` (the released
            code's outward cone axis); see the module docstring for a worked example.
        wrenches: external wrench(es) to resist: None or ``"gravity"`` (weight, ``-z``),
            ``"axis_gravity"`` (weight along each of the six axis directions) or a ``(K, 6)``
            array. A pair passes only if it resists all of them.
        method: ``"clarabel"`` (reference interior point, pair by pair), ``"fast"`` (compiled
            batched method with certificates; undecided pairs go to Clarabel) or ``"auto"`` (the
            default: ``"fast"`` for more than a handful of pairs, else ``"clarabel"``).
        loss_rtol, loss_atol: accuracy of the losses of failing pairs on the fast path:
            ``upper - lower <= loss_rtol * upper + loss_atol``; pairs that do not reach it within
            ``max_refine`` iterations are re-solved by Clarabel. ``loss_rtol=None`` is the
            verdict-only mode (several times faster, what the generator uses on all candidates):
            a failing pair's ``losses`` is then an upper bound attained by its returned forces
            and ``loss_lower`` a proven lower bound (both above ``threshold``); re-evaluate the
            pairs whose exact loss you need.
        max_iterations: fast-path budget per pair to reach a certificate.
        max_refine: fast-path budget per failing pair to reach the loss accuracy.
        chunk_size: pairs per compiled call (bounds memory, drives the progress bar).
        progress: show a progress bar.

    Returns:
        A :class:`ForceClosureResult`.

    Raises:
        ForceClosureError: malformed input: shapes other than ``(N, 4, 3)``, NaN or inf, zero
            normals, non-positive parameters, unknown convention or method.
        SolverError: Clarabel ended with a failure status (never turned into a verdict).
    """
    points, normals = _validate_contacts(contact_points, contact_normals)
    mass = _check_positive("mass", mass)
    gravity = _check_positive("gravity", gravity, allow_zero=True)
    mu = _check_positive("mu", mu, allow_zero=True)
    f_high = _check_positive("f_high", f_high)
    threshold = _check_positive("threshold", threshold)
    if loss_rtol is not None:
        loss_rtol = _check_positive("loss_rtol", loss_rtol, allow_zero=True)
    loss_atol = _check_positive("loss_atol", loss_atol, allow_zero=True)
    if convention not in CONVENTIONS:
        raise ForceClosureError(f"convention: expected one of {CONVENTIONS}, found {convention!r}")
    if method not in METHODS:
        raise ForceClosureError(f"method: expected one of {METHODS}, found {method!r}")
    if int(max_iterations) < 1 or int(max_refine) < 0 or int(chunk_size) < 1:
        raise ForceClosureError(
            "max_iterations, max_refine, chunk_size: expected >= 1, >= 0, >= 1, found "
            f"{max_iterations}, {max_refine}, {chunk_size}"
        )
    W = _validate_wrenches(wrenches, mass, gravity)
    axes = -normals if convention == "physical" else normals
    n, k = points.shape[0], W.shape[0]
    if method == "auto":
        method = "fast" if n * k > 8 else "clarabel"

    rank_ok, quality = _rank_and_quality(points, axes, compiled=method == "fast")
    losses = np.full((n, k), np.nan)
    lower = np.full((n, k), np.nan)
    forces = np.zeros((n, k, 4, 3))
    solved_by = np.zeros((n, k), dtype=np.uint8)
    converged = np.zeros((n, k), dtype=bool)
    todo = np.flatnonzero(rank_ok)

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=int(todo.size), unit="pair", desc="force closure", smoothing=0.1)
    try:
        for start in range(0, todo.size, int(chunk_size)):
            rows = todo[start : start + int(chunk_size)]
            if method == "fast":
                from . import fast_solver

                f, loss, low, status, _ = fast_solver.run(
                    points[rows],
                    axes[rows],
                    W,
                    mu=mu,
                    f_high=f_high,
                    threshold=threshold,
                    margin=CERTIFICATE_MARGIN,
                    loss_rtol=0.0 if loss_rtol is None else loss_rtol,
                    loss_atol=loss_atol,
                    max_iterations=int(max_iterations),
                    max_refine=0 if loss_rtol is None else int(max_refine),
                    squeeze=f_high,
                )
                forces[rows] = f
                losses[rows] = loss
                lower[rows] = low
                solved_by[rows] = SOLVED_FAST
                converged[rows] = (status == fast_solver.CERTIFIED_PASS) | (
                    (status == fast_solver.CERTIFIED_FAIL) & (loss_rtol is not None)
                )
                redo_mask = status == fast_solver.UNDECIDED
                if loss_rtol is not None:
                    redo_mask |= (status == fast_solver.CERTIFIED_FAIL) & (
                        loss - low > loss_rtol * loss + loss_atol
                    )
                redo = np.argwhere(redo_mask)
            else:
                redo = np.argwhere(np.ones((rows.size, k), dtype=bool))
            if redo.size:
                _solve_reference(
                    points,
                    axes,
                    W,
                    mu,
                    f_high,
                    rows[redo[:, 0]],
                    redo[:, 1],
                    forces,
                    losses,
                    lower,
                    solved_by,
                )
                converged[rows[redo[:, 0]], redo[:, 1]] = True
            if bar is not None:
                bar.update(int(rows.size))
    finally:
        if bar is not None:
            bar.close()

    passed = rank_ok & np.all(np.nan_to_num(losses, nan=np.inf) <= threshold, axis=1)
    with np.errstate(invalid="ignore"):
        loss = np.where(rank_ok, np.nanmax(np.where(rank_ok[:, None], losses, 0.0), axis=1), np.nan)
    parameters: dict[str, object] = {
        "convention": convention,
        "method": method,
        "mass": mass,
        "gravity": gravity,
        "mu": mu,
        "f_high": f_high,
        "threshold": threshold,
        "loss_rtol": loss_rtol,
        "loss_exact": loss_rtol is not None,
        "loss_atol": loss_atol,
    }
    return ForceClosureResult(
        loss=loss,
        losses=losses,
        loss_lower=lower,
        loss_converged=converged,
        passed=passed,
        rank_ok=rank_ok,
        contact_forces=forces,
        solved_by=solved_by,
        quality=quality,
        wrenches=W,
        parameters=parameters,
    )


def _rank_and_quality(
    points: FloatArray, axes: FloatArray, *, compiled: bool
) -> tuple[NDArray[np.bool_], FloatArray]:
    """Rank test (exactly ``matrix_rank(G) == 6``) and Q(G) for every pair.

    The compiled statistics settle well-conditioned pairs and their Q(G) in one pass; the rest
    (near-collinear contacts) go through the exact numpy tests.
    """
    if not compiled:
        return full_rank(points, axes), grasp_quality(points)
    from . import fast_solver

    clear = np.zeros(points.shape[0], dtype=bool)
    quality = np.full(points.shape[0], np.nan)
    fast_solver.gram_statistics(np.ascontiguousarray(points), clear, quality, SAFE_CONDITION**2)
    rest = np.flatnonzero(~clear)
    rank_ok = clear.copy()
    if rest.size:
        rank_ok[rest] = full_rank(points[rest], axes[rest])
        quality[rest] = grasp_quality(points[rest])
    return rank_ok, quality


def _solve_reference(
    points: FloatArray,
    axes: FloatArray,
    W: FloatArray,
    mu: float,
    f_high: float,
    pairs: NDArray[np.intp],
    wrench_rows: NDArray[np.intp],
    forces: FloatArray,
    losses: FloatArray,
    lower: FloatArray,
    solved_by: NDArray[np.uint8],
) -> None:
    """Solve the (pair, wrench) problems with Clarabel and write the outcomes in place."""
    from .clarabel_solver import solve_batch

    batch = solve_batch(points[pairs], axes[pairs], W[wrench_rows], mu=mu, f_high=f_high)
    for i, j, status in zip(pairs, wrench_rows, batch.statuses, strict=True):
        if status != "Solved":
            log.info("pair %d wrench %d: Clarabel status %s", i, j, status)
    forces[pairs, wrench_rows] = batch.forces
    losses[pairs, wrench_rows] = batch.losses
    lower[pairs, wrench_rows] = np.nan  # an interior-point solve gives no separate bound here
    solved_by[pairs, wrench_rows] = SOLVED_CLARABEL
