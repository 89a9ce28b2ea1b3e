"""Dual-grasp candidates (antipodal and enclosing) from an observed point cloud with normals (no
mesh).

What a robot sees of an object is a point cloud with normals: the whole surface
(:func:`dg16m_env.subjects.observation.object_observation`) or what one or two depth cameras see of it
(the environments' ``obs_mode="partial"``). :func:`cloud_dual_candidates` turns such a cloud into
dual-arm Panda grasps by the steps of the mesh sampler (:mod:`dataset_gen.sampling`) and the
generator's pairing (:mod:`dataset_gen.pairing`), with the cloud standing in for the mesh:

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
   the grasp frame (as :meth:`dataset_gen.gripper.GripperModel.pose_from_contacts`), and
   ``n_approach`` approach directions about ``x``, evenly spaced with a seeded offset. The jaw
   width is ``w = (p0 - p1) . x``; pairs outside ``(min_width, max_opening - opening_margin]``
   are dropped.
3. **Collision with the cloud** (:func:`hand_hits_cloud`), vectorised over poses and points. A
   pose is rejected when any cloud point lies, beyond ``tolerance`` (m), inside

   * the palm box (:meth:`~dataset_gen.gripper.GripperModel.palm_box`, shrunk by ``tolerance``);
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
4. **Dual candidates** (:func:`dataset_gen.pairing.candidate_pairs`): every unique pair of those
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

Units: metres; object frame; poses are the dg16m grasp frame (:mod:`dataset_gen.gripper`).
Randomness: only the caller's ``numpy.random.Generator`` (seeds, approach offsets, then with
``enclosing`` the enclosing seeds and closing-axis offsets, then the subset of pairs, in that
order): the same cloud, configuration and generator state give the same arrays.
Rejections are validity masks and counts, never exceptions; a malformed cloud (NaN, wrong shapes,
too few points, zero normals) is a :class:`CloudError` that says what was expected and found.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from dataset_gen.checks import check_fields
from dataset_gen.errors import Dg16mError
from dataset_gen.gripper import Box, GripperModel, get_gripper
from dataset_gen.pairing import candidate_pairs, dual_contacts, dual_poses
from dataset_gen.parameters import PAPER
from dataset_gen.sampling import SingleArmGrasps, _tangent_basis

MIN_POINTS = 16
"""Fewest cloud points accepted (after the mask)."""

NORMAL_TOLERANCE = 1e-3
"""Largest ``| |n| - 1 |`` of an input normal; normals are renormalised after the check."""

_COS_EPS = 1e-12


class CloudError(Dg16mError, ValueError):
    """A malformed cloud or bad sampler arguments."""


@dataclass(frozen=True)
class Cloud:
    """A checked point cloud with normals (object frame).

    Attributes:
        points: (P, 3) float64 points (m).
        normals: (P, 3) float64 unit outward normals.
        spacing: median distance from a point to its nearest distinct neighbour (m): the
            cloud's resolution.
    """

    points: np.ndarray
    normals: np.ndarray
    spacing: float

    @property
    def n(self) -> int:
        """Number of points P."""
        return int(self.points.shape[0])

    @cached_property
    def tree(self) -> cKDTree:
        """A k-d tree of the points (built once)."""
        return cKDTree(self.points)


def check_cloud(
    points: np.ndarray,
    normals: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    min_points: int = MIN_POINTS,
) -> Cloud:
    """Validate a cloud and keep its real points.

    Args:
        points: (P, 3) float points (m), object frame.
        normals: (P, 3) float unit outward normals at ``points``.
        mask: optional (P,) validity (1 / True = a real point, 0 = padding, as the environments'
            partial observation); padding rows are dropped before any other check.
        min_points: fewest real points accepted.

    Returns:
        The :class:`Cloud` (float64, C-contiguous, normals renormalised).

    Raises:
        CloudError: wrong shapes or dtypes, NaN or infinite values, normals that are not unit
            (``NORMAL_TOLERANCE``), fewer than ``min_points`` points.
    """
    arrays = {}
    for name, value in (("points", points), ("normals", normals)):
        array = np.asarray(value)
        if array.dtype.kind not in "iuf":
            raise CloudError(f"{name}: expected a float array, found dtype {array.dtype}")
        if array.ndim != 2 or array.shape[1] != 3:
            raise CloudError(f"{name}: expected shape (P, 3), found {array.shape}")
        arrays[name] = np.asarray(array, dtype=np.float64)
    pts, nrm = arrays["points"], arrays["normals"]
    if pts.shape != nrm.shape:
        raise CloudError(f"normals: expected the shape of points {pts.shape}, found {nrm.shape}")
    if mask is not None:
        keep = np.asarray(mask)
        if keep.shape != (len(pts),):
            raise CloudError(f"mask: expected shape ({len(pts)},), found {keep.shape}")
        if keep.dtype.kind not in "biuf" or not np.isfinite(keep.astype(np.float64)).all():
            raise CloudError(f"mask: expected finite 0 / 1 values, found dtype {keep.dtype}")
        keep = keep.astype(np.float64) > 0.5
        pts, nrm = pts[keep], nrm[keep]
    for name, array in (("points", pts), ("normals", nrm)):
        bad = np.flatnonzero(~np.isfinite(array).all(axis=1))
        if bad.size:
            raise CloudError(
                f"{name}: expected finite values, found NaN or inf in {bad.size} rows "
                f"(first: row {int(bad[0])})"
            )
    if len(pts) < min_points:
        raise CloudError(f"points: expected at least {min_points} points, found {len(pts)}")
    length = np.linalg.norm(nrm, axis=1)
    off = np.abs(length - 1.0)
    if off.max() > NORMAL_TOLERANCE:
        row = int(np.argmax(off))
        raise CloudError(
            f"normals: expected unit vectors (within {NORMAL_TOLERANCE}), found length "
            f"{length[row]:.4g} at row {row}"
        )
    nrm = nrm / length[:, None]
    return Cloud(np.ascontiguousarray(pts), np.ascontiguousarray(nrm), _spacing(pts))


def _spacing(points: np.ndarray) -> float:
    """Median distance (m) from a point to its nearest distinct neighbour."""
    distance, _ = cKDTree(points).query(points, k=2)
    nearest = distance[:, 1]
    nearest = nearest[nearest > 0.0]
    return float(np.median(nearest)) if nearest.size else 0.0


@dataclass(frozen=True)
class CloudSamplerConfig:
    """Parameters of :func:`cloud_dual_candidates` (SI units; see the module docstring).

    Attributes:
        mu: friction coefficient; the friction cone's half-angle is ``atan(mu)``.
        n_seeds: first contacts drawn from the cloud (fewer when the cloud is smaller).
        n_approach: approach directions tried per contact pair.
        max_grasps: single-arm grasps kept (the first in seed order).
        max_pairs: dual candidates kept (a seeded uniform subset).
        min_width: smallest contact separation and jaw width (m).
        opening_margin: the jaws must be at least this much narrower than fully open (m).
        tolerance: how far a cloud point may reach into the hand's palm or finger volumes (m).
        clearance_factor: the hand's volumes are grown by this times the cloud's spacing
            (:attr:`Cloud.spacing`) on every side but the fingers' contact faces.
        pad_margin: a contact must lie this far inside its pad's footprint (m).
        min_center_distance: the two grasps' centres at least this far apart (m).
        gripper: a gripper name (:data:`dataset_gen.gripper.GRIPPERS`).
        enclosing: also sample enclosing grasps (:func:`sample_enclosing_grasps`: the hand
            approaches a point against its normal and closes on whatever lies between its
            fingers), which need only one observed side of a thin part.
        n_enclosing_seeds: points the enclosing grasps approach (fewer when the cloud is
            smaller).
        n_closing: closing-axis directions tried per enclosing seed, evenly spaced over half a
            turn about the approach with a seeded offset.
        enclosing_reach: how far the fingertips pass the approached point (m; at most the pad
            length ``finger_tip - palm_depth``).
        free_space_margin: with depth views (:class:`DepthViews`), a point of the open hand
            counts as seen free when a camera saw a surface at least this much farther along
            its pixel's ray (m; about a pixel's footprint at a metre, 6.5 mm at 128 pixels).
        free_space_fingers: test the open fingers' volumes as well as the palm's (else the
            palm's only: fingers next to a surface sit where a pixel's footprint blurs seen
            and unseen space).
    """

    mu: float = PAPER.mu
    n_seeds: int = 2048
    n_approach: int = 8
    max_grasps: int = 200
    max_pairs: int = 1024
    min_width: float = 1e-3
    opening_margin: float = 1e-3
    tolerance: float = 2e-3
    clearance_factor: float = 1.0
    pad_margin: float = 1e-3
    min_center_distance: float = PAPER.min_center_distance
    gripper: str = "panda"
    enclosing: bool = False
    n_enclosing_seeds: int = 512
    n_closing: int = 6
    enclosing_reach: float = 0.03
    free_space_margin: float = 0.01
    free_space_fingers: bool = True

    def __post_init__(self) -> None:
        check_fields(
            self,
            error=CloudError,
            integers={
                "n_seeds": 1,
                "n_approach": 1,
                "max_grasps": 2,
                "max_pairs": 1,
                "n_enclosing_seeds": 1,
                "n_closing": 1,
            },
            zero_allowed=(
                "tolerance",
                "clearance_factor",
                "pad_margin",
                "opening_margin",
                "min_center_distance",
            ),
            skip=("gripper", "enclosing", "free_space_fingers"),
        )
        for flag in ("enclosing", "free_space_fingers"):
            if not isinstance(getattr(self, flag), bool):
                raise CloudError(
                    f"{flag}: expected a bool, found {type(getattr(self, flag)).__name__}"
                )
        model = get_gripper(self.gripper)
        if self.max_width(model) <= self.min_width:
            raise CloudError(
                f"opening_margin: expected max_opening - opening_margin > min_width "
                f"({self.min_width} m), found {self.max_width(model)} m"
            )
        pad = model.finger_tip - model.palm_depth
        if self.enclosing_reach > pad:
            raise CloudError(
                f"enclosing_reach: expected at most the pad length {pad:.4g} m, found "
                f"{self.enclosing_reach} m"
            )

    def max_width(self, model: GripperModel) -> float:
        """The widest jaw opening a grasp may use (m)."""
        return model.max_opening - self.opening_margin


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

    The partners of a seed are searched among the cloud points within ``max_width`` of it (a
    k-d tree, :class:`scipy.spatial.cKDTree`); the cone tests run on the flat list of
    (seed, neighbour) entries.

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
    row, j = _neighbours(cloud.tree, pts[seeds], max_width)
    i = seeds[row]
    d = pts[j] - pts[i]
    dist = np.linalg.norm(d, axis=1)
    ok = (dist > min_width) & (dist <= max_width)
    row, i, j, d, dist = row[ok], i[ok], j[ok], d[ok], dist[ok]
    cos0 = -np.einsum("ek,ek->e", d, nrm[i]) / dist  # d . (-n0)
    cos1 = np.einsum("ek,ek->e", d, nrm[j]) / dist  # d . n1
    both = np.minimum(cos0, cos1)
    ok = both >= cos_cone
    row, j, both = row[ok], j[ok], both[ok]
    # per seed row: the largest cosine, then the lowest partner index
    order = np.lexsort((-j, both, row))
    last = np.flatnonzero(np.r_[row[order][1:] != row[order][:-1], len(order) > 0])
    pick = order[last]
    index = np.stack([seeds[row[pick]], j[pick]], axis=1)
    cosine = both[pick]
    if len(index):
        key = np.sort(index, axis=1)
        _, first = np.unique(key[:, 0] * cloud.n + key[:, 1], return_index=True)
        first = np.sort(first)
        index, cosine = index[first], cosine[first]
    return ContactPairs(index=index.astype(np.int64).reshape(-1, 2), cosine=cosine)


def _neighbours(tree: cKDTree, queries: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Flat (query row, point index) arrays of every tree point within ``radius`` (m) of each
    of ``queries`` (Q, 3), grouped by query row."""
    lists = tree.query_ball_point(queries, r=radius, return_sorted=True)
    sizes = np.fromiter((len(x) for x in lists), dtype=np.int64, count=len(lists))
    rows = np.repeat(np.arange(len(lists), dtype=np.int64), sizes)
    points = (
        np.fromiter(itertools.chain.from_iterable(lists), dtype=np.int64, count=int(sizes.sum()))
        if len(lists)
        else np.zeros(0, dtype=np.int64)
    )
    return rows, points


