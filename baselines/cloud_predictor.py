"""Sample-and-rank dual-grasp predictors that see only a point cloud (issue 27).

A :class:`CloudPredictor` is a predictor ``observation -> (poses (K, 2, 4, 4), scores (K,))`` for
``dg16m evaluate --predictor`` (:mod:`dg16m_env.subjects.predictor`). Per object it

1. takes the cloud: ``view="full"`` the observation's own ``points`` / ``normals`` (2048 points on
   the whole surface); ``view="partial"`` what ``n_cameras`` seeded depth cameras see
   (:func:`camera_cloud`). Given the cloud track's observation (``dg16m evaluate --track cloud``,
   :mod:`dg16m_env.subjects.cloud_observation`: no mesh, the harness's depth cameras and noise),
   both views take ``n_points`` of its points and estimated normals (:func:`is_cloud_track`), and
   ``view="partial"`` its depth images as the depth views (:func:`depth_views`) instead of casting
   rays itself;
2. samples antipodal dual-grasp candidates on the cloud alone
   (:func:`baselines.cloud_grasps.cloud_dual_candidates`; at most ``sampler.max_pairs``); the
   partial-cloud predictors add enclosing grasps (:data:`PARTIAL_SAMPLER`: the hand approaches
   a point against its normal and closes on what lies between its fingers, so a board's edge
   can be held with its underside unseen); when none is found (thin walls, e.g. crates), once
   more with the hand's clearance set to 0. With ``free_space=True`` (not the default: it
   measured worse, ``baselines/RESULTS.md``) a partial view also keeps only hands that lie in
   space the cameras saw empty. With ``completion`` (a partial view; the ``*_completed``
   predictors) the cloud is first completed with the best-fitting shape of a library of
   training objects (:func:`baselines.shape_completion.complete_cloud`: the points no camera
   could see of a procedural training object fitted to the cloud), candidates are sampled on the
   completed cloud and checked against it, and each hand keeps at least one contact on a point
   the cameras saw (:func:`hands_with_seen_contacts`); step 4 then ranks candidates whose hands
   come within ``guessed_clearance`` of a guessed point after all others;
3. checks each candidate for force closure on the cloud's own contacts and normals
   (``force_closure=True``, the default: :func:`dataset_gen.grasps.pairing.score_pairs` with the
   paper's parameters, the check the dataset's labels come from) and ranks them:
   ``ranker="cgdf"`` / ``"pointnetgpd"`` by a trained classifier's logit
   (``baselines/checkpoints/<ranker>-dg16m.pt`` unless ``checkpoint`` names another file; the
   classifier is given the same cloud the candidates came from), ``"random"`` by seeded uniform
   scores (the random-rank control: the same candidates), ``"reversed"`` by the classifier's
   negated logit (a control for tests: it must do worse);
4. returns the ``k`` best with their scores: the candidates that pass the cloud check first,
   each group by descending ranker score (ties in candidate order). A returned score is the
   ranker's score plus :data:`FC_BONUS` for a passing candidate, so the scores order the grasps
   as they were ranked. With ``collision`` (a partial view; off by default, it measured no
   better, ``baselines/RESULTS.md``) a learned check (:mod:`baselines.hand_collision`) first
   ranks the candidates whose open hands likely start in unseen parts after all others
   (:data:`SAFE_BONUS`). With ``robust=True`` (the ``*_robust`` predictors) the passing
   candidates whose cloud contacts would also hold through the protocol's pushes and twists
   (:mod:`baselines.cloud_robust`, the generator's robust criterion with the centre of mass at
   the origin and the inertia of the cloud's hull) rank first within the passing group, then
   the nearly robust ones level by level (:data:`ROBUST_BONUS`).

No step reads the mesh except :func:`camera_views` (and :func:`camera_cloud`, which keeps
``n_points`` of its hits), which stands in for a depth camera on a mesh-track observation
(the ray casting is :func:`dg16m_env.subjects.cloud_observation.cast_view`, the cloud track's
own): it ray casts the observation's mesh from cameras placed as the environments place theirs
(:func:`dg16m_env.physics.cameras.draw_cameras` around the object's box: azimuth spread around,
elevation -70 to -15 degrees, distance 0.9-1.2 x 2.2 x the bounding radius; MuJoCo's default
45-degree field of view, ``camera_resolution`` square pixels) and keeps each pixel's first hit
with that face's outward normal, then ``n_points`` of them
(:func:`~dg16m_env.physics.cameras.fixed_size`). For procedural objects the mesh is the simulated geometry, so this is the
environments' ``obs_mode="partial"`` cloud up to the camera draw; it needs no OpenGL. One camera
never sees two antipodal contacts of a convex object, so the partial predictors default to two
cameras on roughly opposite sides (``MAX_CAMERAS`` of the environments).

Randomness: per object, ``numpy.random.default_rng(object_seed(seed, "cloud:<object_id>"))``
(:func:`dataset_gen.sources.object_source.object_seed`; a cloud-track observation has no id:
:func:`stream_name` names it by its depth images) draws the cameras, the cloud subset, the candidates and
(random ranker) the scores, in that order: the output is a function of the observation and the
parameters only. The same ``seed`` gives every ranker the same candidates.

An object without any candidate raises :class:`~baselines.cloud_grasps.CloudError`; the runner
records it and scores the object 0. torch is imported only by the classifier rankers, with
``torch.set_num_threads(threads)`` (default 1: one core); a loaded model is cached per process.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from baselines.cloud_grasps import (
    Cloud,
    CloudError,
    CloudSamplerConfig,
    DepthViews,
    DualCandidates,
    check_cloud,
    cloud_dual_candidates,
    hand_volume_in_object,
)
from baselines.cloud_robust import (
    MOTION_RATIO_LEVELS,
    candidates_robust_first,
    check_ratio_levels,
)
from baselines.shape_completion import (
    Completion,
    CompletionConfig,
    ShapeLibrary,
    complete_cloud,
    procedural_library,
)
from dataset_gen.grasps.gripper import get_gripper
from dataset_gen.grasps.pairing import score_pairs
from dataset_gen.sources.object_source import object_seed
from dg16m_core.checks import check_integer
from dg16m_core.parameters import PAPER
from dg16m_env.subjects.cloud_observation import (
    FOVY_DEG,
    camera_axes,
    camera_rays,
    cast_view,
    object_cameras,
)

Ranker = Literal["cgdf", "pointnetgpd", "random", "reversed"]
RANKERS: tuple[str, ...] = get_args(Ranker)
View = Literal["full", "partial"]
VIEWS: tuple[str, ...] = get_args(View)

CHECKPOINTS = Path(__file__).resolve().parent / "checkpoints"
"""The shipped classifier checkpoints (``<model>-<labels>.pt``)."""

PAPER_FORCE_CLOSURE = {
    "mass": PAPER.mass,
    "gravity": PAPER.gravity,
    "mu": PAPER.mu,
    "f_high": PAPER.f_high,
    "threshold": PAPER.threshold,
}
"""Keyword arguments of the cloud force-closure check (the paper's parameters)."""

SEED_PREFIX = "cloud:"
"""Prefix of the per-object stream name."""

FC_BONUS = 1.0e3
"""Added to the score of a candidate that passes the cloud force-closure check (ranker scores:
logits of a few tens at most, or uniform in [0, 1))."""

SAFE_BONUS = 2.0e3
"""Added to the score of a candidate whose start risk is at most ``max_start_risk`` (above
:data:`FC_BONUS`: the collision check orders first, then the force-closure check)."""

CLEAR_BONUS = 2.0e3
"""Added to the score of a candidate whose hands keep clear of a completion's guessed points
(above :data:`FC_BONUS`: the clearance orders first, then the force-closure check)."""

ROBUST_BONUS = 500.0
"""Added to the score of a candidate that passes the robust criterion on the cloud
(:mod:`baselines.cloud_robust`; a nearly robust one gains a share per level of
``motion_ratio_levels`` its ratio is within). Below :data:`FC_BONUS`, which every robust candidate
also has, and above the spread of ranker scores: the levels order first within their
force-closure group."""

HAND_COLLISION_CHECKPOINT = CHECKPOINTS / "hand-collision.pt"
"""The shipped hand-collision check (:mod:`baselines.train_hand_collision`)."""

_SCORE_CHUNK = 1024  # candidates per classifier call


# --------------------------------------------------------------------------------------------
# The partial cloud
# --------------------------------------------------------------------------------------------


def camera_views(
    observation: dict[str, Any],
    rng: np.random.Generator,
    *,
    n_cameras: int = 2,
    resolution: int = 128,
) -> tuple[np.ndarray, np.ndarray, DepthViews]:
    """Ray cast what ``n_cameras`` seeded depth cameras see of the observation's object.

    Args:
        observation: needs ``mesh_vertices`` (V, 3), ``mesh_faces`` (F, 3) and ``bounds`` (2, 3)
            (object frame, m).
        rng: draws the cameras (:func:`dg16m_env.physics.cameras.draw_cameras`).
        n_cameras: cameras (>= 1).
        resolution: image side (pixels).

    Returns:
        Every pixel's first hit: ``points (H, 3)`` and their faces' unit outward ``normals (H,
        3)`` (m, object frame), and the :class:`~baselines.cloud_grasps.DepthViews` (each
        pixel's distance to its hit, ``inf`` where it saw nothing).
    """
    check_integer("n_cameras", n_cameras, minimum=1, error=CloudError)
    check_integer("resolution", resolution, minimum=2, error=CloudError)
    missing = [k for k in ("mesh_vertices", "mesh_faces", "bounds") if k not in observation]
    if missing:
        raise CloudError(f"observation: expected keys {missing}, found {sorted(observation)}")
    mesh = trimesh.Trimesh(
        np.asarray(observation["mesh_vertices"], dtype=np.float64),
        np.asarray(observation["mesh_faces"], dtype=np.int64),
        process=False,
    )
    bounds = np.asarray(observation["bounds"], dtype=np.float64)
    points, normals, origins, axes, distances = [], [], [], [], []
    for pose in object_cameras(bounds, rng, n_cameras):
        origin = pose.position
        _, hit_face, ray, where = cast_view(mesh, pose, resolution)
        points.append(where)
        normals.append(mesh.face_normals[hit_face])
        distance = np.full(resolution * resolution, np.inf)
        distance[ray] = np.linalg.norm(where - origin, axis=1)
        origins.append(origin)
        axes.append(camera_axes(origin, np.asarray(pose.lookat)))
        distances.append(distance.reshape(resolution, resolution))
    views = DepthViews(
        origins=np.asarray(origins, dtype=np.float64),
        axes=np.asarray(axes),
        tan_half=math.tan(math.radians(FOVY_DEG) / 2.0),
        distance=np.asarray(distances),
    )
    return np.concatenate(points), np.concatenate(normals), views


def camera_cloud(
    observation: dict[str, Any],
    rng: np.random.Generator,
    *,
    n_cameras: int = 2,
    resolution: int = 128,
    n_points: int = 1024,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What ``n_cameras`` seeded depth cameras see of the observation's object
    (:func:`camera_views`), as a fixed-size cloud.

    Args:
        observation: needs ``mesh_vertices`` (V, 3), ``mesh_faces`` (F, 3) and ``bounds`` (2, 3)
            (object frame, m).
        rng: draws the cameras, then the subset of points.
        n_cameras: cameras (>= 1).
        resolution: image side (pixels).
        n_points: points returned.

    Returns:
        ``points (n_points, 3)``, ``normals (n_points, 3)`` float32 (unit outward) and ``mask
        (n_points,)`` float32 (1 = real, 0 = padding), as the environments' partial observation.
    """
    from dg16m_env.physics.cameras import fixed_size

    check_integer("n_points", n_points, minimum=1, error=CloudError)
    points, normals, _ = camera_views(observation, rng, n_cameras=n_cameras, resolution=resolution)
    return fixed_size(points, normals, n_points, rng)


def is_cloud_track(observation: dict[str, Any]) -> bool:
    """Whether ``observation`` is the cloud track's
    (:func:`dg16m_env.subjects.cloud_observation.cloud_observation`: depth images, no mesh)."""
    return "depth" in observation and "mesh_vertices" not in observation


def stream_name(observation: Any) -> str:
    """The name of an observation's random stream: its ``object_id``; for a cloud-track
    observation (no id), ``"depth-"`` and the first 16 hex digits of the sha256 of its depth
    images and camera poses (the same observation, the same stream)."""
    if isinstance(observation, dict) and is_cloud_track(observation):
        digest = hashlib.sha256()
        for key in ("depth", "camera_poses", "intrinsics"):
            digest.update(np.ascontiguousarray(observation[key], dtype=np.float64).tobytes())
        return "depth-" + digest.hexdigest()[:16]
    object_id = observation.get("object_id") if isinstance(observation, dict) else None
    if not isinstance(object_id, str) or not object_id:
        raise CloudError(f"observation object_id: expected a non-empty str, found {object_id!r}")
    return object_id


def depth_views(observation: dict[str, Any]) -> DepthViews:
    """The :class:`~baselines.cloud_grasps.DepthViews` of a cloud-track observation: camera
    positions and axes from ``camera_poses`` (OpenCV axes: x right, y down, z forward), each
    pixel's distance along its ray from ``depth`` (along the optical axis) and ``intrinsics``
    (``inf`` where the depth is 0).

    Raises:
        CloudError: images that are not square, or intrinsics other than a centred pinhole with
            square pixels (what :class:`~baselines.cloud_grasps.DepthViews` models).
    """
    depth = np.asarray(observation["depth"], dtype=np.float64)
    poses = np.asarray(observation["camera_poses"], dtype=np.float64)
    k = np.asarray(observation["intrinsics"], dtype=np.float64)
    if depth.ndim != 3 or depth.shape[1] != depth.shape[2] or poses.shape != (len(depth), 4, 4):
        raise CloudError(
            f"depth, camera_poses: expected (C, R, R) and (C, 4, 4), found {depth.shape} and "
            f"{poses.shape}"
        )
    r = depth.shape[-1]
    if k.shape != (3, 3) or not np.allclose([k[0, 0], k[0, 2], k[1, 2]], [k[1, 1], r / 2, r / 2]):
        raise CloudError(f"intrinsics: expected a centred pinhole with fx = fy, found {k.tolist()}")
    t = (np.arange(r) + 0.5 - r / 2.0) / k[0, 0]
    stretch = np.sqrt(1.0 + t[None, :] ** 2 + t[:, None] ** 2)  # ray length at unit depth
    rotation = poses[:, :3, :3]
    axes = np.stack([rotation[:, :, 0], -rotation[:, :, 1], rotation[:, :, 2]], axis=1)
    return DepthViews(
        origins=poses[:, :3, 3].copy(),
        axes=axes,
        tan_half=(r / 2.0) / float(k[0, 0]),
        distance=np.where(depth > 0.0, depth * stretch, np.inf),
    )


# --------------------------------------------------------------------------------------------
# Classifiers
# --------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=4)
def load_ranker(path: str, threads: int = 1) -> Any:
    """The classifier of a checkpoint (:func:`baselines.grasp_geometry.load_checkpoint`), on the
    CPU in eval mode, cached per process; sets ``torch.set_num_threads(threads)``."""
    import torch

    from baselines.grasp_geometry import load_checkpoint

    torch.set_num_threads(threads)
    model, _ = load_checkpoint(path)
    return model


def classifier_scores(model: Any, points: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(N,) float64 logits of ``model(points (P, 3), poses (N, 2, 4, 4))`` (m), in chunks."""
    import torch

    cloud = torch.from_numpy(np.ascontiguousarray(points, dtype=np.float32))
    out = []
    with torch.no_grad():
        for start in range(0, len(poses), _SCORE_CHUNK):
            chunk = np.ascontiguousarray(poses[start : start + _SCORE_CHUNK], dtype=np.float32)
            out.append(model(cloud, torch.from_numpy(chunk)).to(torch.float64).numpy())
    return np.concatenate(out) if out else np.zeros(0)


def cloud_force_closure(candidates: DualCandidates) -> np.ndarray:
    """(N,) bool: each candidate's four cloud contacts pass the force-closure check
    (:func:`dataset_gen.grasps.pairing.score_pairs`, the paper's mass, gravity, mu, f_high and
    threshold; the physical convention)."""
    if candidates.n == 0:
        return np.zeros(0, dtype=bool)
    verdict = score_pairs(candidates.grasps, candidates.pairs, **PAPER_FORCE_CLOSURE)
    return np.asarray(verdict.passed, dtype=bool)


def hands_with_seen_contacts(candidates: DualCandidates, n_observed: int) -> DualCandidates:
    """The candidates whose two hands each hold at least one contact on a seen point (cloud
    index below ``n_observed``: :attr:`~baselines.shape_completion.Completion.n_observed`); all of
    them when none does. ``counts["seen_contacts"]`` says how many passed."""
    if candidates.n == 0:
        return candidates
    seen = np.asarray(candidates.grasps.face_ids) < n_observed  # (M, 2)
    keep = seen[candidates.pairs[:, 0]].any(axis=1) & seen[candidates.pairs[:, 1]].any(axis=1)
    counts = dict(candidates.counts, seen_contacts=int(keep.sum()))
    if not keep.any():
        return dataclasses.replace(candidates, counts=counts)
    return DualCandidates(
        candidates.grasps,
        candidates.pairs[keep],
        candidates.poses[keep],
        candidates.contact_points[keep],
        candidates.contact_normals[keep],
        counts,
    )


@functools.lru_cache(maxsize=4)
def _load_library(path: str) -> ShapeLibrary:
    return ShapeLibrary.load(path)


# --------------------------------------------------------------------------------------------
# The predictor
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CloudPredictor:
    """A sample-and-rank predictor on a point cloud (see the module docstring).

    Attributes:
        ranker: ``"cgdf"``, ``"pointnetgpd"``, ``"random"`` or ``"reversed"`` (negated CGDF).
        view: ``"full"`` (the observation's cloud) or ``"partial"`` (:func:`camera_cloud`).
        k: dual grasps returned per object (fewer when there are fewer candidates).
        seed: global seed of the per-object streams.
        n_cameras, camera_resolution, n_points: the partial view (cameras, pixels, points).
        checkpoint: a classifier checkpoint file (default: the shipped ``<ranker>-dg16m.pt``;
            ``"reversed"`` uses CGDF's).
        threads: torch threads.
        force_closure: rank candidates that pass force closure on the cloud first.
        free_space: with ``view="partial"``, keep only hands whose open palm (and fingers,
            ``sampler.free_space_fingers``) lie in space the cameras saw empty
            (:func:`~baselines.cloud_grasps.hands_in_seen_free_space`); space behind what they
            saw may hold the part they did not see.
        sampler: the candidate sampler's parameters.
        collision: with ``view="partial"``, a hand-collision checkpoint
            (:mod:`baselines.hand_collision`; ``"shipped"``: :data:`HAND_COLLISION_CHECKPOINT`):
            candidates whose risk of an open hand starting in the object (``1 - (1 - p0)(1 -
            p1)``) exceeds ``max_start_risk`` are ranked after all others. ``None``: no check.
        max_start_risk: the largest risk of a candidate ranked first (in [0, 1]).
        completion: with ``view="partial"``, complete the cloud with the best-fitting shape of
            a library of training objects (:mod:`baselines.shape_completion`): ``"procedural"``
            (:func:`~baselines.shape_completion.procedural_library`) or the path of a saved
            :class:`~baselines.shape_completion.ShapeLibrary`. Candidates are sampled on, checked
            against and ranked with the completed cloud, and each hand must hold at least one
            contact the cameras saw (a hand on guessed points alone is a guess twice); when no
            candidate does, all are kept. ``None``: the cloud as seen.
        completion_config: the completion's parameters.
        guessed_clearance: with ``completion``, candidates whose open hands
            (:func:`~baselines.cloud_grasps.hand_volume_points`) come within this distance (m) of
            a guessed (added) point are ranked after all others (:data:`CLEAR_BONUS`): a fitted
            shape is right to a centimetre or two, not to the millimetre of a seen point.
        robust: rank the passing candidates by the robust criterion on the cloud
            (:mod:`baselines.cloud_robust`: the disturbance motion ratio under the protocol's
            pushes and twists, the inertia that of the cloud's hull at the paper's 6 kg) within
            their force-closure group: robust ones (ratio <= ``motion_ratio_levels[0]``) first,
            then level by level (:data:`ROBUST_BONUS` in all); the ranker orders each level.
            Needs ``force_closure``.
        motion_ratio_levels: ascending motion ratios (1: no protocol load, left unresisted,
            would move the object past the protocol's bounds).
    """

    ranker: Ranker = "cgdf"
    view: View = "full"
    k: int = 10
    seed: int = 0
    n_cameras: int = 2
    camera_resolution: int = 128
    n_points: int = 1024
    checkpoint: str | None = None
    threads: int = 1
    force_closure: bool = True
    free_space: bool = False
    sampler: CloudSamplerConfig = field(default_factory=CloudSamplerConfig)
    collision: str | None = None
    max_start_risk: float = 0.8
    completion: str | None = None
    completion_config: CompletionConfig = field(default_factory=CompletionConfig)
    guessed_clearance: float = 0.015
    robust: bool = False
    motion_ratio_levels: tuple[float, ...] = MOTION_RATIO_LEVELS

    def __post_init__(self) -> None:
        if self.ranker not in RANKERS:
            raise CloudError(f"ranker: expected one of {RANKERS}, found {self.ranker!r}")
        if self.view not in VIEWS:
            raise CloudError(f"view: expected one of {VIEWS}, found {self.view!r}")
        for name, minimum in (
            ("k", 1),
            ("seed", 0),
            ("n_cameras", 1),
            ("camera_resolution", 2),
            ("n_points", 1),
            ("threads", 1),
        ):
            check_integer(name, getattr(self, name), minimum=minimum, error=CloudError)
        if not (
            isinstance(self.max_start_risk, (int, float))
            and not isinstance(self.max_start_risk, bool)
            and 0.0 <= self.max_start_risk <= 1.0
        ):
            raise CloudError(
                f"max_start_risk: expected a number in [0, 1], found {self.max_start_risk!r}"
            )
        if self.collision is not None and self.view != "partial":
            raise CloudError(
                f"collision: expected None with view={self.view!r} (the check needs the depth "
                f"views of view='partial'), found {self.collision!r}"
            )
        if not (
            isinstance(self.guessed_clearance, (int, float))
            and not isinstance(self.guessed_clearance, bool)
            and 0.0 <= self.guessed_clearance < math.inf
        ):
            raise CloudError(
                f"guessed_clearance: expected a finite number >= 0 (m), found "
                f"{self.guessed_clearance!r}"
            )
        if self.completion is not None and self.view != "partial":
            raise CloudError(
                f"completion: expected None with view={self.view!r} (a full cloud has nothing "
                f"to complete), found {self.completion!r}"
            )
        if self.completion is not None and self.collision is not None:
            raise CloudError(
                f"collision: expected None with completion (the check was trained on clouds as "
                f"seen), found {self.collision!r}"
            )
        if not isinstance(self.robust, bool):
            raise CloudError(f"robust: expected a bool, found {self.robust!r}")
        check_ratio_levels(self.motion_ratio_levels)
        if self.robust and not self.force_closure:
            raise CloudError(
                "robust: expected force_closure=True (the robust criterion refines the "
                "force-closure check), found force_closure=False"
            )
        if not isinstance(self.completion_config, CompletionConfig):
            raise CloudError(
                f"completion_config: expected a CompletionConfig, found "
                f"{type(self.completion_config).__name__}"
            )
        if not isinstance(self.sampler, CloudSamplerConfig):
            raise CloudError(
                f"sampler: expected a CloudSamplerConfig, found {type(self.sampler).__name__}"
            )

    @property
    def name(self) -> str:
        """E.g. ``"cloud-cgdf-partial"``."""
        return f"cloud-{self.ranker}-{self.view}"

    def checkpoint_path(self) -> str:
        """The classifier checkpoint the ranker uses (a str path)."""
        if self.checkpoint is not None:
            return str(self.checkpoint)
        model = "cgdf" if self.ranker == "reversed" else self.ranker
        return str(CHECKPOINTS / f"{model}-dg16m.pt")

    def observe(
        self, observation: dict[str, Any], rng: np.random.Generator
    ) -> tuple[Cloud, DepthViews | None]:
        """The checked cloud of the configured view, and for ``view="partial"`` the depth
        views it came from (``None`` for the full cloud)."""
        from dg16m_env.physics.cameras import fixed_size

        if not isinstance(observation, dict):
            raise CloudError(f"observation: expected a dict, found {type(observation).__name__}")
        if is_cloud_track(observation):  # the harness's cameras: no mesh to cast rays on
            points, normals, mask = fixed_size(
                np.asarray(observation["points"]),
                np.asarray(observation["normals"]),
                self.n_points,
                rng,
            )
            views = depth_views(observation) if self.view == "partial" else None
            return check_cloud(points, normals, mask), views
        if self.view == "partial":
            points, normals, views = camera_views(
                observation, rng, n_cameras=self.n_cameras, resolution=self.camera_resolution
            )
            points, normals, mask = fixed_size(points, normals, self.n_points, rng)
            return check_cloud(points, normals, mask), views
        missing = [k for k in ("points", "normals") if k not in observation]
        if missing:
            raise CloudError(f"observation: expected keys {missing}, found {sorted(observation)}")
        return check_cloud(observation["points"], observation["normals"]), None

    def cloud(self, observation: dict[str, Any], rng: np.random.Generator) -> Cloud:
        """The checked cloud of the configured view."""
        return self.observe(observation, rng)[0]

    def shape_library(self) -> ShapeLibrary | None:
        """The completion's library (``None``: no completion), loaded once per process."""
        if self.completion is None:
            return None
        if self.completion == "procedural":
            return procedural_library()
        return _load_library(str(self.completion))

    def complete(
        self, cloud: Cloud, views: DepthViews | None
    ) -> tuple[Cloud, int, Completion | None]:
        """The cloud completed as configured, how many of its first points were seen, and the
        :class:`~baselines.shape_completion.Completion` (``None`` without completion)."""
        library = self.shape_library()
        if library is None or views is None:
            return cloud, cloud.n, None
        completion = complete_cloud(cloud, views, library, self.completion_config)
        return completion.cloud, completion.n_observed, completion

    def clear_of_guessed_points(self, cloud: Cloud, candidates: DualCandidates) -> np.ndarray:
        """(N,) bool: both open hands of each candidate stay ``guessed_clearance`` (m) away from
        the points a completion added (the last ``counts["completion_added"]`` of ``cloud``);
        all true without added points."""
        added = int(candidates.counts.get("completion_added", 0))
        if added == 0 or candidates.n == 0 or self.guessed_clearance == 0.0:
            return np.ones(candidates.n, dtype=bool)
        guessed = cKDTree(cloud.points[cloud.n - added :])
        volume = hand_volume_in_object(
            candidates.poses.reshape(-1, 4, 4), get_gripper(candidates.grasps.gripper)
        )  # (2N, Q, 3)
        distance, _ = guessed.query(
            volume.reshape(-1, 3), distance_upper_bound=self.guessed_clearance
        )
        near = np.isfinite(distance).reshape(candidates.n, -1)
        return ~near.any(axis=1)

    def collision_path(self) -> str | None:
        """The hand-collision checkpoint the predictor uses (``None``: no check)."""
        if self.collision == "shipped":
            return str(HAND_COLLISION_CHECKPOINT)
        return None if self.collision is None else str(self.collision)

    def candidates(
        self, observation: dict[str, Any]
    ) -> tuple[Cloud, DualCandidates, np.random.Generator]:
        """The cloud, its dual candidates and the object's stream after sampling."""
        cloud, cands, rng, _ = self.observed_candidates(observation)
        return cloud, cands, rng

    def observed_candidates(
        self, observation: dict[str, Any]
    ) -> tuple[Cloud, DualCandidates, np.random.Generator, DepthViews | None]:
        """:meth:`candidates` and the depth views of a partial view (``None`` for the full
        cloud)."""
        rng = np.random.default_rng(object_seed(self.seed, SEED_PREFIX + stream_name(observation)))
        cloud, views = self.observe(observation, rng)
        cloud, n_observed, completion = self.complete(cloud, views)
        free = views if self.free_space else None
        cands = cloud_dual_candidates(cloud, self.sampler, rng=rng, views=free)
        if cands.n == 0 and self.sampler.clearance_factor > 0.0:  # thin walls: no clearance
            relaxed = dataclasses.replace(self.sampler, clearance_factor=0.0)
            cands = cloud_dual_candidates(cloud, relaxed, rng=rng, views=free)
            cands.counts["clearance_relaxed"] = 1
        if completion is not None:
            cands.counts["completion_added"] = completion.added
            cands = hands_with_seen_contacts(cands, n_observed)
        return cloud, cands, rng, views

    def start_risk(self, cloud: Cloud, views: DepthViews, candidates: DualCandidates) -> np.ndarray:
        """(N,) probability that an open hand of each candidate starts in the object
        (:mod:`baselines.hand_collision`, the checkpoint of :meth:`collision_path`)."""
        from baselines.hand_collision import hand_features, load_hand_collision

        path = self.collision_path()
        if path is None or candidates.n == 0:
            return np.zeros(candidates.n)
        model = load_hand_collision(path)
        p = model.probability(hand_features(cloud, views, candidates.poses))
        return 1.0 - (1.0 - p[:, 0]) * (1.0 - p[:, 1])

    def rank(
        self, cloud: Cloud, candidates: DualCandidates, rng: np.random.Generator
    ) -> np.ndarray:
        """(N,) float64 scores of the candidates (higher = better)."""
        if self.ranker == "random":
            return rng.random(candidates.n)
        model = load_ranker(self.checkpoint_path(), self.threads)
        scores = classifier_scores(model, cloud.points, candidates.poses)
        return 0.0 - scores if self.ranker == "reversed" else scores

    def __call__(self, observation: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        """Predict: ``poses (K, 2, 4, 4)`` float64 (object frame, m), ``scores (K,)``, K <= k.

        Raises:
            CloudError: a malformed observation or cloud, or no candidate at all.
        """
        cloud, cands, rng, views = self.observed_candidates(observation)
        if cands.n == 0:
            raise CloudError(
                f"{stream_name(observation)}: expected at least one dual candidate on the "
                f"{self.view} cloud ({cloud.n} points), found none (counts: {cands.counts})"
            )
        scores = self.rank(cloud, cands, rng)
        if self.force_closure:
            passed = cloud_force_closure(cands)
            scores = scores + FC_BONUS * passed
        if self.completion is not None:
            scores = scores + CLEAR_BONUS * self.clear_of_guessed_points(cloud, cands)
        if views is not None and self.collision is not None:
            scores = scores + SAFE_BONUS * (
                self.start_risk(cloud, views, cands) <= self.max_start_risk
            )
        if self.robust:
            scores = candidates_robust_first(
                scores,
                passed,
                cands,
                cloud.points,
                k=self.k,
                bonus=ROBUST_BONUS,
                max_ratios=self.motion_ratio_levels,
            )
        top = np.argsort(-scores, kind="stable")[: self.k]
        return cands.poses[top].astype(np.float64), np.asarray(scores[top], dtype=np.float64)


cgdf_predictor = CloudPredictor("cgdf")
"""CGDF ranks candidates on the full cloud (``baselines.cloud_predictor:cgdf_predictor``)."""
pointnetgpd_predictor = CloudPredictor("pointnetgpd")
"""Dual-PointNetGPD ranks candidates on the full cloud."""
random_predictor = CloudPredictor("random")
"""The random-rank control on the full cloud (same candidates as the classifiers')."""
PARTIAL_SAMPLER = CloudSamplerConfig(enclosing=True)
"""The sampler of the partial-cloud predictors, with antipodal and enclosing grasps
(:func:`baselines.cloud_grasps.sample_enclosing_grasps`). A camera that looks down never sees an
underside, so two antipodal contacts are often not both seen."""
cgdf_partial_predictor = CloudPredictor(
    "cgdf", view="partial", n_points=4096, sampler=PARTIAL_SAMPLER
)
"""CGDF on what two seeded depth cameras see (4096 of their points)."""
pointnetgpd_partial_predictor = CloudPredictor(
    "pointnetgpd", view="partial", n_points=4096, sampler=PARTIAL_SAMPLER
)
"""Dual-PointNetGPD on what two seeded depth cameras see."""
random_partial_predictor = CloudPredictor(
    "random", view="partial", n_points=4096, sampler=PARTIAL_SAMPLER
)
"""The random-rank control on what two seeded depth cameras see."""
cgdf_completed_predictor = CloudPredictor(
    "cgdf", view="partial", n_points=4096, sampler=PARTIAL_SAMPLER, completion="procedural"
)
"""CGDF on what two seeded depth cameras see, completed with the best-fitting procedural training
object (:mod:`baselines.shape_completion`)."""
random_completed_predictor = CloudPredictor(
    "random", view="partial", n_points=4096, sampler=PARTIAL_SAMPLER, completion="procedural"
)
"""The random-rank control on the same completed two-camera candidates."""
cgdf_robust_predictor = CloudPredictor(
    "cgdf",
    view="partial",
    n_points=4096,
    sampler=PARTIAL_SAMPLER,
    completion="procedural",
    robust=True,
)
""":data:`cgdf_completed_predictor` with the robust criterion on the completed cloud
(:mod:`baselines.cloud_robust`): candidates whose contacts would hold through the protocol's
pushes and twists rank first, CGDF orders them."""
random_robust_predictor = CloudPredictor(
    "random",
    view="partial",
    n_points=4096,
    sampler=PARTIAL_SAMPLER,
    completion="procedural",
    robust=True,
)
"""The random-rank control of :data:`cgdf_robust_predictor`: the same candidates and the same
criteria, random order within each group."""


__all__ = [
    "CHECKPOINTS",
    "CLEAR_BONUS",
    "FC_BONUS",
    "FOVY_DEG",
    "HAND_COLLISION_CHECKPOINT",
    "PAPER_FORCE_CLOSURE",
    "PARTIAL_SAMPLER",
    "RANKERS",
    "ROBUST_BONUS",
    "SAFE_BONUS",
    "SEED_PREFIX",
    "VIEWS",
    "CloudPredictor",
    "Ranker",
    "View",
    "camera_axes",
    "camera_cloud",
    "camera_rays",
    "camera_views",
    "cgdf_completed_predictor",
    "cgdf_partial_predictor",
    "cgdf_predictor",
    "cgdf_robust_predictor",
    "classifier_scores",
    "cloud_force_closure",
    "depth_views",
    "hands_with_seen_contacts",
    "is_cloud_track",
    "load_ranker",
    "pointnetgpd_partial_predictor",
    "pointnetgpd_predictor",
    "random_completed_predictor",
    "random_partial_predictor",
    "random_predictor",
    "random_robust_predictor",
    "stream_name",
]
