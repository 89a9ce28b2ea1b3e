"""Complete a partial cloud with the best-fitting shape of a library of training objects (issue 27).

Two depth cameras that look down never see an object's underside, nor the parts behind other
parts. :func:`complete_cloud` guesses them from objects seen before, in the manner of
retrieval-based shape completion for grasping (Goldfeder & Allen, "Data-driven grasping with
partial sensor data", IROS 2009; Bohg et al., "Mind the gap", ICRA 2011, for the visibility test):

1. **Retrieve.** The :class:`ShapeLibrary` holds surface samples of training objects
   (:func:`procedural_library`: procedural training seeds, never a benchmark seed; or any meshes,
   :meth:`ShapeLibrary.from_meshes`). The ``config.shapes`` of them whose box is closest to the
   cloud's (in log size, about the vertical axis) are fitted.
2. **Fit** (:func:`fit_shape`). Each shape is turned about the vertical axis by each of
   ``config.yaws_deg``, scaled per axis so its box matches the cloud's (within the scale limits;
   the vertical scale is clipped harder, an underside may be unseen), placed with its top and its
   horizontal box centre on the cloud's, and moved by a few point-to-point ICP steps (translation
   only, point to plane). Its score is the mean distance from the cloud to the placed shape (clipped at
   :data:`FIT_CLIP`) over the cloud's spacing, plus ``config.violation_weight`` times the share of
   the placed shape's points that lie where the cameras saw empty space
   (:meth:`~baselines.cloud_grasps.DepthViews.seen_free`): a shape a camera would have seen but
   did not is wrong there. The lowest score wins, when it is at most ``config.max_score``.
3. **Complete.** The winner's points that no camera could have seen (behind a seen surface, or
   outside every image: :meth:`~baselines.cloud_grasps.DepthViews.occlusion_depth` beyond the
   margin) and that are not already near the cloud are added, with their normals (transformed
   as normals are, by the inverse transpose of the scaling).

The cloud's own points come first in the completed cloud, so ``Cloud.points[:n_observed]`` are
what the cameras saw. Everything is deterministic: the library's samples are seeded, the fit
draws nothing. Shapes: the library's arrays are ``(M, S, 3)`` (M shapes of S points, metres, each
in its own object frame, ``+z`` up).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from baselines.cloud_grasps import Cloud, CloudError, DepthViews, check_cloud
from dg16m_core.atomic import atomic_path
from dg16m_core.checks import check_integer

FIT_CLIP = 0.05
"""A cloud point's distance to the placed shape counts at most this much in the fit (m): a few
stray points (a part the library lacks) do not dominate the mean."""

BOX_QUANTILE = 0.002
"""The quantile of a cloud's box corners (:func:`cloud_box`)."""

LIBRARY_FORMAT = "dg16m-shape-library"
"""The ``format`` entry of a saved library (:meth:`ShapeLibrary.save`)."""


