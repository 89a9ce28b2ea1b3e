"""Exact hits of short rays on a triangle mesh, at compiled speed.

The gripper's jaw rays (:func:`dataset_gen.grasps.gripper.contacts_from_pose`) need float64 hit points
with a deterministic choice of face, so the generator used trimesh's exact intersector
(:class:`trimesh.ray.ray_triangle.RayMeshIntersector`). Its broad phase is pure Python over an
R-tree, one query per ray, and took most of the generator's time. Here the two stages are:

1. **Candidates** (:func:`segment_candidates`, numba): through a uniform grid of the triangles'
   bounding boxes padded by :data:`PAD` (:class:`TriangleGrid`, built once per mesh), every
   triangle whose box the ray's segment (from ``along = -PAD`` to ``max_distance + PAD``) passes
   through and whose plane it crosses (within :data:`PAD`). The tests are conservative: a point
   of a triangle that lies on the segment passes both.
2. **Exact hits** (:func:`segment_hits`): trimesh's own float64 arithmetic on the candidates
   (the plane-line intersection :func:`trimesh.intersections.planes_lines` with the mesh's face
   normals, the barycentric test :func:`trimesh.triangles.points_to_barycentric` with
   ``trimesh.constants.tol.zero``, the forward test), so each hit's location is the same float64
   value the R-tree path computes.

One difference is by design. trimesh then drops a hit whose location equals another hit's of
the same ray after rounding (to about 1e-8 m), keeping the one its R-tree lists first, an order
of the tree's own; here every hit is kept, so the caller's rule (the nearest hit, ties broken by
the lowest face index: :func:`dataset_gen.grasps.gripper.nearest_hits`) decides alone. The two differ
only where two faces lie within about 1e-8 m of each other along a ray (coincident or
overlapping surfaces, as in a raw mesh of several pieces): on 30,000 random rays per mesh, 6 of
21,242 hits on the shipped couch (distances within 4.8e-9 m), none on the other shipped meshes
and procedural objects; the generator's files are byte-identical on every object measured
(``bench/generate_object.py``, ``tests/test_ray_hits.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from numba import njit
from trimesh import intersections, util
from trimesh import triangles as triangles_module
from trimesh.constants import tol

PAD = 1e-7
"""Padding of every bounding box of the candidate stage (m): far above float64 rounding at
object scale (about 1e-16 m per metre), far below any feature the jaws resolve."""

TARGET_PER_CELL = 8.0
"""Grid resolution: about this many triangle boxes per occupied cell on average."""


@dataclass(frozen=True)
class TriangleGrid:
    """A uniform grid over a mesh's padded triangle bounding boxes.

    Attributes:
        origin: (3,) float64 lower corner of the grid (m).
        cell: edge length of a cubic cell (m).
        shape: (3,) int64 cells per axis.
        cell_start: (C + 1,) int64 offsets into ``cell_triangles`` (C = prod(shape), x-major).
        cell_triangles: (K,) int64 triangle indices, ascending within each cell.
        lower, upper: (F, 3) float64 padded bounding box of each triangle (m).
        normals: (F, 3) float64 unit normals of the triangles' planes (zero for degenerate ones).
        offsets: (F,) float64 ``dot(normal, first vertex)`` (m).
    """

    origin: np.ndarray
    cell: float
    shape: np.ndarray
    cell_start: np.ndarray
    cell_triangles: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray


def triangle_grid(triangles: np.ndarray, cell: float | None = None) -> TriangleGrid:
    """The :class:`TriangleGrid` of (F, 3, 3) float64 ``triangles`` (m); ``cell`` (m) defaults to
    a size that puts about :data:`TARGET_PER_CELL` boxes in a cell."""
    triangles = np.asarray(triangles, dtype=np.float64)
    if triangles.ndim != 3 or triangles.shape[1:] != (3, 3):
        raise ValueError(f"triangles: expected shape (F, 3, 3), found {triangles.shape}")
    lower = triangles.min(axis=1) - PAD
    upper = triangles.max(axis=1) + PAD
    if len(triangles) == 0:
        lower = upper = np.zeros((0, 3))
        origin, extent = np.zeros(3), np.ones(3)
    else:
        origin = lower.min(axis=0)
        extent = np.maximum(upper.max(axis=0) - origin, PAD)
    if cell is None:
        # cells about the size of an average triangle box, at least enough to hold all boxes
        mean_box = float(np.mean(upper - lower)) if len(triangles) else 1.0
        volume_cell = float(np.prod(extent)) * TARGET_PER_CELL / max(len(triangles), 1)
        cell = max(mean_box, volume_cell ** (1.0 / 3.0), float(extent.max()) / 256.0)
    shape = np.maximum(np.ceil(extent / cell).astype(np.int64), 1)
    first = np.clip(np.floor((lower - origin) / cell).astype(np.int64), 0, shape - 1)
    last = np.clip(np.floor((upper - origin) / cell).astype(np.int64), 0, shape - 1)
    counts = np.zeros(int(np.prod(shape)), dtype=np.int64)
    _count_cells(first, last, shape, counts)
    cell_start = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts, out=cell_start[1:])
    cell_triangles = np.empty(int(cell_start[-1]), dtype=np.int64)
    _fill_cells(first, last, shape, cell_start.copy(), cell_triangles)
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    length = np.linalg.norm(cross, axis=1)
    normals = np.divide(cross, length[:, None], out=np.zeros_like(cross), where=length[:, None] > 0)
    offsets = np.einsum("ij,ij->i", normals, triangles[:, 0])
    return TriangleGrid(
        origin, float(cell), shape, cell_start, cell_triangles, lower, upper, normals, offsets
    )


@njit(cache=True)
def _count_cells(first, last, shape, counts):  # pragma: no cover - compiled
    for t in range(first.shape[0]):
        for i in range(first[t, 0], last[t, 0] + 1):
            for j in range(first[t, 1], last[t, 1] + 1):
                for k in range(first[t, 2], last[t, 2] + 1):
                    counts[(i * shape[1] + j) * shape[2] + k] += 1


@njit(cache=True)
def _fill_cells(first, last, shape, cursor, out):  # pragma: no cover - compiled
    for t in range(first.shape[0]):  # ascending t: each cell's list is sorted
        for i in range(first[t, 0], last[t, 0] + 1):
            for j in range(first[t, 1], last[t, 1] + 1):
                for k in range(first[t, 2], last[t, 2] + 1):
                    c = (i * shape[1] + j) * shape[2] + k
                    out[cursor[c]] = t
                    cursor[c] += 1


@njit(cache=True)
def _segment_candidates(
    starts,
    ends,
    origin,
    cell,
    shape,
    cell_start,
    cell_triangles,
    lower,
    upper,
    normals,
    offsets,
    out_ray,
    out_tri,
):  # pragma: no cover - compiled
    """Fill ``out_ray``/``out_tri`` (when long enough) and return the number of pairs."""
    seen = np.full(lower.shape[0], -1, dtype=np.int64)
    n = 0
    capacity = out_ray.shape[0]
    lo = np.empty(3)
    hi = np.empty(3)
    c0 = np.empty(3, dtype=np.int64)
    c1 = np.empty(3, dtype=np.int64)
    for r in range(starts.shape[0]):
        empty = False
        for a in range(3):
            lo[a] = min(starts[r, a], ends[r, a]) - PAD
            hi[a] = max(starts[r, a], ends[r, a]) + PAD
            c0[a] = max(int(np.floor((lo[a] - origin[a]) / cell)), 0)
            c1[a] = min(int(np.floor((hi[a] - origin[a]) / cell)), shape[a] - 1)
            if c0[a] > c1[a]:
                empty = True
        if empty:
            continue
        for i in range(c0[0], c1[0] + 1):
            for j in range(c0[1], c1[1] + 1):
                for k in range(c0[2], c1[2] + 1):
                    c = (i * shape[1] + j) * shape[2] + k
                    for m in range(cell_start[c], cell_start[c + 1]):
                        t = cell_triangles[m]
                        if seen[t] == r:
                            continue
                        seen[t] = r
                        if not (
                            lower[t, 0] <= hi[0]
                            and upper[t, 0] >= lo[0]
                            and lower[t, 1] <= hi[1]
                            and upper[t, 1] >= lo[1]
                            and lower[t, 2] <= hi[2]
                            and upper[t, 2] >= lo[2]
                        ):
                            continue
                        # the segment must cross the triangle's plane (within PAD) ...
                        s0 = -offsets[t]
                        s1 = -offsets[t]
                        for a in range(3):
                            s0 += normals[t, a] * starts[r, a]
                            s1 += normals[t, a] * ends[r, a]
                        if (s0 > PAD and s1 > PAD) or (s0 < -PAD and s1 < -PAD):
                            continue
                        # ... and pass through the triangle's box (slab test)
                        enter, leave = 0.0, 1.0
                        for a in range(3):
                            step = ends[r, a] - starts[r, a]
                            if step == 0.0:
                                if starts[r, a] < lower[t, a] or starts[r, a] > upper[t, a]:
                                    enter, leave = 1.0, 0.0
                                continue
                            u0 = (lower[t, a] - starts[r, a]) / step
                            u1 = (upper[t, a] - starts[r, a]) / step
                            if u0 > u1:
                                u0, u1 = u1, u0
                            enter = max(enter, u0)
                            leave = min(leave, u1)
                        if enter > leave + 1e-9:
                            continue
                        if n < capacity:
                            out_ray[n] = r
                            out_tri[n] = t
                        n += 1
    return n


def segment_candidates(
    grid: TriangleGrid, origins: np.ndarray, directions: np.ndarray, max_distance: float
) -> tuple[np.ndarray, np.ndarray]:
    """Candidate (ray, triangle) pairs of rays whose hits may lie within ``max_distance``.

    Args:
        grid: the mesh's :class:`TriangleGrid`.
        origins: (R, 3) float64 ray origins (m).
        directions: (R, 3) float64 ray directions (any non-zero length).
        max_distance: the farthest ``dot(hit - origin, direction)`` of interest.

    Returns:
        ray (H,) and triangle (H,) int64 indices, ordered by ray, then triangle.
    """
    origins = np.ascontiguousarray(origins, dtype=np.float64)
    directions = np.ascontiguousarray(directions, dtype=np.float64)
    squared = np.einsum("ij,ij->i", directions, directions)
    scale = np.divide(max_distance + PAD, squared, out=np.zeros_like(squared), where=squared > 0)
    starts = origins - directions * (PAD / np.sqrt(np.maximum(squared, 1e-300)))[:, None]
    ends = origins + directions * scale[:, None]
    args = (grid.origin, grid.cell, grid.shape, grid.cell_start, grid.cell_triangles)
    args += (grid.lower, grid.upper, grid.normals, grid.offsets)
    capacity = 8 * len(origins) + 64
    while True:
        ray = np.empty(capacity, dtype=np.int64)
        tri = np.empty(capacity, dtype=np.int64)
        n = _segment_candidates(starts, ends, *args, ray, tri)
        if n <= capacity:
            break
        capacity = n
    ray, tri = ray[:n], tri[:n]
    order = np.lexsort((tri, ray))
    return ray[order], tri[order]


def mesh_triangle_grid(mesh: trimesh.Trimesh) -> TriangleGrid:
    """The :class:`TriangleGrid` of ``mesh``, built once and kept in the mesh's cache (trimesh
    drops it when the mesh's data change)."""
    key = "dg16m_triangle_grid"
    if key not in mesh._cache:
        mesh._cache[key] = triangle_grid(mesh.triangles)
    return mesh._cache[key]


