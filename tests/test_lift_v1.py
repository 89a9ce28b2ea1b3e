"""DualGraspLift-v1 (:mod:`dg16m_env.envs.lift.v1`), v2 (the same task on 5 ms
physics steps, :mod:`dg16m_env.envs.lift.v2`) and v3 (v2 whose success needs the grasp held,
:mod:`dg16m_env.envs.lift.v3`): success is the best return in
every reward mode (seed for seed against a policy that lifts only 5 cm and hovers), the reward
modes agree with each other, ``step()`` after the end is refused, each observation mode passes
Gymnasium's checker, and a restored state gives the same steps bit for bit."""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import dg16m_env  # noqa: F401  registers the environments
from dg16m_env.envs.lift.experts import FeedbackLiftExpert
from dg16m_env.envs.lift.observations import STATE_LAYOUT, STATE_SLICES
from dg16m_env.envs.lift.reward import MAX_STEP_REWARD, REWARD_MODES
from dg16m_env.envs.lift.task import FAILURES
from dg16m_env.envs.lift.v1 import DualGraspLiftV1Env

# v1 and v2 are made on purpose: Gymnasium's note that a newer version is registered is expected.
pytestmark = pytest.mark.filterwarnings(
    "ignore:.*DualGraspLift-v[12] is out of date.*:DeprecationWarning"
)

LIFT_V1 = "dg16m_env/DualGraspLift-v1"
LIFT_IDS = (LIFT_V1, "dg16m_env/DualGraspLift-v2", "dg16m_env/DualGraspLift-v3")
SEEDS = (42, 3)
"""Procedural-benchmark episodes the feedback expert completes (checked in the test)."""


def hover_policy() -> FeedbackLiftExpert:
    """The expert told to stop 5 cm up (``lift_height`` 0.02 + margin 0.03): it grasps and lifts
    the object to half the success height and holds it there to the end: never a success."""
    return FeedbackLiftExpert(lift_height=0.02, lift_margin=0.03)


def run(env: gym.Env, policy: Any, seed: int) -> tuple[float, dict[str, Any], int]:
    """Return, last info and steps of one episode."""
    obs, _ = env.reset(seed=seed)
    total, steps = 0.0, 0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        total += reward
        steps += 1
        if terminated or truncated:
            return total, info, steps


@pytest.fixture(scope="module", params=LIFT_IDS)
def episodes(request) -> dict[str, dict[int, dict[str, tuple[float, dict[str, Any], int]]]]:
    """Per reward mode, per seed: the expert's and the hover policy's episodes (per version)."""
    out: dict[str, dict[int, dict[str, tuple[float, dict[str, Any], int]]]] = {}
    for mode in REWARD_MODES:
        env = gym.make(request.param, reward_mode=mode)
        out[mode] = {
            seed: {
                "expert": run(env, FeedbackLiftExpert(), seed),
                "hover": run(env, hover_policy(), seed),
            }
            for seed in SEEDS
        }
        env.close()
    return out


def test_success_is_the_best_return_in_every_mode(episodes) -> None:
    for mode, per_seed in episodes.items():
        for seed, runs in per_seed.items():
            expert_return, expert_info, _ = runs["expert"]
            hover_return, hover_info, hover_steps = runs["hover"]
            assert expert_info["success"], (mode, seed)
            assert not expert_info["fail"], (mode, seed)
            assert not hover_info["success"], (mode, seed)
            assert not hover_info["fail"], (mode, seed)
            assert hover_steps == 200, (mode, seed)
            assert hover_info["lift"] > 0.03, (mode, seed, hover_info)
            assert expert_return > hover_return, (mode, seed, expert_return, hover_return)


def test_the_modes_agree(episodes) -> None:
    """normalized_dense = dense / R step for step (so in sum); sparse pays 1 for a success."""
    for seed in SEEDS:
        for who in ("expert", "hover"):
            dense = episodes["dense"][seed][who][0]
            normalized = episodes["normalized_dense"][seed][who][0]
            sparse = episodes["sparse"][seed][who][0]
            assert normalized == pytest.approx(dense / MAX_STEP_REWARD, rel=1e-9)
            assert sparse == (1.0 if who == "expert" else 0.0)


def test_the_success_step_pays_the_bound(episodes) -> None:
    """Dense: what the success step pays = R * (T - t + 1); the hover episode earns at most R
    per step, so never that much from the same step on."""
    for seed in SEEDS:
        _, info, steps = episodes["dense"][seed]["expert"]
        assert info["reward_terms"]["success"] == MAX_STEP_REWARD * (200 - steps + 1)
        assert info["elapsed_steps"] == steps
        hover_total = episodes["dense"][seed]["hover"][0]
        assert 0.0 <= hover_total <= MAX_STEP_REWARD * 200


