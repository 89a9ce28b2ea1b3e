"""A learned ``DualGraspLift-v1`` policy: an MLP that reads the ``"state"`` observation in each
hand's *goal frame* and answers in it (:class:`LiftBCPolicy`), as trained by
:mod:`baselines.bc_lift` (behaviour cloning and DAgger on :class:`FeedbackLiftExpert`
demonstrations).

Why a goal frame: a hand must reach its grasp within millimetres from anywhere on a table a
metre wide. In world coordinates the same approach looks different for every object pose and
target, and an MLP on the raw 117 numbers learns none of it (0 of 40 held-out episodes,
measured; issue 40 reported 0/30 and 1/30 before). Expressed in the frame of the hand's goal (its
target grasp, jaw-symmetric like the env's ``rotation_errors``: origin at the target grasp
centre, axes of the target rotation), every approach looks alike; the network answers each
hand's motion in that frame, rotated back to the world for the action. One network serves both
hands (a one-hot says which), so each episode teaches it twice.

Per hand ``k`` the features (:func:`hand_features`, ``(N, 2, FEATURES)``) are, in hand ``k``'s
goal frame unless noted: its commanded and its actual grasp centre relative to the goal (m),
the rotation (rotation vector, rad) turning its commanded rotation onto the goal, the world's
``+z`` (up), heights (world ``z``, m: commanded centre, goal centre, commanded centre above the
object's box top, the box top), finger opening (dm), its two finger contacts, its previous finger
command, its previous motion command (goal frame); the other hand's distance and angle to its
goal, contacts, finger command and opening; the object's lift (m), the hold's progress, the
elapsed fraction, the object's vertical speed (m/s); which hand it is. Outputs per hand
(``(N, 2, 7)``): the motion command (translation, rotation; goal frame, action units, through
``tanh``) and a finger logit (closing if > 0: the expert's finger command is always +1 or -1,
learnt as a binary choice).

Shapes: ``S`` ``(N, 117)`` float ``"state"`` vectors; actions ``(N, 14)`` in [-1, 1].
"""

from __future__ import annotations

import itertools
import os
import pickle
from pathlib import Path
from typing import Any

import numpy as np

from dg16m_core.atomic import atomic_path
from dg16m_env.envs.lift.observations import STATE_SIZE, STATE_SLICES, goal_frames, state_vector
from dg16m_env.envs.lift.spaces import MAX_ROTATION, MAX_TRANSLATION, rotation_vector
from dg16m_env.envs.spaces import rotation_from_6d

FEATURES = 48
"""Features per hand (:func:`hand_features`)."""

FORMAT = "dg16m-lift-bc-policy"
"""The ``format`` of a saved policy (:meth:`LiftBCPolicy.save`)."""

VERSION = 1
"""Version of the saved policy and of its features."""

NEAR = 0.01
"""Scale of the other hand's distance to its goal as a feature (m): near-goal values matter."""

_BOX_SIGNS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)


def check_states(states: Any) -> np.ndarray:
    """``(N, 117)`` float64 from ``(117,)`` or ``(N, 117)`` ``"state"`` vectors; ``ValueError``
    for other shapes or non-finite values."""
    s = np.asarray(states, dtype=np.float64)
    if s.ndim == 1:
        s = s[None]
    if s.ndim != 2 or s.shape[1] != STATE_SIZE:
        raise ValueError(
            f"expected DualGraspLift-v1 'state' observations of shape (N, {STATE_SIZE}), found "
            f"shape {s.shape}"
        )
    if not np.isfinite(s).all():
        raise ValueError("expected finite 'state' observations, found NaN or infinity")
    return s


