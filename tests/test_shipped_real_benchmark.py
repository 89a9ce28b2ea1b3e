"""The shipped real-object benchmark (``dg16m_env/data/benchmark_real.h5``): what the file holds
(the split's 300 objects, each with its mesh, hash and hulls; the attribution), and that every
place a benchmark is taken accepts it by its short name ``"real"``.

Skipped where the package does not ship the file (a checkout before it was built).
"""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env

import dg16m_env  # noqa: F401  (registers the environments)
from dg16m_core.cli import main as cli_main
from dg16m_core.hashing import file_sha256
from dg16m_env.benchmark.file import read_benchmark
from dg16m_env.benchmark.model import SOURCES, Benchmark
from dg16m_env.benchmark.names import REAL_BENCHMARK, benchmark_file
from dg16m_env.benchmark.real import REAL_ATTRIBUTION, REAL_LIMITS, REAL_SPLIT_FILE
from dg16m_env.envs.dual_grasp_pose import DualGraspPoseEnv
from dg16m_env.envs.spaces import action_from_poses
from dg16m_env.evaluators import load_benchmark_ref, make
from dg16m_env.subjects.submission_writer import write_submission

pytestmark = pytest.mark.skipif(
    not REAL_BENCHMARK.is_file(), reason=f"the real benchmark is not shipped ({REAL_BENCHMARK})"
)

ARMS = ("fc_pass", "fc_fail", "random", "farthest", "fc_robust")


@pytest.fixture(scope="module")
def bench() -> Benchmark:
    return read_benchmark(REAL_BENCHMARK)  # checks every carried mesh against its sha256


@pytest.fixture(scope="module")
def split() -> dict:
    return json.loads(REAL_SPLIT_FILE.read_text(encoding="utf-8"))


def test_the_file_holds_the_splits_300_objects_with_meshes_and_hulls(
    bench: Benchmark, split: dict
) -> None:
    ids = [o.object_id for o in bench.objects]
    assert len(ids) == 300 == len(set(ids))
    assert set(ids) == set(split["benchmark"])
    assert not set(ids) & set(split["train"])
    for obj in bench.objects:
        assert obj.has_mesh, obj.object_id
        assert len(obj.mesh_sha256) == 64, obj.object_id  # of the arrays; read_benchmark checked it
        assert len(obj.parts) > 0, obj.object_id
        assert obj.family == "", obj.object_id  # a mesh object, not a procedural one


def test_every_object_gives_its_passing_pairs_and_the_arms_are_the_papers(
    bench: Benchmark,
) -> None:
    names = [SOURCES[int(s)] for s in bench.source]
    assert set(names) == set(ARMS)
    per_object = np.bincount(
        bench.object_index[np.array(names) == "fc_pass"], minlength=len(bench.objects)
    )
    # the admission rule: 40 force-closure-passing pairs per object (REAL_LIMITS.min_passing)
    assert per_object.min() >= REAL_LIMITS.min_passing
    valid = bench.trials.valid
    for arm in ARMS:  # nominal invalid trials: the target is at most 2% per arm
        rows = np.array(names) == arm
        assert 1.0 - valid[rows].mean() <= 0.02, arm


def test_attribution_names_every_object_with_its_licence(bench: Benchmark) -> None:
    text = REAL_ATTRIBUTION.read_text(encoding="utf-8")
    assert "CC-BY-3.0" in text or "CC BY 3.0" in text
    for obj in bench.objects:
        assert obj.object_id in text, obj.object_id
    assert "modified" in text.lower()


def test_the_short_name_reaches_the_file_everywhere(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert benchmark_file("real") == REAL_BENCHMARK
    ref = load_benchmark_ref("real")
    assert ref.path == REAL_BENCHMARK
    assert ref.sha256 == file_sha256(REAL_BENCHMARK)
    assert not ref.embedded
    assert cli_main(["benchmark", "info", "real"]) == 0
    assert "300 objects" in capsys.readouterr().out
    db = tmp_path / "board.sqlite"
    code = cli_main(["leaderboard", "init", "--db", str(db), "--benchmark", "real"])
    assert code == 0
    assert ref.sha256 in capsys.readouterr().out + db.read_bytes().decode("latin-1")


def test_fce_on_a_submission_of_stored_rows(bench: Benchmark, tmp_path: Path) -> None:
    """Up to two stored fc_pass and two fc_fail rows of every object, submitted against
    ``"real"``: ``fce`` gives each object the share of its rows the build stored as passing."""
    ref = load_benchmark_ref("real")
    names = np.array([SOURCES[int(s)] for s in bench.source])
    picked = {}
    for obj in bench.objects:
        rows = bench.object_rows(obj.object_id)
        picked[obj.object_id] = np.concatenate(
            [rows[names[rows] == "fc_pass"][:2], rows[names[rows] == "fc_fail"][:2]]
        )
    poses = {i: bench.poses[rows] for i, rows in picked.items()}
    path = write_submission(tmp_path / "sub.h5", poses, benchmark=ref.sha256)
    result = make("fce", benchmark=ref, progress=False).evaluate(path)
    per_object = result.to_dict()["per_object"]
    for object_id, rows in picked.items():
        expected = float(np.mean(names[rows] == "fc_pass"))
        assert per_object[object_id]["fce"] == pytest.approx(expected), object_id


def test_an_env_on_the_real_benchmark_passes_the_checker_and_replays_stored_trials(
    bench: Benchmark,
) -> None:
    env = gym.make("dg16m_env/DualGraspSelect-v0", benchmark="real", reward_mode="label")
    try:
        gym_check_env(env.unwrapped)
    finally:
        env.close()
    # a stored fc_pass row whose 9 trials all agree, replayed unperturbed, gives its verdict
    pose_env = DualGraspPoseEnv(benchmark="real", perturb=False)
    p = bench.p("full")
    names = np.array([SOURCES[int(s)] for s in bench.source])
    rows = np.flatnonzero((names == "fc_pass") & ((p == 0.0) | (p == 1.0)))
    rows = np.concatenate([rows[p[rows] == 1.0][:2], rows[p[rows] == 0.0][:1]])
    assert len(rows) == 3
    try:
        for row in rows:
            object_id = bench.objects[int(bench.object_index[row])].object_id
            pose_env.reset(seed=0, options={"object_id": object_id})
            action = action_from_poses(bench.poses[row]).astype(np.float32)
            _, _, _, _, info = pose_env.step(action)
            assert info["success"] == bool(bench.trials.success[row]), (object_id, row)
    finally:
        pose_env.close()
