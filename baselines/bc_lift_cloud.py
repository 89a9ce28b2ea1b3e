"""Behaviour cloning with DAgger on ``dg16m_env/DualGraspLift-v2`` with ``obs_mode="pointcloud"``:
learn to lift from the recovering expert without the privileged object state (the policy of
:mod:`baselines.lift_cloud_policy` sees the object only through the cloud).

Reads top to bottom (CleanRL style): one dataclass of arguments, then the run.

1. Split the benchmark's objects: every third object held out for evaluation
   (:func:`dg16m_env.envs.objects.split_objects`).
2. Collect the demonstrations online (the Minari demonstrations store no clouds): the teacher
   (``teacher``: :class:`dg16m_env.envs.lift.recovering_expert.RecoveringLiftExpert`, which
   reads the privileged ``"state"``, or ``planning``,
   :class:`dg16m_env.envs.lift.planning_expert.PlanningLiftExpert`, which also plans its
   approach on the observation's cloud) runs ``teacher_episodes`` episodes on the training objects (reset
   seeds ``seed + i``); each step keeps the state (float32), a seeded subsample of
   ``n_points`` cloud points (float32) and the cloud's lowest and highest ``z``; the
   successful episodes' steps with the teacher's actions are the first training set.
3. Behaviour cloning: the PointNet + MLP of :class:`baselines.lift_cloud_policy.CloudNetwork` on
   each hand's goal-frame features and cloud, mean squared error on the motion (through tanh)
   plus a binary cross-entropy on the finger command, Adam with a one-cycle learning rate.
4. DAgger (as :mod:`baselines.bc_lift`): roll the policy out on the training objects (new
   seeds; in round ``i`` each step is the teacher's with probability ``dagger_beta * 0.5**i``),
   label the visited states of the phases in ``dagger_phases`` (the grasp phases ``close`` and
   ``lift`` by default) with the teacher's action, add them, train again from scratch.
5. Evaluate on the held-out objects with the registered ``policy`` evaluator (pointcloud
   observations): the learned policy, the teacher and uniformly random actions on the same
   seeded episodes, each with a Wilson 95% interval; then on the real benchmark's held-out
   objects when asked.
6. Write the policy (``policy.pt``, :meth:`baselines.lift_cloud_policy.LiftCloudPolicy.load`),
   the picture of the success rates (``success_rates.png``) and the results (JSON, with the
   collection, training and evaluation seconds) to ``--out``.

    .venv/bin/python -m baselines.bc_lift_cloud --out runs/bc_lift_cloud

Measured 2026-12-07 on 2 shared CPU cores, held-out objects, reset seeds 100000 + i (Wilson 95%
intervals): these defaults (500 teacher episodes, 74% of them successful; PointNet 3 -> 32 ->
64 on 128 points; 2 DAgger rounds of 100 episodes, rollouts 35% then 47% successful) 58.5%
[51.6, 65.1] on 200 procedural episodes (the teacher 79.0% [72.8, 84.1], random actions 0.0%)
and 42.0% [32.8, 51.8] on 100 real ones, in 941 s (collection 377, training 449, DAgger
rollouts 115); 300 teacher episodes, a 3 -> 32 -> 64 -> 128 PointNet and 1 DAgger round gave
42.0% [35.4, 48.9] procedural in 729 s.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

import dg16m_env  # noqa: F401  registers the environments
from baselines.bc_lift import PHASES, plot_results
from baselines.lift_bc_policy import goal_frame_actions
from baselines.lift_cloud_policy import (
    FEATURES,
    N_POINTS,
    LiftCloudPolicy,
    hand_features,
    make_network,
    observation_inputs,
)
from baselines.sb3_common import (
    output_and_split,
    parse_args,
    policy_evaluator,
    print_results,
    split_objects,
    write_run,
)
from dg16m_env.envs.lift.expert_registry import make_lift_expert
from dg16m_env.envs.lift.experts import FeedbackLiftExpert
from dg16m_env.evaluators import EvaluationResult, load_benchmark_ref

ENV_ID = "dg16m_env/DualGraspLift-v2"
"""The environment of the demonstrations, the DAgger rollouts and the evaluation."""


@dataclass
class Args:
    seed: int = 0
    """seed of the teacher episodes (reset seeds seed + i), the cloud subsamples, the network, the minibatches and the random baseline"""
    teacher: str = "recovering"
    """the teacher of the demonstrations and the DAgger labels: recovering or planning"""
    teacher_episodes: int = 500
    """teacher episodes collected on the training objects (the successful ones are kept)"""
    episode_steps: int = 0
    """step limit of the collection and DAgger episodes (0: the env's own)"""
    n_points: int = N_POINTS
    """cloud points the PointNet reads per step (a seeded subsample of the masked points)"""
    encoder: str = "32,64"
    """widths of the PointNet's per-point MLP (comma-separated)"""
    hidden: int = 256
    """width of each hidden layer of the head"""
    layers: int = 3
    """hidden layers of the head"""
    epochs: int = 15
    """passes over the training set each time the network is trained"""
    batch_size: int = 256
    """minibatch size (per-hand samples)"""
    learning_rate: float = 1e-3
    """peak learning rate (one-cycle schedule)"""
    dagger_rounds: int = 2
    """DAgger rounds after behaviour cloning (0: behaviour cloning only)"""
    dagger_episodes: int = 100
    """episodes rolled out on the training objects per DAgger round"""
    dagger_beta: float = 0.0
    """probability that a rollout step takes the teacher's action in the first round (halved each round)"""
    dagger_phases: str = "close,lift"
    """the teacher's phases whose DAgger labels are kept (comma-separated; 'all' keeps every label)"""
    dagger_seed: int = 1_000_000
    """first seed of the DAgger rollouts (apart from the teacher's and the evaluation's)"""
    eval_episodes: int = 200
    """seeded evaluation episodes on the procedural benchmark's held-out objects"""
    real_eval_episodes: int = 0
    """seeded evaluation episodes on the real benchmark's held-out objects (0: skip)"""
    eval_seed: int = 100_000
    """first seed of the evaluation episodes"""
    threads: int = 1
    """torch threads (more than 1 slowed the per-step policy calls 20-fold on 2 shared cores)"""
    out: Path = Path("runs/bc_lift_cloud")
    """output folder: policy, picture, results"""


class Steps:
    """Growing per-step training inputs: ``states`` ``(N, 117)``, ``clouds`` ``(N, n_points,
    3)``, ``heights`` ``(N, 2)`` and teacher ``actions`` ``(N, 14)``, all float32."""

    def __init__(self) -> None:
        self.parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []

    def add(self, states: list, clouds: list, heights: list, actions: list) -> None:
        """Append steps (lists of per-step arrays; nothing for empty lists)."""
        if states:
            self.parts.append(
                tuple(np.asarray(a, dtype=np.float32) for a in (states, clouds, heights, actions))
            )

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The four arrays of every step added so far."""
        if not self.parts:
            raise SystemExit("expected training steps, found none (no successful episode)")
        return tuple(np.concatenate(column) for column in zip(*self.parts, strict=True))

    def __len__(self) -> int:
        return sum(len(part[0]) for part in self.parts)


def make_env(object_ids: list[str], episode_steps: int) -> Any:
    """``DualGraspLift-v2`` with pointcloud observations on ``object_ids`` (with a step limit
    of ``episode_steps`` unless 0)."""
    import gymnasium as gym

    limit = {"max_episode_steps": episode_steps} if episode_steps else {}
    return gym.make(ENV_ID, obs_mode="pointcloud", object_ids=object_ids, **limit)


def rollouts(
    env: Any,
    teacher: FeedbackLiftExpert,
    policy: LiftCloudPolicy | None,
    seeds: range,
    args: Args,
    rng: np.random.Generator,
    *,
    beta: float = 1.0,
    phases: set[str] | None = None,
    successful_only: bool = False,
    desc: str = "rollouts",
) -> tuple[Steps, float]:
    """Run one episode per reset seed, each step the teacher's action with probability
    ``beta`` (always without a ``policy``), else the policy's; keep the steps whose teacher
    phase is in ``phases`` (None: all), with the teacher's action, of every episode (of the
    successful ones with ``successful_only``). The steps and the share of successful
    episodes."""
    from dg16m_core.progress import progress_bar

    steps, successes = Steps(), 0
    for seed in progress_bar(seeds, desc=desc, unit="episode"):
        obs, _ = env.reset(seed=seed)
        episode: tuple[list, list, list, list] = ([], [], [], [])
        while True:
            phase, label = teacher.decide(obs)
            if phases is None or phase in phases:
                for column, value in zip(
                    episode, (*observation_inputs(obs, args.n_points, rng), label), strict=True
                ):
                    column.append(value)
            take_teacher = policy is None or rng.random() < beta
            obs, _, terminated, truncated, info = env.step(label if take_teacher else policy(obs))
            if terminated or truncated:
                success = bool(info["success"])
                break
        successes += success
        if success or not successful_only:
            steps.add(*episode)
    return steps, successes / max(len(seeds), 1)


def training_pairs(
    steps: Steps,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-hand ``(2N, FEATURES)`` features, ``(2N, n_points, 3)`` goal-frame clouds and
    ``(2N, 7)`` goal-frame teacher actions of the steps."""
    states, clouds, heights, actions = steps.arrays()
    features, local, to_goal = hand_features(states, clouds, heights)
    return (
        features.reshape(-1, FEATURES),
        local.reshape(-1, *local.shape[2:]),
        goal_frame_actions(actions, to_goal).reshape(-1, 7),
    )


