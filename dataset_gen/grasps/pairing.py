"""Dual-arm pairing of single-arm grasps, its ablations, and the selection of stored pairs.

Pipeline for one object (DG16M paper, Section III-B; DESIGN.md "Facts to honour")::

    cands = candidate_pairs(grasps)                 # all i < j, centre pruning, gripper-gripper
    fc = score_pairs(grasps, cands.pairs)           # force closure, verdict-only (fast)
    points, normals = dual_contacts(grasps, cands.pairs)
    sel = select_pairs(fc, points, normals, rng=rng)  # <= 2000 passing + <= 2000 failing (L > 0.5)
    pairs = cands.pairs[sel.indices]                # (S, 2) grasp indices, passing block first

Grasp centre
------------
The centre of a single-arm grasp is the midpoint of its two contacts
(:attr:`SingleArmGrasps.centers`), not the gripper pose's translation. This is what the released
code prunes on: its sampler builds each grasp from ``grasp_centers = 0.5 * (p1 + p2)`` and the
pair distance is ``|c1 - c2| + alpha * (2 / pi) * arccos(clip(a1 . a2, 0, 1))`` with the grasp
axes ``a``, pairs kept when it exceeds 0.1 m. The axis term adds at most ``alpha`` (dex-net's
``grasp_dist_alpha``, 0.005 by default); this module prunes on the centre distance alone.

Contact order
-------------
A dual grasp ``(i, j)`` has four contacts ``[i finger 0, i finger 1, j finger 0, j finger 1]``
and two poses ``[i, j]``, as in the release's ``grasps/contact_points`` and ``grasps/grasps``.

Ablations (paper, Table III)
----------------------------
:func:`make_pairs` produces pairs by ``"force_closure"`` (every candidate, scored; the dataset keeps
the passing ones), ``"random"`` (uniformly random distinct pairs) or ``"farthest"`` (each grasp
with the grasp whose centre is farthest from its own), all scored by the same force-closure check;
:func:`strategy_pass_rates` reports the fraction of each strategy's pairs that pass.

Units: metres, newtons. All functions are deterministic given their ``rng``.

The selection of stored pairs (:func:`select_pairs`, :class:`Selection`) lives in
:mod:`dataset_gen.grasps.pairing_selection`, the input checks and :class:`PairingError` in
:mod:`dataset_gen.grasps.pairing_checks`; their public names are re-exported here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from dataset_gen.force_closure import ForceClosureResult, evaluate
from dataset_gen.grasps.gripper import GripperModel, get_gripper
from dataset_gen.grasps.pairing_checks import (
    BoolArray,
    FloatArray,
    IntArray,
    PairingError,
    _check_count,
    _check_grasps,
    _check_nonnegative,
    _check_pairs,
    _check_rng,
)
from dataset_gen.grasps.pairing_selection import (
    DEFAULT_FAILING_MIN_LOSS,
    DEFAULT_MAX_FAILING,
    DEFAULT_MAX_PASSING,
    DEFAULT_SELECTION_LOSS_RTOL,
    Selection,
    proven_loss_lower,
    select_pairs,
)
from dataset_gen.grasps.sampling import SingleArmGrasps
from dg16m_core.parameters import PAPER

Strategy = Literal["force_closure", "random", "farthest"]
STRATEGIES: tuple[str, ...] = ("force_closure", "random", "farthest")
"""The pairing strategies :func:`make_pairs` takes (the values of ``Strategy``)."""

#: Release parameter (DESIGN.md), an alias of :data:`dg16m_core.parameters.PAPER`'s field:
#: pairs whose grasp centres are closer than 0.1 m are pruned (the selection's caps are in
#: :mod:`dataset_gen.grasps.pairing_selection`).
DEFAULT_MIN_CENTER_DISTANCE = PAPER.min_center_distance

#: Added to |R| in the separating-axis test so that (near-)parallel edge pairs, whose cross
#: product vanishes, cannot report a separation through rounding (conservative by ~1e-9 m).
SAT_EPSILON = 1e-9

_CHUNK = 8192


# --------------------------------------------------------------------------------------------
# Oriented boxes: separating-axis test
# --------------------------------------------------------------------------------------------


def _sat_separated(R: FloatArray, t: FloatArray, ea: FloatArray, eb: FloatArray) -> BoolArray:
    """Separating-axis test (15 axes) for oriented boxes A and B, broadcast over leading axes.

    Args:
        R: ``(..., 3, 3)`` B's axes in A's frame: ``R[..., i, j] = a_i . b_j``.
        t: ``(..., 3)`` B's centre minus A's centre, in A's frame (m).
        ea, eb: ``(..., 3)`` half extents of A and B along their own axes (m).

    Returns:
        ``(...)`` True where some axis separates the boxes strictly (touching boxes overlap).
    """
    absR = np.abs(R) + SAT_EPSILON
    # A's face normals a_i: radius of B is sum_j eb_j |R_ij|.
    rb = (absR * eb[..., None, :]).sum(axis=-1)
    sep = (np.abs(t) > ea + rb).any(axis=-1)
    # B's face normals b_j: projection of t is t . R[:, j].
    ra = (absR * ea[..., :, None]).sum(axis=-2)
    tb = (t[..., :, None] * R).sum(axis=-2)
    sep |= (np.abs(tb) > ra + eb).any(axis=-1)
    # Edge-edge axes a_i x b_j: entries [i, j] with i1 = i + 1, i2 = i + 2 (mod 3), same for j.
    R_i1, R_i2 = np.roll(R, -1, axis=-2), np.roll(R, -2, axis=-2)
    A_i1, A_i2 = np.roll(absR, -1, axis=-2), np.roll(absR, -2, axis=-2)
    A_j1, A_j2 = np.roll(absR, -1, axis=-1), np.roll(absR, -2, axis=-1)
    t_i1, t_i2 = np.roll(t, -1, axis=-1), np.roll(t, -2, axis=-1)
    ea_i1, ea_i2 = np.roll(ea, -1, axis=-1), np.roll(ea, -2, axis=-1)
    eb_j1, eb_j2 = np.roll(eb, -1, axis=-1), np.roll(eb, -2, axis=-1)
    lhs = np.abs(t_i2[..., :, None] * R_i1 - t_i1[..., :, None] * R_i2)
    rhs = (
        ea_i1[..., :, None] * A_i2
        + ea_i2[..., :, None] * A_i1
        + eb_j1[..., None, :] * A_j2
        + eb_j2[..., None, :] * A_j1
    )
    sep |= (lhs > rhs).any(axis=(-2, -1))
    return sep


def obb_overlap(
    center_a: FloatArray,
    rotation_a: FloatArray,
    half_a: FloatArray,
    center_b: FloatArray,
    rotation_b: FloatArray,
    half_b: FloatArray,
) -> BoolArray:
    """Whether oriented boxes A and B intersect (closed boxes: touching counts), batched.

    Args:
        center_a, center_b: ``(..., 3)`` box centres in a common frame (m).
        rotation_a, rotation_b: ``(..., 3, 3)`` rotations whose columns are the box axes.
        half_a, half_b: ``(..., 3)`` half extents along those axes (m), >= 0.

    Returns:
        ``(...)`` bool, the broadcast of the inputs' leading shapes.

    Raises:
        PairingError: shapes that do not end in ``(3,)`` / ``(3, 3)``, or non-finite values.
    """
    arrays = {}
    for name, value, tail in (
        ("center_a", center_a, (3,)),
        ("rotation_a", rotation_a, (3, 3)),
        ("half_a", half_a, (3,)),
        ("center_b", center_b, (3,)),
        ("rotation_b", rotation_b, (3, 3)),
        ("half_b", half_b, (3,)),
    ):
        array = np.asarray(value, dtype=np.float64)
        if array.shape[array.ndim - len(tail) :] != tail or array.ndim < len(tail):
            raise PairingError(
                f"{name}: expected shape (..., {', '.join(map(str, tail))}), found {array.shape}"
            )
        if not np.isfinite(array).all():
            raise PairingError(f"{name}: expected finite values, found NaN or inf")
        arrays[name] = array
    Ra, Rb = arrays["rotation_a"], arrays["rotation_b"]
    R = np.swapaxes(Ra, -1, -2) @ Rb
    t = (np.swapaxes(Ra, -1, -2) @ (arrays["center_b"] - arrays["center_a"])[..., None])[..., 0]
    return ~_sat_separated(R, t, arrays["half_a"], arrays["half_b"])


# --------------------------------------------------------------------------------------------
# Gripper-gripper collision
# --------------------------------------------------------------------------------------------


def _grasp_boxes(
    grasps: SingleArmGrasps, model: GripperModel, opening: float | str | None
) -> tuple[FloatArray, FloatArray]:
    """Per-grasp box centres in the gripper frame ``(M, 3, 3)`` [palm, finger 0, finger 1] and the
    shared half extents ``(3, 3)``."""
    m = grasps.n
    if isinstance(opening, str):
        if opening != "grasp":
            raise PairingError(
                f"opening: expected None (fully open), 'grasp' (each grasp's width) or a number, "
                f"found {opening!r}"
            )
        widths = np.asarray(grasps.widths, dtype=np.float64)
        if not np.isfinite(widths).all():
            raise PairingError(
                "grasps.widths: expected finite widths for opening='grasp', found NaN"
            )
        widths = np.clip(widths, 0.0, model.max_opening)
    else:
        widths = np.full(m, model._opening(opening))
    palm, f0, _ = model.collision_boxes(None)
    half = np.array([palm.half_extents, f0.half_extents, f0.half_extents], dtype=np.float64)
    centers = np.zeros((m, 3, 3))
    centers[:, 0] = palm.center
    hx = model.finger_thickness / 2.0
    centers[:, 1] = [0.0, f0.center[1], f0.center[2]]
    centers[:, 2] = centers[:, 1]
    centers[:, 1, 0] = widths / 2.0 + hx
    centers[:, 2, 0] = -widths / 2.0 - hx
    return centers, half


def grippers_collide(
    grasps: SingleArmGrasps,
    pairs: IntArray,
    *,
    opening: float | Literal["grasp"] | None = None,
    chunk_size: int = _CHUNK,
) -> BoolArray:
    """Whether the two grippers of each pair intersect each other (boxes: palm and two fingers).

    Each gripper is its :meth:`GripperModel.collision_boxes`; a pair collides when any of the
    9 box pairs overlaps (exact separating-axis test, :func:`obb_overlap`). A bounding-sphere
    test skips pairs far apart.

    Args:
        grasps: M single-arm grasps (their ``gripper`` names the model).
        pairs: ``(P, 2)`` grasp indices.
        opening: finger opening (m); None for fully open (how the grippers sit at their poses
            before closing, as in the simulation protocol), ``"grasp"`` for each grasp's contact
            width (closed on the object).
        chunk_size: grasp pairs per vectorised batch (bounds memory: ~10 kB per pair).

    Returns:
        ``(P,)`` bool.
    """
    grasps = _check_grasps(grasps)
    pairs = _check_pairs(pairs, grasps.n)
    out = np.zeros(len(pairs), dtype=bool)
    if len(pairs) == 0:
        return out
    model = get_gripper(grasps.gripper)
    local, half = _grasp_boxes(grasps, model, opening)
    poses = np.asarray(grasps.poses, dtype=np.float64)
    Rg, tg = poses[:, :3, :3], poses[:, :3, 3]
    world = np.einsum("mij,mbj->mbi", Rg, local) + tg[:, None, :]  # (M, 3, 3) box centres

    # Bounding sphere of each gripper (its box corners), in the world frame.
    signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, -1).T
    corners = (local[:, :, None, :] + signs[None, None] * half[None, :, None, :]).reshape(
        grasps.n, -1, 3
    )
    mid = 0.5 * (corners.min(axis=1) + corners.max(axis=1))
    radius = np.linalg.norm(corners - mid[:, None, :], axis=-1).max(axis=1)
    sphere = np.einsum("mij,mj->mi", Rg, mid) + tg
    i, j = pairs[:, 0], pairs[:, 1]
    near = np.linalg.norm(sphere[i] - sphere[j], axis=1) <= radius[i] + radius[j]
    rows = np.flatnonzero(near)

    ea = half[None, :, None, :]  # A = boxes of grasp i along axis 1
    eb = half[None, None, :, :]  # B = boxes of grasp j along axis 2
    step = max(int(chunk_size), 1)
    for start in range(0, len(rows), step):
        r = rows[start : start + step]
        gi, gj = pairs[r, 0], pairs[r, 1]
        RiT = np.swapaxes(Rg[gi], 1, 2)  # (C, 3, 3)
        R = (RiT @ Rg[gj])[:, None, None]  # (C, 1, 1, 3, 3)
        d = world[gj][:, None, :, :] - world[gi][:, :, None, :]  # (C, 3a, 3b, 3)
        t = np.einsum("cik,cabk->cabi", RiT, d)
        out[r] = (~_sat_separated(R, t, ea, eb)).any(axis=(1, 2))
    return out


# --------------------------------------------------------------------------------------------
# Candidates
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PairCandidates:
    """Dual-grasp candidates of one grasp set.

    Attributes:
        pairs: ``(P, 2)`` int64 grasp indices ``i < j``, sorted lexicographically.
        center_distance: ``(P,)`` distance between the two grasp centres (m).
        counts: ``pairs`` (all M(M-1)/2), ``pruned_distance`` (centres closer than the minimum),
            ``gripper_collision`` (grippers intersect, among the unpruned), ``remaining`` (P).
    """

    pairs: IntArray
    center_distance: FloatArray
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of candidates P."""
        return int(self.pairs.shape[0])


