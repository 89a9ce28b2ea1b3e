"""Lift demonstrations as a Minari dataset (:mod:`dg16m_env.envs.lift.demos`): a tiny dataset is
written, loaded with ``minari`` by name, replayed step for step identically; a changed action is
caught; an existing dataset is not overwritten."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

minari = pytest.importorskip("minari")

from dg16m_env.envs.lift.demo_files import (  # noqa: E402
    LiftDemosError,
    episode_metadata,
    open_lift_demos,
    replay_lift_demo,
)
from dg16m_env.envs.lift.demos import collect_lift_demos  # noqa: E402


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("minari")
    collect_lift_demos(root, episodes=2, objects="all", seed=42, progress=False)
    return root


def test_written_loaded_by_name_and_replayed(root: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    dataset = minari.load_dataset("dg16m/lift-expert-v0")
    assert dataset.total_episodes == 2
    episode = next(iter(dataset.iterate_episodes()))
    assert episode.observations.shape == (len(episode) + 1, 117)
    assert episode.actions.shape == (len(episode), 14)
    rows = episode_metadata(dataset)
    assert [r["seed"] for r in rows] == [42, 43]
    assert rows[0]["object_id"] == "ladder-1000002"
    assert rows[0]["success"] is True or rows[0]["success"] == np.True_
    for index in range(2):
        report = replay_lift_demo(dataset, index)
        assert report.identical, report.format()
        assert report.replayed == report.steps


def test_a_changed_action_is_caught(root: Path) -> None:
    dataset = open_lift_demos(root / "dg16m" / "lift-expert-v0")
    import gymnasium as gym

    episode = next(iter(dataset.storage.get_episodes([0])))
    env = dataset.recover_environment()
    obs, _ = env.reset(seed=42)
    assert np.array_equal(obs, episode["observations"][0])
    actions = np.array(episode["actions"])
    actions[5] = -actions[5]
    for t, action in enumerate(actions[:10]):
        obs, *_ = env.step(action)
        if t >= 5:
            assert not np.array_equal(obs, episode["observations"][t + 1])
    env.close()
    assert isinstance(env, gym.Env)


def test_an_existing_dataset_is_not_overwritten(root: Path) -> None:
    before = sorted(p.stat().st_mtime_ns for p in (root / "dg16m").rglob("*") if p.is_file())
    with pytest.raises(LiftDemosError):
        collect_lift_demos(root, episodes=1, objects="all", seed=0, progress=False)
    after = sorted(p.stat().st_mtime_ns for p in (root / "dg16m").rglob("*") if p.is_file())
    assert before == after
