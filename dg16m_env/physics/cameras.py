"""Seeded depth cameras: the part of a benchmark object a robot's depth camera sees.

:class:`DepthCameras` renders the object's compiled trial scene offscreen with
``mujoco.Renderer`` (depth and segmentation buffers, object at rest at the origin, hands moved
out of the way) from ``n_cameras`` free cameras placed with the environment's generator
(:func:`draw_cameras`), back-projects the pixels that show the object into the object frame
(:func:`back_project`) and returns a fixed-size cloud with a validity mask
(:func:`fixed_size`).

What the cameras see is the simulated geometry: the object's convex parts (exact for procedural
objects, the convex decomposition for meshes). The normal of a point is the outward normal of the
face of the part its pixel sees (the segmentation buffer names the part; :func:`part_normals`
finds the face: the nearest of a box's six faces, a cylinder's side or cap, the active face of a
convex mesh's hull), not an estimate from neighbouring depth pixels.

Units: metres, object frame; images are ``resolution`` x ``resolution`` pixels with MuJoCo's
default vertical field of view (``model.vis.global_.fovy``, 45 degrees).
"""

from __future__ import annotations

import os
import weakref
from dataclasses import dataclass

import mujoco
import numpy as np

from dg16m_env.physics.replay import DISTANCE_FACTOR, RenderError, default_camera, make_renderer
from dg16m_env.physics.scene import Scene
from dg16m_env.physics.trial_protocol import STATE_SPEC, initial_state

ELEVATION_RANGE = (-70.0, -15.0)
"""Camera elevation range (degrees; negative looks down, as a camera above a table does)."""

AZIMUTH_JITTER = 30.0
"""With several cameras, camera ``i`` sits at ``azimuth_0 + i * 360 / n`` plus a uniform jitter
of this many degrees either way (so two cameras see roughly opposite sides)."""

DISTANCE_RANGE = (0.9, 1.2)
"""Camera distance as a multiple of :data:`dg16m_env.physics.replay.DISTANCE_FACTOR` times the object's
bounding radius."""

HANDS_AWAY = 1.0e3
"""Where the hands are put while the cameras look (m from the origin): out of every picture."""


@dataclass(frozen=True)
class CameraPose:
    """A free camera looking at ``lookat`` (m) from ``distance`` (m) at ``azimuth`` and
    ``elevation`` (degrees), as ``mujoco.MjvCamera`` describes one."""

    lookat: tuple[float, float, float]
    distance: float
    azimuth: float
    elevation: float

    @property
    def position(self) -> np.ndarray:
        """(3,) where the camera is (m): ``lookat - distance * forward``, ``forward`` the unit
        view axis at ``azimuth`` / ``elevation``."""
        az, el = np.radians(self.azimuth), np.radians(self.elevation)
        forward = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        return np.asarray(self.lookat) - self.distance * forward

    def mjv_camera(self) -> mujoco.MjvCamera:
        camera = mujoco.MjvCamera()
        camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        camera.lookat[:] = self.lookat
        camera.distance = self.distance
        camera.azimuth = self.azimuth
        camera.elevation = self.elevation
        return camera


def draw_cameras(
    rng: np.random.Generator, n_cameras: int, centre: np.ndarray, radius: float
) -> list[CameraPose]:
    """``n_cameras`` camera poses around an object (centre and bounding radius in m), drawn from
    ``rng``: azimuth uniform (cameras spread around, :data:`AZIMUTH_JITTER`), elevation uniform
    in :data:`ELEVATION_RANGE`, distance uniform in :data:`DISTANCE_RANGE` (scaled)."""
    azimuth0 = float(rng.uniform(0.0, 360.0))
    cameras = []
    for i in range(n_cameras):
        jitter = float(rng.uniform(-AZIMUTH_JITTER, AZIMUTH_JITTER)) if i else 0.0
        elevation = float(rng.uniform(*ELEVATION_RANGE))
        scale = float(rng.uniform(*DISTANCE_RANGE))
        cameras.append(
            CameraPose(
                lookat=(float(centre[0]), float(centre[1]), float(centre[2])),
                distance=DISTANCE_FACTOR * radius * scale,
                azimuth=(azimuth0 + i * 360.0 / n_cameras + jitter) % 360.0,
                elevation=elevation,
            )
        )
    return cameras