def candidate_pairs(
    grasps: SingleArmGrasps,
    *,
    min_center_distance: float = DEFAULT_MIN_CENTER_DISTANCE,
    check_gripper_collision: bool = True,
    opening: float | Literal["grasp"] | None = None,
    chunk_size: int = _CHUNK,
) -> PairCandidates:
    """All unique pairs ``i < j`` of M grasps, pruned as the release does, then without pairs
    whose grippers intersect each other.

    Args:
        grasps: M single-arm grasps.
        min_center_distance: pairs whose grasp centres (contact midpoints) are closer than this
            (m) are pruned; a pair exactly at the distance is kept.
        check_gripper_collision: reject pairs whose two grippers intersect (the release does
            not check this; False reproduces it).
        opening: gripper opening for that check, see :func:`grippers_collide`.
        chunk_size: grasp pairs per vectorised batch of the collision test.

    Returns:
        :class:`PairCandidates`. Fewer than two grasps give no pairs.
    """
    grasps = _check_grasps(grasps)
    min_center_distance = _check_nonnegative("min_center_distance", min_center_distance)
    m = grasps.n
    i, j = np.triu_indices(m, k=1)
    pairs = np.stack([i, j], axis=1).astype(np.int64)
    centers = np.asarray(grasps.centers, dtype=np.float64)
    if not np.isfinite(centers).all():
        bad = int(np.flatnonzero(~np.isfinite(centers).all(axis=1))[0])
        raise PairingError(
            f"grasps.contact_points: expected finite contacts, found NaN at grasp {bad}"
        )
    distance = np.linalg.norm(centers[i] - centers[j], axis=1)
    keep = distance >= min_center_distance
    counts = {"pairs": len(pairs), "pruned_distance": int((~keep).sum())}
    pairs, distance = pairs[keep], distance[keep]
    collide = np.zeros(len(pairs), dtype=bool)
    if check_gripper_collision:
        collide = grippers_collide(grasps, pairs, opening=opening, chunk_size=chunk_size)
    counts["gripper_collision"] = int(collide.sum())
    pairs, distance = pairs[~collide], distance[~collide]
    counts["remaining"] = len(pairs)
    return PairCandidates(pairs=pairs, center_distance=distance, counts=counts)


