"""A generative model of the hands of dual grasps given a point cloud: flow matching of one
hand's pose about an anchor point of the cloud (torch, CPU).

The model learns where the hands of the dataset's force-closure dual grasps go on an object given
what a pair of depth cameras sees of it (:func:`dg16m_env.training.grasp_dataset.partial_cloud`,
the cloud track's cameras and noise). The labels come from the full mesh, so a sample places a
hand where the *whole* object, seen or not, gives a passing grasp. It is the generator of
:mod:`baselines.flow_predictor` (which pairs the hands, checks the pairs on the cloud and ranks
them); :mod:`baselines.train_dual_grasp_flow` trains it.

Why one hand about an anchor, not both hands at once
----------------------------------------------------
A first model drew both hands as one 18-vector from a code of the whole cloud (the DAGDiff and
GraspGen formulation). After 1,798 training steps on the same data, 0.4% of its dual grasps on 20
real furniture objects had both hands holding a part once closed on the cloud, and 0.2% passed
force closure on the full mesh; with the same closing rules this model (without its
graspability head, after 2,268 steps) had 27% of its single hands holding a part on 30 real
objects. A code of the whole cloud does not place a hand to the centimetre an 8 cm opening
needs; anchoring each hand at a cloud point and giving the velocity field that point's
neighbourhood makes the placement local, and force closure between two hands is then checked on
the cloud for every pair of generated hands (``baselines/checkpoints/grasp-flow.md``).

Representation
--------------
A hand is a 9-vector: its grasp centre (between the pads, ``(0, contact_depth, 0)`` in the grasp
frame) minus its anchor, divided by ``patch_scale``, then its closing axis ``x`` and approach axis
``y`` (the dg16m grasp frame's first two columns). :func:`hands_to_vectors` and
:func:`vectors_to_hands` convert; the latter makes a rigid frame of any vector (Gram-Schmidt:
``y`` normalised, ``x`` made orthogonal to it, ``z = x cross y``), so every sample is a valid
pose. A hand turned half a turn about its approach axis is the same grasp written differently;
flow matching learns such multi-modal targets without an alignment step.

Network
-------
* the cloud's code: a PointNet (shared per-point MLP, max and mean pools, an MLP) over the
  cloud's first ``global_points`` points, centred on the cloud's centroid and divided by
  ``length_scale``;
* an anchor's code: a PointNet over its ``patch_points`` nearest points (relative to it, divided
  by ``patch_scale``), with the anchor's place in the cloud;
* the velocity field: an MLP of ``[x_t, time features, cloud code, anchor code]`` (time
  features: sines and cosines of ``t`` at ``time_frequencies`` octaves). Training (rectified
  flow / conditional flow matching, Lipman et al. 2023): ``x_0 ~ N(0, I)``, ``x_1`` a dataset
  hand, ``x_t = (1 - t) x_0 + t x_1``, ``t ~ U(0, 1)``, the loss the mean squared error of the
  velocity against ``x_1 - x_0``; sampling integrates ``dx/dt = v(x, t)`` with ``steps`` Euler
  steps;
* the graspability head: an MLP of the two codes to the logit that a grasp centre of a passing
  dual grasp lies within ``graspable_radius`` of the anchor (binary cross-entropy, trained with
  the flow); :mod:`baselines.flow_predictor` draws its anchors in proportion to it.

No batch norm or dropout: train and eval modes compute the same function. Randomness:
parameters from ``torch.Generator().manual_seed(config.seed)``; sampling noise from the
``generator`` the caller passes: the same seed and cloud give the same poses, bit for bit, on one
machine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import torch
from torch import Tensor, nn

from baselines.grasp_geometry import (
    MLP,
    config_from_dict,
    config_to_dict,
    gather_points,
    require,
    squared_distances,
)
from dataset_gen.grasps.gripper import get_gripper

HAND_SIZE = 9
"""Numbers per hand of :class:`AnchoredGraspFlow`: grasp centre offset (3), closing axis (3),
approach axis (3)."""


@dataclass(frozen=True)
class AnchoredGraspFlowConfig:
    """Every hyper-parameter of :class:`AnchoredGraspFlow`.

    Attributes:
        seed: seed of the parameter initialisation.
        gripper: gripper model name (its ``contact_depth`` places the grasp centre).
        length_scale: the cloud and the anchor's place in it are divided by it (m).
        patch_scale: the anchor's neighbourhood and the grasp centre's offset from the anchor
            are divided by it (m).
        patch_points: neighbours of the anchor in its patch.
        global_points: the cloud's code is made of its first this many points (a cloud in
            random order: a random subset; the patches use every point).
        point_widths: widths of the whole cloud's per-point MLP.
        patch_widths: widths of the patch's per-point MLP.
        condition_width: size of the cloud's code.
        hidden_widths: hidden widths of the velocity MLP.
        time_frequencies: octaves of the time features.
        steps: Euler steps of sampling.
        anchor_radius: a training hand whose grasp centre lies farther than this from every
            observed point has no anchor and is not used (m).
        graspable_radius: a cloud point is *graspable* (the anchor head's label) when the grasp
            centre of a hand of a passing dual grasp lies within this of it (m).
    """

    seed: int = 0
    gripper: str = "panda"
    length_scale: float = 0.25
    patch_scale: float = 0.05
    patch_points: int = 32
    global_points: int = 512
    point_widths: tuple[int, ...] = (64, 128, 256)
    patch_widths: tuple[int, ...] = (32, 64, 128)
    condition_width: int = 256
    hidden_widths: tuple[int, ...] = (384, 384, 384)
    time_frequencies: int = 8
    steps: int = 24
    anchor_radius: float = 0.04
    graspable_radius: float = 0.02

    def __post_init__(self) -> None:
        require(
            isinstance(self.seed, int) and self.seed >= 0,
            f"seed: expected an int >= 0, found {self.seed!r}",
        )
        for name in ("length_scale", "patch_scale", "anchor_radius", "graspable_radius"):
            value = getattr(self, name)
            require(
                isinstance(value, int | float) and value > 0,
                f"{name}: expected a number > 0 m, found {value!r}",
            )
        for name in ("point_widths", "patch_widths", "hidden_widths"):
            widths = getattr(self, name)
            require(
                len(widths) >= 1 and all(isinstance(w, int) and w >= 1 for w in widths),
                f"{name}: expected one or more positive ints, found {widths!r}",
            )
        for name in (
            "patch_points",
            "global_points",
            "condition_width",
            "time_frequencies",
            "steps",
        ):
            value = getattr(self, name)
            require(
                isinstance(value, int) and not isinstance(value, bool) and value >= 1,
                f"{name}: expected an int >= 1, found {value!r}",
            )
        get_gripper(self.gripper)

    def to_dict(self) -> dict[str, Any]:
        """Plain values (tuples as lists), for checkpoints and JSON."""
        return config_to_dict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> AnchoredGraspFlowConfig:
        """Inverse of :meth:`to_dict` (unknown keys refused)."""
        return config_from_dict(cls, data)


def hands_to_vectors(poses: Tensor, anchors: Tensor, contact_depth: float, scale: float) -> Tensor:
    """Hands as 9-vectors about their anchors: ``[(centre - anchor) / scale, x, y]``.

    Args:
        poses: (..., 4, 4) hand poses (m). anchors: (..., 3) anchor points (m).
        contact_depth: the gripper's ``contact_depth`` (m). scale: ``patch_scale`` (m).

    Returns:
        (..., 9).
    """
    centre = poses[..., :3, 3] + contact_depth * poses[..., :3, 1]
    return torch.cat([(centre - anchors) / scale, poses[..., :3, 0], poses[..., :3, 1]], dim=-1)


def vectors_to_hands(
    vectors: Tensor, anchors: Tensor, contact_depth: float, scale: float
) -> Tensor:
    """Inverse of :func:`hands_to_vectors` for any 9-vectors: the nearest rigid frames
    (module docstring).

    Args:
        vectors: (..., 9). anchors: (..., 3) m. contact_depth, scale: as
            :func:`hands_to_vectors`.

    Returns:
        (..., 4, 4) rigid hand poses (the dtype of ``vectors``).
    """
    centre = vectors[..., :3] * scale + anchors
    y_axis = nn.functional.normalize(vectors[..., 6:9], dim=-1, eps=1e-12)
    x_axis = vectors[..., 3:6]
    x_axis = x_axis - (x_axis * y_axis).sum(-1, keepdim=True) * y_axis
    x_axis = nn.functional.normalize(x_axis, dim=-1, eps=1e-12)
    poses = torch.zeros(*vectors.shape[:-1], 4, 4, dtype=vectors.dtype)
    poses[..., :3, 0], poses[..., :3, 1] = x_axis, y_axis
    poses[..., :3, 2] = torch.cross(x_axis, y_axis, dim=-1)
    poses[..., :3, 3] = centre - contact_depth * y_axis
    poses[..., 3, 3] = 1.0
    return poses


class AnchoredGraspFlow(nn.Module):
    """Flow matching of one hand about an anchor point of the cloud (module docstring): the
    velocity field sees the whole cloud's code, the anchor's patch (its ``patch_points`` nearest
    points) and the anchor's place in the cloud; a head scores anchors' graspability.

    ``loss(points (B, P, 3), hands (B, G, 4, 4), anchors (B, G), generator)`` for training;
    ``sample(points (P, 3), anchors (M,), generator) -> (M, 4, 4)`` for use.
    """

    name: str = "anchored_grasp_flow"
    config_class: ClassVar[type] = AnchoredGraspFlowConfig

    def __init__(self, config: AnchoredGraspFlowConfig | None = None) -> None:
        super().__init__()
        self.config = config = config or AnchoredGraspFlowConfig()
        generator = torch.Generator().manual_seed(config.seed)
        self.point_mlp = MLP((3, *config.point_widths), generator, final_activation=True)
        self.condition = MLP(
            (2 * config.point_widths[-1], config.condition_width), generator, final_activation=True
        )
        self.patch_mlp = MLP((3, *config.patch_widths), generator, final_activation=True)
        inputs = (
            HAND_SIZE
            + 2 * config.time_frequencies
            + config.condition_width
            + config.patch_widths[-1]
            + 3
        )
        self.velocity = MLP((inputs, *config.hidden_widths, HAND_SIZE), generator)
        self.anchor_head = MLP((inputs - HAND_SIZE - 2 * config.time_frequencies, 64, 1), generator)
        self.contact_depth = float(get_gripper(config.gripper).contact_depth)
        self.register_buffer(
            "frequencies",
            math.pi * 2.0 ** torch.arange(config.time_frequencies, dtype=torch.float32),
            persistent=False,
        )

    @property
    def model_dtype(self) -> torch.dtype:
        """The dtype inputs are converted to (the parameters')."""
        return next(self.parameters()).dtype

    def conditions(self, points: Tensor, anchors: Tensor) -> tuple[Tensor, Tensor]:
        """``(codes (B, G, C), anchor points (B, G, 3))`` of anchors (B, G) (indices into the
        clouds ``points`` (B, P, 3), m)."""
        config = self.config
        centroid = points.mean(dim=1)
        subset = points[:, : config.global_points]
        features = self.point_mlp((subset - centroid[:, None, :]) / config.length_scale)
        pooled = torch.cat([features.amax(dim=1), features.mean(dim=1)], dim=-1)
        code = self.condition(pooled)  # (B, C)
        anchor = gather_points(points, anchors)  # (B, G, 3)
        k = min(config.patch_points, points.shape[1])
        nearest = torch.topk(squared_distances(anchor, points), k, dim=-1, largest=False).indices
        patch = (gather_points(points, nearest) - anchor[..., None, :]) / config.patch_scale
        patch_code = self.patch_mlp(patch).amax(dim=-2)  # (B, G, Cp)
        b, g = anchors.shape
        place = (anchor - centroid[:, None, :]) / config.length_scale
        return torch.cat([code[:, None, :].expand(b, g, -1), patch_code, place], dim=-1), anchor

    def _velocity(self, x: Tensor, t: Tensor, condition: Tensor) -> Tensor:
        angles = t[..., None] * self.frequencies
        return self.velocity(torch.cat([x, torch.sin(angles), torch.cos(angles), condition], -1))

    def loss(
        self,
        points: Tensor,
        hands: Tensor,
        anchors: Tensor,
        generator: torch.Generator,
        candidates: Tensor | None = None,
        graspable: Tensor | None = None,
    ) -> Tensor:
        """The flow-matching loss of ``G`` anchored dataset hands per cloud, plus the anchor
        head's binary cross-entropy when ``candidates`` and ``graspable`` are given.

        Args:
            points: (B, P, 3) clouds (m).
            hands: (B, G, 4, 4) hands of passing dual grasps (m).
            anchors: (B, G) int64 indices of their anchors in ``points``.
            generator: draws ``t`` and the noise.
            candidates: (B, Q) int64 cloud indices whose graspability is learned.
            graspable: (B, Q) bool labels of ``candidates``.

        Returns:
            Scalar: mean squared velocity error (+ the head's mean cross-entropy).
        """
        dtype = self.model_dtype
        points = points.to(dtype)
        g = anchors.shape[1]
        both = anchors if candidates is None else torch.cat([anchors, candidates], dim=1)
        conditions, anchor = self.conditions(points, both)
        condition, anchor = conditions[:, :g], anchor[:, :g]
        target = hands_to_vectors(
            hands.to(dtype), anchor, self.contact_depth, self.config.patch_scale
        )
        noise = torch.randn(target.shape, generator=generator, dtype=dtype)
        t = torch.rand(target.shape[:2], generator=generator, dtype=dtype)
        x_t = (1.0 - t[..., None]) * noise + t[..., None] * target
        loss = ((self._velocity(x_t, t, condition) - (target - noise)) ** 2).mean()
        if candidates is not None and graspable is not None:
            logits = self.anchor_head(conditions[:, g:])[..., 0]
            loss = loss + nn.functional.binary_cross_entropy_with_logits(
                logits, graspable.to(dtype)
            )
        return loss

    @torch.no_grad()
    def anchor_probabilities(self, points: Tensor | np.ndarray) -> Tensor:
        """(P,) the head's probability that each point of the cloud ``points`` (P, 3) is
        graspable (within ``config.graspable_radius`` of a grasp centre)."""
        points = torch.as_tensor(np.asarray(points), dtype=self.model_dtype)
        every = torch.arange(len(points))[None]
        return torch.sigmoid(self.anchor_head(self.conditions(points[None], every)[0])[0, :, 0])

    @torch.no_grad()
    def sample(
        self, points: Tensor | np.ndarray, anchors: Tensor | np.ndarray, generator: torch.Generator
    ) -> Tensor:
        """One hand per anchor.

        Args:
            points: (P, 3) the cloud (object frame, m), P >= 1, finite.
            anchors: (M,) int indices into ``points``, M >= 1.
            generator: the only source of randomness.

        Returns:
            (M, 4, 4) rigid hand poses (grasp frame -> object frame, m), the model's dtype.

        Raises:
            ValueError: a cloud of another shape or with non-finite values, or bad anchors.
        """
        points = torch.as_tensor(np.asarray(points), dtype=self.model_dtype)
        if points.ndim != 2 or points.shape[1] != 3 or points.shape[0] < 1:
            raise ValueError(
                f"points: expected shape (P, 3) with P >= 1, found {tuple(points.shape)}"
            )
        if not bool(torch.isfinite(points).all()):
            raise ValueError("points: expected finite values, found NaN or inf")
        anchors = torch.as_tensor(np.asarray(anchors), dtype=torch.int64)
        if (
            anchors.ndim != 1
            or len(anchors) < 1
            or anchors.min() < 0
            or anchors.max() >= len(points)
        ):
            raise ValueError(
                f"anchors: expected (M,) indices in [0, {len(points)}) with M >= 1, found shape "
                f"{tuple(anchors.shape)}"
            )
        condition, anchor = self.conditions(points[None], anchors[None])
        dtype = self.model_dtype
        x = torch.randn((1, len(anchors), HAND_SIZE), generator=generator, dtype=dtype)
        steps = self.config.steps
        for k in range(steps):
            t = torch.full(x.shape[:2], k / steps, dtype=dtype)
            x = x + self._velocity(x, t, condition) / steps
        return vectors_to_hands(x[0], anchor[0], self.contact_depth, self.config.patch_scale)


__all__ = [
    "HAND_SIZE",
    "AnchoredGraspFlow",
    "AnchoredGraspFlowConfig",
    "hands_to_vectors",
    "vectors_to_hands",
]
