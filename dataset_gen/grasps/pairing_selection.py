"""The selection of stored pairs: up to ``max_passing`` passing and ``max_failing`` failing pairs
of one object, the failing ones with a loss proven over ``failing_min_loss``.

:func:`select_pairs` takes the verdict-only force closure of the scored candidates
(:func:`~dataset_gen.grasps.pairing.score_pairs`), draws a uniform subset of the passing pairs and walks
the failing pool in a random order, solving each pair exactly until enough are kept; the
:class:`Selection` holds the two blocks, passing first, as the release stores them. The pairing
itself (candidates, contacts, ablations) lives in :mod:`dataset_gen.grasps.pairing`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dataset_gen.force_closure import ForceClosureResult, evaluate
from dataset_gen.grasps.pairing_checks import (
    BoolArray,
    FloatArray,
    IntArray,
    PairingError,
    _check_count,
    _check_nonnegative,
    _check_rng,
)
from dg16m_core.parameters import PAPER

#: Release parameters (DESIGN.md), aliases of :data:`dg16m_core.parameters.PAPER`'s fields:
#: up to 2000 passing and 2000 failing pairs are kept, the failing ones with loss > 0.5.
DEFAULT_MAX_PASSING = PAPER.max_passing
DEFAULT_MAX_FAILING = PAPER.max_failing
DEFAULT_FAILING_MIN_LOSS = PAPER.failing_min_loss
#: Accuracy of the exact losses computed for the selected failing pairs.
DEFAULT_SELECTION_LOSS_RTOL = 1e-4


# --------------------------------------------------------------------------------------------
# Selection
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Selection:
    """The pairs kept for one object: up to ``max_passing`` passing then ``max_failing`` failing.

    S = ``selected_passing + selected_failing`` rows, passing block first, each block sorted
    by index (the release's layout: ``fc_passing_indices`` = ``0 .. S_pass - 1``).

    Attributes:
        indices: ``(S,)`` rows of the scored pairs (index the candidates' ``pairs`` with it).
        passed: ``(S,)`` force-closure verdicts (True for the passing block).
        loss: ``(S,)`` loss (N): the attained residual (<= threshold) of passing pairs, the
            exact optimum (to ``loss_rtol``) of failing pairs, each proven > ``failing_min_loss``.
        contact_forces: ``(S, 4, 3)`` optimal contact forces for the first external wrench,
            object frame (N).
        quality: ``(S,)`` Q(G).
        counts: ``candidates``, ``rank_deficient``, ``passing``, ``failing`` (full rank, not
            passing), ``failing_over_min_loss`` (loss proven > min loss: by the verdict-only
            bounds, a lower bound on the true count; exact with ``exact_counts``),
            ``failing_maybe_over_min_loss`` (upper bound above the min loss, lower bound not:
            undecided by the bounds; 0 with ``exact_counts``), ``failing_reevaluated`` (pairs
            whose exact loss was computed), ``selected_passing``, ``selected_failing``.
    """

    indices: IntArray
    passed: BoolArray
    loss: FloatArray
    contact_forces: FloatArray
    quality: FloatArray
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of selected pairs S."""
        return int(self.indices.shape[0])

    @property
    def passing_indices(self) -> IntArray:
        """Rows of the passing block (sorted)."""
        return self.indices[self.passed]

    @property
    def failing_indices(self) -> IntArray:
        """Rows of the failing block (sorted)."""
        return self.indices[~self.passed]


def proven_loss_lower(result: ForceClosureResult) -> FloatArray:
    """``(N,)`` a proven lower bound on each pair's loss (max over wrenches); 0 where unknown.

    The fast path's dual bound or Clarabel's dual bound (never an attained loss, which is an
    upper bound); rank-deficient pairs get 0 (they are not solved). See
    :attr:`~dataset_gen.force_closure.ForceClosureResult.pair_loss_lower`.
    """
    return result.pair_loss_lower


def _reevaluate(
    result: ForceClosureResult,
    points: FloatArray,
    normals: FloatArray,
    rows: IntArray,
    loss_rtol: float,
) -> ForceClosureResult:
    """Evaluate ``rows`` again with ``result``'s problem and a loss accuracy of ``loss_rtol``."""
    return evaluate(points[rows], normals[rows], **{**result.settings(), "loss_rtol": loss_rtol})


def select_pairs(
    result: ForceClosureResult,
    contact_points: FloatArray,
    contact_normals: FloatArray,
    *,
    rng: np.random.Generator,
    max_passing: int = DEFAULT_MAX_PASSING,
    max_failing: int = DEFAULT_MAX_FAILING,
    failing_min_loss: float = DEFAULT_FAILING_MIN_LOSS,
    loss_rtol: float = DEFAULT_SELECTION_LOSS_RTOL,
    exact_counts: bool = False,
) -> Selection:
    """Choose the pairs to store: up to ``max_passing`` passing and ``max_failing`` failing pairs
    whose loss is PROVEN to exceed ``failing_min_loss``, each block a uniform random subset.

    Passing: a random subset when there are more than ``max_passing``. Failing: the pool is
    every full-rank failing pair whose verdict-only upper bound exceeds ``failing_min_loss``; in
    a random order, pairs are re-evaluated with exact losses (``loss_rtol``) in batches and kept
    when their exact lower bound exceeds ``failing_min_loss``, until ``max_failing`` are kept or
    the pool is exhausted. That is a uniform sample of the pairs with loss > ``failing_min_loss``
    (pairs within ``loss_rtol`` of the limit aside) and costs about ``max_failing`` exact solves.
    Rank-deficient pairs are never selected (they have no loss).

    Args:
        result: force closure of the N scored pairs (normally verdict-only,
            :func:`~dataset_gen.grasps.pairing.score_pairs`).
        contact_points, contact_normals: ``(N, 4, 3)`` the contacts that were scored
            (:func:`~dataset_gen.grasps.pairing.dual_contacts`), for the exact re-evaluation with
            ``result.parameters``.
        rng: random generator; the selection is a function of it and the inputs.
        max_passing, max_failing: caps (the release: 2000 each).
        failing_min_loss: failing pairs must have a loss above this (N; the release: 0.5).
        loss_rtol: relative accuracy of the exact losses of the failing pairs.
        exact_counts: also settle every pair the verdict-only bounds leave undecided about
            ``failing_min_loss`` (a few % of the failing pairs, ~0.1-0.2 s for 100k candidates),
            so that ``counts["failing_over_min_loss"]`` is exact and
            ``counts["failing_maybe_over_min_loss"]`` is 0. The selection is the same either way.

    Returns:
        :class:`Selection`.
    """
    if not isinstance(result, ForceClosureResult):
        raise PairingError(
            f"result: expected a ForceClosureResult (score_pairs), found {type(result).__name__}"
        )
    rng = _check_rng(rng)
    max_passing = _check_count("max_passing", max_passing)
    max_failing = _check_count("max_failing", max_failing)
    failing_min_loss = _check_nonnegative("failing_min_loss", failing_min_loss)
    loss_rtol = _check_nonnegative("loss_rtol", loss_rtol)
    points, normals = _scored_contacts(result.n, contact_points, contact_normals)

    passed = np.asarray(result.passed, dtype=bool)
    failing = np.asarray(result.rank_ok, dtype=bool) & ~passed
    lower = proven_loss_lower(result)
    upper = np.where(failing, np.nan_to_num(result.loss, nan=0.0), 0.0)
    certain = failing & (lower > failing_min_loss)
    maybe = failing & ~certain & (upper > failing_min_loss)

    # The generator draws the passing subset first, then the order of the failing pool.
    pass_rows = _draw_passing(passed, max_passing, rng)
    exact = _ExactFailing(result, points, normals, loss_rtol, failing_min_loss)
    pool = np.flatnonzero(certain | maybe)
    pool = pool[rng.permutation(len(pool))] if len(pool) else pool
    if exact_counts and maybe.any():
        certain, maybe = _settle_undecided(exact, certain, maybe)
    fail_rows = _draw_failing(exact, pool, max_failing)
    counts = {
        "candidates": result.n,
        "rank_deficient": int((~np.asarray(result.rank_ok, dtype=bool)).sum()),
        "passing": int(passed.sum()),
        "failing": int(failing.sum()),
        "failing_over_min_loss": int(certain.sum()),
        "failing_maybe_over_min_loss": int(maybe.sum()),
        "failing_reevaluated": exact.reevaluated,
        "selected_passing": len(pass_rows),
        "selected_failing": len(fail_rows),
    }
    return _selection(result, pass_rows, fail_rows, exact, counts)


def _scored_contacts(
    n: int, contact_points: FloatArray, contact_normals: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The contacts of the N scored pairs as float64 ``(N, 4, 3)`` arrays, shapes checked."""
    points = np.asarray(contact_points, dtype=np.float64)
    normals = np.asarray(contact_normals, dtype=np.float64)
    for name, array in (("contact_points", points), ("contact_normals", normals)):
        if array.shape != (n, 4, 3):
            raise PairingError(
                f"{name}: expected shape ({n}, 4, 3) (one row per scored pair), found {array.shape}"
            )
    return points, normals


def _draw_passing(passed: BoolArray, max_passing: int, rng: np.random.Generator) -> IntArray:
    """The passing block: every passing row, or a sorted uniform subset of ``max_passing``."""
    pass_rows = np.flatnonzero(passed)
    if len(pass_rows) > max_passing:
        pass_rows = np.sort(rng.choice(pass_rows, size=max_passing, replace=False))
    return pass_rows


@dataclass
class _ExactFailing:
    """Exact losses of failing pairs, each row solved at most once.

    ``outcome[row]`` is ``(kept, loss, forces)``: kept when the exact result is full rank, fails,
    and its proven lower bound exceeds ``failing_min_loss``; ``reevaluated`` counts the rows solved.
    """

    result: ForceClosureResult
    points: FloatArray
    normals: FloatArray
    loss_rtol: float
    failing_min_loss: float
    outcome: dict[int, tuple[bool, float, FloatArray]] = field(default_factory=dict)
    reevaluated: int = 0

    def settle(self, rows: IntArray) -> None:
        """Solve the rows of ``rows`` not solved yet, in one batch."""
        todo = np.array([r for r in rows.tolist() if r not in self.outcome], dtype=np.int64)
        if len(todo) == 0:
            return
        exact = _reevaluate(self.result, self.points, self.normals, todo, self.loss_rtol)
        self.reevaluated += len(todo)
        ok = ~exact.passed & exact.rank_ok & (proven_loss_lower(exact) > self.failing_min_loss)
        for k, r in enumerate(todo.tolist()):
            self.outcome[r] = (bool(ok[k]), float(exact.loss[k]), exact.forces[k])

    def kept(self, row: int) -> bool:
        """Whether a settled row's loss is proven over the minimum."""
        return self.outcome[row][0]


def _settle_undecided(
    exact: _ExactFailing, certain: BoolArray, maybe: BoolArray
) -> tuple[BoolArray, BoolArray]:
    """Solve every pair the verdict-only bounds leave undecided (``exact_counts``): the exact
    ``certain`` mask and an all-False ``maybe``."""
    undecided = np.flatnonzero(maybe)
    exact.settle(undecided)
    resolved = np.array([exact.kept(r) for r in undecided.tolist()], dtype=bool)
    certain = certain.copy()
    certain[undecided[resolved]] = True
    return certain, np.zeros_like(maybe)


def _draw_failing(exact: _ExactFailing, pool: IntArray, max_failing: int) -> IntArray:
    """The failing block: walk ``pool`` (already in a random order) in batches, solving each
    pair exactly, and keep the first ``max_failing`` whose loss is proven over the minimum.
    Returns the kept rows sorted."""
    kept: list[int] = []
    cursor = 0
    while len(kept) < max_failing and cursor < len(pool):
        need = max_failing - len(kept)
        batch = pool[cursor : cursor + max(need + need // 8 + 16, 64)]
        cursor += len(batch)
        exact.settle(batch)
        kept.extend([r for r in batch.tolist() if exact.kept(r)][:need])
    return np.sort(np.array(kept, dtype=np.int64))


def _selection(
    result: ForceClosureResult,
    pass_rows: IntArray,
    fail_rows: IntArray,
    exact: _ExactFailing,
    counts: dict[str, int],
) -> Selection:
    """The :class:`Selection` of the two blocks, passing first."""
    fail_loss = np.array([exact.outcome[r][1] for r in fail_rows.tolist()], dtype=np.float64)
    fail_forces = np.array(
        [exact.outcome[r][2] for r in fail_rows.tolist()], dtype=np.float64
    ).reshape(-1, 4, 3)
    indices = np.concatenate([pass_rows, fail_rows]).astype(np.int64)
    return Selection(
        indices=indices,
        passed=np.concatenate([np.ones(len(pass_rows), bool), np.zeros(len(fail_rows), bool)]),
        loss=np.concatenate([result.loss[pass_rows], fail_loss]),
        contact_forces=np.concatenate([result.forces[pass_rows], fail_forces]),
        quality=np.asarray(result.quality)[indices],
        counts=counts,
    )


__all__ = [
    "DEFAULT_FAILING_MIN_LOSS",
    "DEFAULT_MAX_FAILING",
    "DEFAULT_MAX_PASSING",
    "DEFAULT_SELECTION_LOSS_RTOL",
    "Selection",
    "proven_loss_lower",
    "select_pairs",
]
