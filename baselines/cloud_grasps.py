"""Dual-grasp candidates (antipodal and enclosing) from an observed point cloud with normals (no
mesh).

What a robot sees of an object is a point cloud with normals: the whole surface
(:func:`dg16m_env.subjects.observation.object_observation`) or what one or two depth cameras see of it
(the environments' ``obs_mode="partial"``). :func:`cloud_dual_candidates` turns such a cloud into
dual-arm Panda grasps by the steps of the mesh sampler (:mod:`dataset_gen.grasps.sampling`) and the
generator's pairing (:mod:`dataset_gen.grasps.pairing`), with the cloud standing in for the mesh:

1. **Contact pairs across the cloud** (:func:`cloud_contact_pairs`). ``n_seeds`` cloud points
   ``p0`` are drawn without replacement. A partner ``p1`` is any other cloud point with
   ``min_width < |p1 - p0| <= max_opening - opening_margin`` such that the contact line
   ``d = (p1 - p0) / |p1 - p0|`` lies in both friction cones (half-angle ``atan(mu)``, ``mu`` the
   paper's 0.4 unless given): ``d . (-n0) >= cos(atan(mu))`` and ``d . n1 >= cos(atan(mu))``
   (outward normals). Each seed keeps its most antipodal partner (largest ``min`` of the two
   cosines); unordered duplicates are dropped.
2. **The Panda hand at each pair** (:func:`hand_poses`): the closing axis ``x = normalize(n0 -
   n1)`` (the mean of the two outward normals, the mesh sampler's ``axis="normals"``; finger 0
   on ``p0`` at ``+x``), the grasp centre ``c = (p0 + p1) / 2`` at ``(0, contact_depth, 0)`` in
   the grasp frame (as :meth:`dataset_gen.grasps.gripper.GripperModel.pose_from_contacts`), and
   ``n_approach`` approach directions about ``x``, evenly spaced with a seeded offset. The jaw
   width is ``w = (p0 - p1) . x``; pairs outside ``(min_width, max_opening - opening_margin]``
   are dropped.
3. **Collision with the cloud** (:func:`hand_hits_cloud`), every pose against every point. A
   pose is rejected when any cloud point lies, beyond ``tolerance`` (m), inside

   * the palm box (:meth:`~dataset_gen.grasps.gripper.GripperModel.palm_box`, shrunk by ``tolerance``);
   * a finger's swept volume: the finger's footprint (``palm_depth <= y <= finger_tip``,
     ``|z| <= finger_width / 2``) from its contact outwards past the fully open finger,
     ``x`` in ``(x0 + tolerance, max_opening / 2 + finger_thickness]`` for finger 0 (``x0`` its
     contact's ``x``), mirrored for finger 1. This holds the closed fingers (a point there means
     the pad would sit inside the object), the open fingers (the hand could not get there) and
     everything between (the jaw would touch it before the planned contact).

   A pose is also rejected when one of its two contacts falls off its pad (``y`` outside
   ``[palm_depth, finger_tip]`` or ``|z| > finger_width / 2``, less ``pad_margin``). Per pair the
   first approach that passes is kept: one single-arm grasp per contact pair, as the mesh
   sampler and the DG16M release do; the first ``max_grasps`` pairs that have one, in seed
   order, are kept.
4. **Dual candidates** (:func:`dataset_gen.grasps.pairing.candidate_pairs`): every unique pair of those
   grasps whose centres are at least ``min_center_distance`` (the paper's 0.1 m) apart and whose
   two open hands (palm and fingers, exact box test) do not intersect each other; at most
   ``max_pairs`` of them, a seeded uniform subset, in ascending pair order.

With ``enclosing=True`` (the partial-cloud predictors' setting), enclosing grasps are added
before step 4 (:func:`sample_enclosing_grasps`), in the manner of GPD's candidates (ten Pas et
al., 2017): they need one observed side of a thin part, not two antipodal ones.

5. **Approach against a normal** (:func:`enclosing_poses`). ``n_enclosing_seeds`` cloud points
   are drawn; the hand approaches each along its inward normal (``y = -n``) until the fingertips
   pass it by ``enclosing_reach``, with ``n_closing`` closing axes ``x`` evenly spaced over half a
   turn about the approach (a seeded offset).
6. **What the jaws would hold** (:func:`enclose`): the cloud points between the open fingers
   (``palm_depth <= y <= finger_tip``, ``|z| <= finger_width / 2``, ``|x| <= max_opening / 2``);
   the contacts are the held points farthest along ``+x`` and ``-x``, the jaw width their
   distance along ``x``, and the hand is centred on them. A pose is refused when it holds fewer
   than two points, when a contact lies at the edge of the opening (the part goes on past the
   finger), when a contact's normal points back towards the other finger by more than
   :data:`MAX_BACK_FACING`, when neither contact's normal lies in the friction cone about the
   closing axis (no face seen to face its finger), when the width is outside ``(min_width,
   max_width]``, or when the hand hits the cloud (step 3's test with these contacts).
7. Per seed the narrowest collision-free closing axis is kept. A contact's normal is the
   cloud's where it lies in the friction cone about the closing axis; otherwise the face the
   finger meets was not seen (a board's underside under a camera that looks down) and is
   assumed to face the finger (``+x`` for finger 0, ``-x`` for finger 1).

The contacts are cloud points, so they lie on the observed surface (within the cloud's spacing
of the true one) and their normals are the cloud's. A partial cloud has no back side: a hand can
intersect what the cameras did not see, and one camera never sees two antipodal contacts of a
convex object (a face and the face opposite it cannot both face one viewpoint); two cameras on
opposite sides can.

Units: metres; object frame; poses are the dg16m grasp frame (:mod:`dataset_gen.grasps.gripper`).
Randomness: only the caller's ``numpy.random.Generator`` (seeds, approach offsets, then with
``enclosing`` the enclosing seeds and closing-axis offsets, then the subset of pairs, in that
order): the same cloud, configuration and generator state give the same arrays.
Rejections are validity masks and counts, never exceptions; a malformed cloud (NaN, wrong shapes,
too few points, zero normals) is a :class:`CloudError` that says what was expected and found.

The code is cut where its concepts part, imports pointing one way (``cloud_inputs <- cloud_hand <-
cloud_enclosing <- cloud_grasps``): the cloud, its checks and the parameters are in
:mod:`baselines.cloud_inputs`; the hand's poses, its collision with the cloud and the depth
cameras' seen free space (steps 2 and 3) in :mod:`baselines.cloud_hand`; the enclosing grasps
(steps 5-7) in :mod:`baselines.cloud_enclosing`. This module holds the antipodal contact pairs
(step 1), the single-arm grasps of steps 1-3 and the dual candidates (step 4), and re-exports
every public name of the other three, so ``from baselines.cloud_grasps import hand_hits_cloud``
keeps working. The loops over (hand or seed, cloud point) pairs of steps 1, 3 and 6 are compiled
(:mod:`baselines.cloud_kernels`, which imports nothing of these).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from baselines.cloud_enclosing import (
    MAX_BACK_FACING,
    enclose,
    enclosing_poses,
    sample_enclosing_grasps,
)
from baselines.cloud_hand import (
    DepthViews,
    _on_pads,
    hand_hits_cloud,
    hand_poses,
    hand_reach,
    hand_volume_in_object,
    hand_volume_points,
    hands_in_seen_free_space,
)
from baselines.cloud_inputs import (
    MIN_POINTS,
    NORMAL_TOLERANCE,
    Cloud,
    CloudError,
    CloudSamplerConfig,
    check_cloud,
)
from baselines.cloud_kernels import best_partners
from dataset_gen.grasps.gripper import get_gripper
from dataset_gen.grasps.pairing import candidate_pairs, dual_contacts, dual_poses
from dataset_gen.grasps.sampling import SingleArmGrasps
from dg16m_core.parameters import PAPER

_COS_EPS = 1e-12


@dataclass(frozen=True)
class ContactPairs:
    """Antipodal contact pairs of a cloud (step 1 of the module docstring).

    Attributes:
        index: (S, 2) int64 cloud indices ``[p0, p1]`` (finger 0, finger 1).
        cosine: (S,) the smaller of the two cone cosines (1 = exactly antipodal).
    """

    index: np.ndarray
    cosine: np.ndarray

    @property
    def n(self) -> int:
        return int(self.index.shape[0])


def cloud_contact_pairs(
    cloud: Cloud,
    seeds: np.ndarray,
    *,
    mu: float = PAPER.mu,
    min_width: float = 1e-3,
    max_width: float = 0.079,
) -> ContactPairs:
    """Each seed's most antipodal partner within both friction cones, duplicates dropped.

    Every cloud point is tried as each seed's partner in one compiled loop
    (:func:`baselines.cloud_kernels.best_partners`); duplicates are dropped here.

    Args:
        cloud: the cloud.
        seeds: (S,) int cloud indices of the first contacts.
        mu: friction coefficient.
        min_width, max_width: the contact separation must lie in ``(min_width, max_width]`` (m).

    Returns:
        The pairs in seed order (a seed without a partner is left out; of two seeds that chose
        each other, the first is kept); ties between partners go to the lower cloud index.
    """
    seeds = np.asarray(seeds, dtype=np.int64)
    cos_cone = math.cos(math.atan(mu)) - _COS_EPS
    pts, nrm = cloud.points, cloud.normals
    partner, best = best_partners(pts, nrm, seeds, cos_cone, float(min_width), float(max_width))
    found = partner >= 0
    index = np.stack([seeds[found], partner[found]], axis=1)
    cosine = best[found]
    if len(index):
        key = np.sort(index, axis=1)
        _, first = np.unique(key[:, 0] * cloud.n + key[:, 1], return_index=True)
        first = np.sort(first)
        index, cosine = index[first], cosine[first]
    return ContactPairs(index=index.astype(np.int64).reshape(-1, 2), cosine=cosine)


def sample_cloud_grasps(
    cloud: Cloud,
    config: CloudSamplerConfig,
    rng: np.random.Generator,
    counts: dict[str, int] | None = None,
    views: DepthViews | None = None,
) -> SingleArmGrasps:
    """Single-arm grasps on a cloud (steps 1-3 of the module docstring).

    Args:
        cloud: the cloud (:func:`check_cloud`).
        config: the parameters.
        rng: draws the seeds, then the approach offsets.
        counts: a dict that receives per-stage counts (``seeds``, ``contact_pairs``,
            ``within_opening``, ``poses_tried``, ``collision_free``, ``grasps``; with ``views``
            also ``unseen_space``: poses refused because part of the open hand lies where no
            camera saw empty space).
        views: the depth views the cloud came from; then the open hand must lie in space they
            saw empty (:func:`hands_in_seen_free_space`).

    Returns:
        :class:`~dataset_gen.grasps.sampling.SingleArmGrasps` (M <= ``max_grasps``) whose
        ``face_ids`` (M, 2) are the contacts' cloud indices.
    """
    if not isinstance(rng, np.random.Generator):
        raise CloudError(f"rng: expected a numpy Generator, found {type(rng).__name__}")
    model = get_gripper(config.gripper)
    counts = {} if counts is None else counts
    n_seeds = min(config.n_seeds, cloud.n)
    seeds = rng.choice(cloud.n, size=n_seeds, replace=False)
    offsets = rng.random(n_seeds) * (2.0 * np.pi / config.n_approach)
    counts["seeds"] = n_seeds
    max_width = config.max_width(model)
    pairs = cloud_contact_pairs(
        cloud, seeds, mu=config.mu, min_width=config.min_width, max_width=max_width
    )
    counts["contact_pairs"] = pairs.n
    i0, i1 = pairs.index[:, 0], pairs.index[:, 1]
    p0, p1 = cloud.points[i0], cloud.points[i1]
    n0, n1 = cloud.normals[i0], cloud.normals[i1]
    seed_row = {int(s): k for k, s in enumerate(seeds)}
    offset = offsets[[seed_row[int(s)] for s in i0]] if pairs.n else np.zeros(0)
    angles = offset[:, None] + 2.0 * np.pi * np.arange(config.n_approach) / config.n_approach
    poses, widths = hand_poses(p0, p1, n0, n1, angles, model)
    spans = (widths > config.min_width) & (widths <= max_width)
    counts["within_opening"] = int(spans.sum())
    rows = np.flatnonzero(spans)
    clearance = config.clearance_factor * cloud.spacing
    chosen = np.full(len(widths), -1, dtype=np.int64)
    tried = unseen = 0
    for k in range(config.n_approach):  # round k: approach k of every pair still without one
        todo = rows[chosen[rows] < 0]
        if len(todo) == 0 or int((chosen >= 0).sum()) >= config.max_grasps:
            break
        T = poses[todo, k]
        contacts = np.stack([p0[todo], p1[todo]], axis=1)  # (n, 2, 3)
        local = np.einsum("nki,nck->nci", T[:, :3, :3], contacts - T[:, None, :3, 3])
        ok = _on_pads(local, model, config.pad_margin)
        ok[ok] = ~hand_hits_cloud(
            cloud, T[ok], local[ok][..., 0], model, config.tolerance, clearance
        )
        if views is not None:
            skip = np.full((int(ok.sum()), 2), not config.free_space_fingers)
            free = hands_in_seen_free_space(views, T[ok], model, config.free_space_margin, skip)
            unseen += int((~free).sum())
            ok[ok] = free
        tried += len(todo)
        chosen[todo[ok]] = k
    counts["poses_tried"] = tried
    if views is not None:
        counts["unseen_space"] = unseen
    keep = np.flatnonzero(chosen >= 0)
    counts["collision_free"] = len(keep)
    keep = keep[: config.max_grasps]
    counts["grasps"] = len(keep)
    return SingleArmGrasps(
        poses=poses[keep, chosen[keep]].reshape(-1, 4, 4),
        contact_points=np.stack([p0[keep], p1[keep]], axis=1).reshape(-1, 2, 3),
        contact_normals=np.stack([n0[keep], n1[keep]], axis=1).reshape(-1, 2, 3),
        face_ids=pairs.index[keep].reshape(-1, 2),
        widths=widths[keep],
        gripper=model.name,
        counts=dict(counts),
    )


def concatenate_grasps(a: SingleArmGrasps, b: SingleArmGrasps) -> SingleArmGrasps:
    """The grasps of ``a`` then those of ``b`` (same gripper; counts merged)."""
    return SingleArmGrasps(
        poses=np.concatenate([a.poses, b.poses]),
        contact_points=np.concatenate([a.contact_points, b.contact_points]),
        contact_normals=np.concatenate([a.contact_normals, b.contact_normals]),
        face_ids=np.concatenate([a.face_ids, b.face_ids]),
        widths=np.concatenate([a.widths, b.widths]),
        gripper=a.gripper,
        counts={**a.counts, **b.counts},
    )


@dataclass(frozen=True)
class DualCandidates:
    """Dual-grasp candidates of one cloud.

    Attributes:
        grasps: the M single-arm grasps (``face_ids``: cloud indices of the contacts).
        pairs: (N, 2) int64 grasp indices ``i < j``, ascending.
        poses: (N, 2, 4, 4) hand poses ``[i, j]`` (grasp frame -> object frame, m).
        contact_points: (N, 4, 3) ``[i finger 0, i finger 1, j finger 0, j finger 1]`` (m).
        contact_normals: (N, 4, 3) their unit outward cloud normals.
        counts: per-stage counts (:func:`sample_cloud_grasps`'s, then ``pairs`` (all M(M-1)/2),
            ``pruned_distance``, ``gripper_collision``, ``dual_candidates`` (before the subset),
            ``kept``).
    """

    grasps: SingleArmGrasps
    pairs: np.ndarray
    poses: np.ndarray
    contact_points: np.ndarray
    contact_normals: np.ndarray
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of dual candidates N."""
        return int(self.pairs.shape[0])


