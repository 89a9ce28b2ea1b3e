"""CGDF-Classifier: a neural-descriptor-field grasp-pair classifier with rotation-equivariant
vector-neuron features (torch, CPU).

In the spirit of CGDF / Neural Descriptor Fields (Simeonov et al. 2022), whose object encoder is
a Vector Neuron network (Deng et al. 2021): an SO(3)-equivariant encoder turns the object's
cloud into a continuous field of equivariant features; a grasp is described by the field's
invariant values at gripper template points moved to the grasp pose; a head scores the pair.

Vector neurons
--------------
A VN feature is a list of C 3-vectors, stored channel-last as (..., 3, C), so a rotation R acts
as ``R @ x`` on the 3-axis and a linear layer is ``x @ W^T`` on the C-axis.

* :class:`VNLinear` ``x W^T`` (no bias): equivariant.
* :class:`VNLeakyReLU`: a learned direction ``k = x U^T`` per channel; the part of ``x`` pointing
  against ``k`` is projected out (``x - <x,k>/|k|^2 k`` where ``<x,k> < 0``), mixed with ``x`` by
  the negative slope: equivariant.
* :func:`vn_max_pool`: per channel, the member whose vector has the largest ``<x, x W^T>``;
  mean pooling is equivariant as is.

Encoder (once per object)
-------------------------
Centred cloud (centroid at the origin), lengths in ``length_scale`` units.

1. Anchors: ``n_anchors`` points by farthest point sampling, started at the point farthest from
   the centroid (depends only on distances: rotation invariant).
2. Edge layer (VN-DGCNN-lite): for each anchor a and each of its ``edge_k`` nearest cloud points
   p, the three vectors ``(p - a, a, p x a)`` -> VNLinear -> VN-LeakyReLU, mean over the
   neighbours: (S, 3, C1) local features.
3. VN-PointNet on the anchors: two VNLinear + VN-LeakyReLU blocks (C1 -> C2 -> C3); a global
   feature ``[VN max pool, mean pool]`` (3, 2 C3).
4. Per-anchor field features ``F`` (S, 3, C) from ``[local, deep, global]`` by a VN block and a
   VNLinear.

Field query (per grasp: the only per-grasp work)
------------------------------------------------
For every template point q of each hand (:func:`baselines.grasp_geometry.gripper_template`, 22
points by default) moved by the hand's pose:

* the ``field_k + 1`` nearest anchors; interpolation weights
  ``w_i ∝ 1/(d_i + eps) - 1/(d_{k+1} + eps)`` for the k nearest (the field stays continuous when
  the neighbour set changes) give the field value ``F(q) = sum w_i F_i`` and the local surface
  point ``s(q) = sum w_i a_i``;
* the VN vector list ``x(q) = [F(q), q - s(q), q]`` (C + 2 channels) is made invariant NDF-style
  by inner products of two learned linear maps: ``inv_d = <x A_d^T, x B_d^T>``, d = 1..D, plus
  ``|q - s(q)|`` (D + 1 numbers). The maps of ``F`` are linear, so they are applied to the
  anchors once per object and only gathered per query.

The hand's descriptor (M (D + 1) numbers, in template order, which pins the pose) with its pose
features (:func:`baselines.grasp_geometry.hand_pose_features`: relative pose of the other
hand, the centroid seen from the hand) goes through ``hand_widths``; the two hands are pooled
symmetrically (``[h0 + h1, max(h0, h1)]``) and a head gives one logit.

Invariance: translating object and grasps together (centring) and rotating them together about
the centroid (every step above is equivariant or invariant) leave the score unchanged, up to
rounding and up to exact ties in nearest-neighbour ranks (measure zero). With
``gravity_feature=True`` the hands also see gravity's direction (object -z): then only rotations
about the vertical axis leave the score unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor, nn

from baselines.grasp_geometry import (
    MLP,
    PairClassifier,
    config_from_dict,
    config_to_dict,
    farthest_point_indices,
    gather_points,
    grasp_centre_local,
    grasp_chunks,
    gripper_template,
    grouped_knn,
    hand_pose_features,
    knn,
    require,
    symmetric_pool,
    transform_points,
    uniform_parameter,
)

VN_EPS = 1e-6
"""Added to squared norms in VN-LeakyReLU (an invariant, so equivariance is exact)."""


# --------------------------------------------------------------------------------------------
# Vector-neuron layers (features (..., 3, C))
# --------------------------------------------------------------------------------------------


class VNLinear(nn.Module):
    """Vector-neuron linear map: (..., 3, C_in) -> (..., 3, C_out), ``x W^T`` (no bias)."""

    def __init__(self, c_in: int, c_out: int, generator: torch.Generator) -> None:
        super().__init__()
        self.weight = uniform_parameter((c_out, c_in), 1.0 / math.sqrt(c_in), generator)

    def forward(self, x: Tensor) -> Tensor:
        """(..., 3, C_in) -> (..., 3, C_out)."""
        return x @ self.weight.t()


class VNLeakyReLU(nn.Module):
    """Vector-neuron leaky ReLU with a learned direction per channel: (..., 3, C) -> same."""

    def __init__(self, channels: int, negative_slope: float, generator: torch.Generator) -> None:
        super().__init__()
        self.direction = VNLinear(channels, channels, generator)
        self.negative_slope = negative_slope

    def forward(self, x: Tensor) -> Tensor:
        """(..., 3, C) -> (..., 3, C)."""
        k = self.direction(x)
        dot = (x * k).sum(dim=-2, keepdim=True)
        projected = x - dot / (k.square().sum(dim=-2, keepdim=True) + VN_EPS) * k
        out = torch.where(dot >= 0, x, projected)
        return self.negative_slope * x + (1.0 - self.negative_slope) * out


class VNBlock(nn.Module):
    """VNLinear followed by VNLeakyReLU: (..., 3, C_in) -> (..., 3, C_out)."""

    def __init__(
        self, c_in: int, c_out: int, negative_slope: float, generator: torch.Generator
    ) -> None:
        super().__init__()
        self.linear = VNLinear(c_in, c_out, generator)
        self.activation = VNLeakyReLU(c_out, negative_slope, generator)

    def forward(self, x: Tensor) -> Tensor:
        """(..., 3, C_in) -> (..., 3, C_out)."""
        return self.activation(self.linear(x))


class VNMaxPool(nn.Module):
    """Vector-neuron max pooling over a set axis: per channel, the member with the largest
    ``<x, x W^T>``."""

    def __init__(self, channels: int, generator: torch.Generator) -> None:
        super().__init__()
        self.direction = VNLinear(channels, channels, generator)

    def forward(self, x: Tensor, dim: int) -> Tensor:
        """``x`` (..., N, ..., 3, C) with the set axis ``dim`` (negative, before the 3-axis)
        -> the same without that axis."""
        return vn_max_pool(x, self.direction(x), dim)


def vn_max_pool(x: Tensor, key: Tensor, dim: int) -> Tensor:
    """Select, per channel, the member of the set axis ``dim`` maximising ``<x, key>``.

    Args:
        x: (..., N, ..., 3, C) features.
        key: same shape, the equivariant directions.
        dim: negative index of the set axis (before the last two axes).

    Returns:
        ``x`` without the set axis.
    """
    score = (x * key).sum(dim=-2, keepdim=True)  # (..., N, ..., 1, C)
    shape = list(x.shape)
    shape[dim] = 1
    index = score.argmax(dim=dim, keepdim=True).expand(shape)
    return x.gather(dim, index).squeeze(dim)


# --------------------------------------------------------------------------------------------
# Configuration
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CGDFConfig:
    """Every hyper-parameter of :class:`CGDFClassifier`.

    Attributes:
        seed: seed of the parameter initialisation (an explicit ``torch.Generator``).
        gripper: gripper model name (:data:`dataset_gen.grasps.gripper.GRIPPERS`).
        length_scale: lengths are divided by it (m).
        n_anchors: S, cloud points carrying field features (farthest point sampling).
        edge_k: cloud neighbours of each anchor in the edge layer.
        encoder_channels: (C1, C2, C3) VN channels of the edge layer and the two VN-PointNet
            blocks.
        feature_channels: C, VN channels of the field.
        field_k: anchors interpolated per query point.
        field_candidates: anchors kept per hand before its queries' exact nearest-anchor
            search (:func:`baselines.grasp_geometry.grouped_knn`; speed only, same result).
        invariant_channels: D, invariant inner products per query point.
        interpolation_eps: eps of the inverse-distance weights (m).
        negative_slope: of the VN leaky ReLUs.
        finger_rows: template rows along the fingers.
        palm_columns: template columns across the palm.
        hand_widths: widths of the per-hand MLP (last = hand feature size).
        head_widths: hidden widths of the head (output: 1 logit).
        gravity_feature: give each hand gravity's direction (object -z) in its frame; breaks
            invariance to rotations other than about z.
        chunk_size: grasps per chunk in a forward pass (bounds memory, not the result).
    """

    seed: int = 0
    gripper: str = "panda"
    length_scale: float = 0.1
    n_anchors: int = 256
    edge_k: int = 16
    encoder_channels: tuple[int, int, int] = (32, 32, 64)
    feature_channels: int = 32
    field_k: int = 4
    field_candidates: int = 48
    invariant_channels: int = 16
    interpolation_eps: float = 0.001
    negative_slope: float = 0.2
    finger_rows: int = 3
    palm_columns: int = 3
    hand_widths: tuple[int, ...] = (128,)
    head_widths: tuple[int, ...] = (64,)
    gravity_feature: bool = False
    chunk_size: int = 256

    def __post_init__(self) -> None:
        for field in (
            "n_anchors",
            "edge_k",
            "feature_channels",
            "field_k",
            "field_candidates",
            "invariant_channels",
            "chunk_size",
        ):
            value = getattr(self, field)
            require(
                isinstance(value, int) and value >= 1,
                f"{field}: expected an int >= 1, found {value!r}",
            )
        require(
            isinstance(self.seed, int) and self.seed >= 0,
            f"seed: expected an int >= 0, found {self.seed!r}",
        )
        require(
            len(self.encoder_channels) == 3
            and all(isinstance(c, int) and c >= 1 for c in self.encoder_channels),
            f"encoder_channels: expected three positive ints, found {self.encoder_channels!r}",
        )
        require(
            len(self.hand_widths) >= 1
            and all(isinstance(w, int) and w >= 1 for w in self.hand_widths),
            f"hand_widths: expected one or more positive ints, found {self.hand_widths!r}",
        )
        require(
            all(isinstance(w, int) and w >= 1 for w in self.head_widths),
            f"head_widths: expected positive ints, found {self.head_widths!r}",
        )
        require(self.length_scale > 0, f"length_scale: expected > 0 m, found {self.length_scale!r}")
        require(
            self.interpolation_eps > 0,
            f"interpolation_eps: expected > 0 m, found {self.interpolation_eps!r}",
        )
        require(
            0.0 <= self.negative_slope < 1.0,
            f"negative_slope: expected a value in [0, 1), found {self.negative_slope!r}",
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain values (tuples as lists), for checkpoints and JSON."""
        return config_to_dict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CGDFConfig:
        """Inverse of :meth:`to_dict` (unknown keys refused)."""
        return config_from_dict(cls, data)


