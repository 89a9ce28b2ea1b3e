"""The point-cloud Lift policy (``baselines/lift_cloud_policy.py``) and its training script
(``baselines/bc_lift_cloud.py``): the features ignore the privileged object state and follow
the cloud, shapes and dtypes, bad inputs are refused, a saved policy loads and acts the same,
and a tiny end-to-end run writes its files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import gymnasium as gym  # noqa: E402

import dg16m_env  # noqa: E402, F401  registers the environments
from baselines.bc_lift_cloud import Args, rollouts, train  # noqa: E402
from baselines.lift_cloud_policy import (  # noqa: E402
    ALLOWED_STATE,
    FEATURES,
    LiftCloudPolicy,
    hand_features,
    observation_inputs,
)
from dg16m_env.envs.lift.observations import STATE_SLICES  # noqa: E402
from dg16m_env.envs.lift.recovering_expert import RecoveringLiftExpert  # noqa: E402

PRIVILEGED = sorted(set(STATE_SLICES) - set(ALLOWED_STATE))


@pytest.fixture(scope="module")
def env() -> Any:
    e = gym.make("dg16m_env/DualGraspLift-v2", obs_mode="pointcloud")
    yield e
    e.close()


@pytest.fixture(scope="module")
def observation(env: Any) -> dict[str, np.ndarray]:
    obs, _ = env.reset(seed=3)
    teacher = RecoveringLiftExpert()
    for _ in range(5):  # move a little so that previous actions are not all zero
        obs, *_ = env.step(teacher(obs))
    return obs


def inputs(obs: dict[str, np.ndarray], n_points: int = 64) -> tuple[np.ndarray, ...]:
    state, cloud, heights = observation_inputs(obs, n_points, np.random.default_rng(0))
    return state[None], cloud[None], heights[None]


def test_shapes_and_dtypes(observation: dict[str, np.ndarray]) -> None:
    state, cloud, heights = inputs(observation)
    assert state.shape == (1, 117)
    assert state.dtype == np.float32
    assert cloud.shape == (1, 64, 3)
    assert cloud.dtype == np.float32
    assert heights.shape == (1, 2)
    assert heights[0, 0] <= heights[0, 1]
    features, local, to_goal = hand_features(state, cloud, heights)
    assert features.shape == (1, 2, FEATURES)
    assert features.dtype == np.float32
    assert local.shape == (1, 2, 64, 3)
    assert local.dtype == np.float32
    assert to_goal.shape == (1, 2, 3, 3)
    assert np.isfinite(features).all()


def test_features_ignore_the_privileged_state(observation: dict[str, np.ndarray]) -> None:
    state, cloud, heights = inputs(observation)
    features, local, _ = hand_features(state, cloud, heights)
    assert {"object_position", "lift", "hold", "grasp_centres", "object_size"} <= set(PRIVILEGED)
    rng = np.random.default_rng(1)
    for name in PRIVILEGED:
        changed = state.copy()
        changed[0, STATE_SLICES[name]] += rng.normal(size=changed[0, STATE_SLICES[name]].shape)
        other, other_local, _ = hand_features(changed, cloud, heights)
        np.testing.assert_array_equal(other, features, err_msg=name)
        np.testing.assert_array_equal(other_local, local, err_msg=name)


def test_features_follow_the_cloud(observation: dict[str, np.ndarray]) -> None:
    state, cloud, heights = inputs(observation)
    features, local, _ = hand_features(state, cloud, heights)
    moved = cloud + np.float32([0.0, 0.0, 0.05])
    other, other_local, _ = hand_features(state, moved, heights + np.float32(0.05))
    assert not np.allclose(other, features)
    assert not np.allclose(other_local, local)
    # a hand-side state part (the target) does change them
    changed = state.copy()
    changed[0, STATE_SLICES["target_poses"].start] += 0.1
    assert not np.allclose(hand_features(changed, cloud, heights)[0], features)


def test_bad_inputs_are_refused(observation: dict[str, np.ndarray]) -> None:
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match=r"expected a cloud of shape \(n_points, 3\), found"):
        observation_inputs({**observation, "points": np.zeros((10, 4))}, 8, rng)
    nan = observation["points"].copy()
    nan[0, 0] = np.nan
    with pytest.raises(ValueError, match="expected finite cloud points, found NaN"):
        observation_inputs({**observation, "points": nan}, 8, rng)
    with pytest.raises(ValueError, match="with at least one masked point"):
        observation_inputs({**observation, "mask": np.zeros(len(nan))}, 8, rng)
    with pytest.raises(ValueError, match="expected a 'pointcloud' observation"):
        observation_inputs(observation["state"], 8, rng)
    state, cloud, heights = inputs(observation)
    with pytest.raises(ValueError, match=r"expected clouds of shape \(1, n_points, 3\)"):
        hand_features(state, cloud[0], heights)
    bad = state.copy()
    bad[0, 0] = np.inf
    with pytest.raises(ValueError, match="expected finite 'state' observations"):
        hand_features(bad, cloud, heights)


def test_trained_policy_saves_loads_and_acts_the_same(
    env: Any, observation: dict[str, np.ndarray], tmp_path: Path
) -> None:
    args = Args(n_points=32, encoder="8,16", hidden=16, layers=1, epochs=1)
    rng = np.random.default_rng(0)
    steps, rate = rollouts(env, RecoveringLiftExpert(), None, range(1), args, rng, desc="t")
    assert len(steps) > 10
    assert 0.0 <= rate <= 1.0
    policy, loss = train(steps, args)
    assert np.isfinite(loss)
    action = policy(observation)
    assert action.shape == (14,)
    assert action.dtype == np.float32
    assert np.all(np.abs(action) <= 1.0)
    np.testing.assert_array_equal(policy(observation), action)  # seeded subsample
    policy.save(tmp_path / "policy.pt")
    loaded = LiftCloudPolicy.load(tmp_path / "policy.pt")
    assert (loaded.n_points, loaded.encoder) == (32, (8, 16))
    np.testing.assert_array_equal(loaded(observation), action)
    torch.save({"format": "other"}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="expected a file of format 'dg16m-lift-cloud-policy'"):
        LiftCloudPolicy.load(tmp_path / "other.pt")


def test_tiny_end_to_end_run(tmp_path: Path, observation: dict[str, np.ndarray]) -> None:
    out = tmp_path / "run"
    tiny = ["--hidden", "16", "--layers", "1", "--encoder", "8,16", "--n-points", "32"]
    subprocess.run(
        [
            sys.executable,
            "-m",
            "baselines.bc_lift_cloud",
            "--teacher-episodes",
            "2",
            *tiny,
            "--epochs",
            "1",
            "--dagger-rounds",
            "1",
            "--dagger-episodes",
            "1",
            "--episode-steps",
            "120",
            "--eval-episodes",
            "1",
            "--teacher",
            "planning",
            "--out",
            str(out),
        ],
        check=True,
        capture_output=True,
        timeout=300,
    )
    results = json.loads((out / "results.json").read_text())
    assert set(results["results"]) == {"bc_dagger_cloud", "expert", "random_actions"}
    for result in results["results"].values():
        assert result["metrics"]["success_rate"]["episodes"] == 1
    assert [r["round"] for r in results["rounds"]] == [0, 1]
    assert results["teacher"]["name"] == "PlanningLiftExpert"
    assert set(results["seconds"]) >= {"collection", "training", "evaluation"}
    assert (out / "success_rates.png").stat().st_size > 10_000
    policy = LiftCloudPolicy.load(out / "policy.pt")
    assert policy.hidden == 16
    action = policy(observation)
    np.testing.assert_array_equal(LiftCloudPolicy.load(out / "policy.pt")(observation), action)


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("--dagger-phases", "grasp", "expected 'all' or phases among"),
        ("--teacher", "oracle", "--teacher: expected recovering or planning, found 'oracle'"),
    ],
)
def test_wrong_arguments_are_refused(tmp_path: Path, option: str, value: str, message: str) -> None:
    out = tmp_path / "run"
    result = subprocess.run(
        [sys.executable, "-m", "baselines.bc_lift_cloud", option, value, "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode != 0
    assert message in result.stderr
    assert not out.exists()
