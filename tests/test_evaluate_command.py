"""``dg16m evaluate`` and ``dg16m submission``: the evaluators on the command line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dg16m_core.cli import main
from dg16m_core.hashing import file_sha256
from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.evaluators import load_benchmark_ref, read_results
from dg16m_env.subjects.submission_reader import read_submission
from dg16m_env.subjects.submission_writer import write_submission

OBJECTS = ["table-1000000", "crate-1000006"]

PREDICTOR = '''
import numpy as np

def predict(observation):
    """Two dual grasps: the benchmark's rows are not visible here, so take hands 5 m away
    (they miss) for one object and raise for the other."""
    if observation["object_id"].startswith("crate"):
        raise ValueError("no grasp for crates")
    poses = np.tile(np.eye(4), (2, 2, 1, 1))
    poses[:, 0, 0, 3] = 5.0
    poses[:, 1, 0, 3] = -5.0
    return poses, np.array([1.0, 0.0])
'''

CLASSIFIER = '''
import numpy as np

def score(observation, poses):
    """Hands closer together score higher."""
    return -np.linalg.norm(poses[:, 0, :3, 3] - poses[:, 1, :3, 3], axis=1)
'''


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("bench") / "small.h5"
    write_benchmark(path, read_benchmark(EMBEDDED_BENCHMARK).select_objects(OBJECTS))
    return path


@pytest.fixture(scope="module")
def first_rows(small, tmp_path_factory) -> Path:
    ref = load_benchmark_ref(small)
    bench = ref.benchmark
    path = tmp_path_factory.mktemp("sub") / "first.h5"
    poses = {i: bench.poses[bench.object_rows(i)[:3]] for i in ref.object_ids}
    return write_submission(path, poses, benchmark=ref.sha256)


def test_list_names_every_builtin(capsys):
    assert main(["evaluate", "--list"]) == 0
    out = capsys.readouterr().out
    for name in ("fce", "gsr", "classifier", "policy"):
        assert name in out


def test_validate_a_good_and_a_bad_file(small, first_rows, capsys):
    assert main(["submission", "validate", str(first_rows), "--benchmark", str(small)]) == 0
    assert "valid for the benchmark" in capsys.readouterr().out
    # Against the shipped benchmark: another sha256 and 298 missing objects, both listed.
    assert main(["submission", "validate", str(first_rows)]) == 1
    out = capsys.readouterr().out
    assert "2 problems" in out
    assert "made for another benchmark" in out
    assert "298 missing" in out


def test_evaluate_writes_results_that_read_back(small, first_rows, tmp_path, capsys):
    out = tmp_path / "results.json"
    argv = ["evaluate", str(first_rows), "--benchmark", str(small), "--out", str(out)]
    assert main([*argv, "--perturbations", "1", "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "fce v1" in printed
    assert "gsr v1" in printed
    results = read_results(out)
    assert set(results) == {"fce", "gsr"}
    assert results["fce"].score == 1.0
    assert results["gsr"].parameters["perturbation"]["n_perturbations"] == 1
    assert results["gsr"].subject["sha256"] == file_sha256(first_rows)
    assert json.loads(out.read_text())["subject"]["kind"] == "submission"


def test_an_invalid_submission_is_refused_before_scoring_and_nothing_is_written(
    small, tmp_path, capsys
):
    ref = load_benchmark_ref(small)
    poses = {i: np.tile(np.eye(4), (1, 2, 1, 1)) for i in ref.object_ids}
    poses[OBJECTS[0]][0, 1, 0, 0] = 2.0  # a scaled rotation
    bad = write_submission(tmp_path / "bad.h5", poses, benchmark=ref.sha256)
    out = tmp_path / "results.json"
    out.write_text("previous results")
    code = main(["evaluate", str(bad), "--benchmark", str(small), "--out", str(out)])
    assert code == 2
    err = capsys.readouterr().err
    assert f"objects/{OBJECTS[0]}/poses[0, 1]" in err
    assert out.read_text() == "previous results"


def test_evaluate_needs_exactly_one_subject(small, first_rows, capsys):
    assert main(["evaluate", "--benchmark", str(small)]) == 2
    assert "expected one subject" in capsys.readouterr().err
    argv = ["evaluate", str(first_rows), "--classifier", "x.py:f", "--benchmark", str(small)]
    assert main(argv) == 2
    assert "found 2 (submission, classifier)" in capsys.readouterr().err
    assert main(["evaluate", "--policy", "x.py:f"]) == 2
    assert "expected --env-id" in capsys.readouterr().err
    argv = [str(first_rows), "--benchmark", str(small), "--evaluators", "classifier"]
    assert main(["evaluate", *argv]) == 2
    assert "expected evaluators of submissions" in capsys.readouterr().err


def test_evaluate_a_predictor_counts_its_failures_as_zero(small, tmp_path, capsys):
    module = tmp_path / "my_predictor.py"
    module.write_text(PREDICTOR)
    kept = tmp_path / "predicted.h5"
    argv = ["evaluate", "--predictor", f"{module}:predict", "--benchmark", str(small)]
    argv += ["--evaluators", "fce", "--save-submission", str(kept), "--time-limit", "20"]
    assert main([*argv, "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "failed on 1 objects" in out
    assert "ValueError: no grasp for crates" in out
    assert "fce                    0.0%" in out
    sub = read_submission(kept, object_ids=OBJECTS, benchmark_sha256=file_sha256(small))
    assert list(sub.metadata["failed_objects"]) == ["crate-1000006"]
    assert sub.poses["table-1000000"].shape == (2, 2, 4, 4)


def test_a_predictors_submission_goes_beside_its_results(small, tmp_path, capsys):
    """Without --save-submission the produced file is named after --out, so two evaluations
    with different --out (e.g. run side by side) never write the same submission file."""
    module = tmp_path / "my_predictor.py"
    module.write_text(PREDICTOR)
    out = tmp_path / "res" / "mine.json"
    out.parent.mkdir()
    argv = ["evaluate", "--predictor", f"{module}:predict", "--benchmark", str(small)]
    argv += ["--evaluators", "fce", "--out", str(out), "--time-limit", "20", "--no-progress"]
    assert main(argv) == 0
    kept = tmp_path / "res" / "mine.submission.h5"
    assert f"wrote {kept}" in capsys.readouterr().out
    sub = read_submission(kept, object_ids=OBJECTS, benchmark_sha256=file_sha256(small))
    assert sub.poses["table-1000000"].shape == (2, 2, 4, 4)
    assert read_results(out)["fce"].score == 0.0


def test_evaluate_a_classifier_from_a_file(small, tmp_path, capsys):
    module = tmp_path / "my_classifier.py"
    module.write_text(CLASSIFIER)
    argv = ["evaluate", "--classifier", f"{module}:score", "--benchmark", str(small)]
    out = tmp_path / "c.json"
    assert main([*argv, "--k", "5", "--out", str(out), "--no-progress"]) == 0
    result = read_results(out)["classifier"]
    assert result.parameters["k"] == 5
    assert 0.0 <= result.score <= 1.0
    assert "gsr_top5_full" in capsys.readouterr().out


def test_submission_make_from_missing_dg16m_files_names_the_object(small, tmp_path, capsys):
    (tmp_path / "grasps").mkdir()
    argv = ["submission", "make", "--from-dg16m", str(tmp_path / "grasps")]
    argv += ["--out", str(tmp_path / "s.h5"), "--benchmark", str(small)]
    assert main(argv) == 2
    assert "table-1000000" in capsys.readouterr().err
    assert not (tmp_path / "s.h5").exists()