def dual_contacts(grasps: SingleArmGrasps, pairs: IntArray) -> tuple[FloatArray, FloatArray]:
    """Four contacts per pair: ``[i finger 0, i finger 1, j finger 0, j finger 1]``.

    Returns:
        ``points (P, 4, 3)`` (object frame, m) and ``normals (P, 4, 3)`` (unit, OUTWARD), the
        input of :func:`dataset_gen.force_closure.evaluate`.
    """
    grasps = _check_grasps(grasps)
    pairs = _check_pairs(pairs, grasps.n)
    cp = np.asarray(grasps.contact_points, dtype=np.float64)
    cn = np.asarray(grasps.contact_normals, dtype=np.float64)
    points = np.concatenate([cp[pairs[:, 0]], cp[pairs[:, 1]]], axis=1)
    normals = np.concatenate([cn[pairs[:, 0]], cn[pairs[:, 1]]], axis=1)
    return points, normals


def dual_poses(grasps: SingleArmGrasps, pairs: IntArray) -> FloatArray:
    """``(P, 2, 4, 4)`` gripper poses ``[i, j]`` of each pair (the release's ``grasps/grasps``)."""
    grasps = _check_grasps(grasps)
    pairs = _check_pairs(pairs, grasps.n)
    poses = np.asarray(grasps.poses, dtype=np.float64)
    return np.stack([poses[pairs[:, 0]], poses[pairs[:, 1]]], axis=1)


