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

What a verdict proves
---------------------
A pass is always proven: the returned forces are feasible and attain a residual ``<= threshold``.
A failure is proven when a dual certificate gives a lower bound ``> threshold`` (``loss_lower``):
the fast path certifies with a 1 % margin and sends the rest to Clarabel, whose solves get a dual
bound too. Where Clarabel's bounds at its default tolerances straddle the threshold
(``loss_lower <= threshold < loss``), the problem is solved again at tight tolerances
(``SOLVED_CLARABEL_TIGHT``) before the verdict is stored and the better bounds of the two solves
are kept. The band is thus set by the bounds, not by a fixed factor; measured on pairs whose loss
is spread over ``[threshold / 3, 3 threshold]`` and within 1 % of it, it is losses in about
``(threshold, 1.0074 threshold]`` (BENCHMARKS.md). :attr:`ForceClosureResult.verdict_proven`
says which verdicts are proven; the few that a tight solve still cannot settle fail (no forces
attaining the threshold were found).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from dg16m_core.checks import check_integer, check_number
from dg16m_core.errors import ForceClosureError
from dg16m_core.parameters import PAPER

from .geometry import SAFE_CONDITION, FloatArray, full_rank, grasp_quality

log = logging.getLogger(__name__)

Convention = Literal["physical", "release"]
Method = Literal["auto", "fast", "clarabel"]
CONVENTIONS: tuple[str, ...] = ("physical", "release")
METHODS: tuple[str, ...] = ("auto", "fast", "clarabel")

#: How each (pair, wrench) verdict was reached.
SOLVED_NONE = 0  # rank-deficient: not solved, fails by the rank test
SOLVED_FAST = 1  # certified by the compiled fast path
SOLVED_CLARABEL = 2  # solved by the Clarabel reference solver
SOLVED_CLARABEL_TIGHT = 3  # Clarabel again at tight tolerances: its default bounds straddled

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
        losses: ``(N, K)`` loss per wrench, always ATTAINED by ``contact_forces`` (an upper bound
            on the optimum). For passes it is at most ``threshold``; for failures it is the
            optimum to ``loss_rtol`` where ``loss_converged``.
        loss_lower: ``(N, K)`` a proven lower bound on each loss (>= 0): the dual certificate
            of the fast path (0 for its passes) or the dual bound of Clarabel's solution; NaN
            for rank-deficient pairs (not solved).
        loss_converged: ``(N, K)`` True where ``losses`` is the optimum (to ``loss_rtol``):
            Clarabel solves, fast-path passes and refined failures. False only in verdict-only
            mode (``loss_rtol=None``) for failures, whose loss is then an attained upper bound.
        passed: ``(N,)`` full rank and every loss ``<= threshold``.
        rank_ok: ``(N,)`` ``numpy.linalg.matrix_rank(G) == 6``.
        contact_forces: ``(N, K, 4, 3)`` the optimal contact forces per wrench, object frame (N);
            zero for rank-deficient pairs.
        solved_by: ``(N, K)`` uint8: ``SOLVED_NONE``, ``SOLVED_FAST``, ``SOLVED_CLARABEL`` or
            ``SOLVED_CLARABEL_TIGHT``.
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
        clarabel = (self.solved_by == SOLVED_CLARABEL) | (self.solved_by == SOLVED_CLARABEL_TIGHT)
        return float(clarabel.sum() / total) if total else 0.0

    @property
    def pair_loss_lower(self) -> FloatArray:
        """``(N,)`` a proven lower bound on each pair's loss: the largest ``loss_lower`` over the
        wrenches; 0 for rank-deficient pairs (not solved)."""
        if self.loss_lower.shape[1] == 0:
            return np.zeros(self.n)
        lower = np.where(self.rank_ok[:, None], np.nan_to_num(self.loss_lower, nan=0.0), 0.0)
        return lower.max(axis=1)

    def settings(self) -> dict[str, Any]:
        """Keyword arguments of :func:`evaluate` that reproduce this result's problem (the
        convention, the physical parameters, the wrenches and the loss accuracy), e.g. to
        re-evaluate some of its pairs: ``evaluate(p[rows], n[rows], **{**r.settings(), ...})``."""
        keys = ("convention", "mass", "gravity", "mu", "f_high", "threshold", "loss_rtol")
        kwargs: dict[str, Any] = {key: self.parameters[key] for key in (*keys, "loss_atol")}
        return {**kwargs, "wrenches": self.wrenches}

    @property
    def verdict_proven(self) -> NDArray[np.bool_]:
        """``(N,)`` whether each verdict is proven: a pass (forces attain it), a rank-deficient
        pair (the rank test is exact) or a failure with some ``loss_lower > threshold``."""
        threshold = float(self.parameters.get("threshold", PAPER.threshold))  # type: ignore[arg-type]
        with np.errstate(invalid="ignore"):
            certified = np.any(self.loss_lower > threshold, axis=1)
        return self.passed | ~self.rank_ok | certified


