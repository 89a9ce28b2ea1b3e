"""``LiftVectorEnv`` (:mod:`dg16m_env.envs.lift.vector`), ``gym.make_vec``'s default for
DualGraspLift-v2: the same observations, rewards, flags and ``info`` as Gymnasium's
``SyncVectorEnv`` in each autoreset mode, with and without shared memory, resets by mask,
``call``/``get_attr``/``set_attr``/``render``, ``AsyncVectorEnv``'s constructor keywords, the
documented spin, and clear errors from its workers."""

from __future__ import annotations

import functools
import inspect
import multiprocessing
import time
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import dg16m_env  # noqa: F401  registers the environments
from dg16m_env.envs.lift.vector import (
    LiftVectorEnv,
    _wait,
    batch_infos,
    lift_v2_vector_env,
    make_env,
)
from dg16m_env.physics.replay import RenderError

LIFT_V2 = "dg16m_env/DualGraspLift-v2"
SHORT = {"episode_steps": 8, "max_episode_steps": 8}
"""Episodes of 8 steps: a few autoresets in a short run."""


def lift(num_envs: int, **kwargs: Any) -> LiftVectorEnv:
    """``num_envs`` Lift-v2 environments (the registered entry point: vector keywords to
    :class:`LiftVectorEnv`, the others to ``gym.make``)."""
    return lift_v2_vector_env(num_envs, **kwargs)


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


@pytest.mark.parametrize(("mode", "shared_memory"), [("NextStep", True), ("SameStep", False)])
def test_the_same_steps_as_sync_vector_env(mode: str, shared_memory: bool) -> None:
    spin_s = 0.0 if mode == "SameStep" else 0.001  # workers that sleep at once, or poll first
    batched = gym.make_vec(
        LIFT_V2,
        num_envs=3,
        workers=2,
        autoreset_mode=mode,
        spin_s=spin_s,
        shared_memory=shared_memory,
        **SHORT,
    )
    assert isinstance(batched.unwrapped, LiftVectorEnv)  # the registered default
    assert batched.unwrapped.workers == 2
    assert batched.unwrapped.spin_s == spin_s
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
    envs = lift(2, workers=2)
    with pytest.raises(ValueError, match=r"expected every environment reset once before a partial"):
        envs.reset(seed=[1, 2], options={"reset_mask": np.array([True, False])})
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
        lift(2, workers=2, reward_mode="shaped")  # block 0, here
    with pytest.raises(ValueError, match=r"workers: expected at most 2, found 3"):
        lift(2, workers=3)
    with pytest.raises(ValueError, match=r"workers: expected at most 1, found 2"):
        lift(2, workers=2, max_concurrency=1)
    with pytest.raises(ValueError, match=r"num_envs: expected an integer >= 1"):
        lift(0)
    with pytest.raises(ValueError, match=r"env_fns: expected at least one"):
        LiftVectorEnv([])
    for spin_s in (-1.0, float("nan"), float("inf"), "1"):
        with pytest.raises(ValueError, match=r"spin_s: expected finite seconds >= 0"):
            lift(1, spin_s=spin_s)
    for row, error in ((1, RuntimeError), (0, ValueError)):  # a worker's env, then one here
        envs = lift(2, workers=2, **SHORT)
        envs.reset(seed=0)
        actions = np.zeros((2, 14), dtype=np.float32)
        actions[row] = np.nan
        match = r"worker 1: .*action: expected" if row else r"action: expected"
        with pytest.raises(error, match=match):
            envs.step(actions)
        assert envs.closed  # closed on the error: no worker left behind
        assert not envs._processes


def test_one_worker_is_this_process_and_the_larger_block_is_here() -> None:
    here = lift(2, workers=1, **SHORT)
    assert not here._processes
    assert here._blocks == [0, 2]
    here.close()
    three = lift(5, workers=2, **SHORT)
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


def test_async_vector_envs_constructor_keywords() -> None:
    """Every keyword of ``AsyncVectorEnv``, with its default: a caller builds either the same
    way (``env_fns`` and the keywords), and the vector env keeps what it was given."""
    ours = inspect.signature(LiftVectorEnv).parameters
    for name, parameter in inspect.signature(gym.vector.AsyncVectorEnv).parameters.items():
        assert name in ours, name
        assert ours[name].default == parameter.default, name
    make = functools.partial(make_env, LIFT_V2, SHORT)
    for vector_env in (LiftVectorEnv, gym.vector.AsyncVectorEnv):
        envs = vector_env(
            [make] * 2,
            shared_memory=False,
            copy=False,
            context=None,
            daemon=True,
            observation_mode="same",
            autoreset_mode="SameStep",
        )
        assert (envs.num_envs, envs.copy, envs.shared_memory) == (2, False, False)
        assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
        assert envs.observation_space == gym.vector.utils.batch_space(
            envs.single_observation_space, 2
        )
        envs.close()