def score_pairs(
    grasps: SingleArmGrasps,
    pairs: IntArray,
    *,
    convention: Literal["physical", "release"] = "physical",
    **fc_kwargs: Any,
) -> ForceClosureResult:
    """Force closure of each pair in verdict-only mode (``loss_rtol=None``, the fast mode).

    Failing pairs then carry an attained upper bound ``loss`` and a proven ``loss_lower``;
    :func:`select_pairs` computes exact losses for the failing pairs it keeps.

    Args:
        grasps: M single-arm grasps.
        pairs: ``(P, 2)`` grasp indices.
        convention: see :func:`dataset_gen.force_closure.evaluate`.
        fc_kwargs: further arguments of :func:`~dataset_gen.force_closure.evaluate` (mass, mu,
            f_high, threshold, wrenches, progress ...). ``loss_rtol`` may be given to get
            exact losses for every pair (about 6x slower).

    Returns:
        :class:`~dataset_gen.force_closure.ForceClosureResult` with P rows.
    """
    points, normals = dual_contacts(grasps, pairs)
    fc_kwargs.setdefault("loss_rtol", None)
    return evaluate(points, normals, convention=convention, **fc_kwargs)


# --------------------------------------------------------------------------------------------
# Ablation strategies
# --------------------------------------------------------------------------------------------


