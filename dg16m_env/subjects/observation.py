"""What a grasp predictor sees of a benchmark object: a seeded surface point cloud, the box, the mesh.

:func:`object_observation` is the observation handed to predictors run as code
(``dg16m evaluate --predictor``, :mod:`dg16m_env.subjects.predictor`) and to classifiers
(:mod:`dg16m_env.evaluators.classifier`). Everything is in the object frame (origin at the
centre of mass, metres), the frame the submitted hand poses use.

Keys of the observation (a plain ``dict``, all arrays C-contiguous):

========================  =================  ==================================================
key                       shape / type       meaning
========================  =================  ==================================================
``object_id``             str                the benchmark's object id
``family``                str                procedural family ("" for meshes)
``points``                (P, 3) float32     surface points, area-uniform, seeded (m)
``normals``               (P, 3) float32     unit outward normals of the faces under ``points``
``bounds``                (2, 3) float64     axis-aligned box: min corner, max corner (m)
``mesh_vertices``         (V, 3) float64     the object's triangle mesh (m)
``mesh_faces``            (F, 3) int64       vertex indices of each triangle
========================  =================  ==================================================
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dataset_gen.objects.grasp_object import GraspObject
from dataset_gen.sources.object_source import object_seed
from dg16m_core.checks import check_integer
from dg16m_core.errors import Dg16mError

#: Points in an observation's cloud unless asked otherwise.
DEFAULT_POINTS = 2048

#: The keys of an observation, in the order of the table above.
OBSERVATION_KEYS = (
    "object_id",
    "family",
    "points",
    "normals",
    "bounds",
    "mesh_vertices",
    "mesh_faces",
)


class ObservationError(Dg16mError, ValueError):
    """Bad observation arguments (point count, seed)."""


def surface_points(
    vertices: np.ndarray, faces: np.ndarray, n_points: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """``n_points`` points drawn uniformly by area on a triangle mesh, with their face normals.

    Args:
        vertices: (V, 3) float.
        faces: (F, 3) int, counter-clockwise seen from outside.
        n_points: points to draw.
        rng: the random stream (faces first, then barycentric coordinates).

    Returns:
        ``points (n_points, 3)`` and ``normals (n_points, 3)`` unit outward, float64.
    """
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]  # (F, 3, 3)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(cross, axis=1)
    if not np.isfinite(area).all() or area.sum() <= 0.0:
        raise ObservationError("mesh: expected triangles with a positive total area, found none")
    face = rng.choice(area.size, size=n_points, p=area / area.sum())
    u, v = rng.random((2, n_points))
    flip = u + v > 1.0  # fold the unit square onto the triangle
    u, v = np.where(flip, 1.0 - u, u), np.where(flip, 1.0 - v, v)
    t = tri[face]
    points = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    normals = cross[face] / np.maximum(area[face], 1e-300)[:, None]
    return points, normals


def object_observation(
    obj: GraspObject, *, n_points: int = DEFAULT_POINTS, seed: int = 0
) -> dict[str, Any]:
    """The observation of one object (see the module docstring for the keys).

    The cloud's stream is a function of ``(seed, object id)`` only, so the same object gives
    the same bytes in any process and any order.

    Args:
        obj: the object (object frame).
        n_points: points in the cloud (>= 1).
        seed: seed of the cloud.
    """
    check_integer("n_points", n_points, minimum=1, error=ObservationError)
    check_integer("seed", seed, minimum=0, error=ObservationError)
    rng = np.random.default_rng(object_seed(seed, f"observation:{obj.object_id}"))
    vertices = np.ascontiguousarray(obj.mesh.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(obj.mesh.faces, dtype=np.int64)
    points, normals = surface_points(vertices, faces, n_points, rng)
    return {
        "object_id": obj.object_id,
        "family": str(obj.metadata.get("family", "")),
        "points": points.astype(np.float32),
        "normals": normals.astype(np.float32),
        "bounds": np.array([vertices.min(axis=0), vertices.max(axis=0)]),
        "mesh_vertices": vertices,
        "mesh_faces": faces,
    }
