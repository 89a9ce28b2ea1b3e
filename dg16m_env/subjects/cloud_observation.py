"""The cloud track's observation: what the benchmark's depth cameras see of an object, no mesh.

``dg16m evaluate --predictor X --track cloud`` hands a predictor this observation instead of
:func:`dg16m_env.subjects.observation.object_observation` (which holds the mesh). The harness
(this process) builds it; the predictor's process never receives the mesh, the object's id or
its family (an id names a procedural shape, which the generator could rebuild).

Cameras
-------
Per object, ``n_cameras`` (default 2) pinhole depth cameras are placed around the object's box
by :func:`dg16m_env.physics.cameras.draw_cameras` (azimuth spread around, elevation -70 to -15
degrees, distance 0.9-1.2 x 2.2 x the bounding radius, all looking at the box's centre) with
``numpy.random.default_rng(object_seed(camera_seed, "cameras:<object id>"))``: fixed per object by
the benchmark and ``camera_seed`` (default 0), the same for every predictor. Each camera has
MuJoCo's default 45-degree vertical field of view and a square ``resolution`` x ``resolution``
image (default 128). A pixel's depth is ray cast (through its centre) on the object's triangle
mesh, the benchmark's simulated geometry for procedural objects; no OpenGL is needed.

Sensor noise (``noise``)
------------------------
``"none"``: ideal depth. ``"kinect"`` (the default), seeded per object by
``numpy.random.default_rng(object_seed(noise_seed, "noise:<object id>"))``, per camera in this
order (three (H, W) draws each, whatever was hit):

1. **grazing angles**: a pixel whose view ray meets the surface at ``theta`` degrees from its
   normal is missing with probability ``clip((theta - 65) / (85 - 65), 0, 1)`` (0 up to 65
   degrees, one half at 75, always beyond 85): the projected pattern is too stretched to match;
2. **edges**: a pixel with a 4-neighbour that saw nothing or whose ideal depth differs by more
   than :data:`EDGE_JUMP_M` (a depth discontinuity) is missing with probability
   :data:`EDGE_DROP`;
3. **axial noise**: each remaining pixel's depth ``z`` (m, along the optical axis) gains a
   Gaussian error of standard deviation ``sigma(z) = 0.0012 + 0.0019 (z - 0.4)^2`` m (Nguyen,
   Izadi and Lovell, 3DIMPVT 2012, the Kinect's axial model; about 2.5 mm at 1.2 m).

Keys of the observation (a plain ``dict``; object frame: origin at the centre of mass, m)
-------------------------------------------------------------------------------------------
==================  ====================  ==========================================================
key                 shape / type          meaning
==================  ====================  ==========================================================
``points``          (P, 3) float32        every depth pixel back-projected (noisy depth), camera by
                                          camera, rows top to bottom (P varies: no padding)
``normals``         (P, 3) float32        unit normals ESTIMATED from the noisy depth image: the
                                          plane through each pixel's 3 x 3 neighbourhood (pixels
                                          within :data:`EDGE_JUMP_M` of its depth), turned toward
                                          the camera; facing the camera where fewer than 3 pixels
``pixels``          (P, 3) int32          camera, row, column of each point
``depth``           (C, H, W) float32     depth along each camera's optical axis (m); 0 = missing
``intrinsics``      (3, 3) float64        pinhole matrix K (pixels): ``fx = fy = (H / 2) /
                                          tan(fovy / 2)``, ``cx = W / 2``, ``cy = H / 2``; pixel
                                          (row i, column j) has its centre at ``(j + 0.5, i + 0.5)``
``camera_poses``    (C, 4, 4) float64     camera -> object frame; camera axes as OpenCV's: x right,
                                          y down, z forward (the optical axis)
``fovy_deg``        float                 vertical field of view (degrees)
==================  ====================  ==========================================================

A camera-frame point of pixel (i, j) with depth z is ``((j + 0.5 - cx) z / fx, (i + 0.5 - cy) z /
fy, z)``. The observation has no ``mesh_vertices``, ``mesh_faces``, ``bounds``, ``object_id`` or
``family``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from dataset_gen.sources.object_source import object_seed
from dg16m_core.checks import check_integer
from dg16m_env.subjects.observation import ObservationError

if TYPE_CHECKING:
    import trimesh

    from dataset_gen.objects.grasp_object import GraspObject
    from dg16m_env.physics.cameras import CameraPose

FOVY_DEG = 45.0
"""Vertical field of view of the cameras (degrees): MuJoCo's default ``vis.global_.fovy``, which
the environments' depth cameras use."""