def back_project(depth: np.ndarray, camera: mujoco.MjvGLCamera) -> np.ndarray:
    """(H, W, 3) world points (m) of a depth image (H, W) (planar depth along the view axis, m,
    as ``mujoco.Renderer`` returns it; row 0 at the top), from the OpenGL camera that drew it:
    position, forward and up axes, frustum at the near plane. A mono picture is drawn from the
    average of the scene's two eyes (``mujoco.mjv_averageCamera(scene.camera[0],
    scene.camera[1])``; each eye sits half the inter-pupillary distance aside)."""
    height, width = depth.shape
    pos = np.asarray(camera.pos, dtype=np.float64)
    forward = np.asarray(camera.forward, dtype=np.float64)
    up = np.asarray(camera.up, dtype=np.float64)
    right = np.cross(forward, up)
    near = float(camera.frustum_near)
    bottom, top = float(camera.frustum_bottom), float(camera.frustum_top)
    half_width = float(camera.frustum_width) / 2.0 or 0.5 * (top - bottom) * width / height
    centre = float(camera.frustum_center)
    u = (np.arange(width) + 0.5) / width  # 0 left .. 1 right
    v = (np.arange(height) + 0.5) / height  # 0 top .. 1 bottom
    x = (centre + (2.0 * u - 1.0) * half_width) / near  # tangents at unit depth
    y = (top - v * (top - bottom)) / near
    rays = forward + x[None, :, None] * right + y[:, None, None] * up  # (H, W, 3)
    return pos + depth.astype(np.float64)[..., None] * rays


def _mesh_planes(model: mujoco.MjModel, geom: int) -> np.ndarray:
    """(F, 4) outward face planes ``n . x = d`` of a mesh geom's (convex) faces, geom frame."""
    mesh = int(model.geom_dataid[geom])
    v0, nv = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
    f0, nf = int(model.mesh_faceadr[mesh]), int(model.mesh_facenum[mesh])
    verts = np.asarray(model.mesh_vert[v0 : v0 + nv], dtype=np.float64)
    tri = verts[np.asarray(model.mesh_face[f0 : f0 + nf])]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(normal, axis=1)
    keep = norm > 1e-12
    normal = normal[keep] / norm[keep, None]
    d = np.sum(normal * tri[keep, 0], axis=1)
    inside = verts.mean(axis=0)
    flip = normal @ inside - d > 0.0  # orient every plane away from the hull's interior
    normal[flip] *= -1.0
    d[flip] *= -1.0
    return np.concatenate([normal, d[:, None]], axis=1)


def part_normals(
    model: mujoco.MjModel, data: mujoco.MjData, geom: int, points: np.ndarray
) -> np.ndarray:
    """(P, 3) unit outward normals of the faces of geom ``geom`` under ``points`` (P, 3) (world
    frame, on or near its surface): a box's nearest face, a cylinder's side or nearest cap, a
    convex mesh's active face (largest signed plane distance); other shapes: the direction from
    the geom's centre."""
    rotation = data.geom_xmat[geom].reshape(3, 3)
    local = (points - data.geom_xpos[geom]) @ rotation  # world -> geom frame
    kind = int(model.geom_type[geom])
    size = model.geom_size[geom]
    rows = np.arange(len(local))
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        gap = size[None, :3] - np.abs(local)  # distance to each face pair
        axis = np.argmin(gap, axis=1)
        normal = np.zeros_like(local)
        normal[rows, axis] = np.where(local[rows, axis] >= 0.0, 1.0, -1.0)
    elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        radial = np.linalg.norm(local[:, :2], axis=1)
        side = (size[0] - radial) < (size[1] - np.abs(local[:, 2]))
        normal = np.zeros_like(local)
        normal[:, :2] = local[:, :2] / np.maximum(radial, 1e-12)[:, None]
        normal[~side] = 0.0
        normal[~side, 2] = np.where(local[~side, 2] >= 0.0, 1.0, -1.0)
    elif kind == mujoco.mjtGeom.mjGEOM_MESH:
        planes = _mesh_planes(model, geom)
        active = np.argmax(local @ planes[:, :3].T - planes[:, 3], axis=1)
        normal = planes[active, :3]
    else:
        normal = local / np.maximum(np.linalg.norm(local, axis=1), 1e-12)[:, None]
    return normal @ rotation.T  # geom -> world frame


def offscreen_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    """:func:`dg16m_env.physics.replay.make_renderer`, falling back from ``MUJOCO_GL=egl`` to
    ``osmesa`` (software) when no EGL context can be made; the fallback sticks
    (``MUJOCO_GL`` is set to ``osmesa`` for the rest of the process).

    Raises:
        RenderError: neither backend works (both reasons in the message).
    """
    try:
        return make_renderer(model, height, width)
    except RenderError as egl_error:
        if os.environ.get("MUJOCO_GL", "").lower().strip() != "egl":
            raise
        os.environ["MUJOCO_GL"] = "osmesa"
        try:
            return make_renderer(model, height, width)
        except RenderError as osmesa_error:
            os.environ["MUJOCO_GL"] = "egl"
            raise RenderError(
                f"{egl_error}; the osmesa fallback failed too: {osmesa_error}"
            ) from None


def _close_all(box: list[mujoco.Renderer]) -> None:
    while box:
        box.pop().close()


