"""The real-object benchmark's numbers: the import (time, faces, deviation per object) and a
build (admitted and rejected objects by stage, seconds per stage, hulls, hull-to-mesh deviation,
fc_pass counts, invalid nominal trials per arm, GSR per arm), from the folders they wrote.

    .venv/bin/python bench/real_build.py --import runs/real_meshes --build runs/real_pilot
    .venv/bin/python bench/real_build.py --import runs/real_meshes --json runs/real_numbers.json
    # how many imported objects pass the build's screen, per category (no CoACD, no trials)
    .venv/bin/python bench/real_build.py --import runs/real_meshes --screen --workers 2
    # the targets, measured on a benchmark file alone (the shipped one: no build folder needed):
    # fc_pass pairs and faces per object, invalid nominal trials per arm, hull-to-mesh
    # deviation recomputed from the carried mesh and hulls
    .venv/bin/python bench/real_build.py --shipped real --workers 2

The wall time of a build is the sum of its objects' stage seconds over the worker count (the
manifest records each object's seconds per stage; objects finished in an earlier session
count with the seconds they took then).
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from dataset_gen.real.sweethome3d import import_summary
from dataset_gen.sources.object_source import ObjectSource
from dg16m_core.atomic import write_json_atomic


def _percentiles(values: list[float]) -> dict[str, float] | None:
    if not values:
        return None
    p = np.percentile(values, [10, 50, 90, 100])
    return {"p10": float(p[0]), "p50": float(p[1]), "p90": float(p[2]), "max": float(p[3])}


def build_numbers(folder: Path) -> dict[str, Any]:
    """Per-stage and per-arm numbers of a build folder (manifest and finished objects)."""
    from dg16m_env.benchmark.file import read_benchmark
    from dg16m_env.benchmark.model import SOURCES

    manifest = json.loads((folder / "manifest.json").read_text(encoding="utf-8"))
    entries = manifest["entries"]
    ok = {k: e for k, e in entries.items() if e["status"] == "ok"}
    failed = {k: e for k, e in entries.items() if e["status"] != "ok"}
    stages: dict[str, list[float]] = {}
    for entry in entries.values():
        for stage, seconds in entry.get("stage_seconds", {}).items():
            stages.setdefault(stage, []).append(float(seconds))
    total = sum(sum(e.get("stage_seconds", {}).values()) for e in entries.values())
    out: dict[str, Any] = {
        "objects": len(entries),
        "admitted": len(ok),
        "rejected_by_stage": dict(
            Counter(
                f"{e.get('rejected', 'error')} / {e.get('stage', '?')}" for e in failed.values()
            )
        ),
        "core_seconds_total": total,
        "core_seconds_per_object": total / max(1, len(entries)),
        "stage_seconds": {k: _percentiles(v) for k, v in sorted(stages.items())},
        "hulls": _percentiles([float(e["parts"]) for e in ok.values() if "parts" in e]),
        "hull_p95_mm": _percentiles(
            [e["hull_deviation_mm"]["p95"] for e in ok.values() if "hull_deviation_mm" in e]
        ),
        "hull_max_mm": _percentiles(
            [e["hull_deviation_mm"]["max"] for e in ok.values() if "hull_deviation_mm" in e]
        ),
        "objects_over_2mm_p95": sorted(
            k for k, e in ok.items() if e.get("hull_deviation_mm", {}).get("p95", 0) > 2.0
        ),
    }
    arms: dict[str, dict[str, Any]] = {}
    for object_id, entry in sorted(ok.items()):
        bench = read_benchmark(folder / entry["files"]["benchmark"])
        valid = bench.trials.valid
        p = bench.p()
        for k, name in enumerate(SOURCES):
            rows = bench.source == k
            if not rows.any():
                continue
            arm = arms.setdefault(name, {"pairs": 0, "invalid": 0, "p_sum": 0.0, "objects": 0})
            arm["pairs"] += int(rows.sum())
            arm["invalid"] += int((rows & ~valid).sum())
            arm["p_sum"] += float(p[rows].sum())
            arm["objects"] += 1
        del object_id
    for arm in arms.values():
        arm["invalid_share"] = arm["invalid"] / max(1, arm["pairs"])
        arm["gsr"] = arm.pop("p_sum") / max(1, arm["pairs"])
    out["arms"] = arms
    return out


@functools.lru_cache(maxsize=1)
def _read_once(path: str) -> Any:
    """The benchmark, read once per worker process (the tasks index into it)."""
    from dg16m_env.benchmark.file import read_benchmark

    return read_benchmark(path)


def _deviation_one(index: int, path: str) -> dict[str, Any]:
    from dataset_gen.objects.decomposition import decomposition_report

    obj = _read_once(path).objects[index]
    mesh = obj.load().mesh
    report = decomposition_report(mesh, obj.parts, seed=0)
    return {
        "object_id": obj.object_id,
        "faces": len(mesh.faces),
        "hulls": len(obj.parts),
        "p95_mm": 1000 * report.deviation_p95,
        "max_mm": 1000 * report.deviation_max,
    }


def shipped_numbers(benchmark: str, workers: int) -> dict[str, Any]:
    """The targets measured on a benchmark file alone: objects, fc_pass pairs per object
    (and those under the admission rule), invalid nominal trials and GSR per arm, and each
    object's hull-to-mesh deviation recomputed from the mesh and hulls the file carries (the
    same :func:`~dataset_gen.objects.decomposition.decomposition_report`, seed 0, the build used)."""
    from dataset_gen.pipeline.parallel import run_tasks
    from dg16m_env.benchmark.file import read_benchmark
    from dg16m_env.benchmark.model import SOURCES
    from dg16m_env.benchmark.names import benchmark_file
    from dg16m_env.benchmark.real import MAX_HULL_P95_MM, REAL_LIMITS

    path = benchmark_file(benchmark)
    bench = read_benchmark(path)
    names = np.array([SOURCES[int(s)] for s in bench.source])
    passing = np.bincount(bench.object_index[names == "fc_pass"], minlength=len(bench.objects))
    valid = bench.trials.valid
    p = bench.p()
    arms = {}
    for name in SOURCES:
        rows = names == name
        if rows.any():
            arms[name] = {
                "pairs": int(rows.sum()),
                "objects": len(np.unique(bench.object_index[rows])),
                "invalid": int((rows & ~valid).sum()),
                "invalid_share": float((rows & ~valid).sum() / rows.sum()),
                "gsr": float(p[rows].mean()),
            }
    per_object = [
        value
        for _, value in run_tasks(
            _deviation_one, list(range(len(bench.objects))), (str(path),), workers=workers
        )
    ]
    p95 = [v["p95_mm"] for v in per_object]
    return {
        "file": str(path),
        "objects": len(bench.objects),
        "pairs": bench.n,
        "fc_pass_per_object": _percentiles([float(v) for v in passing]),
        "objects_under_min_passing": [
            o.object_id
            for o, n in zip(bench.objects, passing, strict=True)
            if n < REAL_LIMITS.min_passing
        ],
        "arms": arms,
        "faces": _percentiles([float(v["faces"]) for v in per_object]),
        "hulls": _percentiles([float(v["hulls"]) for v in per_object]),
        "hull_p95_mm": _percentiles(p95),
        "hull_max_mm": _percentiles([v["max_mm"] for v in per_object]),
        "objects_over_max_hull_p95": sorted(
            v["object_id"] for v in per_object if v["p95_mm"] > MAX_HULL_P95_MM
        ),
    }


def _screen_one(item: Any, meshes: str) -> dict[str, Any]:
    from dg16m_env.benchmark.arms import screen_passing
    from dg16m_env.benchmark.real import REAL_PARAMETERS

    object_id, category = item
    obj = ObjectSource(object_id, mesh=Path(meshes) / f"{object_id}.obj").load(REAL_PARAMETERS.mass)
    start = time.perf_counter()
    passing = screen_passing(obj, REAL_PARAMETERS)
    return {"category": category, "passing": passing, "seconds": time.perf_counter() - start}


def screen_numbers(meshes: Path, workers: int) -> dict[str, Any]:
    """The build's screen (:func:`dg16m_env.benchmark.arms.screen_passing`) on every imported object:
    per category, how many reach the admission rule's passing pairs before the clearance rule
    (an upper bound on what the build admits)."""
    from dataset_gen.pipeline.parallel import run_tasks
    from dg16m_env.benchmark.real import REAL_LIMITS, REAL_SIZE, import_entries, read_split

    entries = import_entries(meshes)
    items = [
        (k, e["source"]["category"]) for k, e in sorted(entries.items()) if e["status"] == "ok"
    ]
    results = {
        item[0]: value
        for item, value in run_tasks(_screen_one, items, (str(meshes),), workers=workers)
    }
    quota = {c: v["quota"] for c, v in read_split()["categories"].items()}
    by_category: dict[str, dict[str, Any]] = {}
    for value in results.values():
        row = by_category.setdefault(value["category"], {"objects": 0, "pass_screen": 0})
        row["objects"] += 1
        row["pass_screen"] += int(value["passing"] >= REAL_LIMITS.min_passing)
    for name, row in by_category.items():
        row["quota"] = quota.get(name, 0)
        row["short_by"] = max(0, row["quota"] - row["pass_screen"])
    total = sum(r["pass_screen"] for r in by_category.values())
    return {
        "objects": len(results),
        "pass_screen": total,
        "benchmark_size": REAL_SIZE,
        "within_quotas": sum(min(r["quota"], r["pass_screen"]) for r in by_category.values()),
        "by_category": dict(sorted(by_category.items())),
        "screen_seconds": _percentiles([v["seconds"] for v in results.values()]),
        "passing": {k: v["passing"] for k, v in sorted(results.items())},
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--import", dest="imported", type=Path, default=None)
    parser.add_argument("--build", type=Path, default=None)
    parser.add_argument(
        "--shipped",
        default=None,
        help="a benchmark file or short name ('real'): the targets measured on the file alone",
    )
    parser.add_argument("--screen", action="store_true", help="screen every imported object")
    parser.add_argument(
        "--workers", type=int, default=1, help="processes for --screen and --shipped"
    )
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    args = parser.parse_args(argv)
    if args.imported is None and args.build is None and args.shipped is None:
        parser.error("expected --import, --build and/or --shipped, found none")
    numbers: dict[str, Any] = {}
    if args.imported is not None:
        manifest = json.loads((args.imported / "manifest.json").read_text(encoding="utf-8"))
        numbers["import"] = import_summary(manifest)
        if args.screen:
            numbers["screen"] = screen_numbers(args.imported, args.workers)
    if args.build is not None:
        numbers["build"] = build_numbers(args.build)
    if args.shipped is not None:
        numbers["shipped"] = shipped_numbers(args.shipped, args.workers)
    print(json.dumps(numbers, indent=2))
    if args.json is not None:
        write_json_atomic(args.json, numbers)
    return 0


if __name__ == "__main__":
    sys.exit(main())
