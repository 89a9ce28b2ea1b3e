"""Torch helpers shared by the grasp-pair classifiers (:mod:`baselines.dual_pointnet_gpd`,
:mod:`baselines.cgdf_classifier`): input checks, the gripper template, transforms, nearest-point
queries, per-hand pose features, seeded layers and the checkpoint format.

Conventions
-----------
* ``points``: (P, 3) or (B, P, 3) object surface points, object frame, metres.
* ``poses``: (n, 2, 4, 4) or (B, n, 2, 4, 4) dual grasps: two hand poses, "Panda grasp frame ->
  object frame" (metres). Grasp frame (:mod:`dataset_gen.grasps.gripper`): ``+x`` closing axis, ``+y``
  approach axis (palm -> fingertips), origin at the hand's flange; the pads' centre (the *grasp
  centre*) is at ``(0, contact_depth, 0)``.
* Models centre every object at its cloud's centroid (:func:`centre_inputs`) and measure lengths
  in units of a fixed ``length_scale`` (m), never the cloud's size: whether a hand fits depends
  on absolute sizes.

Checkpoints
-----------
:func:`save_checkpoint` writes, with ``torch.save`` (atomically), a dict of plain values::

    {"format": "dg16m-classifier", "format_version": 1, "model": <model name>,
     "config": <config.to_dict()>, "dtype": "float32" | "float64",
     "state_dict": {name: tensor}, "extra": <caller's dict of plain values / tensors>}

and :func:`load_checkpoint` reads it back with ``torch.load(..., weights_only=True)`` (no
arbitrary unpickling), rebuilds the model from its name and config and loads the weights.
"""

from __future__ import annotations

import importlib
import itertools
import math
import os
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from baselines.pairing_baselines import BaselineError
from dataset_gen.grasps.gripper import GripperModel, get_gripper
from dg16m_core.atomic import atomic_path

CHECKPOINT_FORMAT = "dg16m-classifier"
"""Value of a checkpoint's ``format`` entry."""

CHECKPOINT_VERSION = 1
"""Value of a checkpoint's ``format_version`` entry."""

MODEL_CLASSES: dict[str, str] = {
    "dual_pointnet_gpd": "baselines.dual_pointnet_gpd:DualPointNetGPD",
    "cgdf_classifier": "baselines.cgdf_classifier:CGDFClassifier",
    "anchored_grasp_flow": "baselines.dual_grasp_flow:AnchoredGraspFlow",
}
"""Model name -> ``module:class`` (imported on demand by :func:`load_checkpoint`)."""


class ClassifierModelError(BaselineError):
    """Bad classifier input (shapes, values), configuration or checkpoint."""


# --------------------------------------------------------------------------------------------
# Input checks
# --------------------------------------------------------------------------------------------


def _shape(t: Tensor) -> str:
    return "(" + ", ".join(str(s) for s in t.shape) + ")"


def check_inputs(
    points: Any, poses: Any, *, batched: bool, dtype: torch.dtype
) -> tuple[Tensor, Tensor]:
    """Validate and convert one object's or a batch's inputs.

    Args:
        points: (P, 3), or (B, P, 3) when ``batched``; object frame, m. Tensor or array.
        poses: (n, 2, 4, 4), or (B, n, 2, 4, 4) when ``batched``; grasp -> object frame, m.
        batched: whether a leading object axis B is expected.
        dtype: the model's floating dtype; inputs are converted to it.

    Returns:
        ``(points, poses)`` as tensors of ``dtype`` with the checked shapes.

    Raises:
        ClassifierModelError: wrong rank or shape, mismatched B, no points, or non-finite values.
    """
    points = torch.as_tensor(points)
    poses = torch.as_tensor(poses)
    lead = "B, " if batched else ""
    rank = 3 if batched else 2
    if points.dim() != rank or points.shape[-1] != 3 or points.shape[-2] < 1:
        raise ClassifierModelError(
            f"points: expected shape ({lead}P, 3) with P >= 1, found {_shape(points)}"
        )
    if poses.dim() != rank + 2 or tuple(poses.shape[-3:]) != (2, 4, 4):
        raise ClassifierModelError(
            f"poses: expected shape ({lead}n, 2, 4, 4), found {_shape(poses)}"
        )
    if batched and poses.shape[0] != points.shape[0]:
        raise ClassifierModelError(
            f"poses: expected B = {points.shape[0]} objects (as points), found {poses.shape[0]}"
        )
    if points.is_complex() or poses.is_complex():
        raise ClassifierModelError("points, poses: expected real values, found complex ones")
    points = points.to(dtype)
    poses = poses.to(dtype)
    if not bool(torch.isfinite(points).all()):
        raise ClassifierModelError("points: expected finite values, found NaN or inf")
    if not bool(torch.isfinite(poses).all()):
        raise ClassifierModelError("poses: expected finite values, found NaN or inf")
    return points, poses


