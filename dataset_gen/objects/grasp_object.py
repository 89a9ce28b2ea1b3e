"""Objects to grasp: load any mesh, clean and validate it, centre, scale, mass properties, parts.

Frames and units
----------------
Lengths are metres, masses kilograms. An object's frame is the mesh file's frame scaled by
``scale`` and then translated by ``offset``::

    p_object = scale * p_file + offset,     offset = -scale * centroid(file mesh)

so the origin is trimesh's area-weighted surface ``centroid``. This is the DG16M release
convention: its stored contact points lie on the mesh translated by ``-mesh.centroid``
(measured on a real release file, see DESIGN.md). Gravity acts at this origin in the
force-closure check; the true centre of mass is reported in :class:`MassProperties`.

Convex parts
------------
An object may carry its exact convex decomposition as :class:`ConvexPart` items (procedural
objects are unions of primitives, so their parts are exact). The simulator collides each part as
its own convex geom; meshes without parts need a decomposition first.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import trimesh

from dg16m_core.errors import MeshError
from dg16m_core.parameters import PAPER

DEFAULT_MASS_KG = PAPER.mass
"""Object mass used by the DG16M release (with g = 10 m/s^2 its weight is 60 N)."""

MIN_EXTENT_M = 1e-3
"""Smallest accepted longest side of an object, after scaling (m); a hard limit."""

MAX_EXTENT_M = 100.0
"""Largest accepted longest side of an object, after scaling (m); a hard limit."""

DUAL_ARM_MIN_EXTENT_M = 0.05
"""Smallest plausible longest side of a dual-arm object loaded from a file (m).

Smaller files need ``allow_any_size`` (``--allow-any-size``): usually they are in the wrong units
or were given a wrong scale. The single-arm ACRONYM objects of the shared real data are
0.10-0.20 m long and stay above it."""

DUAL_ARM_MAX_EXTENT_M = 5.0
"""Largest plausible longest side of a dual-arm object loaded from a file (m); larger files are
usually in millimetres (an 80 mm box read as 80 m)."""

TYPICAL_EXTENT_M = (0.3, 2.0)
"""Longest sides (m) of the things two arms typically lift (the benchmark's objects are
0.3-1.2 m). The one units rule (:func:`guess_units`) takes a unit among metres, centimetres and
millimetres only when exactly one of them puts a file here: ``dg16m objects repair``
(:func:`dataset_gen.real.own_meshes.decide_units`), ``objects check`` and the size check of
``benchmark build`` and ``generate`` (:func:`check_dual_arm_size`) all use it, so a 100-unit bar
is read as 1 m in centimetres by each (never as 0.1 m in millimetres by one of them)."""

UNIT_FACTORS: Mapping[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254}
"""Metres per file unit, by the name ``--units`` takes."""

UNIT_NAMES: Mapping[str, str] = {
    "m": "metres",
    "cm": "centimetres",
    "mm": "millimetres",
    "inch": "inches",
}

GUESSED_UNITS = ("m", "cm", "mm")
"""The units the one units rule (:func:`guess_units`) chooses among, in order."""
"""Units :func:`guess_units` considers; inches are never guessed (an inch file's 8-80 units
read as plausible centimetres or metres just as often)."""

ARBITRARY_UNIT_SUFFIXES = (".obj", ".stl", ".ply", ".off")
"""Mesh formats whose coordinates carry no unit (GLB/glTF and 3MF are metres or say theirs)."""

LARGE_GUESS_M = 1.5
"""A guessed unit that makes an arbitrary-unit file longer than this (m, table-sized) is warned
about (:func:`large_guess_warning`): two arms lift few things that large."""

UNITS_FLAG = "--units m|cm|mm|inch"
"""The option that gives a file's unit, as the units advice names it."""


def _fitting_units(longest: float) -> list[str]:
    low, high = TYPICAL_EXTENT_M
    return [u for u in GUESSED_UNITS if low <= float(longest) * UNIT_FACTORS[u] <= high]


def guess_units(longest: float) -> str | None:
    """The one units rule: the unit of :data:`GUESSED_UNITS` that gives ``longest`` file units
    a longest side in :data:`TYPICAL_EXTENT_M`, or ``None`` when none or several do."""
    fits = _fitting_units(longest)
    return fits[0] if len(fits) == 1 else None