DEFAULT_CAMERAS = 2
"""Cameras per object unless asked otherwise."""

DEFAULT_RESOLUTION = 128
"""Image side (pixels) unless asked otherwise."""

NOISE_MODELS = ("kinect", "none")
"""The sensor-noise models (see the module docstring); the first is the default."""

AXIAL_SIGMA = (0.0012, 0.0019, 0.4)
"""``(a, b, z0)`` of the axial depth noise ``sigma(z) = a + b (z - z0)^2`` (m)."""

GRAZING_RAMP_DEG = (65.0, 85.0)
"""Incidence angles (degrees) between which a pixel's chance of missing rises from 0 to 1."""

EDGE_JUMP_M = 0.02
"""A depth step (m) between 4-neighbours that makes both edge pixels (and separates surfaces in
the normal estimate)."""

EDGE_DROP = 0.5
"""Chance that an edge pixel is missing."""

OBSERVATION_KEYS = (
    "points",
    "normals",
    "pixels",
    "depth",
    "intrinsics",
    "camera_poses",
    "fovy_deg",
)
"""The keys of a cloud-track observation, in the order of the module docstring's table."""


# --------------------------------------------------------------------------------------------
# Ray-cast pinhole cameras


def camera_axes(position: np.ndarray, lookat: np.ndarray) -> np.ndarray:
    """(3, 3) the unit ``right``, ``up`` and ``forward`` axes (rows) of a camera at ``position``
    looking at ``lookat`` (m), ``+z`` up (``+y`` when it looks straight up or down)."""
    forward = np.asarray(lookat, dtype=np.float64) - np.asarray(position, dtype=np.float64)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:
        right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(right, forward), forward])


