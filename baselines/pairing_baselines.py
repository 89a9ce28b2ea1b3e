"""The paper's pairing baselines (Table III) as grasp predictors on a benchmark observation.

A :class:`PairingBaseline` is a predictor ``observation -> (poses (k, 2, 4, 4), scores (k,))``
(the observation of :func:`dg16m_env.subjects.observation.object_observation`; object frame, origin at
the centre of mass, m). It rebuilds the object from the observation's mesh
(:func:`object_from_observation`), samples ``n_grasps`` antipodal single-arm Panda grasps on it
with the generator's sampler, pairs them with the generator's pairing code, and keeps ``k`` dual
grasps by one strategy:

``random``
    ``k`` pairs drawn uniformly among the collision-free pruned candidates
    (:func:`~dataset_gen.grasps.pairing.candidate_pairs`, :func:`~dataset_gen.grasps.pairing.random_pairs`;
    the paper's random dual-arm pairs). Scores 0.
``farthest``
    ``k`` pairs drawn uniformly among the pairs joining each grasp to the grasp whose centre is
    farthest from it (:func:`~dataset_gen.grasps.pairing.farthest_pairs`, the paper's diametrically
    opposite pairing; like the benchmark's ``farthest`` arm, not restricted to the candidates).
    Scores 0.
``force_closure``
    the candidates are checked for force closure (:func:`~dataset_gen.grasps.pairing.score_pairs`);
    ``k`` passing ones are drawn uniformly; when fewer than ``k`` pass, the failing candidates
    with the lowest exact loss fill the rest (rank-deficient candidates last). Scores
    ``-loss`` (N; higher = better); a rank-deficient pair scores ``-mass * gravity``, the loss
    of applying no force at all, which bounds every other loss.

Randomness: the stream is ``np.random.default_rng(object_seed(seed, "baseline:<object_id>"))``
(:func:`dataset_gen.sources.object_source.object_seed`), a different stream from the benchmark's own
(``"benchmark:<object_id>"``), so the predictions are fresh grasps rather than benchmark rows.
The grasps are sampled first, then the strategy draws from the same stream: the output is a
function of the observation and the parameters only (same seed, same bytes).

Ready-made predictors with the default parameters: :data:`random_baseline`,
:data:`farthest_baseline`, :data:`force_closure_baseline` (e.g.
``dg16m evaluate --predictor baselines.pairing_baselines:force_closure_baseline``).

With the same ``seed``, ``n_grasps`` and ``mu`` the three strategies see the same sampled grasps;
:meth:`PairingBaseline.sample` and :meth:`PairingBaseline.choose` let a caller sample once and
apply several strategies, with the same result as calling each predictor.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any, Literal, get_args

import numpy as np
import trimesh

from dataset_gen.force_closure import ForceClosureResult, evaluate
from dataset_gen.grasps.pairing import (
    candidate_pairs,
    dual_contacts,
    dual_poses,
    farthest_pairs,
    random_pairs,
    score_pairs,
)
from dataset_gen.grasps.sampling import SingleArmGrasps, sample_antipodal_grasps
from dataset_gen.objects.grasp_object import GraspObject, make_object
from dataset_gen.sources.object_source import object_seed
from dg16m_core.checks import check_fields
from dg16m_core.errors import Dg16mError
from dg16m_core.parameters import PAPER

PairingStrategy = Literal["random", "farthest", "force_closure"]
PAIRING_STRATEGIES: tuple[str, ...] = get_args(PairingStrategy)
"""The pairing baselines, in the order of the paper's Table III ablation."""

SEED_PREFIX = "baseline:"
"""Prefix of the per-object stream name (the benchmark's own is ``"benchmark:"``)."""

EXACT_LOSS_RTOL = 1e-3
"""Relative accuracy of the exact losses of the failing pairs that fill a ``force_closure``
shortfall (the accuracy of the benchmark's stored losses)."""


