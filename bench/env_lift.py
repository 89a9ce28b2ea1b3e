"""Step rate of ``dg16m_env/DualGraspLift-v0`` on one core, against a bare MuJoCo loop.

For each object (default: the first object of each family in the shipped benchmark), in one run
(the machine is noisy, so every reference shares it), with ``target_grasp="benchmark"``:

* **random**: episodes of seeded random actions (each up to the registered 200 steps, or until
  it terminates); only ``env.step`` is timed.
* **scripted**: episodes of :class:`~dg16m_env.envs.lift.experts.ScriptedLiftPolicy`
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

``--speed`` (issue 40) compares this tree with a *reference* tree (``--reference DIR``; default:
a temporary ``git worktree`` of ``HEAD``, removed afterwards), each measurement in fresh
subprocesses whose ``PYTHONPATH`` picks the tree, the two trees alternating ``--rounds`` times
(medians; the machine is noisy, read the ratios):

* **random** / **scripted**: steps/s of ``env.step`` of one ``gym.make`` environment (random
  actions without a target; :class:`~dg16m_env.envs.lift.experts.ScriptedLiftPolicy` with the
  benchmark's target), seeded: both trees run the same episodes when their behaviour is the
  same (checked: a sha256 of every observation and reward);
* **vector**: a 2-worker ``gymnasium.vector.AsyncVectorEnv`` (what ``gym.make_vec(...,
  vectorization_mode="async")`` makes) against one env of the same tree in the same subprocess
  (random actions, one object, autoreset included in both), with the workers left to the
  scheduler and pinned to a core each; and the same ratios for an environment that only burns
  the step time just measured (what two workers can gain on this machine at that moment);
* **make**: ``gym.make`` of the procedural and of the real benchmark in a fresh process
  (the environment module's import included), then the first ``reset``;
* **render**: the first 240x180 ``rgb_array`` frame and the next ones (one step between), of
  v0 and of ``DualGraspLift-v1`` (1024-pixel shadow maps).

    .venv/bin/python bench/env_lift.py --speed                        # ~4 min on 2 cores
    .venv/bin/python bench/env_lift.py --speed --reference /tmp/lift_ref --rounds 5 --json x.json
    .venv/bin/python bench/env_lift.py --speed --only render          # the frames only

``--versions 6``: steps/s of ``DualGraspLift-v0``, ``-v1`` and ``-v2`` on the same seeded
random-action episodes, taking turns in one process, and the ratios to v0.

``--vector ENV_ID``: the 2-worker async vector env of the ``--speed`` probe for one env id of
this tree, left to the scheduler and pinned; for ``dg16m_env/DualGraspLift-v2`` also its
``LiftVectorEnv`` (``--num-envs``, default 16; 2 workers and 1) against one env, interleaved
in short slices (``--steps`` env steps each; this VM's speed drifts within seconds), beside
the machine's ceiling: two free-running processes of pure-Python work against one.

    .venv/bin/python bench/env_lift.py --versions 6
    .venv/bin/python bench/env_lift.py --vector dg16m_env/DualGraspLift-v2 --num-envs 16 --steps 800

``--timesteps 0.002,0.005,0.01`` (a study for a later version, not what v0 does): the scripted
expert with the benchmark's target on the same seeded episodes with the scene's timestep
changed (so fewer physics substeps per 50 ms control step): successes, unstable endings, time
in ``mj_step`` and in ``env.step`` per control step (CPU time), and the deepest contact
penetration after each step (p99 and max over the steps), the timesteps alternating episode by
episode.

    .venv/bin/python bench/env_lift.py --timesteps 0.002,0.005,0.01 --episodes 30
"""

from __future__ import annotations

import os

# One core: no BLAS, OpenMP or numba threads (set before numpy is imported).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import contextlib
import functools
import hashlib
import json
import multiprocessing
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium
import mujoco
import numpy as np

from dg16m_core.atomic import write_json_atomic
from dg16m_env.envs.lift.experts import ScriptedLiftPolicy
from dg16m_env.envs.lift.scenes import use_timestep
from dg16m_env.envs.lift.spaces import ACTION_SIZE
from dg16m_env.envs.lift.v0 import DualGraspLiftEnv
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


