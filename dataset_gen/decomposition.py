"""Convex decomposition of meshes that have no convex parts (CoACD), cached on disk.

MuJoCo collides every mesh geom as its convex hull, so a non-convex object needs a convex
decomposition before it can be simulated (see DESIGN.md, "Simulation facts"). Procedural objects
carry their exact parts; loaded meshes do not, and CoACD takes 25-110 s per real mesh, so results
are cached by a digest of the mesh arrays, the parameters and the CoACD version.

Frames and units: the parts are in the mesh's own frame and units (for a
:class:`~dataset_gen.objects.GraspObject` that is the object frame, metres); every part is a
``ConvexPart(kind="mesh", pose=identity, vertices=hull_vertices)``.

Cache layout: ``<cache_dir>/<digest>.json``, written atomically, holding::

    {"format": "dg16m-coacd", "schema_version": 1, "digest": "<sha256 hex>",
     "parameters": {...DecompositionParameters...}, "coacd_version": "1.0.14",
     "parts": [ConvexPart.to_dict(), ...]}

A cache file that cannot be read, has another format, or does not match the request is ignored,
recomputed and overwritten.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from scipy.spatial import ConvexHull, QhullError

from dataset_gen.atomic import write_json_atomic
from dataset_gen.errors import MeshError
from dataset_gen.objects import ConvexPart, GraspObject, part_from_dict

CACHE_FORMAT = "dg16m-coacd"
"""Value of the ``"format"`` field of a cache file."""

CACHE_SCHEMA_VERSION = 1
"""Value of the ``"schema_version"`` field of a cache file."""

MIN_RELATIVE_HULL_VOLUME = 1e-9
"""Hulls with volume below this fraction of the mesh's bounding-box volume are dropped."""

_INSTALL_HINT = "convex decomposition needs the 'coacd' package; reinstall dg16m (pip install -e .)"


@dataclass(frozen=True)
class DecompositionParameters:
    """CoACD settings (the names follow ``coacd.run_coacd``; ``max_convex_hulls`` is its
    ``max_convex_hull``).

    Attributes:
        threshold: concavity threshold in (0, 1], relative to the mesh size; smaller gives more,
            tighter hulls. Thin features (handles, rims, slats) need a finer one (e.g. 0.02), or
            CoACD covers them and the gaps between them with one hull.
        max_convex_hulls: upper bound on the number of hulls after merging; -1 means no limit.
        preprocess_resolution: voxel resolution of the manifold pre-processing (cells per side).
        resolution: number of surface samples used to measure concavity.
        mcts_nodes: children per node of the Monte-Carlo tree search over cutting planes.
        mcts_iterations: search iterations per cut.
        mcts_max_depth: search depth (cuts looked ahead).
        seed: CoACD's random seed, in [0, 2**32); equal seeds give equal hulls.

    Raises:
        MeshError: a value of the wrong type or out of range.
    """

    threshold: float = 0.05
    max_convex_hulls: int = -1
    preprocess_resolution: int = 50
    resolution: int = 2000
    mcts_nodes: int = 20
    mcts_iterations: int = 150
    mcts_max_depth: int = 3
    seed: int = 0

    def __post_init__(self) -> None:
        threshold = self.threshold
        if isinstance(threshold, bool) or not isinstance(threshold, (int, float, np.number)):
            raise MeshError(f"threshold: expected a number in (0, 1], found {threshold!r}")
        threshold = float(threshold)
        if not (math.isfinite(threshold) and 0.0 < threshold <= 1.0):
            raise MeshError(f"threshold: expected a number in (0, 1], found {threshold!r}")
        object.__setattr__(self, "threshold", threshold)
        ranges = {
            "max_convex_hulls": (-1, None),
            "preprocess_resolution": (1, None),
            "resolution": (1, None),
            "mcts_nodes": (1, None),
            "mcts_iterations": (1, None),
            "mcts_max_depth": (1, None),
            "seed": (0, 2**32 - 1),
        }
        for name, (low, high) in ranges.items():
            value = getattr(self, name)
            wanted = f"an integer >= {low}" if high is None else f"an integer in [{low}, {high}]"
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise MeshError(f"{name}: expected {wanted}, found {value!r}")
            value = int(value)
            if value < low or (high is not None and value > high):
                raise MeshError(f"{name}: expected {wanted}, found {value}")
            object.__setattr__(self, name, value)
        if self.max_convex_hulls == 0:
            raise MeshError("max_convex_hulls: expected -1 (no limit) or at least 1, found 0")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready ``{field: value}``."""
        return dataclasses.asdict(self)

    def coacd_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for ``coacd.run_coacd``."""
        kwargs = self.to_dict()
        kwargs["max_convex_hull"] = kwargs.pop("max_convex_hulls")
        return kwargs


def _import_coacd() -> Any:
    """The ``coacd`` module, or an ImportError that says how to install it."""
    try:
        import coacd
    except ImportError as exc:
        raise ImportError(_INSTALL_HINT) from exc
    return coacd


