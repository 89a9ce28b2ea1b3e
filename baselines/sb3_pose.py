"""SAC on ``dg16m_env/DualGraspPose-v0``: propose two hand poses from the object's point cloud.

Reads top to bottom (CleanRL style): one dataclass of arguments, then the run.

1. Split the benchmark's objects: every third object held out for evaluation.
2. Train stable-baselines3 SAC on the training objects: one step per episode, the action is
   two hand poses (position + 6D rotation each, ``Box(-1, 1, (2, 9))``), the reward is one
   perturbed MuJoCo trial of the benchmark's protocol (1 = held through every disturbance).
   The policy sees a 64-point cloud with normals and the object's box.
3. Evaluate on the held-out objects with the registered ``policy`` evaluator: the trained
   policy and uniformly random actions, on the same seeded episodes (Wilson 95% intervals).
4. Write the checkpoint, the learning curve (PNG) and the results (JSON) to ``--out``.

    .venv/bin/python -m baselines.sb3_pose --total-timesteps 10000 --out runs/sb3_pose

A sparse one-trial reward in an 18-dimensional continuous action space is a hard exploration
problem: expect little from a 10-minute budget (the results file says what it got).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import dg16m_env  # noqa: F401  registers the environments
from baselines.sb3_common import (
    parse_args,
    report,
    reward_curve_callback,
    save_model,
    split_objects,
)
from dg16m_env.evaluators import load_benchmark_ref, make

ENV_ID = "dg16m_env/DualGraspPose-v0"


@dataclass
class Args:
    seed: int = 0
    """seed of the training environment, the policy and the evaluation episodes"""
    total_timesteps: int = 10_000
    """environment steps of SAC training (one step = one episode)"""
    learning_rate: float = 3e-4
    """Adam learning rate"""
    batch_size: int = 256
    """SAC minibatch size"""
    learning_starts: int = 1_000
    """random steps collected before learning starts"""
    n_points: int = 64
    """points of the object's cloud in each observation"""
    eval_episodes: int = 200
    """seeded evaluation episodes after training (the policy evaluator)"""
    eval_seed: int = 100_000
    """first seed of the evaluation episodes (apart from the training seeds)"""
    out: Path = Path("runs/sb3_pose")
    """output folder: model, learning curve, results"""


def main() -> None:
    args = parse_args(Args, __doc__.split("\n\n")[0])
    from stable_baselines3 import SAC
    from stable_baselines3.common.env_util import make_vec_env

    args.out.mkdir(parents=True, exist_ok=True)
    ref = load_benchmark_ref()
    train_ids, test_ids = split_objects(ref.object_ids)
    env_kwargs = {"n_points": args.n_points, "fc_info": False}

    # --- training ------------------------------------------------------------------------------
    train_env = make_vec_env(
        ENV_ID, n_envs=1, seed=args.seed, env_kwargs={**env_kwargs, "object_ids": train_ids}
    )
    curve = reward_curve_callback()
    model = SAC(
        "MultiInputPolicy",
        train_env,
        learning_rate=args.learning_rate,
        batch_size=args.batch_size,
        learning_starts=args.learning_starts,
        buffer_size=args.total_timesteps,  # every step fits; SB3's default (1e6) wastes GBs
        gamma=0.0,  # one step per episode
        seed=args.seed,
        device="cpu",
        verbose=0,
    )
    started = time.perf_counter()
    model.learn(total_timesteps=args.total_timesteps, callback=curve)
    train_s = time.perf_counter() - started
    save_model(model, args.out / "sac_pose.zip")

    # --- evaluation on held-out objects ---------------------------------------------------------
    evaluator = make(
        "policy",
        env_id=ENV_ID,
        n_episodes=args.eval_episodes,
        seed=args.eval_seed,
        env_kwargs={**env_kwargs, "object_ids": test_ids},
        progress=True,
    )
    rng = np.random.default_rng(args.seed)

    def random_actions(observation: Any) -> np.ndarray:
        return rng.uniform(-1.0, 1.0, size=(2, 9)).astype(np.float32)

    started = time.perf_counter()
    results = {
        "sac": evaluator.evaluate(model),
        "random_actions": evaluator.evaluate(random_actions),
    }
    eval_s = time.perf_counter() - started

    # --- learning curve and results ----------------------------------------------------------
    report(
        args,
        results,
        curve,
        env_id=ENV_ID,
        title="SAC on DualGraspPose-v0 (held-out objects)",
        ylabel="success rate",
        train_label="SAC training episodes (one trial each)",
        train_objects=len(train_ids),
        test_objects=len(test_ids),
        train_seconds=train_s,
        eval_seconds=eval_s,
    )


if __name__ == "__main__":
    main()