@dataclass(frozen=True)
class ShapeLibrary:
    """Surface samples of known objects, each in its own object frame (``+z`` up).

    Attributes:
        ids: the M shapes' names.
        points: (M, S, 3) float64 surface points (m), area-uniform.
        normals: (M, S, 3) float64 unit outward normals at ``points``.
    """

    ids: tuple[str, ...]
    points: np.ndarray
    normals: np.ndarray

    def __post_init__(self) -> None:
        points = np.asarray(self.points)
        if points.ndim != 3 or points.shape[-1] != 3 or points.shape[0] != len(self.ids):
            raise CloudError(
                f"library points: expected shape ({len(self.ids)}, S, 3), found {points.shape}"
            )
        if np.asarray(self.normals).shape != points.shape:
            raise CloudError(
                f"library normals: expected shape {points.shape}, found "
                f"{np.asarray(self.normals).shape}"
            )
        if points.shape[0] == 0 or points.shape[1] < 16:
            raise CloudError(
                f"library: expected at least one shape of at least 16 points, found {points.shape}"
            )
        if not (np.isfinite(points).all() and np.isfinite(self.normals).all()):
            raise CloudError("library: expected finite points and normals, found NaN or inf")

    @property
    def n(self) -> int:
        """Number of shapes M."""
        return len(self.ids)

    @functools.cached_property
    def extents(self) -> np.ndarray:
        """(M, 3) each shape's box size (m)."""
        return self.points.max(axis=1) - self.points.min(axis=1)

    @classmethod
    def from_meshes(
        cls, meshes: Sequence[tuple[str, object]], *, n_points: int = 2048, seed: int = 0
    ) -> ShapeLibrary:
        """A library of ``(name, trimesh.Trimesh)`` pairs, each sampled with ``n_points``
        area-uniform points (:func:`dg16m_env.subjects.observation.surface_points`, stream seeded by
        ``seed`` and the shape's position in the list)."""
        from dg16m_env.subjects.observation import surface_points

        check_integer("n_points", n_points, minimum=16, error=CloudError)
        ids, points, normals = [], [], []
        for i, (name, mesh) in enumerate(meshes):
            vertices = np.asarray(getattr(mesh, "vertices", None), dtype=np.float64)
            faces = np.asarray(getattr(mesh, "faces", None), dtype=np.int64)
            if vertices.ndim != 2 or faces.ndim != 2 or len(faces) == 0:
                raise CloudError(f"library mesh {name!r}: expected a triangle mesh, found none")
            p, n = surface_points(vertices, faces, n_points, np.random.default_rng([seed, i]))
            ids.append(str(name))
            points.append(p)
            normals.append(n)
        if not ids:
            raise CloudError("library: expected at least one mesh, found none")
        return cls(tuple(ids), np.stack(points), np.stack(normals))

    def save(self, path: str | Path) -> Path:
        """Write the library to an ``.npz`` file (atomically); :meth:`load` reads it."""
        path = Path(path)
        with atomic_path(path) as tmp, open(tmp, "wb") as handle:
            np.savez_compressed(
                handle,
                format=np.array(LIBRARY_FORMAT),
                ids=np.array(self.ids),
                points=self.points.astype(np.float32),
                normals=self.normals.astype(np.float32),
            )
        return path

    @classmethod
    def load(cls, path: str | Path) -> ShapeLibrary:
        """Read a library written by :meth:`save`.

        Raises:
            CloudError: not such a file (missing, unreadable, other keys or format).
        """
        try:
            with np.load(Path(path), allow_pickle=False) as data:
                kind = str(data["format"]) if "format" in data.files else None
                if kind != LIBRARY_FORMAT:
                    raise CloudError(
                        f"{path}: expected a shape library (format {LIBRARY_FORMAT!r}), found "
                        f"{'no format entry' if kind is None else repr(kind)}"
                    )
                ids = tuple(str(i) for i in data["ids"])
                points = np.asarray(data["points"], dtype=np.float64)
                normals = np.asarray(data["normals"], dtype=np.float64)
        except (OSError, ValueError, KeyError) as exc:
            raise CloudError(f"{path}: expected a readable shape library, found {exc}") from None
        return cls(ids, points, normals)


@functools.lru_cache(maxsize=4)
def procedural_library(per_family: int = 20, n_points: int = 2048, seed: int = 0) -> ShapeLibrary:
    """The library of procedural training objects: seeds ``0 .. per_family - 1`` of each of the
    benchmark's families (:mod:`dataset_gen.sources.procedural`; train seeds only, never a benchmark
    seed), each in its observation frame (:func:`dg16m_env.subjects.observation.object_observation`),
    built once per process (about 0.03 s per shape)."""
    from dataset_gen.sources.procedural import (
        FAMILIES,
        N_BENCHMARK_FAMILIES,
        make_procedural_object,
        split_of,
    )

    check_integer("per_family", per_family, minimum=1, error=CloudError)
    meshes = []
    for family in FAMILIES[:N_BENCHMARK_FAMILIES]:
        for object_seed_ in range(per_family):
            if split_of(family, object_seed_) != "train":
                raise CloudError(f"library: expected train seeds, found {family} {object_seed_}")
            obj = make_procedural_object(family, object_seed_)
            meshes.append((obj.object_id, obj.mesh))
    return ShapeLibrary.from_meshes(meshes, n_points=n_points, seed=seed)