def coacd_version() -> str:
    """The installed CoACD version (part of the cache key).

    Raises:
        ImportError: coacd is not installed.
    """
    from importlib import metadata

    try:
        return metadata.version("coacd")
    except metadata.PackageNotFoundError as exc:
        raise ImportError(_INSTALL_HINT) from exc


def mesh_digest(vertices: np.ndarray, faces: np.ndarray, params: DecompositionParameters) -> str:
    """The cache key of a decomposition: a sha256 hex digest (64 characters).

    Hashes the shapes and the bytes of ``vertices`` as little-endian float64 and ``faces`` as
    little-endian int64, the parameters as key-sorted JSON and the CoACD version.

    Args:
        vertices: (V, 3) coordinates (any unit; the digest changes with the frame and scale).
        faces: (F, 3) vertex indices.
        params: the CoACD settings.

    Raises:
        ImportError: coacd is not installed (its version is part of the key).
    """
    verts = np.ascontiguousarray(vertices, dtype="<f8")
    tris = np.ascontiguousarray(faces, dtype="<i8")
    header = {
        "vertices_shape": list(verts.shape),
        "faces_shape": list(tris.shape),
        "parameters": params.to_dict(),
        "coacd_version": coacd_version(),
    }
    digest = hashlib.sha256()
    digest.update(json.dumps(header, sort_keys=True).encode("utf-8"))
    digest.update(verts.tobytes())
    digest.update(tris.tobytes())
    return digest.hexdigest()


def default_cache_dir() -> Path:
    """Where decompositions are cached: ``$DG16M_CACHE_DIR/coacd`` when that is set, else
    ``$XDG_CACHE_HOME/dg16m/coacd`` (``~/.cache/dg16m/coacd`` when XDG_CACHE_HOME is unset)."""
    root = os.environ.get("DG16M_CACHE_DIR")
    if root:
        return Path(root).expanduser() / "coacd"
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "dg16m" / "coacd"


def _mesh_name(mesh: trimesh.Trimesh, name: str | None) -> str:
    if name:
        return name
    metadata = getattr(mesh, "metadata", None) or {}
    return str(metadata.get("file_name") or metadata.get("name") or "mesh")


def _check_mesh(mesh: Any, name: str | None) -> tuple[np.ndarray, np.ndarray, str]:
    """Validated ``(vertices (V, 3) float64, faces (F, 3) int64, name)``."""
    if not isinstance(mesh, trimesh.Trimesh):
        raise MeshError(
            f"{name or 'mesh'}: expected a trimesh.Trimesh, found {type(mesh).__name__}"
        )
    label = _mesh_name(mesh, name)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces)
    if len(vertices) == 0 or len(faces) == 0:
        raise MeshError(
            f"{label}: expected a triangle mesh, found {len(vertices)} vertices and "
            f"{len(faces)} faces"
        )
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise MeshError(f"{label}: expected (V, 3) vertices, found shape {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise MeshError(f"{label}: expected (F, 3) triangle faces, found shape {faces.shape}")
    if not np.all(np.isfinite(vertices)):
        bad = int((~np.isfinite(vertices)).any(axis=1).sum())
        raise MeshError(
            f"{label}: expected finite vertex coordinates, found {bad} vertices with NaN or inf"
        )
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise MeshError(
            f"{label}: expected face indices in [0, {len(vertices) - 1}], found indices from "
            f"{int(faces.min())} to {int(faces.max())}"
        )
    extent = float(np.max(np.ptp(vertices, axis=0)))
    if extent <= 0.0:
        raise MeshError(f"{label}: expected a mesh with extent, found all vertices at one point")
    return vertices, faces.astype(np.int64), label


def _hull_part(points: np.ndarray, min_volume: float) -> ConvexPart | None:
    """A mesh part of the hull's vertices, or ``None`` when the hull is degenerate."""
    points = np.unique(np.asarray(points, dtype=np.float64).reshape(-1, 3), axis=0)
    if len(points) < 4 or not np.all(np.isfinite(points)):
        return None
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):  # flat or collinear points
        return None
    if not hull.volume > min_volume:
        return None
    vertices = points[np.sort(hull.vertices)]
    if len(vertices) < 4:
        return None
    return ConvexPart(kind="mesh", pose=np.eye(4), vertices=vertices)


def _compute(
    vertices: np.ndarray, faces: np.ndarray, params: DecompositionParameters, label: str
) -> tuple[ConvexPart, ...]:
    coacd = _import_coacd()
    if hasattr(coacd, "set_log_level"):
        coacd.set_log_level("error")
    result = coacd.run_coacd(coacd.Mesh(vertices, faces.astype(np.int32)), **params.coacd_kwargs())
    box_volume = float(np.prod(np.ptp(vertices, axis=0)))
    min_volume = MIN_RELATIVE_HULL_VOLUME * box_volume
    parts = [_hull_part(hull_vertices, min_volume) for hull_vertices, _ in result]
    kept = tuple(part for part in parts if part is not None)
    if not kept:
        raise MeshError(
            f"{label}: expected CoACD to return at least one non-degenerate convex hull, "
            f"found {len(result)} hulls, all with fewer than 4 vertices or ~zero volume"
        )
    return kept


