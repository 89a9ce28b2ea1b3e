"""Geometric queries on triangle meshes and convex hulls, for the decomposition report.

A bounding-sphere tree over a mesh's triangles (``_TriangleTree``, its queries compiled with
numba on first use) gives exact distances to the surface (:func:`surface_distance`) and a fast
generalised winding number, the inside test; beside it, area-weighted uniform samples on
triangles and the test of points against hulls given by their half-spaces. They are what
:func:`dataset_gen.objects.decomposition.decomposition_report` measures a convex decomposition with;
:func:`surface_distance` also measures how far a repaired mesh moved (:mod:`dataset_gen.real.repair`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import trimesh

from dg16m_core.errors import MeshError


def _sample_triangles(triangles: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` area-weighted uniform points (count, 3) on triangles (T, 3, 3)."""
    edges_a = triangles[:, 1] - triangles[:, 0]
    edges_b = triangles[:, 2] - triangles[:, 0]
    areas = 0.5 * np.linalg.norm(np.cross(edges_a, edges_b), axis=1)
    chosen = rng.choice(len(triangles), size=count, p=areas / areas.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    return triangles[chosen, 0] + u[:, None] * edges_a[chosen] + v[:, None] * edges_b[chosen]


def _inside_any(points: np.ndarray, equations: list[np.ndarray], tol: float) -> np.ndarray:
    """(N,) whether each point (N, 3) lies in at least one hull given by its planes (F, 4)."""
    inside = np.zeros(len(points), dtype=bool)
    for planes in equations:
        todo = ~inside
        if not todo.any():
            break
        candidate = points[todo]
        inside[np.flatnonzero(todo)] = np.all(
            candidate @ planes[:, :3].T + planes[:, 3] <= tol, axis=1
        )
    return inside


WINDING_BETA = 2.0
"""Fast winding number: a tree node whose bounding sphere (radius r) is farther than
``WINDING_BETA * r`` from the point counts as one dipole (Barill et al., 2018)."""

_WINDING_LEAF_SIZE = 8
_compiled_kernels: dict[str, Any] = {}


def _winding_kernel(
    points: np.ndarray,
    corners: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    start: np.ndarray,
    stop: np.ndarray,
    center: np.ndarray,
    radius: np.ndarray,
    dipole: np.ndarray,
    beta: float,
) -> np.ndarray:
    """Generalised winding numbers (N,) of points (N, 3) (compiled by numba on first use).

    ``corners`` (F, 3, 3) are the triangles in tree order; node ``k`` holds triangles
    ``start[k]:stop[k]``, children ``left[k]``/``right[k]`` (-1 for a leaf), its area-weighted
    centroid, bounding radius and dipole (sum of area times unit normal).
    """
    result = np.zeros(len(points))
    stack = np.empty(128, dtype=np.int64)
    for i in range(len(points)):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        total = 0.0
        depth = 1
        stack[0] = 0
        while depth > 0:
            depth -= 1
            node = stack[depth]
            dx = center[node, 0] - px
            dy = center[node, 1] - py
            dz = center[node, 2] - pz
            dist = np.sqrt(dx * dx + dy * dy + dz * dz)
            if dist > beta * radius[node]:
                total += (dx * dipole[node, 0] + dy * dipole[node, 1] + dz * dipole[node, 2]) / (
                    dist * dist * dist
                )
            elif left[node] < 0:
                for t in range(start[node], stop[node]):
                    ax = corners[t, 0, 0] - px
                    ay = corners[t, 0, 1] - py
                    az = corners[t, 0, 2] - pz
                    bx = corners[t, 1, 0] - px
                    by = corners[t, 1, 1] - py
                    bz = corners[t, 1, 2] - pz
                    cx = corners[t, 2, 0] - px
                    cy = corners[t, 2, 1] - py
                    cz = corners[t, 2, 2] - pz
                    la = np.sqrt(ax * ax + ay * ay + az * az)
                    lb = np.sqrt(bx * bx + by * by + bz * bz)
                    lc = np.sqrt(cx * cx + cy * cy + cz * cz)
                    det = (
                        ax * (by * cz - bz * cy)
                        - ay * (bx * cz - bz * cx)
                        + az * (bx * cy - by * cx)
                    )
                    den = (
                        la * lb * lc
                        + (ax * bx + ay * by + az * bz) * lc
                        + (bx * cx + by * cy + bz * cz) * la
                        + (cx * ax + cy * ay + cz * az) * lb
                    )
                    total += 2.0 * np.arctan2(det, den)
            else:
                stack[depth] = left[node]
                stack[depth + 1] = right[node]
                depth += 2
        result[i] = total / (4.0 * np.pi)
    return result


def _distance_kernel(
    points: np.ndarray,
    corners: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    start: np.ndarray,
    stop: np.ndarray,
    center: np.ndarray,
    radius: np.ndarray,
) -> np.ndarray:
    """Exact distances (N,) from points (N, 3) to the nearest triangle (compiled by numba).

    Branch and bound over the tree of :func:`_winding_kernel` (a node cannot hold a triangle
    closer than its centre's distance minus its bounding radius); the point-triangle distance
    is Ericson's closest-point-on-triangle (Real-Time Collision Detection, 5.1.5).
    """
    result = np.empty(len(points))
    stack = np.empty(128, dtype=np.int64)
    for i in range(len(points)):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        best = np.inf
        depth = 1
        stack[0] = 0
        while depth > 0:
            depth -= 1
            node = stack[depth]
            dx = center[node, 0] - px
            dy = center[node, 1] - py
            dz = center[node, 2] - pz
            bound = np.sqrt(dx * dx + dy * dy + dz * dz) - radius[node]
            if bound > 0.0 and bound * bound >= best:
                continue
            if left[node] >= 0:
                a, b = left[node], right[node]
                ax = center[a, 0] - px
                ay = center[a, 1] - py
                az = center[a, 2] - pz
                bx = center[b, 0] - px
                by = center[b, 1] - py
                bz = center[b, 2] - pz
                if ax * ax + ay * ay + az * az < bx * bx + by * by + bz * bz:
                    a, b = b, a  # push the farther child first: the nearer is searched first
                stack[depth] = a
                stack[depth + 1] = b
                depth += 2
                continue
            for t in range(start[node], stop[node]):
                ax, ay, az = corners[t, 0, 0], corners[t, 0, 1], corners[t, 0, 2]
                abx, aby, abz = corners[t, 1, 0] - ax, corners[t, 1, 1] - ay, corners[t, 1, 2] - az
                acx, acy, acz = corners[t, 2, 0] - ax, corners[t, 2, 1] - ay, corners[t, 2, 2] - az
                apx, apy, apz = px - ax, py - ay, pz - az
                d1 = abx * apx + aby * apy + abz * apz
                d2 = acx * apx + acy * apy + acz * apz
                if d1 <= 0.0 and d2 <= 0.0:
                    qx, qy, qz = ax, ay, az
                else:
                    bpx = px - corners[t, 1, 0]
                    bpy = py - corners[t, 1, 1]
                    bpz = pz - corners[t, 1, 2]
                    d3 = abx * bpx + aby * bpy + abz * bpz
                    d4 = acx * bpx + acy * bpy + acz * bpz
                    cpx = px - corners[t, 2, 0]
                    cpy = py - corners[t, 2, 1]
                    cpz = pz - corners[t, 2, 2]
                    d5 = abx * cpx + aby * cpy + abz * cpz
                    d6 = acx * cpx + acy * cpy + acz * cpz
                    vc = d1 * d4 - d3 * d2
                    vb = d5 * d2 - d1 * d6
                    va = d3 * d6 - d5 * d4
                    if d3 >= 0.0 and d4 <= d3:
                        qx, qy, qz = corners[t, 1, 0], corners[t, 1, 1], corners[t, 1, 2]
                    elif d6 >= 0.0 and d5 <= d6:
                        qx, qy, qz = corners[t, 2, 0], corners[t, 2, 1], corners[t, 2, 2]
                    elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
                        v = d1 / (d1 - d3)
                        qx, qy, qz = ax + v * abx, ay + v * aby, az + v * abz
                    elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
                        w = d2 / (d2 - d6)
                        qx, qy, qz = ax + w * acx, ay + w * acy, az + w * acz
                    elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
                        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
                        qx = corners[t, 1, 0] + w * (corners[t, 2, 0] - corners[t, 1, 0])
                        qy = corners[t, 1, 1] + w * (corners[t, 2, 1] - corners[t, 1, 1])
                        qz = corners[t, 1, 2] + w * (corners[t, 2, 2] - corners[t, 1, 2])
                    else:
                        total = va + vb + vc
                        if total > 0.0:
                            v = vb / total
                            w = vc / total
                        else:  # degenerate triangle: its first corner
                            v = 0.0
                            w = 0.0
                        qx = ax + abx * v + acx * w
                        qy = ay + aby * v + acy * w
                        qz = az + abz * v + acz * w
                ex, ey, ez = px - qx, py - qy, pz - qz
                squared = ex * ex + ey * ey + ez * ez
                if squared < best:
                    best = squared
        result[i] = np.sqrt(best)
    return result


class _TriangleTree:
    """A bounding-sphere tree over a mesh's triangles: exact distances to the surface and a fast
    generalised winding number (Barill et al., 2018), both O(log faces) per point.

    The winding number is the inside test of :func:`decomposition_report`: exact near the
    surface (leaf triangles summed by their solid angles), a first-order dipole per tree node
    far from it (measured error under 0.05 on the real meshes, so the verdict at 1/2 is
    safe). Unlike ray parity (``mesh.contains``: rays grazing edges are
    misjudged, and retried in random directions so results change between calls; measured 112
    of 40,000 points flipping on the couch mesh) or the closest face's pseudo-normal (fooled by
    coincident faces of opposite orientation, i.e. internal double walls: 5 of 2,000 random
    points of the couch misjudged, up to 29 mm deep), it is deterministic and right for double
    walls and self-intersections. Inside: winding number > 1/2. (With ``mesh.contains`` the
    couch's report at threshold 0.02 gave max 24.9 mm, from interior points taken for outside;
    the true max is 7.1 mm.)
    """

    def __init__(self, mesh: trimesh.Trimesh) -> None:
        triangles = np.asarray(mesh.vertices, dtype=np.float64)[np.asarray(mesh.faces)]
        centroids = triangles.mean(axis=1)
        vectors = 0.5 * np.cross(
            triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
        )
        areas = np.linalg.norm(vectors, axis=1)
        order = np.arange(len(triangles))
        nodes: list[list[Any]] = []  # [start, stop, left, right]

        def build(lo: int, hi: int) -> int:
            index = len(nodes)
            nodes.append([lo, hi, -1, -1])
            if hi - lo > _WINDING_LEAF_SIZE:
                chunk = centroids[order[lo:hi]]
                axis = int(np.argmax(np.ptp(chunk, axis=0)))
                mid = (hi - lo) // 2
                order[lo:hi] = order[lo:hi][np.argpartition(chunk[:, axis], mid)]
                nodes[index][2] = build(lo, lo + mid)
                nodes[index][3] = build(lo + mid, hi)
            return index

        build(0, len(triangles))
        table = np.asarray(nodes, dtype=np.int64)
        self.corners = np.ascontiguousarray(triangles[order])
        weights, points, dipoles = areas[order], centroids[order], vectors[order]
        self.start, self.stop = table[:, 0].copy(), table[:, 1].copy()
        self.left, self.right = table[:, 2].copy(), table[:, 3].copy()
        count = len(table)
        self.center = np.empty((count, 3))
        self.radius = np.empty(count)
        self.dipole = np.empty((count, 3))
        for k, (lo, hi) in enumerate(zip(self.start, self.stop, strict=True)):
            w = weights[lo:hi]
            c = (
                (points[lo:hi] * w[:, None]).sum(axis=0) / w.sum()
                if w.sum() > 0
                else points[lo:hi].mean(axis=0)
            )
            self.center[k] = c
            self.radius[k] = np.sqrt(((self.corners[lo:hi] - c) ** 2).sum(axis=2).max())
            self.dipole[k] = dipoles[lo:hi].sum(axis=0)

    def _tree(self) -> tuple[np.ndarray, ...]:
        """The arrays both compiled queries walk: triangles, children, ranges, bounding spheres."""
        return (
            self.corners,
            self.left,
            self.right,
            self.start,
            self.stop,
            self.center,
            self.radius,
        )

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """(N,) winding numbers of points (N, 3): about 1 inside, 0 outside, 1/2 on the surface."""
        return _compiled("winding")(
            np.ascontiguousarray(points, dtype=np.float64), *self._tree(), self.dipole, WINDING_BETA
        )

    def contains(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: winding number > 1/2."""
        return self(points) > 0.5

    def distance(self, points: np.ndarray) -> np.ndarray:
        """(N,) exact distances (mesh units) from points (N, 3) to the surface."""
        return _compiled("distance")(np.ascontiguousarray(points, dtype=np.float64), *self._tree())


def surface_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """(N,) exact distances (mesh units) from ``points`` (N, 3) to the surface of ``mesh``
    (any triangle mesh; a bounding-sphere tree, O(log faces) per point). Zero-area faces
    (they hold no surface, and the exact triangle projection divides by their area) are
    left out."""
    keep = np.asarray(mesh.area_faces) > 0
    if not keep.all():
        mesh = trimesh.Trimesh(mesh.vertices, np.asarray(mesh.faces)[keep], process=False)
    if len(mesh.faces) == 0:
        raise MeshError("expected a mesh with surface to measure distances to, found none")
    return _TriangleTree(mesh).distance(np.asarray(points, dtype=np.float64).reshape(-1, 3))


def _compiled(name: str) -> Any:
    """The numba-compiled kernel ``"winding"`` or ``"distance"`` (compiled on first use and
    cached on disk, so importing this module does not import numba)."""
    if name not in _compiled_kernels:
        from numba import njit

        kernel = {"winding": _winding_kernel, "distance": _distance_kernel}[name]
        _compiled_kernels[name] = njit(cache=True)(kernel)
    return _compiled_kernels[name]


__all__ = [
    "WINDING_BETA",
    "surface_distance",
]