# --------------------------------------------------------------------------------------------
# Geometry
# --------------------------------------------------------------------------------------------


def gripper_template(
    gripper: str | GripperModel = "panda",
    *,
    finger_rows: int = 3,
    palm_columns: int = 3,
    opening: float | None = None,
) -> np.ndarray:
    """Template points on the open gripper, grasp frame, metres (deterministic, no sampling).

    Built from the gripper's boxes (:class:`dataset_gen.grasps.gripper.GripperModel`; for the Panda:
    palm face at y = 0.066 m, fingertips at 0.1122 m, 0.02 m thick fingers, 0.08 m opening,
    palm 0.205 x 0.066 x 0.063 m). With ``r = finger_rows`` and ``c = palm_columns``, in order:

    * finger 0 (+x) then finger 1 (-x): ``r`` points on the inner face (x = ±w/2, z = 0) and
      ``r`` on the outer face (x = ±(w/2 + thickness), z = 0), at y = ``linspace(palm face,
      fingertip, r)``; 4r points;
    * the closing region's centre line (x = 0, z = 0) at the same y; r points;
    * the palm face (y = palm face) at x = ``linspace(-hx, hx, c)`` and z = ±hz; 2c points;
    * the palm's back centre (0, palm face - 2 hy, 0); 1 point.

    Total ``5 r + 2 c + 1`` points (22 for the defaults).

    Returns:
        (M, 3) float64 points in the grasp frame (m).
    """
    if finger_rows < 2 or palm_columns < 2:
        raise ClassifierModelError(
            f"template: expected finger_rows >= 2 and palm_columns >= 2, found "
            f"{finger_rows} and {palm_columns}"
        )
    g = get_gripper(gripper)
    half = g._opening(opening) / 2.0
    ys = np.linspace(g.palm_depth, g.finger_tip, finger_rows)
    rows: list[np.ndarray] = []
    for sign in (1.0, -1.0):
        for x in (half, half + g.finger_thickness):
            rows.append(np.stack([np.full_like(ys, sign * x), ys, np.zeros_like(ys)], axis=1))
    rows.append(np.stack([np.zeros_like(ys), ys, np.zeros_like(ys)], axis=1))
    hx, hy, hz = g.palm_half_extents
    xs = np.linspace(-hx, hx, palm_columns)
    for z in (-hz, hz):
        rows.append(np.stack([xs, np.full_like(xs, g.palm_depth), np.full_like(xs, z)], axis=1))
    rows.append(np.array([[0.0, g.palm_depth - 2.0 * hy, 0.0]]))
    return np.concatenate(rows, axis=0)


def grasp_centre_local(gripper: str | GripperModel = "panda") -> np.ndarray:
    """(3,) the grasp centre (between the pads) in the grasp frame: ``(0, contact_depth, 0)``
    (m; 0.1034 m for the Panda, Franka's TCP)."""
    return np.array([0.0, get_gripper(gripper).contact_depth, 0.0])


