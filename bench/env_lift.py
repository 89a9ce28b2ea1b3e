"""Step rate of ``dg16m_env/DualGraspLift-v0`` on one core, against a bare MuJoCo loop.

For each object (default: the first object of each family in the shipped benchmark), in one run
(the machine is noisy, so every reference shares it), with ``target_grasp="benchmark"``:

* **random**: episodes of seeded random actions (each up to the registered 200 steps, or until
  it terminates); only ``env.step`` is timed.
* **scripted**: episodes of :class:`~dg16m_env.envs.lift_expert.ScriptedLiftPolicy`
  (approach, grasp, lift, hold); ``env.step`` is timed apart from the policy, successes counted.
* **reference** (of each): the bare ``mujoco.mj_step`` loop of the same compiled model for the
  same simulated time. Each run is replayed once more (seeded, so identical) with
  ``mujoco.mj_step`` wrapped to record the inputs of every physics step (hand targets, finger
  forces) and each episode's state after reset; the reference sets those inputs and calls
  ``mj_step``, nothing else, and must end in the same state bit for bit (checked). Its rate is
  given in env-step equivalents (physics steps/s divided by the substeps per env step), so
  ``ratio = env steps/s / reference`` is the share of the env's time spent in physics.

Ends with the medians over objects against the 500 env steps/s target.

    nice -n 19 .venv/bin/python bench/env_lift.py                      # 10 objects, ~1-2 min
    .venv/bin/python bench/env_lift.py --objects table-1000000 --episodes 2 --random-episodes 1
    .venv/bin/python bench/env_lift.py --json runs/env_lift.json
"""

from __future__ import annotations

import os

# One core: no BLAS, OpenMP or numba threads (set before numpy is imported).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import contextlib
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from dataset_gen.atomic import write_json_atomic
from dg16m_env.envs.dual_grasp_lift import ACTION_SIZE, DualGraspLiftEnv
from dg16m_env.envs.lift_expert import ScriptedLiftPolicy
from dg16m_env.envs.objects import BenchmarkObjects

TARGET_STEPS_PER_S = 500.0
MAX_STEPS = 200  # the registered TimeLimit
STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # everything, solver warm start included

Policy = Callable[[np.ndarray], np.ndarray]


@dataclass
class Episode:
    """What the reference replays: the state after reset, then each physics step's inputs."""

    start: np.ndarray
    inputs: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)
    end: np.ndarray | None = None


@dataclass
class Run:
    steps: int = 0
    step_time: float = 0.0
    policy_time: float = 0.0
    successes: int = 0
    lengths: list[int] = field(default_factory=list)
    episodes: list[Episode] = field(default_factory=list)


def default_objects() -> list[str]:
    """The first object of each family of the shipped benchmark."""
    first: dict[str, str] = {}
    for obj in BenchmarkObjects().ref.benchmark.objects:
        first.setdefault(obj.family or obj.object_id, obj.object_id)
    return list(first.values())


def _state(env: DualGraspLiftEnv) -> np.ndarray:
    assert env._current is not None
    model, data = env._current.scene.model, env._current.data
    state = np.empty(mujoco.mj_stateSize(model, STATE))
    mujoco.mj_getState(model, data, state, STATE)
    return state


@contextlib.contextmanager
def recording(run: Run) -> Iterator[None]:
    """Wrap ``mujoco.mj_step`` (module attribute, as the env calls it) to record each single
    physics step's inputs into the run's last episode."""
    original = mujoco.mj_step

    def step(model: mujoco.MjModel, data: mujoco.MjData, nstep: int = 1) -> None:
        if nstep == 1 and run.episodes:
            inputs = (data.mocap_pos.copy(), data.mocap_quat.copy(), data.ctrl.copy())
            run.episodes[-1].inputs.append(inputs)
        original(model, data, nstep=nstep)

    mujoco.mj_step = step  # type: ignore[assignment]
    try:
        yield
    finally:
        mujoco.mj_step = original  # type: ignore[assignment]


def play(
    env: DualGraspLiftEnv, policies: Callable[[int], Policy], seeds: list[int], record: bool
) -> Run:
    """Episodes from ``seeds`` (a fresh policy per episode); times ``env.step`` and the policy."""
    run = Run()
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        policy = policies(seed)
        if record:
            run.episodes.append(Episode(start=_state(env)))
        length, terminated, info = 0, False, {}
        with recording(run) if record else contextlib.nullcontext():
            while not terminated and length < MAX_STEPS:
                t0 = time.perf_counter()
                action = policy(obs)
                t1 = time.perf_counter()
                obs, _, terminated, _, info = env.step(action)
                run.step_time += time.perf_counter() - t1
                run.policy_time += t1 - t0
                length += 1
        if record:
            run.episodes[-1].end = _state(env)
        run.steps += length
        run.successes += int(info.get("success", False))
        run.lengths.append(length)
    return run


