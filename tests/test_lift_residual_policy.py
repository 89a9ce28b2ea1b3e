"""The residual Lift policy (:mod:`baselines.lift_residual_policy`) and its PPO script
(:mod:`baselines.residual_lift`): an untrained residual acts exactly as its base policy, residuals
move the motion in the goal frames and soften the fingers within the action bounds, a saved
policy loads to the same actions, wrong files are refused, and the script trains, evaluates and
writes its run on a tiny budget."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("torch")

import torch

import dg16m_env  # noqa: F401  registers the environments
from baselines.lift_bc_policy import FEATURES, LiftBCPolicy, hand_features, make_network
from baselines.lift_residual_policy import (
    ACTOR_INPUTS,
    CRITIC_INPUTS,
    LiftResidualPolicy,
    compose_actions,
)
from dg16m_env.envs.lift.experts import FeedbackLiftExpert


def tiny_base(seed: int = 0) -> LiftBCPolicy:
    """A small untrained base policy with a non-trivial normalisation."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    return LiftBCPolicy(
        make_network(16, 1), rng.normal(size=FEATURES), 1.0 + rng.random(FEATURES), 16, 1
    )


@pytest.fixture(scope="module")
def states() -> np.ndarray:
    """States of an expert episode (approach, close and lift)."""
    env = gym.make("dg16m_env/DualGraspLift-v1")
    expert = FeedbackLiftExpert()
    obs, _ = env.reset(seed=42)
    out = []
    for _ in range(80):
        out.append(obs)
        obs, _, terminated, truncated, _ = env.step(expert(obs))
        if terminated or truncated:
            break
    env.close()
    return np.array(out)


def test_an_untrained_residual_acts_as_its_base(states: np.ndarray) -> None:
    base = tiny_base()
    policy = LiftResidualPolicy.from_base(base, hidden=32, init_std=0.05)
    assert np.array_equal(policy.act(states), base.act(states))
    assert np.array_equal(policy(states[3]), base(states[3]))
    actor_in, critic_in, base_out, to_goal = policy.inputs(states)
    assert actor_in.shape == (len(states), 2, ACTOR_INPUTS)
    assert critic_in.shape == (len(states), CRITIC_INPUTS)
    assert base_out.shape == (len(states), 2, 7)
    assert to_goal.shape == (len(states), 2, 3, 3)


def test_residuals_move_the_motion_in_the_goal_frames(states: np.ndarray) -> None:
    base = tiny_base()
    features, to_goal = hand_features(states)
    outputs = base.outputs(features)
    residual = np.zeros((len(states), 2, 7))
    residual[:, 0, 0] = 0.25  # hand 0: along its goal frame's x axis
    moved = compose_actions(outputs, residual, to_goal)
    still = compose_actions(outputs, np.zeros_like(residual), to_goal)
    # hand 1 unchanged; hand 0's translation changed along its goal x axis (world frame),
    # unless the base motion there already saturates
    assert np.array_equal(moved[:, 7:], still[:, 7:])
    along = np.einsum("nj,nj->n", moved[:, :3] - still[:, :3], to_goal[:, 0, 0])
    free = np.abs(outputs[:, 0, 0] + 0.25) < 1.0
    assert free.any()
    assert np.allclose(along[free], 0.25, atol=1e-5)
    # a finger residual softens the squeeze (or the release), never beyond [-1, 1]
    residual = np.zeros((len(states), 2, 7))
    residual[..., 6] = -0.4
    soft = compose_actions(outputs, residual, to_goal)
    fingers = np.where(outputs[..., 6] > 0, 0.6, -1.0)
    assert np.allclose(soft[:, [6, 13]], fingers, atol=1e-6)
    huge = compose_actions(outputs, np.full((len(states), 2, 7), 50.0), to_goal)
    assert np.abs(huge).max() <= 1.0
    assert huge.dtype == np.float32


def test_a_saved_policy_acts_the_same(tmp_path: Path, states: np.ndarray) -> None:
    policy = LiftResidualPolicy.from_base(tiny_base(), hidden=32, init_std=0.1)
    with torch.no_grad():  # a trained-looking residual
        policy.actor[-1].weight.normal_(0.0, 0.1)
        policy.actor[-1].bias.normal_(0.0, 0.1)
    path = tmp_path / "policy.pt"
    policy.save(path)
    loaded = LiftResidualPolicy.load(path)
    assert np.array_equal(loaded.act(states), policy.act(states))
    assert not np.array_equal(policy.act(states), policy.base.act(states))
    assert torch.allclose(loaded.log_std, torch.log(torch.full((7,), 0.1)))


def test_wrong_files_and_arguments_are_refused(tmp_path: Path) -> None:
    base_file = tmp_path / "base.pt"
    tiny_base().save(base_file)
    with pytest.raises(ValueError, match="expected a file of format 'dg16m-lift-residual-policy'"):
        LiftResidualPolicy.load(base_file)
    broken = tmp_path / "broken.pt"
    broken.write_bytes(b"not a torch file")
    with pytest.raises(ValueError, match="expected a saved LiftResidualPolicy"):
        LiftResidualPolicy.load(broken)
    with pytest.raises(ValueError, match=r"expected a standard deviation > 0, found 0\.0"):
        LiftResidualPolicy.from_base(tiny_base(), hidden=8, init_std=0.0)


def test_the_script_help() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "baselines.residual_lift", "--help"],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    assert "--base-policy" in result.stdout
    assert "--init-std" in result.stdout


def test_two_episode_smoke_run(tmp_path: Path) -> None:
    base_file = tmp_path / "base.pt"
    tiny_base().save(base_file)
    out = tmp_path / "run"
    tiny = ["--hidden", "16", "--num-envs", "2", "--num-steps", "100", "--total-timesteps", "400"]
    subprocess.run(
        [
            sys.executable,
            "-m",
            "baselines.residual_lift",
            "--base-policy",
            str(base_file),
            *tiny,
            "--critic-warmup",
            "1",
            "--eval-episodes",
            "2",
            "--out",
            str(out),
        ],
        check=True,
        capture_output=True,
        timeout=600,
    )
    results = json.loads((out / "results.json").read_text())
    assert set(results["results"]) == {"bc_residual", "bc_base", "random_actions"}
    for result in results["results"].values():
        assert result["metrics"]["success_rate"]["episodes"] == 2
    assert results["train_timesteps"] == 400
    assert (out / "learning_curve.png").stat().st_size > 10_000
    trained = LiftResidualPolicy.load(out / "policy.pt")
    assert trained.hidden == 16
    # one actor update happened (iteration 2 of 2): the residual is no longer zero
    assert float(trained.actor[-1].weight.detach().abs().sum()) > 0.0


def test_a_missing_base_policy_is_refused(tmp_path: Path) -> None:
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "baselines.residual_lift",
            "--base-policy",
            str(tmp_path / "nothing.pt"),
            "--out",
            str(tmp_path / "run"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode != 0
    assert "--base-policy:" in result.stderr
    assert "expected a saved LiftBCPolicy" in result.stderr