def train(steps: Steps, args: Args) -> tuple[LiftCloudPolicy, float]:
    """Fit a fresh network to the per-hand pairs of ``steps``; the policy and the last
    epoch's mean loss."""
    from dg16m_core.progress import progress_bar

    x, c, y = training_pairs(steps)
    torch.manual_seed(args.seed)
    mean, std = x.mean(axis=0), x.std(axis=0) + 1e-3
    xt, ct, yt = torch.from_numpy((x - mean) / std), torch.from_numpy(c), torch.from_numpy(y)
    closing = (yt[:, 6] > 0).float()
    encoder = tuple(int(w) for w in args.encoder.split(","))
    network = make_network(args.hidden, args.layers, encoder)
    optimiser = torch.optim.Adam(network.parameters(), lr=args.learning_rate)
    batches = (len(xt) + args.batch_size - 1) // args.batch_size
    schedule = torch.optim.lr_scheduler.OneCycleLR(
        optimiser, args.learning_rate, total_steps=args.epochs * batches
    )
    generator = torch.Generator().manual_seed(args.seed)
    mean_loss = float("nan")
    for _ in progress_bar(range(args.epochs), desc=f"training on {len(xt)} pairs", unit="epoch"):
        order = torch.randperm(len(xt), generator=generator)
        total = 0.0
        for start in range(0, len(xt), args.batch_size):
            batch = order[start : start + args.batch_size]
            out = network(xt[batch], ct[batch])
            motion = ((torch.tanh(out[:, :6]) - yt[batch, :6]) ** 2).mean()
            finger = torch.nn.functional.binary_cross_entropy_with_logits(out[:, 6], closing[batch])
            loss = (6.0 * motion + finger) / 7.0
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            schedule.step()
            total += loss.item() * len(batch)
        mean_loss = total / len(xt)
    policy = LiftCloudPolicy(
        network, mean, std, args.hidden, args.layers, encoder, args.n_points, args.seed
    )
    return policy, mean_loss


