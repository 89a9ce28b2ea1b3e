"""How stable are the benchmark's success-probability labels? Relabel a sample of rows and compare.

Two modes, both on a seeded sample of ``--rows`` rows of a benchmark file (version 2),
stratified by arm (each arm present in the file gets its proportional share, largest remainder;
every object is eligible):

* ``independent`` (default): label every sampled row twice, with two independent perturbation
  seeds (``--seeds A B``: the file's perturbation spec with its ``seed`` replaced; a row's own
  seed is ``row_seeds(seed, object_id, rows of the object)[row within the object]``, as the
  build derives it, so a row's perturbations do not depend on which rows were sampled). Reports
  how often the binary labels of the two labellings disagree at both levels, overall and per arm,
  with 95 % confidence intervals (Wilson on rows; object-resampled with
  :func:`dg16m_env.rates.object_rate`), mean |p1 - p2|, the uncertain fraction and the trial
  throughput; then checks the targets: disagreement <= 2 % of all rows and <= 3 % of ``fc_pass``
  rows.
* ``shipped``: relabel the sampled rows with the file's own per-row seeds and spec, and compare
  with the stored labels: identical binary labels (target >= 99 %), identical per-trial
  statuses and failing phases, max |p difference|, and the nominal trial's float measures. On the
  machine that built the file everything must be identical (same computation); on another
  machine this measures cross-machine agreement (CPU model and numpy / MuJoCo versions printed).

Objects are independent tasks (``--workers`` processes, :func:`dataset_gen.pipeline.parallel.run_tasks`),
each compiled the way the benchmark did (``BenchmarkObject.load`` + ``compile_scene`` with the
file's scene parameters and the stored convex parts). The same arguments give the same sample and
the same labels.

    .venv/bin/python bench/label_stability.py                                # 600 rows, seeds 1, 2
    .venv/bin/python bench/label_stability.py --rows 1200 --workers 16 --json runs/stability.json
    .venv/bin/python bench/label_stability.py --mode shipped --json runs/shipped_agreement.json
    .venv/bin/python bench/label_stability.py --benchmark out/benchmark.h5 --meshes meshes/
"""

from __future__ import annotations

import os

# One core per worker: no BLAS, OpenMP or numba threads (set before numpy is imported).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import math
import platform
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from dataset_gen.pipeline.parallel import run_tasks
from dg16m_core.atomic import write_json_atomic
from dg16m_core.errors import Dg16mError
from dg16m_core.json_values import json_ready
from dg16m_env.benchmark.file import read_benchmark
from dg16m_env.benchmark.model import SOURCES, Benchmark, BenchmarkObject
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.physics.labels import (
    LEVELS,
    GraspLabels,
    PerturbationSpec,
    concatenate_labels,
    row_seeds,
    success_probability,
)
from dg16m_env.physics.scene import SceneParameters, compile_scene
from dg16m_env.physics.trial_protocol import TrialProtocol, TrialResults, TrialStatus
from dg16m_env.rates import object_rate

MODES = ("independent", "shipped")
TARGET_ALL = 0.02
"""Independent mode: at most this fraction of all sampled rows may change label."""
TARGET_FC_PASS = 0.03
"""Independent mode: at most this fraction of the sampled ``fc_pass`` rows may change label."""
TARGET_SHIPPED = 0.99
"""Shipped mode: at least this fraction of the relabelled rows must keep their stored label."""
Z95 = 1.959963984540054
"""Two-sided 95 % normal quantile (Wilson interval)."""
N_RESAMPLES = 2000
"""Object resamples of the object-resampled confidence intervals."""
FLOAT_FIELDS = ("max_displacement", "max_rotation_deg", "max_penetration")
"""The nominal trial's float measures compared in shipped mode."""


@dataclass
class Arguments:
    mode: str = "independent"
    benchmark: str = str(EMBEDDED_BENCHMARK)
    rows: int = 600
    seed: int = 0
    seeds: tuple[int, int] = (1, 2)
    workers: int = 2
    perturbations: int | None = None
    meshes: str | None = None
    json: str | None = None


