"""A residual policy for ``DualGraspLift-v1``: a frozen behaviour-cloned policy
(:class:`~baselines.lift_bc_policy.LiftBCPolicy`) plus a small learned correction
(:class:`LiftResidualPolicy`), as fine-tuned with PPO by :mod:`baselines.residual_lift`.

Per hand ``k`` (one network serves both hands, like the base policy's):

* the **actor** reads the base policy's normalised goal-frame features of that hand
  (:func:`~baselines.lift_bc_policy.hand_features`, ``FEATURES`` = 48) and the base policy's
  outputs for it (7: the motion command through ``tanh`` and the finger logit), and answers a
  residual ``r`` of 7 numbers: the mean of a Gaussian with a learned, state-independent standard
  deviation per component (:data:`RESIDUAL_SIZE`);
* the action of hand ``k`` is the base motion plus ``r[:6]`` (goal frame, action units, clipped
  to [-1, 1], then turned into the world frame) and the base finger command (+1 or -1) plus
  ``r[6]`` (clipped to [-1, 1]: a softer squeeze or a release) (:func:`compose_actions`).

The actor's last layer starts at zero, so an untrained residual policy acts exactly as its base
policy. The **critic** (for PPO) reads both hands' normalised features (96 numbers).

Shapes: ``S`` ``(N, 117)`` ``"state"`` vectors; actions ``(N, 14)`` in [-1, 1]; residuals
``(N, 2, 7)``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from baselines.lift_bc_policy import (
    FEATURES,
    LiftBCPolicy,
    check_payload,
    hand_features,
    read_payload,
)
from dg16m_core.atomic import atomic_path
from dg16m_env.envs.lift.observations import state_vector

RESIDUAL_SIZE = 7
"""Residual numbers per hand: 6 motion components (goal frame) and the finger command."""

ACTOR_INPUTS = FEATURES + RESIDUAL_SIZE
"""Actor inputs per hand: the normalised features and the base policy's outputs."""

CRITIC_INPUTS = 2 * FEATURES
"""Critic inputs: both hands' normalised features."""

FORMAT = "dg16m-lift-residual-policy"
"""The ``format`` of a saved residual policy (:meth:`LiftResidualPolicy.save`)."""

VERSION = 1
"""Version of the saved residual policy."""


def compose_actions(
    base_outputs: np.ndarray, residuals: np.ndarray, to_goal: np.ndarray
) -> np.ndarray:
    """``(N, 2, 7)`` base outputs (motion in [-1, 1], finger logit), ``(N, 2, 7)`` residuals and
    ``(N, 2, 3, 3)`` world-to-goal rotations -> ``(N, 14)`` float32 world actions in [-1, 1]."""
    base = np.asarray(base_outputs, dtype=np.float64)
    r = np.asarray(residuals, dtype=np.float64)
    motion = np.clip(base[..., :6] + r[..., :6], -1.0, 1.0)
    to_world = np.swapaxes(to_goal, -1, -2)
    translation = np.einsum("nkij,nkj->nki", to_world, motion[..., :3])
    rotation = np.einsum("nkij,nkj->nki", to_world, motion[..., 3:])
    finger = np.clip(np.where(base[..., 6] > 0.0, 1.0, -1.0) + r[..., 6], -1.0, 1.0)
    action = np.concatenate([translation, rotation, finger[..., None]], axis=-1)
    return np.clip(action.reshape(len(base), 14), -1.0, 1.0).astype(np.float32)


def make_actor(hidden: int) -> Any:
    """``ACTOR_INPUTS`` -> 2 x ``hidden`` (tanh) -> 7, the last layer at zero (torch)."""
    import torch

    actor = torch.nn.Sequential(
        torch.nn.Linear(ACTOR_INPUTS, hidden),
        torch.nn.Tanh(),
        torch.nn.Linear(hidden, hidden),
        torch.nn.Tanh(),
        torch.nn.Linear(hidden, RESIDUAL_SIZE),
    )
    torch.nn.init.zeros_(actor[-1].weight)
    torch.nn.init.zeros_(actor[-1].bias)
    return actor