def cloud_dual_candidates(
    cloud: Cloud,
    config: CloudSamplerConfig | None = None,
    *,
    rng: np.random.Generator,
    views: DepthViews | None = None,
) -> DualCandidates:
    """Dual-grasp candidates of a cloud (steps 1-4 of the module docstring).

    Args:
        cloud: the cloud (:func:`check_cloud`).
        config: the parameters (default :class:`CloudSamplerConfig`).
        rng: the only source of randomness.
        views: the depth views the cloud came from, if any: every open hand must then lie in
            space they saw empty (:func:`hands_in_seen_free_space`).

    Returns:
        The candidates; ``n == 0`` when the cloud yields none (the counts say where they went).
    """
    config = CloudSamplerConfig() if config is None else config
    counts: dict[str, int] = {}
    grasps = sample_cloud_grasps(cloud, config, rng, counts, views)
    if config.enclosing:
        enclosing = sample_enclosing_grasps(cloud, config, rng, counts, views)
        grasps = concatenate_grasps(grasps, enclosing)
    if grasps.n >= 2:
        cands = candidate_pairs(grasps, min_center_distance=config.min_center_distance)
        counts.update({k: int(v) for k, v in cands.counts.items() if k != "remaining"})
        pairs = cands.pairs
    else:
        pairs = np.zeros((0, 2), dtype=np.int64)
        counts.update(pairs=0, pruned_distance=0, gripper_collision=0)
    counts["dual_candidates"] = len(pairs)
    if len(pairs) > config.max_pairs:
        pairs = pairs[np.sort(rng.choice(len(pairs), size=config.max_pairs, replace=False))]
    counts["kept"] = len(pairs)
    return paired_candidates(grasps, pairs, counts)