def hand_poses(
    p0: np.ndarray,
    p1: np.ndarray,
    n0: np.ndarray,
    n1: np.ndarray,
    angles: np.ndarray,
    model: GripperModel,
) -> tuple[np.ndarray, np.ndarray]:
    """Hand poses putting finger 0 on ``p0`` and finger 1 on ``p1`` (step 2).

    Args:
        p0, p1: (S, 3) contacts (m). n0, n1: (S, 3) their unit outward normals.
        angles: (S, A) approach angles (rad) about the closing axis, measured from the first
            vector of :func:`dataset_gen.sampling._tangent_basis` of the axis.
        model: the gripper.

    Returns:
        ``poses (S, A, 4, 4)`` (grasp frame -> object frame, m) and ``widths (S,)`` jaw widths
        ``(p0 - p1) . x`` (m; may be <= 0 for pairs whose normals are not opposed).
    """
    x = n0 - n1
    x = x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300)
    b1, b2 = _tangent_basis(x)
    c, s = np.cos(angles)[..., None], np.sin(angles)[..., None]  # (S, A, 1)
    y = c * b1[:, None, :] + s * b2[:, None, :]
    z = c * b2[:, None, :] - s * b1[:, None, :]  # x cross y (b2 = x cross b1)
    centre = 0.5 * (p0 + p1)
    poses = np.zeros((*angles.shape, 4, 4))
    poses[..., :3, 0] = x[:, None, :]
    poses[..., :3, 1] = y
    poses[..., :3, 2] = z
    poses[..., :3, 3] = centre[:, None, :] - model.contact_depth * y
    poses[..., 3, 3] = 1.0
    widths = np.einsum("sk,sk->s", p0 - p1, x)
    return poses, widths