def unit_readings(longest: float) -> str:
    """What each guessed unit makes of ``longest`` file units, for a refused guess."""
    low, high = TYPICAL_EXTENT_M
    readings = ", ".join(
        f"{_length(longest * UNIT_FACTORS[u])} in {UNIT_NAMES[u]}" for u in GUESSED_UNITS
    )
    fits = _fitting_units(longest)
    found = "none" if not fits else f"{len(fits)} of them"
    return f"{readings}; {found} in the typical {low:g}-{high:g} m of a dual-arm object"


def large_guess_warning(unit: str, extents_m: Sequence[float], suffix: str) -> str | None:
    """The warning for a guessed ``unit`` that makes an arbitrary-unit file (``suffix`` in
    :data:`ARBITRARY_UNIT_SUFFIXES`) table-sized (longest of ``extents_m`` > :data:`LARGE_GUESS_M`),
    else ``None``."""
    longest = float(max(extents_m))
    if suffix.lower() not in ARBITRARY_UNIT_SUFFIXES or longest <= LARGE_GUESS_M:
        return None
    sides = " x ".join(f"{v:.2f}" for v in extents_m)
    return (
        f"guessed {UNIT_NAMES[unit]}: the object is {longest:.2g} m long ({sides} m), large for "
        f"two arms, and {suffix.lstrip('.').upper()} files have no units; pass {UNITS_FLAG} "
        "if that is wrong"
    )


MESH_SUFFIXES = (".obj", ".stl", ".ply", ".off", ".glb", ".gltf")
"""File types :func:`load_mesh` accepts (anything trimesh reads among these)."""

PartKind = Literal["box", "cylinder", "mesh"]


