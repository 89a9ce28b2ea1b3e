"""The mesh of a release file and the faces under its contacts, for :mod:`dataset_gen.pipeline.verify`.

:func:`load_release_mesh` loads a mesh the way the released code did (raw, scaled, centred), and
:func:`contact_geometry` finds, for every distinct contact point of a file, its distance to the
mesh, trimesh's face under it and every other face (within a tolerance) with a different normal:
the :class:`ContactGeometry` whose ambiguous points the verifier resolves.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from numpy.typing import NDArray

from dg16m_core.errors import MeshError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

#: Two face normals are the same choice when their dot product is at least this.
SAME_NORMAL_DOT = 1.0 - 1e-10
#: Two face normals are opposite (two-sided surface) when their dot product is at most this.
OPPOSITE_NORMAL_DOT = -1.0 + 1e-6


# --------------------------------------------------------------------------------------------
# Mesh and contact geometry
# --------------------------------------------------------------------------------------------


def load_release_mesh(path: str | Path, scale: float) -> trimesh.Trimesh:
    """Load ``path`` as the released code did: ``trimesh.load(path, force="mesh")`` (trimesh's
    default processing, no cleaning), scaled by ``scale``, translated by ``-centroid``.

    Raises:
        MeshError: missing or unreadable file, or no triangles in it.
    """
    path = Path(path)
    if not path.exists():
        raise MeshError(f"{path}: no such file")
    if path.is_dir():
        raise MeshError(f"{path}: expected a mesh file, found a directory")
    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as exc:  # third-party parsers raise anything on hostile input
        raise MeshError(
            f"{path}: could not be loaded as a triangle mesh ({type(exc).__name__}: {exc})"
        ) from exc
    if not isinstance(mesh, trimesh.Trimesh):
        raise MeshError(f"{path}: expected a triangle mesh, found {type(mesh).__name__}")
    if len(mesh.faces) == 0 or not np.isfinite(mesh.vertices).all():
        raise MeshError(
            f"{path}: expected finite vertices and at least one triangle, found "
            f"{len(mesh.vertices)} vertices and {len(mesh.faces)} faces"
        )
    if mesh.area <= 0:
        raise MeshError(f"{path}: expected a surface with positive area, found area 0")
    mesh.apply_scale(float(scale))
    mesh.apply_translation(-mesh.centroid)
    return mesh


@dataclass
class ContactGeometry:
    """Faces under the distinct contact points of a file.

    Attributes:
        points: ``(U, 3)`` distinct contact points.
        inverse: ``(N * 4,)`` index into ``points`` of each contact (pair-major).
        distance: ``(U,)`` distance to the mesh (m).
        primary: ``(U,)`` face returned by ``mesh.nearest.on_surface`` (trimesh's choice).
        options: per point, faces with pairwise different normals, primary first (one face when
            the point is unambiguous or off the mesh).
        two_sided: ``(U,)`` some of the point's faces have opposite normals.
    """

    points: FloatArray
    inverse: IntArray
    distance: FloatArray
    primary: IntArray
    options: list[list[int]]
    two_sided: BoolArray

    @property
    def ambiguous(self) -> BoolArray:
        """``(U,)`` points on several faces with different normals."""
        return np.array([len(o) > 1 for o in self.options], dtype=bool)


def contact_geometry(
    mesh: trimesh.Trimesh, contact_points: FloatArray, tolerance_m: float
) -> ContactGeometry:
    """Nearest face, distance and the set of faces (within ``tolerance_m``) under each distinct
    contact point of ``contact_points`` ``(N, 4, 3)``."""
    flat = np.asarray(contact_points, dtype=np.float64).reshape(-1, 3)
    points, inverse = np.unique(flat, axis=0, return_inverse=True)
    inverse = np.asarray(inverse, dtype=np.int64).reshape(-1)
    _, distance, primary = mesh.nearest.on_surface(points)
    primary = np.asarray(primary, dtype=np.int64)
    normals = np.asarray(mesh.face_normals, dtype=np.float64)
    valid_face = np.linalg.norm(normals, axis=1) > 0.5

    ids, counts = mesh.triangles_tree.intersection_v(points - tolerance_m, points + tolerance_m)
    ids = np.asarray(ids, dtype=np.int64)
    rows = np.repeat(np.arange(len(points)), np.asarray(counts, dtype=np.int64))
    if ids.size:
        close = trimesh.triangles.closest_point(mesh.triangles[ids], points[rows])
        near = np.linalg.norm(close - points[rows], axis=1) <= tolerance_m
        near &= valid_face[ids]
        ids, rows = ids[near], rows[near]
    order = np.lexsort((ids, rows))
    ids, rows = ids[order], rows[order]
    starts = np.searchsorted(rows, np.arange(len(points) + 1))

    options: list[list[int]] = []
    two_sided = np.zeros(len(points), dtype=bool)
    for u in range(len(points)):
        first = int(primary[u])
        if not valid_face[first]:  # a degenerate face won: take the nearest usable one
            candidates = ids[starts[u] : starts[u + 1]]
            if candidates.size == 0:
                raise MeshError(
                    f"contact point {points[u].tolist()} lies on a degenerate face {first} "
                    "(zero area, no normal) and on no other face"
                )
            first = int(candidates[0])
            primary[u] = first
        chosen = [first]
        if distance[u] <= tolerance_m:
            for face in ids[starts[u] : starts[u + 1]]:
                dots = normals[chosen] @ normals[face]
                if dots.max() < SAME_NORMAL_DOT:
                    chosen.append(int(face))
                    two_sided[u] |= bool(dots.min() <= OPPOSITE_NORMAL_DOT)
        options.append(chosen)
    return ContactGeometry(points, inverse, np.asarray(distance), primary, options, two_sided)


__all__ = [
    "OPPOSITE_NORMAL_DOT",
    "SAME_NORMAL_DOT",
    "BoolArray",
    "ContactGeometry",
    "FloatArray",
    "IntArray",
    "contact_geometry",
    "load_release_mesh",
]