def reference(env: DualGraspLiftEnv, run: Run) -> tuple[float, bool]:
    """Env-step equivalents per second of the bare ``mj_step`` loop replaying ``run``, and
    whether every episode ended in the env's state bit for bit."""
    assert env._current is not None
    model = env._current.scene.model
    data = mujoco.MjData(model)
    elapsed, identical, physics_steps = 0.0, True, 0
    for episode in run.episodes:
        mujoco.mj_setState(model, data, episode.start, STATE)
        t0 = time.perf_counter()
        for pos, quat, ctrl in episode.inputs:
            data.mocap_pos[:] = pos
            data.mocap_quat[:] = quat
            data.ctrl[:] = ctrl
            mujoco.mj_step(model, data)
        elapsed += time.perf_counter() - t0
        physics_steps += len(episode.inputs)
        end = np.empty(mujoco.mj_stateSize(model, STATE))
        mujoco.mj_getState(model, data, end, STATE)
        assert episode.end is not None
        identical &= bool(np.array_equal(end, episode.end))
    return physics_steps / env.substeps / elapsed, identical


def random_policies(seed: int) -> Policy:
    rng = np.random.default_rng(seed)
    return lambda obs: rng.uniform(-1.0, 1.0, ACTION_SIZE).astype(np.float32)


def scripted_policies(seed: int) -> Policy:
    return ScriptedLiftPolicy()


def measure(
    env: DualGraspLiftEnv, policies: Callable[[int], Policy], seeds: list[int]
) -> dict[str, Any]:
    timed = play(env, policies, seeds, record=False)
    recorded = play(env, policies, seeds, record=True)
    ref_rate, identical = reference(env, recorded)
    rate = timed.steps / timed.step_time
    return {
        "episodes": len(seeds),
        "steps": timed.steps,
        "steps_per_s": rate,
        "reference_steps_per_s": ref_rate,
        "ratio": rate / ref_rate,
        "replay_identical": identical and recorded.steps == timed.steps,
        "policy_ms_per_step": 1e3 * timed.policy_time / timed.steps,
        "successes": timed.successes,
        "median_episode_steps": float(np.median(timed.lengths)),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--objects", nargs="+", help="object ids (default: one per family)")
    parser.add_argument("--random-episodes", type=int, default=2, help="per object")
    parser.add_argument("--episodes", type=int, default=4, help="scripted episodes per object")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, help="also write the results here")
    args = parser.parse_args(argv)
    objects = args.objects or default_objects()
    print(
        f"{'object':30s} {'random/s':>9s} {'ref/s':>7s} {'ratio':>5s}  "
        f"{'script/s':>8s} {'ref/s':>7s} {'ratio':>5s} {'policy ms':>9s} {'success':>7s} "
        f"{'replay':>6s}"
    )
    rows = []
    for object_id in objects:
        env = DualGraspLiftEnv(object_ids=[object_id], target_grasp="benchmark")
        env.reset(seed=args.seed)  # compile and cache outside the timings
        random = measure(env, random_policies, [args.seed + i for i in range(args.random_episodes)])
        scripted = measure(env, scripted_policies, [args.seed + i for i in range(args.episodes)])
        env.close()
        rows.append({"object_id": object_id, "random": random, "scripted": scripted})
        same = random["replay_identical"] and scripted["replay_identical"]
        print(
            f"{object_id:30s} {random['steps_per_s']:9.0f} {random['reference_steps_per_s']:7.0f} "
            f"{random['ratio']:5.2f}  {scripted['steps_per_s']:8.0f} "
            f"{scripted['reference_steps_per_s']:7.0f} {scripted['ratio']:5.2f} "
            f"{scripted['policy_ms_per_step']:9.2f} "
            f"{scripted['successes']:>3d}/{scripted['episodes']:<3d} "
            f"{'same' if same else 'DIFF':>6s}"
        )

    def median(kind: str, key: str) -> float:
        return float(np.median([row[kind][key] for row in rows]))

    summary = {
        "median_random_steps_per_s": median("random", "steps_per_s"),
        "median_scripted_steps_per_s": median("scripted", "steps_per_s"),
        "median_random_ratio": median("random", "ratio"),
        "median_scripted_ratio": median("scripted", "ratio"),
        "slowest_steps_per_s": min(
            min(row["random"]["steps_per_s"], row["scripted"]["steps_per_s"]) for row in rows
        ),
        "scripted_successes": sum(row["scripted"]["successes"] for row in rows),
        "scripted_episodes": sum(row["scripted"]["episodes"] for row in rows),
        "target_steps_per_s": TARGET_STEPS_PER_S,
    }
    worst = min(summary["median_random_steps_per_s"], summary["median_scripted_steps_per_s"])
    verdict = "meets" if worst >= TARGET_STEPS_PER_S else "MISSES"
    print(
        f"median: random {summary['median_random_steps_per_s']:.0f} steps/s "
        f"(env/reference {summary['median_random_ratio']:.2f}), scripted "
        f"{summary['median_scripted_steps_per_s']:.0f} steps/s "
        f"(env/reference {summary['median_scripted_ratio']:.2f}); slowest object "
        f"{summary['slowest_steps_per_s']:.0f} steps/s; {verdict} the "
        f"{TARGET_STEPS_PER_S:.0f} steps/s target; scripted successes "
        f"{summary['scripted_successes']}/{summary['scripted_episodes']}"
    )
    if args.json:
        write_json_atomic(args.json, {"objects": rows, "summary": summary})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