def test_call_get_attr_set_attr_and_render_across_blocks() -> None:
    """Gymnasium's methods on the sub-environments, block 0's (here) and a worker's, in
    environment order, as ``SyncVectorEnv``'s (frames where OpenGL can draw offscreen). The
    worker is spawned: a process forked from one that already drew with EGL (other tests of the
    session) can hang in its first frame."""
    mode = {"render_mode": "rgb_array", "width": 64, "height": 48}
    envs = lift(3, workers=2, context="spawn", **SHORT, **mode)
    reference = gym.make_vec(LIFT_V2, num_envs=3, vectorization_mode="sync", **SHORT, **mode)
    for vector in (envs, reference):
        vector.reset(seed=7)
    assert envs.get_attr("np_random_seed") == reference.get_attr("np_random_seed") == (7, 8, 9)
    assert envs.np_random_seed == (7, 8, 9)
    envs.set_attr("probe", ["a", "b", "c"])
    assert envs.get_attr("probe") == ("a", "b", "c")
    envs.set_attr("probe", 5)
    assert envs.call("get_wrapper_attr", "probe") == (5, 5, 5)
    with pytest.raises(ValueError, match=r"values: expected 3 \(one per sub-environment\)"):
        envs.set_attr("probe", [1, 2])
    assert envs.render_mode == "rgb_array"
    try:
        expected = reference.render()
    except RenderError:
        expected = None  # no offscreen OpenGL here
    if expected is not None:
        frames = envs.render()
        assert len(frames) == 3
        assert frames[2].shape == (48, 64, 3)
        assert all(same(a, b) for a, b in zip(frames, expected, strict=True))
    reference.close()
    envs.close()


def test_the_spin_is_an_option_that_polls_then_sleeps() -> None:
    """``spin_s`` (off by default): a waiting process polls its pipe for at most ``spin_s``
    seconds (at once when an answer is there), then sleeps in ``recv``; 0 does not poll."""
    assert inspect.signature(LiftVectorEnv).parameters["spin_s"].default == 0.0
    here, there = multiprocessing.Pipe()
    t0 = time.perf_counter()
    _wait(here, 0.02)
    assert time.perf_counter() - t0 >= 0.02  # nothing came: polled for the whole spin
    there.send("answer")
    t0 = time.perf_counter()
    _wait(here, 5.0)
    assert time.perf_counter() - t0 < 1.0  # an answer: at once
    assert here.recv() == "answer"
    t0 = time.perf_counter()
    _wait(here, 0.0)
    assert time.perf_counter() - t0 < 0.01
    here.close()
    there.close()


def test_spawned_workers_and_different_observation_spaces() -> None:
    """Worker processes started by ``spawn`` (the functions pickled, the ids registered by
    importing the module) give ``SyncVectorEnv``'s steps; ``observation_mode="different"``
    batches every environment's space."""
    make = functools.partial(make_env, LIFT_V2, SHORT)
    envs = LiftVectorEnv([make] * 2, context="spawn", workers=2, observation_mode="different")
    reference = gym.vector.SyncVectorEnv([make] * 2, observation_mode="different")
    assert envs.observation_space == reference.observation_space
    first, second = run(envs, steps=4), run(reference, steps=4)
    assert all(same(a, b) for a, b in zip(first, second, strict=True))


def test_disabled_autoreset_with_partial_resets_as_sync_vector_env() -> None:
    """``autoreset_mode="Disabled"``: the caller resets ended environments by mask, as with
    ``SyncVectorEnv``, the same bytes."""

    def episodes(envs: gym.vector.VectorEnv) -> list[Any]:
        out: list[Any] = [envs.reset(seed=3)]
        rng = np.random.default_rng(1)
        for _ in range(12):
            step = envs.step(rng.uniform(-1, 1, (3, 14)).astype(np.float32))
            out.append(step)
            ended = step[2] | step[3]
            if ended.any():
                out.append(envs.reset(options={"reset_mask": ended}))
        envs.close()
        return out

    make = functools.partial(make_env, LIFT_V2, SHORT)
    first = episodes(LiftVectorEnv([make] * 3, workers=2, autoreset_mode="Disabled"))
    second = episodes(gym.vector.SyncVectorEnv([make] * 3, autoreset_mode="Disabled"))
    assert len(first) == len(second) > 13  # episodes ended and were reset by mask
    assert all(same(a, b) for a, b in zip(first, second, strict=True))