def random_pairs(
    m: int, count: int, rng: np.random.Generator, *, among: IntArray | None = None
) -> IntArray:
    """``count`` distinct unordered pairs drawn uniformly without replacement, sorted.

    Args:
        m: number of grasps.
        count: pairs wanted; capped at the number available.
        rng: the random generator.
        among: ``(Q, 2)`` pairs to draw from instead of all ``i < j`` pairs.

    Returns:
        ``(min(count, available), 2)`` int64, rows sorted lexicographically.
    """
    m = _check_count("m", m)
    count = _check_count("count", count)
    rng = _check_rng(rng)
    if among is None:
        i, j = np.triu_indices(m, k=1)
        pool = np.stack([i, j], axis=1).astype(np.int64)
    else:
        pool = _check_pairs(among, m)
    take = min(count, len(pool))
    chosen = np.sort(rng.choice(len(pool), size=take, replace=False))
    return pool[chosen]


def farthest_pairs(grasps: SingleArmGrasps, *, among: IntArray | None = None) -> IntArray:
    """Each grasp paired with the grasp whose centre is farthest from its own.

    Ties go to the lowest index. Pairs are returned as ``i < j``, deduplicated and sorted.

    Args:
        grasps: M single-arm grasps.
        among: ``(Q, 2)`` allowed pairs (e.g. the candidates); a grasp with no allowed partner
            is left out. Default: any two grasps.

    Returns:
        ``(P, 2)`` int64 with ``P <= M``.
    """
    grasps = _check_grasps(grasps)
    m = grasps.n
    if m < 2:
        return np.zeros((0, 2), dtype=np.int64)
    centers = np.asarray(grasps.centers, dtype=np.float64)
    d = np.linalg.norm(centers[:, None, :] - centers[None, :, :], axis=-1)
    if among is None:
        np.fill_diagonal(d, -np.inf)
    else:
        allowed = np.zeros((m, m), dtype=bool)
        pairs = _check_pairs(among, m)
        allowed[pairs[:, 0], pairs[:, 1]] = True
        allowed[pairs[:, 1], pairs[:, 0]] = True
        d = np.where(allowed, d, -np.inf)
    partner = np.argmax(d, axis=1)
    has = np.isfinite(d[np.arange(m), partner])
    first = np.flatnonzero(has)
    pairs = np.sort(np.stack([first, partner[has]], axis=1), axis=1).astype(np.int64)
    return np.unique(pairs, axis=0).reshape(-1, 2)


