"""``LiftVectorEnv`` (:mod:`dg16m_env.envs.lift_vector`), ``gym.make_vec``'s default for
DualGraspLift-v2: the same observations, rewards, flags and ``info`` as Gymnasium's
``SyncVectorEnv`` in each autoreset mode, resets by mask, and clear errors from its workers."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import dg16m_env  # noqa: F401  registers the environments
from dg16m_env.envs.lift_vector import LiftVectorEnv

LIFT_V2 = "dg16m_env/DualGraspLift-v2"
SHORT = {"episode_steps": 8, "max_episode_steps": 8}
"""Episodes of 8 steps: a few autoresets in a short run."""


def same(a: Any, b: Any) -> bool:
    """Equal structure and bytes (dicts in the same key order, arrays of the same dtype)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and list(a) == list(b) and all(same(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray):
        if not (isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape):
            return False
        if a.dtype == object:
            return all(same(x, y) for x, y in zip(a.ravel(), b.ravel(), strict=True))
        return a.tobytes() == b.tobytes()
    if isinstance(a, tuple | list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


def run(envs: gym.vector.VectorEnv, steps: int = 20) -> list[Any]:
    out: list[Any] = [envs.reset(seed=5)]
    rng = np.random.default_rng(0)
    for _ in range(steps):
        out.append(envs.step(rng.uniform(-1, 1, (envs.num_envs, 14)).astype(np.float32)))
    envs.close()
    return out


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_the_same_steps_as_sync_vector_env(mode: str) -> None:
    batched = gym.make_vec(LIFT_V2, num_envs=3, workers=2, autoreset_mode=mode, **SHORT)
    assert isinstance(batched.unwrapped, LiftVectorEnv)  # the registered default
    assert batched.unwrapped.workers == 2
    reference = gym.make_vec(
        LIFT_V2,
        num_envs=3,
        vectorization_mode="sync",
        vector_kwargs={"autoreset_mode": mode},
        **SHORT,
    )
    first, second = run(batched), run(reference)
    assert len(first) == len(second) == 21
    for step, (a, b) in enumerate(zip(first, second, strict=True)):
        assert same(a, b), step
    ends = sum(int((s[2] | s[3]).sum()) for s in first[1:])
    assert ends >= 6  # episodes ended and were reset on the way


def test_a_reset_mask_resets_only_those_envs() -> None:
    envs = LiftVectorEnv(2, workers=2, env_id=LIFT_V2)
    obs, _ = envs.reset(seed=[1, 2])
    envs.step(np.zeros((2, 14), dtype=np.float32))
    moved, _, _, _, _ = envs.step(np.full((2, 14), 0.5, dtype=np.float32))
    again, info = envs.reset(seed=[1, 2], options={"reset_mask": np.array([True, False])})
    assert again[0].tobytes() == obs[0].tobytes()  # env 0 back at its seeded start
    assert again[1].tobytes() == moved[1].tobytes()  # env 1 untouched
    assert info["_object_id"].tolist() == [True, False]
    with pytest.raises(ValueError, match=r"seed: expected 2 seeds"):
        envs.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match=r"reset_mask'\]: expected a bool array"):
        envs.reset(options={"reset_mask": [True, False]})
    envs.close()


def test_worker_errors_and_bad_arguments_are_clear() -> None:
    with pytest.raises(RuntimeError, match=r"worker 0: .*reward_mode: expected one of"):
        LiftVectorEnv(2, workers=2, env_id=LIFT_V2, reward_mode="shaped")
    with pytest.raises(ValueError, match=r"workers: expected at most num_envs = 2, found 3"):
        LiftVectorEnv(2, workers=3)
    with pytest.raises(ValueError, match=r"num_envs: expected an integer >= 1"):
        LiftVectorEnv(0)
    with pytest.raises(ValueError, match=r"render_mode: expected None"):
        LiftVectorEnv(1, render_mode="rgb_array")
    envs = LiftVectorEnv(1, workers=1, env_id=LIFT_V2, **SHORT)
    envs.reset(seed=0)
    with pytest.raises(RuntimeError, match=r"worker 0: .*action: expected"):
        envs.step(np.full((1, 14), np.nan, dtype=np.float32))
    assert envs.closed  # closed on the error: no worker left behind
    assert not envs._processes