# --------------------------------------------------------------------------------------------
# Convex parts
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ConvexPart:
    """One convex piece of an object, in the object frame.

    Attributes:
        kind: ``"box"``, ``"cylinder"`` (axis along the part's local z) or ``"mesh"`` (convex hull
            of ``vertices``).
        pose: (4, 4) rigid transform from the part's local frame to the object frame.
        size: box: half extents (3,) in m; cylinder: (radius, half_length) in m; mesh: empty.
        vertices: mesh parts only, (V, 3) points in the part's local frame (m).
    """

    kind: PartKind
    pose: np.ndarray
    size: tuple[float, ...] = ()
    vertices: np.ndarray | None = None

    def __post_init__(self) -> None:
        pose = np.asarray(self.pose, dtype=np.float64)
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
            raise MeshError(f"part pose: expected a finite (4, 4) transform, found {pose.shape}")
        if not is_rigid(pose):
            raise MeshError("part pose: expected a rigid transform (rotation + translation)")
        object.__setattr__(self, "pose", pose)
        expected = {"box": 3, "cylinder": 2, "mesh": 0}
        if self.kind not in expected:
            raise MeshError(f"part kind: expected one of {sorted(expected)}, found {self.kind!r}")
        size = tuple(float(s) for s in self.size)
        if len(size) != expected[self.kind] or not all(math.isfinite(s) and s > 0 for s in size):
            raise MeshError(
                f"{self.kind} part size: expected {expected[self.kind]} positive numbers, "
                f"found {self.size!r}"
            )
        object.__setattr__(self, "size", size)
        if self.kind == "mesh":
            verts = np.asarray(self.vertices, dtype=np.float64)
            if verts.ndim != 2 or verts.shape[1] != 3 or len(verts) < 4:
                raise MeshError(f"mesh part: expected (V>=4, 3) vertices, found {verts.shape}")
            if not np.all(np.isfinite(verts)):
                raise MeshError("mesh part: vertices contain NaN or inf")
            object.__setattr__(self, "vertices", verts)
        elif self.vertices is not None:
            raise MeshError(f"{self.kind} part: vertices are only for mesh parts")

    def to_mesh(self, sections: int = 32) -> trimesh.Trimesh:
        """A watertight triangle mesh of the part in the object frame."""
        if self.kind == "box":
            mesh = trimesh.creation.box(extents=2.0 * np.asarray(self.size))
        elif self.kind == "cylinder":
            radius, half_length = self.size
            mesh = trimesh.creation.cylinder(
                radius=radius, height=2.0 * half_length, sections=sections
            )
        else:
            mesh = trimesh.convex.convex_hull(self.vertices)
        mesh.apply_transform(self.pose)
        return mesh

    def transformed(
        self, scale: float = 1.0, translation: Sequence[float] = (0, 0, 0)
    ) -> ConvexPart:
        """The part after ``p -> scale * p + translation`` (uniform scale, m)."""
        pose = self.pose.copy()
        pose[:3, 3] = scale * pose[:3, 3] + np.asarray(translation, dtype=np.float64)
        verts = None if self.vertices is None else scale * self.vertices
        size = tuple(scale * s for s in self.size)
        return ConvexPart(self.kind, pose, size, verts)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (see :func:`part_from_dict` for the schema)."""
        out: dict[str, Any] = {
            "kind": self.kind,
            "pose": [[float(x) for x in row] for row in self.pose],
        }
        if self.size:
            out["size"] = [float(s) for s in self.size]
        if self.vertices is not None:
            out["vertices"] = [[float(x) for x in row] for row in self.vertices]
        return out


def part_from_dict(data: Mapping[str, Any]) -> ConvexPart:
    """Inverse of :meth:`ConvexPart.to_dict`.

    Schema: ``{"kind": "box"|"cylinder"|"mesh", "pose": 4x4 list, "size": [...],
    "vertices": [[x, y, z], ...]}`` with ``size`` as in :class:`ConvexPart`.
    """
    if not isinstance(data, Mapping) or "kind" not in data or "pose" not in data:
        raise MeshError(f"part: expected an object with 'kind' and 'pose', found {data!r:.80}")
    vertices = data.get("vertices")
    return ConvexPart(
        kind=data["kind"],
        pose=np.asarray(data["pose"], dtype=np.float64),
        size=tuple(data.get("size", ())),
        vertices=None if vertices is None else np.asarray(vertices, dtype=np.float64),
    )


def parts_to_mesh(parts: Sequence[ConvexPart]) -> trimesh.Trimesh:
    """Exact boolean union of convex parts as one watertight mesh (manifold3d)."""
    if not parts:
        raise MeshError("parts: expected at least one convex part, found none")
    meshes = [part.to_mesh() for part in parts]
    if len(meshes) == 1:
        return meshes[0]
    return trimesh.boolean.union(meshes, engine="manifold")


# --------------------------------------------------------------------------------------------
# Loading and cleaning
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CleaningReport:
    """What :func:`clean_mesh` changed. Counts are of faces or vertices removed."""

    merged_vertices: int = 0
    degenerate_faces: int = 0
    duplicate_faces: int = 0
    unreferenced_vertices: int = 0

    @property
    def changed(self) -> bool:
        return any(dataclasses.astuple(self))

    def words(self) -> str:
        """What changed, in words ("3 duplicate vertices merged, 1 degenerate faces dropped");
        "" when nothing did."""
        changes = [
            f"{count} {what}"
            for count, what in (
                (self.merged_vertices, "duplicate vertices merged"),
                (self.degenerate_faces, "degenerate faces dropped"),
                (self.duplicate_faces, "duplicate faces dropped"),
                (self.unreferenced_vertices, "unreferenced vertices dropped"),
            )
            if count
        ]
        return ", ".join(changes)


def load_mesh(path: str | os.PathLike[str]) -> tuple[trimesh.Trimesh, CleaningReport]:
    """Read a mesh file (OBJ, STL, PLY, OFF, GLB/GLTF), concatenate scenes, clean and validate.

    Returns the cleaned mesh in the file's own frame and units, and what cleaning changed.

    Raises:
        MeshError: naming the file and the defect (missing, unreadable, empty, non-finite,
            out-of-range faces, all faces degenerate, zero extent).
    """
    path = Path(path)
    if not path.exists():
        raise MeshError(f"{path}: no such file")
    if path.is_dir():
        raise MeshError(f"{path}: expected a mesh file, found a directory")
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise MeshError(
            f"{path}: unsupported mesh format {suffix or '(no extension)'!r}; "
            f"expected one of {', '.join(MESH_SUFFIXES)}"
        )
    if path.stat().st_size == 0:
        raise MeshError(f"{path}: expected a mesh with faces, found an empty file (0 bytes)")
    vertices, faces = read_mesh_arrays(path)
    return clean_mesh(vertices, faces, name=str(path))


def read_mesh_arrays(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Parse ``path`` with trimesh without processing; scenes are flattened with their transforms."""
    try:
        loaded = trimesh.load(path, process=False, force=None)
    except Exception as exc:  # third-party parsers raise anything on hostile input; we re-raise.
        raise MeshError(
            f"{path}: could not be parsed as {path.suffix.lstrip('.').upper()} "
            f"({type(exc).__name__}: {exc})"
        ) from exc
    if isinstance(loaded, trimesh.Scene):
        geometries = [g for g in loaded.dump(concatenate=False) if isinstance(g, trimesh.Trimesh)]
        if not geometries:
            kinds = sorted({type(g).__name__ for g in loaded.geometry.values()})
            found = (
                f"only {', '.join(kinds)}"
                if kinds
                else "nothing readable (corrupt or truncated file?)"
            )
            raise MeshError(f"{path}: expected triangle geometry, found {found}")
        vertices, faces = _concatenate_arrays(geometries)
    elif isinstance(loaded, trimesh.Trimesh):
        vertices, faces = loaded.vertices, loaded.faces
    else:
        raise MeshError(
            f"{path}: expected a triangle mesh, found {type(loaded).__name__} "
            "(a point cloud or paths have no faces to grasp)"
        )
    return np.asarray(vertices, dtype=np.float64), np.asarray(faces)