@dataclass(frozen=True)
class PairingResult:
    """Pairs produced by one strategy and their force-closure verdicts.

    Attributes:
        strategy: ``"force_closure"``, ``"random"`` or ``"farthest"``.
        pairs: ``(P, 2)`` grasp indices.
        fc: verdict-only :class:`~dataset_gen.force_closure.ForceClosureResult` with P rows.
        counts: ``pairs`` (P), ``rank_deficient``, ``passing``; for ``"force_closure"`` also the
            candidate stages of :class:`PairCandidates` (``all_pairs``, ``pruned_distance``,
            ``gripper_collision``).
    """

    strategy: str
    pairs: IntArray
    fc: ForceClosureResult
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def pass_rate(self) -> float:
        """Fraction of the strategy's pairs that pass force closure (NaN when there are none)."""
        return float(self.fc.passed.mean()) if self.fc.n else float("nan")

    @property
    def passing_pairs(self) -> IntArray:
        """``(P_pass, 2)`` the passing pairs (for ``"force_closure"``: the selected dataset)."""
        return self.pairs[self.fc.passed]


def make_pairs(
    grasps: SingleArmGrasps,
    strategy: Strategy,
    *,
    rng: np.random.Generator | None = None,
    n_pairs: int | None = None,
    min_center_distance: float = DEFAULT_MIN_CENTER_DISTANCE,
    check_gripper_collision: bool = True,
    opening: float | Literal["grasp"] | None = None,
    from_candidates: bool = False,
    convention: Literal["physical", "release"] = "physical",
    **fc_kwargs: Any,
) -> PairingResult:
    """Pair single-arm grasps by a named strategy and score every pair by force closure.

    Strategies (the paper's Table III):

    * ``"force_closure"``: every candidate of :func:`candidate_pairs` (distance pruning and
      gripper-gripper collision), scored; the dataset keeps the passing ones.
    * ``"random"``: ``n_pairs`` pairs drawn uniformly (default: as many as the force-closure
      strategy evaluates) from all ``i < j`` pairs, or from the candidates with
      ``from_candidates``. Needs ``rng``.
    * ``"farthest"``: each grasp with the grasp whose centre is farthest from it (deduplicated),
      among all grasps or among the candidates with ``from_candidates``.

    Args:
        grasps: M single-arm grasps.
        strategy: one of :data:`STRATEGIES`.
        rng: random generator (required for ``"random"``).
        n_pairs: pair count for ``"random"``.
        min_center_distance, check_gripper_collision, opening: candidate filters (m).
        from_candidates: draw the ablations' pairs from the candidates rather than all pairs.
        convention, fc_kwargs: force-closure settings, see :func:`score_pairs`.

    Returns:
        :class:`PairingResult`.
    """
    grasps = _check_grasps(grasps)
    if strategy not in STRATEGIES:
        raise PairingError(f"strategy: expected one of {STRATEGIES}, found {strategy!r}")
    n_pairs = _check_count("n_pairs", n_pairs, allow_none=True)
    counts: dict[str, int] = {}
    candidates: PairCandidates | None = None
    needs_candidates = (
        strategy == "force_closure" or from_candidates or (strategy == "random" and n_pairs is None)
    )
    if needs_candidates:
        candidates = candidate_pairs(
            grasps,
            min_center_distance=min_center_distance,
            check_gripper_collision=check_gripper_collision,
            opening=opening,
        )
    among = candidates.pairs if (from_candidates and candidates is not None) else None
    if strategy == "force_closure":
        assert candidates is not None
        pairs = candidates.pairs
        counts.update(
            all_pairs=candidates.counts["pairs"],
            pruned_distance=candidates.counts["pruned_distance"],
            gripper_collision=candidates.counts["gripper_collision"],
        )
    elif strategy == "random":
        if rng is None:
            raise PairingError(
                "rng: expected a numpy.random.Generator for strategy 'random', found None"
            )
        count = n_pairs if n_pairs is not None else candidates.n  # type: ignore[union-attr]
        pairs = random_pairs(grasps.n, count, rng, among=among)
    else:
        pairs = farthest_pairs(grasps, among=among)
    fc = score_pairs(grasps, pairs, convention=convention, **fc_kwargs)
    counts.update(
        pairs=len(pairs),
        rank_deficient=int((~fc.rank_ok).sum()),
        passing=int(fc.passed.sum()),
    )
    return PairingResult(strategy=strategy, pairs=pairs, fc=fc, counts=counts)


