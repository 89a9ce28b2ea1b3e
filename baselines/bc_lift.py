"""Behaviour cloning with DAgger on ``dg16m_env/DualGraspLift-v2`` (or ``-v1``: the
demonstrations' env): learn to lift from the state-feedback expert's demonstrations.

Reads top to bottom (CleanRL style): one dataclass of arguments, then the run.

1. Split the benchmark's objects: every third object held out for evaluation
   (:func:`dg16m_env.envs.objects.split_objects`).
2. Read the demonstrations: a Minari dataset written by ``dg16m demos collect`` (episodes of
   :class:`~dg16m_env.envs.lift.experts.FeedbackLiftExpert`, or with ``--expert recovering``
   of :class:`~dg16m_env.envs.lift.recovering_expert.RecoveringLiftExpert`, on the training
   objects); the successful episodes' (state, action) pairs are the first training set. The
   dataset's env id (``dg16m demos collect --env-id``) is the env of the DAgger rollouts and
   the evaluation, and its expert labels the DAgger states and is the evaluation's teacher.
3. Behaviour cloning: an MLP on each hand's goal-frame features
   (:mod:`baselines.lift_bc_policy`), mean squared error on the motion (through tanh) plus a
   binary cross-entropy on the finger command, Adam with a one-cycle learning rate.
4. DAgger: roll the current policy out on the training objects (new seeds; for round ``i`` each
   step is the expert's with probability ``dagger_beta * 0.5**i``), label the visited states
   with the expert's action (the expert is a function of the observation, so it can be asked
   anywhere), add those of the phases in ``dagger_phases`` to the training set, train again
   from scratch. Only the grasp phases by default (``close``, ``lift``): the policy's failures
   are there (it twists a lifted object out of the hands, correcting errors the expert ignores
   while lifting), and the expert's labels there are local and consistent; off its approach
   path the expert retreats up and across, a different strategy that the network averages with
   path following. Measured on 100 held-out episodes: behaviour cloning alone 49% [39.4,
   58.7]; one round keeping every label fell to 15 of 40; one round of grasp-phase labels 61%
   [51.2, 70.0] (baselines/RESULTS.md). With ``--dagger-on-path true`` (demonstrations of
   :class:`~dg16m_env.envs.lift.recovering_expert.RecoveringLiftExpert`) the approach states
   where both hands follow their approach paths are labelled too
   (:meth:`~dg16m_env.envs.lift.recovering_expert.RecoveringLiftExpert.following_path`): there
   that expert's labels are local as well (on along the path, or back along it), and they
   teach the way back after a dropped grasp; every approach label, the way round over the
   object included, still costs (baselines/RESULTS.md, issue 57).
5. Evaluate on the held-out objects with the registered ``policy`` evaluator: the learned
   policy, the expert and uniformly random actions on the same seeded episodes, each with a
   Wilson 95% interval; then on the real benchmark's held-out objects when asked.
6. Write the policy (``policy.pt``, :meth:`~baselines.lift_bc_policy.LiftBCPolicy.load`), a
   picture of the success rates and of each DAgger round's rollouts (``success_rates.png``)
   and the results (JSON) to ``--out``.

    dg16m demos collect --episodes 500 --workers 2 --out runs/demos
    .venv/bin/python -m baselines.bc_lift --demos runs/demos/dg16m/lift-expert-v0 --out runs/bc_lift

Budget: see baselines/RESULTS.md for the measured times on 2 CPU cores.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import dg16m_env  # noqa: F401  registers the environments
from baselines.lift_bc_policy import (
    FEATURES,
    LiftBCPolicy,
    goal_frame_actions,
    hand_features,
    make_network,
)
from baselines.sb3_common import (
    lift_held_out_evaluators,
    output_and_split,
    parse_args,
    print_results,
    write_run,
)
from dg16m_core.atomic import atomic_path
from dg16m_env.envs.lift.expert_registry import make_lift_expert
from dg16m_env.envs.lift.experts import FeedbackLiftExpert
from dg16m_env.envs.lift.observations import STATE_SIZE
from dg16m_env.envs.lift.recovering_expert import RecoveringLiftExpert
from dg16m_env.evaluators import EvaluationResult

PHASES = ("approach", "close", "lift")
"""The expert's phases (:meth:`FeedbackLiftExpert.phase`)."""