class BaselineError(Dg16mError, ValueError):
    """Bad baseline arguments, a malformed observation, or an object that yields no grasp."""


# --------------------------------------------------------------------------------------------
# The object of an observation
# --------------------------------------------------------------------------------------------


def object_from_observation(
    observation: dict[str, Any], *, mass: float = PAPER.mass
) -> GraspObject:
    """The :class:`GraspObject` of an observation's mesh, in the observation's frame.

    Args:
        observation: a dict with ``object_id`` (str), ``mesh_vertices`` (V, 3) float (m) and
            ``mesh_faces`` (F, 3) int (:func:`dg16m_env.subjects.observation.object_observation`);
            ``family`` (str) is kept in the metadata when present.
        mass: object mass (kg) for its mass properties.

    Returns:
        The object, not re-centred (the observation's frame is the object frame the poses use).

    Raises:
        BaselineError: a missing key or a malformed mesh array.
        MeshError: a mesh too small or too large to be an object, or a non-positive mass.
    """
    if not isinstance(observation, dict):
        raise BaselineError(f"observation: expected a dict, found {type(observation).__name__}")
    missing = [k for k in ("object_id", "mesh_vertices", "mesh_faces") if k not in observation]
    if missing:
        raise BaselineError(f"observation: expected keys {missing}, found {sorted(observation)}")
    object_id = observation["object_id"]
    if not isinstance(object_id, str) or not object_id:
        raise BaselineError(f"observation object_id: expected a non-empty str, found {object_id!r}")
    vertices = np.asarray(observation["mesh_vertices"], dtype=np.float64)
    faces = np.asarray(observation["mesh_faces"])
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) < 3:
        raise BaselineError(
            f"{object_id}: mesh_vertices: expected shape (V >= 3, 3), found {vertices.shape}"
        )
    if not np.isfinite(vertices).all():
        raise BaselineError(f"{object_id}: mesh_vertices: expected finite values, found NaN or inf")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) < 1:
        raise BaselineError(
            f"{object_id}: mesh_faces: expected shape (F >= 1, 3), found {faces.shape}"
        )
    if not np.issubdtype(faces.dtype, np.integer):
        raise BaselineError(
            f"{object_id}: mesh_faces: expected integers, found dtype {faces.dtype}"
        )
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise BaselineError(
            f"{object_id}: mesh_faces: expected vertex indices in [0, {len(vertices)}), found "
            f"[{faces.min()}, {faces.max()}]"
        )
    mesh = trimesh.Trimesh(vertices, faces.astype(np.int64), process=False)
    family = observation.get("family", "")
    return make_object(
        mesh,
        object_id=object_id,
        mass=mass,
        center=False,
        metadata={"family": str(family)} if family else None,
    )


# --------------------------------------------------------------------------------------------
# The predictor
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class SampledGrasps:
    """The single-arm grasps a baseline sampled on one object, and its stream after sampling.

    Attributes:
        object_id: the object.
        grasps: the M sampled grasps (object frame, m).
        rng: the object's generator right after sampling (:meth:`PairingBaseline.choose` draws
            from a copy, so one sample serves several strategies).
        key: ``(seed, n_grasps, mu)`` of the baseline that sampled them.
    """

    object_id: str
    grasps: SingleArmGrasps
    rng: np.random.Generator
    key: tuple[int, int, float]


