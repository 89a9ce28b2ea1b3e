"""scripts/compare_results.py: GSR over all submitted grasps and paired differences."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from script_loader import load_script


def _script():
    return load_script("scripts/compare_results.py")


def _results(path: Path, per_object: dict[str, tuple[int, float]]) -> Path:
    gsr = {
        "per_object": {
            k: {"grasps": n, "gsr": g, "gsr_gravity": 1.0} for k, (n, g) in per_object.items()
        },
        "metrics": {"gsr_valid": {"rate": 0.5}, "gsr_gravity": {"rate": 0.9}},
        "details": {"statuses": {"invalid": 9, "success": 81}, "trials": 90},
    }
    fce = {
        "metrics": {"fce": {"rate": 0.25}},
        "per_object": {k: {"grasps": n, "fce": g} for k, (n, g) in per_object.items()},
    }
    path.write_text(json.dumps({"results": {"fce": fce, "gsr": gsr}}))
    return path


def test_gsr_weighs_objects_by_their_grasps_and_differences_are_paired(tmp_path, capsys):
    a = _results(tmp_path / "a.json", {"x": (10, 1.0), "y": (10, 0.0), "z": (10, 0.5)})
    b = _results(tmp_path / "b.json", {"x": (5, 1.0), "y": (10, 0.0), "z": (10, 0.5), "w": (1, 1)})
    assert _script().main([str(a), str(b)]) == 0
    first, second = capsys.readouterr().out.splitlines()
    assert "3 objects, 30 grasps" in first
    assert "gsr 50.0%" in first
    assert "invalid 10.0%" in first
    assert "(all" not in first
    assert "fce 50.0%" in first
    assert "gravity 100.0%" in first
    # b: (5 * 1 + 10 * 0 + 10 * 0.5) / 25 = 40%; the object only b scored is left out
    assert "3 objects, 25 grasps" in second
    assert "gsr 40.0%" in second
    assert "minus the first -10.0 points" in second
    assert "fce 40.0%" in second  # per object, over the 3 objects compared
    assert "invalid 10.0% (all 4 objects)" in second  # per-trial counts: the whole file's


def test_a_file_without_gsr_is_refused(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"results": {"fce": {}}}))
    with pytest.raises(SystemExit, match="expected results of fce and gsr"):
        _script().main([str(bad)])


def test_the_objects_of_a_selection_set_can_be_left_out(tmp_path, capsys):
    from dg16m_env.benchmark.file import read_benchmark, write_benchmark
    from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK

    selection = tmp_path / "selection.h5"
    write_benchmark(selection, read_benchmark(EMBEDDED_BENCHMARK).select_objects(["table-1000000"]))
    scored = {"table-1000000": (10, 1.0), "bench-1000000": (10, 0.0), "tub-1000000": (10, 0.5)}
    a = _results(tmp_path / "a.json", scored)
    assert _script().main([str(a), "--exclude", str(selection)]) == 0
    note, line = capsys.readouterr().out.splitlines()
    assert note == f"left out the 1 objects of {selection}"
    assert "2 objects, 20 grasps" in line
    assert "gsr 25.0%" in line  # (0 + 0.5) / 2 without the table's 1.0
    with pytest.raises(SystemExit, match=r"--exclude .*: expected a benchmark file"):
        _script().main([str(a), "--exclude", str(a)])
    everything = tmp_path / "all.h5"
    write_benchmark(everything, read_benchmark(EMBEDDED_BENCHMARK).select_objects(list(scored)))
    with pytest.raises(SystemExit, match="expected objects that every file scored"):
        _script().main([str(a), "--exclude", str(everything)])
