"""PPO on ``dg16m_env/DualGraspSelect-v0``: learn to pick the dual grasp that holds.

Reads top to bottom (CleanRL style): one dataclass of arguments, then the run.

1. Split the benchmark's objects: every third object (by benchmark order, so each family
   appears on both sides) is held out for evaluation; training sees the other two thirds.
2. Train stable-baselines3 PPO on the training objects with ``reward_mode="label"``: the
   reward of a pick is a Bernoulli draw of the candidate's stored success probability p (the
   benchmark's labels; a thousand times faster than simulating, the same expected reward). The
   policy sees each candidate's two hand poses and four contacts (points and normals), the
   candidate mask and the object's box, not the point cloud.
3. Evaluate on the held-out objects with the registered ``policy`` evaluator, in
   ``reward_mode="simulate"`` (one perturbed MuJoCo trial of the chosen grasp per episode):
   the trained policy and a policy that picks a random candidate, on the same seeded episodes
   (the same objects and candidates), each with a Wilson 95% interval.
4. Write the checkpoint, the learning curve (PNG) and the results (JSON) to ``--out``.

    .venv/bin/python -m baselines.sb3_select --total-timesteps 100000 --out runs/sb3_select

Budget: the defaults finish in about 10 minutes on 2 CPU cores (see baselines/RESULTS.md).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import dg16m_env  # noqa: F401  registers the environments
from baselines.sb3_common import (
    learn,
    output_and_split,
    parse_args,
    policy_evaluator,
    report,
    reward_curve_callback,
    training_envs,
)

ENV_ID = "dg16m_env/DualGraspSelect-v0"
POLICY_KEYS = ("bounds", "candidates", "candidate_contacts", "candidate_mask")


@dataclass
class Args:
    seed: int = 0
    """seed of the training environments, the policy and the evaluation episodes"""
    total_timesteps: int = 100_000
    """training steps (one step = one episode: one pick)"""
    n_envs: int = 8
    """training environments (in one process)"""
    n_candidates: int = 16
    """K candidates per episode"""
    level: str = "full"
    """success level: "full" (all 12 disturbances) or "gravity\""""
    learning_rate: float = 1e-3
    """Adam learning rate"""
    n_steps: int = 256
    """steps per environment per PPO update"""
    batch_size: int = 256
    """PPO minibatch size"""
    n_epochs: int = 10
    """PPO epochs per rollout"""
    ent_coef: float = 0.01
    """entropy bonus coefficient"""
    eval_episodes: int = 400
    """evaluation episodes on the held-out objects (simulated trials)"""
    eval_seed: int = 100_000
    """first reset seed of the evaluation episodes"""
    out: Path = Path("runs/sb3_select")
    """output folder: model, learning curve, results"""


def candidate_scorer_class() -> type:
    """The policy's feature extractor (built lazily: torch is imported only by this script)."""
    import torch
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

    class CandidateScorer(BaseFeaturesExtractor):
        """One small MLP shared by every candidate: its two hand poses (18), its four contacts
        (24) and the object's box (6) -> one score; empty slots get -10. The K scores are the
        features, so the policy treats every slot alike (a flat MLP over all K candidates has
        to learn that from scratch)."""

        def __init__(self, observation_space: gym.spaces.Dict, hidden: int = 128) -> None:
            k = observation_space["candidate_mask"].shape[0]
            super().__init__(observation_space, features_dim=k)
            self.k = k
            self.mlp = torch.nn.Sequential(
                torch.nn.Linear(48, hidden),
                torch.nn.ReLU(),
                torch.nn.Linear(hidden, hidden),
                torch.nn.ReLU(),
                torch.nn.Linear(hidden, 1),
            )

        def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
            n = obs["candidate_mask"].shape[0]
            features = torch.cat(
                [
                    obs["candidates"].reshape(n, self.k, 18),
                    obs["candidate_contacts"].reshape(n, self.k, 24),
                    obs["bounds"].reshape(n, 1, 6).expand(n, self.k, 6),
                ],
                dim=-1,
            )
            scores = self.mlp(features).squeeze(-1)
            return torch.where(obs["candidate_mask"] > 0.5, scores, torch.full_like(scores, -10.0))

    return CandidateScorer


class SelectForPolicy(gym.ObservationWrapper):
    """Keep only the keys the policy reads (:data:`POLICY_KEYS`)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.observation_space = gym.spaces.Dict({k: env.observation_space[k] for k in POLICY_KEYS})

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        return {k: observation[k] for k in POLICY_KEYS}


def main() -> None:
    args = parse_args(Args, __doc__.split("\n\n")[0])
    from stable_baselines3 import PPO

    train_ids, test_ids = output_and_split(args.out)
    # fc_info=False: the force-closure verdict in info is not needed here (and costs ~9 ms)
    env_kwargs = {
        "n_candidates": args.n_candidates,
        "level": args.level,
        "n_points": 16,
        "fc_info": False,
    }

    # --- training on the stored labels -------------------------------------------------------
    train_env = training_envs(
        ENV_ID,
        args,
        {**env_kwargs, "object_ids": train_ids, "reward_mode": "label"},
        wrapper_class=SelectForPolicy,
    )

    curve = reward_curve_callback()
    model = PPO(
        "MultiInputPolicy",
        train_env,
        policy_kwargs={
            "features_extractor_class": candidate_scorer_class(),
            "net_arch": {"pi": [], "vf": [64]},
        },
        learning_rate=args.learning_rate,
        n_steps=args.n_steps,
        batch_size=args.batch_size,
        n_epochs=args.n_epochs,
        gamma=0.0,  # one step per episode: a contextual bandit
        ent_coef=args.ent_coef,
        seed=args.seed,
        device="cpu",
        verbose=0,
    )
    train_s = learn(model, args, curve, "ppo_select.zip")

    # --- evaluation on held-out objects, simulated ------------------------------------------
    wrapper = SelectForPolicy(gym.make(ENV_ID, **env_kwargs, object_ids=test_ids))

    def trained(observation: dict[str, Any]) -> Any:
        return model.predict(wrapper.observation(observation), deterministic=True)[0]

    pick_rng = np.random.default_rng(args.seed)

    def random_candidate(observation: dict[str, Any]) -> int:
        return int(pick_rng.choice(np.flatnonzero(observation["candidate_mask"] > 0.5)))

    evaluator = policy_evaluator(
        ENV_ID,
        args.eval_episodes,
        args.eval_seed,
        {**env_kwargs, "object_ids": test_ids, "reward_mode": "simulate"},
    )
    started = time.perf_counter()
    results = {
        "ppo": evaluator.evaluate(trained),
        "random_candidate": evaluator.evaluate(random_candidate),
    }
    eval_s = time.perf_counter() - started

    # --- learning curve and results ----------------------------------------------------------
    report(
        args,
        results,
        curve,
        env_id=ENV_ID,
        title="PPO on DualGraspSelect-v0 (held-out objects, simulated)",
        ylabel="success rate",
        train_label="training picks (label reward)",
        train_objects=len(train_ids),
        test_objects=len(test_ids),
        train_seconds=train_s,
        eval_seconds=eval_s,
    )


if __name__ == "__main__":
    main()
