"""Enclosing grasps on a cloud (steps 5-7 of the docstring of :mod:`baselines.cloud_grasps`, the
"module docstring" of the docstrings below), in the manner of GPD's candidates: the hand
approaches a cloud point against its normal (:func:`enclosing_poses`), its jaws hold the points
between its open fingers (:func:`enclose`), and per approached point the narrowest collision-free
closing axis is kept (:func:`sample_enclosing_grasps`); a contact whose normal points back
towards the other finger by more than :data:`MAX_BACK_FACING` is refused. They need one observed
side of a thin part, not two antipodal ones; :func:`~baselines.cloud_grasps.cloud_dual_candidates`
adds them with ``enclosing=True``.
"""

from __future__ import annotations

import math

import numpy as np

from baselines.cloud_hand import DepthViews, hand_hits_cloud, hands_in_seen_free_space
from baselines.cloud_inputs import Cloud, CloudSamplerConfig
from baselines.cloud_kernels import held_extremes
from dataset_gen.grasps.gripper import GripperModel, get_gripper
from dataset_gen.grasps.sampling import SingleArmGrasps, _tangent_basis

MAX_BACK_FACING = 0.5
"""An enclosing grasp's contact is refused when its normal points back towards the other finger
by more than this cosine (``n0 . x < -MAX_BACK_FACING`` for finger 0 at ``+x``): the part then
goes on, unseen, past where the finger would close."""


def enclosing_poses(
    points: np.ndarray, normals: np.ndarray, angles: np.ndarray, reach: float, model: GripperModel
) -> np.ndarray:
    """Hand poses approaching each point against its normal (step 5 of the module docstring).

    Args:
        points: (S, 3) approached points (m). normals: (S, 3) their unit outward normals.
        angles: (S, A) closing-axis angles (rad) about the approach, measured from the first
            vector of :func:`dataset_gen.grasps.sampling._tangent_basis` of the approach.
        reach: how far the fingertips pass the point along the approach (m).
        model: the gripper.

    Returns:
        (S, A, 4, 4) poses (grasp frame -> object frame, m): ``y = -normal``, ``x`` the closing
        axis, the point at ``(0, finger_tip - reach, 0)`` in the grasp frame.
    """
    y = -normals
    b1, b2 = _tangent_basis(y)
    c, s = np.cos(angles)[..., None], np.sin(angles)[..., None]
    x = c * b1[:, None, :] + s * b2[:, None, :]
    z = np.cross(x, np.broadcast_to(y[:, None, :], x.shape))
    poses = np.zeros((*angles.shape, 4, 4))
    poses[..., :3, 0] = x
    poses[..., :3, 1] = y[:, None, :]
    poses[..., :3, 2] = z
    poses[..., :3, 3] = points[:, None, :] - (model.finger_tip - reach) * y[:, None, :]
    poses[..., 3, 3] = 1.0
    return poses


def enclose(
    cloud: Cloud, poses: np.ndarray, model: GripperModel, *, pad_margin: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """What each hand pose's closing jaws would hold (step 6): the cloud points between its open
    fingers, ``palm_depth <= y <= finger_tip``, ``|z| <= finger_width / 2 - pad_margin``,
    ``|x| <= max_opening / 2`` in the grasp frame; the first contact of each finger is the
    held point farthest along ``+x`` (finger 0) and along ``-x`` (finger 1); of points at the
    same ``x``, finger 0's is the last in cloud order and finger 1's the first. Every point is
    tested against every pose in one compiled loop (:func:`baselines.cloud_kernels.held_extremes`).

    Args:
        cloud: the cloud.
        poses: (N, 4, 4) hand poses (m).
        model: the gripper.
        pad_margin: the held region is this much narrower than the pads (m).

    Returns:
        ``index (N, 2)`` int64 cloud indices of the two contacts (-1 when the pose holds fewer
        than two points) and ``local_x (N, 2)`` their ``x`` in the pose's frame (m).
    """
    poses = np.ascontiguousarray(np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4))
    return held_extremes(
        cloud.points,
        poses,
        float(model.palm_depth),
        float(model.finger_tip),
        float(model.finger_width / 2.0 - pad_margin),
        float(model.max_opening / 2.0),
    )