def hand_reach(model: GripperModel) -> float:
    """Radius (m) of a sphere about the grasp centre ``(0, contact_depth, 0)`` that holds the
    palm and both fully open fingers."""
    corners = np.concatenate([b.corners for b in model.collision_boxes(None)])
    return float(np.linalg.norm(corners - [0.0, model.contact_depth, 0.0], axis=1).max())


def hand_hits_cloud(
    points: np.ndarray | Cloud,
    poses: np.ndarray,
    contact_x: np.ndarray,
    model: GripperModel,
    tolerance: float,
    clearance: float = 0.0,
) -> np.ndarray:
    """Whether each hand pose has a cloud point inside its palm or finger volumes (step 3).

    Only the points within :func:`hand_reach` of each pose's grasp centre are tested (a k-d
    tree), on a flat list of (pose, point) entries.

    Args:
        points: (P, 3) cloud points (m), or a :class:`Cloud` (its tree is reused).
        poses: (N, 4, 4) hand poses (grasp frame -> object frame, m).
        contact_x: (N, 2) the ``x`` of finger 0's and finger 1's contact in each pose's frame
            (m; ``+w/2`` and ``-w/2`` for a centred grasp).
        model: the gripper.
        tolerance: how far a point may reach into a volume (m).
        clearance: the volumes grown by this much (m) on every side but the fingers' inner
            (contact) faces: a sparse cloud has no point where a thin feature the hand would hit
            falls between its points.

    Returns:
        (N,) bool, True = the hand intersects the cloud.
    """
    if isinstance(points, Cloud):
        pts, tree = points.points, points.tree
    else:
        pts = np.asarray(points, dtype=np.float64)
        tree = cKDTree(pts)
    poses = np.asarray(poses, dtype=np.float64)
    contact_x = np.asarray(contact_x, dtype=np.float64)
    if len(poses) == 0:
        return np.zeros(0, dtype=bool)
    palm = model.palm_box()
    grow = clearance - tolerance
    palm_lo = np.asarray(palm.center) - np.asarray(palm.half_extents) - grow
    palm_hi = np.asarray(palm.center) + np.asarray(palm.half_extents) + grow
    outer = model.max_opening / 2.0 + model.finger_thickness + clearance
    half_z = model.finger_width / 2.0 + clearance
    centres = poses[:, :3, 3] + model.contact_depth * poses[:, :3, 1]
    pose, point = _neighbours(tree, centres, hand_reach(model) + 2.0 * max(clearance, 0.0))
    R, t = poses[pose, :3, :3], poses[pose, :3, 3]
    local = np.einsum("eki,ek->ei", R, pts[point] - t)
    gx, gy, gz = local[:, 0], local[:, 1], local[:, 2]
    in_palm = (
        (gx > palm_lo[0])
        & (gx < palm_hi[0])
        & (gy > palm_lo[1])
        & (gy < palm_hi[1])
        & (gz > palm_lo[2])
        & (gz < palm_hi[2])
    )
    foot = (gy >= model.palm_depth - clearance) & (gy <= model.finger_tip + clearance)
    foot &= np.abs(gz) <= half_z
    finger0 = (gx > contact_x[pose, 0] + tolerance) & (gx <= outer)
    finger1 = (gx < contact_x[pose, 1] - tolerance) & (gx >= -outer)
    hit = in_palm | (foot & (finger0 | finger1))
    return np.bincount(pose[hit], minlength=len(poses)) > 0


