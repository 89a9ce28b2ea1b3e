"""SAC on ``dg16m_env/DualGraspPose-v0``: propose two hand poses from the object's point cloud.

Reads top to bottom (CleanRL style): one dataclass of arguments, then the run.

1. Split the benchmark's objects: every third object held out for evaluation.
2. Train stable-baselines3 SAC (``--algo ppo``: PPO) on the training objects: one step per
   episode, the reward is one perturbed MuJoCo trial of the benchmark's protocol (1 = held
   through every disturbance). The policy sees a 64-point cloud with normals and the object's
   box. The action (``--action-mode``): ``pose``, two free hand poses (position + 6D rotation
   each, ``Box(-1, 1, (2, 9))``); ``surface``, two hands placed on observed surface points,
   approaching along the inward normals (``[point, roll, depth]`` each, ``Box(-1, 1, (2, 3))``,
   :mod:`dg16m_env.envs.pose_surface_actions`).
3. Evaluate on the held-out objects with the registered ``policy`` evaluator: the trained
   policy and uniformly random actions of the same mode, on the same seeded episodes (Wilson
   95% intervals); in surface mode also uniformly random pose-mode actions, for reference.
4. Write the checkpoint, the learning curve (PNG) and the results (JSON) to ``--out``.

Run it::

    .venv/bin/python -m baselines.sb3_pose --total-timesteps 10000 --out runs/sb3_pose
    .venv/bin/python -m baselines.sb3_pose --action-mode surface --total-timesteps 20000 \\
        --eval-episodes 1000 --out runs/sb3_pose_surface

In pose mode a sparse one-trial reward in an 18-dimensional continuous action space is a hard
exploration problem: uniformly random poses almost never touch the object. Surface mode puts
every hand on the object's observed surface (the results file says what each got).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

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
from dg16m_env.envs.dual_grasp_pose import ACTION_MODES

ENV_ID = "dg16m_env/DualGraspPose-v0"
ALGOS = ("sac", "ppo")


@dataclass
class Args:
    seed: int = 0
    """seed of the training environment, the policy and the evaluation episodes"""
    action_mode: str = "pose"
    """the environment's action_mode: "pose" (two free hand poses) or "surface" (two hands on
    observed surface points, approaching along the normals)"""
    algo: str = "sac"
    """the learner: "sac" or "ppo" (stable-baselines3 defaults otherwise, gamma 0)"""
    total_timesteps: int = 10_000
    """environment steps of training (one step = one episode)"""
    learning_rate: float = 3e-4
    """Adam learning rate"""
    batch_size: int = 256
    """SAC / PPO minibatch size"""
    learning_starts: int = 1_000
    """SAC: random steps collected before learning starts"""
    n_envs: int = 1
    """environments stepped together (PPO: its rollout is n_envs x n_steps)"""
    n_steps: int = 1_024
    """PPO: steps per environment per update"""
    n_points: int = 64
    """points of the object's cloud in each observation"""
    eval_episodes: int = 200
    """seeded evaluation episodes after training, for each evaluated policy"""
    eval_seed: int = 100_000
    """first seed of the evaluation episodes (apart from the training seeds)"""
    out: Path = Path("runs/sb3_pose")
    """output folder: model, learning curve, results"""


def main() -> None:
    args = parse_args(Args, __doc__.split("\n\n")[0])
    if args.action_mode not in ACTION_MODES:
        raise SystemExit(
            f"--action-mode: expected one of {ACTION_MODES}, found {args.action_mode!r}"
        )
    if args.algo not in ALGOS:
        raise SystemExit(f"--algo: expected one of {ALGOS}, found {args.algo!r}")
    from stable_baselines3 import PPO, SAC

    train_ids, test_ids = output_and_split(args.out)
    env_kwargs = {"n_points": args.n_points, "fc_info": False, "action_mode": args.action_mode}
    if args.action_mode == "pose":
        del env_kwargs["action_mode"]  # the registered default, as before the option existed

    # --- training ------------------------------------------------------------------------------
    train_env = training_envs(ENV_ID, args, {**env_kwargs, "object_ids": train_ids})
    curve = reward_curve_callback()
    common = {"learning_rate": args.learning_rate, "batch_size": args.batch_size, "gamma": 0.0}
    if args.algo == "sac":
        model: Any = SAC(
            "MultiInputPolicy",
            train_env,
            learning_starts=args.learning_starts,
            buffer_size=args.total_timesteps,  # every step fits; SB3's default (1e6) wastes GBs
            seed=args.seed,
            device="cpu",
            verbose=0,
            **common,
        )
    else:
        model = PPO(
            "MultiInputPolicy",
            train_env,
            n_steps=args.n_steps,
            gae_lambda=1.0,  # one step per episode: the advantage is reward - value
            seed=args.seed,
            device="cpu",
            verbose=0,
            **common,
        )
    suffix = "" if args.action_mode == "pose" else f"_{args.action_mode}"
    train_s = learn(model, args, curve, f"{args.algo}_pose{suffix}.zip")

    # --- evaluation on held-out objects ---------------------------------------------------------
    def evaluator(kwargs: dict[str, Any]) -> Any:
        return policy_evaluator(
            ENV_ID, args.eval_episodes, args.eval_seed, {**kwargs, "object_ids": test_ids}
        )

    shape = tuple(int(n) for n in train_env.action_space.shape)  # type: ignore[union-attr]
    started = time.perf_counter()
    same_mode = evaluator(env_kwargs)
    results = {
        args.algo: same_mode.evaluate(model),
        "random_actions": same_mode.evaluate(uniform_actions(shape, args.seed)),
    }
    if args.action_mode != "pose":
        pose_kwargs = {k: v for k, v in env_kwargs.items() if k != "action_mode"}
        results["random_pose_actions"] = evaluator(pose_kwargs).evaluate(
            uniform_actions((2, 9), args.seed)
        )
    eval_s = time.perf_counter() - started

    # --- learning curve and results ----------------------------------------------------------
    report(
        args,
        results,
        curve,
        env_id=ENV_ID,
        title=f"{args.algo.upper()} on DualGraspPose-v0, {args.action_mode} actions (held-out objects)",
        ylabel="success rate",
        train_label=f"{args.algo.upper()} training episodes (one trial each)",
        train_objects=len(train_ids),
        test_objects=len(test_ids),
        train_seconds=train_s,
        eval_seconds=eval_s,
    )


if __name__ == "__main__":
    main()