def _concatenate_arrays(meshes: Sequence[trimesh.Trimesh]) -> tuple[np.ndarray, np.ndarray]:
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    vertices = np.concatenate([np.asarray(m.vertices, dtype=np.float64) for m in meshes])
    faces = np.concatenate([np.asarray(m.faces) + o for m, o in zip(meshes, offsets, strict=True)])
    return vertices, faces


def clean_mesh(
    vertices: np.ndarray, faces: np.ndarray, *, name: str = "mesh"
) -> tuple[trimesh.Trimesh, CleaningReport]:
    """Validate raw arrays and return a cleaned mesh.

    Args:
        vertices: (V, 3) float coordinates.
        faces: (F, 3) integer vertex indices.
        name: used in error messages (usually the file path).

    Cleaning merges exactly coincident vertices and drops zero-area faces, duplicate faces and
    unreferenced vertices. Anything that cannot be repaired raises :class:`MeshError`.
    """
    vertices = np.asarray(vertices)
    faces = np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise MeshError(f"{name}: expected (V, 3) vertices, found shape {vertices.shape}")
    if faces.size == 0:
        raise MeshError(
            f"{name}: the mesh has no faces ({len(vertices)} vertices); "
            "expected a triangle surface, found an empty mesh or a point cloud"
        )
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise MeshError(f"{name}: expected (F, 3) triangle faces, found shape {faces.shape}")
    if not np.issubdtype(faces.dtype, np.integer):
        raise MeshError(f"{name}: expected integer face indices, found dtype {faces.dtype}")
    n_nan = int(np.isnan(vertices).any(axis=1).sum())
    n_inf = int(np.isinf(vertices).any(axis=1).sum())
    if n_nan or n_inf:
        raise MeshError(
            f"{name}: expected finite vertex coordinates, found {n_nan} vertices with NaN "
            f"and {n_inf} with inf (of {len(vertices)})"
        )
    if faces.min() < 0 or faces.max() >= len(vertices):
        bad = int(((faces < 0) | (faces >= len(vertices))).any(axis=1).sum())
        raise MeshError(
            f"{name}: expected face indices in [0, {len(vertices) - 1}], found {bad} faces "
            f"with indices from {int(faces.min())} to {int(faces.max())}"
        )

    mesh = trimesh.Trimesh(vertices=vertices.astype(np.float64), faces=faces, process=False)
    n_vertices_before = len(mesh.vertices)
    mesh.merge_vertices(merge_tex=True, merge_norm=True, digits_vertex=12)
    merged = n_vertices_before - len(mesh.vertices)

    keep_nondegenerate = mesh.nondegenerate_faces(height=1e-12)
    n_degenerate = int((~keep_nondegenerate).sum())
    if n_degenerate == len(mesh.faces):
        raise MeshError(
            f"{name}: all {len(mesh.faces)} faces are degenerate (zero area); "
            "expected at least one triangle with area"
        )
    mesh.update_faces(keep_nondegenerate)
    keep_unique = np.zeros(len(mesh.faces), dtype=bool)
    keep_unique[mesh.unique_faces()] = True
    n_duplicate = int((~keep_unique).sum())
    mesh.update_faces(keep_unique)
    n_vertices_before = len(mesh.vertices)
    mesh.remove_unreferenced_vertices()
    unreferenced = n_vertices_before - len(mesh.vertices)

    extents = mesh.extents
    if float(extents.max()) <= 0.0:
        raise MeshError(f"{name}: expected a mesh with extent, found all vertices at one point")
    flat = [axis for axis, e in zip("xyz", extents, strict=True) if e <= 1e-9 * extents.max()]
    if flat:
        raise MeshError(
            f"{name}: expected a solid with thickness, found a flat mesh "
            f"(zero extent along {', '.join(flat)}; extents {np.round(extents, 6).tolist()})"
        )
    report = CleaningReport(merged, n_degenerate, n_duplicate, unreferenced)
    return mesh, report


