"""A dual-grasp predictor that sees only a depth cloud: a learned hand generator, checks on the
cloud, pairing, and a learned ranker (issue 59).

Per object (``dg16m evaluate --predictor baselines.flow_predictor:flow_predictor --track
cloud``) :class:`FlowPredictor`

1. takes ``check_points`` of the observation's points and estimated normals in a random order
   (the cloud track's harness cameras; a mesh-track observation's own ``points`` / ``normals``
   otherwise) for the checks, the first ``n_points`` of them for the models (with ``smoothing``,
   each camera's depth is smoothed first and the points and normals rebuilt from it:
   :mod:`baselines.depth_smoothing`, :data:`flow_smoothed_predictor`);
2. draws ``n_samples`` anchor points of the cloud (in proportion to the generator's learned
   graspability of each point) and one hand per anchor from the generator
   (:class:`baselines.dual_grasp_flow.AnchoredGraspFlow`: flow matching of a hand's pose about
   its anchor, given the whole cloud and the anchor's neighbourhood; trained on the hands of the
   dataset's force-closure dual grasps of thousands of objects given the same kind of cloud, so
   its hands reflect the full mesh, seen or not);
3. closes each hand's jaws on the cloud (:func:`snap_hands`): the jaws hold the cloud points
   between the open fingers (:func:`baselines.cloud_enclosing.enclose`), the hand is centred on
   them along its closing axis, and of :data:`DEPTH_OFFSETS` along its approach the first that
   holds a part no wider than the opening without a cloud point inside the palm or fingers is
   kept, under the cloud sampler's rules for enclosing grasps (no contact whose normal points
   back at the other finger, one contact seen to face its finger, no held point at the edge of
   the opening); other hands are dropped;
4. pairs the kept hands (:func:`pair_hands`: the paper's minimum distance between grasp
   centres, no intersecting grippers; at most ``max_pairs``) and checks each pair for force
   closure on its four cloud contacts (the paper's check and parameters, the centre of mass at
   the observation's origin); a contact whose estimated normal does not face its finger is taken
   to face it (the closing axis), as the cloud sampler's enclosing grasps do;
5. ranks passing pairs first, each group by the ranker: ``ranker="learned"``, a
   :class:`baselines.dual_pointnet_gpd.DualPointNetGPD` trained on this pipeline's own pairs
   labelled on the full meshes (GraspGen's lesson: a classifier trained only on dataset grasps
   is fooled by generated ones); ``"random"``, seeded uniform scores on the same pairs (the
   control); with ``robust=True`` (:data:`flow_robust_predictor`) the passing pairs are first
   ordered by the robust criterion on their cloud contacts (:mod:`baselines.cloud_robust`: robust,
   then nearly robust level by level; the ranker orders each level); and returns the ``k`` best.
   An object without any pair raises :class:`~baselines.cloud_grasps.CloudError` (the runner
   scores it 0).

Randomness: per object ``object_seed(seed, "flow:" + stream name)`` seeds a
``numpy.random.Generator`` (the cloud subset, the anchors, the pair subset, the random ranker,
in that order) and a ``torch.Generator`` (the generator's noise): the output is a function of the
observation and the parameters. Models are loaded once per process; torch uses ``threads``
threads.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, Literal, get_args

import numpy as np

from baselines.cloud_enclosing import MAX_BACK_FACING, enclose
from baselines.cloud_grasps import (
    Cloud,
    CloudError,
    DualCandidates,
    check_cloud,
    concatenate_grasps,
    hand_hits_cloud,
    paired_candidates,
    sample_cloud_grasps,
    sample_enclosing_grasps,
)
from baselines.cloud_predictor import (
    CHECKPOINTS,
    PARTIAL_SAMPLER,
    ROBUST_BONUS,
    classifier_scores,
    cloud_force_closure,
    is_cloud_track,
    stream_name,
)
from baselines.cloud_robust import (
    MOTION_RATIO_LEVELS,
    candidates_robust_first,
    check_ratio_levels,
)
from baselines.depth_smoothing import DepthSmoothing, smoothed_observation
from dataset_gen.grasps.gripper import GripperModel, get_gripper
from dataset_gen.grasps.pairing import candidate_pairs
from dataset_gen.grasps.sampling import SingleArmGrasps
from dataset_gen.sources.object_source import object_seed
from dg16m_core.checks import check_integer
from dg16m_core.parameters import PAPER

FlowRanker = Literal["learned", "random"]
FLOW_RANKERS: tuple[str, ...] = get_args(FlowRanker)
AnchorSampling = Literal["learned", "uniform"]
ANCHOR_SAMPLINGS: tuple[str, ...] = get_args(AnchorSampling)
Proposals = Literal["generator", "generator+sampler", "sampler"]
PROPOSALS: tuple[str, ...] = get_args(Proposals)

GENERATOR_CHECKPOINT = CHECKPOINTS / "grasp-flow.pt"
"""The shipped generator (:mod:`baselines.train_dual_grasp_flow`)."""

RANKER_CHECKPOINT = CHECKPOINTS / "grasp-flow-ranker.pt"
"""The shipped ranker of the pipeline's own pairs (:mod:`baselines.train_dual_grasp_flow`)."""

