"""``dg16m evaluate --objects / --limit``: score a few of the benchmark's objects, marked partial
everywhere, and never ranked by the leaderboard."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dg16m_core.cli import main
from dg16m_env.benchmark.model import BenchmarkError
from dg16m_env.benchmark.names import REAL_BENCHMARK
from dg16m_env.evaluators import load_benchmark_ref, make, read_results
from dg16m_env.subjects.submission import Submission
from dg16m_env.subjects.submission_reader import read_submission
from dg16m_env.subjects.submission_writer import PartialSubmissionWarning, write_submission

OBJECTS = ["table-1000000", "crate-1000006"]

PREDICTOR = '''
import numpy as np

def predict(observation):
    """One dual grasp 5 m away (it misses)."""
    poses = np.tile(np.eye(4), (1, 2, 1, 1))
    poses[:, 0, 0, 3] = 5.0
    poses[:, 1, 0, 3] = -5.0
    return poses
'''


@pytest.fixture(scope="module")
def ref():
    return load_benchmark_ref()


def _rows(ref, ids: list[str], path: Path) -> Path:
    """A submission of the benchmark's first 2 rows of each of ``ids`` (the shipped one)."""
    bench = ref.benchmark
    poses = {i: bench.poses[bench.object_rows(i)[:2]] for i in ids}
    return write_submission(path, poses, benchmark="embedded")


@pytest.fixture(scope="module")
def two(ref, tmp_path_factory) -> Path:
    with pytest.warns(
        PartialSubmissionWarning, match="expected dual grasps for all"
    ):  # a partial file for the shipped benchmark: said so
        return _rows(ref, OBJECTS, tmp_path_factory.mktemp("sub") / "two.h5")


def test_subset_keeps_the_file_and_records_that_it_is_partial(ref):
    sub = ref.subset(list(reversed(OBJECTS)))
    assert sub.object_ids == OBJECTS  # the benchmark's order
    assert sub.sha256 == ref.sha256
    assert sub.partial
    assert not ref.partial
    record = sub.record()
    assert record["partial"] is True
    assert record["subset"] == OBJECTS
    assert record["of"] == len(ref.object_ids)
    assert record["objects"] == 2
    assert "partial" not in ref.record()
    assert ref.subset(ref.object_ids) is ref  # every object: the whole benchmark
    assert ref.first(3).object_ids == ref.object_ids[:3]


def test_unknown_repeated_and_empty_ids_are_refused(ref):
    with pytest.raises(BenchmarkError, match=r"expected ids of the benchmark.*found unknown: nope"):
        ref.subset(["table-1000000", "nope"])
    with pytest.raises(BenchmarkError, match="expected distinct ids"):
        ref.subset(["table-1000000", "table-1000000"])
    with pytest.raises(BenchmarkError, match="at least one"):
        ref.subset([])
    with pytest.raises(BenchmarkError, match="limit: expected an integer >= 1"):
        ref.first(0)


