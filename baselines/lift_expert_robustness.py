"""How the Lift experts hold up when their actions are perturbed (issue 57).

Reads top to bottom (CleanRL style): one dataclass of arguments, then the run.

Each expert runs ``episodes`` seeded episodes (reset seeds ``seed + i``, the held-out seeds of
the Lift baselines) of ``dg16m_env/DualGraspLift-v2`` on the benchmark's held-out objects
(:func:`dg16m_env.envs.objects.split_objects`), in the observation mode the expert needs (its
``OBS_MODE``: ``"pointcloud"`` for the planning expert, which plans its approach on the cloud;
``"state"`` for the others), once clean and once perturbed: on each step,
with probability ``noise_probability``, N(0, ``noise_std``) is added to every action component
(action units; the sum clipped to [-1, 1]) while the expert's phase is one of
``noise_phases``. The perturbation's generator is seeded per episode (``seed + i``), so both
experts meet the same draws for as long as their phases agree. Success rates with Wilson 95%
intervals, how the failed episodes ended (termination and the expert's last phase) and each
episode's record (seed, object, success, termination, last phase, steps, steps perturbed) go to
``out`` (JSON); the rates to stdout and, with ``plot``, a bar chart.

    .venv/bin/python -m baselines.lift_expert_robustness --out runs/lift_robustness.json
"""

from __future__ import annotations

import collections
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from baselines.sb3_common import parse_args
from dg16m_core.atomic import write_json_atomic
from dg16m_core.progress import progress_bar

PHASES = ("approach", "close", "lift")
"""The experts' phases (``expert.decide(obs)[0]``)."""


@dataclass
class Args:
    experts: str = "feedback,recovering"
    """comma-separated experts (``dg16m_env.envs.lift.expert_registry.LIFT_EXPERTS``)"""
    benchmark: str = "procedural"
    """the benchmark whose held-out objects are lifted: procedural or real"""
    episodes: int = 200
    """episodes per expert and setting"""
    seed: int = 100000
    """first reset seed (the Lift baselines' held-out seeds)"""
    noise_std: float = 0.3
    """standard deviation of the added noise (action units)"""
    noise_probability: float = 0.3
    """probability that a step's action is perturbed"""
    noise_phases: str = "approach,close,lift"
    """comma-separated expert phases in which actions are perturbed"""
    clean: bool = True
    """also run each expert without noise"""
    out: Path = Path("runs/lift_robustness.json")
    """the results (JSON)"""
    plot: str = ""
    """a bar chart of the success rates (PNG path; empty: none)"""


def check_args(args: Args) -> tuple[list[str], set[str]]:
    """The experts and noisy phases asked for; ``ValueError`` naming what was expected."""
    from dg16m_env.envs.lift.expert_registry import LIFT_EXPERTS

    experts = [name.strip() for name in args.experts.split(",") if name.strip()]
    unknown = [name for name in experts if name not in LIFT_EXPERTS]
    if not experts or unknown:
        raise ValueError(
            f"experts: expected names from {sorted(LIFT_EXPERTS)}, found {args.experts!r}"
        )
    phases = {name.strip() for name in args.noise_phases.split(",") if name.strip()}
    if not phases or phases - set(PHASES):
        raise ValueError(f"noise_phases: expected names from {PHASES}, found {args.noise_phases!r}")
    if args.episodes < 1:
        raise ValueError(f"episodes: expected at least 1, found {args.episodes}")
    if not (np.isfinite(args.noise_std) and args.noise_std >= 0.0):
        raise ValueError(f"noise_std: expected a finite number >= 0, found {args.noise_std}")
    if not 0.0 <= args.noise_probability <= 1.0:
        raise ValueError(
            f"noise_probability: expected a number in [0, 1], found {args.noise_probability}"
        )
    return experts, phases


def run_episode(
    env: Any, expert: Any, seed: int, noise_std: float, probability: float, phases: set[str]
) -> dict[str, Any]:
    """One episode; its success, termination, the expert's last phase and the steps perturbed."""
    rng = np.random.default_rng(seed)
    observation, _ = env.reset(seed=seed)
    expert.reset()
    perturbed = steps = 0
    while True:
        phase, action = expert.decide(observation)
        if noise_std > 0.0 and phase in phases and rng.random() < probability:
            noise = rng.normal(0.0, noise_std, action.shape)
            action = np.clip(action + noise, -1.0, 1.0).astype(np.float32)
            perturbed += 1
        observation, _, terminated, truncated, info = env.step(action)
        steps += 1
        if terminated or truncated:
            return {
                "seed": seed,
                "object_id": str(info["object_id"]),
                "success": bool(info["success"]),
                "termination": str(info["termination"]) or "time_limit",
                "last_phase": phase,
                "steps": steps,
                "perturbed_steps": perturbed,
            }