# --------------------------------------------------------------------------------------------
# Mass properties
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MassProperties:
    """Rigid-body properties in the object frame (SI units).

    Attributes:
        mass: kg.
        center_of_mass: (3,) m.
        inertia: (3, 3) kg m^2, about the centre of mass, axes of the object frame.
        volume: m^3 for a closed mesh, ``None`` when the mesh is open.
        model: ``"solid"`` (uniform density, closed mesh) or ``"shell"`` (mass spread uniformly
            over the surface area; used for open meshes, whose volume is undefined).
    """

    mass: float
    center_of_mass: np.ndarray
    inertia: np.ndarray
    volume: float | None
    model: Literal["solid", "shell"]

    @property
    def density(self) -> float | None:
        """kg/m^3 for solid models, else ``None``."""
        return None if self.volume is None else self.mass / self.volume


def mass_properties(mesh: trimesh.Trimesh, mass: float = DEFAULT_MASS_KG) -> MassProperties:
    """Mass properties of ``mesh`` with total ``mass`` (kg).

    Closed, consistently wound meshes with positive volume are treated as uniform solids; other
    meshes as uniform shells (exact area-weighted second moments of each triangle).
    """
    if not (math.isfinite(mass) and mass > 0):
        raise MeshError(f"mass: expected a positive number of kg, found {mass!r}")
    if mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0:
        volume = float(mesh.volume)
        props = mesh.mass_properties
        com = np.asarray(props["center_mass"], dtype=np.float64)
        inertia = np.asarray(props["inertia"], dtype=np.float64) * (mass / props["mass"])
        return MassProperties(float(mass), com, inertia, volume, "solid")
    com, inertia = _shell_inertia(np.asarray(mesh.triangles, dtype=np.float64), mass)
    return MassProperties(float(mass), com, inertia, None, "shell")