class UsageError(Dg16mError, ValueError):
    """Bad arguments (reported in one line, exit status 2)."""


def parse(argv: list[str] | None = None) -> Arguments:
    defaults = Arguments()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mode", choices=MODES, default=defaults.mode)
    parser.add_argument(
        "--benchmark",
        default=defaults.benchmark,
        help="benchmark file, schema version 2 (default: the shipped one)",
    )
    parser.add_argument(
        "--rows",
        type=int,
        default=defaults.rows,
        help="rows to sample, stratified by arm (all rows when the file has fewer)",
    )
    parser.add_argument("--seed", type=int, default=defaults.seed, help="seed of the row sample")
    parser.add_argument(
        "--seeds",
        type=int,
        nargs=2,
        metavar=("A", "B"),
        default=list(defaults.seeds),
        help="independent mode: the perturbation seeds of the two labellings",
    )
    parser.add_argument("--workers", type=int, default=defaults.workers)
    parser.add_argument(
        "--perturbations",
        type=int,
        default=None,
        metavar="K",
        help="independent mode: label with K perturbed trials per row instead of the file's K "
        "(to choose K by measurement)",
    )
    parser.add_argument(
        "--meshes", default=None, help="mesh folder of a benchmark built from mesh files"
    )
    parser.add_argument("--json", default=None, help="also write every number here (atomically)")
    values = vars(parser.parse_args(argv))
    values["seeds"] = tuple(values["seeds"])
    return Arguments(**values)


def check(args: Arguments) -> None:
    if args.rows < 1:
        raise UsageError(f"--rows: expected an integer >= 1, found {args.rows}")
    if args.workers < 1:
        raise UsageError(f"--workers: expected an integer >= 1, found {args.workers}")
    if args.seed < 0 or min(args.seeds) < 0:
        raise UsageError(
            f"--seed, --seeds: expected non-negative integers, found {args.seed}, {args.seeds}"
        )
    if args.perturbations is not None and (args.perturbations < 0 or args.mode != "independent"):
        raise UsageError(
            f"--perturbations: expected an integer >= 0 in independent mode, found "
            f"{args.perturbations} in {args.mode} mode"
        )
    if args.mode == "independent" and args.seeds[0] == args.seeds[1]:
        raise UsageError(
            f"--seeds: expected two different seeds (independent labellings), found {args.seeds}"
        )


# --------------------------------------------------------------------------------------------
# The sample
# --------------------------------------------------------------------------------------------


def allocate(counts: np.ndarray, total: int) -> np.ndarray:
    """Rows to draw from each stratum: proportional to ``counts`` (largest remainder, ties to the
    lower index), summing to ``min(total, counts.sum())``, never above a stratum's count; every
    non-empty stratum gets at least one row when ``total`` allows it."""
    counts = np.asarray(counts, dtype=np.int64)
    available = int(counts.sum())
    total = min(total, available)
    share = counts * total / available
    take = np.floor(share).astype(np.int64)
    order = sorted(range(counts.size), key=lambda k: (-(share[k] - take[k]), k))
    for k in order[: total - int(take.sum())]:
        take[k] += 1
    # A tiny arm rounded to zero borrows a row from the largest allocation.
    for k in np.flatnonzero((counts > 0) & (take == 0)):
        donor = int(np.argmax(take))
        if take[donor] > 1:
            take[donor] -= 1
            take[k] += 1
    return take


def sample_rows(bench: Benchmark, n_rows: int, seed: int) -> np.ndarray:
    """Sorted row indices: ``n_rows`` rows (all when fewer) stratified by arm (:data:`SOURCES`
    order), drawn without replacement from a generator seeded with ``seed``."""
    counts = np.bincount(bench.source, minlength=len(SOURCES))
    take = allocate(counts, n_rows)
    rng = np.random.default_rng(seed)
    chosen = []
    for arm in range(len(SOURCES)):
        rows = np.flatnonzero(bench.source == arm)
        if take[arm] == rows.size:
            chosen.append(rows)
        elif take[arm]:
            chosen.append(rng.choice(rows, size=int(take[arm]), replace=False))
    return np.sort(np.concatenate(chosen)) if chosen else np.zeros(0, np.int64)