# --------------------------------------------------------------------------------------------
# Model
# --------------------------------------------------------------------------------------------


@dataclass
class ObjectField:
    """What the encoder computes once per object (centred, in ``length_scale`` units).

    Attributes:
        anchors: (B, S, 3) anchor positions.
        table: (B S, 3 * 2D + 3) per anchor i: the two invariant maps applied to its vector
            list with the local-surface term folded in, ``F_i A^T - a_i w_offset^T`` (3, 2D)
            flattened, then ``a_i`` (3); rows of object b start at ``b S``.
    """

    anchors: Tensor
    table: Tensor


class CGDFClassifier(PairClassifier):
    """Neural-descriptor-field grasp-pair classifier with a vector-neuron encoder (see the
    module docstring).

    ``forward(points (P, 3), poses (n, 2, 4, 4)) -> (n,)`` logits for one object;
    ``forward_batch(points (B, P, 3), poses (B, n, 2, 4, 4)) -> (B, n)`` for training.
    """

    name: str = "cgdf_classifier"
    config_class: ClassVar[type] = CGDFConfig

    def __init__(self, config: CGDFConfig | None = None) -> None:
        super().__init__()
        self.config = config = config or CGDFConfig()
        g = torch.Generator().manual_seed(config.seed)
        c1, c2, c3 = config.encoder_channels
        c, d, slope = config.feature_channels, config.invariant_channels, config.negative_slope
        self.edge = VNBlock(3, c1, slope, g)
        self.block2 = VNBlock(c1, c2, slope, g)
        self.block3 = VNBlock(c2, c3, slope, g)
        self.global_pool = VNMaxPool(c3, g)
        self.field_block = VNBlock(c1 + c3 + 2 * c3, c, slope, g)
        self.field_out = VNLinear(c, c, g)
        # The two invariant maps (A, B) over [F (C), q - s (1), q (1)] -> D channels each.
        self.invariant_maps = VNLinear(c + 2, 2 * d, g)
        template = gripper_template(
            config.gripper, finger_rows=config.finger_rows, palm_columns=config.palm_columns
        )
        self.register_buffer(
            "template", torch.as_tensor(template, dtype=torch.float32), persistent=False
        )
        self.register_buffer(
            "centre_local",
            torch.as_tensor(grasp_centre_local(config.gripper), dtype=torch.float32),
            persistent=False,
        )
        pose_size = 18 if config.gravity_feature else 15
        m = len(template)
        self.hand_mlp = MLP(
            (m * (d + 1) + pose_size, *config.hand_widths), g, final_activation=True
        )
        self.head = MLP((2 * config.hand_widths[-1], *config.head_widths, 1), g)

    def score_centred(self, points: Tensor, poses: Tensor) -> Tensor:
        """(B, n) logits: the field is encoded once per object, the grasps scored in chunks."""
        field = self.encode(points)
        n = poses.shape[1]
        return torch.cat(
            [self.score(field, poses[:, s]) for s in grasp_chunks(n, self.config.chunk_size)],
            dim=1,
        )

    # ---- stages ----------------------------------------------------------------------------

    def encode(self, points: Tensor) -> ObjectField:
        """The object's field (run once per object).

        Args:
            points: (B, P, 3) centred points (m).

        Returns:
            :class:`ObjectField` with S = min(n_anchors, P) anchors.
        """
        cfg = self.config
        x = points / cfg.length_scale
        s = min(cfg.n_anchors, x.shape[1])
        anchors = gather_points(x, farthest_point_indices(x, s))  # (B, S, 3)
        neighbours, _ = knn(anchors, x, min(cfg.edge_k, x.shape[1]))
        near = gather_points(x, neighbours)  # (B, S, k, 3)
        centre = anchors[:, :, None, :].expand_as(near)
        edge = torch.stack([near - centre, centre, torch.cross(near, centre, dim=-1)], dim=-1)
        local = self.edge(edge).mean(dim=2)  # (B, S, 3, C1)
        deep = self.block3(self.block2(local))  # (B, S, 3, C3)
        pooled = torch.cat([self.global_pool(deep, dim=-3), deep.mean(dim=-3)], dim=-1)
        glob = pooled[:, None].expand(-1, s, -1, -1)  # (B, S, 3, 2 C3)
        features = self.field_out(self.field_block(torch.cat([local, deep, glob], dim=-1)))
        c = cfg.feature_channels
        maps = self.invariant_maps.weight  # (2D, C + 2)
        projections = features @ maps[:, :c].t() - anchors[..., None] * maps[:, c]
        table = torch.cat([projections.flatten(-2), anchors], dim=-1)  # (B, S, 6D + 3)
        return ObjectField(anchors=anchors, table=table.flatten(0, 1))

    def query(self, field: ObjectField, queries: Tensor) -> Tensor:
        """Invariant field descriptors at query points.

        Args:
            field: the objects' fields.
            queries: (B, G, M, 3) centred query points in ``length_scale`` units, in G compact
                groups (the M template points of one hand).

        Returns:
            (B, G, M, D + 1) invariants: D inner products and the distance to the local surface.
        """
        cfg = self.config
        s = field.anchors.shape[1]
        eps = cfg.interpolation_eps / cfg.length_scale
        continuous = s > cfg.field_k
        k = cfg.field_k + 1 if continuous else s
        index, dist = grouped_knn(
            queries, field.anchors, k, max(cfg.field_candidates, k)
        )  # (B, G, M, k)
        inverse = 1.0 / (dist + eps)
        if continuous:
            weights = (inverse[..., :-1] - inverse[..., -1:]).clamp_min(0.0)
            index = index[..., :-1]
        else:
            weights = inverse
        weights = weights / (weights.sum(dim=-1, keepdim=True) + 1e-12)  # (B, G, M, k)
        # sum_i w_i [F_i A^T - a_i w_offset^T, a_i] as one fused gather-and-sum; with
        # sum_i w_i = 1 this is [F(q) A^T - s(q) w_offset^T, s(q)].
        rows = index + (torch.arange(len(index), device=index.device) * s).reshape(-1, 1, 1, 1)
        summed = nn.functional.embedding_bag(
            rows.reshape(-1, index.shape[-1]),
            field.table,
            per_sample_weights=weights.reshape(-1, weights.shape[-1]),
            mode="sum",
        ).reshape(*queries.shape[:-1], -1)
        surface = summed[..., -3:]  # (B, G, M, 3)
        offset = queries - surface
        c = cfg.feature_channels
        maps = self.invariant_maps.weight  # (2D, C + 2)
        proj = summed[..., :-3].reshape(*queries.shape, -1)  # (B, G, M, 3, 2D)
        proj = proj + queries[..., None] * (maps[:, c] + maps[:, c + 1])
        first, second = proj.chunk(2, dim=-1)
        inner = (first * second).sum(dim=-2)  # (B, G, M, D)
        gap = offset.square().sum(dim=-1, keepdim=True).clamp_min(1e-20).sqrt()
        return torch.cat([inner, gap], dim=-1)

    def score(self, field: ObjectField, poses: Tensor) -> Tensor:
        """Logits of a chunk of grasps.

        Args:
            field: the objects' fields (B objects).
            poses: (B, c, 2, 4, 4) centred poses (m).

        Returns:
            (B, c) logits.
        """
        cfg = self.config
        b, c = poses.shape[:2]
        queries = transform_points(poses, self.template) / cfg.length_scale  # (B, c, 2, M, 3)
        m = queries.shape[-2]
        inv = self.query(field, queries.reshape(b, c * 2, m, 3)).reshape(b, c, 2, -1)
        pose = hand_pose_features(
            poses, self.centre_local, cfg.length_scale, gravity=cfg.gravity_feature
        )
        hands = self.hand_mlp(torch.cat([inv, pose], dim=-1))  # (B, c, 2, H)
        return self.head(symmetric_pool(hands))[..., 0]


__all__ = [
    "CGDFClassifier",
    "CGDFConfig",
    "ObjectField",
    "VNBlock",
    "VNLeakyReLU",
    "VNLinear",
    "VNMaxPool",
    "vn_max_pool",
]
