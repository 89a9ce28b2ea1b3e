"""Lift demonstrations in Minari format (:mod:`dg16m_env.envs.lift.demos`, ``dg16m demos``):
a dataset written and found by ``minari.load_dataset`` under ``MINARI_DATASETS_PATH``, with its
spaces and metadata; replays identical, a tampered action found; no overwrite without force; the
same bytes for 1 and 2 workers; the command line. Tiny datasets (2-3 episodes, short ones
where success does not matter), a few seconds each."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

minari = pytest.importorskip("minari", reason="minari is not installed: pip install -e '.[demos]'")
pytest.importorskip("mujoco", reason="MuJoCo is not installed: pip install -e '.[sim]'")
h5py = pytest.importorskip("h5py")

from dg16m_core.cli import main  # noqa: E402
from dg16m_env.envs.lift.demo_files import (  # noqa: E402
    DEFAULT_DATASET_ID,
    ENV_ID,
    ENV_IDS,
    METADATA_KEY,
    LiftDemosError,
    demos_metadata,
    episode_metadata,
    open_lift_demos,
    replay_lift_demo,
    summarize_lift_demos,
)
from dg16m_env.envs.lift.demos import collect_lift_demos, select_objects  # noqa: E402
from dg16m_env.envs.lift.observations import STATE_LAYOUT, STATE_SIZE  # noqa: E402
from dg16m_env.envs.lift.spaces import ACTION_SIZE  # noqa: E402
from dg16m_env.envs.objects import split_objects  # noqa: E402

SHORT = {"episode_steps": 25}
"""Episodes cut at 25 steps (no success): enough to compare bytes."""


@pytest.fixture(scope="module")
def demos(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two full-length episodes from seed 0 (the expert lifts both: a success and its
    termination on record), written under a Minari root; returns the root."""
    root = tmp_path_factory.mktemp("minari")
    collect_lift_demos(root, episodes=2, seed=0, progress=False)
    return root


def test_split_objects_lives_in_the_env_layer_and_the_baselines_reexport_it() -> None:
    from baselines import sb3_common

    ids = [f"o{i}" for i in range(10)]
    train, held_out = split_objects(ids)
    assert held_out == ["o0", "o3", "o6", "o9"]
    assert train == ["o1", "o2", "o4", "o5", "o7", "o8"]
    assert sb3_common.split_objects is split_objects
    assert select_objects(ids, "train") == train
    assert select_objects(ids, "held-out") == held_out
    assert select_objects(ids, "all") == ids
    assert select_objects(ids, "o2, o5") == ["o2", "o5"]
    with pytest.raises(LiftDemosError, match=r"expected one of .* found \[.nope.\]"):
        select_objects(ids, "o2,nope")


def test_a_dataset_loads_by_id_with_its_spaces_and_metadata(
    demos: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(demos))
    assert DEFAULT_DATASET_ID in minari.list_local_datasets()
    dataset = minari.load_dataset(DEFAULT_DATASET_ID)
    assert dataset.total_episodes == 2
    assert dataset.observation_space.shape == (STATE_SIZE,)
    assert dataset.action_space.shape == (ACTION_SIZE,)
    assert dataset.spec.env_spec.id == ENV_ID
    for episode in dataset.iterate_episodes():
        steps = len(episode)
        assert episode.observations.shape == (steps + 1, STATE_SIZE)
        assert episode.observations.dtype == np.float32
        assert episode.actions.shape == (steps, ACTION_SIZE)
        assert np.all(np.abs(episode.actions) <= 1.0)
        assert episode.terminations[-1] or episode.truncations[-1]
        assert episode.infos["success"].shape == (steps + 1,)

    rows = episode_metadata(dataset)
    assert [r["seed"] for r in rows] == [0, 1]
    for row, episode in zip(rows, dataset.iterate_episodes(), strict=True):
        assert row["expert"] == "FeedbackLiftExpert"
        assert row["steps"] == len(episode)
        assert row["success"] is bool(episode.infos["success"][-1])
        assert row["return"] == pytest.approx(float(episode.rewards.sum()))
    assert any(r["success"] and r["termination"] == "success" for r in rows)

    ours = dataset.storage.metadata[METADATA_KEY]
    assert ours == demos_metadata(dataset)
    assert ours["env_id"] == ENV_ID
    assert ours["obs_mode"] == "state"
    assert ours["benchmark"] == "procedural"
    assert ours["seeds"]["first"] == 0
    assert ours["seeds"]["last"] == 1
    assert ours["expert"]["name"] == "FeedbackLiftExpert"
    assert ours["env_kwargs"]["object_ids"] == split_objects(_procedural_ids())[0]
    assert {r["object_id"] for r in rows} <= set(ours["env_kwargs"]["object_ids"])
    assert ours["episodes"] == 2
    assert ours["successes"] == sum(r["success"] for r in rows)
    assert ours["package_version"]
    assert ours["mujoco_version"]

    summary = summarize_lift_demos(dataset)
    assert summary["episodes"] == 2
    assert summary["successes"] == ours["successes"]
    assert summary["steps"]["total"] == dataset.total_steps
    env = dataset.recover_environment()  # Minari alone remakes the env
    try:
        assert env.unwrapped.objects.object_ids == ours["env_kwargs"]["object_ids"]
    finally:
        env.close()


