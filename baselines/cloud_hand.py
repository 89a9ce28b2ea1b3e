"""The Panda hand against what was observed of an object, for the cloud grasp sampler
(:mod:`baselines.cloud_grasps`; the steps named below are those of its docstring): hand poses that
put the fingers on two contacts (:func:`hand_poses`), whether an open hand has a cloud point inside
its palm or finger volumes (:func:`hand_hits_cloud`)
or a contact off its pad, and what depth cameras saw (:class:`DepthViews`), to test whether every
point of an open hand (:func:`hand_volume_points`) lies in space a camera saw empty
(:func:`hands_in_seen_free_space`). Units: metres; poses are the dg16m grasp frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from baselines.cloud_inputs import Cloud
from baselines.cloud_kernels import hands_hit_points
from dataset_gen.grasps.gripper import Box, GripperModel
from dataset_gen.grasps.sampling import _tangent_basis


def hand_poses(
    p0: np.ndarray,
    p1: np.ndarray,
    n0: np.ndarray,
    n1: np.ndarray,
    angles: np.ndarray,
    model: GripperModel,
) -> tuple[np.ndarray, np.ndarray]:
    """Hand poses putting finger 0 on ``p0`` and finger 1 on ``p1`` (step 2).

    Args:
        p0, p1: (S, 3) contacts (m). n0, n1: (S, 3) their unit outward normals.
        angles: (S, A) approach angles (rad) about the closing axis, measured from the first
            vector of :func:`dataset_gen.grasps.sampling._tangent_basis` of the axis.
        model: the gripper.

    Returns:
        ``poses (S, A, 4, 4)`` (grasp frame -> object frame, m) and ``widths (S,)`` jaw widths
        ``(p0 - p1) . x`` (m; may be <= 0 for pairs whose normals are not opposed).
    """
    x = n0 - n1
    x = x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300)
    b1, b2 = _tangent_basis(x)
    c, s = np.cos(angles)[..., None], np.sin(angles)[..., None]  # (S, A, 1)
    y = c * b1[:, None, :] + s * b2[:, None, :]
    z = c * b2[:, None, :] - s * b1[:, None, :]  # x cross y (b2 = x cross b1)
    centre = 0.5 * (p0 + p1)
    poses = np.zeros((*angles.shape, 4, 4))
    poses[..., :3, 0] = x[:, None, :]
    poses[..., :3, 1] = y
    poses[..., :3, 2] = z
    poses[..., :3, 3] = centre[:, None, :] - model.contact_depth * y
    poses[..., 3, 3] = 1.0
    widths = np.einsum("sk,sk->s", p0 - p1, x)
    return poses, widths


def hand_reach(model: GripperModel) -> float:
    """Radius (m) of a sphere about the grasp centre ``(0, contact_depth, 0)`` that holds the
    palm and both fully open fingers."""
    corners = np.concatenate([b.corners for b in model.collision_boxes(None)])
    return float(np.linalg.norm(corners - [0.0, model.contact_depth, 0.0], axis=1).max())


def hand_hits_cloud(
    points: np.ndarray | Cloud,
    poses: np.ndarray,
    contact_x: np.ndarray,
    model: GripperModel,
    tolerance: float,
    clearance: float = 0.0,
) -> np.ndarray:
    """Whether each hand pose has a cloud point inside its palm or finger volumes (step 3).

    Every point is tested against every pose in one compiled loop
    (:func:`baselines.cloud_kernels.hands_hit_points`) that stops at a hand's first hit: on a
    small object nearly every sampled hand hits it within its first few points.

    Args:
        points: (P, 3) cloud points (m), or a :class:`Cloud`.
        poses: (N, 4, 4) hand poses (grasp frame -> object frame, m).
        contact_x: (N, 2) the ``x`` of finger 0's and finger 1's contact in each pose's frame
            (m; ``+w/2`` and ``-w/2`` for a centred grasp).
        model: the gripper.
        tolerance: how far a point may reach into a volume (m).
        clearance: the volumes grown by this much (m) on every side but the fingers' inner
            (contact) faces: a sparse cloud has no point where a thin feature the hand would hit
            falls between its points.

    Returns:
        (N,) bool, True = the hand intersects the cloud: a point strictly inside the palm box
        grown by ``clearance - tolerance``, or within the fingers' footprint
        (``palm_depth - clearance <= y <= finger_tip + clearance``, ``|z| <= finger_width / 2 +
        clearance``) and past a finger's contact by more than ``tolerance`` out to its open
        outer face grown by ``clearance`` (``x <= max_opening / 2 + finger_thickness +
        clearance`` for finger 0, mirrored for finger 1).
    """
    pts = points.points if isinstance(points, Cloud) else np.asarray(points, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    contact_x = np.asarray(contact_x, dtype=np.float64)
    if len(poses) == 0:
        return np.zeros(0, dtype=bool)
    palm = model.palm_box()
    grow = clearance - tolerance
    palm_lo = np.asarray(palm.center) - np.asarray(palm.half_extents) - grow
    palm_hi = np.asarray(palm.center) + np.asarray(palm.half_extents) + grow
    foot_y = np.array([model.palm_depth - clearance, model.finger_tip + clearance])
    return hands_hit_points(
        np.ascontiguousarray(pts.reshape(-1, 3)),
        np.ascontiguousarray(poses.reshape(-1, 4, 4)),
        np.ascontiguousarray(contact_x.reshape(-1, 2)),
        palm_lo,
        palm_hi,
        foot_y,
        float(model.finger_width / 2.0 + clearance),
        float(model.max_opening / 2.0 + model.finger_thickness + clearance),
        float(tolerance),
    )


def _on_pads(local_contacts: np.ndarray, model: GripperModel, margin: float) -> np.ndarray:
    """(N,) whether both contacts (N, 2, 3) (grasp frame, m) lie on their pads."""
    y, z = local_contacts[..., 1], local_contacts[..., 2]
    ok = (y >= model.palm_depth + margin) & (y <= model.finger_tip - margin)
    ok &= np.abs(z) <= model.finger_width / 2.0 - margin
    return ok.all(axis=-1)


@dataclass(frozen=True)
class DepthViews:
    """What depth cameras saw, to tell space seen empty from space no camera saw into.

    Attributes:
        origins: (C, 3) camera positions (m, object frame).
        axes: (C, 3, 3) each camera's unit ``right``, ``up`` and ``forward`` axes (rows).
        tan_half: tangent of half the (square) field of view.
        distance: (C, R, R) float64 distance (m) from the camera to the first surface along
            each pixel's ray through its centre (row 0 at the top, column 0 at the left);
            ``inf`` where the ray hit nothing.
    """

    origins: np.ndarray
    axes: np.ndarray
    tan_half: float
    distance: np.ndarray

    @property
    def resolution(self) -> int:
        """Image side R (pixels)."""
        return int(self.distance.shape[-1])

    def seen_free(self, points: np.ndarray, margin: float) -> np.ndarray:
        """(Q,) bool: each of ``points`` (Q, 3) (m) lies in a camera's image at least ``margin``
        (m) in front of the surface its pixel saw (or where it saw nothing). A point no camera
        sees, or that every camera sees behind a surface, is not known to be free."""
        return self.occlusion_depth(points) < -margin

    def occlusion_depth(self, points: np.ndarray) -> np.ndarray:
        """(Q,) float64: for each of ``points`` (Q, 3) (m), the least over the cameras whose
        image holds it of (its distance from the camera - the distance its pixel saw): negative
        in front of the seen surface, positive behind it; ``-inf`` where a pixel saw nothing (seen
        empty), ``+inf`` where no image holds the point."""
        points = np.asarray(points, dtype=np.float64)
        rel = points[None, :, :] - self.origins[:, None, :]  # (C, Q, 3)
        cam = np.einsum("cij,cqj->cqi", self.axes, rel)
        forward = cam[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = cam[..., 0] / (forward * self.tan_half)
            v = cam[..., 1] / (forward * self.tan_half)
        r = self.resolution
        in_view = (forward > 0.0) & (np.abs(u) < 1.0) & (np.abs(v) < 1.0)
        col = np.clip(np.floor((np.where(in_view, u, 0.0) + 1.0) * r / 2.0), 0, r - 1)
        row = np.clip(np.floor((1.0 - np.where(in_view, v, 0.0)) * r / 2.0), 0, r - 1)
        camera = np.broadcast_to(np.arange(len(self.origins))[:, None], col.shape)
        seen = self.distance[camera, row.astype(np.int64), col.astype(np.int64)]
        with np.errstate(invalid="ignore"):
            depth = np.where(in_view, np.linalg.norm(rel, axis=-1) - seen, np.inf)
        return depth.min(axis=0)


def hand_volume_points(model: GripperModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points filling the open hand (grasp frame, m): ``palm (6 * 4 * 4, 3)``, ``finger 0
    (3 * 5 * 3, 3)`` and ``finger 1``, a grid over each collision box with its faces (the
    boxes of :meth:`~dataset_gen.grasps.gripper.GripperModel.collision_boxes` at full opening)."""

    def grid(box: Box, counts: tuple[int, int, int]) -> np.ndarray:
        lo = np.asarray(box.center) - np.asarray(box.half_extents)
        hi = np.asarray(box.center) + np.asarray(box.half_extents)
        axes = [np.linspace(lo[k], hi[k], counts[k]) for k in range(3)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)

    palm, finger0, finger1 = model.collision_boxes(None)
    return grid(palm, (6, 4, 4)), grid(finger0, (3, 5, 3)), grid(finger1, (3, 5, 3))


