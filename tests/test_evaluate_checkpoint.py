"""``dg16m evaluate --out R.json``: gsr checkpoints each finished object beside the results
(``R.gsr.checkpoint/``); an interrupt (Ctrl-C or SIGTERM) keeps them and ``--resume`` simulates
only the rest, with the same bytes as an uninterrupted run. A checkpoint of another run is
refused. Also: inputs are checked before the partial-run banner, and ``--policy`` takes
``--objects``."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import numpy as np
import pytest
from checkpoint_stops import ctrl_c, sigterm, stop_after

from dg16m_core.cli import main
from dg16m_core.hashing import file_sha256
from dg16m_env.evaluators import load_benchmark_ref, read_results
from dg16m_env.evaluators.checkpoint import checkpoint_folder
from dg16m_env.physics import success_probabilities
from dg16m_env.subjects.submission_writer import PartialSubmissionWarning, write_submission

OBJECTS = ["table-1000000", "crate-1000006", "bench-1000012"]
FAST = ["--objects", ",".join(OBJECTS), "--perturbations", "1", "--no-progress"]


@pytest.fixture(scope="module")
def three(tmp_path_factory) -> Path:
    ref = load_benchmark_ref()
    objects = [i for i in OBJECTS if i in ref.object_ids]
    assert objects == OBJECTS, f"expected {OBJECTS} in the benchmark, found {objects}"
    bench = ref.benchmark
    poses = {i: bench.poses[bench.object_rows(i)[:2]] for i in OBJECTS}
    path = tmp_path_factory.mktemp("sub") / "three.h5"
    with pytest.warns(PartialSubmissionWarning, match="expected dual grasps for all"):
        return write_submission(path, poses, benchmark="embedded")


@pytest.fixture(scope="module")
def uninterrupted(three, tmp_path_factory) -> bytes:
    out = tmp_path_factory.mktemp("whole") / "r.json"
    assert main(["evaluate", str(three), "--evaluators", "fce,gsr", "--out", str(out), *FAST]) == 0
    assert not checkpoint_folder(out, "gsr").exists()  # removed once gsr completed
    return out.read_bytes()


def _count_simulated(patch) -> list[str]:
    simulated: list[str] = []
    task = success_probabilities._task

    def counted(job, *args):
        simulated.append(job.object_id)
        return task(job, *args)

    patch.setattr(success_probabilities, "_task", counted)
    return simulated


@pytest.mark.parametrize("stop", [ctrl_c, sigterm], ids=["ctrl-c", "sigterm"])
def test_an_interrupted_gsr_resumes_where_it_stopped_with_the_same_bytes(
    three, uninterrupted, tmp_path, capsys, monkeypatch, stop
):
    out = tmp_path / "r.json"
    folder = checkpoint_folder(out, "gsr")
    argv = ["evaluate", str(three), "--evaluators", "fce,gsr", "--out", str(out), *FAST]
    with monkeypatch.context() as patch:
        stop_after(patch, 1, stop)
        assert main(argv) == 130
    err = capsys.readouterr().err
    assert "interrupted during gsr" in err
    assert f"kept fce in {out}" in err
    assert f"kept 1 finished gsr objects in {folder}" in err
    assert "rerun with --resume" in err
    assert list(read_results(out)) == ["fce"]
    (kept,) = folder.glob("*.npz")
    kept_id = str(np.load(kept)["__object_id__"])
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # the handler was put back
    with monkeypatch.context() as patch:
        simulated = _count_simulated(patch)
        assert main([*argv, "--resume"]) == 0
    captured = capsys.readouterr()
    assert "gsr: resuming: 1 of 3 objects kept" in captured.err
    assert sorted(simulated) == sorted(set(OBJECTS) - {kept_id})  # only the ones not yet done
    assert not folder.exists()
    assert out.read_bytes() == uninterrupted
    # a checkpoint left by a stop between writing the result and removing it: removed
    folder.mkdir()
    assert main([*argv, "--resume"]) == 0
    assert not folder.exists()
    assert out.read_bytes() == uninterrupted


def test_the_library_call_checkpoints_and_removes_its_folder(three, tmp_path):
    from dg16m_env.evaluators import make
    from dg16m_env.evaluators.checkpoint import CheckpointRequest

    ref = load_benchmark_ref().subset(OBJECTS)
    ev = make("gsr", benchmark=ref, n_perturbations=1)
    folder = tmp_path / "c"
    with pytest.MonkeyPatch.context() as patch:
        stop_after(patch, 2, ctrl_c)
        with pytest.raises(KeyboardInterrupt):
            ev.evaluate(three, checkpoint=CheckpointRequest(folder))
    assert len(list(folder.glob("*.npz"))) == 2
    resumed = ev.evaluate(three, checkpoint=CheckpointRequest(folder, resume=True))
    assert not folder.exists()
    assert resumed.to_dict() == ev.evaluate(three).to_dict()


def test_without_resume_a_checkpoint_is_discarded(three, uninterrupted, tmp_path, capsys):
    out = tmp_path / "r.json"
    argv = ["evaluate", str(three), "--evaluators", "fce,gsr", "--out", str(out), *FAST]
    with pytest.MonkeyPatch.context() as patch:
        stop_after(patch, 2, ctrl_c)
        assert main(argv) == 130
    with pytest.MonkeyPatch.context() as patch:
        simulated = _count_simulated(patch)
        assert main(argv) == 0
    assert sorted(simulated) == sorted(OBJECTS)
    assert out.read_bytes() == uninterrupted


def test_a_checkpoint_of_another_run_is_refused(three, tmp_path, capsys):
    out = tmp_path / "r.json"
    argv = ["evaluate", str(three), "--evaluators", "gsr", "--out", str(out), *FAST]
    with pytest.MonkeyPatch.context() as patch:
        stop_after(patch, 1, ctrl_c)
        assert main(argv) == 130
    capsys.readouterr()
    folder = checkpoint_folder(out, "gsr")
    run = json.loads((folder / "run.json").read_text())
    assert run["subject"] == file_sha256(three)
    assert run["evaluator"] == "gsr"
    assert run["seeds"]["perturbation"] >= 0
    # another perturbation count: other parameters
    assert main([*argv, "--resume", "--perturbations", "2"]) == 2
    err = capsys.readouterr().err
    assert "expected the checkpoint" in err
    assert "another parameters" in err
    # another seed of the intervals
    assert main([*argv, "--resume", "--seed", "3"]) == 2
    assert "another seeds" in capsys.readouterr().err
    # another evaluator version
    run["evaluator_version"] = "0"
    (folder / "run.json").write_text(json.dumps(run))
    assert main([*argv, "--resume"]) == 2
    assert "another evaluator_version" in capsys.readouterr().err
    assert len(list(folder.glob("*.npz"))) == 1  # nothing was merged or removed


def test_a_checkpoint_of_another_submission_is_refused(three, tmp_path, capsys):
    out = tmp_path / "r.json"
    argv = ["evaluate", str(three), "--evaluators", "gsr", "--out", str(out), *FAST]
    with pytest.MonkeyPatch.context() as patch:
        stop_after(patch, 1, ctrl_c)
        assert main(argv) == 130
    capsys.readouterr()
    bench = load_benchmark_ref().benchmark
    poses = {i: bench.poses[bench.object_rows(i)[2:3]] for i in OBJECTS}
    with pytest.warns(PartialSubmissionWarning):
        other = write_submission(tmp_path / "other.h5", poses, benchmark="embedded")
    argv[1] = str(other)
    assert main([*argv, "--resume"]) == 2
    assert "another subject" in capsys.readouterr().err


def test_an_interrupt_without_out_says_nothing_was_kept(three, capsys, monkeypatch):
    def interrupted(self, subject, **kwargs):
        raise KeyboardInterrupt

    from dg16m_env.evaluators import gsr

    monkeypatch.setattr(gsr.GraspSuccessRate, "evaluate", interrupted)
    assert main(["evaluate", str(three), "--evaluators", "gsr", *FAST]) == 130
    err = capsys.readouterr().err
    assert "interrupted during gsr: nothing was kept (no --out)" in err


def test_an_interrupt_of_the_predictor_stage_says_so(tmp_path, capsys, monkeypatch):
    from dg16m_env.subjects import predictor

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(predictor, "submission_from_predictor", interrupted)
    out = tmp_path / "p.json"
    argv = ["evaluate", "--predictor", "x.py:f", "--out", str(out), *FAST]
    assert main(argv) == 130
    err = capsys.readouterr().err
    assert "interrupted while the predictor ran" in err
    assert "nothing was kept" in err


def test_a_missing_submission_is_reported_before_the_partial_banner(tmp_path, capsys):
    assert main(["evaluate", str(tmp_path / "missing.h5"), "--limit", "5"]) == 2
    captured = capsys.readouterr()
    assert "partial run" not in captured.out
    assert "missing.h5" in captured.err


POLICY = """
def act(observation):
    return 0
"""


def test_a_policy_takes_objects(tmp_path, capsys):
    module = tmp_path / "first.py"
    module.write_text(POLICY)
    out = tmp_path / "policy.json"
    held_out = OBJECTS[:2]
    argv = ["evaluate", "--policy", f"{module}:act", "--env-id", "dg16m_env/DualGraspSelect-v0"]
    argv += ["--episodes", "6", "--objects", ",".join(held_out), "--out", str(out)]
    assert main([*argv, "--no-progress"]) == 0
    assert "partial run: 2 of the benchmark's" in capsys.readouterr().out
    result = read_results(out)["policy"]
    assert result.parameters["env_kwargs"] == {"object_ids": held_out}
    assert set(result.per_object) <= set(held_out)
    assert sum(e["episodes"] for e in result.per_object.values()) == 6
    assert json.loads(out.read_text())["subject"]["objects"]["subset"] == held_out
    # an unknown id is refused before any episode
    assert main([*argv[:-2], "--objects", "nope-1", "--no-progress"]) == 2
    assert "nope-1" in capsys.readouterr().err
