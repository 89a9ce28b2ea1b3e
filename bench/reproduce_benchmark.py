"""Rebuild the shipped simulation benchmark on this machine and compare it with the shipped file.

The shipped ``dg16m_env/data/benchmark.h5`` was built on one machine. This script rebuilds some or
all of its objects here (same parameters, same seeds) and reports, row by row, what reproduces:
inputs (poses, contacts, force-closure verdicts), labels (the binary label and the success
probabilities at both levels), every trial's status and failing phase (nominal and perturbed),
the nominal trial's discrete results, and how far its floating-point measures (slip, rotation,
penetration) moved. On the machine that built
the file everything is identical; on another CPU the physics differs in the last bits and, after
contact chaos, by more. This is how the user guide's reproducibility claim (docs/guide.md) was measured.

    python bench/reproduce_benchmark.py --limit 20 --workers 2
    python bench/reproduce_benchmark.py --workers 16 --out runs/reproduce.json   # all 300 objects
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from dg16m_core.atomic import write_json_atomic
from dg16m_core.json_values import json_ready
from dg16m_env.benchmark.build import benchmark_object
from dg16m_env.benchmark.file import read_benchmark
from dg16m_env.benchmark.model import SOURCES, Benchmark, BenchmarkParameters
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.benchmark.sources import procedural_benchmark_sources
from dg16m_env.physics.trial_protocol import TrialResults

INPUT_FIELDS = ("poses", "contact_points", "contact_normals", "source", "fc_passed", "fc_loss")
"""Per-row inputs of the trials: identical unless sampling or force closure moved."""

EXACT_TRIAL_FIELDS = ("success", "status", "failing_phase", "invalid_reason")
"""Discrete trial results compared exactly (those present in this version's TrialResults)."""

FLOAT_THRESHOLDS = (0.0, 1e-12, 1e-9, 1e-6, 1e-3)
"""Report how many rows differ by more than each of these (in the field's unit; 0: at all)."""


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _rebuild(index: int) -> tuple[int, Benchmark, float]:
    item = procedural_benchmark_sources(index + 1)[index]
    start = time.perf_counter()
    rebuilt = benchmark_object(item, BenchmarkParameters())
    return index, rebuilt, time.perf_counter() - start


def _compare(shipped: Benchmark, rows: np.ndarray, rebuilt: Benchmark) -> dict:
    out: dict = {"rows": int(rows.size)}
    if rebuilt.n != rows.size:
        out["row_count_differs"] = [int(rows.size), int(rebuilt.n)]
        return out
    same_inputs = np.ones(rows.size, dtype=bool)
    for name in INPUT_FIELDS:
        a, b = getattr(shipped, name)[rows], getattr(rebuilt, name)
        equal = (a == b).reshape(rows.size, -1).all(axis=1)
        same_inputs &= equal
    out["inputs_differ"] = int((~same_inputs).sum())
    exact = {}
    for name in EXACT_TRIAL_FIELDS:
        if not hasattr(rebuilt.trials, name):
            continue
        a, b = getattr(shipped.trials, name)[rows], getattr(rebuilt.trials, name)
        exact[name] = int((a != b).reshape(rows.size, -1).any(axis=1).sum())
    for name in ("status", "failing_phase"):  # every trial of the row, nominal and perturbed
        a, b = getattr(shipped.labels, name)[rows], getattr(rebuilt.labels, name)
        exact[f"labels.{name}"] = int((a != b).any(axis=1).sum())
    for level in ("full", "gravity"):
        exact[f"p_{level}"] = int((shipped.p(level)[rows] != rebuilt.p(level)).sum())
    out["exact_differ"] = exact
    labels_a, labels_b = shipped.label()[rows], rebuilt.label()
    flips = np.flatnonzero(labels_a != labels_b)
    out["label_flips"] = [
        {
            "row": int(rows[i]),
            "source": SOURCES[int(shipped.source[rows[i]])],
            "shipped": bool(labels_a[i]),
            "rebuilt": bool(labels_b[i]),
        }
        for i in flips
    ]
    floats = {}
    for name in TrialResults.ARRAY_FIELDS:
        a = np.asarray(getattr(shipped.trials, name)[rows])
        if a.dtype.kind != "f":
            continue
        b = np.asarray(getattr(rebuilt.trials, name))
        diff = np.abs(np.nan_to_num(a - b, nan=0.0)).reshape(rows.size, -1).max(axis=1)
        nan_mismatch = (np.isnan(a) != np.isnan(b)).reshape(rows.size, -1).any(axis=1)
        floats[name] = {
            "max_abs": float(diff.max()) if diff.size else 0.0,
            "rows_over": {f"{t:g}": int((diff > t).sum()) for t in FLOAT_THRESHOLDS},
            "nan_mismatch": int(nan_mismatch.sum()),
        }
    out["floats"] = floats
    return out


def _totals(per_object: dict[str, dict]) -> dict:
    rows = sum(o["rows"] for o in per_object.values())
    flips = [f for o in per_object.values() for f in o.get("label_flips", [])]
    total: dict = {
        "objects": len(per_object),
        "rows": rows,
        "rows_with_input_differences": sum(o.get("inputs_differ", 0) for o in per_object.values()),
        "label_flips": len(flips),
        "label_flip_fraction": len(flips) / rows if rows else 0.0,
        "objects_with_flips": sorted(k for k, o in per_object.items() if o.get("label_flips")),
    }
    exact: dict[str, int] = {}
    floats: dict[str, dict] = {}
    for o in per_object.values():
        for name, count in o.get("exact_differ", {}).items():
            exact[name] = exact.get(name, 0) + count
        for name, f in o.get("floats", {}).items():
            agg = floats.setdefault(
                name, {"max_abs": 0.0, "rows_over": dict.fromkeys(f["rows_over"], 0)}
            )
            agg["max_abs"] = max(agg["max_abs"], f["max_abs"])
            for key, count in f["rows_over"].items():
                agg["rows_over"][key] += count
    total["exact_differ"] = exact
    total["floats"] = floats
    return total


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--limit", type=int, default=None, help="first N objects (default: all)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--reference", type=Path, default=EMBEDDED_BENCHMARK)
    parser.add_argument("--out", type=Path, default=None, help="JSON report")
    args = parser.parse_args(argv)

    shipped = read_benchmark(args.reference)
    count = len(shipped.objects) if args.limit is None else min(args.limit, len(shipped.objects))
    ids = [o.object_id for o in shipped.objects]
    start = time.perf_counter()
    per_object: dict[str, dict] = {}
    seconds = 0.0
    with ProcessPoolExecutor(max_workers=max(1, args.workers)) as pool:
        for index, rebuilt, took in pool.map(_rebuild, range(count)):
            object_id = rebuilt.objects[0].object_id
            if object_id != ids[index]:
                raise SystemExit(f"object {index}: expected {ids[index]}, rebuilt {object_id}")
            per_object[object_id] = _compare(shipped, shipped.object_rows(object_id), rebuilt)
            seconds += took
            if args.out is not None and len(per_object) % 25 == 0:
                _write(args.out, _report(args, per_object, start, seconds))  # partial, if killed
            print(
                f"{object_id:24s} rows {per_object[object_id]['rows']:4d} "
                f"flips {len(per_object[object_id].get('label_flips', []))}",
                flush=True,
            )
    report = _report(args, per_object, start, seconds)
    if args.out is not None:
        _write(args.out, report)
    print(json.dumps({"machine": report["machine"], "totals": report["totals"]}, indent=1))
    return 0


def _report(args: argparse.Namespace, per_object: dict[str, dict], start: float, seconds: float):
    return {
        "machine": {
            "cpu": _cpu_name(),
            "python": sys.version.split()[0],
            "numpy": np.__version__,
            "mujoco": __import__("mujoco").__version__,
            "platform": platform.platform(),
        },
        "reference": str(args.reference),
        "wall_seconds": time.perf_counter() - start,
        "object_seconds": seconds,
        "totals": _totals(per_object),
        "objects": per_object,
    }


def _write(path: Path, report: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, json_ready(report))


if __name__ == "__main__":
    sys.exit(main())
