"""A learned ``DualGraspLift-v2`` policy that sees the object only through the ``"pointcloud"``
observation's cloud (:class:`baselines.lift_cloud_policy.LiftCloudPolicy`), as trained by
:mod:`baselines.bc_lift_cloud`.

It is the goal-frame policy of :mod:`baselines.lift_bc_policy` without the privileged object
state: of the ``"state"`` vector it reads only the hands and their targets (``hand_poses`` is not
needed: the actual grasp centres come as ``centre_errors``), ``commanded_poses``,
``finger_openings``, ``finger_contacts``, ``target_poses``, ``previous_action``, ``elapsed``,
``centre_errors`` and ``rotation_errors``; never ``object_position``, ``object_rotation``, the
object's velocities, ``grasp_centres``, ``object_size``, ``object_box_centre``, ``lift`` or
``hold``. What the state policy took from those (the box top, the lift) comes from the cloud:

* cloud statistics (:func:`baselines.lift_cloud_policy.cloud_inputs`, over every masked
  point): the cloud's lowest and highest world ``z`` (m): the object resting on the table has
  its lowest point near the table, so the lowest point rises with the lift; the highest point
  stands in for the box top;
* a small PointNet (:class:`baselines.lift_cloud_policy.CloudNetwork`): a shared per-point
  MLP (ReLU; 3 -> 32 -> 64 by default in :mod:`baselines.bc_lift_cloud`) and a max-pool
  over a seeded subsample of ``n_points`` cloud points, expressed in each hand's goal frame
  (points minus the goal centre, rotated into the goal's axes, in dm), so that each hand sees
  the object's shape around its own grasp.

Per hand ``k`` the vector features (:func:`baselines.lift_cloud_policy.hand_features`,
``(N, 2, FEATURES)``) are, in hand ``k``'s goal frame unless noted: its commanded and actual
grasp centre relative to the goal (m), the rotation vector (rad) turning its commanded rotation
onto the goal, the same three clipped to one action step, the world's ``+z``, heights (world
``z``, m: commanded centre, goal centre, commanded centre above the cloud's top, the cloud's
top), finger opening (dm), its two finger contacts, its previous finger command and motion
(goal frame); the other hand's distance and angle to its goal, scaled distance, contacts,
finger command and opening; the cloud's lowest and highest ``z`` (m), the elapsed fraction;
the cloud's centroid in the goal frame (m); which hand it is. Outputs per hand (``(N, 2,
7)``), as the state policy's: the motion in the goal frame through ``tanh`` and a finger logit
(:func:`baselines.lift_bc_policy.world_actions`).

Shapes: ``S`` ``(N, 117)`` float ``"state"`` vectors; ``C`` ``(N, n_points, 3)`` float32
subsampled clouds (world frame, m); ``Z`` ``(N, 2)`` float32 lowest and highest cloud ``z``
(m); actions ``(N, 14)`` in [-1, 1].
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from baselines.lift_bc_policy import (
    check_payload,
    check_states,
    hand_parts,
    read_payload,
    world_actions,
)
from dg16m_core.atomic import atomic_path
from dg16m_env.envs.lift.observations import STATE_SLICES

FEATURES = 50
"""Vector features per hand (:func:`baselines.lift_cloud_policy.hand_features`)."""

FORMAT = "dg16m-lift-cloud-policy"
"""The ``format`` of a saved policy (:meth:`baselines.lift_cloud_policy.LiftCloudPolicy.save`)."""

VERSION = 1
"""Version of the saved policy and of its features."""

N_POINTS = 128
"""Cloud points the PointNet reads per step unless asked otherwise."""

CLOUD_SCALE = 10.0
"""Cloud coordinates in the goal frame are multiplied by this (m -> dm) before the PointNet."""

ALLOWED_STATE = (
    "centre_errors",
    "rotation_errors",
    "hand_poses",
    "commanded_poses",
    "finger_openings",
    "finger_contacts",
    "target_poses",
    "target_flag",
    "previous_action",
    "elapsed",
)
"""The parts of the ``"state"`` vector the policy may read (module docstring)."""


def check_cloud(points: Any, mask: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """``(n, 3)`` float64 points and ``(n,)`` bool mask of one observation's cloud;
    ``ValueError`` for other shapes, non-finite masked points or an empty mask."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim == 1 and p.size % 3 == 0:  # v3's flat cloud
        p = p.reshape(-1, 3)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise ValueError(f"expected a cloud of shape (n_points, 3), found shape {p.shape}")
    m = np.ones(len(p), bool) if mask is None else np.asarray(mask).reshape(-1) > 0.5
    if m.shape != (len(p),):
        raise ValueError(f"expected a cloud mask of shape ({len(p)},), found shape {m.shape}")
    if not m.any():
        raise ValueError("expected a cloud with at least one masked point, found none")
    if not np.isfinite(p[m]).all():
        raise ValueError("expected finite cloud points, found NaN or infinity")
    return p, m


