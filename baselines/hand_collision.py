"""A learned check for open hands that would start inside parts no camera saw (issue 27).

A partial cloud has no back side, so :func:`baselines.cloud_grasps.hand_hits_cloud` passes hands
whose palm or fingers go into what the cameras did not see: on the procedural benchmark such
hands made 10-13% of the two-camera predictor's trials invalid, on real furniture 25%. Refusing
every hand that reaches into unseen space (``free_space=True``) removed more good hands than bad
ones. This module learns the risk instead, from the generated training objects, where the truth
is known: :func:`hand_features` describes what the cameras saw around one open hand, and
:class:`HandCollisionNet` maps it to the probability that the hand starts in the object
(deeper than the protocol's ``invalid_penetration``, the rule that makes a trial invalid).

Features of one hand at pose ``T`` (grasp frame, :mod:`dataset_gen.grasps.gripper`), ``F =
N_VOLUME + GRID ** 3`` float32 values:

* **visibility of the hand's volume** (``N_VOLUME`` = 186 values): for each point of
  :func:`baselines.cloud_grasps.hand_volume_points`, its occlusion depth
  (:meth:`DepthViews.occlusion_depth`: how far it lies behind the surface seen along its pixel,
  for the camera that sees it least occluded; negative in seen-empty space), clipped to
  ``+-DEPTH_SCALE`` and divided by it (``+1``: deep behind a seen surface or in no image);
* **the cloud around the hand** (``GRID ** 3`` = 216 values): occupancy (0/1) of a ``GRID`` cubed
  grid over the open hand's box grown by ``GRID_MARGIN`` on every side, in the hand's frame.

Training: ``python -m baselines.train_hand_collision`` (its docstring). Inference is numpy for
the features and one small MLP call; torch is imported only by :func:`load_hand_collision`.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from baselines.cloud_grasps import (
    Cloud,
    CloudError,
    DepthViews,
    hand_volume_in_object,
    hand_volume_points,
)
from dataset_gen.grasps.gripper import GripperModel, get_gripper

DEPTH_SCALE = 0.05
"""Occlusion depths are clipped to +-this (m) and divided by it."""

GRID = 6
"""Cells per side of the occupancy grid around a hand."""

GRID_MARGIN = 0.02
"""The grid covers the open hand's box grown by this on every side (m)."""

HIDDEN = (256, 128)
"""Hidden layer widths of :class:`HandCollisionNet`."""


def hand_grid_bounds(model: GripperModel) -> np.ndarray:
    """(2, 3) lower and upper corner (grasp frame, m) of the occupancy grid: the open hand's
    collision boxes' bounding box grown by :data:`GRID_MARGIN`."""
    corners = np.concatenate([box.corners for box in model.collision_boxes(None)])
    return np.stack([corners.min(axis=0) - GRID_MARGIN, corners.max(axis=0) + GRID_MARGIN])


def n_features(model: GripperModel | None = None) -> int:
    """F, the length of one hand's feature vector."""
    model = model or get_gripper("panda")
    return sum(len(p) for p in hand_volume_points(model)) + GRID**3