def camera_rays(
    position: np.ndarray, lookat: np.ndarray, resolution: int, fovy_deg: float = FOVY_DEG
) -> np.ndarray:
    """(R * R, 3) unit ray directions through the pixel centres of a pinhole camera at
    ``position`` looking at ``lookat`` (m, :func:`camera_axes`), square image of ``resolution``
    pixels, rows top to bottom."""
    right, up, forward = camera_axes(position, lookat)
    half = math.tan(math.radians(fovy_deg) / 2.0)
    t = (2.0 * (np.arange(resolution) + 0.5) / resolution - 1.0) * half
    u, v = np.meshgrid(t, -t)  # rows top to bottom
    rays = forward + u[..., None] * right + v[..., None] * up
    rays = rays.reshape(-1, 3)
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def cast_view(
    mesh: trimesh.Trimesh, pose: CameraPose, resolution: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ray cast one camera's image on ``mesh`` (first hits only).

    Returns:
        ``rays (R * R, 3)`` unit directions (:func:`camera_rays`), ``hit_face (H,)`` the face
        each hit lies on, ``hit_ray (H,)`` the pixel (flat index) of each hit and ``where (H,
        3)`` the hit points (m; the mesh's frame).
    """
    origin = pose.position
    rays = camera_rays(origin, np.asarray(pose.lookat), resolution)
    hit_face, hit_ray, where = mesh.ray.intersects_id(
        np.tile(origin, (len(rays), 1)), rays, multiple_hits=False, return_locations=True
    )
    return rays, hit_face, hit_ray, where


def object_cameras(
    vertices: np.ndarray, rng: np.random.Generator, n_cameras: int
) -> list[CameraPose]:
    """``n_cameras`` poses around the box of ``vertices`` (V, 3) (m), drawn from ``rng`` by
    :func:`dg16m_env.physics.cameras.draw_cameras` (centre: the box's; radius: half its
    diagonal, at least 1 mm)."""
    from dg16m_env.physics.cameras import draw_cameras

    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    radius = max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-3)
    return draw_cameras(rng, n_cameras, (lo + hi) / 2.0, radius)


def intrinsics_matrix(resolution: int, fovy_deg: float = FOVY_DEG) -> np.ndarray:
    """(3, 3) pinhole matrix K (pixels) of a square image (see the module docstring)."""
    f = (resolution / 2.0) / math.tan(math.radians(fovy_deg) / 2.0)
    c = resolution / 2.0
    return np.array([[f, 0.0, c], [0.0, f, c], [0.0, 0.0, 1.0]])


def camera_pose_matrix(axes: np.ndarray, position: np.ndarray) -> np.ndarray:
    """(4, 4) camera -> object transform of a camera with ``axes`` (right, up, forward rows,
    :func:`camera_axes`) at ``position`` (m), camera axes as OpenCV's (x right, y down, z
    forward)."""
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2] = axes[0], -axes[1], axes[2]
    pose[:3, 3] = position
    return pose


# --------------------------------------------------------------------------------------------
# The noise model and the estimated normals


def window_shifts(image: np.ndarray, radius: int = 1, fill: Any = 0.0) -> np.ndarray:
    """(S, H, W, ...) ``image`` (H, W, ...) shifted by each offset of a ``(2 radius + 1)`` square
    window, row offsets outer, column offsets inner (S = (2 radius + 1)^2; ``fill`` outside)."""
    h, w = image.shape[:2]
    pad = [(radius, radius), (radius, radius)] + [(0, 0)] * (image.ndim - 2)
    padded = np.pad(image, pad, constant_values=fill)
    side = range(-radius, radius + 1)
    return np.stack(
        [
            padded[radius + i : radius + i + h, radius + j : radius + j + w]
            for i in side
            for j in side
        ]
    )


def edge_pixels(depth: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels that saw something (``depth > 0``) with a 4-neighbour inside the image
    that saw nothing or whose depth differs by more than :data:`EDGE_JUMP_M`."""
    valid = depth > 0.0
    edge = np.zeros_like(valid)
    for axis in (0, 1):
        a = np.take(depth, range(depth.shape[axis] - 1), axis=axis)
        b = np.take(depth, range(1, depth.shape[axis]), axis=axis)
        va, vb = a > 0.0, b > 0.0
        step = (va != vb) | (va & vb & (np.abs(a - b) > EDGE_JUMP_M))
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        edge[tuple(lo)] |= step
        edge[tuple(hi)] |= step
    return edge & valid


def noisy_depth(
    depth: np.ndarray, incidence_deg: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """The ``"kinect"`` model (module docstring) applied to one ideal depth image.

    Args:
        depth: (H, W) ideal depth along the optical axis (m; 0 = nothing seen).
        incidence_deg: (H, W) angle between each pixel's ray and the surface normal (degrees).
        rng: draws (H, W) uniforms for the grazing angles, then for the edges, then (H, W)
            standard normals for the axial noise.

    Returns:
        (H, W) float64 noisy depth (m; 0 = missing).
    """
    shape = depth.shape
    u_grazing, u_edge = rng.random(shape), rng.random(shape)
    gauss = rng.standard_normal(shape)
    lo, hi = GRAZING_RAMP_DEG
    p_grazing = np.clip((incidence_deg - lo) / (hi - lo), 0.0, 1.0)
    keep = (depth > 0.0) & (u_grazing >= p_grazing)
    keep &= ~(edge_pixels(depth) & (u_edge < EDGE_DROP))
    a, b, z0 = AXIAL_SIGMA
    noisy = depth + (a + b * (depth - z0) ** 2) * gauss
    return np.where(keep & (noisy > 0.0), noisy, 0.0)


def back_project(depth: np.ndarray, k: np.ndarray) -> np.ndarray:
    """(H, W, 3) camera-frame points (m, OpenCV axes) of a depth image (H, W) (m) and its
    pinhole matrix ``k`` (3, 3) (pixels)."""
    h, w = depth.shape
    x = (np.arange(w) + 0.5 - k[0, 2]) / k[0, 0]
    y = (np.arange(h) + 0.5 - k[1, 2]) / k[1, 1]
    return np.stack(np.broadcast_arrays(x[None, :] * depth, y[:, None] * depth, depth), axis=-1)


def estimate_normals(camera_points: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(H, W, 3) unit normals (camera frame) estimated from a depth image alone: the normal of the
    plane fitted (least squares) to each pixel's 3 x 3 neighbours that saw something within
    :data:`EDGE_JUMP_M` of its depth, turned toward the camera; where fewer than 3 such pixels
    (or a degenerate patch), the direction back to the camera. Zeros where ``depth`` is 0."""
    valid = depth > 0.0
    shifted = window_shifts(camera_points)  # (9, H, W, 3)
    near = window_shifts(depth)
    weight = ((near > 0.0) & (np.abs(near - depth) <= EDGE_JUMP_M) & valid).astype(np.float64)
    count = weight.sum(axis=0)
    normals = np.zeros_like(camera_points)
    towards = -camera_points / np.maximum(np.linalg.norm(camera_points, axis=-1), 1e-12)[..., None]
    normals[valid] = towards[valid]
    fit = valid & (count >= 3)
    if fit.any():
        w = weight[:, fit]  # (9, N)
        p = shifted[:, fit]  # (9, N, 3)
        mean = (w[..., None] * p).sum(axis=0) / count[fit][:, None]
        d = p - mean
        cov = np.einsum("kn,kni,knj->nij", w, d, d)
        values, vectors = np.linalg.eigh(cov)
        n = vectors[:, :, 0]  # the least-spread direction
        flat = values[:, 1] <= 1e-12  # a line or a point: no plane
        n = np.where(flat[:, None], towards[fit], n)
        n = np.where((np.einsum("ni,ni->n", n, towards[fit]) < 0.0)[:, None], -n, n)
        normals[fit] = n / np.linalg.norm(n, axis=1, keepdims=True)
    return normals


# --------------------------------------------------------------------------------------------
# The observation


@dataclass(frozen=True)
class CloudTrack:
    """The cloud track's cameras and sensor model (see the module docstring).

    Attributes:
        n_cameras: depth cameras per object (>= 1).
        resolution: image side (pixels, >= 2).
        camera_seed: seed of the camera draw (>= 0); fixed by the benchmark, the same for every
            predictor.
        noise: a name of :data:`NOISE_MODELS`.
        noise_seed: seed of the sensor noise (>= 0).

    Raises:
        ObservationError: a bad value.
    """

    n_cameras: int = DEFAULT_CAMERAS
    resolution: int = DEFAULT_RESOLUTION
    camera_seed: int = 0
    noise: str = NOISE_MODELS[0]
    noise_seed: int = 0

    def __post_init__(self) -> None:
        for name, minimum in (
            ("n_cameras", 1),
            ("resolution", 2),
            ("camera_seed", 0),
            ("noise_seed", 0),
        ):
            check_integer(name, getattr(self, name), minimum=minimum, error=ObservationError)
        if self.noise not in NOISE_MODELS:
            raise ObservationError(f"noise: expected one of {NOISE_MODELS}, found {self.noise!r}")

    def record(self) -> dict[str, Any]:
        """The track's parameters as a submission's metadata records them (JSON-ready)."""
        return {
            "noise": self.noise,
            "noise_seed": int(self.noise_seed),
            "cameras": int(self.n_cameras),
            "camera_seed": int(self.camera_seed),
            "resolution": int(self.resolution),
            "fovy_deg": FOVY_DEG,
        }

    def observe(self, obj: GraspObject) -> dict[str, Any]:
        """The cloud-track observation of ``obj`` (object frame); see :func:`cloud_observation`."""
        return cloud_observation(obj, self)


def cloud_observation(obj: GraspObject, track: CloudTrack | None = None) -> dict[str, Any]:
    """What ``track``'s depth cameras see of ``obj`` (module docstring: keys, cameras, noise).

    The same object, ``camera_seed`` and ``noise_seed`` give the same bytes in any process and
    any order.

    Args:
        obj: the benchmark object (object frame, m).
        track: cameras and noise (default :class:`CloudTrack`'s defaults).
    """
    import trimesh

    track = CloudTrack() if track is None else track
    vertices = np.ascontiguousarray(obj.mesh.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(obj.mesh.faces, dtype=np.int64)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    poses = object_cameras(
        vertices,
        np.random.default_rng(object_seed(track.camera_seed, f"cameras:{obj.object_id}")),
        track.n_cameras,
    )
    noise_rng = np.random.default_rng(object_seed(track.noise_seed, f"noise:{obj.object_id}"))
    r = track.resolution
    k = intrinsics_matrix(r)
    depths, matrices, points, normals, pixels = [], [], [], [], []
    for c, pose in enumerate(poses):
        rays, hit_face, hit_ray, where = cast_view(mesh, pose, r)
        axes = camera_axes(pose.position, np.asarray(pose.lookat))
        depth = np.zeros(r * r)
        depth[hit_ray] = (where - pose.position) @ axes[2]
        depth = depth.reshape(r, r)
        if track.noise == "kinect":
            cosine = np.zeros(r * r)
            cosine[hit_ray] = np.abs(
                np.einsum("ni,ni->n", rays[hit_ray], mesh.face_normals[hit_face])
            )
            incidence = np.degrees(np.arccos(np.clip(cosine, 0.0, 1.0))).reshape(r, r)
            depth = noisy_depth(depth, incidence, noise_rng)
        matrix = camera_pose_matrix(axes, pose.position)
        local = back_project(depth, k)
        normal = estimate_normals(local, depth)
        seen = depth > 0.0
        rows, cols = np.nonzero(seen)
        points.append(local[seen] @ matrix[:3, :3].T + matrix[:3, 3])
        normals.append(normal[seen] @ matrix[:3, :3].T)
        pixels.append(np.stack([np.full(rows.size, c), rows, cols], axis=1))
        depths.append(depth)
        matrices.append(matrix)
    return {
        "points": np.ascontiguousarray(np.concatenate(points), dtype=np.float32),
        "normals": np.ascontiguousarray(np.concatenate(normals), dtype=np.float32),
        "pixels": np.ascontiguousarray(np.concatenate(pixels), dtype=np.int32),
        "depth": np.asarray(depths, dtype=np.float32),
        "intrinsics": k,
        "camera_poses": np.asarray(matrices, dtype=np.float64),
        "fovy_deg": FOVY_DEG,
    }


__all__ = [
    "AXIAL_SIGMA",
    "DEFAULT_CAMERAS",
    "DEFAULT_RESOLUTION",
    "EDGE_DROP",
    "EDGE_JUMP_M",
    "FOVY_DEG",
    "GRAZING_RAMP_DEG",
    "NOISE_MODELS",
    "OBSERVATION_KEYS",
    "CloudTrack",
    "back_project",
    "camera_axes",
    "camera_pose_matrix",
    "camera_rays",
    "cast_view",
    "cloud_observation",
    "edge_pixels",
    "estimate_normals",
    "intrinsics_matrix",
    "noisy_depth",
    "object_cameras",
    "window_shifts",
]