def cloud_inputs(
    points: Any, mask: Any, n_points: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """One observation's cloud (``(n, 3)`` points, m, and ``(n,)`` mask) -> ``(n_points, 3)``
    float32 masked points drawn with ``rng`` (without replacement when there are enough, else
    with) and ``(2,)`` float32 lowest and highest ``z`` over all masked points (m)."""
    p, m = check_cloud(points, mask)
    kept = p[m]
    index = rng.choice(len(kept), size=n_points, replace=len(kept) < n_points)
    heights = np.array([kept[:, 2].min(), kept[:, 2].max()])
    return kept[index].astype(np.float32), heights.astype(np.float32)


def observation_inputs(
    obs: Any, n_points: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ``"pointcloud"`` observation -> its ``(117,)`` float32 state, ``(n_points, 3)`` cloud
    and ``(2,)`` heights (:func:`baselines.lift_cloud_policy.cloud_inputs`); ``ValueError``
    for another observation."""
    if not isinstance(obs, Mapping) or not {"state", "points"} <= set(obs):
        found = sorted(obs) if isinstance(obs, Mapping) else type(obs).__name__
        raise ValueError(
            f"expected a 'pointcloud' observation (a dictionary with 'state' and 'points'), "
            f"found {found}"
        )
    state = check_states(obs["state"])[0].astype(np.float32)
    cloud, heights = cloud_inputs(obs["points"], obs.get("mask"), n_points, rng)
    return state, cloud, heights


def privileged_free(states: Any) -> np.ndarray:
    """``(N, 117)`` float64 states with every part outside
    :data:`baselines.lift_cloud_policy.ALLOWED_STATE` set to 0 (what
    the features are computed from, so they cannot depend on it)."""
    s = check_states(states).copy()
    for name, sl in STATE_SLICES.items():
        if name not in ALLOWED_STATE:
            s[:, sl] = 0.0
    return s


def hand_features(
    states: Any, clouds: Any, heights: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-hand inputs of the network from ``S``, ``C`` and ``Z`` (module docstring).

    Returns the ``(N, 2, FEATURES)`` float32 vector features, the ``(N, 2, n_points, 3)``
    float32 clouds in each hand's goal frame (dm,
    :data:`baselines.lift_cloud_policy.CLOUD_SCALE`) and the ``(N, 2, 3, 3)``
    world-to-goal rotations (for :func:`baselines.lift_bc_policy.goal_frame_actions` and
    :func:`baselines.lift_bc_policy.world_actions`). ``ValueError`` for mismatched shapes or
    non-finite values.
    """
    s = privileged_free(states)
    n = len(s)
    c = np.asarray(clouds, dtype=np.float32)
    z = np.asarray(heights, dtype=np.float64)
    if c.ndim != 3 or c.shape[0] != n or c.shape[2] != 3:
        raise ValueError(f"expected clouds of shape ({n}, n_points, 3), found shape {c.shape}")
    if z.shape != (n, 2):
        raise ValueError(f"expected cloud heights of shape ({n}, 2), found shape {z.shape}")
    if not (np.isfinite(c).all() and np.isfinite(z).all()):
        raise ValueError("expected finite clouds and heights, found NaN or infinity")
    own, other, to_goal, goals = hand_parts(s, z[:, 1])
    task = np.concatenate([z, s[:, STATE_SLICES["elapsed"]]], axis=-1)
    # (N, 2, P, 3): each hand's cloud relative to its goal centre, in its goal's axes
    local = np.einsum("nkij,npj->nkpi", to_goal.astype(np.float32), c) - np.einsum(
        "nkij,nkj->nki", to_goal, goals
    )[:, :, None].astype(np.float32)
    centroid = local.mean(axis=2)
    which = np.broadcast_to(np.eye(2), (n, 2, 2))
    features = np.concatenate(
        [own, other, np.repeat(task[:, None], 2, axis=1), centroid, which], axis=-1
    )
    if features.shape[-1] != FEATURES:
        raise AssertionError(f"expected {FEATURES} features, found {features.shape[-1]}")
    return features.astype(np.float32), (CLOUD_SCALE * local).astype(np.float32), to_goal


def make_network(hidden: int, layers: int, encoder: tuple[int, ...]) -> Any:
    """A :class:`baselines.lift_cloud_policy.CloudNetwork` (torch) of these sizes."""
    return CloudNetwork(hidden, layers, encoder)


def _mlp(sizes: list[int], last_relu: bool) -> Any:
    """``torch.nn.Sequential`` of Linear layers of ``sizes`` with ReLU between (and after the
    last with ``last_relu``)."""
    modules: list[Any] = []
    for a, b in itertools.pairwise(sizes):
        modules += [torch.nn.Linear(a, b), torch.nn.ReLU()]
    return torch.nn.Sequential(*(modules if last_relu else modules[:-1]))


class CloudNetwork(torch.nn.Module):
    """PointNet encoder + MLP head: ``forward(features (B, FEATURES), cloud (B, P, 3))`` ->
    ``(B, 7)``: the per-point MLP ``3 -> encoder`` (ReLU), max over the ``P`` points, then
    ``[features, pooled]`` -> ``layers`` x ``hidden`` (ReLU) -> 7."""

    def __init__(self, hidden: int, layers: int, encoder: tuple[int, ...]):
        super().__init__()
        self.encoder = _mlp([3, *encoder], last_relu=True)
        self.head = _mlp([FEATURES + encoder[-1]] + [hidden] * layers + [7], last_relu=False)

    def forward(self, features: Any, cloud: Any) -> Any:
        """``(B, FEATURES)`` normalised features, ``(B, P, 3)`` goal-frame clouds (dm) ->
        ``(B, 7)`` outputs (before tanh)."""
        pooled = self.encoder(cloud).amax(dim=-2)
        return self.head(torch.cat([features, pooled], dim=-1))


class LiftCloudPolicy:
    """``policy(obs) -> action`` for ``DualGraspLift-v2`` with ``obs_mode="pointcloud"``: the
    trained :class:`baselines.lift_cloud_policy.CloudNetwork` with its feature normalisation
    (``mean``, ``std``:
    ``(FEATURES,)``). Each call subsamples the cloud with a generator seeded by ``cloud_seed``
    (so the same observation gives the same action). Stateless (``reset()`` does nothing).
    Load a saved one with :meth:`baselines.lift_cloud_policy.LiftCloudPolicy.load`.
    """

    name = "bc_lift_cloud"

    def __init__(
        self,
        network: Any,
        mean: np.ndarray,
        std: np.ndarray,
        hidden: int,
        layers: int,
        encoder: tuple[int, ...],
        n_points: int = N_POINTS,
        cloud_seed: int = 0,
    ):
        self.network = network.eval()
        self.mean = np.asarray(mean, dtype=np.float32)
        self.std = np.asarray(std, dtype=np.float32)
        self.hidden, self.layers = int(hidden), int(layers)
        self.encoder = tuple(int(e) for e in encoder)
        self.n_points, self.cloud_seed = int(n_points), int(cloud_seed)

    def reset(self) -> None:
        """Nothing to forget; for evaluators that call it."""

    def outputs(self, features: np.ndarray, clouds: np.ndarray) -> np.ndarray:
        """``(..., FEATURES)`` features and ``(..., P, 3)`` goal-frame clouds -> ``(..., 7)``
        outputs (motion through tanh, finger logit)."""
        with torch.no_grad():
            x = torch.from_numpy(((features - self.mean) / self.std).astype(np.float32))
            y = self.network(x, torch.from_numpy(clouds)).numpy()
        y[..., :6] = np.tanh(y[..., :6])
        return y

    def act(self, states: Any, clouds: Any, heights: Any) -> np.ndarray:
        """``S``, ``C``, ``Z`` -> ``(N, 14)`` float32 actions."""
        features, local, to_goal = hand_features(states, clouds, heights)
        return world_actions(self.outputs(features, local), to_goal)

    def __call__(self, obs: Any) -> np.ndarray:
        rng = np.random.default_rng(self.cloud_seed)
        state, cloud, heights = observation_inputs(obs, self.n_points, rng)
        return self.act(state[None], cloud[None], heights[None])[0]

    def payload(self) -> dict[str, Any]:
        """The weights, sizes and normalisation as a dictionary (what
        :meth:`baselines.lift_cloud_policy.LiftCloudPolicy.save` writes;
        :meth:`baselines.lift_cloud_policy.LiftCloudPolicy.from_payload` reads it back)."""
        return {
            "format": FORMAT,
            "version": VERSION,
            "hidden": self.hidden,
            "layers": self.layers,
            "encoder": list(self.encoder),
            "n_points": self.n_points,
            "cloud_seed": self.cloud_seed,
            "mean": self.mean,
            "std": self.std,
            "state_dict": self.network.state_dict(),
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write :meth:`baselines.lift_cloud_policy.LiftCloudPolicy.payload` to ``path`` (torch
        file), atomically."""
        with atomic_path(Path(path)) as tmp:
            torch.save(self.payload(), tmp)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> LiftCloudPolicy:
        """A policy saved by :meth:`baselines.lift_cloud_policy.LiftCloudPolicy.save`;
        ``ValueError`` for another file."""
        return cls.from_payload(read_payload(path, "LiftCloudPolicy"), str(path))

    @classmethod
    def from_payload(cls, payload: Any, source: str = "payload") -> LiftCloudPolicy:
        """The policy of a :meth:`baselines.lift_cloud_policy.LiftCloudPolicy.payload`
        dictionary; ``ValueError`` (naming ``source``) for
        anything else."""
        check_payload(payload, FORMAT, VERSION, source)
        encoder = tuple(payload["encoder"])
        network = make_network(payload["hidden"], payload["layers"], encoder)
        network.load_state_dict(payload["state_dict"])
        return cls(
            network,
            payload["mean"],
            payload["std"],
            payload["hidden"],
            payload["layers"],
            encoder,
            payload["n_points"],
            payload["cloud_seed"],
        )
