"""Dual-PointNetGPD: the DG16M paper's PointNetGPD baseline for dual-arm grasps (torch, CPU).

PointNetGPD (Liang et al. 2019) scores a single grasp from the object points near the gripper,
expressed in the grasp frame, with a PointNet (shared per-point MLP, max-pool, MLP). The paper's
dual version feeds both hands' crops, with a per-point hand indicator, through one PointNet.
Here, for one object and a dual grasp:

1. Centre: the cloud's centroid becomes the origin (points and pose translations), lengths are
   divided by ``length_scale`` (m). Scores are invariant to translating object and grasps.
2. Crop, per hand: the ``points_per_hand`` object points nearest to the hand's grasp centre
   (the point between the pads, ``(0, contact_depth, 0)`` in the grasp frame; ``crop="centre"``,
   the default and the fast one), or, with ``crop="template"``, nearest to the hand's gripper
   template (:func:`baselines.grasp_geometry.gripper_template`: distance from each object point
   to its nearest template point; about ``M`` = 22 times more distance work). Each crop is
   expressed in its own hand's grasp frame, relative to the grasp centre.
3. Features: one shared per-point MLP (``point_widths``, ReLU) over the union of both crops,
   max-pooled per hand: the hand indicator decides which hand's pool a point joins (feeding it
   as an input channel would make the score depend on the hands' order). The max over the union
   is the elementwise max of the two pools, which the symmetric pooling below contains.
4. Each hand's pooled feature is concatenated with its pose features
   (:func:`baselines.grasp_geometry.hand_pose_features`: the other hand and the centroid seen
   from this hand, the relative rotation, and, with ``gravity_feature``, gravity's direction:
   the object frame's -z is down in the benchmark's trials) and mapped by ``hand_widths``.
5. Symmetric pooling over the hands (``[h0 + h1, max(h0, h1)]``) and a head MLP to one logit.

No batch norm or dropout: train and eval modes compute the same function.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import torch
from torch import Tensor

from baselines.grasp_geometry import (
    MLP,
    PairClassifier,
    config_from_dict,
    config_to_dict,
    gather_points,
    grasp_centre_local,
    grasp_chunks,
    gripper_template,
    hand_pose_features,
    require,
    squared_distances,
    symmetric_pool,
    to_local,
    transform_points,
)

CropMode = Literal["centre", "template"]


@dataclass(frozen=True)
class DualPointNetGPDConfig:
    """Every hyper-parameter of :class:`DualPointNetGPD`.

    Attributes:
        seed: seed of the parameter initialisation (an explicit ``torch.Generator``).
        gripper: gripper model name (:data:`dataset_gen.grasps.gripper.GRIPPERS`).
        points_per_hand: K, object points cropped per hand. 128 of a 2048-point cloud of a
            0.3-1.2 m object is a ball of roughly 0.1-0.25 m around the grasp centre.
        crop: ``"centre"`` (nearest to the grasp centre) or ``"template"`` (nearest to the
            gripper template).
        length_scale: lengths are divided by it (m).
        point_widths: hidden widths of the shared per-point MLP (input 3: x, y, z).
        hand_widths: widths of the per-hand MLP after pooling (last = hand feature size).
        head_widths: hidden widths of the head (output: 1 logit).
        gravity_feature: give each hand gravity's direction in its frame (object -z).
        finger_rows: template rows along the fingers (``crop="template"`` only).
        palm_columns: template columns across the palm (``crop="template"`` only).
        chunk_size: grasps per chunk in a forward pass (bounds memory, not the result).
    """

    seed: int = 0
    gripper: str = "panda"
    points_per_hand: int = 128
    crop: CropMode = "centre"
    length_scale: float = 0.1
    point_widths: tuple[int, ...] = (32, 64, 128)
    hand_widths: tuple[int, ...] = (128,)
    head_widths: tuple[int, ...] = (64,)
    gravity_feature: bool = True
    finger_rows: int = 3
    palm_columns: int = 3
    chunk_size: int = 32

    def __post_init__(self) -> None:
        require(
            isinstance(self.seed, int) and self.seed >= 0,
            f"seed: expected an int >= 0, found {self.seed!r}",
        )
        require(
            isinstance(self.points_per_hand, int) and self.points_per_hand >= 1,
            f"points_per_hand: expected an int >= 1, found {self.points_per_hand!r}",
        )
        require(
            self.crop in ("centre", "template"),
            f"crop: expected 'centre' or 'template', found {self.crop!r}",
        )
        require(
            self.length_scale > 0,
            f"length_scale: expected > 0 m, found {self.length_scale!r}",
        )
        for field in ("point_widths", "hand_widths"):
            widths = getattr(self, field)
            require(
                len(widths) >= 1 and all(isinstance(w, int) and w >= 1 for w in widths),
                f"{field}: expected one or more positive ints, found {widths!r}",
            )
        require(
            all(isinstance(w, int) and w >= 1 for w in self.head_widths),
            f"head_widths: expected positive ints, found {self.head_widths!r}",
        )
        require(
            isinstance(self.chunk_size, int) and self.chunk_size >= 1,
            f"chunk_size: expected an int >= 1, found {self.chunk_size!r}",
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain values (tuples as lists), for checkpoints and JSON."""
        return config_to_dict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DualPointNetGPDConfig:
        """Inverse of :meth:`to_dict` (unknown keys refused)."""
        return config_from_dict(cls, data)


