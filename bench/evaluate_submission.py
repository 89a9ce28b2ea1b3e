"""Wall time of ``fce`` + ``gsr`` on a whole-benchmark submission (target: 300 objects x 10 dual
grasps in under 5 minutes on 2 cores), with a same-run reference.

The submission is a file given with ``--submission`` (e.g. a reference submission from
``dg16m baselines submissions``) or, by default, the benchmark's own first ``--k`` rows of each
object (its force-closure-passing pairs: most of them hold, so every trial runs all 14 phases,
the slowest case). In one run (the machine is shared and noisy, so the reference shares it):

* **reference**: ``gsr`` in this process (``workers=1``) on the first ``--reference-objects``
  objects, giving the per-core labelling rate (trials/s) at this moment;
* **fce** and **gsr** with ``--workers`` processes on every object, timed separately.

Prints the wall times, the total against the 300 s target, the parallel trials/s and the ratio
of the parallel rate to the per-core reference (the parallel speed-up; 2 cores ideally give 2).

    nice -n 19 .venv/bin/python bench/evaluate_submission.py --workers 2   # ~5 min
    .venv/bin/python bench/evaluate_submission.py --limit 20 --workers 2   # a quick look
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import tempfile
import time
from pathlib import Path

from dg16m_core.atomic import write_json_atomic
from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.evaluators import load_benchmark_ref, make
from dg16m_env.subjects.submission import Submission

TARGET_S = 300.0


def _first_rows(ref, k: int) -> Submission:
    bench = ref.benchmark
    poses = {i: bench.poses[bench.object_rows(i)[:k]] for i in ref.object_ids}
    return Submission(poses=poses, benchmark=ref.sha256, metadata={"source": f"first {k} rows"})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--submission", type=Path, default=None)
    parser.add_argument("--k", type=int, default=10, help="rows per object of the default")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--limit", type=int, default=None, help="only the first N objects")
    parser.add_argument("--reference-objects", type=int, default=3)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        path = EMBEDDED_BENCHMARK
        if args.limit is not None:
            bench = read_benchmark(EMBEDDED_BENCHMARK)
            path = Path(tmp) / "benchmark.h5"
            ids = [o.object_id for o in bench.objects[: args.limit]]
            write_benchmark(path, bench.select_objects(ids))
        ref = load_benchmark_ref(path)
        subject = args.submission if args.submission is not None else _first_rows(ref, args.k)

        small_path = Path(tmp) / "reference.h5"
        ids = ref.object_ids[: args.reference_objects]
        write_benchmark(small_path, ref.benchmark.select_objects(ids))
        small = load_benchmark_ref(small_path)
        started = time.perf_counter()
        reference = make("gsr", benchmark=small).evaluate(_first_rows(small, args.k))
        reference_s = time.perf_counter() - started
        per_core = reference.details["trials"] / reference_s

        started = time.perf_counter()
        fce = make("fce", benchmark=ref, workers=args.workers, progress=True).evaluate(subject)
        fce_s = time.perf_counter() - started
        started = time.perf_counter()
        gsr = make("gsr", benchmark=ref, workers=args.workers, progress=True).evaluate(subject)
        gsr_s = time.perf_counter() - started

    total = fce_s + gsr_s
    rate = gsr.details["trials"] / gsr_s
    report = {
        "objects": len(ref.object_ids),
        "dual_grasps": gsr.metrics["gsr"]["rows"],
        "trials": gsr.details["trials"],
        "workers": args.workers,
        "fce_s": fce_s,
        "gsr_s": gsr_s,
        "total_s": total,
        "target_s": TARGET_S,
        "gsr_trials_per_s": rate,
        "reference_trials_per_s_per_core": per_core,
        "parallel_speedup": rate / per_core,
        "fce": fce.metrics["fce"]["rate"],
        "gsr": gsr.metrics["gsr"]["rate"],
        "gsr_gravity": gsr.metrics["gsr_gravity"]["rate"],
    }
    print(
        f"{report['objects']} objects, {report['dual_grasps']} dual grasps, "
        f"{report['trials']} trials, {args.workers} workers"
    )
    print(f"fce  {fce_s:7.1f} s   (FCE {report['fce']:.3f})")
    print(f"gsr  {gsr_s:7.1f} s   (GSR {report['gsr']:.3f}, gravity {report['gsr_gravity']:.3f})")
    print(
        f"total {total:6.1f} s   target {TARGET_S:.0f} s: {'met' if total < TARGET_S else 'MISSED'}"
    )
    print(
        f"gsr {rate:.1f} trials/s on {args.workers} workers; reference {per_core:.1f} trials/s "
        f"on one core in this run; ratio {rate / per_core:.2f}"
    )
    if args.json is not None:
        write_json_atomic(args.json, report)


if __name__ == "__main__":
    main()