def gravity_wrench(mass: float = PAPER.mass, gravity: float = PAPER.gravity) -> FloatArray:
    """The object's weight as a wrench about its centroid, ``(6,)``: ``(0, 0, -m g, 0, 0, 0)``."""
    return np.array([0.0, 0.0, -mass * gravity, 0.0, 0.0, 0.0])


def axis_gravity_wrenches(mass: float = PAPER.mass, gravity: float = PAPER.gravity) -> FloatArray:
    """The weight pulling along each of ``-z, +z, -x, +x, -y, +y``, ``(6, 6)``.

    The first row is ordinary gravity, so ``result.forces`` stays the gravity solution.
    """
    weight = mass * gravity
    out = np.zeros((6, 6))
    for row, (axis, sign) in enumerate([(2, -1), (2, 1), (0, -1), (0, 1), (1, -1), (1, 1)]):
        out[row, axis] = sign * weight
    return out


# --------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------


def _number(name: str, value: Any, *, allow_zero: bool = False) -> float:
    return check_number(name, value, allow_zero=allow_zero, error=ForceClosureError)


def _integer(name: str, value: Any, minimum: int) -> int:
    return check_integer(name, value, minimum=minimum, error=ForceClosureError)


@dataclass(frozen=True)
class _Settings:
    """The validated keyword arguments of :func:`evaluate`."""

    mass: float
    gravity: float
    mu: float
    f_high: float
    threshold: float
    convention: str
    method: str
    loss_rtol: float | None
    loss_atol: float
    max_iterations: int
    max_refine: int
    chunk_size: int

    @classmethod
    def check(cls, **values: Any) -> _Settings:
        if values["convention"] not in CONVENTIONS:
            raise ForceClosureError(
                f"convention: expected one of {CONVENTIONS}, found {values['convention']!r}"
            )
        if values["method"] not in METHODS:
            raise ForceClosureError(
                f"method: expected one of {METHODS}, found {values['method']!r}"
            )
        rtol = values["loss_rtol"]
        return cls(
            mass=_number("mass", values["mass"]),
            gravity=_number("gravity", values["gravity"], allow_zero=True),
            mu=_number("mu", values["mu"], allow_zero=True),
            f_high=_number("f_high", values["f_high"]),
            threshold=_number("threshold", values["threshold"]),
            convention=values["convention"],
            method=values["method"],
            loss_rtol=None if rtol is None else _number("loss_rtol", rtol, allow_zero=True),
            loss_atol=_number("loss_atol", values["loss_atol"], allow_zero=True),
            max_iterations=_integer("max_iterations", values["max_iterations"], 1),
            max_refine=_integer("max_refine", values["max_refine"], 0),
            chunk_size=_integer("chunk_size", values["chunk_size"], 1),
        )

    def parameters(self, method: str) -> dict[str, object]:
        """What :attr:`ForceClosureResult.parameters` records."""
        return {
            "convention": self.convention,
            "method": method,
            "mass": self.mass,
            "gravity": self.gravity,
            "mu": self.mu,
            "f_high": self.f_high,
            "threshold": self.threshold,
            "loss_rtol": self.loss_rtol,
            "loss_exact": self.loss_rtol is not None,
            "loss_atol": self.loss_atol,
        }


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
                f"{name}: expected shape (N, 4, 3) (four 3-D contacts per pair), "
                f"found {array.shape}"
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
            f"< {_MIN_NORMAL:g}, first at pair {pair} contact {contact}: "
            f"{n[pair, contact].tolist()}"
        )
    return p, n / length[..., None]