def sample_enclosing_grasps(
    cloud: Cloud,
    config: CloudSamplerConfig,
    rng: np.random.Generator,
    counts: dict[str, int] | None = None,
    views: DepthViews | None = None,
) -> SingleArmGrasps:
    """Single-arm enclosing grasps on a cloud (steps 5-7 of the module docstring).

    Args:
        cloud: the cloud.
        config: the parameters (``n_enclosing_seeds``, ``n_closing``, ``enclosing_reach``).
        rng: draws the seeds, then the closing-axis offsets.
        counts: receives ``enclosing_seeds``, ``enclosing_poses``, ``enclosing_held`` (poses whose
            jaws hold a part within the opening), ``enclosing_collision_free``, with ``views``
            ``enclosing_unseen_space``, and ``enclosing_grasps``.
        views: as for :func:`~baselines.cloud_grasps.sample_cloud_grasps`; the volume of a finger whose contact face was
            not seen is not tested (the face is assumed to face the finger, the space beyond it
            to be empty).

    Returns:
        :class:`~dataset_gen.grasps.sampling.SingleArmGrasps` (at most one per seed, its narrowest
        collision-free closing axis; at most ``max_grasps``); ``face_ids`` are the contacts'
        cloud indices; a contact normal is the cloud's where it lies in the friction cone about
        the closing axis, else the closing axis itself (the face the finger meets was not seen:
        it is assumed to face the finger).
    """
    model = get_gripper(config.gripper)
    counts = {} if counts is None else counts
    n_seeds = min(config.n_enclosing_seeds, cloud.n)
    seeds = rng.choice(cloud.n, size=n_seeds, replace=False)
    step = np.pi / config.n_closing
    angles = rng.random(n_seeds)[:, None] * step + step * np.arange(config.n_closing)
    poses = enclosing_poses(
        cloud.points[seeds], cloud.normals[seeds], angles, config.enclosing_reach, model
    ).reshape(-1, 4, 4)
    counts["enclosing_seeds"] = n_seeds
    counts["enclosing_poses"] = len(poses)
    index, local_x = enclose(cloud, poses, model, pad_margin=config.pad_margin)
    width = local_x[:, 0] - local_x[:, 1]
    x_axis = poses[:, :3, 0]
    n0 = cloud.normals[np.maximum(index[:, 0], 0)]
    n1 = cloud.normals[np.maximum(index[:, 1], 0)]
    facing0 = np.einsum("nk,nk->n", n0, x_axis)
    facing1 = -np.einsum("nk,nk->n", n1, x_axis)
    ok = (index[:, 0] >= 0) & (width > config.min_width) & (width <= config.max_width(model))
    ok &= (facing0 >= -MAX_BACK_FACING) & (facing1 >= -MAX_BACK_FACING)
    # At least one contact on a face seen to face its finger (within the friction cone about the
    # closing axis): jaws that would close on nothing but assumed faces were, on 60 procedural
    # objects, in the object at the start 48 times in 121 (30 in 483 with one face seen).
    cos_cone = math.cos(math.atan(config.mu))
    assumed_face = np.stack([facing0 < cos_cone, facing1 < cos_cone], axis=1)  # (N, 2)
    ok &= ~assumed_face.all(axis=1)
    # A held point at the edge of the opening: the part goes on past the open finger (the
    # collision test below would find it; this is the cheap test first).
    clearance = config.clearance_factor * cloud.spacing
    edge = model.max_opening / 2.0 - max(clearance, config.tolerance) - cloud.spacing
    ok &= (local_x[:, 0] < edge) & (local_x[:, 1] > -edge)
    counts["enclosing_held"] = int(ok.sum())
    centred = poses.copy()
    centred[:, :3, 3] += 0.5 * (local_x[:, 0] + local_x[:, 1])[:, None] * x_axis
    half = 0.5 * width
    rows = np.flatnonzero(ok)
    free = ~hand_hits_cloud(
        cloud,
        centred[rows],
        np.stack([half[rows], -half[rows]], axis=1),
        model,
        config.tolerance,
        clearance,
    )
    ok[rows] = free
    counts["enclosing_collision_free"] = int(ok.sum())
    if views is not None:
        rows = np.flatnonzero(ok)
        skip = assumed_face[rows] | (not config.free_space_fingers)
        ok[rows] = hands_in_seen_free_space(
            views, centred[rows], model, config.free_space_margin, skip
        )
        counts["enclosing_unseen_space"] = len(rows) - int(ok[rows].sum())
    per_seed = ok.reshape(n_seeds, config.n_closing)
    narrowest = np.argmin(np.where(ok, width, np.inf).reshape(n_seeds, -1), axis=1)
    keep = np.flatnonzero(per_seed.any(axis=1))[: config.max_grasps]
    chosen = keep * config.n_closing + narrowest[keep]
    counts["enclosing_grasps"] = len(chosen)
    x_chosen = x_axis[chosen]
    normals = np.stack([n0[chosen], n1[chosen]], axis=1)
    assumed = np.stack([x_chosen, -x_chosen], axis=1)
    normals = np.where(assumed_face[chosen][..., None], assumed, normals)
    return SingleArmGrasps(
        poses=centred[chosen].reshape(-1, 4, 4),
        contact_points=cloud.points[index[chosen]].reshape(-1, 2, 3),
        contact_normals=normals.reshape(-1, 2, 3),
        face_ids=index[chosen].reshape(-1, 2),
        widths=width[chosen],
        gripper=model.name,
        counts=dict(counts),
    )


__all__ = [
    "MAX_BACK_FACING",
    "enclose",
    "enclosing_poses",
    "sample_enclosing_grasps",
]