def centre_inputs(points: Tensor, poses: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Move every object and its grasps so that the cloud's centroid is the origin.

    Args:
        points: (B, P, 3) m.
        poses: (B, n, 2, 4, 4).

    Returns:
        ``(points - c, poses with translations - c, c)``; c: (B, 3) centroids (m). Rotations
        are untouched, so the result is invariant to translating object and grasps together.
    """
    centroid = points.mean(dim=1)
    points = points - centroid[:, None, :]
    shift = torch.zeros_like(poses)
    shift[..., :3, 3] = centroid[:, None, None, :]
    return points, poses - shift, centroid


def transform_points(poses: Tensor, local: Tensor) -> Tensor:
    """Map grasp-frame points into the object frame.

    Args:
        poses: (..., 4, 4) rigid transforms.
        local: (M, 3) points in the grasp frame.

    Returns:
        (..., M, 3) ``R p + t`` for every pose and point.
    """
    return local @ poses[..., :3, :3].transpose(-1, -2) + poses[..., None, :3, 3]


def to_local(poses: Tensor, world: Tensor) -> Tensor:
    """Express object-frame points in each pose's frame.

    Args:
        poses: (..., 4, 4) rigid transforms.
        world: (..., K, 3) points, one set per pose.

    Returns:
        (..., K, 3) ``R^T (p - t)``.
    """
    return (world - poses[..., None, :3, 3]) @ poses[..., :3, :3]


def squared_distances(queries: Tensor, points: Tensor) -> Tensor:
    """Pairwise squared distances as ONE matmul (``|q|^2 + |p|^2 - 2 q.p``; rounding error
    about ``eps * |q|^2``, so only for ranking: recompute exact distances of the winners).

    Args:
        queries: (B, Q, 3).
        points: (B, P, 3).

    Returns:
        (B, Q, P) squared distances (can be slightly negative).
    """
    ones_q = torch.ones_like(queries[..., :1])
    ones_p = torch.ones_like(points[..., :1])
    q = torch.cat([queries, ones_q, (queries * queries).sum(-1, keepdim=True)], dim=-1)
    p = torch.cat([-2.0 * points, (points * points).sum(-1, keepdim=True), ones_p], dim=-1)
    return q @ p.transpose(-1, -2)


def gather_points(points: Tensor, index: Tensor) -> Tensor:
    """``points[b, index[b, ...]]``.

    Args:
        points: (B, P, *F).
        index: (B, *I) int64 indices into P.

    Returns:
        (B, *I, *F).
    """
    b = points.shape[0]
    flat = index.reshape(b, -1)
    batch = torch.arange(b, device=points.device)[:, None]
    out = points[batch, flat]
    return out.reshape(*index.shape, *points.shape[2:])


def knn(queries: Tensor, points: Tensor, k: int) -> tuple[Tensor, Tensor]:
    """The ``k`` nearest ``points`` of every query, nearest first.

    Args:
        queries: (B, Q, 3).
        points: (B, P, 3), P >= k.

    Returns:
        ``(index, distance)``: (B, Q, k) int64 indices into P and (B, Q, k) exact Euclidean
        distances (recomputed from the selected points, so they carry gradients and have no
        cancellation error).
    """
    d2 = squared_distances(queries, points)
    index = torch.topk(d2, k, dim=-1, largest=False, sorted=True).indices
    chosen = gather_points(points, index)
    distance = (chosen - queries[..., None, :]).square().sum(-1).clamp_min(1e-20).sqrt()
    return index, distance


def grouped_knn(queries: Tensor, points: Tensor, k: int, candidates: int) -> tuple[Tensor, Tensor]:
    """Exact ``k`` nearest ``points`` of queries that come in compact groups (the template
    points of one hand), faster than :func:`knn` when ``candidates`` << P.

    Each group first keeps the ``candidates`` points nearest to its centre c (the mean of its
    queries); a query's k nearest among those are certified exact when
    ``d_k(q) + |q - c| <= D`` (D: distance from c to the farthest kept candidate; every other
    point is at least D from c, hence at least ``D - |q - c|`` from q). Queries that fail the
    certificate are searched again among all points, so the result equals :func:`knn`'s
    (up to ties).

    Args:
        queries: (B, G, M, 3) G groups of M query points.
        points: (B, P, 3), P >= k.
        k: neighbours per query.
        candidates: points kept per group (>= k).

    Returns:
        ``(index, distance)``: (B, G, M, k) int64 indices into P and exact distances, nearest
        first.
    """
    b, g, m, _ = queries.shape
    p = points.shape[1]
    if candidates >= p or g == 0 or m == 0:
        index, distance = knn(queries.reshape(b, g * m, 3), points, k)
        return index.reshape(b, g, m, k), distance.reshape(b, g, m, k)
    centre = queries.mean(dim=2)  # (B, G, 3)
    kept = torch.topk(
        squared_distances(centre, points), candidates, dim=-1, largest=False, sorted=False
    ).indices  # (B, G, A)
    kept_points = gather_points(points, kept)  # (B, G, A, 3)
    reach = (kept_points - centre[:, :, None, :]).square().sum(-1).amax(dim=-1)  # (B, G)
    q = queries.reshape(b * g, m, 3)
    a = kept_points.reshape(b * g, candidates, 3)
    local_index, distance = knn(q, a, k)  # (B G, M, k)
    index = kept.reshape(b * g, candidates).gather(1, local_index.reshape(b * g, m * k))
    index = index.reshape(b, g, m, k)
    distance = distance.reshape(b, g, m, k)
    # Certificate, with a margin for the rounding of the candidates' ranking.
    offset = (queries - centre[:, :, None, :]).square().sum(-1).sqrt()  # (B, G, M)
    scale = points.square().sum(-1).amax(dim=1)[:, None] + centre.square().sum(-1)
    safe = (reach - 1e-5 * scale).clamp_min(0.0).sqrt()  # (B, G)
    bad = ((distance[..., -1] + offset) > safe[:, :, None]).reshape(b, g * m)
    if bool(bad.any()):
        index = index.reshape(b, g * m, k)
        distance = distance.reshape(b, g * m, k)
        flat_queries = queries.reshape(b, g * m, 3)
        for batch in range(b):
            rows = bad[batch].nonzero()[:, 0]
            if len(rows) == 0:
                continue
            again_index, again_distance = knn(
                flat_queries[batch, rows][None], points[batch : batch + 1], k
            )
            where = (torch.full_like(rows, batch), rows)
            index = index.index_put(where, again_index[0])
            distance = distance.index_put(where, again_distance[0])
        index = index.reshape(b, g, m, k)
        distance = distance.reshape(b, g, m, k)
    return index, distance


def farthest_point_indices(points: Tensor, count: int) -> Tensor:
    """Farthest point sampling, started at the point farthest from the origin (the centroid
    for centred clouds), so the selection depends only on distances (rotation invariant).

    Args:
        points: (B, P, 3) centred clouds.
        count: number of points to keep (<= P).

    Returns:
        (B, count) int64 indices.
    """
    b, p, _ = points.shape
    batch = torch.arange(b, device=points.device)
    with torch.no_grad():
        current = points.square().sum(-1).argmax(dim=1)
        nearest = torch.full((b, p), math.inf, dtype=points.dtype, device=points.device)
        chosen = torch.empty((b, count), dtype=torch.int64, device=points.device)
        for i in range(count):
            chosen[:, i] = current
            step = (points - points[batch, current][:, None, :]).square().sum(-1)
            nearest = torch.minimum(nearest, step)
            current = nearest.argmax(dim=1)
    return chosen


def hand_pose_features(
    poses: Tensor, centre_local: Tensor, length_scale: float, *, gravity: bool
) -> Tensor:
    """Per-hand features of a dual grasp that depend only on relative geometry.

    For hand i (other hand j), with ``R_i`` its rotation, ``c_i`` its grasp centre (object
    frame, centred at the cloud's centroid), ``L = length_scale``:
    ``R_i^T (c_j - c_i) / L`` (3), ``R_i^T R_j`` (9, row-major), ``R_i^T (0 - c_i) / L``
    (the centroid seen from the hand, 3) and, when ``gravity``, ``R_i^T (0, 0, -1)``
    (gravity's direction seen from the hand, 3; breaks rotation invariance except about z).
    Invariant to translating everything; to rotations about the centroid unless ``gravity``;
    swapping the hands swaps the two rows exactly.

    Args:
        poses: (..., 2, 4, 4) centred dual grasps.
        centre_local: (3,) grasp centre in the grasp frame (m).
        length_scale: L (m).
        gravity: append the gravity direction.

    Returns:
        (..., 2, 15) or (..., 2, 18).
    """
    rot = poses[..., :3, :3]
    centre = poses[..., :3, 3] + rot @ centre_local
    other = centre.flip(-2)
    rot_other = rot.flip(-3)
    rt = rot.transpose(-1, -2)
    parts = [
        (rt @ (other - centre)[..., None])[..., 0] / length_scale,
        (rt @ rot_other).flatten(-2),
        (rt @ (-centre)[..., None])[..., 0] / length_scale,
    ]
    if gravity:
        parts.append(-rt[..., :, 2])
    return torch.cat(parts, dim=-1)


def symmetric_pool(per_hand: Tensor) -> Tensor:
    """Combine the two hands' features symmetrically: ``[h0 + h1, max(h0, h1)]``.

    Args:
        per_hand: (..., 2, F).

    Returns:
        (..., 2F); swapping the hands gives the same bits (sum and max commute exactly).
    """
    return torch.cat([per_hand.sum(dim=-2), per_hand.amax(dim=-2)], dim=-1)


def grasp_chunks(n: int, size: int) -> Iterator[slice]:
    """Slices of ``range(n)`` of at most ``size`` grasps."""
    for start in range(0, n, size):
        yield slice(start, min(n, start + size))


# --------------------------------------------------------------------------------------------
# Seeded layers (no global RNG)
# --------------------------------------------------------------------------------------------


def uniform_parameter(
    shape: Sequence[int], bound: float, generator: torch.Generator
) -> nn.Parameter:
    """A parameter drawn from U(-bound, bound) with ``generator`` (the global RNG is untouched)."""
    data = torch.rand(tuple(shape), generator=generator, dtype=torch.float32)
    return nn.Parameter((2.0 * data - 1.0) * bound)


class Dense(nn.Module):
    """Affine layer ``x W^T + b`` on the last axis, initialised like ``nn.Linear`` (Kaiming
    uniform, bound ``1/sqrt(fan_in)``) from an explicit generator."""

    def __init__(self, fan_in: int, fan_out: int, generator: torch.Generator) -> None:
        super().__init__()
        bound = 1.0 / math.sqrt(fan_in)
        self.weight = uniform_parameter((fan_out, fan_in), bound, generator)
        self.bias = uniform_parameter((fan_out,), bound, generator)

    def forward(self, x: Tensor) -> Tensor:
        """(..., fan_in) -> (..., fan_out)."""
        return torch.addmm(self.bias, x.reshape(-1, x.shape[-1]), self.weight.t()).reshape(
            *x.shape[:-1], -1
        )


class MLP(nn.Module):
    """``Dense -> ReLU`` for every hidden width, then a final ``Dense`` (no activation unless
    ``final_activation``)."""

    def __init__(
        self,
        widths: Sequence[int],
        generator: torch.Generator,
        *,
        final_activation: bool = False,
    ) -> None:
        super().__init__()
        self.layers = nn.ModuleList(Dense(a, b, generator) for a, b in itertools.pairwise(widths))
        self.final_activation = final_activation

    def forward(self, x: Tensor) -> Tensor:
        """(..., widths[0]) -> (..., widths[-1])."""
        last = len(self.layers) - 1
        for i, layer in enumerate(self.layers):
            x = layer(x)
            if i < last or self.final_activation:
                x = torch.relu_(x)  # in place: a fresh output of Dense, saves a pass
        return x


class PairClassifier(nn.Module):
    """What both grasp-pair classifiers share: input checks, centring on the cloud's centroid,
    empty batches and the two entry points; a subclass scores centred inputs
    (:meth:`score_centred`).

    ``forward(points (P, 3), poses (n, 2, 4, 4)) -> (n,)`` logits for one object (the call the
    ``classifier`` evaluator makes); ``forward_batch(points (B, P, 3), poses (B, n, 2, 4, 4))
    -> (B, n)`` for training.
    """

    name: str = ""

    @classmethod
    def from_checkpoint(cls, path: Any) -> tuple[Any, dict[str, Any]]:
        """``(model, extra)`` from a checkpoint of this model (others refused)."""
        return load_checkpoint(path, expected=cls.name)

    @property
    def model_dtype(self) -> torch.dtype:
        """The dtype inputs are converted to (the parameters')."""
        return next(self.parameters()).dtype

    def forward(self, points: Tensor, poses: Tensor) -> Tensor:
        """Score the dual grasps of one object.

        Args:
            points: (P, 3) float32 object surface points, object frame (m).
            poses: (n, 2, 4, 4) float32 hand poses, grasp frame -> object frame (m).

        Returns:
            (n,) logits (higher = more likely to succeed).
        """
        points, poses = check_inputs(points, poses, batched=False, dtype=self.model_dtype)
        return self.forward_batch(points[None], poses[None])[0]

    def forward_batch(self, points: Tensor, poses: Tensor) -> Tensor:
        """Score ``n`` dual grasps on each of ``B`` objects.

        Args:
            points: (B, P, 3) object surface points, object frames (m).
            poses: (B, n, 2, 4, 4) hand poses, grasp frame -> object frame (m).

        Returns:
            (B, n) logits.
        """
        points, poses = check_inputs(points, poses, batched=True, dtype=self.model_dtype)
        points, poses, _ = centre_inputs(points, poses)
        if poses.shape[1] == 0:
            return points.new_zeros(poses.shape[:2])
        return self.score_centred(points, poses)

    def score_centred(self, points: Tensor, poses: Tensor) -> Tensor:
        """(B, n) logits of centred inputs (n >= 1); implemented by each model."""
        raise NotImplementedError


def count_parameters(model: nn.Module) -> int:
    """Number of trainable scalars."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


# --------------------------------------------------------------------------------------------
# Configuration helpers
# --------------------------------------------------------------------------------------------


def config_from_dict(cls: type, data: Mapping[str, Any]) -> Any:
    """Build the dataclass ``cls`` from ``to_dict()`` output (lists become tuples).

    Raises:
        ClassifierModelError: ``data`` is not a mapping or holds unknown keys.
    """
    import dataclasses

    if not isinstance(data, Mapping):
        raise ClassifierModelError(f"{cls.__name__}: expected a dict, found {type(data).__name__}")
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ClassifierModelError(
            f"{cls.__name__}: expected keys among {sorted(known)}, found unknown {unknown}"
        )
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
    return cls(**values)


def config_to_dict(config: Any) -> dict[str, Any]:
    """A dataclass as a dict of plain values (tuples become lists)."""
    import dataclasses

    return {
        k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(config).items()
    }


def require(condition: bool, message: str) -> None:
    """Raise :class:`ClassifierModelError` with ``message`` unless ``condition``."""
    if not condition:
        raise ClassifierModelError(message)


# --------------------------------------------------------------------------------------------
# Checkpoints
# --------------------------------------------------------------------------------------------

_PLAIN = (str, int, float, bool, type(None))


def _check_plain(value: Any, where: str) -> None:
    """Refuse values ``torch.load(weights_only=True)`` could not read back."""
    if isinstance(value, (*_PLAIN, Tensor)):
        return
    if isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            _check_plain(item, f"{where}[{i}]")
        return
    if isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, str):
                raise ClassifierModelError(f"{where}: expected str keys, found {key!r}")
            _check_plain(item, f"{where}[{key!r}]")
        return
    raise ClassifierModelError(
        f"{where}: expected str, int, float, bool, None, tensors, lists or dicts, found "
        f"{type(value).__name__}"
    )


def save_checkpoint(
    path: str | os.PathLike[str], model: nn.Module, extra: dict[str, Any] | None = None
) -> None:
    """Write ``model`` (name, config, weights) and ``extra`` to ``path`` atomically.

    Args:
        path: destination file (``.pt``).
        model: a classifier with ``name`` and ``config`` (:data:`MODEL_CLASSES`).
        extra: caller's metadata: str/int/float/bool/None, tensors, lists and str-keyed dicts.

    Raises:
        ClassifierModelError: an unknown model or ``extra`` values that cannot be stored safely.
    """
    name = getattr(model, "name", None)
    if name not in MODEL_CLASSES:
        raise ClassifierModelError(
            f"model: expected one of {sorted(MODEL_CLASSES)}, found {name!r}"
        )
    extra = dict(extra or {})
    _check_plain(extra, "extra")
    dtype = next(model.parameters()).dtype
    payload = {
        "format": CHECKPOINT_FORMAT,
        "format_version": CHECKPOINT_VERSION,
        "model": name,
        "config": model.config.to_dict(),
        "dtype": str(dtype).removeprefix("torch."),
        "state_dict": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
        "extra": extra,
    }
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)


def load_checkpoint(
    path: str | os.PathLike[str], *, expected: str | None = None
) -> tuple[nn.Module, dict[str, Any]]:
    """Read a checkpoint written by :func:`save_checkpoint`.

    Args:
        path: the file.
        expected: the model name the caller needs (e.g. ``"cgdf_classifier"``); a checkpoint of
            another model is refused. None accepts any known model.

    Returns:
        ``(model, extra)``: the model on the CPU in eval mode, and the stored ``extra`` dict.

    Raises:
        ClassifierModelError: missing or unreadable file, another format, another model than
            ``expected``, or weights that do not fit the stored configuration.
    """
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise ClassifierModelError(f"{path}: expected a checkpoint file, found none") from None
    except Exception as exc:
        raise ClassifierModelError(
            f"{path}: expected a {CHECKPOINT_FORMAT} checkpoint (torch.save of plain values), "
            f"found an unreadable file ({type(exc).__name__}: {str(exc).splitlines()[0][:200]})"
        ) from None
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        found = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise ClassifierModelError(
            f"{path}: expected format {CHECKPOINT_FORMAT!r}, found {found!r}"
        )
    if payload.get("format_version") != CHECKPOINT_VERSION:
        raise ClassifierModelError(
            f"{path}: expected format_version {CHECKPOINT_VERSION}, "
            f"found {payload.get('format_version')!r}"
        )
    name = payload.get("model")
    if expected is not None and name != expected:
        raise ClassifierModelError(
            f"{path}: expected a {expected!r} checkpoint, found one of model {name!r}"
        )
    if name not in MODEL_CLASSES:
        raise ClassifierModelError(
            f"{path}: expected a model among {sorted(MODEL_CLASSES)}, found {name!r}"
        )
    module_name, class_name = MODEL_CLASSES[name].split(":")
    cls = getattr(importlib.import_module(module_name), class_name)
    config = cls.config_class.from_dict(payload.get("config"))
    model = cls(config)
    dtype = {"float32": torch.float32, "float64": torch.float64}.get(payload.get("dtype"))
    if dtype is None:
        raise ClassifierModelError(
            f"{path}: expected dtype float32 or float64, found {payload.get('dtype')!r}"
        )
    model = model.to(dtype)
    try:
        model.load_state_dict(payload["state_dict"], strict=True)
    except (RuntimeError, KeyError, TypeError) as exc:
        raise ClassifierModelError(
            f"{path}: expected weights matching the stored {name} config, found a mismatch "
            f"({str(exc).splitlines()[0][:200]})"
        ) from None
    model.eval()
    extra = payload.get("extra", {})
    return model, extra if isinstance(extra, dict) else {}


__all__ = [
    "CHECKPOINT_FORMAT",
    "CHECKPOINT_VERSION",
    "MLP",
    "MODEL_CLASSES",
    "ClassifierModelError",
    "Dense",
    "centre_inputs",
    "check_inputs",
    "config_from_dict",
    "config_to_dict",
    "count_parameters",
    "farthest_point_indices",
    "gather_points",
    "grasp_centre_local",
    "grasp_chunks",
    "gripper_template",
    "grouped_knn",
    "hand_pose_features",
    "knn",
    "load_checkpoint",
    "require",
    "save_checkpoint",
    "squared_distances",
    "symmetric_pool",
    "to_local",
    "transform_points",
    "uniform_parameter",
]
