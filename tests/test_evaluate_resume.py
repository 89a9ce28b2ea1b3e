"""``dg16m evaluate --out``: each evaluator's result is written as it finishes (an interrupt keeps
the finished ones), and ``--resume`` skips the evaluators already done for the same run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dg16m_core.cli import main
from dg16m_env.evaluators import gsr, load_benchmark_ref, read_results
from dg16m_env.subjects.submission_writer import PartialSubmissionWarning, write_submission

OBJECTS = ["table-1000000", "crate-1000006"]
FAST = ["--objects", ",".join(OBJECTS), "--perturbations", "1", "--no-progress"]

PREDICTOR = """
import numpy as np

def predict(observation):
    poses = np.tile(np.eye(4), (1, 2, 1, 1))
    poses[:, 0, 0, 3] = 5.0
    poses[:, 1, 0, 3] = -5.0
    return poses
"""


@pytest.fixture(scope="module")
def two(tmp_path_factory) -> Path:
    bench = load_benchmark_ref().benchmark
    poses = {i: bench.poses[bench.object_rows(i)[:2]] for i in OBJECTS}
    path = tmp_path_factory.mktemp("sub") / "two.h5"
    with pytest.warns(PartialSubmissionWarning, match="expected dual grasps for all"):
        return write_submission(path, poses, benchmark="embedded")


def _interrupt_gsr(monkeypatch) -> None:
    def interrupted(self, subject, **options):
        raise KeyboardInterrupt

    monkeypatch.setattr(gsr.GraspSuccessRate, "evaluate", interrupted)


def test_an_interrupt_keeps_finished_results_and_resume_skips_them(
    two, tmp_path, capsys, monkeypatch
):
    out = tmp_path / "r.json"
    argv = ["evaluate", str(two), "--evaluators", "fce,gsr", "--out", str(out), *FAST]
    with monkeypatch.context() as patch:
        _interrupt_gsr(patch)
        assert main(argv) == 130
    err = capsys.readouterr().err
    assert "kept fce" in err
    assert "--resume" in err
    kept = read_results(out)
    assert list(kept) == ["fce"]
    assert main([*argv, "--resume"]) == 0
    printed = capsys.readouterr().out
    assert "fce: kept from" in printed
    done = read_results(out)
    assert list(done) == ["fce", "gsr"]
    assert done["fce"].to_dict() == kept["fce"].to_dict()
    assert done["gsr"].parameters["perturbation"]["n_perturbations"] == 1
    # everything done: a second resume scores nothing and gives the same file
    before = out.read_bytes()
    assert main([*argv, "--resume"]) == 0
    assert "gsr: kept from" in capsys.readouterr().out
    assert out.read_bytes() == before


def test_resume_refuses_results_of_another_run(two, tmp_path, capsys):
    out = tmp_path / "r.json"
    argv = ["evaluate", str(two), "--evaluators", "fce", "--out", str(out), *FAST]
    assert main(argv) == 0
    capsys.readouterr()
    assert main([*argv, "--resume", "--seed", "1"]) == 2
    err = capsys.readouterr().err
    assert "expected" in err
    assert "another seeds" in err
    # another subset of objects: another benchmark record
    other = ["evaluate", str(two), "--evaluators", "fce", "--out", str(out), "--resume"]
    assert main([*other, "--objects", OBJECTS[0], "--no-progress"]) == 2


def test_resume_needs_out(two, tmp_path, capsys):
    assert main(["evaluate", str(two), "--resume", *FAST]) == 2
    assert "expected --out" in capsys.readouterr().err


def test_resume_of_a_missing_file_runs_everything(two, tmp_path, capsys):
    out = tmp_path / "new.json"
    argv = ["evaluate", str(two), "--evaluators", "fce", "--out", str(out), "--resume", *FAST]
    assert main(argv) == 0
    assert "no finished evaluators" in capsys.readouterr().out
    assert list(read_results(out)) == ["fce"]


def test_a_predictor_run_resumes_with_its_submission(tmp_path, capsys, monkeypatch):
    module = tmp_path / "far.py"
    module.write_text(PREDICTOR)
    out = tmp_path / "p.json"
    argv = ["evaluate", "--predictor", f"{module}:predict", "--evaluators", "fce,gsr"]
    argv += ["--out", str(out), "--time-limit", "20", *FAST]
    with monkeypatch.context() as patch:
        _interrupt_gsr(patch)
        assert main(argv) == 130
    subject = json.loads(out.read_text())["subject"]
    assert Path(subject["file"]).is_file()
    capsys.readouterr()
    assert main([*argv, "--resume"]) == 0
    printed = capsys.readouterr().out
    assert "reusing the predictor's submission" in printed
    assert "fce: kept from" in printed
    assert list(read_results(out)) == ["fce", "gsr"]
