"""Compare `dg16m evaluate` results of several predictors on the same objects.

    python scripts/compare_results.py runs/a.json runs/b.json [...]

For each results file (the ``--out`` JSON of ``dg16m evaluate --evaluators fce,gsr``): the dual
grasps submitted, FCE, GSR (the mean over all submitted grasps, DESIGN.md) with an
object-resampled 95% interval, the gravity-level rate, the valid-only rate and the share of
trials not run (invalid; these two are the whole file's, marked so when only some of its objects
are compared), and for every file after the first the paired object-bootstrap difference of its
GSR minus the first file's (the same resampled objects for both). Only the objects every file
scored are used, less those of ``--exclude BENCHMARK`` (e.g. the selection set a setting was
chosen on). The bootstrap is seeded (``--seed``), so the output is reproducible.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", type=Path, nargs="+", help="dg16m evaluate --out JSON files")
    parser.add_argument("--resamples", type=int, default=2000, help="bootstrap resamples (2000)")
    parser.add_argument("--seed", type=int, default=0, help="bootstrap seed (0)")
    parser.add_argument(
        "--exclude",
        type=Path,
        default=None,
        metavar="BENCHMARK",
        help="leave out the objects of this benchmark file (e.g. a selection set used to choose "
        "settings, to compare on the objects not used for any choice)",
    )
    return parser.parse_args(argv)


def load_results(path: Path) -> dict[str, Any]:
    """The ``results`` of a results file, which must hold both ``fce`` and ``gsr``."""
    try:
        results = json.loads(path.read_text(encoding="utf-8"))["results"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SystemExit(f"{path}: expected a dg16m evaluate results file, found {exc!r}") from None
    missing = [e for e in ("fce", "gsr") if e not in results]
    if missing:
        raise SystemExit(f"{path}: expected results of fce and gsr, found none of {missing}")
    return results


def excluded_objects(path: Path) -> set[str]:
    """The object ids of a benchmark file (:func:`dg16m_env.benchmark.file.read_benchmark`)."""
    from dg16m_env.benchmark.file import read_benchmark
    from dg16m_env.benchmark.model import BenchmarkError

    try:
        return {o.object_id for o in read_benchmark(path).objects}
    except (OSError, BenchmarkError) as exc:
        raise SystemExit(f"--exclude {path}: expected a benchmark file, found {exc}") from None


def pooled_gsr(grasps: np.ndarray, gsr: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """GSR over all grasps of the objects ``rows`` (..., n) of per-object ``grasps`` and
    ``gsr`` (n,): ``sum(grasps * gsr) / sum(grasps)`` along the last axis."""
    return (grasps[rows] * gsr[rows]).sum(-1) / np.maximum(grasps[rows].sum(-1), 1)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    loaded = {path: load_results(path) for path in args.results}
    per_object = {p: r["gsr"]["per_object"] for p, r in loaded.items()}
    ids = sorted(set.intersection(*(set(v) for v in per_object.values())))
    if args.exclude is not None:
        excluded = excluded_objects(args.exclude)
        ids = [i for i in ids if i not in excluded]
        print(f"left out the {len(excluded)} objects of {args.exclude}")
    if not ids:
        raise SystemExit("expected objects that every file scored, found none in common")
    boot = np.random.default_rng(args.seed).integers(0, len(ids), (args.resamples, len(ids)))
    every = np.arange(len(ids))
    first: np.ndarray | None = None
    for path, results in loaded.items():
        grasps = np.array([per_object[path][i]["grasps"] for i in ids], dtype=float)
        gsr = np.array([per_object[path][i]["gsr"] for i in ids], dtype=float)
        resampled = pooled_gsr(grasps, gsr, boot)
        low, high = np.percentile(resampled, [2.5, 97.5])
        metrics = results["gsr"]["metrics"]
        details = results["gsr"]["details"]
        invalid = details["statuses"].get("invalid", 0) / max(details["trials"], 1)
        fce_rows = results["fce"]["per_object"]
        fce = np.array([fce_rows[i]["fce"] if i in fce_rows else np.nan for i in ids])
        fce_grasps = np.array([fce_rows[i]["grasps"] if i in fce_rows else 0 for i in ids])
        gravity = np.array([per_object[path][i]["gsr_gravity"] for i in ids], dtype=float)
        # valid-only and invalid need per-trial counts, which the file holds for all its objects
        whole = (
            "" if len(ids) == len(per_object[path]) else f" (all {len(per_object[path])} objects)"
        )
        line = (
            f"{path}: {len(ids)} objects, {int(grasps.sum())} grasps, "
            f"fce {100 * np.nansum(fce * fce_grasps) / max(fce_grasps.sum(), 1):.1f}%, "
            f"gsr {100 * pooled_gsr(grasps, gsr, every):.1f}% [{100 * low:.1f}, {100 * high:.1f}], "
            f"gravity {100 * pooled_gsr(grasps, gravity, every):.1f}%, "
            f"valid-only {100 * metrics['gsr_valid']['rate']:.1f}%{whole}, "
            f"invalid {100 * invalid:.1f}%{whole}"
        )
        if first is None:
            first = resampled
            base = pooled_gsr(grasps, gsr, every)
        else:
            diff = resampled - first
            d_low, d_high = np.percentile(diff, [2.5, 97.5])
            delta = pooled_gsr(grasps, gsr, every) - base
            line += (
                f"; minus the first {100 * delta:+.1f} points "
                f"[{100 * d_low:+.1f}, {100 * d_high:+.1f}]"
            )
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