# --------------------------------------------------------------------------------------------
# --speed: this tree against a reference tree (issue 40)
# --------------------------------------------------------------------------------------------

LIFT_ID = "dg16m_env/DualGraspLift-v0"
VECTOR_OBJECT = "table-1000000"
RENDER_SIZE = (240, 180)


def _lift(env_id: str = LIFT_ID, **kwargs: Any) -> Any:
    import gymnasium as gym

    import dg16m_env  # noqa: F401  (registers the environments)

    return gym.make(env_id, **kwargs)


def serve_episodes() -> None:
    """Subprocess side of :func:`paired_steps`: one ``gym.make`` environment per kind; each
    input line ``{"kind": "random" | "scripted", "seed": s}`` runs one seeded episode (up to
    the registered 200 steps) and prints ``{"steps", "elapsed" (s of env.step only), "sha256"
    (every observation and reward)}``."""
    envs: dict[str, Any] = {}
    for line in sys.stdin:
        order = json.loads(line)
        kind, seed = order["kind"], int(order["seed"])
        scripted = kind == "scripted"
        if kind not in envs:
            envs[kind] = _lift(target_grasp="benchmark") if scripted else _lift()
        env = envs[kind]
        env.action_space.seed(seed)
        obs, _ = env.reset(seed=seed)
        policy = ScriptedLiftPolicy() if scripted else None
        h = hashlib.sha256()
        elapsed, steps, done = 0.0, 0, False
        while not done:
            action = policy(obs) if policy is not None else env.action_space.sample()
            t0 = time.perf_counter()
            obs, reward, terminated, truncated, _ = env.step(action)
            elapsed += time.perf_counter() - t0
            h.update(obs.tobytes())
            h.update(np.float64(reward).tobytes())
            steps += 1
            done = terminated or truncated
        print(json.dumps({"steps": steps, "elapsed": elapsed, "sha256": h.hexdigest()}))
        sys.stdout.flush()


def paired_steps(trees: dict[str, Path], kind: str, seeds: list[int], rounds: int) -> dict:
    """Steps/s of ``env.step`` of one environment per tree, each in its own long-lived
    subprocess (:func:`serve_episodes`), the trees alternating episode by episode (the first
    swapped every episode) so that both see the same machine; the same seeded episodes in both
    (compared by hash). The objects are compiled in a first, untimed round."""
    procs = {
        name: subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--probe", "serve"],
            env=dict(os.environ, PYTHONPATH=str(tree)),
            cwd=tree,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        for name, tree in trees.items()
    }

    def episode(name: str, seed: int) -> dict[str, Any]:
        proc = procs[name]
        assert proc.stdin is not None
        assert proc.stdout is not None
        proc.stdin.write(json.dumps({"kind": kind, "seed": seed}) + "\n")
        proc.stdin.flush()
        return json.loads(proc.stdout.readline())

    try:
        for seed in seeds:  # warm-up: compile each object in both
            for name in procs:
                episode(name, seed)
        totals = {name: [0.0, 0] for name in procs}
        ratios, same = [], True
        names = list(procs)
        for r in range(rounds):
            for i, seed in enumerate(seeds):
                got = {}
                for name in names if (i + r) % 2 == 0 else names[::-1]:
                    got[name] = episode(name, seed)
                    totals[name][0] += got[name]["elapsed"]
                    totals[name][1] += got[name]["steps"]
                same &= len({g["sha256"] for g in got.values()}) == 1
                a, b = (got[n]["steps"] / got[n]["elapsed"] for n in names)
                ratios.append(a / b)
    finally:
        for proc in procs.values():
            assert proc.stdin is not None
            proc.stdin.close()
            proc.wait()
    return {
        "steps_per_s": {name: steps / elapsed for name, (elapsed, steps) in totals.items()},
        "steps": {name: steps for name, (_, steps) in totals.items()},
        "speed_up": float(np.median(ratios)),
        "same_episodes": same,
    }


