"""PPO on ``dg16m_env/DualGraspLift-v0`` with a target dual grasp: lift the object from the table.

Reads top to bottom (CleanRL style): one dataclass of arguments, then the run.

1. Split the benchmark's objects: every third object held out for evaluation.
2. Train stable-baselines3 PPO on the training objects with ``target_grasp="benchmark"``: each
   episode puts one of the object's force-closure-passing benchmark grasps (stored p >= 0.5) in
   the observation; the dense reward (reach, align, grasp, lift, hold, success) guides the hands.
3. Evaluate on the held-out objects with the registered ``policy`` evaluator: the trained
   policy, the scripted grasp-and-lift reference (:class:`ScriptedLiftPolicy`, which reads the
   same observation) and uniformly random actions, on the same seeded episodes, each with a
   Wilson 95% interval.
4. Write the checkpoint, the learning curve (PNG) and the results (JSON) to ``--out``.

    .venv/bin/python -m baselines.sb3_lift --total-timesteps 300000 --out runs/sb3_lift

Budget: the defaults finish in about 15 minutes on 2 CPU cores (see baselines/RESULTS.md).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import dg16m_env  # noqa: F401  registers the environments
from baselines.sb3_common import (
    learn,
    output_and_split,
    parse_args,
    policy_evaluator,
    report,
    reward_curve_callback,
    training_envs,
    uniform_actions,
)
from dg16m_env.envs.lift.experts import ScriptedLiftPolicy

ENV_ID = "dg16m_env/DualGraspLift-v0"


@dataclass
class Args:
    seed: int = 0
    """seed of the training environments, the policy and the evaluation episodes"""
    total_timesteps: int = 300_000
    """environment steps of PPO training"""
    n_envs: int = 8
    """environments stepped together (one vectorised env)"""
    learning_rate: float = 3e-4
    """Adam learning rate"""
    n_steps: int = 256
    """steps per environment in each PPO rollout"""
    batch_size: int = 512
    """PPO minibatch size"""
    n_epochs: int = 10
    """PPO epochs per rollout"""
    gamma: float = 0.99
    """discount factor"""
    ent_coef: float = 0.0
    """entropy bonus coefficient"""
    eval_episodes: int = 100
    """seeded evaluation episodes after training (the policy evaluator)"""
    eval_seed: int = 100_000
    """first seed of the evaluation episodes (apart from the training seeds)"""
    out: Path = Path("runs/sb3_lift")
    """output folder: model, learning curve, results"""


def main() -> None:
    args = parse_args(Args, __doc__.split("\n\n")[0])
    from stable_baselines3 import PPO

    train_ids, test_ids = output_and_split(args.out)
    skip = {"shelf-1000011", "barrel_with_handles-1000006"}  # no benchmark grasp to target
    train_ids = [i for i in train_ids if i not in skip]
    test_ids = [i for i in test_ids if i not in skip]
    env_kwargs = {"target_grasp": "benchmark"}

    # --- training ------------------------------------------------------------------------------
    train_env = training_envs(ENV_ID, args, {**env_kwargs, "object_ids": train_ids})
    curve = reward_curve_callback()
    model = PPO(
        "MlpPolicy",
        train_env,
        learning_rate=args.learning_rate,
        n_steps=args.n_steps,
        batch_size=args.batch_size,
        n_epochs=args.n_epochs,
        gamma=args.gamma,
        ent_coef=args.ent_coef,
        seed=args.seed,
        device="cpu",
        verbose=0,
    )
    train_s = learn(model, args, curve, "ppo_lift.zip")

    # --- evaluation on held-out objects ---------------------------------------------------------
    evaluator = policy_evaluator(
        ENV_ID, args.eval_episodes, args.eval_seed, {**env_kwargs, "object_ids": test_ids}
    )
    started = time.perf_counter()
    results = {
        "ppo": evaluator.evaluate(model),
        "scripted": evaluator.evaluate(ScriptedLiftPolicy()),
        "random_actions": evaluator.evaluate(uniform_actions((14,), args.seed)),
    }
    eval_s = time.perf_counter() - started

    # --- learning curve and results ----------------------------------------------------------
    report(
        args,
        results,
        curve,
        env_id=ENV_ID,
        title="PPO on DualGraspLift-v0 (target grasp; held-out objects)",
        ylabel="mean dense reward per step (training)",
        train_label="PPO training reward",
        train_objects=len(train_ids),
        test_objects=len(test_ids),
        train_seconds=train_s,
        eval_seconds=eval_s,
    )


if __name__ == "__main__":
    main()
