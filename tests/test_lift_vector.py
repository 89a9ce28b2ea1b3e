"""``LiftVectorEnv`` (:mod:`dg16m_env.envs.lift_vector`), ``gym.make_vec``'s default for
DualGraspLift-v2: the same observations, rewards, flags and ``info`` as Gymnasium's
``SyncVectorEnv`` in each autoreset mode, resets by mask, and clear errors from its workers."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import dg16m_env  # noqa: F401  registers the environments
from dg16m_env.envs.lift_vector import LiftVectorEnv, batch_infos

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
    spin_s = 0.0 if mode == "SameStep" else None  # workers that sleep at once, or poll first
    batched = gym.make_vec(
        LIFT_V2, num_envs=3, workers=2, autoreset_mode=mode, spin_s=spin_s, **SHORT
    )
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
    with pytest.raises(ValueError, match=r"reward_mode: expected one of"):
        LiftVectorEnv(2, workers=2, env_id=LIFT_V2, reward_mode="shaped")  # block 0, here
    with pytest.raises(ValueError, match=r"workers: expected at most num_envs = 2, found 3"):
        LiftVectorEnv(2, workers=3)
    with pytest.raises(ValueError, match=r"num_envs: expected an integer >= 1"):
        LiftVectorEnv(0)
    with pytest.raises(ValueError, match=r"render_mode: expected None"):
        LiftVectorEnv(1, render_mode="rgb_array")
    for spin_s in (-1.0, float("nan"), float("inf"), "1"):
        with pytest.raises(ValueError, match=r"spin_s: expected finite seconds >= 0"):
            LiftVectorEnv(1, spin_s=spin_s)
    for row, error in ((1, RuntimeError), (0, ValueError)):  # a worker's env, then one here
        envs = LiftVectorEnv(2, workers=2, env_id=LIFT_V2, **SHORT)
        envs.reset(seed=0)
        actions = np.zeros((2, 14), dtype=np.float32)
        actions[row] = np.nan
        match = r"worker 1: .*action: expected" if row else r"action: expected"
        with pytest.raises(error, match=match):
            envs.step(actions)
        assert envs.closed  # closed on the error: no worker left behind
        assert not envs._processes


def test_one_worker_is_this_process_and_the_larger_block_is_here() -> None:
    here = LiftVectorEnv(2, workers=1, env_id=LIFT_V2, **SHORT)
    assert not here._processes
    assert here._blocks == [0, 2]
    here.close()
    three = LiftVectorEnv(5, workers=2, env_id=LIFT_V2, **SHORT)
    assert three._blocks == [0, 3, 5]  # the larger block here: a worker's pays for messages
    three.close()


def _gymnasium_infos(records: list[tuple[int, dict[str, Any]]], num_envs: int) -> dict[str, Any]:
    helper = gym.vector.VectorEnv()
    helper.num_envs = num_envs
    infos: dict[str, Any] = {}
    for env_num, info in records:
        infos = helper._add_info(infos, info, env_num)
    return infos


def test_batch_infos_is_gymnasiums_add_info() -> None:
    """The column-wise batching gives what ``VectorEnv._add_info`` gives record by record,
    for regular steps and for the records it hands back to ``_add_info``."""
    rng = np.random.default_rng(3)

    def info(i: int) -> dict[str, Any]:
        return {
            "object_id": f"obj-{i}",
            "success": bool(i % 2),
            "lift": float(rng.normal()),
            "count": int(i),
            "f32": np.float32(i / 3),
            "flag": np.bool_(i % 3 == 0),
            "slip": rng.normal(size=2),
            "terms": {"reach": float(i), "grasp": np.int64(i)},
            "pair": (i, i + 1),
        }

    regular = [(i, info(i)) for i in range(4)]
    cases = {
        "regular": regular,
        "a reset among steps": [*regular[:2], (2, {"object_id": "x", "count": 7}), regular[3]],
        "some envs only": [(1, info(1)), (3, info(3))],
        "int then float": [(0, {"v": 1}), (1, {"v": 2.5}), (2, {"v": 3}), (3, {"v": 4})],
        "shapes differ": [(i, {"a": np.zeros(i + 1)}) for i in range(1)]
        + [(i, {"a": np.ones(1)}) for i in range(1, 4)],
        "same step final": [
            (0, {"final_obs": np.ones(3), "final_info": info(0)}),
            (0, {"object_id": "new"}),
            *regular[1:],
        ],
        "a mask-like key": [(i, {"_x": i, "x": i}) for i in range(4)],
        "dict here, number there": [(0, {"v": {"a": 1}}), (1, {"v": 2})],
    }
    for name, records in cases.items():
        try:
            expected: Any = _gymnasium_infos(records, 4)
        except Exception as exc:  # Gymnasium's own failure is the reference
            expected = type(exc)
        if isinstance(expected, type):
            with pytest.raises(expected):
                batch_infos(records, 4)
        else:
            assert same(batch_infos(records, 4), expected), name