class _Burn(gymnasium.Env):  # type: ignore[type-arg]
    """A Lift-shaped environment whose step only burns ``seconds`` of CPU: what a 2-worker
    vector env can gain on this machine for that step time."""

    observation_space = gymnasium.spaces.Box(-1.0, 1.0, (71,), np.float32)
    action_space = gymnasium.spaces.Box(-1.0, 1.0, (ACTION_SIZE,), np.float32)

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds

    def reset(self, *, seed: int | None = None, options: Any = None) -> Any:
        super().reset(seed=seed)
        return np.zeros(71, np.float32), {}

    def step(self, action: Any) -> Any:
        end = time.process_time() + self.seconds
        while time.process_time() < end:
            pass
        return np.zeros(71, np.float32), 0.0, False, False, {}


def _pinned(make: Callable[[], Any], cpu: int) -> Any:
    """``make()`` in a process pinned to ``cpu`` when called in a vector env's worker; in the
    parent (Gymnasium's ``AsyncVectorEnv`` makes a first env there for the spaces) it only
    makes the env: pinning the parent would pin every process it starts later."""
    if multiprocessing.parent_process() is not None:
        os.sched_setaffinity(0, {cpu % (os.cpu_count() or 1)})
    return make()


def _random_steps_rate(env: Any, steps: int) -> float:
    """Steps/s of ``steps`` random-action steps of ``env`` (reset where an episode ends)."""
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - t0)


def _single_env_rate(make: Callable[[], Any], steps: int, seed: int) -> float:
    """Steps/s of ``steps`` random-action steps (autoreset) of one ``make()`` env, after 20
    steps of warm-up (the object is compiled at the first reset)."""
    env = make()
    env.action_space.seed(seed)
    env.reset(seed=seed)
    for _ in range(20):
        env.step(env.action_space.sample())
    rate = _random_steps_rate(env, steps)
    env.close()
    return rate


def _burn(loops: int) -> int:
    """Pure-Python work of a fixed size (the machine-ceiling reference)."""
    total = 0
    for i in range(loops):
        total += i
    return total


def _burn_worker(conn: Any, loops: int, repeats: int) -> None:
    """A free-running burner: on each message, ``repeats`` times :func:`_burn` (no barrier
    inside), then an answer."""
    while conn.recv() == "burn":
        for _ in range(repeats):
            _burn(loops)
        conn.send("done")


def _interleaved(first: Callable[[], float], second: Callable[[], float], rounds: int) -> Any:
    """Per round ``first()``, ``second()``, ``first()``: the ratios of ``second`` to the mean of
    the two ``first`` around it (this VM's speed drifts by tens of percent within seconds;
    only runs next to each other compare)."""
    ratios, firsts, seconds = [], [], []
    for _ in range(rounds):
        a, b, c = first(), second(), first()
        ratios.append(2.0 * b / (a + c))
        firsts.append((a + c) / 2.0)
        seconds.append(b)
    return np.array(ratios), np.array(firsts), np.array(seconds)