# --------------------------------------------------------------------------------------------
# Labelling (one task per object)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ObjectWork:
    """The sampled rows of one object and the per-row seeds of each labelling."""

    item: BenchmarkObject
    rows: np.ndarray  # file rows, sorted
    poses: np.ndarray  # (n, 2, 4, 4)
    seeds: tuple[np.ndarray, ...]  # one (n,) array per labelling

    @property
    def object_id(self) -> str:
        return self.item.object_id


def label_object(
    work: ObjectWork,
    scene_params: SceneParameters,
    protocol: TrialProtocol,
    specs: tuple[PerturbationSpec, ...],
    mesh_root: str | None,
) -> dict[str, Any]:
    """Compile the object's scene as the benchmark did and label its rows once per spec."""
    start = time.perf_counter()
    obj = work.item.load(mesh_root)
    scene = compile_scene(obj, params=scene_params, parts=work.item.parts)
    compiled = time.perf_counter()
    labels = [
        success_probability(scene, work.poses, spec=spec, seeds=seeds, protocol=protocol)
        for spec, seeds in zip(specs, work.seeds, strict=True)
    ]
    return {
        "labels": labels,
        "setup_s": compiled - start,
        "label_s": time.perf_counter() - compiled,
    }


def plan_work(
    bench: Benchmark, rows: np.ndarray, seeds_of: list[np.ndarray] | None
) -> list[ObjectWork]:
    """One :class:`ObjectWork` per object with sampled rows, in object order. ``seeds_of``: per
    labelling, an (N,) array of every file row's seed (None: the file's stored seeds)."""
    seeds_of = seeds_of if seeds_of is not None else [bench.labels.seeds]
    out = []
    for index, item in enumerate(bench.objects):
        mine = rows[bench.object_index[rows] == index]
        if mine.size:
            out.append(
                ObjectWork(
                    item=item,
                    rows=mine,
                    poses=bench.poses[mine],
                    seeds=tuple(np.asarray(s[mine], dtype=np.int64) for s in seeds_of),
                )
            )
    return out


def file_row_seeds(bench: Benchmark, seed: int) -> np.ndarray:
    """(N,) every file row's perturbation seed for global ``seed``, derived as the build does:
    ``row_seeds(seed, object_id, rows of the object)`` in the object's row order."""
    out = np.zeros(bench.n, dtype=np.int64)
    for index, item in enumerate(bench.objects):
        mine = np.flatnonzero(bench.object_index == index)
        out[mine] = row_seeds(seed, item.object_id, mine.size)
    return out


def relabel(
    bench: Benchmark,
    works: list[ObjectWork],
    specs: tuple[PerturbationSpec, ...],
    args: Arguments,
) -> tuple[list[GraspLabels], np.ndarray, dict[str, Any]]:
    """Run every object's task; returns one :class:`GraspLabels` per spec over the sampled rows
    (in sorted row order), those rows, and the timings."""
    params = bench.parameters()
    done: dict[str, dict[str, Any]] = {}
    start = time.perf_counter()
    task_args = (params.scene, params.protocol, specs, args.meshes)
    live = sys.stderr.isatty()
    for work, result in run_tasks(label_object, works, task_args, workers=args.workers):
        done[work.object_id] = result
        if live:
            print(f"\r  objects {len(done)}/{len(works)}", end="", file=sys.stderr, flush=True)
    if live:
        print(file=sys.stderr)
    wall = time.perf_counter() - start
    labels = [
        concatenate_labels([done[w.object_id]["labels"][k] for w in works])
        for k in range(len(specs))
    ]
    rows = np.concatenate([w.rows for w in works])
    trials = sum(lab.n * lab.spec.trials for lab in labels)
    simulated = sum(int((lab.status != TrialStatus.INVALID).sum()) for lab in labels)
    setup = sum(r["setup_s"] for r in done.values())
    labelling = sum(r["label_s"] for r in done.values())
    timing = {
        "workers": args.workers,
        "objects": len(works),
        "trials": trials,
        "simulated_trials": simulated,
        "wall_s": wall,
        "setup_s": setup,
        "label_s": labelling,
        "trials_per_s": trials / wall if wall > 0 else None,
        "trials_per_s_per_worker": trials / wall / args.workers if wall > 0 else None,
        "trials_per_label_s": trials / labelling if labelling > 0 else None,
        "simulated_trials_per_s": simulated / wall if wall > 0 else None,
    }
    return labels, rows, timing