def segment_hits(
    mesh: trimesh.Trimesh, origins: np.ndarray, directions: np.ndarray, max_distance: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every hit of each ray on ``mesh`` that may lie within ``max_distance`` of its origin, as
    :meth:`trimesh.ray.ray_triangle.RayMeshIntersector.intersects_id` computes them (with
    ``multiple_hits=True, return_locations=True``, but keeping hits at the same location; see
    the module docstring): triangle (H,), ray (H,), location (H, 3) float64, ordered by ray,
    then triangle.

    Hits with ``dot(location - origin, direction)`` outside ``[0, max_distance]`` may be among
    them; the caller filters by distance.
    """
    empty = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
    origins = np.asarray(origins, dtype=np.float64)
    directions = np.asarray(directions, dtype=np.float64)
    if len(origins) == 0 or len(mesh.faces) == 0:
        return empty
    ray_id, candidates = segment_candidates(
        mesh_triangle_grid(mesh), origins, directions, max_distance
    )
    if len(candidates) == 0:
        return empty
    triangles = np.asarray(mesh.triangles, dtype=np.float64)[candidates]
    location, valid = intersections.planes_lines(
        plane_origins=triangles[:, 0, :],
        plane_normals=np.asarray(mesh.face_normals, dtype=np.float64)[candidates],
        line_origins=origins[ray_id],
        line_directions=directions[ray_id],
    )
    if not valid.any():
        return empty
    with np.errstate(invalid="ignore", divide="ignore"):  # degenerate faces: NaN, no hit
        barycentric = triangles_module.points_to_barycentric(triangles[valid], location)
    hit = np.logical_and(
        (barycentric > -tol.zero).all(axis=1), (barycentric < (1 + tol.zero)).all(axis=1)
    )
    index_tri = candidates[valid][hit]
    index_ray = ray_id[valid][hit]
    location = location[hit]
    vector = location - origins[index_ray]
    forward = util.diagonal_dot(vector, directions[index_ray]) > -1e-6
    return index_tri[forward], index_ray[forward], location[forward]