@pytest.mark.parametrize("env_id", LIFT_IDS)
def test_dense_terms_are_bounded_per_step(env_id: str) -> None:
    env = gym.make(env_id)
    obs, info = env.reset(seed=5)
    assert info["fail"] is False
    assert info["elapsed_steps"] == 0
    rng = np.random.default_rng(0)
    expert = FeedbackLiftExpert()
    for t in range(60):
        action = expert(obs) if t % 2 else rng.uniform(-1, 1, 14).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        assert all(v >= 0.0 for v in info["reward_terms"].values())
        assert info["fail"] == (info["termination"] in FAILURES)
        if not info["success"]:
            assert reward <= MAX_STEP_REWARD
        if terminated or truncated:
            break
    env.close()


@pytest.mark.parametrize("env_id", LIFT_IDS)
def test_step_after_the_end_is_refused(env_id: str) -> None:
    env = gym.make(env_id, episode_steps=3)
    obs, _ = env.reset(seed=0)
    action = np.zeros(14, dtype=np.float32)
    for _ in range(3):
        obs, *_, truncated, info = env.step(action)
    assert truncated
    assert info["elapsed_steps"] == 3
    assert obs[STATE_SLICES["elapsed"]][0] == 1.0
    with pytest.raises(RuntimeError, match=r"expected reset\(\) after the episode ended"):
        env.unwrapped.step(action)
    env.reset(seed=1)
    env.step(env.action_space.sample())  # a reset allows steps again
    env.close()


@pytest.mark.parametrize("env_id", LIFT_IDS)
@pytest.mark.parametrize("obs_mode", ["state", "state_dict", "pointcloud"])
def test_each_observation_mode_passes_check_env(env_id: str, obs_mode: str) -> None:
    env = gym.make(env_id, obs_mode=obs_mode, n_points=64)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=7)
    assert env.observation_space.contains(obs)
    if obs_mode == "state_dict":
        assert list(obs) == [name for name, _, _, _ in STATE_LAYOUT]
    if obs_mode == "pointcloud":
        flat = env.unwrapped.version.flat_cloud  # v3: (3 n,) vectors, the same numbers
        assert obs["points"].shape == obs["normals"].shape == ((192,) if flat else (64, 3))
        assert obs["mask"].sum() > 0
        state = obs["state"]
        # the cloud is carried with the object: points stay near the object's position
        points = obs["points"].reshape(-1, 3)
        near = points[obs["mask"] > 0] - state[STATE_SLICES["object_position"]]
        assert np.abs(near).max() < 2.0
    env.close()


def test_wrong_modes_are_refused() -> None:
    with pytest.raises(ValueError, match="reward_mode: expected one of"):
        DualGraspLiftV1Env(reward_mode="shaped")
    with pytest.raises(ValueError, match="obs_mode: expected one of"):
        DualGraspLiftV1Env(obs_mode="rgbd")


@pytest.mark.parametrize("env_id", LIFT_IDS)
def test_a_restored_state_gives_the_same_steps(env_id: str) -> None:
    env = gym.make(env_id)
    inner = env.unwrapped
    rng = np.random.default_rng(3)
    env.reset(seed=11)
    expert = FeedbackLiftExpert()
    obs = None
    for _ in range(20):
        obs, *_ = env.step(rng.uniform(-1, 1, 14).astype(np.float32))
    state = inner.get_state()
    assert tuple(state) == inner.get_state_keys()  # the keys set_state checks are the ones written
    actions = []
    first = []
    for _ in range(30):
        action = expert(obs)
        actions.append(action)
        obs, reward, terminated, truncated, _ = env.step(action)
        first.append((obs.tobytes(), reward, terminated, truncated))
        if terminated or truncated:
            break
    env.reset(seed=99)  # another object, another episode
    restored = inner.set_state(state)
    again = []
    for action in actions:
        obs, reward, terminated, truncated, _ = env.step(action)
        again.append((obs.tobytes(), reward, terminated, truncated))
    assert again == first
    assert restored.dtype == np.float32
    with pytest.raises(ValueError, match="expected a get_state"):
        inner.set_state({"version": 0})
    with pytest.raises(ValueError, match=r"found \['cloud'\] missing"):
        inner.set_state({k: v for k, v in state.items() if k != "cloud"})
    bad = dict(state, physics=np.zeros(3))
    with pytest.raises(ValueError, match=r"state\['physics'\]: expected shape"):
        inner.set_state(bad)
    env.close()