FC_BONUS = 1.0e3
"""Added to the score of a pair whose cloud contacts pass force closure (ranker scores: logits
of a few tens at most, or uniform in [0, 1))."""

DEPTH_OFFSETS = (0.0, -0.01, -0.02, 0.01)
"""Shifts along a hand's approach axis tried in :func:`snap_hands`, in order (m; negative =
back out)."""


def _close_hands(
    cloud: Cloud, poses: np.ndarray, model: GripperModel, tolerance: float, clearance: float
) -> tuple[np.ndarray, ...]:
    """One try of :func:`snap_hands` for hands ``poses`` (H, 4, 4): ``(ok (H,), centred poses,
    contact indices (H, 2), widths (H,))``."""
    index, local_x = enclose(cloud, poses, model)
    width = local_x[:, 0] - local_x[:, 1]
    ok = (index[:, 0] >= 0) & (width > 1e-3) & (width <= model.max_opening - 2.0 * tolerance)
    # The cloud sampler's enclosing rules (baselines.cloud_enclosing): no contact whose normal
    # points back at the other finger (the part goes on, unseen, past it), at least one contact
    # seen to face its finger, and no held point at the edge of the opening.
    safe = np.maximum(index, 0)
    facing = np.stack(
        [
            np.einsum("hk,hk->h", cloud.normals[safe[:, 0]], poses[:, :3, 0]),
            -np.einsum("hk,hk->h", cloud.normals[safe[:, 1]], poses[:, :3, 0]),
        ],
        axis=1,
    )
    ok &= (facing >= -MAX_BACK_FACING).all(axis=1)
    ok &= (facing >= math.cos(math.atan(PAPER.mu))).any(axis=1)
    edge = model.max_opening / 2.0 - tolerance - cloud.spacing
    ok &= (local_x[:, 0] < edge) & (local_x[:, 1] > -edge)
    centred = poses.copy()
    centred[:, :3, 3] += 0.5 * (local_x[:, 0] + local_x[:, 1])[:, None] * poses[:, :3, 0]
    rows = np.flatnonzero(ok)
    half = 0.5 * width[rows]
    ok[rows] = ~hand_hits_cloud(
        cloud, centred[rows], np.stack([half, -half], axis=1), model, tolerance, clearance
    )
    return ok, centred, index, width