class RendererSlot:
    """Holds one offscreen ``mujoco.Renderer``: closed when replaced, on :meth:`close`, when the
    slot is collected, and at interpreter exit while the GL modules still exist (a renderer
    left to the end of the interpreter's teardown fails to free its context, noisily)."""

    def __init__(self) -> None:
        self._box: list[mujoco.Renderer] = []
        self._finalizer = weakref.finalize(self, _close_all, self._box)

    @property
    def renderer(self) -> mujoco.Renderer | None:
        return self._box[0] if self._box else None

    def hold(self, renderer: mujoco.Renderer) -> mujoco.Renderer:
        """Hold ``renderer`` (closing the one held before); returns it."""
        _close_all(self._box)
        self._box.append(renderer)
        return renderer

    def close(self) -> None:
        """Close the renderer held (idempotent)."""
        _close_all(self._box)


def fixed_size(
    points: np.ndarray, normals: np.ndarray, n_points: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exactly ``n_points`` points: a random subset (without replacement, in random order) when
    there are more, all of them in random order then zero padding when there are fewer.

    Returns:
        ``points (n_points, 3)``, ``normals (n_points, 3)`` float32 and ``mask (n_points,)``
        float32 (1 = a real point, 0 = padding).
    """
    n = len(points)
    take = rng.choice(n, size=n_points, replace=False) if n > n_points else rng.permutation(n)
    out_points = np.zeros((n_points, 3), dtype=np.float32)
    out_normals = np.zeros((n_points, 3), dtype=np.float32)
    mask = np.zeros(n_points, dtype=np.float32)
    out_points[: take.size] = points[take]
    out_normals[: take.size] = normals[take]
    mask[: take.size] = 1.0
    return out_points, out_normals, mask


class DepthCameras:
    """Offscreen depth + segmentation cameras on one scene at a time (the renderer of the last
    scene is kept; a new object gets a new one).

    Args:
        resolution: image width and height (pixels, 16 to 960).

    Raises:
        RenderError: no offscreen OpenGL context, EGL or osmesa (:func:`offscreen_renderer`).
    """

    def __init__(self, resolution: int = 128) -> None:
        self.resolution = resolution
        self._slot = RendererSlot()
        self._object_id: str | None = None
        self._data: mujoco.MjData | None = None

    def _prepare(self, scene: Scene) -> tuple[mujoco.Renderer, mujoco.MjData]:
        renderer = self._slot.renderer
        if renderer is None or self._object_id != scene.object_id:
            self.close()
            model = scene.model
            data = mujoco.MjData(model)
            mujoco.mj_setState(model, data, initial_state(scene), STATE_SPEC)
            data.mocap_pos[scene.hand_mocap] = [[HANDS_AWAY, 0.0, 0.0], [-HANDS_AWAY, 0.0, 0.0]]
            mujoco.mj_forward(model, data)
            renderer = self._slot.hold(offscreen_renderer(model, self.resolution, self.resolution))
            self._data = data
            self._object_id = scene.object_id
        assert self._data is not None
        return renderer, self._data

    def look(
        self, scene: Scene, rng: np.random.Generator, n_cameras: int
    ) -> tuple[np.ndarray, np.ndarray, list[CameraPose]]:
        """Every object pixel of ``n_cameras`` cameras drawn from ``rng``, back-projected.

        Returns:
            ``points (P, 3)`` and ``normals (P, 3)`` float64 (object frame = world frame at the
            start of a trial, m) and the camera poses.
        """
        renderer, data = self._prepare(scene)
        view = default_camera(scene, data)
        radius = float(view.distance) / DISTANCE_FACTOR
        cameras = draw_cameras(rng, n_cameras, np.array(view.lookat), radius)
        object_geoms = np.asarray(scene.object_geoms)
        points, normals = [], []
        for pose in cameras:
            camera = pose.mjv_camera()
            renderer.update_scene(data, camera=camera)
            renderer.enable_depth_rendering()
            depth = renderer.render()
            renderer.disable_depth_rendering()
            renderer.enable_segmentation_rendering()
            segmentation = renderer.render()
            renderer.disable_segmentation_rendering()
            geom_ids = segmentation[..., 0]
            seen = (segmentation[..., 1] == mujoco.mjtObj.mjOBJ_GEOM) & np.isin(
                geom_ids, object_geoms
            )
            eyes = renderer.scene.camera  # mono rendering draws from the eyes' average
            world = back_project(depth, mujoco.mjv_averageCamera(eyes[0], eyes[1]))[seen]
            geoms = geom_ids[seen]
            normal = np.empty_like(world)
            for geom in np.unique(geoms):
                hit = geoms == geom
                normal[hit] = part_normals(scene.model, data, int(geom), world[hit])
            points.append(world)
            normals.append(normal)
        return np.concatenate(points), np.concatenate(normals), cameras

    def observe(
        self, scene: Scene, rng: np.random.Generator, n_points: int, n_cameras: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[CameraPose]]:
        """:meth:`look`, then :func:`fixed_size`: ``points``, ``normals`` (n_points, 3) and
        ``mask`` (n_points,), float32, and the camera poses."""
        points, normals, cameras = self.look(scene, rng, n_cameras)
        return (*fixed_size(points, normals, n_points, rng), cameras)

    def close(self) -> None:
        """Free the renderer (idempotent)."""
        self._slot.close()
        self._data = None
        self._object_id = None
