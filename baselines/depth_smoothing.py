"""Smoothing a depth camera's noisy depth before its cloud is used (issue 59).

The cloud track's sensor (:mod:`dg16m_env.subjects.cloud_observation`) drops pixels at grazing
angles and at depth edges and adds axial noise of about 1-2.5 mm to the others. The axial noise
alone costs the learned predictor nothing and the missing pixels about half of what the two
cost together: hands that start inside the object (measured in ``baselines/RESULTS.md``). :func:`smooth_depth` replaces each pixel's depth by
the plane fitted to its neighbours (a moving-least-squares step along the pixel's ray): within a
``(2 radius + 1)`` square window, the neighbours that saw something within ``gate_sigmas`` times
the axial noise of the pixel's depth; the pixel moves onto the plane along its ray only when the
move is within ``accept_sigmas`` noise levels (a corner or an edge, where the plane is wrong,
stays as seen). Normals are then estimated from the smoothed image as the harness estimates
them (:func:`~dg16m_env.subjects.cloud_observation.estimate_normals`, a 3 x 3 plane fit).
:func:`smoothed_observation` applies it to every camera of a cloud-track observation and
rebuilds its ``points`` and ``normals`` pixel by pixel (the ``pixels`` key); every other key is
kept. Units: metres; pixels as the observation's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from baselines.cloud_grasps import CloudError
from dg16m_env.subjects.cloud_observation import (
    AXIAL_SIGMA,
    back_project,
    estimate_normals,
    window_shifts,
)


@dataclass(frozen=True)
class DepthSmoothing:
    """Parameters of :func:`smooth_depth`.

    Attributes:
        radius: half side of the square window (pixels; 2 = 5 x 5).
        gate_sigmas: a neighbour counts when its depth is within this many noise levels of the
            pixel's (and at least 1 mm).
        min_count: neighbours (the pixel included) needed to fit a plane.
        accept_sigmas: the pixel moves onto the plane only when the move along its ray is within
            this many noise levels.
        axial_sigma: ``(a, b, z0)`` of the sensor's axial noise ``a + b (z - z0)^2`` (m): the
            cloud track's documented Kinect-like model unless another sensor is meant.
    """

    radius: int = 2
    gate_sigmas: float = 4.0
    min_count: int = 4
    accept_sigmas: float = 3.0
    axial_sigma: tuple[float, float, float] = AXIAL_SIGMA

    def __post_init__(self) -> None:
        if not (isinstance(self.radius, int) and 1 <= self.radius <= 5):
            raise CloudError(f"radius: expected an integer in [1, 5] pixels, found {self.radius!r}")
        if not (isinstance(self.min_count, int) and self.min_count >= 3):
            raise CloudError(f"min_count: expected an integer >= 3, found {self.min_count!r}")
        for name in ("gate_sigmas", "accept_sigmas"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and np.isfinite(value) and value > 0.0):
                raise CloudError(f"{name}: expected a positive number, found {value!r}")

    def sigma(self, depth: np.ndarray) -> np.ndarray:
        """The axial noise (m) at each depth (m)."""
        a, b, z0 = self.axial_sigma
        return a + b * (np.asarray(depth, dtype=np.float64) - z0) ** 2


def smooth_depth(
    depth: np.ndarray, intrinsics: np.ndarray, config: DepthSmoothing = DepthSmoothing()
) -> np.ndarray:
    """One depth image smoothed (module docstring).

    Args:
        depth: (H, W) depth along the optical axis (m; 0 = missing).
        intrinsics: (3, 3) pinhole matrix K (pixels).
        config: the window and the gates.

    Returns:
        (H, W) float64 depth: the same pixels missing (0), the others on their local plane where
        it fits.
    """
    depth = np.asarray(depth, dtype=np.float64)
    seen = depth > 0.0
    points = back_project(depth, np.asarray(intrinsics, dtype=np.float64))  # (H, W, 3)
    near = window_shifts(depth, config.radius)  # (S, H, W)
    gate = np.maximum(config.gate_sigmas * config.sigma(depth), 1e-3)
    weight = ((near > 0.0) & (np.abs(near - depth) <= gate) & seen).astype(np.float64)
    count = weight.sum(axis=0)
    fit = seen & (count >= config.min_count)
    out = depth.copy()
    if not fit.any():
        return out
    w = weight[:, fit]  # (S, N)
    p = window_shifts(points, config.radius)[:, fit]  # (S, N, 3)
    mean = np.einsum("sn,sni->ni", w, p) / count[fit][:, None]
    d = p - mean
    cov = np.einsum("sn,sni,snj->nij", w, d, d)
    _, vectors = np.linalg.eigh(cov)
    normal = vectors[:, :, 0]  # the least-spread direction
    ray = points[fit] / depth[fit][:, None]  # (N, 3), z = 1
    along = np.einsum("ni,ni->n", normal, ray)
    steep = np.abs(along) < 0.2 * np.linalg.norm(ray, axis=1)  # ray nearly in the plane
    moved = np.einsum("ni,ni->n", normal, mean) / np.where(steep, 1.0, along)
    keep = ~steep & (np.abs(moved - depth[fit]) <= config.accept_sigmas * config.sigma(depth[fit]))
    out[fit] = np.where(keep, moved, depth[fit])
    return out


def smoothed_observation(
    observation: dict[str, Any], config: DepthSmoothing = DepthSmoothing()
) -> dict[str, Any]:
    """A cloud-track observation with every camera's depth smoothed (module docstring).

    Returns:
        A new dict: ``depth`` smoothed, ``points`` back-projected from it and ``normals``
        estimated from it (float32, the rows of ``pixels``, object frame); other keys as given.

    Raises:
        CloudError: without ``depth``, ``intrinsics``, ``camera_poses`` and ``pixels`` of
            matching shapes, or with depths that are negative or not finite.
    """
    needed = ("depth", "intrinsics", "camera_poses", "pixels", "points")
    missing = [k for k in needed if k not in observation]
    if missing:
        raise CloudError(f"observation: expected keys {missing}, found {sorted(observation)}")
    depth = np.asarray(observation["depth"], dtype=np.float64)
    k = np.asarray(observation["intrinsics"], dtype=np.float64)
    poses = np.asarray(observation["camera_poses"], dtype=np.float64)
    pixels = np.asarray(observation["pixels"])
    n = len(np.asarray(observation["points"]))
    if depth.ndim != 3 or k.shape != (3, 3) or poses.shape != (len(depth), 4, 4):
        raise CloudError(
            "observation depth/intrinsics/camera_poses: expected (C, H, W), (3, 3) and "
            f"(C, 4, 4), found {depth.shape}, {k.shape} and {poses.shape}"
        )
    if pixels.shape != (n, 3) or not np.issubdtype(pixels.dtype, np.integer):
        raise CloudError(
            f"observation pixels: expected ({n}, 3) integers (one row per point), found "
            f"{pixels.shape} {pixels.dtype}"
        )
    if not np.isfinite(depth).all() or (depth < 0.0).any():
        raise CloudError("observation depth: expected finite depths >= 0 m, found others")
    c, h, w = depth.shape
    inside = (pixels >= 0).all(axis=1) & (pixels < np.array([c, h, w])).all(axis=1)
    if not inside.all() or not (depth[tuple(pixels.T)] > 0.0).all():
        raise CloudError(
            f"observation pixels: expected (camera, row, column) of seen pixels of depth "
            f"{depth.shape}, found {int((~inside).sum())} outside it or on missing pixels"
        )
    points = np.zeros((c, h, w, 3))
    normals = np.zeros((c, h, w, 3))
    smoothed = np.zeros_like(depth)
    for cam in range(c):
        smoothed[cam] = smooth_depth(depth[cam], k, config)
        local = back_project(smoothed[cam], k)
        rotation, position = poses[cam, :3, :3], poses[cam, :3, 3]
        points[cam] = local @ rotation.T + position
        normals[cam] = estimate_normals(local, smoothed[cam]) @ rotation.T
    index = tuple(pixels.T)
    return {
        **observation,
        "depth": smoothed.astype(np.float32),
        "points": np.ascontiguousarray(points[index], dtype=np.float32),
        "normals": np.ascontiguousarray(normals[index], dtype=np.float32),
    }


__all__ = ["DepthSmoothing", "smooth_depth", "smoothed_observation"]