def rigid(poses: np.ndarray) -> np.ndarray:
    """(..., 4, 4) float64 poses made exactly rigid (Gram-Schmidt on the approach axis ``y``,
    then the closing axis ``x``; ``z = x cross y``): the generator's float32 frames to the
    precision of float64."""
    out = np.array(poses, dtype=np.float64)
    y = out[..., :3, 1] / np.linalg.norm(out[..., :3, 1], axis=-1, keepdims=True)
    x = out[..., :3, 0] - np.einsum("...k,...k->...", out[..., :3, 0], y)[..., None] * y
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    out[..., :3, 0], out[..., :3, 1], out[..., :3, 2] = x, y, np.cross(x, y)
    out[..., 3, :] = (0.0, 0.0, 0.0, 1.0)
    return out


def snap_hands(
    cloud: Cloud,
    hands: np.ndarray,
    *,
    gripper: str = "panda",
    tolerance: float = 3e-3,
    clearance_factor: float = 1.0,
    depth_offsets: tuple[float, ...] = DEPTH_OFFSETS,
) -> tuple[np.ndarray, SingleArmGrasps]:
    """Close each hand on the cloud (step 3 of the module docstring).

    Args:
        cloud: the observed cloud.
        hands: (M, 4, 4) hand poses (grasp frame -> object frame, m).
        gripper: the gripper model.
        tolerance: how far a cloud point may reach into the hand's volumes (m), and the margin
            kept from the full opening; the cloud track's depth noise is about 2.5 mm.
        clearance_factor: the hand's volumes are grown by this times the cloud's spacing (a
            sparse cloud has no point where a thin feature the hand would hit falls between its
            points; the cloud sampler's rule).
        depth_offsets: approach shifts tried in order (m); the first that works is kept.

    Returns:
        ``kept (M,)`` bool (the hand holds a part no wider than the opening and clears the
        observed points) and the kept hands, in order, as
        :class:`~dataset_gen.grasps.sampling.SingleArmGrasps` (centred poses, cloud contacts,
        their normals, ``face_ids`` = cloud indices).
    """
    model = get_gripper(gripper)
    clearance = clearance_factor * cloud.spacing
    hands = np.asarray(hands, dtype=np.float64).reshape(-1, 4, 4)
    done = np.zeros(len(hands), dtype=bool)
    best = hands.copy()
    index = np.full((len(hands), 2), -1, dtype=np.int64)
    width = np.zeros(len(hands))
    for offset in depth_offsets:
        rows = np.flatnonzero(~done)
        if rows.size == 0:
            break
        shifted = hands[rows].copy()
        shifted[:, :3, 3] += offset * shifted[:, :3, 1]
        ok, centred, idx, w = _close_hands(cloud, shifted, model, tolerance, clearance)
        best[rows[ok]], index[rows[ok]], width[rows[ok]] = centred[ok], idx[ok], w[ok]
        done[rows[ok]] = True
    rows = np.flatnonzero(done)
    normals = cloud.normals[index[rows]].reshape(-1, 2, 3)
    x_axis = best[rows, :3, 0]
    facing = np.stack(
        [
            np.einsum("hk,hk->h", normals[:, 0], x_axis),
            -np.einsum("hk,hk->h", normals[:, 1], x_axis),
        ],
        axis=1,
    )
    cone = math.cos(math.atan(PAPER.mu))
    assumed = np.stack([x_axis, -x_axis], axis=1)
    normals = np.where((facing < cone)[..., None], assumed, normals)
    kept = SingleArmGrasps(
        poses=best[rows],
        contact_points=cloud.points[index[rows]].reshape(-1, 2, 3),
        contact_normals=normals,
        face_ids=index[rows].reshape(-1, 2),
        widths=width[rows],
        gripper=model.name,
    )
    return done, kept


def pair_hands(
    singles: SingleArmGrasps, max_pairs: int, rng: np.random.Generator
) -> DualCandidates:
    """Dual candidates of the kept hands (step 4 of the module docstring): every pair at least
    the paper's ``min_center_distance`` apart whose grippers do not intersect
    (:func:`dataset_gen.grasps.pairing.candidate_pairs`), at most ``max_pairs`` of them drawn
    with ``rng``."""
    if singles.n >= 2:
        pairs = candidate_pairs(singles, min_center_distance=PAPER.min_center_distance).pairs
    else:
        pairs = np.zeros((0, 2), dtype=np.int64)
    if len(pairs) > max_pairs:
        pairs = pairs[np.sort(rng.choice(len(pairs), size=max_pairs, replace=False))]
    return paired_candidates(singles, pairs, {"pairs": len(pairs)})


