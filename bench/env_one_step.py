"""Episodes per second of the one-step environments against the trial rate, on one core.

For the first ``--objects`` objects of the embedded procedural benchmark (one per family), with
their scenes compiled and everything warmed up (numba, caches) beforehand, measures in one run
(the machine is noisy, so every reference shares it), ``--rounds`` times, medians reported:

* **Pose** (``DualGraspPose-v0``, default arguments): ``reset`` + ``step`` with the action at a
  stored benchmark row's poses (float32 encoding), pose noise on; with the force-closure info
  (``fc_info=True``, the default) and without it;
* **Select, simulate** (``DualGraspSelect-v0``): ``reset`` + ``step`` of a random slot, with and
  without the force-closure info (cached per row: a row pays it once);
* **Select, label**: ``reset`` + ``step`` drawing the reward from the stored p (no trial);
* **Pose over all objects** (``fc_info=False``): the same, walking over all 300 objects, so
  nearly every ``reset`` misses the environment's object cache
  (:data:`dg16m_env.envs.objects.CACHE_SIZE` objects) and loads, compiles and samples the
  object again;
* **reference**: :func:`dg16m_env.physics.trial.run_trials` called directly, one trial per call, on the
  very poses the environment's trials ran at (``env.last_trial_poses``), on the same compiled
  scenes: the trial rate. Beside it the batched rate (one ``run_trials`` call per object) for
  context.

Prints episodes/s and the ratio to the trial rate (target: close to 1 for Pose and Select in
simulate mode; the environment adds the observation copy, the action check and the info).

    nice -n 19 .venv/bin/python bench/env_one_step.py                 # ~2-3 min
    .venv/bin/python bench/env_one_step.py --episodes 60 --rounds 1 --json runs/env.json
"""

from __future__ import annotations

import os

# One core: no BLAS, OpenMP or numba threads (set before numpy is imported).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from dg16m_core.atomic import write_json_atomic
from dg16m_env.envs.dual_grasp_pose import DualGraspPoseEnv
from dg16m_env.envs.dual_grasp_select import DualGraspSelectEnv
from dg16m_env.envs.spaces import action_from_poses
from dg16m_env.physics.trial import run_trials

_NEXT: dict[int, int] = {}  # per environment: where its walk over the objects stands


def _pin_one_core() -> str:
    """Run on one CPU (the first this process may use), where the OS allows it."""
    if hasattr(os, "sched_setaffinity"):
        cpu = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})
        return f"cpu {cpu}"
    return "not pinned"


def _episodes(
    env: Any, n: int, objects: list[str], seed: int, act: Callable[[Any, dict], Any]
) -> tuple[float, list[tuple[str, np.ndarray]]]:
    """Time ``n`` episodes (reset + step), objects in turn (continuing where the last call
    stopped); returns seconds and the (object, poses) of every trial that ran."""
    ran: list[tuple[str, np.ndarray]] = []
    offset = _NEXT.get(id(env), 0)
    _NEXT[id(env)] = offset + n
    start = time.perf_counter()
    for i in range(n):
        object_id = objects[(offset + i) % len(objects)]
        obs, info = env.reset(seed=seed + i, options={"object_id": object_id})
        env.step(act(obs, info))
        if env.last_trial_poses is not None:
            ran.append((object_id, env.last_trial_poses))
    return time.perf_counter() - start, ran