@dataclass(frozen=True)
class PairingBaseline:
    """A pairing baseline of the paper's Table III as a predictor (see the module docstring).

    Attributes:
        strategy: ``"random"``, ``"farthest"`` or ``"force_closure"``.
        k: dual grasps per object (fewer when the object has fewer pairs).
        n_grasps: single-arm grasps sampled per object.
        seed: global seed; each object's stream derives from ``(seed, "baseline:<id>")``.
        mu: friction coefficient (sampling cone and force closure).
        min_center_distance: candidate pruning: grasp centres at least this far apart (m).
        mass: object mass (kg) of the force-closure gravity wrench.
        gravity: gravitational acceleration (m/s^2).
        f_high: force bound per contact (N).
        threshold: force-closure threshold on the residual (N).

    Every numeric default is the paper's (:data:`dg16m_core.parameters.PAPER`) except
    ``n_grasps`` (200, the benchmark's).
    """

    strategy: PairingStrategy
    k: int = 10
    n_grasps: int = 200
    seed: int = 0
    mu: float = PAPER.mu
    min_center_distance: float = PAPER.min_center_distance
    mass: float = PAPER.mass
    gravity: float = PAPER.gravity
    f_high: float = PAPER.f_high
    threshold: float = PAPER.threshold

    def __post_init__(self) -> None:
        if self.strategy not in PAIRING_STRATEGIES:
            raise BaselineError(
                f"strategy: expected one of {PAIRING_STRATEGIES}, found {self.strategy!r}"
            )
        check_fields(
            self,
            error=BaselineError,
            integers={"k": 1, "n_grasps": 2, "seed": 0},
            zero_allowed=("min_center_distance",),
            skip=("strategy",),
        )

    @property
    def name(self) -> str:
        """The strategy's name (``"random"``, ``"farthest"`` or ``"force_closure"``)."""
        return self.strategy

    def force_closure_kwargs(self) -> dict[str, float]:
        """Keyword arguments of :func:`dataset_gen.force_closure.evaluate` (mass, gravity, mu,
        f_high, threshold)."""
        return {
            "mass": self.mass,
            "gravity": self.gravity,
            "mu": self.mu,
            "f_high": self.f_high,
            "threshold": self.threshold,
        }

    def sample(self, observation: dict[str, Any]) -> SampledGrasps:
        """Sample ``n_grasps`` antipodal grasps on the observation's object (fewer when the
        sampler's budget runs out first) and keep the stream for :meth:`choose`."""
        obj = object_from_observation(observation, mass=self.mass)
        rng = np.random.default_rng(object_seed(self.seed, SEED_PREFIX + obj.object_id))
        grasps = sample_antipodal_grasps(obj, n_grasps=self.n_grasps, mu=self.mu, rng=rng)
        return SampledGrasps(obj.object_id, grasps, rng, self._key())

    def choose(self, sampled: SampledGrasps) -> tuple[np.ndarray, np.ndarray]:
        """Apply the strategy to grasps :meth:`sample` returned (of a baseline with the same
        ``seed``, ``n_grasps`` and ``mu``; ``sampled`` is left unchanged).

        Returns:
            ``poses (K, 2, 4, 4)`` float64 hand poses (object frame, m) and ``scores (K,)``
            float64 (higher = better), ``1 <= K <= k``.

        Raises:
            BaselineError: grasps sampled with other parameters, or no dual grasp at all.
        """
        if sampled.key != self._key():
            raise BaselineError(
                f"{sampled.object_id}: expected grasps sampled with (seed, n_grasps, mu) = "
                f"{self._key()}, found {sampled.key}"
            )
        grasps = sampled.grasps
        rng = copy.deepcopy(sampled.rng)
        if self.strategy == "farthest":
            pairs = farthest_pairs(grasps)
            pairs = pairs[_draw(len(pairs), self.k, rng)]
            scores = np.zeros(len(pairs))
            candidates = None
        else:
            candidates = candidate_pairs(grasps, min_center_distance=self.min_center_distance)
            if self.strategy == "random":
                pairs = random_pairs(grasps.n, self.k, rng, among=candidates.pairs)
                scores = np.zeros(len(pairs))
            else:
                pairs, scores = self._force_closure(grasps, candidates.pairs, rng)
        if len(pairs) == 0:
            found = f"{candidates.n} candidate pairs" if candidates is not None else "no pairs"
            raise BaselineError(
                f"{sampled.object_id}: expected at least one {self.strategy} dual grasp, found "
                f"none ({grasps.n} single-arm grasps sampled, {found})"
            )
        return dual_poses(grasps, pairs), np.asarray(scores, dtype=np.float64)

    def __call__(self, observation: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        """Predict: ``poses (K, 2, 4, 4)`` (object frame, m) and ``scores (K,)``, K <= k.

        Raises:
            BaselineError: a malformed observation or an object that yields no dual grasp.
            MeshError: a mesh unusable as an object.
        """
        return self.choose(self.sample(observation))

    def _key(self) -> tuple[int, int, float]:
        return (int(self.seed), int(self.n_grasps), float(self.mu))

    def _force_closure(
        self, grasps: SingleArmGrasps, candidates: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """``k`` passing candidates (seeded draw), the shortfall filled by the lowest losses."""
        if len(candidates) == 0:
            return candidates, np.zeros(0)
        fc_kwargs = self.force_closure_kwargs()
        verdict = score_pairs(grasps, candidates, **fc_kwargs)
        passing = np.flatnonzero(verdict.passed)
        take = passing[_draw(len(passing), self.k, rng)]
        scores = 0.0 - verdict.loss[take]  # 0.0 - x: no negative zeros
        need = self.k - len(take)
        if need > 0:
            fill, fill_scores = _lowest_losses(
                verdict, grasps, candidates, need, fc_kwargs, weight=self.mass * self.gravity
            )
            take = np.concatenate([take, fill])
            scores = np.concatenate([scores, fill_scores])
        return candidates[take].reshape(-1, 2), scores


def _draw(n: int, k: int, rng: np.random.Generator) -> np.ndarray:
    """``min(k, n)`` sorted row indices drawn uniformly from ``range(n)`` (all rows when
    ``n <= k``, drawing nothing)."""
    if n <= k:
        return np.arange(n)
    return np.sort(rng.choice(n, size=k, replace=False))


def _lowest_losses(
    verdict: ForceClosureResult,
    grasps: SingleArmGrasps,
    candidates: np.ndarray,
    need: int,
    fc_kwargs: dict[str, float],
    *,
    weight: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The ``need`` failing candidates of least exact loss (ties: lowest row), then
    rank-deficient ones; returns their rows and scores (``-loss``, ``-weight`` when rank
    deficient).

    Only the failing rows whose proven lower bound is at most the ``need``-th smallest attained
    upper bound can be among the lowest; only those are solved exactly.
    """
    failing = np.flatnonzero(verdict.rank_ok & ~verdict.passed)
    if len(failing) > need:
        cutoff = np.partition(verdict.loss[failing], need - 1)[need - 1]
        failing = failing[verdict.pair_loss_lower[failing] <= cutoff]
    loss = np.zeros(0)
    if len(failing):
        points, normals = dual_contacts(grasps, candidates[failing])
        loss = evaluate(points, normals, loss_rtol=EXACT_LOSS_RTOL, **fc_kwargs).loss
    order = np.lexsort((failing, loss))[:need]
    rows, scores = failing[order], 0.0 - loss[order]
    short = need - len(rows)
    if short > 0:
        deficient = np.flatnonzero(~verdict.rank_ok)[:short]
        rows = np.concatenate([rows, deficient])
        scores = np.concatenate([scores, np.full(len(deficient), -weight)])
    return rows, scores


random_baseline = PairingBaseline("random")
"""The ``random`` baseline with the default parameters (a predictor: ``module:callable``)."""
farthest_baseline = PairingBaseline("farthest")
"""The ``farthest`` baseline with the default parameters."""
force_closure_baseline = PairingBaseline("force_closure")
"""The ``force_closure`` baseline with the default parameters."""


__all__ = [
    "EXACT_LOSS_RTOL",
    "PAIRING_STRATEGIES",
    "SEED_PREFIX",
    "BaselineError",
    "PairingBaseline",
    "PairingStrategy",
    "SampledGrasps",
    "farthest_baseline",
    "force_closure_baseline",
    "object_from_observation",
    "random_baseline",
]