def make_critic(hidden: int) -> Any:
    """``CRITIC_INPUTS`` -> 2 x ``hidden`` (tanh) -> 1 (torch)."""
    import torch

    return torch.nn.Sequential(
        torch.nn.Linear(CRITIC_INPUTS, hidden),
        torch.nn.Tanh(),
        torch.nn.Linear(hidden, hidden),
        torch.nn.Tanh(),
        torch.nn.Linear(hidden, 1),
    )


class LiftResidualPolicy:
    """``policy(obs) -> action`` for ``DualGraspLift-v1``: ``base`` plus the actor's mean
    residual (deterministic; :meth:`inputs` and :meth:`compose` serve training). Stateless.
    ``log_std``: ``(7,)`` the Gaussian's log standard deviations (action units)."""

    name = "bc_residual_lift"

    def __init__(self, base: LiftBCPolicy, actor: Any, critic: Any, log_std: Any, hidden: int):
        self.base, self.actor, self.critic = base, actor, critic
        self.log_std, self.hidden = log_std, int(hidden)

    def reset(self) -> None:
        """Nothing to forget; for evaluators that call it."""

    def inputs(self, states: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(N, 117)`` states -> the actor's ``(N, 2, ACTOR_INPUTS)`` and the critic's ``(N,
        CRITIC_INPUTS)`` float32 inputs, the base outputs ``(N, 2, 7)`` and the world-to-goal
        rotations ``(N, 2, 3, 3)``."""
        features, to_goal = hand_features(states)
        normalised = ((features - self.base.mean) / self.base.std).astype(np.float32)
        base_outputs = self.base.outputs(features).astype(np.float32)
        actor_in = np.concatenate([normalised, base_outputs], axis=-1)
        return actor_in, normalised.reshape(len(features), CRITIC_INPUTS), base_outputs, to_goal

    def act(self, states: Any) -> np.ndarray:
        """``(N, 117)`` states -> ``(N, 14)`` actions with the mean residual."""
        import torch

        actor_in, _, base_outputs, to_goal = self.inputs(states)
        with torch.no_grad():
            residual = self.actor(torch.from_numpy(actor_in)).numpy()
        return compose_actions(base_outputs, residual, to_goal)

    def __call__(self, obs: Any) -> np.ndarray:
        return self.act(state_vector(obs, "LiftResidualPolicy"))[0]

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the base policy, the actor, the critic and ``log_std`` to ``path`` (one torch
        file), atomically."""
        import torch

        payload = {
            "format": FORMAT,
            "version": VERSION,
            "hidden": self.hidden,
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "log_std": self.log_std.detach().clone(),
            "base": self.base.payload(),
        }
        with atomic_path(Path(path)) as tmp:
            torch.save(payload, tmp)

    @classmethod
    def from_base(cls, base: LiftBCPolicy, hidden: int, init_std: float) -> LiftResidualPolicy:
        """A fresh residual policy on ``base`` (acts as ``base``), exploring with standard
        deviation ``init_std`` (action units) per component."""
        import torch

        if not init_std > 0.0:
            raise ValueError(f"init_std: expected a standard deviation > 0, found {init_std!r}")
        log_std = torch.nn.Parameter(torch.full((RESIDUAL_SIZE,), float(np.log(init_std))))
        return cls(base, make_actor(hidden), make_critic(hidden), log_std, hidden)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> LiftResidualPolicy:
        """A policy saved by :meth:`save`; ``ValueError`` for another file."""
        import torch

        payload = read_payload(path, "LiftResidualPolicy")
        check_payload(payload, FORMAT, VERSION, str(path))
        base = LiftBCPolicy.from_payload(payload.get("base"), f"{path} (its base policy)")
        actor, critic = make_actor(payload["hidden"]), make_critic(payload["hidden"])
        actor.load_state_dict(payload["actor"])
        critic.load_state_dict(payload["critic"])
        log_std = torch.nn.Parameter(payload["log_std"].clone())
        return cls(base, actor.eval(), critic.eval(), log_std, payload["hidden"])