def probe_batched(
    steps: int, seed: int, env_id: str, num_envs: int = 16, rounds: int = 15
) -> dict[str, Any]:
    """Steps/s of ``LiftVectorEnv`` (``num_envs`` environments) with 2 workers (polling
    ``spin_s`` = 1 ms, and sleeping at once: ``spin_s=0``, the default) and with 1 worker against
    one env in this process (same object, random actions, autoreset), interleaved in
    slices of about ``steps`` env steps (:func:`_interleaved`, ``rounds`` rounds: medians and
    quartiles of the ratios); and the machine's own ceiling: two free-running processes of
    pure-Python work against the same work in one, interleaved the same way."""
    from dg16m_env.envs.lift.vector import LiftVectorEnv

    if hasattr(os, "sched_getaffinity") and len(os.sched_getaffinity(0)) < (os.cpu_count() or 1):
        print(f"note: this process may use CPUs {sorted(os.sched_getaffinity(0))} only")
    single = _lift(env_id, object_ids=[VECTOR_OBJECT])
    single.action_space.seed(seed)
    single.reset(seed=seed)
    make = functools.partial(_lift, env_id, object_ids=[VECTOR_OBJECT])
    vectors = {  # name: (workers, spin_s)
        name: LiftVectorEnv([make] * num_envs, workers=w, spin_s=spin)
        for name, (w, spin) in {"w2": (2, 0.001), "w2_sleep": (2, 0.0), "w1": (1, 0.0)}.items()
    }
    for envs in vectors.values():
        envs.action_space.seed(seed)
        envs.reset(seed=seed)
        for _ in range(3):
            envs.step(envs.action_space.sample())

    one = functools.partial(_random_steps_rate, single, steps)

    def vector(name: str) -> float:
        envs, batches = vectors[name], max(1, steps // num_envs)
        t0 = time.perf_counter()
        for _ in range(batches):
            envs.step(envs.action_space.sample())
        return batches * num_envs / (time.perf_counter() - t0)

    out: dict[str, Any] = {"num_envs": num_envs, "rounds": rounds, "slice_steps": steps}
    out["spin_s"] = vectors["w2"].spin_s
    singles = []
    for name in vectors:
        ratios, ones, rates = _interleaved(one, functools.partial(vector, name), rounds)
        out[f"{name}_over_single"] = float(np.median(ratios))
        out[f"{name}_over_single_quartiles"] = np.quantile(ratios, [0.25, 0.75]).tolist()
        out[f"{name}_steps_per_s"] = float(np.median(rates))
        singles += ones.tolist()
    out["single_steps_per_s"] = float(np.median(singles))
    for envs in vectors.values():
        envs.close()
    single.close()

    t0, loops = time.perf_counter(), 200_000
    _burn(loops)
    loops = max(1, int(loops * 1e-3 / (time.perf_counter() - t0)))  # about 1 ms of work
    repeats = max(1, round(steps / out["single_steps_per_s"] / 1e-3))  # slices as long
    ctx = multiprocessing.get_context()
    conns, burners = [], []
    for _ in range(2):
        parent, child = ctx.Pipe()
        burner = ctx.Process(target=_burn_worker, args=(child, loops, repeats), daemon=True)
        burner.start()
        conns.append(parent)
        burners.append(burner)

    def burn_one() -> float:
        t0 = time.perf_counter()
        for _ in range(repeats):
            _burn(loops)
        return repeats / (time.perf_counter() - t0)

    def burn_two() -> float:
        t0 = time.perf_counter()
        for conn in conns:
            conn.send("burn")
        for conn in conns:
            conn.recv()
        return 2 * repeats / (time.perf_counter() - t0)

    ratios, _, _ = _interleaved(burn_one, burn_two, rounds)
    for conn, burner in zip(conns, burners, strict=True):
        conn.send("stop")
        burner.join(timeout=10.0)
    out["ceiling_two_free_processes"] = float(np.median(ratios))
    out["ceiling_quartiles"] = np.quantile(ratios, [0.25, 0.75]).tolist()
    return out


def probe_vector(steps: int, seed: int, env_id: str = LIFT_ID) -> dict[str, Any]:
    """Total steps/s of a 2-worker async vector env against one env (same tree, same object,
    random actions, autoreset in both), with the workers left to the scheduler and pinned to
    one core each; and the same for :class:`_Burn` at the step time just measured. The
    variants alternate (3 rounds), so that each ratio's runs see the same machine."""

    def one(make: Callable[[], Any]) -> float:
        return _single_env_rate(make, steps, seed)

    def vec(make: Callable[[], Any], pin: bool) -> float:
        fns = [functools.partial(_pinned, make, k) if pin else make for k in range(2)]
        env = gymnasium.vector.AsyncVectorEnv(fns)
        env.action_space.seed(seed)
        env.reset(seed=seed)
        for _ in range(20):
            env.step(env.action_space.sample())
        t0 = time.perf_counter()
        for _ in range(steps // 2):
            env.step(env.action_space.sample())
        rate = 2 * (steps // 2) / (time.perf_counter() - t0)
        env.close()
        return rate

    lift = functools.partial(_lift, env_id, object_ids=[VECTOR_OBJECT])
    keys = ("single", "vector", "pinned", "burn_single", "burn_vector", "burn_pinned")
    runs: dict[str, list[float]] = {k: [] for k in keys}
    pin = hasattr(os, "sched_setaffinity") and (os.cpu_count() or 1) >= 2
    for _ in range(3):
        runs["single"].append(one(lift))
        runs["vector"].append(vec(lift, False))
        runs["pinned"].append(vec(lift, True) if pin else float("nan"))
        burn = functools.partial(_Burn, 1.0 / runs["single"][-1])  # the step time just measured
        runs["burn_single"].append(one(burn))
        runs["burn_vector"].append(vec(burn, False))
        runs["burn_pinned"].append(vec(burn, True) if pin else float("nan"))
    r = {k: np.array(v) for k, v in runs.items()}
    return {
        "single_steps_per_s": float(np.median(r["single"])),
        "vector_steps_per_s": float(np.median(r["vector"])),
        "ratio": float(np.median(r["vector"] / r["single"])),
        "pinned_ratio": float(np.median(r["pinned"] / r["single"])),
        "burn_ratio": float(np.median(r["burn_vector"] / r["burn_single"])),
        "burn_pinned_ratio": float(np.median(r["burn_pinned"] / r["burn_single"])),
        "runs": runs,
    }


MAKE_CODE = """
import json, sys, time
t0 = time.perf_counter()
import gymnasium as gym
import dg16m_env
t1 = time.perf_counter()
env = gym.make("dg16m_env/DualGraspLift-v0", benchmark=sys.argv[1])
t2 = time.perf_counter()
env.reset(seed=0)
t3 = time.perf_counter()
env.close()
print(json.dumps({"import_s": t1 - t0, "make_s": t2 - t1, "reset_s": t3 - t2}))
"""
"""Seconds of ``gym.make`` in a fresh process that imported only gymnasium and ``dg16m_env``
(the environment module's import is part of ``gym.make``), then of the first reset."""


def probe_render(frames: int, benchmark: str, env_id: str = LIFT_ID) -> dict[str, Any]:
    """Seconds of the first ``rgb_array`` frame and the median of the next ones."""
    width, height = RENDER_SIZE
    env = _lift(env_id, render_mode="rgb_array", width=width, height=height, benchmark=benchmark)
    env.action_space.seed(0)
    env.reset(seed=0)
    t0 = time.perf_counter()
    frame = env.render()
    first = time.perf_counter() - t0
    h = hashlib.sha256(frame.tobytes())
    times = []
    for _ in range(frames):
        env.step(env.action_space.sample())
        t0 = time.perf_counter()
        frame = env.render()
        times.append(time.perf_counter() - t0)
        h.update(frame.tobytes())
    env.close()
    return {"first_s": first, "next_s": float(np.median(times)), "sha256": h.hexdigest()}


PROBES: dict[str, Callable[..., dict[str, Any]]] = {
    "vector": probe_vector,
    "render": probe_render,
}


def _run_probe(tree: Path, name: str, **kwargs: Any) -> dict[str, Any]:
    """One probe in a fresh subprocess whose ``PYTHONPATH`` picks ``tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    if name == "make":
        command = [sys.executable, "-c", MAKE_CODE, kwargs["benchmark"]]
    else:
        command = [sys.executable, str(Path(__file__).resolve()), "--probe", name]
        command += ["--probe-args", json.dumps(kwargs)]
    out = subprocess.run(command, env=env, cwd=tree, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@contextlib.contextmanager
def _reference_tree(given: Path | None) -> Iterator[Path]:
    if given is not None:
        yield given.resolve()
        return
    repo = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "ref"
        subprocess.run(
            ["git", "-C", str(repo), "worktree", "add", "--detach", str(tree), "HEAD"],
            check=True,
            capture_output=True,
        )
        try:
            yield tree
        finally:
            subprocess.run(
                ["git", "-C", str(repo), "worktree", "remove", "--force", str(tree)],
                check=False,
                capture_output=True,
            )


def speed(reference: Path | None, rounds: int, json_path: Path | None, only: str = "") -> int:
    """The issue 40 table: each probe on both trees, alternating, medians and ratios (only the
    measurements whose label contains ``only``)."""
    here = Path(__file__).resolve().parents[1]
    cases: list[tuple[str, str, dict[str, Any], str]] = [
        # (label, probe, kwargs, key: "" for the render probes' two times)
        (
            "2-worker async vector env (steps/s)",
            "vector",
            {"steps": 400, "seed": 0},
            "vector_steps_per_s",
        ),
        ("gym.make procedural (s)", "make", {"benchmark": "procedural"}, "make_s"),
        ("gym.make real (s)", "make", {"benchmark": "real"}, "make_s"),
        ("render procedural (s)", "render", {"frames": 6, "benchmark": "procedural"}, ""),
        ("render real (s)", "render", {"frames": 6, "benchmark": "real"}, ""),
        ("render v1 procedural (s)", "render", {"frames": 6, "benchmark": "procedural"}, ""),
        ("render v1 real (s)", "render", {"frames": 6, "benchmark": "real"}, ""),
    ]
    for label, _, kwargs, _ in cases:
        if "v1" in label:
            kwargs["env_id"] = "dg16m_env/DualGraspLift-v1"
    cases = [case for case in cases if only in case[0]]
    results: dict[str, Any] = {"date": time.strftime("%Y-%m-%d"), "rounds": rounds, "probes": {}}
    with _reference_tree(reference) as ref:
        results["reference"] = str(ref)
        print(f"this tree {here}\nreference {ref}\n")
        print(f"{'measurement':46s} {'this tree':>10s} {'reference':>10s} {'speed-up':>9s}")
        for kind, seeds in (("random", list(range(6))), ("scripted", list(range(6)))):
            label = f"one env, {kind} {'actions' if kind == 'random' else 'expert'} (steps/s)"
            if only not in label:
                continue
            got = paired_steps({"this": here, "reference": ref}, kind, seeds, max(1, rounds // 2))
            results["probes"][label] = got
            rate = got["steps_per_s"]
            print(
                f"{label:46s} {rate['this']:10.1f} {rate['reference']:10.1f} "
                f"{got['speed_up']:8.2f}x"
            )
            print(f"  {'same episodes in both trees':44s} {got['same_episodes']}")
        for label, name, kwargs, key in cases:
            runs: dict[str, list[dict[str, Any]]] = {"this": [], "reference": []}
            for i in range(rounds):  # alternating, the first tree swapped every round
                order = [("this", here), ("reference", ref)]
                for side, tree in order if i % 2 == 0 else order[::-1]:
                    runs[side].append(_run_probe(tree, name, **kwargs))
            results["probes"][label] = runs
            keys = [key] if key else ["first_s", "next_s"]
            if name == "vector":
                keys += ["single_steps_per_s", "ratio", "pinned_ratio", "burn_ratio"]
                keys += ["burn_pinned_ratio"]
            if not key:
                print(label)
            for k in keys:
                mine = [r[k] for r in runs["this"]]
                theirs = [r[k] for r in runs["reference"]]
                higher = k.endswith("per_s") or "ratio" in k
                # speed-up: the median of each round's pair (the two runs next to each other)
                pairs = [a / b if higher else b / a for a, b in zip(mine, theirs, strict=True)]
                row = label if k == key else f"  {k}"
                print(
                    f"{row:46s} {np.median(mine):10.3f} {np.median(theirs):10.3f} "
                    f"{np.median(pairs):8.2f}x"
                )
            if "sha256" in runs["this"][0]:
                same = len({r["sha256"] for r in runs["this"] + runs["reference"]}) == 1
                print(f"  {'same episodes / frames in both trees':44s} {same}")
    if json_path:
        write_json_atomic(json_path, results)
    return 0


# --------------------------------------------------------------------------------------------
# --versions: v1 against v0 in one process
# --------------------------------------------------------------------------------------------


def versions(episodes: int, json_path: Path | None) -> int:
    """Steps/s of ``env.step`` of ``DualGraspLift-v0``, ``-v1`` and ``-v2`` (all with the
    benchmark's target), the same seeded random-action episodes, the versions taking turns
    episode by episode in one process (the machine's load is shared), and the ratios to v0."""
    ids = {v: f"dg16m_env/DualGraspLift-{v}" for v in ("v0", "v1", "v2")}
    envs = {v: _lift(env_id, target_grasp="benchmark") for v, env_id in ids.items()}
    steps = dict.fromkeys(envs, 0)
    seconds = dict.fromkeys(envs, 0.0)
    for episode in range(episodes):
        shift = episode % len(envs)
        order = list(envs)[shift:] + list(envs)[:shift]
        for v in order:
            rng = np.random.default_rng(episode)
            envs[v].reset(seed=episode)
            for _ in range(200):
                action = rng.uniform(-1.0, 1.0, 14).astype(np.float32)
                t0 = time.perf_counter()
                _, _, terminated, truncated, _ = envs[v].step(action)
                seconds[v] += time.perf_counter() - t0
                steps[v] += 1
                if terminated or truncated:
                    break
    rates = {v: steps[v] / seconds[v] for v in envs}
    for v in envs:
        print(f"{ids[v]:30s} {steps[v]:6d} steps {rates[v]:8.0f} steps/s")
    print(f"v1 / v0: {rates['v1'] / rates['v0']:.2f}   v2 / v0: {rates['v2'] / rates['v0']:.2f}")
    if json_path:
        write_json_atomic(json_path, {"steps": steps, "steps_per_s": rates})
    return 0


# --------------------------------------------------------------------------------------------
# --timesteps: fewer, longer physics steps (a study for a later version)
# --------------------------------------------------------------------------------------------


def _retimed(timestep: float) -> DualGraspLiftEnv:
    """A v0 environment (target grasp from the benchmark) whose scene is compiled with another
    timestep: the control rate stays 20 Hz, the substeps per control step follow."""
    env = DualGraspLiftEnv(target_grasp="benchmark")
    use_timestep(env, timestep)
    return env


def timestep_study(timesteps: list[float], episodes: int, json_path: Path | None) -> int:
    envs = {dt: _retimed(dt) for dt in timesteps}
    keys = ("successes", "unstable", "steps", "physics_s", "step_s")
    stats: dict[float, dict[str, Any]] = {dt: dict.fromkeys(keys, 0) for dt in timesteps}
    depths: dict[float, list[float]] = {dt: [] for dt in timesteps}
    original = mujoco.mj_step
    physics = [0.0]

    def timed(model: mujoco.MjModel, data: mujoco.MjData, nstep: int = 1) -> None:
        t0 = time.process_time()
        original(model, data, nstep=nstep)
        physics[0] += time.process_time() - t0

    for seed in range(episodes):
        for dt in timesteps if seed % 2 == 0 else timesteps[::-1]:
            env, row = envs[dt], stats[dt]
            obs, _ = env.reset(seed=seed)
            policy = ScriptedLiftPolicy()
            info: dict[str, Any] = {}
            mujoco.mj_step = timed  # type: ignore[assignment]
            try:
                for _ in range(MAX_STEPS):
                    action = policy(obs)
                    physics[0] = 0.0
                    t0 = time.process_time()
                    obs, _, terminated, _, info = env.step(action)
                    row["step_s"] += time.process_time() - t0
                    row["physics_s"] += physics[0]
                    row["steps"] += 1
                    assert env._current is not None
                    data = env._current.data
                    if data.ncon:
                        depths[dt].append(max(0.0, -float(data.contact.dist[: data.ncon].min())))
                    if terminated:
                        break
            finally:
                mujoco.mj_step = original  # type: ignore[assignment]
            row["successes"] += int(bool(info.get("success")))
            row["unstable"] += int(info.get("termination") == "unstable")
    print(
        f"{'timestep':>9s} {'substeps':>8s} {'success':>9s} {'unstable':>8s} "
        f"{'mj_step us':>10s} {'env.step us':>11s} {'pen p99 mm':>10s} {'pen max mm':>10s}"
    )
    out = []
    for dt in timesteps:
        row = stats[dt]
        d = np.array(depths[dt] or [0.0])
        result = {
            "timestep": dt,
            "substeps": envs[dt].substeps,
            "episodes": episodes,
            "successes": row["successes"],
            "unstable": row["unstable"],
            "physics_us_per_step": 1e6 * row["physics_s"] / row["steps"],
            "step_us_per_step": 1e6 * row["step_s"] / row["steps"],
            "penetration_p99_mm": 1e3 * float(np.percentile(d, 99)),
            "penetration_max_mm": 1e3 * float(d.max()),
        }
        out.append(result)
        print(
            f"{dt * 1e3:7.1f}ms {result['substeps']:8d} {row['successes']:4d}/{episodes:<4d} "
            f"{row['unstable']:8d} {result['physics_us_per_step']:10.0f} "
            f"{result['step_us_per_step']:11.0f} {result['penetration_p99_mm']:10.2f} "
            f"{result['penetration_max_mm']:10.2f}"
        )
    if json_path:
        write_json_atomic(json_path, {"timesteps": out})
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--objects", nargs="+", help="object ids (default: one per family)")
    parser.add_argument("--random-episodes", type=int, default=2, help="per object")
    parser.add_argument("--episodes", type=int, default=4, help="scripted episodes per object")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, help="also write the results here")
    parser.add_argument(
        "--speed", action="store_true", help="this tree against a reference tree (issue 40)"
    )
    parser.add_argument("--reference", type=Path, help="--speed: the reference tree (default HEAD)")
    parser.add_argument("--rounds", type=int, default=5, help="--speed: alternations per probe")
    parser.add_argument(
        "--only", default="", help="--speed: only the measurements whose label contains this"
    )
    parser.add_argument(
        "--versions", type=int, metavar="EPISODES", help="v1, v2 against v0: random-action episodes"
    )
    parser.add_argument(
        "--timesteps", help="study: comma-separated scene timesteps (s), scripted episodes"
    )
    parser.add_argument(
        "--vector",
        metavar="ENV_ID",
        help="2-worker async vector env of ENV_ID against one env (this tree only)",
    )
    parser.add_argument("--steps", type=int, default=2000, help="--vector: steps per run")
    parser.add_argument(
        "--num-envs", type=int, default=16, help="--vector: LiftVectorEnv's environments"
    )
    parser.add_argument("--probe", help=argparse.SUPPRESS)  # one measurement, in a subprocess
    parser.add_argument("--probe-args", default="{}", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.probe == "serve":
        serve_episodes()
        return 0
    if args.probe:
        print(json.dumps(PROBES[args.probe](**json.loads(args.probe_args))))
        return 0
    if args.speed:
        return speed(args.reference, args.rounds, args.json, args.only)
    if args.versions:
        return versions(args.versions, args.json)
    if args.vector:
        result = probe_vector(args.steps, args.seed, args.vector)
        print(
            f"{args.vector}, AsyncVectorEnv: one env {result['single_steps_per_s']:.0f} steps/s, "
            f"2 workers {result['vector_steps_per_s']:.0f}: {result['ratio']:.2f}x left to the "
            f"scheduler, {result['pinned_ratio']:.2f}x pinned; an env that only burns the same "
            f"CPU time: {result['burn_ratio']:.2f}x, {result['burn_pinned_ratio']:.2f}x pinned"
        )
        if args.vector == "dg16m_env/DualGraspLift-v2":
            batched = probe_batched(args.steps, args.seed, args.vector, args.num_envs)
            result["batched"] = batched
            q2, qs, q1, qc = (
                batched["w2_over_single_quartiles"],
                batched["w2_sleep_over_single_quartiles"],
                batched["w1_over_single_quartiles"],
                batched["ceiling_quartiles"],
            )
            print(
                f"{args.vector}, LiftVectorEnv ({batched['num_envs']} envs), interleaved with one "
                f"env in this process ({batched['single_steps_per_s']:.0f} steps/s), medians "
                f"[quartiles] of {batched['rounds']} rounds: 2 workers "
                f"{batched['w2_over_single']:.2f}x [{q2[0]:.2f}, {q2[1]:.2f}] (spin_s "
                f"{batched['spin_s']:g}; sleeping at once {batched['w2_sleep_over_single']:.2f}x "
                f"[{qs[0]:.2f}, {qs[1]:.2f}]), 1 worker "
                f"{batched['w1_over_single']:.2f}x [{q1[0]:.2f}, {q1[1]:.2f}]; this machine's "
                f"ceiling (two free processes of pure-Python work against one): "
                f"{batched['ceiling_two_free_processes']:.2f}x [{qc[0]:.2f}, {qc[1]:.2f}]"
            )
        if args.json:
            write_json_atomic(args.json, result)
        return 0
    if args.timesteps:
        steps = [float(x) for x in args.timesteps.split(",")]
        return timestep_study(steps, args.episodes, args.json)
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
