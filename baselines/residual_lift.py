"""Residual PPO on ``dg16m_env/DualGraspLift-v2`` (``--env-id``: or ``-v1``): fine-tune a
behaviour-cloned policy with the v1 reward (v2's is the same), by learning a correction on top
of it.

Reads top to bottom (CleanRL style, after ``ppo_continuous_action.py``): one dataclass of
arguments, the pieces of an iteration in the order they run (:func:`collect` a rollout,
:func:`advantages_and_returns`, :func:`ppo_update`), then the run (:func:`main`).

1. Load the base policy (``policy.pt`` of :mod:`baselines.bc_lift`) and wrap it in a
   :class:`~baselines.lift_residual_policy.LiftResidualPolicy` whose residual starts at zero:
   before any update the policy *is* the base policy (plus the exploration noise).
2. Roll it out on the training objects (every object not held out by
   :func:`~dg16m_env.envs.objects.split_objects`) in ``num_envs`` environments (batched
   network calls; :class:`~dg16m_env.envs.lift.vector.LiftVectorEnv` steps them in this
   process and a worker, for v2 and v1 alike), ``reward_mode="normalized_dense"``: a step
   pays at most 1, the success step what the steps left could have paid (the v1 bound), so
   the return is highest for the fastest success. Rewards are multiplied by ``reward_scale`` for the critic.
   An episode that reaches ``T`` (200 steps) ends there by the task's definition (``elapsed``
   is observed), so a truncation is treated as an end, not bootstrapped.
3. PPO on the residual's Gaussian (clipped objective, GAE, advantage normalisation, a KL stop):
   the first ``critic_warmup`` iterations train the critic only, so that the actor's first
   steps follow a value function that has seen the base policy's returns; ``residual_coef``
   can pull the residual towards zero (the base policy).
4. Evaluate on the held-out objects with the registered ``policy`` evaluator, the residual
   policy (its mean), its base and uniformly random actions on the same seeded episodes (reset
   seeds ``eval_seed + i``, those of ``baselines.bc_lift``), each with a Wilson 95% interval;
   then on the real benchmark's held-out objects when asked.
5. Write the policy (``policy.pt``, :meth:`LiftResidualPolicy.load`), the learning curve
   (``learning_curve.png``: success and return of the training episodes) and the results
   (JSON) to ``--out``.

    .venv/bin/python -m baselines.residual_lift --base-policy runs/bc_lift/policy.pt --out runs/residual_lift

Budget and outcome: 400,000 steps train in about 13 min on one core, the evaluation takes
about 7 min more. Measured (baselines/RESULTS.md): no setting tried so far improves on its base
policy; exploration noise alone costs the base policy's success (std 0.1: 60% -> about 25% on
the training rollouts), and the defaults here (the least harmful of six runs; 1,000,000 steps
changed nothing) keep the base's procedural held-out rate within its interval.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import dg16m_env  # noqa: F401  registers the environments
from baselines.lift_bc_policy import LiftBCPolicy
from baselines.lift_residual_policy import (
    ACTOR_INPUTS,
    CRITIC_INPUTS,
    RESIDUAL_SIZE,
    LiftResidualPolicy,
    compose_actions,
)
from baselines.sb3_common import (
    lift_held_out_evaluators,
    output_and_split,
    parse_args,
    print_results,
    uniform_actions,
    write_run,
)
from dg16m_core.atomic import atomic_path
from dg16m_env.envs.lift.demo_files import ENV_IDS
from dg16m_env.envs.lift.vector import LiftVectorEnv
from dg16m_env.evaluators import EvaluationResult


@dataclass
class Args:
    seed: int = 0
    """seed of the networks, the exploration noise, the minibatches and the random baseline"""
    env_id: str = "dg16m_env/DualGraspLift-v2"
    """the environment: dg16m_env/DualGraspLift-v2 or -v1 (the base policy's, best)"""
    base_policy: str = "runs/bc_lift/policy.pt"
    """the behaviour-cloned policy to fine-tune (policy.pt written by baselines.bc_lift)"""
    total_timesteps: int = 300_000
    """environment steps of training"""
    num_envs: int = 8
    """environments stepped together (LiftVectorEnv: this process and a worker)"""
    num_steps: int = 256
    """steps per environment per rollout"""
    learning_rate: float = 3e-5
    """Adam learning rate (constant)"""
    gamma: float = 0.99
    """discount"""
    gae_lambda: float = 0.95
    """GAE lambda"""
    num_minibatches: int = 8
    """minibatches per epoch"""
    update_epochs: int = 4
    """epochs over each rollout"""
    clip_coef: float = 0.1
    """PPO's ratio clip"""
    vf_coef: float = 0.5
    """weight of the value loss"""
    max_grad_norm: float = 0.5
    """gradient norm clip"""
    target_kl: float = 0.01
    """stop an update's epochs when the approximate KL exceeds this"""
    init_std: float = 0.03
    """the residual's initial standard deviation (action units)"""
    hidden: int = 256
    """width of the actor's and the critic's two hidden layers"""
    reward_mode: str = "normalized_dense"
    """the v1 reward mode trained on"""
    reward_scale: float = 0.1
    """rewards are multiplied by this for the critic"""
    critic_warmup: int = 20
    """first iterations that train the critic only"""
    residual_coef: float = 0.0
    """weight of the mean squared residual (action units) in the loss: keeps the policy near its base"""
    train_seed: int = 2_000_000
    """reset seed of the first training environment (environment k: train_seed + k)"""
    eval_episodes: int = 200
    """seeded evaluation episodes on the procedural benchmark's held-out objects"""
    real_eval_episodes: int = 0
    """seeded evaluation episodes on the real benchmark's held-out objects (0: skip)"""
    eval_seed: int = 100_000
    """first seed of the evaluation episodes"""
    threads: int = 1
    """torch threads"""
    out: Path = Path("runs/residual_lift")
    """output folder: policy, learning curve, results"""


def rolling(curve: list[dict[str, float]], key: str, episodes: int = 200) -> np.ndarray:
    """Per iteration: the mean of ``key`` over the training episodes of the last iterations that
    hold at least ``episodes`` of them (weighted by each iteration's episodes)."""
    counts = np.array([c["episodes"] for c in curve], float)
    sums = np.array([c[key] * c["episodes"] for c in curve], float)
    out = np.empty(len(curve))
    for i in range(len(curve)):
        first = i
        while first > 0 and counts[first : i + 1].sum() < episodes:
            first -= 1
        out[i] = sums[first : i + 1].sum() / counts[first : i + 1].sum()
    return out


def plot_curve(
    path: Path, curve: list[dict[str, float]], results: dict[str, EvaluationResult]
) -> None:
    """Success rate and mean return of the training episodes (each iteration's, faint; over the
    last 200 or more episodes, bold) against environment steps, with the held-out success of
    each evaluated policy."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8.4, 3.8))
    success, returns = fig.subplots(1, 2)
    steps = [c["timesteps"] for c in curve]
    for axis, key in ((success, "success"), (returns, "return")):
        axis.plot(steps, [c[key] for c in curve], ".", color="C0", alpha=0.25, ms=3)
        if curve:
            axis.plot(steps, rolling(curve, key), "-", color="C0", lw=2, label="training episodes")
        axis.set_xlabel("environment steps")
    for k, (name, result) in enumerate(results.items()):
        rate = result.metrics["success_rate"]
        success.axhline(rate["rate"], color=f"C{k + 1}", ls="--", label=f"{name} (held-out)")
    success.set_ylabel("success rate")
    success.set_ylim(0, 1)
    returns.set_ylabel("mean return (normalized_dense)")
    fig.legend(*success.get_legend_handles_labels(), loc="lower center", ncol=3, fontsize=7)
    fig.suptitle("Residual PPO on a behaviour-cloned DualGraspLift-v1 policy")
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)


@dataclass
class Rollout:
    """One rollout's tensors, ``(steps, envs, ...)``: what PPO's update reads."""

    actor_in: Any
    critic_in: Any
    residuals: Any
    logprobs: Any
    rewards: Any
    dones: Any
    values: Any

    @classmethod
    def zeros(cls, t: int, n: int) -> Rollout:
        """Zeroed tensors for ``t`` steps of ``n`` environments."""
        import torch

        return cls(
            torch.zeros((t, n, 2, ACTOR_INPUTS)),
            torch.zeros((t, n, CRITIC_INPUTS)),
            torch.zeros((t, n, 2, RESIDUAL_SIZE)),
            *(torch.zeros((t, n)) for _ in range(4)),
        )


def distribution(policy: LiftResidualPolicy, actor_in: Any) -> Any:
    """The residual's Gaussian for the actor inputs ``actor_in``."""
    import torch

    return torch.distributions.Normal(policy.actor(actor_in), policy.log_std.exp())


def collect(
    envs: Any, policy: LiftResidualPolicy, buffer: Rollout, state: dict[str, Any], scale: float
) -> tuple[list[bool], list[float]]:
    """Fill ``buffer`` with one rollout from ``state`` (the policy's ``inputs``, ``done``, each
    environment's ``episode_return``: updated in place for the next rollout); the success and
    return of each episode that ended."""
    import torch

    finished_success, finished_return = [], []
    inputs, done, episode_return = state["inputs"], state["done"], state["episode_return"]
    for step in range(buffer.rewards.shape[0]):
        a_in, c_in, base_out, to_goal = inputs
        a_in_t, c_in_t = torch.from_numpy(a_in), torch.from_numpy(c_in)
        with torch.no_grad():
            dist = distribution(policy, a_in_t)
            residual = dist.sample()
            buffer.values[step] = policy.critic(c_in_t)[:, 0]
        buffer.actor_in[step], buffer.critic_in[step], buffer.residuals[step] = (
            a_in_t,
            c_in_t,
            residual,
        )
        buffer.logprobs[step] = dist.log_prob(residual).sum(dim=(1, 2))
        buffer.dones[step] = done
        action = compose_actions(base_out, residual.numpy(), to_goal)
        obs, reward, terminated, truncated, info = envs.step(action)
        inputs = policy.inputs(obs)
        episode_return += reward
        buffer.rewards[step] = torch.as_tensor(reward * scale, dtype=torch.float32)
        ended = np.logical_or(terminated, truncated)
        done = torch.as_tensor(ended, dtype=torch.float32)
        for k in np.flatnonzero(ended):
            finished_success.append(bool(info["final_info"]["success"][k]))
            finished_return.append(float(episode_return[k]))
            episode_return[k] = 0.0
    state["inputs"], state["done"] = inputs, done
    return finished_success, finished_return


def advantages_and_returns(
    policy: LiftResidualPolicy, buffer: Rollout, state: dict[str, Any], args: Args
) -> tuple[Any, Any]:
    """GAE over ``buffer``; ``dones[s]`` says the episode ended before step s (its obs is a
    reset's), ``state`` holds the observation after the rollout."""
    import torch

    t, n = buffer.rewards.shape
    values, dones, done = buffer.values, buffer.dones, state["done"]
    with torch.no_grad():
        next_value = policy.critic(torch.from_numpy(state["inputs"][1]))[:, 0]
        advantages = torch.zeros((t, n))
        last = torch.zeros(n)
        for s in reversed(range(t)):
            following = next_value if s == t - 1 else values[s + 1]
            alive = 1.0 - (done if s == t - 1 else dones[s + 1])
            delta = buffer.rewards[s] + args.gamma * following * alive - values[s]
            last = delta + args.gamma * args.gae_lambda * alive * last
            advantages[s] = last
        returns = advantages + values
    return advantages, returns


def ppo_update(
    policy: LiftResidualPolicy,
    optimiser: Any,
    buffer: Rollout,
    advantages: Any,
    returns: Any,
    args: Args,
    iteration: int,
) -> float:
    """PPO's epochs over ``buffer`` (the critic only before ``critic_warmup`` iterations); the
    last approximate KL."""
    import torch

    actor, critic = policy.actor, policy.critic
    params = [*actor.parameters(), *critic.parameters(), policy.log_std]
    batch = buffer.rewards.numel()
    minibatch = max(batch // args.num_minibatches, 1)
    b_actor_in, b_critic_in = (
        buffer.actor_in.reshape(batch, 2, -1),
        buffer.critic_in.reshape(batch, -1),
    )
    b_residuals, b_logprobs = buffer.residuals.reshape(batch, 2, -1), buffer.logprobs.reshape(batch)
    b_advantages, b_returns = advantages.reshape(batch), returns.reshape(batch)
    train_actor = iteration >= args.critic_warmup
    kl = 0.0
    generator = torch.Generator().manual_seed(args.seed * 100_003 + iteration)
    for _ in range(args.update_epochs):
        order = torch.randperm(batch, generator=generator)
        for first in range(0, batch, minibatch):
            idx = order[first : first + minibatch]
            v_loss = 0.5 * ((critic(b_critic_in[idx])[:, 0] - b_returns[idx]) ** 2).mean()
            loss = args.vf_coef * v_loss
            if train_actor:
                dist = distribution(policy, b_actor_in[idx])
                log_ratio = dist.log_prob(b_residuals[idx]).sum(dim=(1, 2)) - b_logprobs[idx]
                ratio = log_ratio.exp()
                with torch.no_grad():
                    kl = float(((ratio - 1) - log_ratio).mean())
                adv = b_advantages[idx]
                adv = (adv - adv.mean()) / (adv.std() + 1e-8)
                pg_loss = torch.max(
                    -adv * ratio,
                    -adv * torch.clamp(ratio, 1 - args.clip_coef, 1 + args.clip_coef),
                ).mean()
                loss = loss + pg_loss + args.residual_coef * (dist.mean**2).mean()
            optimiser.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(params, args.max_grad_norm)
            optimiser.step()
        if train_actor and kl > args.target_kl:
            break
    return kl


def main() -> None:
    args = parse_args(Args, __doc__.split("\n\n")[0])
    import gymnasium as gym
    import torch

    from dg16m_core.progress import progress_bar

    if args.env_id not in ENV_IDS:
        raise SystemExit(f"--env-id: expected one of {ENV_IDS}, found {args.env_id!r}")
    for name in ("total_timesteps", "num_envs", "num_steps", "num_minibatches", "update_epochs"):
        if getattr(args, name) < 1:
            raise SystemExit(
                f"--{name.replace('_', '-')}: expected >= 1, found {getattr(args, name)}"
            )
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    try:
        base = LiftBCPolicy.load(args.base_policy)
    except ValueError as exc:
        raise SystemExit(f"--base-policy: {exc}") from None
    policy = LiftResidualPolicy.from_base(base, args.hidden, args.init_std)
    params = [*policy.actor.parameters(), *policy.critic.parameters(), policy.log_std]
    optimiser = torch.optim.Adam(params, lr=args.learning_rate, eps=1e-5)
    train_ids, test_ids = output_and_split(args.out)
    make = functools.partial(
        gym.make, args.env_id, object_ids=train_ids, reward_mode=args.reward_mode
    )
    envs = LiftVectorEnv([make] * args.num_envs, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)

    # --- training --------------------------------------------------------------------------
    n, t = args.num_envs, args.num_steps
    iterations = max(args.total_timesteps // (n * t), 1)
    buffer = Rollout.zeros(t, n)
    started = time.perf_counter()
    obs, _ = envs.reset(seed=args.train_seed)
    state = {"inputs": policy.inputs(obs), "done": torch.zeros(n), "episode_return": np.zeros(n)}
    curve: list[dict[str, float]] = []
    timesteps = 0
    bar = progress_bar(range(iterations), desc="residual PPO", unit="iteration")
    for iteration in bar:
        finished_success, finished_return = collect(envs, policy, buffer, state, args.reward_scale)
        timesteps += n * t
        advantages, returns = advantages_and_returns(policy, buffer, state, args)
        kl = ppo_update(policy, optimiser, buffer, advantages, returns, args, iteration)
        if finished_success:
            curve.append(
                {
                    "timesteps": timesteps,
                    "episodes": len(finished_success),
                    "success": float(np.mean(finished_success)),
                    "return": float(np.mean(finished_return)),
                    "kl": kl,
                    "std": float(policy.log_std.detach().exp().mean()),
                }
            )
            bar.set_postfix(success=f"{curve[-1]['success']:.2f}", std=f"{curve[-1]['std']:.3f}")
    envs.close()
    train_s = time.perf_counter() - started
    policy.actor.eval()
    policy.critic.eval()
    policy.save(args.out / "policy.pt")

    # --- evaluation on held-out objects -------------------------------------------------------
    started = time.perf_counter()
    evaluator, real_evaluator = lift_held_out_evaluators(
        args.env_id, test_ids, args.eval_episodes, args.real_eval_episodes, args.eval_seed
    )
    results: dict[str, EvaluationResult] = {
        "bc_residual": evaluator.evaluate(policy),
        "bc_base": evaluator.evaluate(base),
        "random_actions": evaluator.evaluate(uniform_actions((14,), args.seed)),
    }
    if real_evaluator is not None:
        results["bc_residual_real"] = real_evaluator.evaluate(policy)
        results["bc_base_real"] = real_evaluator.evaluate(base)
    eval_s = time.perf_counter() - started

    # --- picture and results ------------------------------------------------------------
    plot_curve(args.out / "learning_curve.png", curve, results)
    write_run(
        args.out / "results.json",
        args,
        results,
        env_id=args.env_id,
        curve=curve,
        train_objects=len(train_ids),
        test_objects=len(test_ids),
        train_timesteps=timesteps,
        train_seconds=train_s,
        eval_seconds=eval_s,
    )
    print_results(results, args.out)


if __name__ == "__main__":
    main()