def strategy_pass_rates(
    grasps: SingleArmGrasps,
    *,
    rng: np.random.Generator,
    strategies: Sequence[str] = STRATEGIES,
    **kwargs: Any,
) -> dict[str, float]:
    """Fraction of each strategy's pairs that pass force closure (see :func:`make_pairs`).

    For ``"force_closure"`` this is the pass rate of its candidates (the pairs it keeps pass by
    construction). The paper finds random < farthest < force-closure-selected pairs.
    """
    return {s: make_pairs(grasps, s, rng=rng, **kwargs).pass_rate for s in strategies}  # type: ignore[arg-type]


__all__ = [
    "DEFAULT_FAILING_MIN_LOSS",
    "DEFAULT_MAX_FAILING",
    "DEFAULT_MAX_PASSING",
    "DEFAULT_MIN_CENTER_DISTANCE",
    "DEFAULT_SELECTION_LOSS_RTOL",
    "STRATEGIES",
    "PairCandidates",
    "PairingError",
    "PairingResult",
    "Selection",
    "candidate_pairs",
    "dual_contacts",
    "dual_poses",
    "farthest_pairs",
    "grippers_collide",
    "make_pairs",
    "obb_overlap",
    "proven_loss_lower",
    "random_pairs",
    "score_pairs",
    "select_pairs",
    "strategy_pass_rates",
]