class DualPointNetGPD(PairClassifier):
    """Dual-arm PointNetGPD grasp-pair classifier (see the module docstring).

    ``forward(points (P, 3), poses (n, 2, 4, 4)) -> (n,)`` logits for one object;
    ``forward_batch(points (B, P, 3), poses (B, n, 2, 4, 4)) -> (B, n)`` for training.
    """

    name: str = "dual_pointnet_gpd"
    config_class: ClassVar[type] = DualPointNetGPDConfig

    def __init__(self, config: DualPointNetGPDConfig | None = None) -> None:
        super().__init__()
        self.config = config = config or DualPointNetGPDConfig()
        generator = torch.Generator().manual_seed(config.seed)
        self.point_mlp = MLP((3, *config.point_widths), generator, final_activation=True)
        pose_size = 18 if config.gravity_feature else 15
        self.hand_mlp = MLP(
            (config.point_widths[-1] + pose_size, *config.hand_widths),
            generator,
            final_activation=True,
        )
        self.head = MLP((2 * config.hand_widths[-1], *config.head_widths, 1), generator)
        self.register_buffer(
            "centre_local",
            torch.as_tensor(grasp_centre_local(config.gripper), dtype=torch.float32),
            persistent=False,
        )
        template = gripper_template(
            config.gripper, finger_rows=config.finger_rows, palm_columns=config.palm_columns
        )
        self.register_buffer(
            "template", torch.as_tensor(template, dtype=torch.float32), persistent=False
        )

    def crop(self, points: Tensor, poses: Tensor) -> Tensor:
        """Each hand's ``points_per_hand`` nearest object points in its grasp frame.

        Args:
            points: (B, P, 3) centred points (m).
            poses: (B, n, 2, 4, 4) centred poses.

        Returns:
            (B, n, 2, K, 3) points relative to each hand's grasp centre, in its grasp frame
            (m, not scaled); K = min(points_per_hand, P), nearest first.
        """
        b, n = poses.shape[:2]
        k = min(self.config.points_per_hand, points.shape[1])
        if self.config.crop == "centre":
            centres = transform_points(poses, self.centre_local[None])[..., 0, :]
            d2 = squared_distances(centres.reshape(b, n * 2, 3), points)
        else:
            anchors = transform_points(poses, self.template)  # (B, n, 2, M, 3)
            m = anchors.shape[-2]
            d2 = squared_distances(anchors.reshape(b, n * 2 * m, 3), points)
            d2 = d2.reshape(b, n * 2, m, -1).amin(dim=2)
        index = torch.topk(d2, k, dim=-1, largest=False, sorted=True).indices
        chosen = gather_points(points, index).reshape(b, n, 2, k, 3)
        return to_local(poses, chosen) - self.centre_local

    def score_centred(self, points: Tensor, poses: Tensor) -> Tensor:
        """(B, n) logits, the grasps scored in chunks of ``config.chunk_size``."""
        n = poses.shape[1]
        return torch.cat(
            [self._score(points, poses[:, s]) for s in grasp_chunks(n, self.config.chunk_size)],
            dim=1,
        )

    def _score(self, points: Tensor, poses: Tensor) -> Tensor:
        """(B, P, 3) centred points, (B, c, 2, 4, 4) centred poses -> (B, c) logits."""
        scale = self.config.length_scale
        local = self.crop(points, poses) / scale  # (B, c, 2, K, 3)
        pooled = self.point_mlp(local).amax(dim=-2)  # (B, c, 2, C)
        pose = hand_pose_features(
            poses, self.centre_local, scale, gravity=self.config.gravity_feature
        )
        hands = self.hand_mlp(torch.cat([pooled, pose], dim=-1))  # (B, c, 2, H)
        return self.head(symmetric_pool(hands))[..., 0]


__all__ = ["DualPointNetGPD", "DualPointNetGPDConfig"]
