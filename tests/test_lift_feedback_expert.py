"""FeedbackLiftExpert (:mod:`dg16m_env.envs.lift.experts`): a pure function of the
DualGraspLift-v1 observation (same observation, same action, in any order, nothing remembered),
a clear error without a target, the three observation modes alike, and episodes of the
procedural benchmark it completes: as is, after the object was moved under it, and after 30
random actions (the states DAgger visits)."""

from __future__ import annotations

import copy
import math

import gymnasium as gym
import numpy as np
import pytest

import dg16m_env  # noqa: F401  registers the environments
from dg16m_env.envs.lift.experts import FeedbackLiftExpert
from dg16m_env.envs.lift.observations import STATE_LAYOUT, STATE_SLICES
from dg16m_env.envs.lift.spaces import ACTION_SIZE

# v1 is made on purpose: Gymnasium's note that a newer version (v2) is registered is expected.
pytestmark = pytest.mark.filterwarnings(
    "ignore:.*DualGraspLift-v1 is out of date.*:DeprecationWarning"
)

LIFT_V1 = "dg16m_env/DualGraspLift-v1"
SEED = 42
"""A procedural-benchmark episode the expert completes (ladder-1000002, 73 steps)."""


def run(env: gym.Env, expert: FeedbackLiftExpert, obs: object) -> tuple[list, dict]:
    """Run the expert to the episode's end: the observations it acted on, the last info."""
    seen = []
    while True:
        seen.append(obs)
        obs, _, terminated, truncated, info = env.step(expert(obs))
        if terminated or truncated:
            return seen, info


@pytest.fixture(scope="module")
def episode() -> tuple[list[np.ndarray], dict]:
    env = gym.make(LIFT_V1)
    try:
        obs, _ = env.reset(seed=SEED)
        return run(env, FeedbackLiftExpert(), obs)
    finally:
        env.close()


def test_completes_a_benchmark_episode(episode) -> None:
    observations, info = episode
    assert info["success"]
    assert info["termination"] == "success"
    expert = FeedbackLiftExpert()
    phases = [expert.phase(obs) for obs in observations]
    assert phases[0] == "approach"
    assert phases[-1] == "lift"
    assert {"approach", "close", "lift"} == set(phases)


def test_is_a_pure_function_of_the_observation(episode) -> None:
    observations = episode[0][::4]
    expert = FeedbackLiftExpert()
    attributes = copy.deepcopy(vars(expert))
    copies = [obs.copy() for obs in observations]
    forward = [expert(obs) for obs in observations]
    again = [expert(obs) for obs in observations]
    backward = [expert(obs) for obs in reversed(observations)][::-1]
    fresh = FeedbackLiftExpert()
    other = [fresh(obs) for obs in observations]
    for actions in (again, backward, other):
        assert all(np.array_equal(a, b) for a, b in zip(forward, actions, strict=True))
    for action in forward:
        assert action.dtype == np.float32
        assert action.shape == (ACTION_SIZE,)
        assert np.abs(action).max() <= 1.0
    assert all(np.array_equal(a, b) for a, b in zip(observations, copies, strict=True))
    assert vars(expert).keys() == attributes.keys()
    for name, value in attributes.items():
        assert np.array_equal(vars(expert)[name], value), name
    expert.reset()  # does nothing: the same actions after it
    assert np.array_equal(expert(observations[-1]), forward[-1])


def test_refuses_an_observation_without_a_target() -> None:
    env = gym.make(LIFT_V1, target_grasp=None)
    try:
        obs, _ = env.reset(seed=SEED)
    finally:
        env.close()
    expert = FeedbackLiftExpert()
    with pytest.raises(ValueError, match=r"expected an observation with a target .* found"):
        expert(obs)
    with pytest.raises(ValueError, match=r"expected a DualGraspLift-v1 state .* found shape"):
        expert(np.zeros(71, dtype=np.float32))
    with pytest.raises(ValueError, match=r"expected a DualGraspLift-v1 observation .* found"):
        expert({"points": np.zeros((4, 3))})


@pytest.mark.parametrize("obs_mode", ["state_dict", "pointcloud"])
def test_takes_every_observation_mode(episode, obs_mode: str) -> None:
    expected = [FeedbackLiftExpert()(obs) for obs in episode[0][:6]]
    env = gym.make(LIFT_V1, obs_mode=obs_mode)
    expert = FeedbackLiftExpert()
    try:
        obs, _ = env.reset(seed=SEED)
        for action in expected:
            assert isinstance(obs, dict)
            assert np.array_equal(expert(obs), action)
            obs = env.step(action)[0]
    finally:
        env.close()
    state = episode[0][0]
    parts = {name: state[STATE_SLICES[name]] for name, _, _, _ in STATE_LAYOUT}
    assert np.array_equal(expert(parts), expected[0])


def test_replans_when_the_object_moves() -> None:
    """The object moved (5 cm, turned 0.4 rad) while the hands are on their way: the expert
    goes to the grasp where it now is."""
    env = gym.make(LIFT_V1)
    expert = FeedbackLiftExpert()
    try:
        obs, _ = env.reset(seed=SEED)
        for _ in range(20):
            obs = env.step(expert(obs))[0]
        assert expert.phase(obs) == "approach"
        inner = env.unwrapped
        state = inner.get_state()
        qpos = slice(1 + inner._current.scene.object_qpos.start, None)  # after the time
        pose = state["physics"][qpos]
        pose[:2] += (0.04, -0.03)
        turn = np.array([math.cos(0.2), 0.0, 0.0, math.sin(0.2)])  # 0.4 rad about z
        w, v = turn[0], turn[1:]
        q = pose[3:7].copy()
        pose[3] = w * q[0] - v @ q[1:]
        pose[4:7] = w * q[1:] + q[0] * v + np.cross(v, q[1:])
        before = obs[STATE_SLICES["target_poses"]]
        obs = inner.set_state(state)
        moved = obs[STATE_SLICES["target_poses"]].reshape(2, 9)[:, :3] - before.reshape(2, 9)[:, :3]
        assert np.linalg.norm(moved, axis=1).min() > 0.03
        _, info = run(env, expert, obs)
    finally:
        env.close()
    assert info["success"]


def test_succeeds_after_random_actions() -> None:
    """DAgger's states: 30 uniform random actions first, then the expert."""
    env = gym.make(LIFT_V1)
    rng = np.random.default_rng(1000 + SEED)
    try:
        obs, _ = env.reset(seed=SEED)
        for _ in range(30):
            obs = env.step(rng.uniform(-1.0, 1.0, ACTION_SIZE).astype(np.float32))[0]
        _, info = run(env, FeedbackLiftExpert(), obs)
    finally:
        env.close()
    assert info["success"]
