"""The scoring tutorial's example predictor (docs/tutorials/my_grasps.py) grasps: run through
``dg16m evaluate --predictor`` (the sandboxed child, the submission, the ``fce`` evaluator) on
three procedural benchmark objects, it scores a positive force-closure efficiency on each."""

from __future__ import annotations

from pathlib import Path

from dg16m_core.cli import main
from dg16m_env.evaluators import read_results
from dg16m_env.subjects.submission_reader import read_submission

PREDICTOR = Path(__file__).resolve().parents[1] / "docs" / "tutorials" / "my_grasps.py"
OBJECTS = ("table-1000000", "chair-1000000", "ladder-1000000")


def test_the_tutorial_predictor_scores_a_positive_fce(tmp_path: Path, capsys) -> None:
    out, kept = tmp_path / "r.json", tmp_path / "s.h5"
    argv = ["evaluate", "--predictor", f"{PREDICTOR}:predict", "--objects", ",".join(OBJECTS)]
    argv += ["--evaluators", "fce", "--out", str(out), "--save-submission", str(kept)]
    assert main([*argv, "--time-limit", "60", "--no-progress"]) == 0, capsys.readouterr().err
    sub = read_submission(kept)
    assert sub.metadata["failed_objects"] == {}, sub.metadata["failed_objects"]
    assert sorted(sub.poses) == sorted(OBJECTS)
    result = read_results(out)["fce"]
    assert result.failures == {}
    rate = result.metrics["fce"]["rate"]
    assert rate > 0.0, f"expected a positive fce, found {rate}"
    for object_id in OBJECTS:
        entry = result.per_object[object_id]
        assert entry["fce"] > 0.0, f"{object_id}: expected a passing dual grasp, found {entry}"
