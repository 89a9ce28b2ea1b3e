"""The learned generator as a ``DualGraspPose-v0`` policy (issue 59): actions in the space from
the env's partial cloud, deterministic for an observation, clear errors for a malformed one,
and the script's results and plot, with every episode counted."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("torch")

import dg16m_env  # noqa: F401
from baselines.cloud_inputs import CloudError
from baselines.flow_pose_policy import (
    ENV_ID,
    Args,
    CloudGraspPolicy,
    main,
    paired_difference,
    policy_cloud,
    run_episode,
    summarise,
)
from dg16m_env.benchmark.names import REAL_BENCHMARK


def partial_env(**kwargs) -> gym.Env:
    return gym.make(ENV_ID, obs_mode="partial", n_cameras=2, n_points=1024, **kwargs)


@pytest.fixture(scope="module")
def observation() -> dict[str, np.ndarray]:
    env = partial_env()
    obs, _ = env.reset(seed=100001)
    env.close()
    return obs


def test_the_policy_acts_in_the_space_from_the_partial_cloud(observation) -> None:
    env = partial_env()
    env.reset(seed=100001)
    policy = CloudGraspPolicy()
    action = policy(observation)
    assert action.dtype == np.float32
    assert action.shape == (2, 9)
    assert env.action_space.contains(action)
    again = CloudGraspPolicy()(dict(observation))
    assert again.tobytes() == action.tobytes()  # the same observation, the same action
    _, reward, terminated, _, info = env.step(action)
    assert terminated
    assert reward in (0.0, 1.0)
    assert info["success"] == (reward == 1.0)
    env.close()


def test_the_mask_drops_padding_and_names_the_stream(observation) -> None:
    cloud = policy_cloud(observation)
    valid = int((observation["mask"] > 0.5).sum())
    assert cloud["points"].shape == cloud["normals"].shape == (valid, 3)
    assert cloud["object_id"].startswith("cloud-")
    assert len(cloud["object_id"]) == 22
    padded = dict(observation)
    mask = observation["mask"].copy()
    mask[: len(mask) // 2] = 0.0
    padded["mask"] = mask
    assert policy_cloud(padded)["object_id"] != cloud["object_id"]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda o: {k: v for k, v in o.items() if k != "normals"}, "expected keys"),
        (lambda o: {**o, "points": o["points"][:-1]}, "3 P values"),
        (lambda o: {**o, "mask": o["mask"][:-3]}, "mask: expected"),
        (lambda o: {**o, "mask": np.zeros_like(o["mask"])}, "at least one observed point"),
        (lambda o: {**o, "points": np.full_like(o["points"], np.nan)}, "expected"),
        (lambda o: list(o), "expected a dict"),
    ],
)
def test_a_malformed_observation_gets_the_clouds_error(observation, change, message) -> None:
    with pytest.raises(CloudError, match=message):
        CloudGraspPolicy()(change(observation))


def test_a_policy_that_raises_fails_its_episode_and_counts() -> None:
    def no_candidate(observation):
        raise CloudError("expected dual candidates on the cloud, found none")

    env = partial_env()
    record = run_episode(env, no_candidate, 100000)
    assert record["success"] is False
    assert record["failure"].startswith("CloudError")
    outside = run_episode(env, lambda o: np.full((2, 9), 5.0, np.float32), 100000)
    assert outside["success"] is False
    assert outside["failure"] == "action outside the space"
    env.close()


def test_the_script_scores_every_episode_and_writes_results(tmp_path: Path) -> None:
    out = tmp_path / "pose.json"
    args = Args(
        policies="flow,random_actions",
        episodes=3,
        n_points=1024,
        out=out,
        plot=str(tmp_path / "pose.png"),
    )
    results = main(args)
    assert json.loads(out.read_text()) == json.loads(json.dumps(results))
    assert [row["policy"] for row in results["rates"]] == ["flow", "random_actions"]
    for row in results["rates"]:
        assert row["rows"] == 3
        assert len(row["episodes"]) == 3
        assert row["successes"] == sum(e["success"] for e in row["episodes"])
        assert row["ci_low"] <= row["rate"] <= row["ci_high"]
        assert sum(row["failures"].values()) == 3 - row["successes"]
    assert [e["seed"] for e in results["rates"][0]["episodes"]] == [100000, 100001, 100002]
    assert (tmp_path / "pose.png").stat().st_size > 1000
    paired = results["rates"][1]["paired_vs_first"]
    assert paired["policy"] == "flow"
    assert paired["difference"] == pytest.approx(
        results["rates"][1]["rate"] - results["rates"][0]["rate"]
    )


def test_every_invalid_start_counts_and_every_failure_stays_in_the_rate() -> None:
    reasons = ["hand0_penetrates", "hand1_penetrates", "hands_overlap", "not held"]
    episodes = [{"seed": i, "success": False, "failure": r} for i, r in enumerate(reasons)]
    episodes.append({"seed": 9, "success": True, "failure": None, "seconds": 0.5})
    row = summarise(episodes)
    assert row["invalid_starts"] == 3 / 5
    assert row["rate"] == 1 / 5
    assert sum(row["failures"].values()) == 4


def test_the_paired_difference_is_over_the_same_episodes() -> None:
    first = [{"seed": s, "success": False} for s in range(40)]
    other = [{"seed": s, "success": s % 2 == 0} for s in range(40)]
    paired = paired_difference(first, other, seed=0)
    assert paired["difference"] == 0.5
    assert 0.3 < paired["ci_low"] < 0.5 < paired["ci_high"] < 0.7
    assert paired == paired_difference(first, other, seed=0)  # seeded
    with pytest.raises(ValueError, match="same seeds"):
        paired_difference(first, other[::-1], seed=0)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"policies": "flow,sac"}, "policies: expected"),
        ({"policies": ""}, "policies: expected"),
        ({"benchmark": "acronym"}, "benchmark: expected"),
        ({"episodes": 0}, "episodes: expected"),
        ({"obs_mode": "depth"}, "obs_mode: expected"),
        ({"n_points": -1}, "n_points: expected"),
    ],
)
def test_bad_arguments_are_refused_before_any_work(tmp_path: Path, change, message) -> None:
    args = replace(Args(out=tmp_path / "r.json"), **change)
    with pytest.raises(ValueError, match=message):
        main(args)
    assert not (tmp_path / "r.json").exists()


@pytest.mark.skipif(
    not REAL_BENCHMARK.is_file(), reason=f"the real benchmark is not shipped ({REAL_BENCHMARK})"
)
def test_the_policy_acts_on_a_real_object() -> None:
    env = partial_env(benchmark="real")
    obs, _ = env.reset(seed=100002)
    action = CloudGraspPolicy()(obs)
    assert env.action_space.contains(action)
    env.close()