def hand_volume_in_object(poses: np.ndarray, model: GripperModel) -> np.ndarray:
    """(N, Q, 3) the points of :func:`hand_volume_points` (palm, finger 0, finger 1 in that
    order) of each open hand at ``poses`` (N, 4, 4), in the object frame (m)."""
    local = np.concatenate(hand_volume_points(model))
    return np.einsum("nij,qj->nqi", poses[:, :3, :3], local) + poses[:, None, :3, 3]


def hands_in_seen_free_space(
    views: DepthViews,
    poses: np.ndarray,
    model: GripperModel,
    margin: float,
    skip_finger: np.ndarray | None = None,
) -> np.ndarray:
    """(N,) bool: every point of each open hand (:func:`hand_volume_points`) at ``poses``
    (N, 4, 4) is seen free (:meth:`DepthViews.seen_free`).

    ``skip_finger`` (N, 2) bool leaves out finger 0's / finger 1's volume: that of a finger
    whose contact face was not seen and is assumed to face it (an enclosing grasp), so the
    space beyond that face is assumed empty too."""
    poses = np.asarray(poses, dtype=np.float64)
    n = len(poses)
    if n == 0:
        return np.zeros(0, dtype=bool)
    palm, finger0, finger1 = hand_volume_points(model)
    part = np.repeat([0, 1, 2], [len(palm), len(finger0), len(finger1)])
    world = hand_volume_in_object(poses, model)
    free = views.seen_free(world.reshape(-1, 3), margin).reshape(n, len(part))
    if skip_finger is not None:
        skip = np.asarray(skip_finger, dtype=bool)
        free |= (part[None, :] == 1) & skip[:, :1]
        free |= (part[None, :] == 2) & skip[:, 1:]
    return free.all(axis=1)


__all__ = [
    "DepthViews",
    "hand_hits_cloud",
    "hand_poses",
    "hand_reach",
    "hand_volume_in_object",
    "hand_volume_points",
    "hands_in_seen_free_space",
]
