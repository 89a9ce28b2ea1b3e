"""bench/compare_benchmarks.py: a file against itself is identical; one changed label is found."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
from script_loader import load_script

from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK

TINY_REAL = Path(__file__).parent / "data" / "real_tiny" / "benchmark.h5"


def _script():
    return load_script("bench/compare_benchmarks.py")


def test_identical_and_changed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    script = _script()
    assert script.main([str(TINY_REAL), str(TINY_REAL)]) == 0
    assert "every shared field identical" in capsys.readouterr().out
    bench = read_benchmark(TINY_REAL)
    status = bench.labels.status.copy()
    status[3, 1] = 1 - min(status[3, 1], 1)  # one perturbed trial of row 3 flips
    changed = replace(bench, labels=replace(bench.labels, status=status))
    write_benchmark(tmp_path / "changed.h5", changed)
    assert script.main([str(TINY_REAL), str(tmp_path / "changed.h5")]) == 1
    out = capsys.readouterr().out
    assert f"labels.status                identical rows {bench.n - 1} / {bench.n}" in out
    # files of other objects are not compared row by row
    assert script.main([str(TINY_REAL), str(EMBEDDED_BENCHMARK)]) == 2
    assert "expected the same objects and rows" in capsys.readouterr().err