def _procedural_ids() -> list[str]:
    from dg16m_env.benchmark.ref import load_benchmark_ref

    return list(load_benchmark_ref("procedural", lazy=True).object_ids)


def test_replay_is_identical_and_finds_a_tampered_action(demos: Path, tmp_path: Path) -> None:
    dataset = open_lift_demos(demos / DEFAULT_DATASET_ID)
    for index in range(dataset.total_episodes):
        report = replay_lift_demo(dataset, index)
        assert report.identical, report.format()
        assert report.first_mismatch is None
        assert report.replayed == report.steps == len(dataset[index])
        assert "identical" in report.format()

    copy = tmp_path / "copy"
    shutil.copytree(demos / DEFAULT_DATASET_ID, copy)
    with h5py.File(copy / "data" / "main_data.hdf5", "r+") as file:
        actions = file["episode_1/actions"]
        actions[7] = np.clip(actions[7] + 0.5, -1.0, 1.0)
    tampered = open_lift_demos(copy)
    report = replay_lift_demo(tampered, 1)
    assert not report.identical
    assert report.first_mismatch == 8  # the observation after the changed action
    assert report.what.startswith("observation")
    assert "MISMATCH at step 8" in report.format()
    assert replay_lift_demo(tampered, 0).identical
    with pytest.raises(LiftDemosError, match=r"expected an index in \[0, 2\), found 2"):
        replay_lift_demo(tampered, 2)


def test_an_existing_dataset_is_kept_unless_forced(tmp_path: Path) -> None:
    first = collect_lift_demos(tmp_path, episodes=2, env_kwargs=SHORT, progress=False)
    before = (first.path / "data" / "main_data.hdf5").read_bytes()
    with pytest.raises(LiftDemosError, match=r"expected no dataset there .* found one"):
        collect_lift_demos(tmp_path, episodes=2, seed=7, env_kwargs=SHORT, progress=False)
    assert (first.path / "data" / "main_data.hdf5").read_bytes() == before

    again = collect_lift_demos(
        tmp_path, episodes=3, seed=7, env_kwargs=SHORT, force=True, progress=False
    )
    assert again.path == first.path
    dataset = open_lift_demos(again.path)
    assert [r["seed"] for r in episode_metadata(dataset)] == [7, 8, 9]
    # nothing left beside it: no temporary folder, no replaced copy
    assert sorted(p.name for p in first.path.parent.iterdir()) == [
        "lift-expert-v0",
        "namespace_metadata.json",
    ]


def test_the_worker_count_does_not_change_the_data(tmp_path: Path) -> None:
    kwargs = {"episodes": 3, "seed": 11, "obs_mode": "state_dict", "env_kwargs": SHORT}
    one = collect_lift_demos(tmp_path / "one", workers=1, progress=False, **kwargs)
    two = collect_lift_demos(tmp_path / "two", workers=2, progress=False, **kwargs)
    a, b = open_lift_demos(one.path), open_lift_demos(two.path)
    assert set(a.observation_space.spaces) == {name for name, _, _, _ in STATE_LAYOUT}
    for x, y in zip(a.iterate_episodes(), b.iterate_episodes(), strict=True):
        assert len(x) == len(y) == SHORT["episode_steps"]
        for name in x.observations:
            assert x.observations[name].tobytes() == y.observations[name].tobytes(), name
        assert x.actions.tobytes() == y.actions.tobytes()
        assert x.rewards.tobytes() == y.rewards.tobytes()
    assert episode_metadata(a) == episode_metadata(b)
    assert replay_lift_demo(b, 2).identical  # dictionary observations replay too


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"dataset_id": "dg16m/lift-expert"}, "expected \\(namespace/\\)name-vN"),
        ({"obs_mode": "pointcloud"}, "obs_mode: expected one of"),
        ({"objects": "tarin"}, "objects: expected one of"),
        ({"env_kwargs": {"obs_mode": "state"}}, "env_kwargs: expected none of"),
        ({"workers": 0}, "workers: expected an integer >= 1"),
        ({"env_id": "dg16m_env/DualGraspLift-v0"}, "env_id: expected one of"),
        (
            {"expert": "oracle"},
            "expert: expected one of \\('feedback', 'recovering'\\), found 'oracle'",
        ),
    ],
)
def test_bad_arguments_are_refused(tmp_path: Path, kwargs: dict, message: str) -> None:
    with pytest.raises(LiftDemosError, match=message):
        collect_lift_demos(tmp_path, episodes=1, progress=False, **kwargs)
    assert not (tmp_path / DEFAULT_DATASET_ID).exists()