def evaluators(test_ids: list[str], args: Args) -> tuple[Any, Any]:
    """The ``policy`` evaluators with pointcloud observations: ``eval_episodes`` seeded
    episodes on the procedural held-out objects, and ``real_eval_episodes`` on the real
    benchmark's held-out objects (None when 0)."""
    kwargs = {"obs_mode": "pointcloud"}
    procedural = policy_evaluator(
        ENV_ID, args.eval_episodes, args.eval_seed, {"object_ids": test_ids, **kwargs}
    )
    if not args.real_eval_episodes:
        return procedural, None
    real_ids = split_objects(list(load_benchmark_ref("real", lazy=True).object_ids))[1]
    real_kwargs = {"benchmark": "real", "object_ids": real_ids, **kwargs}
    return procedural, policy_evaluator(
        ENV_ID, args.real_eval_episodes, args.eval_seed, real_kwargs
    )


def main() -> None:
    args = parse_args(Args, __doc__.split("\n\n")[0])
    torch.set_num_threads(args.threads)
    phases = None if args.dagger_phases == "all" else set(args.dagger_phases.split(","))
    if phases is not None and not phases <= set(PHASES):
        raise SystemExit(
            f"--dagger-phases: expected 'all' or phases among {PHASES}, found {args.dagger_phases!r}"
        )
    if args.teacher not in ("recovering", "planning"):
        raise SystemExit(f"--teacher: expected recovering or planning, found {args.teacher!r}")
    train_ids, test_ids = output_and_split(args.out)
    teacher = make_lift_expert(args.teacher)
    rng = np.random.default_rng(args.seed)
    env = make_env(train_ids, args.episode_steps)
    seconds = {"collection": 0.0, "training": 0.0, "dagger_rollouts": 0.0, "evaluation": 0.0}

    # --- teacher demonstrations, collected online -------------------------------------------
    started = time.perf_counter()
    seeds = range(args.seed, args.seed + args.teacher_episodes)
    steps, teacher_rate = rollouts(
        env, teacher, None, seeds, args, rng, successful_only=True, desc="teacher episodes"
    )
    seconds["collection"] = time.perf_counter() - started
    print(
        f"teacher: {teacher_rate:.0%} of {args.teacher_episodes} episodes succeeded, {len(steps)} steps "
        f"kept ({seconds['collection']:.0f} s)"
    )

    # --- behaviour cloning, then DAgger on the training objects --------------------------
    started = time.perf_counter()
    policy, loss = train(steps, args)
    seconds["training"] += time.perf_counter() - started
    rounds = [{"round": 0, "steps": len(steps), "loss": loss, "rollout_success": None}]
    print(f"behaviour cloning: loss {loss:.4f} ({seconds['training']:.0f} s)")
    for i in range(args.dagger_rounds):
        beta = args.dagger_beta * 0.5**i
        first = args.dagger_seed + i * args.dagger_episodes
        started = time.perf_counter()
        new, rate = rollouts(
            env,
            teacher,
            policy,
            range(first, first + args.dagger_episodes),
            args,
            rng,
            beta=beta,
            phases=phases,
            desc=f"DAgger rollouts (beta {beta:.2f})",
        )
        steps.parts += new.parts
        seconds["dagger_rollouts"] += time.perf_counter() - started
        started = time.perf_counter()
        policy, loss = train(steps, args)
        seconds["training"] += time.perf_counter() - started
        rounds.append({"round": i + 1, "steps": len(steps), "loss": loss, "rollout_success": rate})
        print(
            f"DAgger round {i + 1}: rollouts {rate:.0%} successful (beta {beta:.2f}), "
            f"{len(steps)} steps, loss {loss:.4f}"
        )
    env.close()
    policy.save(args.out / "policy.pt")

    # --- evaluation on held-out objects -------------------------------------------------------
    def random_actions(observation: Any) -> np.ndarray:
        return rng.uniform(-1.0, 1.0, size=14).astype(np.float32)

    started = time.perf_counter()
    evaluator, real_evaluator = evaluators(test_ids, args)
    results: dict[str, EvaluationResult] = {
        "bc_dagger_cloud": evaluator.evaluate(policy),
        "expert": evaluator.evaluate(teacher),
        "random_actions": evaluator.evaluate(random_actions),
    }
    if real_evaluator is not None:
        results["bc_dagger_cloud_real"] = real_evaluator.evaluate(policy)
        results["expert_real"] = real_evaluator.evaluate(teacher)
    seconds["evaluation"] = time.perf_counter() - started
    print("seconds: " + ", ".join(f"{k} {v:.0f}" for k, v in seconds.items()))

    # --- picture and results ------------------------------------------------------------
    plot_results(args.out / "success_rates.png", results, rounds, f"{ENV_ID} (pointcloud)")
    write_run(
        args.out / "results.json",
        args,
        results,
        env_id=ENV_ID,
        obs_mode="pointcloud",
        teacher={
            "name": type(teacher).__name__,
            "episodes": args.teacher_episodes,
            "success_rate": teacher_rate,
        },
        rounds=rounds,
        train_objects=len(train_ids),
        test_objects=len(test_ids),
        seconds=seconds,
    )
    print_results(results, args.out)


if __name__ == "__main__":
    main()