@dataclass
class Args:
    seed: int = 0
    """seed of the network, the minibatches, the DAgger rollouts and the random baseline"""
    demos: str = "runs/demos/dg16m/lift-expert-v0"
    """the demonstrations: a Minari dataset folder written by 'dg16m demos collect', or a dataset id under MINARI_DATASETS_PATH"""
    hidden: int = 512
    """width of each hidden layer"""
    layers: int = 3
    """hidden layers"""
    epochs: int = 30
    """passes over the training set each time the network is trained"""
    batch_size: int = 256
    """minibatch size"""
    learning_rate: float = 1e-3
    """peak learning rate (one-cycle schedule)"""
    dagger_rounds: int = 1
    """DAgger rounds after behaviour cloning (0: behaviour cloning only)"""
    dagger_episodes: int = 100
    """episodes rolled out on the training objects per DAgger round"""
    dagger_beta: float = 0.0
    """probability that a rollout step takes the expert's action in the first round (halved each round)"""
    dagger_phases: str = "close,lift"
    """the expert's phases whose DAgger labels are kept (comma-separated; 'all' keeps every label)"""
    dagger_on_path: bool = False
    """also keep the approach labels where both hands follow their approach paths (an expert with 'following_path': recovering)"""
    dagger_seed: int = 1_000_000
    """first seed of the DAgger rollouts (apart from the demonstrations' and the evaluation's)"""
    eval_episodes: int = 100
    """seeded evaluation episodes on the procedural benchmark's held-out objects"""
    real_eval_episodes: int = 0
    """seeded evaluation episodes on the real benchmark's held-out objects (0: skip)"""
    eval_seed: int = 100_000
    """first seed of the evaluation episodes"""
    threads: int = 1
    """torch threads"""
    out: Path = Path("runs/bc_lift")
    """output folder: policy, learning curve, results"""


def demonstrations_expert(source: str) -> str:
    """The class name of the expert that collected the Minari dataset ``source``
    (``FeedbackLiftExpert`` for datasets that do not say)."""
    from dg16m_env.envs.lift.demo_files import demos_metadata, open_lift_demos

    expert = demos_metadata(open_lift_demos(source)).get("expert") or {}
    return str(expert.get("name", "FeedbackLiftExpert"))


def load_demonstrations(source: str) -> tuple[np.ndarray, np.ndarray, int, int, str]:
    """The successful episodes' ``(N, 117)`` states and ``(N, 14)`` actions of a Minari dataset
    of ``"state"`` observations, the number of episodes and of successful ones, and the env id
    they were collected on."""
    from dg16m_env.envs.lift.demo_files import ENV_IDS, demos_metadata, open_lift_demos

    dataset = open_lift_demos(source)
    metadata = demos_metadata(dataset)
    env_id = metadata.get("env_id")
    if env_id not in ENV_IDS:
        raise SystemExit(f"{source}: expected demonstrations on one of {ENV_IDS}, found {env_id!r}")
    mode = metadata.get("obs_mode")
    if mode != "state":
        raise SystemExit(f"{source}: expected demonstrations with obs_mode 'state', found {mode!r}")
    states, actions, episodes, successes = [], [], 0, 0
    for episode in dataset.iterate_episodes():
        episodes += 1
        if not bool(np.asarray(episode.infos["success"])[-1]):
            continue
        successes += 1
        states.append(np.asarray(episode.observations)[:-1])
        actions.append(np.asarray(episode.actions))
    if not states:
        raise SystemExit(f"{source}: expected successful demonstrations, found none")
    return np.concatenate(states), np.concatenate(actions), episodes, successes, env_id