def test_a_relative_root_takes_more_than_one_batch(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 56: ``dg16m demos collect --out runs/demos`` (a relative root, as the docs give it)
    failed when the second batch of episodes was added; one episode per batch here."""
    import dg16m_env.envs.lift.demos as demos_module

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(demos_module, "FLUSH_EPISODES", 1)
    collect_lift_demos(Path("runs/demos"), episodes=2, progress=False, env_kwargs=SHORT)
    data = open_lift_demos(tmp_path / "runs" / "demos" / DEFAULT_DATASET_ID)
    assert data.total_episodes == 2


def test_v1_demonstrations_are_collected_and_replayed_on_v1(tmp_path: Path) -> None:
    """``env_id`` picks the version; the dataset records it and a replay remakes that env."""
    report = collect_lift_demos(
        tmp_path, episodes=2, env_id=ENV_IDS[0], env_kwargs=SHORT, progress=False
    )
    dataset = open_lift_demos(report.path)
    assert dataset.spec.env_spec.id == ENV_IDS[0] == "dg16m_env/DualGraspLift-v1"
    assert demos_metadata(dataset)["env_id"] == ENV_IDS[0]
    assert replay_lift_demo(dataset, 1).identical
    assert ENV_ID == ENV_IDS[1] == "dg16m_env/DualGraspLift-v2"
    assert ENV_IDS[-1] == "dg16m_env/DualGraspLift-v3"


def test_recovering_expert_demonstrations_record_their_expert_and_replay(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--expert recovering`` collects with RecoveringLiftExpert (issue 57): the dataset names
    it, its episodes replay identically, and bc_lift labels DAgger states with it."""
    from baselines.bc_lift import demonstrations_expert
    from dg16m_env.envs.lift.demo_files import DEMO_EXPERTS, DEMO_OBS_MODES
    from dg16m_env.envs.lift.expert_registry import LIFT_EXPERTS, make_lift_expert
    from dg16m_env.envs.lift.recovering_expert import RecoveringLiftExpert

    stored = tuple(name for name, cls in LIFT_EXPERTS.items() if cls.OBS_MODE in DEMO_OBS_MODES)
    assert stored == DEMO_EXPERTS
    out = tmp_path / "root"
    args = ["--out", str(out), "--episode-steps", "30", "--no-progress", "--expert", "recovering"]
    assert main(["demos", "collect", "--episodes", "2", *args]) == 0
    capsys.readouterr()
    dataset = open_lift_demos(out / DEFAULT_DATASET_ID)
    assert demos_metadata(dataset)["expert"]["name"] == "RecoveringLiftExpert"
    assert {row["expert"] for row in episode_metadata(dataset)} == {"RecoveringLiftExpert"}
    assert replay_lift_demo(dataset, 1).identical
    name = demonstrations_expert(str(out / DEFAULT_DATASET_ID))
    assert isinstance(make_lift_expert(name), RecoveringLiftExpert)
    with pytest.raises(ValueError, match=r"expected one of .* found 'Oracle'"):
        make_lift_expert("Oracle")


def test_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "root"
    common = ["--out", str(out), "--episode-steps", "20", "--no-progress"]
    assert main(["demos", "collect", "--episodes", "2", *common]) == 0
    assert "2 episodes, 40 steps" in capsys.readouterr().out
    assert main(["demos", "collect", "--episodes", "2", *common]) == 2
    assert "expected no dataset there" in capsys.readouterr().err

    folder = str(out / DEFAULT_DATASET_ID)
    assert main(["demos", "info", folder]) == 0
    text = capsys.readouterr().out
    assert "episodes    2, 40 steps" in text
    assert "on dg16m_env/DualGraspLift-v2" in text  # the default env
    assert "Wilson 95%" in text

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(out))
    assert main(["demos", "replay", DEFAULT_DATASET_ID, "--all"]) == 0
    assert "replayed 2 episodes: identical" in capsys.readouterr().out
    assert main(["demos", "replay", folder, "--episodes", "0,5"]) == 2
    assert "expected indices in [0, 2), found [5]" in capsys.readouterr().err

    with h5py.File(out / DEFAULT_DATASET_ID / "data" / "main_data.hdf5", "r+") as file:
        file["episode_0/rewards"][3] += 1.0
    assert main(["demos", "replay", folder]) == 1
    assert "MISMATCH at step 4: reward" in capsys.readouterr().out


def test_the_installed_command_shows_its_help() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "dg16m_core.cli", "demos", "collect", "--help"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert "--episodes N" in done.stdout
    assert "dg16m demos collect --episodes 500" in done.stdout