def _shell_inertia(triangles: np.ndarray, mass: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre of mass (3,) and inertia about it (3, 3) of a uniform shell of (F, 3, 3) triangles."""
    edge1 = triangles[:, 1] - triangles[:, 0]
    edge2 = triangles[:, 2] - triangles[:, 0]
    areas = 0.5 * np.linalg.norm(np.cross(edge1, edge2), axis=1)
    total = areas.sum()
    centroids = triangles.mean(axis=1)
    com = (areas[:, None] * centroids).sum(axis=0) / total
    local = triangles - com
    vsum = local.sum(axis=1)
    # Second moment of a triangle: A/12 * (sum_i v_i v_i^T + (sum_i v_i)(sum_i v_i)^T)
    second = np.einsum("f,fij->ij", areas / 12.0, np.einsum("fvi,fvj->fij", local, local))
    second += np.einsum("f,fi,fj->ij", areas / 12.0, vsum, vsum)
    second *= mass / total
    inertia = np.trace(second) * np.eye(3) - second
    return com, inertia


# --------------------------------------------------------------------------------------------
# Objects
# --------------------------------------------------------------------------------------------


@dataclass(eq=False)
class GraspObject:
    """An object ready for grasp sampling and simulation, in its centred object frame.

    Attributes:
        object_id: stable identifier (file stem or procedural id).
        mesh: cleaned, scaled, centred triangle mesh (m).
        scale: factor applied to the file's coordinates.
        offset: (3,) translation applied after scaling (m); ``-scale * centroid`` by default.
        mass_properties: see :class:`MassProperties`.
        parts: exact convex decomposition in the object frame, or ``None`` when unknown.
        source: the mesh file it came from, if any.
        cleaning: what :func:`clean_mesh` changed.
        metadata: free-form JSON-ready facts (family, seed, ...).
    """

    object_id: str
    mesh: trimesh.Trimesh
    scale: float
    offset: np.ndarray
    mass_properties: MassProperties
    parts: tuple[ConvexPart, ...] | None = None
    source: Path | None = None
    cleaning: CleaningReport = field(default_factory=CleaningReport)
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def extents(self) -> np.ndarray:
        """(3,) side lengths of the axis-aligned bounding box (m)."""
        return np.asarray(self.mesh.extents, dtype=np.float64)

    @property
    def is_watertight(self) -> bool:
        return bool(self.mesh.is_watertight)

    def file_to_object(self, points: np.ndarray) -> np.ndarray:
        """Map (..., 3) points from the mesh file's frame into the object frame."""
        return self.scale * np.asarray(points, dtype=np.float64) + self.offset


def load_object(
    path: str | os.PathLike[str],
    *,
    object_id: str | None = None,
    scale: float | None = None,
    target_extent: float | None = None,
    mass: float = DEFAULT_MASS_KG,
    center: bool = True,
    parts: Sequence[ConvexPart] | None = None,
    allow_any_size: bool = False,
) -> GraspObject:
    """Load a mesh file as a :class:`GraspObject`.

    Args:
        path: mesh file (see :data:`MESH_SUFFIXES`).
        object_id: defaults to the file stem.
        scale: factor applied to the file's coordinates (e.g. 0.001 for millimetres, or the
            ``object/scale`` of a DG16M or ACRONYM file). Exclusive with ``target_extent``.
        target_extent: scale so that the longest bounding-box side is this many metres.
        mass: kg (default 6, the release value).
        center: translate by ``-centroid`` (the release convention). ``False`` keeps the file origin.
        parts: convex parts in the file's frame and units; they are scaled and translated with the mesh.
        allow_any_size: accept a longest side outside the plausible dual-arm range
            [:data:`DUAL_ARM_MIN_EXTENT_M`, :data:`DUAL_ARM_MAX_EXTENT_M`] (the hard limits
            still hold). Pass it when the scale is known to be right, e.g. given by a grasp file.

    Raises:
        MeshError: the file is unusable, the scaled size is outside [:data:`MIN_EXTENT_M`,
            :data:`MAX_EXTENT_M`], or outside the dual-arm range without ``allow_any_size``
            (the message suggests a scale).
    """
    mesh, report = load_mesh(path)
    if not allow_any_size:
        check_dual_arm_size(mesh, scale=scale, target_extent=target_extent, name=str(path))
    return make_object(
        mesh,
        object_id=object_id or Path(path).stem,
        scale=scale,
        target_extent=target_extent,
        mass=mass,
        center=center,
        parts=parts,
        source=Path(path),
        cleaning=report,
    )


def check_mesh_folder(folder: str | os.PathLike[str], flag: str = "--meshes") -> None:
    """Raise :class:`MeshError` when ``folder`` (given as ``flag``) is a file where a folder of
    mesh files must go: ``--meshes chair.obj`` in ``dg16m generate`` and ``dg16m benchmark
    build`` alike. A path that does not exist is left to the reader of the folder."""
    path = Path(folder)
    if path.exists() and not path.is_dir():
        what = "a file" if path.is_file() else "something that is not a folder"
        raise MeshError(f"{flag}: expected a folder of mesh files, found {what}: {folder}")


def check_dual_arm_size(
    mesh: trimesh.Trimesh,
    *,
    scale: float | None = None,
    target_extent: float | None = None,
    name: str = "mesh",
) -> None:
    """Raise :class:`MeshError` unless ``mesh`` (file units) scaled as asked has a longest side in
    [:data:`DUAL_ARM_MIN_EXTENT_M`, :data:`DUAL_ARM_MAX_EXTENT_M`].

    The message says what was found and suggests the scale of :func:`guess_units` that puts the
    object in range (dropping ``--scale`` when the file is already in metres). Invalid ``scale``
    or ``target_extent`` values are left to :func:`make_object`, which names them.
    """
    longest = float(np.max(mesh.extents))
    if target_extent is not None:
        size = float(target_extent)
    else:
        size = longest * (1.0 if scale is None else float(scale))
    if not (math.isfinite(size) and size > 0):
        return
    if DUAL_ARM_MIN_EXTENT_M <= size <= DUAL_ARM_MAX_EXTENT_M:
        return
    expected = (
        f"expected {DUAL_ARM_MIN_EXTENT_M:g}-{DUAL_ARM_MAX_EXTENT_M:g} m for a dual-arm object"
    )
    if target_extent is not None:
        hint = "choose a --target-extent in that range"
    else:
        hint = _scale_hint(longest, scale)
    raise MeshError(
        f"{name}: longest side {_length(size)}: {expected}; {hint}, "
        "or pass --allow-any-size if the size is right"
    )


def _scale_hint(longest: float, scale: float | None) -> str:
    """Suggest the scale the one units rule (:func:`guess_units`) gives ``longest`` file units."""
    current = 1.0 if scale is None else float(scale)
    unit = guess_units(longest)
    if unit is None:
        return (
            f"cannot guess the units ({unit_readings(longest)}): pass --scale or --target-extent "
            f"('dg16m objects check' and 'objects repair' take {UNITS_FLAG} too)"
        )
    factor = UNIT_FACTORS[unit]
    if factor == 1.0:
        return (
            f"the file's own units give {_length(longest)}: it seems to be in metres "
            f"already, so --scale {current:g} looks wrong (drop it)"
        )
    return (
        f"a file in {UNIT_NAMES[unit]} needs --scale {factor:g} ({_length(longest * factor)}, "
        "the only unit giving a typical size)"
    )


def _length(metres: float) -> str:
    """A length for people: ``80 m``, ``0.8 mm``, ``0.301 m``."""
    if metres < 0.01:
        return f"{metres * 1000:.3g} mm"
    return f"{metres:.3g} m"


def make_object(
    mesh: trimesh.Trimesh,
    *,
    object_id: str,
    scale: float | None = None,
    target_extent: float | None = None,
    mass: float = DEFAULT_MASS_KG,
    center: bool = True,
    parts: Sequence[ConvexPart] | None = None,
    source: Path | None = None,
    cleaning: CleaningReport | None = None,
    metadata: Mapping[str, Any] | None = None,
) -> GraspObject:
    """Build a :class:`GraspObject` from an already clean mesh (file frame); see :func:`load_object`."""
    name = str(source) if source is not None else object_id
    if scale is not None and target_extent is not None:
        raise MeshError(f"{name}: give either scale or target_extent, not both")
    longest = float(np.max(mesh.extents))
    if target_extent is not None:
        if not (math.isfinite(target_extent) and target_extent > 0):
            raise MeshError(
                f"target_extent: expected a positive length in m, found {target_extent!r}"
            )
        scale = target_extent / longest
    scale = 1.0 if scale is None else float(scale)
    if not (math.isfinite(scale) and scale > 0):
        raise MeshError(f"scale: expected a positive finite factor, found {scale!r}")
    size = longest * scale
    if size > MAX_EXTENT_M:
        raise MeshError(
            f"{name}: expected a longest side of at most {MAX_EXTENT_M:g} m, found {size:.4g} m; "
            "if the file is in millimetres pass scale=0.001 (--scale 0.001)"
        )
    if size < MIN_EXTENT_M:
        raise MeshError(
            f"{name}: expected a longest side of at least {MIN_EXTENT_M:g} m, found {size:.4g} m; "
            "pass a scale (--scale) or a target size (--target-extent)"
        )
    scaled = mesh.copy()
    if scale != 1.0:
        scaled.apply_scale(scale)
    offset = -np.asarray(scaled.centroid, dtype=np.float64) if center else np.zeros(3)
    scaled.apply_translation(offset)
    placed_parts = None
    if parts is not None:
        placed_parts = tuple(part.transformed(scale, offset) for part in parts)
    return GraspObject(
        object_id=object_id,
        mesh=scaled,
        scale=scale,
        offset=offset,
        mass_properties=mass_properties(scaled, mass),
        parts=placed_parts,
        source=source,
        cleaning=cleaning or CleaningReport(),
        metadata=dict(metadata or {}),
    )


def is_rigid(transforms: np.ndarray, atol: float = 1e-6) -> np.ndarray | bool:
    """Whether (..., 4, 4) transforms are rigid: orthonormal rotation with det +1, last row 0001.

    Returns a bool for one transform, else a (...) bool mask.
    """
    T = np.asarray(transforms, dtype=np.float64)
    R = T[..., :3, :3]
    orthonormal = (
        np.abs(np.einsum("...ji,...jk->...ik", R, R) - np.eye(3)).max(axis=(-2, -1)) <= atol
    )
    proper = np.abs(np.linalg.det(R) - 1.0) <= atol
    last_row = np.abs(T[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])).max(axis=-1) <= atol
    mask = orthonormal & proper & last_row & np.isfinite(T).all(axis=(-2, -1))
    return bool(mask) if mask.ndim == 0 else mask