def paired_candidates(
    grasps: SingleArmGrasps, pairs: np.ndarray, counts: dict[str, int]
) -> DualCandidates:
    """The :class:`DualCandidates` of ``pairs`` (N, 2) of ``grasps`` (their poses and contacts;
    N may be 0), with ``counts``."""
    if len(pairs):
        points, normals = dual_contacts(grasps, pairs)
        poses = dual_poses(grasps, pairs)
    else:
        points = normals = np.zeros((0, 4, 3))
        poses = np.zeros((0, 2, 4, 4))
    return DualCandidates(grasps, pairs, poses, points, normals, counts)


__all__ = [
    "MAX_BACK_FACING",
    "MIN_POINTS",
    "NORMAL_TOLERANCE",
    "Cloud",
    "CloudError",
    "CloudSamplerConfig",
    "ContactPairs",
    "DepthViews",
    "DualCandidates",
    "check_cloud",
    "cloud_contact_pairs",
    "cloud_dual_candidates",
    "concatenate_grasps",
    "enclose",
    "enclosing_poses",
    "hand_hits_cloud",
    "hand_poses",
    "hand_reach",
    "hand_volume_in_object",
    "hand_volume_points",
    "hands_in_seen_free_space",
    "paired_candidates",
    "sample_cloud_grasps",
    "sample_enclosing_grasps",
]