def summarise(episodes: list[dict[str, Any]]) -> dict[str, Any]:
    """Success rate with its Wilson interval, and how the failures ended."""
    from dg16m_env.evaluators.policy import wilson_interval

    successes = sum(e["success"] for e in episodes)
    failures = collections.Counter(
        f"{e['termination']} in {e['last_phase']}" for e in episodes if not e["success"]
    )
    return {
        **wilson_interval(successes, len(episodes)),
        "successes": successes,
        "failures": dict(failures.most_common()),
        "mean_perturbed_steps": float(np.mean([e["perturbed_steps"] for e in episodes])),
    }


def plot_rates(results: dict[str, Any], path: Path) -> None:
    """Bars of each expert's success rate per setting with Wilson 95% intervals."""
    from dg16m_core.figures import new_figure, save_png

    rows = results["rates"]
    fig = new_figure(6.0, 3.2)
    ax = fig.add_subplot(1, 1, 1)
    settings = sorted({r["setting"] for r in rows})
    experts = list(dict.fromkeys(r["expert"] for r in rows))
    width = 0.8 / len(experts)
    for j, expert in enumerate(experts):
        for i, setting in enumerate(settings):
            row = next((r for r in rows if r["expert"] == expert and r["setting"] == setting), None)
            if row is None:
                continue
            x = i + (j - (len(experts) - 1) / 2) * width
            err = [[row["rate"] - row["ci_low"]], [row["ci_high"] - row["rate"]]]
            ax.bar(x, row["rate"], width, color=f"C{j}", label=expert if i == 0 else None)
            ax.errorbar(x, row["rate"], yerr=err, color="black", capsize=3, lw=1)
    noise = results["noise"]
    names = {
        "clean": "clean",
        "perturbed": f"perturbed: N(0, {noise['std']:g})\non {noise['probability']:.0%} of steps",
    }
    ax.set_xticks(range(len(settings)), [names.get(s, s) for s in settings])
    ax.set_ylim(0.0, 1.0)
    ax.set_ylabel("success (Wilson 95%)")
    ax.set_title(
        f"DualGraspLift-v2 experts, {results['benchmark']} held-out, {results['episodes']} episodes"
    )
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    save_png(fig, path, dpi=120)


def main(args: Args | None = None) -> dict[str, Any]:
    args = args or parse_args(Args, __doc__.split("\n\n")[0])
    experts, phases = check_args(args)
    import gymnasium as gym

    from dg16m_env.envs.lift.expert_registry import make_lift_expert
    from dg16m_env.envs.objects import split_objects
    from dg16m_env.evaluators import load_benchmark_ref

    ref = load_benchmark_ref(None if args.benchmark == "procedural" else args.benchmark)
    held_out = split_objects(list(ref.object_ids))[1]
    envs: dict[str, Any] = {}  # one per observation mode the experts need
    settings = ([("clean", 0.0)] if args.clean else []) + [("perturbed", args.noise_std)]
    started = time.monotonic()
    rows: list[dict[str, Any]] = []
    for name in experts:
        expert = make_lift_expert(name)
        obs_mode = expert.OBS_MODE
        if obs_mode not in envs:
            envs[obs_mode] = gym.make(
                "dg16m_env/DualGraspLift-v2",
                benchmark=ref,
                object_ids=held_out,
                obs_mode=obs_mode,
            )
        env = envs[obs_mode]
        for setting, std in settings:
            seeds = range(args.seed, args.seed + args.episodes)
            episodes = [
                run_episode(env, expert, seed, std, args.noise_probability, phases)
                for seed in progress_bar(seeds, desc=f"{name} {setting}")
            ]
            row = {
                "expert": name,
                "obs_mode": obs_mode,
                "setting": setting,
                **summarise(episodes),
                "episodes": episodes,
            }
            rows.append(row)
            print(
                f"{name} {setting}: {row['successes']}/{args.episodes} = {row['rate']:.1%} "
                f"[{row['ci_low']:.1%}, {row['ci_high']:.1%}]; failures {row['failures']}"
            )
    for env in envs.values():
        env.close()
    results: dict[str, Any] = {
        "env_id": "dg16m_env/DualGraspLift-v2",
        "benchmark": args.benchmark,
        "episodes": args.episodes,
        "first_seed": args.seed,
        "noise": {
            "std": args.noise_std,
            "probability": args.noise_probability,
            "phases": sorted(phases),
        },
        "seconds": round(time.monotonic() - started, 1),
        "rates": rows,
    }
    write_json_atomic(args.out, results)
    if args.plot:
        plot_rates(results, Path(args.plot))
    return results


if __name__ == "__main__":
    main()