def test_evaluate_a_few_objects_says_partial_everywhere(two, tmp_path, capsys):
    out = tmp_path / "r.json"
    argv = ["evaluate", str(two), "--objects", ",".join(OBJECTS), "--evaluators", "fce"]
    assert main([*argv, "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "partial run: 2 of the benchmark's 300 objects" in printed
    assert "PARTIAL" in printed
    data = json.loads(out.read_text())
    assert data["subject"]["partial"] is True
    assert data["subject"]["objects"] == {"subset": OBJECTS, "of": 300}
    result = read_results(out)["fce"]
    assert result.partial
    assert result.benchmark["subset"] == OBJECTS
    assert result.metrics["fce"]["objects"] == 2
    assert set(result.per_object) == set(OBJECTS)


def test_objects_from_a_file_and_unknown_ids(two, tmp_path, capsys):
    ids = tmp_path / "ids.txt"
    ids.write_text("# my objects\ntable-1000000\n\ncrate-1000006  # a crate\n")
    argv = ["evaluate", str(two), "--objects", str(ids), "--evaluators", "fce", "--no-progress"]
    assert main(argv) == 0
    assert "2 of the benchmark's 300" in capsys.readouterr().out
    assert main(["evaluate", str(two), "--objects", "table-1000000,nope", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "expected ids of the benchmark" in err
    assert "found unknown: nope" in err


def test_the_submission_must_hold_exactly_the_subset(ref, two, capsys):
    # the whole benchmark: 298 missing (as before)
    assert main(["evaluate", str(two), "--evaluators", "fce", "--no-progress"]) == 2
    assert "298 missing" in capsys.readouterr().err
    # one object of the subset: the other one is unknown there
    argv = ["evaluate", str(two), "--objects", OBJECTS[0], "--evaluators", "fce"]
    assert main([*argv, "--no-progress"]) == 2
    assert "crate-1000006" in capsys.readouterr().err
    # the first 2 objects of the benchmark are other objects
    assert main(["evaluate", str(two), "--limit", "2", "--no-progress"]) == 2
    assert ref.object_ids[1] in capsys.readouterr().err
    # validate takes the subset too
    assert main(["submission", "validate", str(two), "--objects", ",".join(OBJECTS)]) == 0
    assert "valid for the benchmark" in capsys.readouterr().out


def test_limit_scores_the_first_objects(ref, tmp_path, capsys):
    with pytest.warns(PartialSubmissionWarning, match="expected dual grasps for all"):
        first = _rows(ref, ref.object_ids[:2], tmp_path / "first.h5")
    out = tmp_path / "r.json"
    argv = ["evaluate", str(first), "--limit", "2", "--evaluators", "fce", "--out", str(out)]
    assert main([*argv, "--no-progress"]) == 0
    assert read_results(out)["fce"].benchmark["subset"] == ref.object_ids[:2]


def test_a_predictor_runs_only_on_the_subset(tmp_path, capsys, recwarn):
    module = tmp_path / "far.py"
    module.write_text(PREDICTOR)
    kept = tmp_path / "far.h5"
    argv = ["evaluate", "--predictor", f"{module}:predict", "--limit", "1", "--evaluators", "fce"]
    argv += ["--save-submission", str(kept), "--time-limit", "20", "--no-progress"]
    assert main(argv) == 0
    assert "fce                    0.0%" in capsys.readouterr().out
    sub = read_submission(kept)
    assert list(sub.poses) == [load_benchmark_ref().object_ids[0]]
    assert sub.metadata["objects"]["of"] == 300
    assert not [w for w in recwarn if "expected dual grasps for all" in str(w.message)]


def test_the_leaderboard_refuses_a_partial_result(ref, tmp_path):
    from leaderboard.board import Board, BoardError
    from leaderboard.queue import NewSubmission

    sub = ref.subset(OBJECTS)
    bench = sub.benchmark
    poses = {i: bench.poses[bench.object_rows(i)[:1]] for i in OBJECTS}
    submission = Submission(
        poses=poses, scores={}, benchmark="embedded", metadata={}, sha256="0" * 64
    )
    result = make("fce", benchmark=sub).evaluate(submission)
    assert result.partial
    board = Board(tmp_path / "board.db")
    team, _ = board.add_team("lab")
    new = NewSubmission(team.id, team.name, "1" * 64, 1, "a.h5", "a", ["fce"])
    sid = board.jobs.enqueue(new)
    claim = board.claim("w", 60.0, submission_id=sid)
    with pytest.raises(BoardError, match="never ranks partial results"):
        board.finish(claim, {"fce": result}, "log")
    assert board.submission_row(sid)["status"] == "running"  # nothing stored
    assert not board.scored()


def test_one_object_note():
    from baselines.reproduce import one_object_note

    assert "rests on one object" in one_object_note(1)
    assert one_object_note(2) is None


@pytest.mark.skipif(not REAL_BENCHMARK.is_file(), reason="the real benchmark is not shipped here")
def test_reproduce_limit_is_per_category_on_the_real_benchmark(tmp_path):
    from baselines.reproduce import limited_benchmark

    ref = limited_benchmark(tmp_path, 1, "real")
    categories = ref.categories()
    assert len(categories) == len(set(categories)) > 1  # one object of each category
    assert all(categories)
    assert np.all([o.family == "" for o in ref.benchmark.objects])