def _read_cache(
    path: Path, digest: str, params: DecompositionParameters, version: str
) -> tuple[ConvexPart, ...] | None:
    """The cached parts, or ``None`` when the file is missing, unreadable or does not match."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        if not (
            isinstance(data, dict)
            and data.get("format") == CACHE_FORMAT
            and data.get("schema_version") == CACHE_SCHEMA_VERSION
            and data.get("digest") == digest
            and data.get("parameters") == params.to_dict()
            and data.get("coacd_version") == version
            and isinstance(data.get("parts"), list)
            and data["parts"]
        ):
            return None
        parts = tuple(part_from_dict(item) for item in data["parts"])
    except (OSError, ValueError, TypeError, KeyError, AttributeError, RecursionError):
        # Missing, not UTF-8, not JSON, or malformed parts (MeshError is a ValueError).
        return None
    if not all(part.kind == "mesh" for part in parts):
        return None
    return parts


def convex_decomposition(
    mesh: trimesh.Trimesh,
    *,
    params: DecompositionParameters | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    use_cache: bool = True,
    name: str | None = None,
    stats: dict[str, Any] | None = None,
) -> tuple[ConvexPart, ...]:
    """Convex parts of ``mesh`` by CoACD, read from or written to the on-disk cache.

    Args:
        mesh: the triangle mesh; parts come out in its frame and units.
        params: CoACD settings (defaults: :class:`DecompositionParameters`).
        cache_dir: cache folder (default :func:`default_cache_dir`); created when missing.
        use_cache: ``False`` always computes and neither reads nor writes the cache.
        name: used in error messages (default: the mesh's ``file_name`` metadata, or "mesh").
        stats: when given, receives ``"cache_hit"`` (bool), ``"cache_path"`` (Path or None)
            and ``"seconds"`` (float, wall time of this call).

    Returns:
        One ``ConvexPart(kind="mesh", pose=identity, vertices=(V, 3) hull vertices)`` per hull,
        in CoACD's order; hulls with fewer than 4 vertices or ~zero volume are dropped.

    Raises:
        MeshError: ``mesh`` is not a Trimesh, is empty or has non-finite vertices, or CoACD left
            no non-degenerate hull.
        ImportError: coacd is not installed.
    """
    start = time.perf_counter()
    params = DecompositionParameters() if params is None else params
    if not isinstance(params, DecompositionParameters):
        raise MeshError(f"params: expected DecompositionParameters, found {type(params).__name__}")
    vertices, faces, label = _check_mesh(mesh, name)
    _import_coacd()
    path: Path | None = None
    parts: tuple[ConvexPart, ...] | None = None
    digest = version = ""
    if use_cache:
        version = coacd_version()
        digest = mesh_digest(vertices, faces, params)
        folder = default_cache_dir() if cache_dir is None else Path(cache_dir)
        path = folder / f"{digest}.json"
        parts = _read_cache(path, digest, params, version)
    hit = parts is not None
    if parts is None:
        parts = _compute(vertices, faces, params, label)
        if path is not None:
            payload = {
                "format": CACHE_FORMAT,
                "schema_version": CACHE_SCHEMA_VERSION,
                "digest": digest,
                "parameters": params.to_dict(),
                "coacd_version": version,
                "parts": [part.to_dict() for part in parts],
            }
            try:
                write_json_atomic(path, payload)
            except OSError as exc:
                warnings.warn(
                    f"{label}: could not write the CoACD cache file {path} ({exc}); "
                    "the decomposition will be recomputed next time",
                    stacklevel=2,
                )
    if stats is not None:
        stats["cache_hit"] = hit
        stats["cache_path"] = path
        stats["seconds"] = time.perf_counter() - start
    return parts


def object_parts(obj: GraspObject, **kwargs: Any) -> tuple[ConvexPart, ...]:
    """The convex parts to simulate ``obj`` with, in its object frame (m).

    Returns ``obj.parts`` when the object has them (procedural objects: exact, no CoACD call),
    else :func:`convex_decomposition` of ``obj.mesh`` with ``kwargs`` (``name`` defaults to the
    object id).

    Raises:
        MeshError: ``obj`` is not a GraspObject, or as :func:`convex_decomposition`.
    """
    if not isinstance(obj, GraspObject):
        raise MeshError(f"object: expected a GraspObject, found {type(obj).__name__}")
    if obj.parts:
        return tuple(obj.parts)
    kwargs.setdefault("name", obj.object_id)
    return convex_decomposition(obj.mesh, **kwargs)