@functools.lru_cache(maxsize=4)
def load_generator(path: str, threads: int = 1) -> Any:
    """The generator of a checkpoint (:func:`baselines.grasp_geometry.load_checkpoint`), cached
    per process; sets ``torch.set_num_threads(threads)``."""
    import torch

    from baselines.grasp_geometry import load_checkpoint

    torch.set_num_threads(threads)
    model, _ = load_checkpoint(path, expected="anchored_grasp_flow")
    return model


@functools.lru_cache(maxsize=4)
def load_flow_ranker(path: str, threads: int = 1) -> Any:
    """The ranker of a checkpoint (a dual PointNetGPD), cached per process."""
    import torch

    from baselines.grasp_geometry import load_checkpoint

    torch.set_num_threads(threads)
    model, _ = load_checkpoint(path, expected="dual_pointnet_gpd")
    return model


def check_observation(observation: Any) -> None:
    """Refuse what is not an observation a :class:`FlowPredictor` can read.

    Raises:
        CloudError: not a dict, or without ``points`` and ``normals`` (and, for the cloud
            track's, the ``depth``, ``camera_poses`` and ``intrinsics`` that name its stream).
    """
    if not isinstance(observation, dict):
        raise CloudError(f"observation: expected a dict, found {type(observation).__name__}")
    needed = ["points", "normals"]
    if is_cloud_track(observation):
        needed += ["camera_poses", "intrinsics"]
    missing = [k for k in needed if k not in observation]
    if missing:
        raise CloudError(f"observation: expected keys {missing}, found {sorted(observation)}")


def observed_cloud(observation: dict[str, Any], n_points: int, rng: np.random.Generator) -> Cloud:
    """``n_points`` of the observation's points and normals, in a random order, as a checked
    :class:`~baselines.cloud_grasps.Cloud` (points repeated when it has fewer).

    Raises:
        CloudError: not a dict with ``points`` and ``normals`` of one (P, 3) shape, or a
            malformed cloud (:func:`~baselines.cloud_grasps.check_cloud`).
    """
    from dg16m_env.physics.cameras import fixed_size

    check_observation(observation)
    points = np.asarray(observation["points"])
    normals = np.asarray(observation["normals"])
    if points.ndim != 2 or points.shape[1:] != (3,) or normals.shape != points.shape:
        raise CloudError(
            f"observation points/normals: expected two (P, 3) arrays, found {points.shape} and "
            f"{normals.shape}"
        )
    checked = check_cloud(points, normals)  # NaN, inf and non-unit normals refused here
    if is_cloud_track(observation) or checked.n != n_points:
        points, normals, mask = fixed_size(checked.points, checked.normals, n_points, rng)
        return check_cloud(points, normals, mask)
    order = rng.permutation(checked.n)
    return check_cloud(checked.points[order], checked.normals[order])


