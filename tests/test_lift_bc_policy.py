"""The learned Lift policy's pieces (:mod:`baselines.lift_bc_policy`): per-hand goal-frame
features of the right shape, actions turned into the goal frames and back unchanged, a saved
policy loaded to the same actions, bad observations and files refused with what was expected."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("torch")

import dg16m_env  # noqa: F401  registers the environments
from baselines.lift_bc_policy import (
    FEATURES,
    LiftBCPolicy,
    goal_frame_actions,
    hand_features,
    make_network,
    world_actions,
)
from dg16m_env.envs.lift.experts import FeedbackLiftExpert


@pytest.fixture(scope="module")
def visited() -> tuple[np.ndarray, np.ndarray]:
    """States of an expert episode and the expert's actions there."""
    env = gym.make("dg16m_env/DualGraspLift-v1")
    expert = FeedbackLiftExpert()
    obs, _ = env.reset(seed=42)
    states, actions = [], []
    for _ in range(60):
        action = expert(obs)
        states.append(obs)
        actions.append(action)
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    env.close()
    return np.array(states), np.array(actions)


def test_features_and_action_frames(visited) -> None:
    states, actions = visited
    features, to_goal = hand_features(states)
    assert features.shape == (len(states), 2, FEATURES)
    assert features.dtype == np.float32
    assert np.isfinite(features).all()
    # the rotations are rotations
    eye = np.einsum("nkij,nklj->nkil", to_goal, to_goal)
    assert np.allclose(eye, np.eye(3), atol=1e-9)
    # the expert's actions (fingers always +1 or -1) survive the trip to the goal frames and back
    back = world_actions(goal_frame_actions(actions, to_goal), to_goal)
    assert np.allclose(back, actions, atol=1e-6)
    # near the goal, the saturated error in action units is the expert's close-phase motion
    assert np.all(np.abs(features[..., 9:18]) <= 1.0)


def test_a_saved_policy_acts_the_same(tmp_path: Path, visited) -> None:
    import torch

    torch.manual_seed(0)
    features, _ = hand_features(visited[0])
    x = features.reshape(-1, FEATURES)
    policy = LiftBCPolicy(make_network(16, 2), x.mean(0), x.std(0) + 1e-3, 16, 2)
    path = tmp_path / "policy.pt"
    policy.save(path)
    loaded = LiftBCPolicy.load(path)
    for state in visited[0][::7]:
        a = policy(state)
        assert a.shape == (14,)
        assert a.dtype == np.float32
        assert np.all(np.abs(a) <= 1.0)
        assert np.array_equal(a, loaded(state))
    other = tmp_path / "other.pt"
    torch.save({"format": "something else"}, other)
    with pytest.raises(ValueError, match="expected a file of format"):
        LiftBCPolicy.load(other)
    broken = tmp_path / "broken.pt"
    broken.write_bytes(b"not a torch file")
    with pytest.raises(ValueError, match="expected a saved LiftBCPolicy"):
        LiftBCPolicy.load(broken)


def test_bad_observations_are_refused(visited) -> None:
    with pytest.raises(ValueError, match=r"expected DualGraspLift-v1 'state' observations"):
        hand_features(np.zeros((3, 71)))
    bad = visited[0][:2].copy()
    bad[1, 4] = np.nan
    with pytest.raises(ValueError, match="expected finite"):
        hand_features(bad)