def training_pairs(states: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 117) states and (N, 14) expert actions -> (2N, FEATURES) per-hand features and (2N, 7)
    per-hand actions in the goal frames: what the network fits (computed once per state)."""
    features, to_goal = hand_features(states)
    return features.reshape(-1, FEATURES), goal_frame_actions(actions, to_goal).reshape(-1, 7)


def train(x: np.ndarray, y: np.ndarray, args: Args) -> tuple[LiftBCPolicy, float]:
    """Fit a fresh network to the per-hand pairs of :func:`training_pairs`; the policy and the
    last epoch's mean loss."""
    import torch

    torch.manual_seed(args.seed)
    mean, std = x.mean(axis=0), x.std(axis=0) + 1e-3
    xt = torch.from_numpy((x - mean) / std)
    yt = torch.from_numpy(y)
    closing = (yt[:, 6] > 0).float()
    network = make_network(args.hidden, args.layers)
    optimiser = torch.optim.Adam(network.parameters(), lr=args.learning_rate)
    batches = (len(xt) + args.batch_size - 1) // args.batch_size
    schedule = torch.optim.lr_scheduler.OneCycleLR(
        optimiser, args.learning_rate, total_steps=args.epochs * batches
    )
    generator = torch.Generator().manual_seed(args.seed)
    mean_loss = float("nan")
    for _ in range(args.epochs):
        order = torch.randperm(len(xt), generator=generator)
        total = 0.0
        for start in range(0, len(xt), args.batch_size):
            batch = order[start : start + args.batch_size]
            out = network(xt[batch])
            motion = ((torch.tanh(out[:, :6]) - yt[batch, :6]) ** 2).mean()
            finger = torch.nn.functional.binary_cross_entropy_with_logits(out[:, 6], closing[batch])
            loss = (6.0 * motion + finger) / 7.0
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            schedule.step()
            total += loss.item() * len(batch)
        mean_loss = total / len(xt)
    return LiftBCPolicy(network, mean, std, args.hidden, args.layers), mean_loss


def _both_on_path(expert: FeedbackLiftExpert, obs: Any) -> bool:
    """Whether both hands of an approach state follow their paths (only a
    :class:`~dg16m_env.envs.lift.recovering_expert.RecoveringLiftExpert` says so)."""
    return isinstance(expert, RecoveringLiftExpert) and bool(expert.following_path(obs).all())


def dagger_rollouts(
    env: Any,
    policy: LiftBCPolicy,
    expert: FeedbackLiftExpert,
    seeds: range,
    beta: float,
    phases: set[str] | None,
    rng: Any,
    on_path: bool = False,
) -> tuple[np.ndarray, np.ndarray, float]:
    """The visited states whose expert phase is in ``phases`` (None: all) or, with ``on_path``,
    that are approach states where both hands follow their paths (``expert.following_path``),
    the expert's actions there, and the share of episodes that succeeded."""
    from dg16m_core.progress import progress_bar

    states, labels, successes = [], [], 0
    for seed in progress_bar(seeds, desc=f"DAgger rollouts (beta {beta:.2f})", unit="episode"):
        obs, _ = env.reset(seed=seed)
        while True:
            phase, label = expert.decide(obs)
            if (
                phases is None
                or phase in phases
                or (on_path and phase == "approach" and _both_on_path(expert, obs))
            ):
                states.append(obs)
                labels.append(label)
            action = label if rng.random() < beta else policy(obs)
            obs, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                successes += bool(info["success"])
                break
    empty = (np.zeros((0, STATE_SIZE)), np.zeros((0, 14)))
    if not states:
        return *empty, successes / max(len(seeds), 1)
    return np.array(states), np.array(labels), successes / max(len(seeds), 1)