def _on_pads(local_contacts: np.ndarray, model: GripperModel, margin: float) -> np.ndarray:
    """(N,) whether both contacts (N, 2, 3) (grasp frame, m) lie on their pads."""
    y, z = local_contacts[..., 1], local_contacts[..., 2]
    ok = (y >= model.palm_depth + margin) & (y <= model.finger_tip - margin)
    ok &= np.abs(z) <= model.finger_width / 2.0 - margin
    return ok.all(axis=-1)


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
        :class:`~dataset_gen.sampling.SingleArmGrasps` (M <= ``max_grasps``) whose
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


@dataclass(frozen=True)
class DepthViews:
    """What depth cameras saw, to tell space seen empty from space no camera saw into.

    Attributes:
        origins: (C, 3) camera positions (m, object frame).
        axes: (C, 3, 3) each camera's unit ``right``, ``up`` and ``forward`` axes (rows).
        tan_half: tangent of half the (square) field of view.
        distance: (C, R, R) float64 distance (m) from the camera to the first surface along
            each pixel's ray through its centre (row 0 at the top, column 0 at the left);
            ``inf`` where the ray hit nothing.
    """

    origins: np.ndarray
    axes: np.ndarray
    tan_half: float
    distance: np.ndarray

    @property
    def resolution(self) -> int:
        """Image side R (pixels)."""
        return int(self.distance.shape[-1])

    def seen_free(self, points: np.ndarray, margin: float) -> np.ndarray:
        """(Q,) bool: each of ``points`` (Q, 3) (m) lies in a camera's image at least ``margin``
        (m) in front of the surface its pixel saw (or where it saw nothing). A point no camera
        sees, or that every camera sees behind a surface, is not known to be free."""
        return self.occlusion_depth(points) < -margin

    def occlusion_depth(self, points: np.ndarray) -> np.ndarray:
        """(Q,) float64: for each of ``points`` (Q, 3) (m), the least over the cameras whose
        image holds it of (its distance from the camera - the distance its pixel saw): negative
        in front of the seen surface, positive behind it; ``-inf`` where a pixel saw nothing (seen
        empty), ``+inf`` where no image holds the point."""
        points = np.asarray(points, dtype=np.float64)
        rel = points[None, :, :] - self.origins[:, None, :]  # (C, Q, 3)
        cam = np.einsum("cij,cqj->cqi", self.axes, rel)
        forward = cam[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = cam[..., 0] / (forward * self.tan_half)
            v = cam[..., 1] / (forward * self.tan_half)
        r = self.resolution
        in_view = (forward > 0.0) & (np.abs(u) < 1.0) & (np.abs(v) < 1.0)
        col = np.clip(np.floor((np.where(in_view, u, 0.0) + 1.0) * r / 2.0), 0, r - 1)
        row = np.clip(np.floor((1.0 - np.where(in_view, v, 0.0)) * r / 2.0), 0, r - 1)
        camera = np.broadcast_to(np.arange(len(self.origins))[:, None], col.shape)
        seen = self.distance[camera, row.astype(np.int64), col.astype(np.int64)]
        with np.errstate(invalid="ignore"):
            depth = np.where(in_view, np.linalg.norm(rel, axis=-1) - seen, np.inf)
        return depth.min(axis=0)


def hand_volume_points(model: GripperModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points filling the open hand (grasp frame, m): ``palm (6 * 4 * 4, 3)``, ``finger 0
    (3 * 5 * 3, 3)`` and ``finger 1``, a grid over each collision box with its faces (the
    boxes of :meth:`~dataset_gen.gripper.GripperModel.collision_boxes` at full opening)."""

    def grid(box: Box, counts: tuple[int, int, int]) -> np.ndarray:
        lo = np.asarray(box.center) - np.asarray(box.half_extents)
        hi = np.asarray(box.center) + np.asarray(box.half_extents)
        axes = [np.linspace(lo[k], hi[k], counts[k]) for k in range(3)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)

    palm, finger0, finger1 = model.collision_boxes(None)
    return grid(palm, (6, 4, 4)), grid(finger0, (3, 5, 3)), grid(finger1, (3, 5, 3))


def hand_volume_in_object(poses: np.ndarray, model: GripperModel) -> np.ndarray:
    """(N, Q, 3) the points of :func:`hand_volume_points` (palm, finger 0, finger 1 in that
    order) of each open hand at ``poses`` (N, 4, 4), in the object frame (m)."""
    local = np.concatenate(hand_volume_points(model))
    return np.einsum("nij,qj->nqi", poses[:, :3, :3], local) + poses[:, None, :3, 3]


def hands_in_seen_free_space(
    views: DepthViews,
    poses: np.ndarray,
    model: GripperModel,
    margin: float,
    skip_finger: np.ndarray | None = None,
) -> np.ndarray:
    """(N,) bool: every point of each open hand (:func:`hand_volume_points`) at ``poses``
    (N, 4, 4) is seen free (:meth:`DepthViews.seen_free`).

    ``skip_finger`` (N, 2) bool leaves out finger 0's / finger 1's volume: that of a finger
    whose contact face was not seen and is assumed to face it (an enclosing grasp), so the
    space beyond that face is assumed empty too."""
    poses = np.asarray(poses, dtype=np.float64)
    n = len(poses)
    if n == 0:
        return np.zeros(0, dtype=bool)
    palm, finger0, finger1 = hand_volume_points(model)
    part = np.repeat([0, 1, 2], [len(palm), len(finger0), len(finger1)])
    world = hand_volume_in_object(poses, model)
    free = views.seen_free(world.reshape(-1, 3), margin).reshape(n, len(part))
    if skip_finger is not None:
        skip = np.asarray(skip_finger, dtype=bool)
        free |= (part[None, :] == 1) & skip[:, :1]
        free |= (part[None, :] == 2) & skip[:, 1:]
    return free.all(axis=1)


MAX_BACK_FACING = 0.5
"""An enclosing grasp's contact is refused when its normal points back towards the other finger
by more than this cosine (``n0 . x < -MAX_BACK_FACING`` for finger 0 at ``+x``): the part then
goes on, unseen, past where the finger would close."""


def _grouped_extremes(
    group: np.ndarray, value: np.ndarray, n_groups: int
) -> tuple[np.ndarray, ...]:
    """Per group ``g`` of the entries (``group`` (E,) int, ``value`` (E,) float): the entry
    index of the largest and of the smallest value (-1 for an empty group) and the group size."""
    size = np.bincount(group, minlength=n_groups)
    top = np.full(n_groups, -1, dtype=np.int64)
    bottom = np.full(n_groups, -1, dtype=np.int64)
    if len(group):
        order = np.lexsort((value, group))  # by group, then value ascending
        g = group[order]
        first = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
        last = np.r_[first[1:] - 1, len(g) - 1]
        bottom[g[first]] = order[first]
        top[g[last]] = order[last]
    return top, bottom, size


def enclosing_poses(
    points: np.ndarray, normals: np.ndarray, angles: np.ndarray, reach: float, model: GripperModel
) -> np.ndarray:
    """Hand poses approaching each point against its normal (step 5 of the module docstring).

    Args:
        points: (S, 3) approached points (m). normals: (S, 3) their unit outward normals.
        angles: (S, A) closing-axis angles (rad) about the approach, measured from the first
            vector of :func:`dataset_gen.sampling._tangent_basis` of the approach.
        reach: how far the fingertips pass the point along the approach (m).
        model: the gripper.

    Returns:
        (S, A, 4, 4) poses (grasp frame -> object frame, m): ``y = -normal``, ``x`` the closing
        axis, the point at ``(0, finger_tip - reach, 0)`` in the grasp frame.
    """
    y = -normals
    b1, b2 = _tangent_basis(y)
    c, s = np.cos(angles)[..., None], np.sin(angles)[..., None]
    x = c * b1[:, None, :] + s * b2[:, None, :]
    z = np.cross(x, np.broadcast_to(y[:, None, :], x.shape))
    poses = np.zeros((*angles.shape, 4, 4))
    poses[..., :3, 0] = x
    poses[..., :3, 1] = y[:, None, :]
    poses[..., :3, 2] = z
    poses[..., :3, 3] = points[:, None, :] - (model.finger_tip - reach) * y[:, None, :]
    poses[..., 3, 3] = 1.0
    return poses


def enclose(
    cloud: Cloud, poses: np.ndarray, model: GripperModel, *, pad_margin: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """What each hand pose's closing jaws would hold (step 6): the cloud points between its open
    fingers, ``palm_depth <= y <= finger_tip``, ``|z| <= finger_width / 2 - pad_margin``,
    ``|x| <= max_opening / 2`` in the grasp frame; the first contact of each finger is the
    held point farthest along ``+x`` (finger 0) and along ``-x`` (finger 1).

    Args:
        cloud: the cloud.
        poses: (N, 4, 4) hand poses (m).
        model: the gripper.
        pad_margin: the held region is this much narrower than the pads (m).

    Returns:
        ``index (N, 2)`` int64 cloud indices of the two contacts (-1 when the pose holds fewer
        than two points) and ``local_x (N, 2)`` their ``x`` in the pose's frame (m).
    """
    n = len(poses)
    half_x = model.max_opening / 2.0
    half_z = model.finger_width / 2.0 - pad_margin
    mid = 0.5 * (model.palm_depth + model.finger_tip)
    radius = math.sqrt(half_x**2 + (0.5 * (model.finger_tip - model.palm_depth)) ** 2 + half_z**2)
    centres = poses[:, :3, 3] + mid * poses[:, :3, 1]
    pose, point = _neighbours(cloud.tree, centres, radius)
    local = np.einsum("eki,ek->ei", poses[pose, :3, :3], cloud.points[point] - poses[pose, :3, 3])
    held = (
        (local[:, 1] >= model.palm_depth)
        & (local[:, 1] <= model.finger_tip)
        & (np.abs(local[:, 2]) <= half_z)
        & (np.abs(local[:, 0]) <= half_x)
    )
    pose, point, gx = pose[held], point[held], local[held, 0]
    top, bottom, size = _grouped_extremes(pose, gx, n)
    index = np.full((n, 2), -1, dtype=np.int64)
    local_x = np.zeros((n, 2))
    ok = size >= 2
    index[ok, 0], index[ok, 1] = point[top[ok]], point[bottom[ok]]
    local_x[ok, 0], local_x[ok, 1] = gx[top[ok]], gx[bottom[ok]]
    return index, local_x


def sample_enclosing_grasps(
    cloud: Cloud,
    config: CloudSamplerConfig,
    rng: np.random.Generator,
    counts: dict[str, int] | None = None,
    views: DepthViews | None = None,
) -> SingleArmGrasps:
    """Single-arm enclosing grasps on a cloud (steps 5-7 of the module docstring).

    Args:
        cloud: the cloud.
        config: the parameters (``n_enclosing_seeds``, ``n_closing``, ``enclosing_reach``).
        rng: draws the seeds, then the closing-axis offsets.
        counts: receives ``enclosing_seeds``, ``enclosing_poses``, ``enclosing_held`` (poses whose
            jaws hold a part within the opening), ``enclosing_collision_free``, with ``views``
            ``enclosing_unseen_space``, and ``enclosing_grasps``.
        views: as for :func:`sample_cloud_grasps`; the volume of a finger whose contact face was
            not seen is not tested (the face is assumed to face the finger, the space beyond it
            to be empty).

    Returns:
        :class:`~dataset_gen.sampling.SingleArmGrasps` (at most one per seed, its narrowest
        collision-free closing axis; at most ``max_grasps``); ``face_ids`` are the contacts'
        cloud indices; a contact normal is the cloud's where it lies in the friction cone about
        the closing axis, else the closing axis itself (the face the finger meets was not seen:
        it is assumed to face the finger).
    """
    model = get_gripper(config.gripper)
    counts = {} if counts is None else counts
    n_seeds = min(config.n_enclosing_seeds, cloud.n)
    seeds = rng.choice(cloud.n, size=n_seeds, replace=False)
    step = np.pi / config.n_closing
    angles = rng.random(n_seeds)[:, None] * step + step * np.arange(config.n_closing)
    poses = enclosing_poses(
        cloud.points[seeds], cloud.normals[seeds], angles, config.enclosing_reach, model
    ).reshape(-1, 4, 4)
    counts["enclosing_seeds"] = n_seeds
    counts["enclosing_poses"] = len(poses)
    index, local_x = enclose(cloud, poses, model, pad_margin=config.pad_margin)
    width = local_x[:, 0] - local_x[:, 1]
    x_axis = poses[:, :3, 0]
    n0 = cloud.normals[np.maximum(index[:, 0], 0)]
    n1 = cloud.normals[np.maximum(index[:, 1], 0)]
    facing0 = np.einsum("nk,nk->n", n0, x_axis)
    facing1 = -np.einsum("nk,nk->n", n1, x_axis)
    ok = (index[:, 0] >= 0) & (width > config.min_width) & (width <= config.max_width(model))
    ok &= (facing0 >= -MAX_BACK_FACING) & (facing1 >= -MAX_BACK_FACING)
    # At least one contact on a face seen to face its finger (within the friction cone about the
    # closing axis): jaws that would close on nothing but assumed faces were, on 60 procedural
    # objects, in the object at the start 48 times in 121 (30 in 483 with one face seen).
    cos_cone = math.cos(math.atan(config.mu))
    assumed_face = np.stack([facing0 < cos_cone, facing1 < cos_cone], axis=1)  # (N, 2)
    ok &= ~assumed_face.all(axis=1)
    # A held point at the edge of the opening: the part goes on past the open finger (the
    # collision test below would find it; this is the cheap test first).
    clearance = config.clearance_factor * cloud.spacing
    edge = model.max_opening / 2.0 - max(clearance, config.tolerance) - cloud.spacing
    ok &= (local_x[:, 0] < edge) & (local_x[:, 1] > -edge)
    counts["enclosing_held"] = int(ok.sum())
    centred = poses.copy()
    centred[:, :3, 3] += 0.5 * (local_x[:, 0] + local_x[:, 1])[:, None] * x_axis
    half = 0.5 * width
    rows = np.flatnonzero(ok)
    free = ~hand_hits_cloud(
        cloud,
        centred[rows],
        np.stack([half[rows], -half[rows]], axis=1),
        model,
        config.tolerance,
        clearance,
    )
    ok[rows] = free
    counts["enclosing_collision_free"] = int(ok.sum())
    if views is not None:
        rows = np.flatnonzero(ok)
        skip = assumed_face[rows] | (not config.free_space_fingers)
        ok[rows] = hands_in_seen_free_space(
            views, centred[rows], model, config.free_space_margin, skip
        )
        counts["enclosing_unseen_space"] = len(rows) - int(ok[rows].sum())
    per_seed = ok.reshape(n_seeds, config.n_closing)
    narrowest = np.argmin(np.where(ok, width, np.inf).reshape(n_seeds, -1), axis=1)
    keep = np.flatnonzero(per_seed.any(axis=1))[: config.max_grasps]
    chosen = keep * config.n_closing + narrowest[keep]
    counts["enclosing_grasps"] = len(chosen)
    x_chosen = x_axis[chosen]
    normals = np.stack([n0[chosen], n1[chosen]], axis=1)
    assumed = np.stack([x_chosen, -x_chosen], axis=1)
    normals = np.where(assumed_face[chosen][..., None], assumed, normals)
    return SingleArmGrasps(
        poses=centred[chosen].reshape(-1, 4, 4),
        contact_points=cloud.points[index[chosen]].reshape(-1, 2, 3),
        contact_normals=normals.reshape(-1, 2, 3),
        face_ids=index[chosen].reshape(-1, 2),
        widths=width[chosen],
        gripper=model.name,
        counts=dict(counts),
    )


def _concatenate(a: SingleArmGrasps, b: SingleArmGrasps) -> SingleArmGrasps:
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
        grasps = _concatenate(grasps, enclosing)
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
    "enclose",
    "enclosing_poses",
    "hand_hits_cloud",
    "hand_poses",
    "hand_reach",
    "hand_volume_in_object",
    "hand_volume_points",
    "hands_in_seen_free_space",
    "sample_cloud_grasps",
    "sample_enclosing_grasps",
]