def _validate_wrenches(wrenches: object, mass: float, gravity: float) -> FloatArray:
    if wrenches is None or (isinstance(wrenches, str) and wrenches == "gravity"):
        return gravity_wrench(mass, gravity)[None]
    if isinstance(wrenches, str):
        if wrenches == "axis_gravity":
            return axis_gravity_wrenches(mass, gravity)
        raise ForceClosureError(
            "wrenches: expected None, 'gravity', 'axis_gravity' or a (K, 6) array, "
            f"found {wrenches!r}"
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


# --------------------------------------------------------------------------------------------
# Entry point
# --------------------------------------------------------------------------------------------


def evaluate(
    contact_points: FloatArray,
    contact_normals: FloatArray,
    *,
    mass: float = PAPER.mass,
    gravity: float = PAPER.gravity,
    mu: float = PAPER.mu,
    f_high: float = PAPER.f_high,
    threshold: float = PAPER.threshold,
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
            and ``loss_lower`` a proven lower bound (both above ``threshold`` where the verdict
            is proven); re-evaluate the pairs whose exact loss you need.
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
    settings = _Settings.check(
        mass=mass,
        gravity=gravity,
        mu=mu,
        f_high=f_high,
        threshold=threshold,
        convention=convention,
        method=method,
        loss_rtol=loss_rtol,
        loss_atol=loss_atol,
        max_iterations=max_iterations,
        max_refine=max_refine,
        chunk_size=chunk_size,
    )
    W = _validate_wrenches(wrenches, settings.mass, settings.gravity)
    axes = -normals if settings.convention == "physical" else normals
    n, k = points.shape[0], W.shape[0]
    chosen = settings.method
    if chosen == "auto":
        chosen = "fast" if n * k > 8 else "clarabel"

    rank_ok, quality = _rank_and_quality(points, axes, compiled=chosen == "fast")
    out = _Problems.empty(n, k)
    todo = np.flatnonzero(rank_ok)
    with _progress(progress, int(todo.size)) as advance:
        for start in range(0, todo.size, settings.chunk_size):
            rows = todo[start : start + settings.chunk_size]
            if chosen == "fast":
                redo = _solve_fast(points, axes, W, rows, settings, out)
            else:
                redo = np.argwhere(np.ones((rows.size, k), dtype=bool))
            if redo.size:
                _solve_reference(points, axes, W, rows[redo[:, 0]], redo[:, 1], settings, out)
            advance(int(rows.size))
    return out.result(rank_ok, quality, W, settings.threshold, settings.parameters(chosen))


# --------------------------------------------------------------------------------------------
# Steps
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Problems:
    """Outcome arrays of the N x K (pair, wrench) problems, filled in place by the solvers."""

    forces: FloatArray
    losses: FloatArray
    lower: FloatArray
    solved_by: NDArray[np.uint8]
    converged: NDArray[np.bool_]

    @classmethod
    def empty(cls, n: int, k: int) -> _Problems:
        return cls(
            forces=np.zeros((n, k, 4, 3)),
            losses=np.full((n, k), np.nan),
            lower=np.full((n, k), np.nan),
            solved_by=np.zeros((n, k), dtype=np.uint8),
            converged=np.zeros((n, k), dtype=bool),
        )

    def result(
        self,
        rank_ok: NDArray[np.bool_],
        quality: FloatArray,
        W: FloatArray,
        threshold: float,
        parameters: dict[str, object],
    ) -> ForceClosureResult:
        """The verdicts (full rank, every loss ``<= threshold``) and the result record."""
        losses = self.losses
        passed = rank_ok & np.all(np.nan_to_num(losses, nan=np.inf) <= threshold, axis=1)
        with np.errstate(invalid="ignore"):
            worst = np.nanmax(np.where(rank_ok[:, None], losses, 0.0), axis=1)
        return ForceClosureResult(
            loss=np.where(rank_ok, worst, np.nan),
            losses=losses,
            loss_lower=self.lower,
            loss_converged=self.converged,
            passed=passed,
            rank_ok=rank_ok,
            contact_forces=self.forces,
            solved_by=self.solved_by,
            quality=quality,
            wrenches=W,
            parameters=parameters,
        )


@contextmanager
def _progress(enabled: bool, total: int) -> Iterator[Callable[[int], None]]:
    """A function that advances a progress bar by a number of pairs (does nothing if disabled)."""
    if not enabled:
        yield lambda _: None
        return
    from dg16m_core.progress import progress_bar

    bar = progress_bar(total=total, unit="pair", desc="force closure", smoothing=0.1)
    try:
        yield lambda count: bar.update(count)
    finally:
        bar.close()


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


def _solve_fast(
    points: FloatArray,
    axes: FloatArray,
    W: FloatArray,
    rows: NDArray[np.intp],
    settings: _Settings,
    out: _Problems,
) -> NDArray[np.intp]:
    """Run the compiled fast path on ``rows``; returns the ``(row index, wrench)`` problems it
    left to Clarabel: undecided ones, and in exact-loss mode failures short of the accuracy."""
    from . import fast_solver

    exact = settings.loss_rtol is not None
    rtol = settings.loss_rtol if settings.loss_rtol is not None else 0.0
    f, loss, low, status, _ = fast_solver.run(
        points[rows],
        axes[rows],
        W,
        mu=settings.mu,
        f_high=settings.f_high,
        threshold=settings.threshold,
        margin=CERTIFICATE_MARGIN,
        loss_rtol=rtol,
        loss_atol=settings.loss_atol,
        max_iterations=settings.max_iterations,
        max_refine=settings.max_refine if exact else 0,
        squeeze=settings.f_high,
    )
    out.forces[rows] = f
    out.losses[rows] = loss
    out.lower[rows] = low
    out.solved_by[rows] = SOLVED_FAST
    failed = status == fast_solver.CERTIFIED_FAIL
    out.converged[rows] = (status == fast_solver.CERTIFIED_PASS) | (failed & exact)
    redo = status == fast_solver.UNDECIDED
    if exact:
        redo |= failed & (loss - low > rtol * loss + settings.loss_atol)
    return np.argwhere(redo)


def _solve_reference(
    points: FloatArray,
    axes: FloatArray,
    W: FloatArray,
    pairs: NDArray[np.intp],
    wrench_rows: NDArray[np.intp],
    settings: _Settings,
    out: _Problems,
) -> None:
    """Solve the (pair, wrench) problems with Clarabel and write the outcomes in place.

    Problems whose bounds straddle the threshold (attained loss above it, dual bound not) are
    solved again at tight tolerances, so that near the threshold the stored verdict is proven or,
    failing that, the verdict of a tight solve.
    """
    from .clarabel_solver import best_of, solve_batch

    mu, f_high, threshold = settings.mu, settings.f_high, settings.threshold
    batch = solve_batch(points[pairs], axes[pairs], W[wrench_rows], mu=mu, f_high=f_high)
    forces, losses, lower = batch.forces, batch.losses, batch.lower
    statuses = list(batch.statuses)
    solved_by = np.full(pairs.size, SOLVED_CLARABEL, dtype=np.uint8)
    straddle = np.flatnonzero((losses > threshold) & ~(lower > threshold))
    if straddle.size:
        tight = solve_batch(
            points[pairs[straddle]],
            axes[pairs[straddle]],
            W[wrench_rows[straddle]],
            mu=mu,
            f_high=f_high,
            tight=True,
        )
        first = type(batch)(
            forces=forces[straddle],
            losses=losses[straddle],
            lower=lower[straddle],
            statuses=[statuses[i] for i in straddle.tolist()],
        )
        sharp = best_of(first, tight)
        forces[straddle] = sharp.forces
        losses[straddle] = sharp.losses
        lower[straddle] = sharp.lower
        solved_by[straddle] = SOLVED_CLARABEL_TIGHT
        for index, status in zip(straddle.tolist(), sharp.statuses, strict=True):
            statuses[index] = f"{status} (tight)"
    for i, j, status in zip(pairs, wrench_rows, statuses, strict=True):
        if not status.startswith("Solved"):
            log.info("pair %d wrench %d: Clarabel status %s", i, j, status)
    out.forces[pairs, wrench_rows] = forces
    out.losses[pairs, wrench_rows] = losses
    # Keep the better of the fast path's bound (where it ran) and Clarabel's; a loss is >= 0.
    known = np.nan_to_num(out.lower[pairs, wrench_rows], nan=0.0)
    out.lower[pairs, wrench_rows] = np.fmax(np.fmax(known, lower), 0.0)
    out.solved_by[pairs, wrench_rows] = solved_by
    out.converged[pairs, wrench_rows] = True
