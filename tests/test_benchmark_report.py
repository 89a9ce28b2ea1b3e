"""``dg16m benchmark info``: the v2 text report, its JSON, the figure and clear errors."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

pytest.importorskip("mujoco")

from dg16m_core.cli import main as cli_main
from dg16m_core.json_values import json_ready
from dg16m_env.benchmark.build import build_benchmark
from dg16m_env.benchmark.file import read_benchmark
from dg16m_env.benchmark.model import ARMS, SOURCES, Benchmark, BenchmarkParameters
from dg16m_env.benchmark.report import (
    HISTOGRAM_BINS,
    benchmark_report,
    failure_phases,
    p_histogram,
    summary_by_family,
)
from dg16m_env.benchmark.report_plot import plot_summary
from dg16m_env.benchmark.report_text import format_summary
from dg16m_env.benchmark.sources import procedural_benchmark_sources
from dg16m_env.physics.labels import LEVELS
from dg16m_env.physics.trial_protocol import PHASES, TrialStatus

SMALL = BenchmarkParameters(n_grasps=60, n_passing=6, n_failing=4, n_random=4, n_farthest=4)
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def bench_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("report_bench")
    return build_benchmark(procedural_benchmark_sources(2), out, SMALL, progress=False)


@pytest.fixture(scope="module")
def bench(bench_file: Path) -> Benchmark:
    return read_benchmark(bench_file)


def _refuse_nan(name: str) -> None:
    raise AssertionError(f"JSON holds {name}")


def _info_json(path: Path, capsys: pytest.CaptureFixture[str]) -> dict[str, Any]:
    assert cli_main(["benchmark", "info", str(path), "--json"]) == 0
    return json.loads(capsys.readouterr().out, parse_constant=_refuse_nan)


def test_text_report_names_every_arm_level_and_ci(
    bench: Benchmark, bench_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli_main(["benchmark", "info", str(bench_file)]) == 0
    out = capsys.readouterr().out
    assert str(bench_file) in out
    assert f"{bench.labels.spec.trials} trials per pair" in out
    assert "d = 1 mm" in out
    assert "theta = 1 deg" in out
    assert "built by dg16m" in out
    assert "95% CI" in out
    lines = out.splitlines()
    for arm in ARMS:
        assert any(line.startswith(f"{arm} ") for line in lines), arm
    for level in LEVELS:
        assert sum(f"  {level} " in line for line in lines) >= len(ARMS), level
    summary = bench.summary()
    row = summary["by_arm"]["fc_pass"]["full"]["gsr"]
    assert f"{100 * row['rate']:5.1f}% [{100 * row['ci_low']:.1f}-" in out
    for heading in (
        "pairs per value of p, full level",
        "uncertain pairs (0.2 < p < 0.8), all arms",
        "failure phase of failed trials",
        "invalid trials",
        "penetration of the hands while held",
        "by family",
    ):
        assert heading in out, heading
    assert "nan" not in out.lower()
    assert format_summary(bench, path=bench_file) == out.rstrip("\n")


def test_json_matches_the_summary_and_holds_no_nan(
    bench: Benchmark, bench_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report = _info_json(bench_file, capsys)
    summary = json_ready(bench.summary())
    for key, value in summary.items():
        assert report[key] == value, key
    assert set(report["by_arm"]) == set(ARMS)
    for arm, row in report["by_arm"].items():
        rows = bench.arm_rows(arm)
        assert row["pairs"] == int(rows.sum())
        for level in LEVELS:
            gsr = row[level]["gsr"]
            assert gsr["rate"] == pytest.approx(float(bench.p(level)[rows].mean()))
            assert gsr["ci_low"] <= gsr["rate"] <= gsr["ci_high"]
    for key in ("p_histogram", "failure_phases", "by_family", "invalid", "penetration"):
        assert key in report, key
    assert report["by_family"] == json_ready(summary_by_family(bench))
    assert report["created_by"].startswith("dg16m ")
    pen = report["penetration"]
    valid = bench.trials.valid
    assert pen["trials"] == int(valid.sum())
    assert pen["max_m"] == pytest.approx(float(bench.trials.max_penetration[valid].max()))
    assert pen["p99_m"] <= pen["max_m"]
    assert report["invalid"]["invalid"] == int(np.sum(bench.labels.status == TrialStatus.INVALID))
    assert report["invalid"]["nominal_invalid"] == int((~valid).sum())


def test_histogram_counts_add_up_to_each_arms_pairs(bench: Benchmark) -> None:
    trials = bench.labels.spec.trials
    for level in LEVELS:
        hist = p_histogram(bench, level)
        assert hist["bins"] == list(HISTOGRAM_BINS)
        assert len(hist["values"]) == trials + 1
        p = bench.p(level)
        for arm, counts in hist["counts"].items():
            rows = bench.arm_rows(arm)
            assert sum(counts) == int(rows.sum())
            assert sum(hist["exact"][arm]) == int(rows.sum())
            assert counts[0] == int(np.sum(p[rows] == 0))
            assert counts[-1] == int(np.sum(p[rows] == 1))
            inner = p[rows][(p[rows] > 0) & (p[rows] < 1)]
            for j in range(1, 6):
                low, high = 0.2 * (j - 1), 0.2 * j
                expected = np.sum((inner > low + 1e-9) & (inner <= high + 1e-9))
                assert counts[j] == int(expected), (arm, j)
        assert sum(sum(c) for c in hist["counts"].values()) == bench.n


def test_failure_phases_count_every_failed_or_unstable_trial(bench: Benchmark) -> None:
    phases = failure_phases(bench)
    status = bench.labels.status
    failed = (status == TrialStatus.FAILED) | (status == TrialStatus.UNSTABLE)
    pooled = phases["pooled"]
    assert pooled["trials"] == status.size == bench.n * bench.labels.spec.trials
    assert pooled["failed"] + pooled["unstable"] == int(failed.sum())
    assert sum(pooled["phases"].values()) == int(failed.sum())
    assert list(pooled["phases"])[: len(PHASES)] == list(PHASES)
    for arm, entry in phases["by_arm"].items():
        rows = bench.source == SOURCES.index(arm)
        assert sum(entry["phases"].values()) == int(failed[rows].sum())
    for name, count in pooled["phases"].items():
        assert count == sum(e["phases"].get(name, 0) for e in phases["by_arm"].values())


def test_plot_writes_a_png_without_touching_the_backend(
    bench: Benchmark,
    bench_file: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import matplotlib

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("library code called matplotlib.use")

    monkeypatch.setattr(matplotlib, "use", refuse)
    png = tmp_path / "summary.png"
    assert cli_main(["benchmark", "info", str(bench_file), "--plot", str(png)]) == 0
    assert f"wrote {png}" in capsys.readouterr().out
    data = png.read_bytes()
    assert data[:8] == PNG_MAGIC
    assert len(data) > 20_000
    again = tmp_path / "again.png"
    plot_summary(bench, again, benchmark_report(bench))
    assert again.read_bytes()[:8] == PNG_MAGIC


def test_version_1_file_exits_2_naming_the_version(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    old = tmp_path / "old.h5"
    with h5py.File(old, "w") as f:
        f.attrs.create("format", "dg16m-benchmark", dtype=h5py.string_dtype("utf-8"))
        f.attrs.create("schema_version", np.int64(1))
    for extra in ([], ["--json"]):
        assert cli_main(["benchmark", "info", str(old), *extra]) == 2
        captured = capsys.readouterr()
        assert captured.out == ""
        assert captured.err.startswith("dg16m benchmark: error: ")
        assert "schema_version" in captured.err
        assert "found 1" in captured.err
        assert "dg16m benchmark build" in captured.err


@pytest.mark.parametrize(
    ("content", "found"),
    [
        (b"", "found an empty file (0 bytes)"),
        (b"not hdf5", "found a file without the HDF5 signature (it starts with b'not hdf5')"),
    ],
)
def test_not_a_benchmark_exits_2(
    content: bytes, found: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An empty or a text file: what was expected and what was found, not h5py's words."""
    bad = tmp_path / "bad.h5"
    bad.write_bytes(content)
    assert cli_main(["benchmark", "info", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: expected an HDF5 file, {found}" in err
    assert "Unable to" not in err  # h5py's "Unable to synchronously open file"


def test_no_benchmark_at_the_path_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli_main(["benchmark", "info", str(tmp_path / "absent.h5")]) == 2
    assert "expected a dg16m benchmark HDF5 file, found nothing at this path" in (
        capsys.readouterr().err
    )
    assert cli_main(["benchmark", "info", str(tmp_path)]) == 2
    assert "expected a dg16m benchmark HDF5 file, found a directory" in capsys.readouterr().err


def test_json_ready_replaces_non_finite_numbers() -> None:
    value = {
        "a": float("nan"),
        "b": [np.float64("inf"), np.int64(3), np.bool_(True)],
        "c": np.array([1.5, np.nan]),
        "d": (1, "x", None),
    }
    out = json_ready(value)
    assert out == {"a": None, "b": [None, 3, True], "c": [1.5, None], "d": [1, "x", None]}
    json.dumps(out, allow_nan=False)
    assert all(not isinstance(v, float) or math.isfinite(v) for v in out["b"])


def test_summary_by_family_covers_every_pair(bench: Benchmark) -> None:
    families = summary_by_family(bench)
    assert set(families) == {o.family for o in bench.objects}
    assert sum(f["pairs"] for f in families.values()) == bench.n
    assert sum(f["objects"] for f in families.values()) == len(bench.objects)
    for name, entry in families.items():
        index = [i for i, o in enumerate(bench.objects) if o.family == name]
        rows = np.isin(bench.object_index, index)
        for level in LEVELS:
            assert entry[level]["gsr"] == pytest.approx(float(bench.p(level)[rows].mean()))