@dataclass(frozen=True)
class CompletionConfig:
    """Parameters of :func:`fit_shape` and :func:`complete_cloud` (SI units).

    Attributes:
        shapes: library shapes fitted (those with the closest boxes).
        yaws_deg: turns about ``+z`` tried per shape (degrees).
        xy_scale: limits of the horizontal scale factors (a shape outside is not tried).
        z_scale: limits of the vertical scale factor (outside: not tried) and ``z_clip`` the range
            it is then clipped to (the cloud's height may miss an unseen bottom).
        icp_steps: translation-only ICP steps.
        fit_points: cloud points the fit uses (every k-th point).
        violation_weight: weight of the share of shape points in seen-empty space in the score.
        max_score: the largest score accepted (``inf``: any fit).
        margin_spacings: the visibility margin in cloud spacings (at least ``min_margin`` m).
        new_point_spacings: a shape point is added only when farther than this many cloud
            spacings from every cloud point.
    """

    shapes: int = 12
    yaws_deg: tuple[float, ...] = (0.0, 90.0, 180.0, 270.0)
    xy_scale: tuple[float, float] = (0.7, 1.4)
    z_scale: tuple[float, float] = (0.5, 1.4)
    z_clip: tuple[float, float] = (0.8, 1.25)
    icp_steps: int = 8
    fit_points: int = 400
    violation_weight: float = 10.0
    max_score: float = math.inf
    margin_spacings: float = 2.0
    min_margin: float = 0.01
    new_point_spacings: float = 2.0

    def __post_init__(self) -> None:
        for name in ("shapes", "icp_steps", "fit_points"):
            check_integer(name, getattr(self, name), minimum=1, error=CloudError)
        if not self.yaws_deg or not all(math.isfinite(y) for y in self.yaws_deg):
            raise CloudError(f"yaws_deg: expected finite angles, found {self.yaws_deg!r}")
        for name in ("xy_scale", "z_scale", "z_clip"):
            lo, hi = getattr(self, name)
            if not (0.0 < lo <= hi and math.isfinite(hi)):
                raise CloudError(f"{name}: expected 0 < low <= high, found {(lo, hi)!r}")
        for name in ("violation_weight", "margin_spacings", "min_margin", "new_point_spacings"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise CloudError(f"{name}: expected a finite number >= 0, found {value!r}")
        if not self.max_score > 0.0:
            raise CloudError(f"max_score: expected a number > 0, found {self.max_score!r}")


@dataclass(frozen=True)
class ShapeFit:
    """A library shape placed on a cloud: ``x_cloud = scale * (R(yaw) x_shape - centre) + t``.

    Attributes:
        index: the shape's row in the library; ``shape_id`` its name.
        yaw_deg: its turn about ``+z`` (degrees).
        scale: (3,) per-axis scale factors (after the turn).
        centre: (3,) the turned shape's box centre (m), subtracted before scaling.
        translation: (3,) the placement (m).
        fit: mean clipped distance from the cloud to the placed shape (m).
        violation: share of the placed shape's points in seen-empty space.
        score: ``fit / spacing + violation_weight * violation``.
    """

    index: int
    shape_id: str
    yaw_deg: float
    scale: np.ndarray
    centre: np.ndarray
    translation: np.ndarray
    fit: float
    violation: float
    score: float

    def place(self, library: ShapeLibrary) -> tuple[np.ndarray, np.ndarray]:
        """The placed shape: ``points (S, 3)`` (m) and unit ``normals (S, 3)``."""
        turn = yaw_matrix(self.yaw_deg)
        points = (library.points[self.index] @ turn.T - self.centre) * self.scale
        normals = (library.normals[self.index] @ turn.T) / self.scale
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        return points + self.translation, normals


@dataclass(frozen=True)
class Completion:
    """A completed cloud.

    Attributes:
        cloud: the cloud's own points first, then the added ones.
        n_observed: how many of ``cloud.points`` the cameras saw (the first ones).
        fit: the accepted shape fit (``None``: nothing fitted well enough, nothing added).
        counts: ``shapes_fitted``, ``placements`` (scale limits passed), ``added``.
    """

    cloud: Cloud
    n_observed: int
    fit: ShapeFit | None
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def added(self) -> int:
        """Points added to the cloud."""
        return self.cloud.n - self.n_observed


def yaw_matrix(yaw_deg: float) -> np.ndarray:
    """(3, 3) rotation by ``yaw_deg`` degrees about ``+z``."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def cloud_box(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The :data:`BOX_QUANTILE` and ``1 - BOX_QUANTILE`` corners (3,), (3,) of ``points`` (Q, 3)
    (m): a box that a few stray points do not widen."""
    low, high = np.quantile(points, [BOX_QUANTILE, 1.0 - BOX_QUANTILE], axis=0)
    return low, high


def _box_key(extent: np.ndarray) -> np.ndarray:
    """(..., 3) log of (longer horizontal side, shorter horizontal side, height): a box's size
    regardless of its turn about ``+z``."""
    e = np.maximum(extent, 1e-6)
    return np.log(
        np.stack(
            [np.maximum(e[..., 0], e[..., 1]), np.minimum(e[..., 0], e[..., 1]), e[..., 2]], -1
        )
    )


def _plane_step(
    tree: cKDTree, shape: np.ndarray, normals: np.ndarray, points: np.ndarray
) -> np.ndarray:
    """(3,) the translation of ``shape`` (S, 3) that best brings it onto ``points`` (Q, 3) in the
    point-to-plane sense (each point against the tangent plane of its nearest shape point, with
    ``normals`` (S, 3); far matches, beyond 5 median distances, left out), plus a small
    point-to-point term so that a direction no plane constrains stays put."""
    d, nearest = tree.query(points)
    inlier = d <= 5.0 * np.median(d) + 1e-9
    n = normals[nearest[inlier]]
    offset = points[inlier] - shape[nearest[inlier]]
    a = n.T @ n + 1e-3 * len(n) * np.eye(3)
    b = n.T @ np.einsum("ij,ij->i", n, offset) + 1e-3 * offset.sum(axis=0)
    return np.linalg.solve(a, b)


def margin_of(cloud: Cloud, config: CompletionConfig) -> float:
    """The visibility margin (m) for a cloud."""
    return max(config.margin_spacings * cloud.spacing, config.min_margin)


def fit_shape(
    cloud: Cloud,
    views: DepthViews,
    library: ShapeLibrary,
    config: CompletionConfig | None = None,
    counts: dict[str, int] | None = None,
) -> ShapeFit | None:
    """The best-scoring placement of a library shape on the cloud (steps 1-2 of the module
    docstring), or ``None`` when no shape passes the scale limits or ``config.max_score``."""
    config = CompletionConfig() if config is None else config
    counts = {} if counts is None else counts
    margin = margin_of(cloud, config)
    low, high = cloud_box(cloud.points)
    size = high - low
    distance = np.linalg.norm(_box_key(library.extents) - _box_key(size), axis=1)
    order = np.argsort(distance, kind="stable")[: config.shapes]
    sample = cloud.points[:: max(1, cloud.n // config.fit_points)]
    spacing = max(cloud.spacing, 1e-3)
    best: ShapeFit | None = None
    counts["shapes_fitted"] = len(order)
    counts["placements"] = 0
    for index in order:
        for yaw in config.yaws_deg:
            turned = library.points[index] @ yaw_matrix(yaw).T
            shape_low, shape_high = turned.min(axis=0), turned.max(axis=0)
            scale = size / np.maximum(shape_high - shape_low, 1e-6)
            lo_xy, hi_xy = config.xy_scale
            lo_z, hi_z = config.z_scale
            if (
                (scale[:2] < lo_xy).any()
                or (scale[:2] > hi_xy).any()
                or not lo_z <= scale[2] <= hi_z
            ):
                continue
            scale[2] = float(np.clip(scale[2], *config.z_clip))
            centre = (shape_low + shape_high) / 2.0
            placed = (turned - centre) * scale
            # horizontal box centres and tops together (a camera that looks down sees the top)
            translation = np.array(
                [(low[0] + high[0]) / 2.0, (low[1] + high[1]) / 2.0, high[2] - placed[:, 2].max()]
            )
            tree = cKDTree(placed)
            turned_normals = library.normals[index] @ yaw_matrix(yaw).T
            for _ in range(config.icp_steps):
                step = _plane_step(tree, placed, turned_normals, sample - translation)
                translation = translation + step
                if float(np.linalg.norm(step)) < 1e-4:
                    break
            d, _ = tree.query(sample - translation)
            fit = float(np.mean(np.minimum(d, FIT_CLIP)))
            violation = float(np.mean(views.seen_free(placed + translation, margin)))
            score = fit / spacing + config.violation_weight * violation
            counts["placements"] += 1
            if best is None or score < best.score:
                best = ShapeFit(
                    index=int(index),
                    shape_id=library.ids[index],
                    yaw_deg=float(yaw),
                    scale=scale,
                    centre=centre,
                    translation=translation,
                    fit=fit,
                    violation=violation,
                    score=score,
                )
    if best is None or best.score > config.max_score:
        return None
    return best


def complete_cloud(
    cloud: Cloud,
    views: DepthViews,
    library: ShapeLibrary,
    config: CompletionConfig | None = None,
) -> Completion:
    """The cloud with the unseen points of its best library fit added (module docstring).

    Args:
        cloud: what the cameras saw (:func:`~baselines.cloud_grasps.check_cloud`).
        views: the depth views it came from.
        library: the shapes to fit.
        config: the parameters (default :class:`CompletionConfig`).

    Returns:
        The :class:`Completion`; with no accepted fit, the cloud unchanged.
    """
    config = CompletionConfig() if config is None else config
    counts: dict[str, int] = {}
    fit = fit_shape(cloud, views, library, config, counts)
    counts["added"] = 0
    if fit is None:
        return Completion(cloud, cloud.n, None, counts)
    points, normals = fit.place(library)
    unseen = views.occlusion_depth(points) > margin_of(cloud, config)
    gap, _ = cloud.tree.query(points)
    new = unseen & (gap > config.new_point_spacings * cloud.spacing)
    counts["added"] = int(new.sum())
    if not new.any():
        return Completion(cloud, cloud.n, fit, counts)
    completed = check_cloud(
        np.concatenate([cloud.points, points[new]]), np.concatenate([cloud.normals, normals[new]])
    )
    return Completion(completed, cloud.n, fit, counts)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m baselines.shape_completion``: write a library of mesh files (e.g. the real
    benchmark's training split, from ``dg16m objects import-sweethome3d``) for
    ``CloudPredictor(completion=<file>)``."""
    import argparse

    import trimesh

    parser = argparse.ArgumentParser(description=main.__doc__.split("\n\n")[0])
    parser.add_argument("--meshes", type=Path, required=True, help="folder of <id>.obj files")
    parser.add_argument("--out", type=Path, required=True, help="the library (.npz) to write")
    parser.add_argument(
        "--real-train",
        action="store_true",
        help="only the training ids of the real split (dg16m_env/data/real_split.json)",
    )
    parser.add_argument("--points", type=int, default=2048, help="samples per shape (2048)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the samples (0)")
    args = parser.parse_args(argv)
    if args.real_train:
        from dg16m_env.benchmark.real import read_split

        names = [str(i) for i in read_split()["train"]]
        files = [args.meshes / f"{name}.obj" for name in names]
    else:
        files = sorted(args.meshes.glob("*.obj"))
    missing = [str(f) for f in files if not f.is_file()]
    if not files or missing:
        parser.exit(
            2,
            f"--meshes: expected {len(files) or 'some'} .obj files in {args.meshes}, found "
            f"{len(files) - len(missing)} (missing: {missing[:3]})\n",
        )
    meshes = [(f.stem, trimesh.load(f, force="mesh", process=False)) for f in files]
    library = ShapeLibrary.from_meshes(meshes, n_points=args.points, seed=args.seed)
    print(f"wrote {library.save(args.out)}: {library.n} shapes of {args.points} points")
    return 0


__all__ = [
    "BOX_QUANTILE",
    "FIT_CLIP",
    "LIBRARY_FORMAT",
    "Completion",
    "CompletionConfig",
    "ShapeFit",
    "ShapeLibrary",
    "cloud_box",
    "complete_cloud",
    "fit_shape",
    "margin_of",
    "procedural_library",
    "yaw_matrix",
]


if __name__ == "__main__":
    raise SystemExit(main())