def plot_results(
    path: Path, results: dict[str, EvaluationResult], rounds: list[dict[str, Any]], env_id: str
) -> None:
    """Each evaluated policy's success rate with its Wilson interval (bars), and the success of
    each DAgger round's rollouts on the training objects (points)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.2, 3.6))
    bars, curve = fig.subplots(1, 2, gridspec_kw={"width_ratios": [2.2, 1]})
    names = list(results)
    rates = [results[n].metrics["success_rate"] for n in names]
    y = np.arange(len(names))[::-1]
    values = np.array([r["rate"] for r in rates])
    low = values - np.array([r["ci_low"] for r in rates])
    high = np.array([r["ci_high"] for r in rates]) - values
    bars.barh(y, values, xerr=[low, high], color=[f"C{k}" for k in range(len(names))], capsize=3)
    for yi, rate in zip(y, rates, strict=True):
        bars.text(min(rate["ci_high"] + 0.02, 0.9), yi, f"{rate['rate']:.0%}", va="center")
    bars.set_yticks(y, [f"{n} ({r['episodes']})" for n, r in zip(names, rates, strict=True)])
    bars.set_xlim(0, 1)
    bars.set_xlabel("success rate, held-out objects (Wilson 95% CI)")
    done = [r for r in rounds if r["rollout_success"] is not None]
    curve.plot([r["round"] for r in done], [r["rollout_success"] for r in done], "o-")
    curve.set_xlabel("DAgger round")
    curve.set_ylabel("rollout success (training objects)")
    curve.set_ylim(0, 1)
    curve.set_xticks([r["round"] for r in rounds])
    fig.suptitle(f"Behaviour cloning + DAgger on {env_id.split('/')[-1]}")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)


def main() -> None:
    args = parse_args(Args, __doc__.split("\n\n")[0])
    import gymnasium as gym
    import torch

    torch.set_num_threads(args.threads)
    train_ids, test_ids = output_and_split(args.out)
    # DAgger labels and the evaluation's teacher: the expert that collected the demonstrations
    expert = make_lift_expert(demonstrations_expert(args.demos))
    rng = np.random.default_rng(args.seed)
    phases = None if args.dagger_phases == "all" else set(args.dagger_phases.split(","))
    if phases is not None and not phases <= set(PHASES):
        raise SystemExit(
            f"--dagger-phases: expected 'all' or phases among {PHASES}, found {args.dagger_phases!r}"
        )
    if args.dagger_on_path and not isinstance(expert, RecoveringLiftExpert):
        raise SystemExit(
            "--dagger-on-path: expected demonstrations of an expert that says when its hands "
            f"follow their paths (recovering), found {type(expert).__name__}"
        )

    # --- behaviour cloning on the demonstrations ---------------------------------------------
    started = time.perf_counter()
    states, actions, n_episodes, n_successes, env_id = load_demonstrations(args.demos)
    print(
        f"{args.demos}: {n_successes} of {n_episodes} episodes on {env_id} succeeded: "
        f"{len(states)} steps"
    )
    x, y = training_pairs(states, actions)
    policy, loss = train(x, y, args)
    rounds = [{"round": 0, "steps": len(states), "loss": loss, "rollout_success": None}]
    print(f"behaviour cloning: loss {loss:.4f}")

    # --- DAgger on the training objects -------------------------------------------------------
    env = gym.make(env_id, object_ids=train_ids)
    for i in range(args.dagger_rounds):
        beta = args.dagger_beta * 0.5**i
        first = args.dagger_seed + i * args.dagger_episodes
        seeds = range(first, first + args.dagger_episodes)
        new_states, new_actions, rate = dagger_rollouts(
            env, policy, expert, seeds, beta, phases, rng, args.dagger_on_path
        )
        new_x, new_y = training_pairs(new_states, new_actions)
        x, y = np.concatenate([x, new_x]), np.concatenate([y, new_y])
        policy, loss = train(x, y, args)
        steps = len(x) // 2
        rounds.append({"round": i + 1, "steps": steps, "loss": loss, "rollout_success": rate})
        print(
            f"DAgger round {i + 1}: rollouts {rate:.0%} successful (beta {beta:.2f}), "
            f"{steps} steps, loss {loss:.4f}"
        )
    env.close()
    train_s = time.perf_counter() - started
    policy.save(args.out / "policy.pt")

    # --- evaluation on held-out objects -------------------------------------------------------
    def random_actions(observation: Any) -> np.ndarray:
        return rng.uniform(-1.0, 1.0, size=14).astype(np.float32)

    started = time.perf_counter()
    evaluator, real_evaluator = lift_held_out_evaluators(
        env_id, test_ids, args.eval_episodes, args.real_eval_episodes, args.eval_seed
    )
    results: dict[str, EvaluationResult] = {
        "bc_dagger": evaluator.evaluate(policy),
        "expert": evaluator.evaluate(expert),
        "random_actions": evaluator.evaluate(random_actions),
    }
    if real_evaluator is not None:
        results["bc_dagger_real"] = real_evaluator.evaluate(policy)
        results["expert_real"] = real_evaluator.evaluate(expert)
    eval_s = time.perf_counter() - started

    # --- picture and results ------------------------------------------------------------
    plot_results(args.out / "success_rates.png", results, rounds, env_id)
    write_run(
        args.out / "results.json",
        args,
        results,
        env_id=env_id,
        demonstrations={"dataset": args.demos, "episodes": n_episodes, "successes": n_successes},
        rounds=rounds,
        train_objects=len(train_ids),
        test_objects=len(test_ids),
        train_seconds=train_s,
        eval_seconds=eval_s,
    )
    print_results(results, args.out)


if __name__ == "__main__":
    main()