def _reference(env: Any, ran: list[tuple[str, np.ndarray]]) -> tuple[float, float]:
    """Seconds of ``run_trials`` on the same poses one call per trial, and batched per object."""
    protocol = env.protocol
    scenes = {object_id: env.objects.scene(object_id) for object_id, _ in ran}  # compiled first
    start = time.perf_counter()
    for object_id, poses in ran:
        run_trials(scenes[object_id], poses[None], protocol)
    single = time.perf_counter() - start
    by_object: dict[str, list[np.ndarray]] = {}
    for object_id, poses in ran:
        by_object.setdefault(object_id, []).append(poses)
    start = time.perf_counter()
    for object_id, poses_list in by_object.items():
        run_trials(scenes[object_id], np.stack(poses_list), protocol)
    return single, time.perf_counter() - start


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=150, help="episodes per measurement")
    parser.add_argument("--objects", type=int, default=10, help="benchmark objects used")
    parser.add_argument("--rounds", type=int, default=3, help="repeats (medians reported)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    args = parser.parse_args(argv)
    pinned = _pin_one_core()

    pose_envs = {
        "pose": DualGraspPoseEnv(),
        "pose_no_fc": DualGraspPoseEnv(fc_info=False),
    }
    select_envs = {
        "select_simulate": DualGraspSelectEnv(),
        "select_simulate_no_fc": DualGraspSelectEnv(fc_info=False),
        "select_label": DualGraspSelectEnv(reward_mode="label"),
        "select_label_no_fc": DualGraspSelectEnv(reward_mode="label", fc_info=False),
    }
    cold = {"pose_no_fc_all_objects": DualGraspPoseEnv(fc_info=False)}
    any_env = pose_envs["pose"]
    everything = list(any_env.objects.object_ids)
    objects = everything[: args.objects]
    bench = any_env.benchmark
    rows = {o: any_env.objects.rows(o) for o in everything}
    rng = np.random.default_rng(args.seed)

    def pose_action(obs: Any, info: dict) -> np.ndarray:
        row = int(rng.choice(rows[info["object_id"]]))
        return action_from_poses(bench.poses[row]).astype(np.float32)

    def select_action(obs: Any, info: dict) -> int:
        return int(rng.integers(16))

    acts = {
        **dict.fromkeys([*pose_envs, *cold], pose_action),
        **dict.fromkeys(select_envs, select_action),
    }
    envs = {**pose_envs, **select_envs, **cold}
    used = {name: everything if name in cold else objects for name in envs}
    for name, env in envs.items():  # warm up: scenes, clouds, numba, fc of the first rows
        _episodes(env, 2 * len(objects), objects, 10_000, acts[name])

    results: dict[str, list[dict[str, float]]] = {name: [] for name in envs}
    for r in range(args.rounds):
        for name, env in envs.items():
            seconds, ran = _episodes(env, args.episodes, used[name], 1000 * r, acts[name])
            entry = {"episodes_per_s": args.episodes / seconds}
            if ran:
                single, batched = _reference(env, ran)
                entry["trials_per_s"] = len(ran) / single
                entry["trials_per_s_batched"] = len(ran) / batched
            results[name].append(entry)

    summary: dict[str, Any] = {
        "pinned": pinned,
        "objects": objects,
        "episodes": args.episodes,
        "rounds": args.rounds,
    }
    reference = statistics.median(
        e["trials_per_s"] for name in envs for e in results[name] if "trials_per_s" in e
    )
    print(f"one core ({pinned}), {len(objects)} objects, {args.episodes} episodes x {args.rounds}")
    print(f"{'':24s} {'episodes/s':>10s} {'trials/s':>9s} {'batched':>8s} {'ratio':>6s}")
    for name in envs:
        eps = statistics.median(e["episodes_per_s"] for e in results[name])
        line: dict[str, Any] = {"episodes_per_s": eps}
        if "trials_per_s" in results[name][0]:
            trial = statistics.median(e["trials_per_s"] for e in results[name])
            batched = statistics.median(e["trials_per_s_batched"] for e in results[name])
            line.update(trials_per_s=trial, trials_per_s_batched=batched, ratio=eps / trial)
            print(f"{name:24s} {eps:10.1f} {trial:9.1f} {batched:8.1f} {eps / trial:6.2f}")
        else:
            line["ratio_to_trial_rate"] = eps / reference
            print(
                f"{name:24s} {eps:10.1f} {'-':>9s} {'-':>8s} {eps / reference:6.1f}"
                "  (no trial: against the median trial rate)"
            )
        summary[name] = line
    for env in envs.values():
        env.close()
    if args.json is not None:
        write_json_atomic(args.json, summary)
    return summary


if __name__ == "__main__":
    main()