def hand_features(
    cloud: Cloud, views: DepthViews, poses: np.ndarray, model: GripperModel | None = None
) -> np.ndarray:
    """(N, 2, F) float32 features of both open hands of each dual grasp (module docstring).

    Args:
        cloud: the observed cloud (object frame, m).
        views: the depth views it came from.
        poses: (N, 2, 4, 4) dual grasps (object frame, m).
        model: the gripper (default Panda).
    """
    model = model or get_gripper("panda")
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 4 or poses.shape[1:] != (2, 4, 4):
        raise CloudError(f"poses: expected shape (N, 2, 4, 4), found {poses.shape}")
    n = len(poses)
    hands = poses.reshape(-1, 4, 4)
    world = hand_volume_in_object(hands, model)
    depth = views.occlusion_depth(world.reshape(-1, 3)).reshape(world.shape[:2])
    visibility = np.clip(depth, -DEPTH_SCALE, DEPTH_SCALE) / DEPTH_SCALE
    occupancy = np.zeros((len(hands), GRID**3), dtype=np.float32)
    if len(hands):
        lo, hi = hand_grid_bounds(model)
        centre_local = (lo + hi) / 2.0
        radius = float(np.linalg.norm(hi - lo)) / 2.0
        centres = np.einsum("nij,j->ni", hands[:, :3, :3], centre_local) + hands[:, :3, 3]
        near = cloud.tree.query_ball_point(centres, radius)
        counts = np.fromiter((len(ix) for ix in near), dtype=np.int64, count=len(hands))
        if counts.sum():
            hand = np.repeat(np.arange(len(hands)), counts)
            point = np.concatenate([np.asarray(ix, dtype=np.int64) for ix in near if len(ix)])
            rel = cloud.points[point] - hands[hand, :3, 3]
            local = np.einsum("nji,nj->ni", hands[hand, :3, :3], rel)  # R^T (p - t)
            cell = np.floor((local - lo) / (hi - lo) * GRID).astype(np.int64)
            inside = np.all((cell >= 0) & (cell < GRID), axis=1)
            flat = (cell[:, 0] * GRID + cell[:, 1]) * GRID + cell[:, 2]
            occupancy[hand[inside], flat[inside]] = 1.0
    features = np.concatenate([visibility.astype(np.float32), occupancy], axis=1)
    return features.reshape(n, 2, -1)


@dataclass(frozen=True)
class HandCollisionModel:
    """A trained :class:`HandCollisionNet` with the settings it was trained for."""

    net: Any
    metadata: dict[str, Any]

    def probability(self, features: np.ndarray) -> np.ndarray:
        """(...,) float64 probability that each hand of ``features`` (..., F) starts in the
        object."""
        import torch

        features = np.asarray(features, dtype=np.float32)
        shape = features.shape[:-1]
        with torch.no_grad():
            logits = self.net(torch.from_numpy(features.reshape(-1, features.shape[-1])))
        return torch.sigmoid(logits).to(torch.float64).numpy().reshape(shape)


def make_net(n_in: int) -> Any:
    """:class:`HandCollisionNet`: an MLP ``n_in -> HIDDEN -> 1`` (logit), ReLU."""
    import torch
    from torch import nn

    class HandCollisionNet(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            widths = (n_in, *HIDDEN)
            layers: list[nn.Module] = []
            for a, b in itertools.pairwise(widths):
                layers += [nn.Linear(a, b), nn.ReLU()]
            layers.append(nn.Linear(widths[-1], 1))
            self.layers = nn.Sequential(*layers)

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            return self.layers(x).squeeze(-1)

    return HandCollisionNet()


@functools.lru_cache(maxsize=2)
def load_hand_collision(path: str) -> HandCollisionModel:
    """The model of a checkpoint written by :mod:`baselines.train_hand_collision`, cached.

    Raises:
        CloudError: the file is not such a checkpoint or was made for other features.
    """
    import pickle

    import torch

    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except (OSError, RuntimeError, ValueError, EOFError, pickle.UnpicklingError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CloudError(f"{path}: expected a hand-collision checkpoint, found {first}") from None
    meta = data.get("metadata") if isinstance(data, dict) else None
    if not isinstance(meta, dict) or meta.get("kind") != "hand-collision":
        what = f"kind {meta.get('kind')!r}" if isinstance(meta, dict) else "no metadata"
        raise CloudError(f"{path}: expected a hand-collision checkpoint, found {what}")
    expected = {"n_features": n_features(), "grid": GRID, "depth_scale": DEPTH_SCALE}
    found = {k: meta.get(k) for k in expected}
    if found != expected:
        raise CloudError(f"{path}: expected features {expected}, found {found}")
    net = make_net(int(meta["n_features"]))
    net.load_state_dict(data["state_dict"])
    net.eval()
    return HandCollisionModel(net=net, metadata=meta)


__all__ = [
    "DEPTH_SCALE",
    "GRID",
    "GRID_MARGIN",
    "HIDDEN",
    "HandCollisionModel",
    "hand_features",
    "hand_grid_bounds",
    "load_hand_collision",
    "make_net",
    "n_features",
]