@dataclass(frozen=True)
class FlowPredictor:
    """The learned-generator predictor (see the module docstring).

    Attributes:
        generator_checkpoint: the generator (None: :data:`GENERATOR_CHECKPOINT`).
        ranker_checkpoint: the ranker (None: :data:`RANKER_CHECKPOINT`).
        ranker: ``"learned"`` or ``"random"`` (the control).
        n_points: cloud points given to the models (the first of the checks' cloud, which
            is in a random order).
        check_points: cloud points the hands are closed on and checked against, and the
            cloud sampler's (all the cameras saw when fewer): a denser cloud has a smaller
            spacing, so the clearance grown by it is tighter.
        n_samples: hands drawn per object (one per anchor).
        max_pairs: pairs checked and ranked at most.
        k: dual grasps returned.
        seed: the per-object streams' seed.
        tolerance: :func:`snap_hands`'s tolerance (m).
        anchors: ``"learned"``: anchors drawn (with replacement) in proportion to the
            generator's graspability head; ``"uniform"``: distinct uniform cloud points.
        proposals: where the hands come from: ``"generator"``; ``"generator+sampler"``, the
            generator's and the cloud sampler's (antipodal and enclosing,
            :data:`baselines.cloud_predictor.PARTIAL_SAMPLER`); ``"sampler"``, the sampler's
            only (an ablation: the same pairing, checks and ranker without the generator).
        threads: torch threads.
        smoothing: with a cloud-track observation (its depth images), each camera's depth is
            first smoothed (:mod:`baselines.depth_smoothing`) and the points and normals
            rebuilt from it; None: the observation's points and normals as they are.
        robust: rank the passing pairs by the robust criterion on their cloud contacts first
            (:func:`baselines.cloud_robust.robust_first`: the disturbance motion ratio under
            the protocol's loads, the centre of mass at the observation's origin, the inertia
            of a solid filling the checks' cloud's hull at the paper's mass): robust pairs
            (ratio <= ``motion_ratio_levels[0]``) first, then level by level; the ranker orders
            each level (:data:`baselines.cloud_predictor.ROBUST_BONUS`, as there).
        motion_ratio_levels: ascending motion ratios of those levels.
    """

    generator_checkpoint: str | None = None
    ranker_checkpoint: str | None = None
    ranker: FlowRanker = "learned"
    n_points: int = 1024
    check_points: int = 4096
    n_samples: int = 512
    max_pairs: int = 1024
    k: int = 10
    seed: int = 0
    tolerance: float = 3e-3
    anchors: AnchorSampling = "learned"
    proposals: Proposals = "generator+sampler"
    threads: int = 1
    smoothing: DepthSmoothing | None = None
    robust: bool = False
    motion_ratio_levels: tuple[float, ...] = MOTION_RATIO_LEVELS

    def __post_init__(self) -> None:
        if not isinstance(self.robust, bool):
            raise CloudError(f"robust: expected a bool, found {self.robust!r}")
        check_ratio_levels(self.motion_ratio_levels)
        if self.ranker not in FLOW_RANKERS:
            raise CloudError(f"ranker: expected one of {FLOW_RANKERS}, found {self.ranker!r}")
        if self.proposals not in PROPOSALS:
            raise CloudError(f"proposals: expected one of {PROPOSALS}, found {self.proposals!r}")
        if self.anchors not in ANCHOR_SAMPLINGS:
            raise CloudError(f"anchors: expected one of {ANCHOR_SAMPLINGS}, found {self.anchors!r}")
        for name in ("n_points", "check_points", "n_samples", "max_pairs", "k", "threads"):
            check_integer(name, getattr(self, name), minimum=1, error=CloudError)
        check_integer("seed", self.seed, minimum=0, error=CloudError)
        if not (isinstance(self.tolerance, int | float) and 0.0 <= self.tolerance < 0.02):
            raise CloudError(
                f"tolerance: expected a number in [0, 0.02) m, found {self.tolerance!r}"
            )

    def candidates(
        self, observation: dict[str, Any]
    ) -> tuple[Cloud, DualCandidates, np.ndarray, np.random.Generator]:
        """``(the models' cloud, dual candidates, cloud force-closure verdicts (N,), rng)`` of
        one object (steps 1-4 of the module docstring; N may be 0)."""
        import torch

        check_observation(observation)
        stream = object_seed(self.seed, f"flow:{stream_name(observation)}")
        rng = np.random.default_rng(stream)
        if self.smoothing is not None and is_cloud_track(observation):
            observation = smoothed_observation(observation, self.smoothing)
        dense = observed_cloud(observation, self.check_points, rng)
        cloud = check_cloud(dense.points[: self.n_points], dense.normals[: self.n_points])
        generator = load_generator(
            str(self.generator_checkpoint or GENERATOR_CHECKPOINT), self.threads
        )
        if self.anchors == "learned":
            chance = generator.anchor_probabilities(cloud.points).to(torch.float64).numpy()
            anchors = rng.choice(cloud.n, self.n_samples, p=chance / chance.sum())
        else:
            anchors = rng.choice(cloud.n, self.n_samples, replace=cloud.n < self.n_samples)
        hands = generator.sample(
            cloud.points, anchors, torch.Generator().manual_seed(stream % 2**63)
        )
        hands = rigid(hands.to(torch.float64).numpy())
        _, singles = snap_hands(dense, hands, tolerance=self.tolerance)
        if self.proposals == "sampler":  # drawn all the same: the sampler's draws stay the same
            _, singles = snap_hands(dense, hands[:0])
        generated = singles.n
        if self.proposals != "generator":
            singles = concatenate_grasps(singles, sample_cloud_grasps(dense, PARTIAL_SAMPLER, rng))
            singles = concatenate_grasps(
                singles, sample_enclosing_grasps(dense, PARTIAL_SAMPLER, rng)
            )
        candidates = pair_hands(singles, self.max_pairs, rng)
        candidates.counts.update(
            samples=self.n_samples, kept_hands=generated, sampler_hands=singles.n - generated
        )
        return cloud, candidates, cloud_force_closure(candidates), rng

    def __call__(self, observation: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        """``(poses (k', 2, 4, 4), scores (k',))`` for one object, best first (k' <= k).

        Raises:
            CloudError: a malformed observation, or no dual candidate on the cloud.
        """
        cloud, candidates, passed, rng = self.candidates(observation)
        if candidates.n == 0:
            raise CloudError(
                f"expected dual candidates on the cloud, found none ({candidates.counts})"
            )
        if self.ranker == "learned":
            model = load_flow_ranker(str(self.ranker_checkpoint or RANKER_CHECKPOINT), self.threads)
            scores = classifier_scores(model, cloud.points, candidates.poses)
        else:
            scores = rng.random(candidates.n)
        scores = scores + FC_BONUS * passed
        if self.robust:
            scores = candidates_robust_first(
                scores,
                passed,
                candidates,
                cloud.points,
                k=self.k,
                bonus=ROBUST_BONUS,
                max_ratios=self.motion_ratio_levels,
            )
        order = np.argsort(-scores, kind="stable")[: self.k]
        return candidates.poses[order], scores[order]


flow_predictor = FlowPredictor()
"""The shipped generator and ranker: 512 generated hands and the cloud sampler's, the 10 best pairs
(``--track cloud``)."""

flow_smoothed_predictor = FlowPredictor(smoothing=DepthSmoothing())
"""The same with each camera's depth smoothed first (:mod:`baselines.depth_smoothing`)."""

flow_robust_predictor = FlowPredictor(smoothing=DepthSmoothing(), robust=True)
"""The smoothed predictor with the robust criterion on the cloud contacts ranking the passing
pairs level by level before the ranker (``robust=True``)."""

flow_random_predictor = FlowPredictor(ranker="random")
"""The same pairs and checks in random order within each group: the ranker's control."""


__all__ = [
    "ANCHOR_SAMPLINGS",
    "DEPTH_OFFSETS",
    "FC_BONUS",
    "FLOW_RANKERS",
    "GENERATOR_CHECKPOINT",
    "PROPOSALS",
    "RANKER_CHECKPOINT",
    "FlowPredictor",
    "check_observation",
    "flow_predictor",
    "flow_random_predictor",
    "flow_robust_predictor",
    "flow_smoothed_predictor",
    "load_flow_ranker",
    "load_generator",
    "observed_cloud",
    "pair_hands",
    "rigid",
    "snap_hands",
]
