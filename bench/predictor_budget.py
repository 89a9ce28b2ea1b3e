"""How close the shipped pairing baselines come to the predictor's per-object time limit.

``dg16m evaluate --predictor`` gives each call of a predictor ``--time-limit`` seconds (default
:data:`DEFAULT_TIME_LIMIT_S`); an object whose call runs over scores 0 (it never leaves the
denominator). This script runs the paper's pairing baselines (``baselines.pairing_baselines``: random,
farthest and force-closure pairing) in this process on every object of a benchmark, one core,
and prints each baseline's median, 99th percentile and largest seconds per object, the slowest
objects, and the headroom: the limit divided by the largest time (the machine is shared: the
headroom says how much slower a machine may be before a shipped baseline loses an object).

    .venv/bin/python bench/predictor_budget.py --benchmark real          # ~8 minutes
    .venv/bin/python bench/predictor_budget.py --benchmark procedural --limit 50
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import time
from dataclasses import dataclass

import numpy as np

from baselines.pairing_baselines import farthest_baseline, force_closure_baseline, random_baseline
from dg16m_core.progress import progress_bar
from dg16m_env.benchmark import load_benchmark_ref
from dg16m_env.envs.objects import BenchmarkObjects
from dg16m_env.subjects.observation import object_observation
from dg16m_env.subjects.predictor_process import PredictorSpec

DEFAULT_TIME_LIMIT_S = PredictorSpec("baselines.pairing_baselines:random_baseline").time_limit_s
BASELINES = {
    "random": random_baseline,
    "farthest": farthest_baseline,
    "force_closure": force_closure_baseline,
}


@dataclass
class Arguments:
    benchmark: str = "real"
    limit: int | None = None
    slowest: int = 5


def parse() -> Arguments:
    defaults = Arguments()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--benchmark", default=defaults.benchmark)
    parser.add_argument("--limit", type=int, default=defaults.limit, help="first N objects")
    parser.add_argument("--slowest", type=int, default=defaults.slowest)
    return Arguments(**vars(parser.parse_args()))


def main() -> None:
    args = parse()
    ref = load_benchmark_ref(args.benchmark)
    objects = BenchmarkObjects(ref)
    ids = ref.object_ids[: args.limit] if args.limit else ref.object_ids
    # warm-up outside the timings: the compiled kernels (force closure, jaw rays)
    warm = object_observation(objects.load(ids[0]))
    for predict in BASELINES.values():
        predict(warm)
    seconds = {name: np.zeros(len(ids)) for name in BASELINES}
    for i, object_id in enumerate(progress_bar(ids, desc="objects", unit="object")):
        observation = object_observation(objects.load(object_id))
        for name, predict in BASELINES.items():
            start = time.perf_counter()
            predict(observation)
            seconds[name][i] = time.perf_counter() - start
    load = os.getloadavg()
    print(
        f"{args.benchmark}: {len(ids)} objects, one core, load average "
        f"{load[0]:.1f} / {load[1]:.1f} (1 / 5 min); per-object limit {DEFAULT_TIME_LIMIT_S:.0f} s"
    )
    worst = 0.0
    for name, values in seconds.items():
        order = np.argsort(values)[::-1][: args.slowest]
        slowest = ", ".join(f"{ids[j]} {values[j]:.1f} s" for j in order)
        worst = max(worst, float(values.max()))
        print(
            f"  {name:14s} median {np.median(values):5.2f} s  p99 {np.percentile(values, 99):5.2f} s"
            f"  max {values.max():5.2f} s  (slowest: {slowest})"
        )
    print(f"headroom: the limit is {DEFAULT_TIME_LIMIT_S / worst:.0f}x the slowest call")


if __name__ == "__main__":
    main()
