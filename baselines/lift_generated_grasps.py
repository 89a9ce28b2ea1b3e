"""Lift with generated grasps: cloud -> the learned generator's dual grasp -> the feedback expert
lifts it, beside the same expert with the benchmark's grasp (issue 59).

Reads top to bottom (CleanRL style): one dataclass of arguments, then the run.

For each of ``episodes`` seeds, the env draws a held-out object of
``dg16m_env/DualGraspLift-v2`` (every third object of the benchmark, the split the Lift baselines
are scored on; objects without a benchmark grasp that stays above the table are never drawn),
then the same seed and object run twice:

1. **benchmark grasp**: the env draws its target from the benchmark's dual grasps (the
   default), and :class:`dg16m_env.envs.lift.experts.FeedbackLiftExpert` grasps and lifts;
2. **generated grasp**: the cloud track's observation of the object (two seeded depth cameras,
   kinect noise, no mesh; :func:`dg16m_env.subjects.cloud_observation.cloud_observation`) goes
   to :data:`baselines.flow_predictor.flow_predictor`; its ranked dual grasps are tried as the
   episode's target in rank order until one has both hands above the table in the episode's
   resting pose (the env's ``target_above_table``: the robot sees the table; at most ``k``
   tries, else the last one), and the same expert lifts it. An object without any generated
   grasp counts as a failed episode.

The same seeds give both settings the same object and resting pose. Success rates with Wilson
95% intervals go to ``out`` (JSON) and stdout.

    .venv/bin/python -m baselines.lift_generated_grasps --out runs/lift_generated.json
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from baselines.cloud_grasps import CloudError
from baselines.sb3_common import parse_args
from dg16m_core.atomic import write_json_atomic
from dg16m_core.progress import progress_bar


@dataclass
class Args:
    benchmark: str = "procedural"
    """the benchmark whose held-out objects are lifted: procedural or real"""
    episodes: int = 200
    """episodes (seeds) per setting"""
    k: int = 10
    """generated dual grasps tried at most per episode (the first above the table is used)"""
    seed: int = 0
    """first episode seed"""
    out: Path = Path("runs/lift_generated.json")
    """the results (JSON)"""


def run_episode(env: Any, expert: Any, seed: int, options: dict[str, Any]) -> tuple[bool, dict]:
    """One episode with the expert; ``(success, reset info)``."""
    observation, info = env.reset(seed=seed, options=options)
    expert.reset()
    reset_info = dict(info)
    while True:
        observation, _, terminated, truncated, info = env.step(expert(observation))
        if terminated or truncated:
            return bool(info.get("success", False)), reset_info


def generated_targets(obj: Any, k: int) -> np.ndarray:
    """The generator's ranked dual grasps (k', 2, 4, 4) for the object's cloud observation."""
    from baselines.flow_predictor import flow_predictor
    from dg16m_env.subjects.cloud_observation import cloud_observation

    try:
        poses, _ = flow_predictor(cloud_observation(obj))
    except CloudError:
        return np.zeros((0, 2, 4, 4))
    return poses[:k]


def main(args: Args | None = None) -> dict[str, Any]:
    args = args or parse_args(Args, __doc__.split("\n\n")[0])
    import gymnasium as gym

    from dg16m_env.envs.lift.experts import FeedbackLiftExpert
    from dg16m_env.envs.objects import split_objects
    from dg16m_env.evaluators import load_benchmark_ref
    from dg16m_env.evaluators.policy import wilson_interval

    ref = load_benchmark_ref(None if args.benchmark == "procedural" else args.benchmark)
    held_out = split_objects(list(ref.object_ids))[1]
    objects = {o.object_id: o for o in ref.benchmark.objects}
    env = gym.make("dg16m_env/DualGraspLift-v2", benchmark=ref, object_ids=held_out)
    expert = FeedbackLiftExpert()
    outcome: dict[str, list[bool]] = {"benchmark_grasp": [], "generated_grasp": []}
    targets: dict[str, np.ndarray] = {}
    tries, started = [], time.monotonic()
    for seed in progress_bar(range(args.seed, args.seed + args.episodes), desc="episodes"):
        _, info = env.reset(seed=seed)
        object_id = str(info["object_id"])
        ok, _ = run_episode(env, expert, seed, {"object_id": object_id})
        outcome["benchmark_grasp"].append(ok)
        if object_id not in targets:
            targets[object_id] = generated_targets(objects[object_id].load(None), args.k)
        if len(targets[object_id]) == 0:
            outcome["generated_grasp"].append(False)
            continue
        for t, target in enumerate(targets[object_id]):
            ok, info = run_episode(
                env, expert, seed, {"object_id": object_id, "target_grasp": target}
            )
            if info.get("target_above_table", True) or t == len(targets[object_id]) - 1:
                break
        tries.append(t + 1)
        outcome["generated_grasp"].append(ok)
    env.close()
    results: dict[str, Any] = {
        "benchmark": args.benchmark,
        "objects": len(targets),
        "episodes": len(outcome["benchmark_grasp"]),
        "seconds": round(time.monotonic() - started, 1),
        "mean_tries": float(np.mean(tries)) if tries else None,
    }
    for name, successes in outcome.items():
        n, s = len(successes), int(np.sum(successes))
        results[name] = rate = wilson_interval(s, n)
        print(f"{name}: {s}/{n} = {rate['rate']:.1%} [{rate['ci_low']:.1%}, {rate['ci_high']:.1%}]")
    write_json_atomic(args.out, results)
    return results


if __name__ == "__main__":
    main()