def in_frame(to_goal: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """(N, 2, 3) world vectors -> the goal frames (``to_goal`` (N, 2, 3, 3) = R^T)."""
    return np.einsum("nkij,nkj->nki", to_goal, vectors)


def hand_features(states: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(N, 2, FEATURES)`` float32 per-hand features (module docstring) and the ``(N, 2, 3,
    3)`` world-to-goal rotations (for :func:`goal_frame_actions` / :func:`world_actions`)."""
    s = check_states(states)
    n = len(s)
    object_rot = rotation_from_6d(s[:, STATE_SLICES["object_rotation"]])[0]
    corners = (
        s[:, None, STATE_SLICES["object_box_centre"]]
        + 0.5 * _BOX_SIGNS[None] * s[:, None, STATE_SLICES["object_size"]]
    )
    top = (
        np.einsum("nij,npj->npi", object_rot, corners)[:, :, 2]
        + s[:, None, STATE_SLICES["object_position"]][:, :, 2]
    ).max(axis=1)
    own, other, to_goal, _ = hand_parts(s, top)
    task = np.stack(
        [
            s[:, STATE_SLICES["lift"]][:, 0],
            s[:, STATE_SLICES["hold"]][:, 0],
            s[:, STATE_SLICES["elapsed"]][:, 0],
            s[:, STATE_SLICES["object_linear_velocity"]][:, 2],
        ],
        axis=-1,
    )
    which = np.broadcast_to(np.eye(2), (n, 2, 2))
    features = np.concatenate([own, other, np.repeat(task[:, None], 2, axis=1), which], axis=-1)
    assert features.shape[-1] == FEATURES
    return features.astype(np.float32), to_goal


def hand_parts(
    s: np.ndarray, top: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The per-hand features of the hands alone, shared by this policy and
    :mod:`baselines.lift_cloud_policy`, from checked ``(N, 117)`` float64 states and the
    object's ``(N,)`` top height (m; world ``z``).

    Returns ``own`` ``(N, 2, 35)``: hand ``k``'s errors to its goal (goal frame; m, rad, and
    the same clipped to one action step), the world's ``+z``, heights (commanded centre, goal
    centre, commanded centre above ``top``, ``top``), finger opening (dm), contacts, previous
    finger command and motion; ``other`` ``(N, 2, 7)``: the other hand's distance and angle to
    its goal, scaled distance, contacts, finger command and opening; the ``(N, 2, 3, 3)``
    world-to-goal rotations and the ``(N, 2, 3)`` goal centres (world, m).
    """
    n = len(s)
    goal_rot, goals, centres, rotations = goal_frames(s)
    to_goal = np.swapaxes(goal_rot, -1, -2)
    own_error = in_frame(to_goal, centres - goals)
    actual_error = in_frame(to_goal, s[:, STATE_SLICES["centre_errors"]].reshape(n, 2, 3))
    turn = in_frame(to_goal, rotation_vector(goal_rot @ np.swapaxes(rotations, -1, -2)))
    heights = np.stack(
        [
            centres[:, :, 2],
            goals[:, :, 2],
            centres[:, :, 2] - top[:, None],
            np.repeat(top[:, None], 2, axis=1),
        ],
        axis=-1,
    )
    opening = 10.0 * s[:, STATE_SLICES["finger_openings"]].reshape(n, 2, 1)
    contacts = s[:, STATE_SLICES["finger_contacts"]].reshape(n, 2, 2)
    previous = s[:, STATE_SLICES["previous_action"]].reshape(n, 2, 7)
    finger = previous[:, :, 6:7]
    own = np.concatenate(
        [
            own_error,
            actual_error,
            turn,
            np.clip(-own_error / MAX_TRANSLATION, -1.0, 1.0),
            np.clip(-actual_error / MAX_TRANSLATION, -1.0, 1.0),
            np.clip(turn / MAX_ROTATION, -1.0, 1.0),
            to_goal[:, :, :, 2],
            heights,
            opening,
            contacts,
            finger,
            in_frame(to_goal, previous[:, :, :3]),
            in_frame(to_goal, previous[:, :, 3:6]),
        ],
        axis=-1,
    )
    distance = np.linalg.norm(np.maximum(np.abs(own_error), np.abs(actual_error)), axis=-1)
    other = np.concatenate(
        [
            np.linalg.norm(own_error, axis=-1, keepdims=True),
            np.linalg.norm(turn, axis=-1, keepdims=True),
            np.clip(distance / NEAR, 0.0, 5.0)[..., None],
            contacts,
            finger,
            opening,
        ],
        axis=-1,
    )[:, ::-1]
    return own, other, to_goal, goals


def goal_frame_actions(actions: Any, to_goal: np.ndarray) -> np.ndarray:
    """``(N, 14)`` world actions -> ``(N, 2, 7)``: each hand's motion in its goal frame, its
    finger command as it is."""
    a = np.asarray(actions, dtype=np.float64).reshape(len(to_goal), 2, 7).copy()
    a[:, :, :3] = in_frame(to_goal, a[:, :, :3])
    a[:, :, 3:6] = in_frame(to_goal, a[:, :, 3:6])
    return a.astype(np.float32)


def world_actions(outputs: np.ndarray, to_goal: np.ndarray) -> np.ndarray:
    """``(N, 2, 7)`` network outputs (motion in goal frames, in [-1, 1]; finger logit) ->
    ``(N, 14)`` float32 world actions in [-1, 1] (finger +1 if the logit is > 0, else -1)."""
    out = np.asarray(outputs, dtype=np.float64).reshape(len(to_goal), 2, 7).copy()
    to_world = np.swapaxes(to_goal, -1, -2)
    out[:, :, :3] = in_frame(to_world, out[:, :, :3])
    out[:, :, 3:6] = in_frame(to_world, out[:, :, 3:6])
    out[:, :, 6] = np.where(out[:, :, 6] > 0.0, 1.0, -1.0)
    return np.clip(out.reshape(len(to_goal), 14), -1.0, 1.0).astype(np.float32)


def make_network(hidden: int, layers: int) -> Any:
    """The MLP: ``FEATURES`` -> ``layers`` x ``hidden`` (ReLU) -> 7 (torch)."""
    import torch

    sizes = [FEATURES] + [hidden] * layers
    modules: list[Any] = []
    for a, b in itertools.pairwise(sizes):
        modules += [torch.nn.Linear(a, b), torch.nn.ReLU()]
    modules.append(torch.nn.Linear(sizes[-1], 7))
    return torch.nn.Sequential(*modules)


def read_payload(path: str | os.PathLike[str], kind: str) -> Any:
    """What the torch file ``path`` holds; ``ValueError`` (naming ``kind``, the saved class) for
    a file torch cannot read."""
    import torch

    try:
        return torch.load(path, map_location="cpu", weights_only=False)
    except (OSError, RuntimeError, EOFError, pickle.UnpicklingError) as exc:
        raise ValueError(f"{path}: expected a saved {kind}, found: {exc}") from None


def check_payload(payload: Any, fmt: str, version: int, source: str) -> None:
    """``ValueError`` (naming ``source``) unless ``payload`` is a dictionary of format ``fmt``
    and version ``version``."""
    if not isinstance(payload, dict) or payload.get("format") != fmt:
        raise ValueError(f"{source}: expected a file of format {fmt!r}, found another file")
    if payload.get("version") != version:
        raise ValueError(
            f"{source}: expected version {version}, found version {payload.get('version')!r}"
        )


class LiftBCPolicy:
    """``policy(obs) -> action`` for ``DualGraspLift-v1`` (a ``"state"`` vector, or a
    ``"state_dict"`` / ``"pointcloud"`` observation's state): the trained network with its
    feature normalisation (``mean``, ``std``: ``(FEATURES,)``). Stateless (``reset()`` does
    nothing). Load a saved one with :meth:`load`.
    """

    name = "bc_lift"

    def __init__(self, network: Any, mean: np.ndarray, std: np.ndarray, hidden: int, layers: int):
        self.network = network.eval()
        self.mean = np.asarray(mean, dtype=np.float32)
        self.std = np.asarray(std, dtype=np.float32)
        self.hidden, self.layers = int(hidden), int(layers)

    def reset(self) -> None:
        """Nothing to forget; for evaluators that call it."""

    def outputs(self, features: np.ndarray) -> np.ndarray:
        """``(..., FEATURES)`` features -> ``(..., 7)`` outputs (motion through tanh, logit)."""
        import torch

        with torch.no_grad():
            x = torch.from_numpy(((features - self.mean) / self.std).astype(np.float32))
            y = self.network(x).numpy()
        y[..., :6] = np.tanh(y[..., :6])
        return y

    def act(self, states: Any) -> np.ndarray:
        """``(N, 117)`` states -> ``(N, 14)`` actions."""
        features, to_goal = hand_features(states)
        return world_actions(self.outputs(features), to_goal)

    def __call__(self, obs: Any) -> np.ndarray:
        return self.act(state_vector(obs, "LiftBCPolicy"))[0]

    def payload(self) -> dict[str, Any]:
        """The weights, sizes and normalisation as a dictionary (what :meth:`save` writes;
        :meth:`from_payload` reads it back)."""
        return {
            "format": FORMAT,
            "version": VERSION,
            "hidden": self.hidden,
            "layers": self.layers,
            "mean": self.mean,
            "std": self.std,
            "state_dict": self.network.state_dict(),
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write :meth:`payload` to ``path`` (torch file), atomically."""
        import torch

        with atomic_path(Path(path)) as tmp:
            torch.save(self.payload(), tmp)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> LiftBCPolicy:
        """A policy saved by :meth:`save`; ``ValueError`` for another file."""
        return cls.from_payload(read_payload(path, "LiftBCPolicy"), str(path))

    @classmethod
    def from_payload(cls, payload: Any, source: str = "payload") -> LiftBCPolicy:
        """The policy of a :meth:`payload` dictionary; ``ValueError`` (naming ``source``) for
        anything else."""
        check_payload(payload, FORMAT, VERSION, source)
        network = make_network(payload["hidden"], payload["layers"])
        network.load_state_dict(payload["state_dict"])
        return cls(network, payload["mean"], payload["std"], payload["hidden"], payload["layers"])