# --------------------------------------------------------------------------------------------
# Statistics
# --------------------------------------------------------------------------------------------


def wilson(k: int, n: int, z: float = Z95) -> tuple[float | None, float | None]:
    """Wilson score interval of a proportion k / n."""
    if n == 0:
        return None, None
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def rate_entry(
    indicator: np.ndarray, groups: np.ndarray, mask: np.ndarray, seed: int
) -> dict[str, Any]:
    """Count, rate, Wilson and object-resampled 95 % intervals of a 0/1 ``indicator``."""
    n = int(mask.sum())
    k = int(indicator[mask].sum())
    low, high = wilson(k, n)
    obj = object_rate(indicator.astype(np.float64), groups, mask, N_RESAMPLES, seed)
    return {
        "rows": n,
        "objects": obj["objects"],
        "count": k,
        "rate": k / n if n else None,
        "wilson": [low, high],
        "object_ci": [obj["ci_low"], obj["ci_high"]],
    }


def strata(source: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """("all", every row) then each arm present, in :data:`SOURCES` order."""
    out = [("all", np.ones(source.shape, dtype=bool))]
    out += [(name, source == k) for k, name in enumerate(SOURCES) if (source == k).any()]
    return out


def independent_stats(
    bench: Benchmark, rows: np.ndarray, first: GraspLabels, second: GraspLabels, seed: int
) -> dict[str, Any]:
    groups = bench.object_index[rows]
    out: dict[str, Any] = {}
    for level in LEVELS:
        p1, p2 = first.p(level), second.p(level)
        disagree = first.label(level) != second.label(level)
        u1, u2 = first.uncertain(level), second.uncertain(level)
        by: dict[str, Any] = {}
        for name, mask in strata(bench.source[rows]):
            entry = rate_entry(disagree, groups, mask, seed)
            entry["mean_abs_dp"] = float(np.abs(p1 - p2)[mask].mean())
            entry["uncertain"] = [float(u1[mask].mean()), float(u2[mask].mean())]
            entry["uncertain_either"] = float((u1 | u2)[mask].mean())
            entry["label_rate"] = [
                float(first.label(level)[mask].mean()),
                float(second.label(level)[mask].mean()),
            ]
            by[name] = entry
        out[level] = by
    return out


def shipped_stats(
    bench: Benchmark, rows: np.ndarray, fresh: GraspLabels, seed: int
) -> dict[str, Any]:
    stored = bench.labels.select(rows)
    groups = bench.object_index[rows]
    same_status = (stored.status == fresh.status).all(axis=1)
    same_phase = (stored.failing_phase == fresh.failing_phase).all(axis=1)
    out: dict[str, Any] = {
        "rows_identical_status": int(same_status.sum()),
        "rows_identical_phase": int(same_phase.sum()),
        "trials_identical_status": int((stored.status == fresh.status).sum()),
        "trials_identical_phase": int((stored.failing_phase == fresh.failing_phase).sum()),
        "trials": int(stored.status.size),
        "seeds_identical": bool(np.array_equal(stored.seeds, fresh.seeds)),
    }
    nominal = {}
    for name in TrialResults.ARRAY_FIELDS:
        a = np.asarray(getattr(stored.nominal, name))
        b = np.asarray(getattr(fresh.nominal, name))
        if name in FLOAT_FIELDS:
            equal = (a == b) | (np.isnan(a) & np.isnan(b))
            diff = np.abs(np.nan_to_num(a - b, nan=0.0))
            nominal[name] = {
                "rows_differ": int((~equal).reshape(len(a), -1).any(axis=1).sum()),
                "max_abs": float(diff.max()) if diff.size else 0.0,
            }
        else:
            nominal[name] = {"rows_differ": int((a != b).reshape(len(a), -1).any(axis=1).sum())}
    out["nominal"] = nominal
    for level in LEVELS:
        same = stored.label(level) == fresh.label(level)
        dp = np.abs(stored.p(level) - fresh.p(level))
        by: dict[str, Any] = {}
        for name, mask in strata(bench.source[rows]):
            entry = rate_entry(same, groups, mask, seed)
            entry["max_abs_dp"] = float(dp[mask].max())
            entry["mean_abs_dp"] = float(dp[mask].mean())
            by[name] = entry
        out[level] = by
    return out


# --------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------


def pct(value: float | None, digits: int = 1) -> str:
    return "n/a" if value is None else f"{100 * value:.{digits}f}%"


def interval(bounds: list[float | None]) -> str:
    return f"[{pct(bounds[0])}, {pct(bounds[1])}]"


def machine() -> dict[str, str]:
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        cpu = platform.processor() or "unknown"
    return {
        "cpu": cpu,
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "mujoco": mujoco.__version__,
        "platform": platform.platform(),
    }


def header(bench: Benchmark, args: Arguments, rows: np.ndarray, spec: PerturbationSpec) -> str:
    objects = np.unique(bench.object_index[rows]).size
    return (
        f"{args.benchmark}: {len(bench.objects)} objects, {bench.n} rows; K = "
        f"{spec.n_perturbations}, d = {1000 * spec.translation:g} mm, theta = "
        f"{spec.rotation_deg:g} deg\nsample: {rows.size} rows over {objects} objects "
        f"(seed {args.seed}, stratified by arm)"
    )


def print_independent(stats: dict[str, Any], timing: dict[str, Any], args: Arguments) -> None:
    a, b = args.seeds
    if args.perturbations is not None:
        print(
            f"relabelled with K = {args.perturbations} perturbed trials per row (--perturbations)"
        )
    for level in LEVELS:
        print()
        print(f"level {level}: labels of seed {a} vs seed {b}")
        print(
            f"{'arm':10s} {'rows':>5s} {'obj':>4s} {'disagree':>14s} {'Wilson 95%':>18s} "
            f"{'object 95%':>18s} {'mean|dp|':>9s} {'uncertain A/B/either':>22s}"
        )
        for name, e in stats[level].items():
            unc = f"{pct(e['uncertain'][0])}/{pct(e['uncertain'][1])}/{pct(e['uncertain_either'])}"
            print(
                f"{name:10s} {e['rows']:5d} {e['objects']:4d} "
                f"{e['count']:4d} ({pct(e['rate']):>6s}) {interval(e['wilson']):>18s} "
                f"{interval(e['object_ci']):>18s} {e['mean_abs_dp']:9.3f} {unc:>22s}"
            )
    print()
    print(
        f"throughput: {timing['trials']} trials ({timing['simulated_trials']} simulated, the rest "
        f"invalid) over {timing['objects']} objects in {timing['wall_s']:.1f} s wall on "
        f"{timing['workers']} worker(s): {timing['trials_per_s']:.1f} trials/s, "
        f"{timing['trials_per_s_per_worker']:.1f} per worker; inside success_probability "
        f"{timing['trials_per_label_s']:.1f} trials/s per worker (scene load + compile "
        f"{timing['setup_s']:.1f} s in all)"
    )
    for level in LEVELS:
        for name, target in (("all", TARGET_ALL), ("fc_pass", TARGET_FC_PASS)):
            e = stats[level].get(name)
            if e is None:
                print(f"target {level}/{name}: n/a (no {name} rows in the sample)")
                continue
            verdict = "PASS" if e["rate"] <= target else "FAIL"
            print(
                f"target {level:7s} {name:8s} disagreement <= {pct(target, 0)}: {verdict} "
                f"({e['count']}/{e['rows']} = {pct(e['rate'], 2)}, Wilson upper "
                f"{pct(e['wilson'][1])}, object upper {pct(e['object_ci'][1])})"
            )


def print_shipped(stats: dict[str, Any], timing: dict[str, Any], info: dict[str, str]) -> None:
    print(
        f"machine: {info['cpu']}; python {info['python']}, numpy {info['numpy']}, mujoco "
        f"{info['mujoco']}; {info['platform']}"
    )
    print(f"per-row seeds identical to the stored ones: {stats['seeds_identical']}")
    for level in LEVELS:
        print()
        print(f"level {level}: relabelled vs stored")
        print(
            f"{'arm':10s} {'rows':>5s} {'obj':>4s} {'same label':>16s} {'Wilson 95%':>18s} "
            f"{'object 95%':>18s} {'max|dp|':>8s} {'mean|dp|':>9s}"
        )
        for name, e in stats[level].items():
            print(
                f"{name:10s} {e['rows']:5d} {e['objects']:4d} "
                f"{e['count']:5d} ({pct(e['rate'], 2):>7s}) {interval(e['wilson']):>18s} "
                f"{interval(e['object_ci']):>18s} {e['max_abs_dp']:8.3f} {e['mean_abs_dp']:9.4f}"
            )
    rows = stats["full"]["all"]["rows"]
    print()
    print(
        f"per-trial statuses identical: {stats['rows_identical_status']}/{rows} rows, "
        f"{stats['trials_identical_status']}/{stats['trials']} trials; failing phases identical: "
        f"{stats['rows_identical_phase']}/{rows} rows, {stats['trials_identical_phase']}/"
        f"{stats['trials']} trials"
    )
    floats = ", ".join(
        f"{name} {v['rows_differ']} rows (max {v['max_abs']:.3g})"
        for name, v in stats["nominal"].items()
        if name in FLOAT_FIELDS
    )
    codes = ", ".join(
        f"{name} {v['rows_differ']}"
        for name, v in stats["nominal"].items()
        if name not in FLOAT_FIELDS
    )
    print(f"nominal trial, rows that differ: {floats}; {codes}")
    print(
        f"throughput: {timing['trials']} trials in {timing['wall_s']:.1f} s wall on "
        f"{timing['workers']} worker(s): {timing['trials_per_s']:.1f} trials/s, "
        f"{timing['trials_per_s_per_worker']:.1f} per worker"
    )
    for level in LEVELS:
        e = stats[level]["all"]
        verdict = "PASS" if e["rate"] >= TARGET_SHIPPED else "FAIL"
        print(
            f"target {level:7s} identical labels >= {pct(TARGET_SHIPPED, 0)}: {verdict} "
            f"({e['count']}/{e['rows']} = {pct(e['rate'], 2)}, max |dp| {e['max_abs_dp']:.3f})"
        )


def per_row(bench: Benchmark, rows: np.ndarray, named: dict[str, GraspLabels]) -> dict[str, Any]:
    """The sampled rows (file row, object id, arm) and each labelling's p at both levels."""
    return {
        "row": rows.tolist(),
        "object": [bench.objects[int(i)].object_id for i in bench.object_index[rows]],
        "arm": [SOURCES[int(k)] for k in bench.source[rows]],
        **{name: {level: lab.p(level).tolist() for level in LEVELS} for name, lab in named.items()},
    }


# --------------------------------------------------------------------------------------------
# Main
# --------------------------------------------------------------------------------------------


def run(args: Arguments) -> int:
    check(args)
    if not Path(args.benchmark).is_file():
        raise UsageError(f"--benchmark: expected a benchmark file, found no file {args.benchmark}")
    bench = read_benchmark(args.benchmark)
    if args.meshes is None:
        meshes = sorted(o.object_id for o in bench.objects if not o.family and not o.has_mesh)
        if meshes:
            raise UsageError(
                f"{args.benchmark}: expected --meshes DIR (its objects are mesh files, e.g. "
                f"{meshes[0]!r}), found none given"
            )
    spec = bench.labels.spec
    rows = sample_rows(bench, args.rows, args.seed)
    stored_seeds_ok = bool(np.array_equal(file_row_seeds(bench, spec.seed), bench.labels.seeds))
    print(header(bench, args, rows, spec))
    print(
        f"stored per-row seeds == row_seeds({spec.seed}, object id, rows of the object): "
        f"{stored_seeds_ok}"
    )
    report: dict[str, Any] = {
        "mode": args.mode,
        "arguments": {k: getattr(args, k) for k in Arguments.__dataclass_fields__},
        "benchmark": {
            "path": str(args.benchmark),
            "objects": len(bench.objects),
            "rows": bench.n,
            "perturbation": spec.to_dict(),
            "arm_rows": {
                name: int((bench.source == k).sum())
                for k, name in enumerate(SOURCES)
                if (bench.source == k).any()
            },
        },
        "sample": {"rows": rows.size, "objects": int(np.unique(bench.object_index[rows]).size)},
        "stored_seeds_derive_from_row_seeds": stored_seeds_ok,
        "machine": machine(),
    }
    if args.mode == "independent":
        k = spec.n_perturbations if args.perturbations is None else args.perturbations
        specs = tuple(replace(spec, seed=s, n_perturbations=k) for s in args.seeds)
        works = plan_work(bench, rows, [file_row_seeds(bench, s) for s in args.seeds])
        labels, done_rows, timing = relabel(bench, works, specs, args)
        order = np.argsort(done_rows, kind="stable")  # back to sorted row order (already is)
        first, second = (lab.select(order) for lab in labels)
        stats = independent_stats(bench, done_rows[order], first, second, args.seed)
        report["per_row"] = per_row(
            bench,
            done_rows[order],
            {f"seed_{args.seeds[0]}": first, f"seed_{args.seeds[1]}": second},
        )
        print_independent(stats, timing, args)
        targets = {
            level: {
                "all": stats[level]["all"]["rate"] <= TARGET_ALL,
                **(
                    {"fc_pass": stats[level]["fc_pass"]["rate"] <= TARGET_FC_PASS}
                    if "fc_pass" in stats[level]
                    else {}
                ),
            }
            for level in LEVELS
        }
        report["targets"] = {"all": TARGET_ALL, "fc_pass": TARGET_FC_PASS, "pass": targets}
    else:
        works = plan_work(bench, rows, None)
        labels, done_rows, timing = relabel(bench, works, (spec,), args)
        order = np.argsort(done_rows, kind="stable")
        fresh = labels[0].select(order)
        stats = shipped_stats(bench, done_rows[order], fresh, args.seed)
        stored = bench.labels.select(done_rows[order])
        report["per_row"] = per_row(
            bench, done_rows[order], {"stored": stored, "relabelled": fresh}
        )
        print_shipped(stats, timing, report["machine"])
        report["targets"] = {
            "identical_labels": TARGET_SHIPPED,
            "pass": {level: stats[level]["all"]["rate"] >= TARGET_SHIPPED for level in LEVELS},
        }
    report["stats"] = stats
    report["timing"] = timing
    if args.json:
        write_json_atomic(Path(args.json), json_ready(report))
        print(f"wrote {args.json}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    try:
        return run(args)
    except Dg16mError as exc:
        print(f"label_stability: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
