"""Scoring speed of the grasp-pair classifiers on one CPU core: N candidate dual grasps of one
object, against references measured in the same run.

For one object of the embedded procedural benchmark (``--object``, default the first: a 1.2 m
table), its observation cloud (``--points`` points, the evaluator's default 2048) and ``--n``
synthetic candidate dual grasps (each hand's grasp centre 1-3 cm inside the surface at a random
cloud point, approaching along the inward normal, closing axis random about it), times, with
``torch.set_num_threads(--threads)``, ``--repeats`` times after a warm-up (min and median):

* ``dual_pointnet_gpd`` and ``cgdf_classifier`` with their default configurations (seed 0),
  eval mode, ``torch.no_grad()``: one ``model(points, poses)`` call for all N grasps, the call
  the ``classifier`` evaluator makes (it chunks by its ``batch_size``, 4096 by default);
* CGDF's once-per-object part alone (the same call with one grasp);
* references: ``torch.cdist`` between the 2N grasp centres and the cloud (same sizes as
  Dual-PointNetGPD's crop search) and a fixed 1024 x 1024 float32 numpy matmul, with the ratio
  of each model's time to them (the machine is shared and noisy; ratios travel better).

Target: CGDF under 2 s for N = 10,000 on one core.

    nice -n 19 .venv/bin/python bench/classifier_scoring.py                # ~1 min
    .venv/bin/python bench/classifier_scoring.py --n 2000 --repeats 1 --out runs/scoring.json
"""

from __future__ import annotations

import os

# One core: no BLAS or OpenMP threads (set before numpy and torch are imported).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from baselines.cgdf_classifier import CGDFClassifier
from baselines.dual_pointnet_gpd import DualPointNetGPD
from baselines.grasp_geometry import count_parameters, grasp_centre_local
from dg16m_core.atomic import write_json_atomic
from dg16m_env.evaluators import load_benchmark_ref
from dg16m_env.subjects.observation import object_observation

TARGET_S = 2.0
"""CGDF's target for N = 10,000 grasps on one core (s)."""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=10_000, help="dual grasps to score")
    parser.add_argument("--points", type=int, default=2048, help="points in the cloud")
    parser.add_argument("--object", type=int, default=0, help="benchmark object index")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per measurement")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--seed", type=int, default=0, help="seed of the synthetic grasps")
    parser.add_argument("--out", type=Path, default=None, help="optional JSON results file")
    args = parser.parse_args(argv)
    for name in ("n", "points", "repeats", "threads"):
        if getattr(args, name) < 1:
            parser.error(f"--{name}: expected a positive integer, found {getattr(args, name)}")
    return args


def candidate_poses(
    points: np.ndarray, normals: np.ndarray, n: int, rng: np.random.Generator
) -> np.ndarray:
    """(n, 2, 4, 4) float32 dual grasps near the surface (see the module docstring)."""
    pick = rng.integers(len(points), size=(n, 2))
    approach = -normals[pick].astype(np.float64)  # +y: into the object
    approach /= np.linalg.norm(approach, axis=-1, keepdims=True)
    guess = rng.normal(size=(n, 2, 3))
    closing = guess - approach * (guess * approach).sum(-1, keepdims=True)
    closing /= np.linalg.norm(closing, axis=-1, keepdims=True)
    rotation = np.stack([closing, approach, np.cross(closing, approach)], axis=-1)
    depth = rng.uniform(0.01, 0.03, size=(n, 2, 1))
    centre = points[pick] + depth * approach
    poses = np.zeros((n, 2, 4, 4))
    poses[..., :3, :3] = rotation
    poses[..., :3, 3] = centre - rotation @ grasp_centre_local()
    poses[..., 3, 3] = 1.0
    return poses.astype(np.float32)


def timed(fn: Callable[[], Any], repeats: int) -> dict[str, float]:
    """Min and median wall time of ``fn`` (s) over ``repeats`` calls after one warm-up."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return {"min_s": min(times), "median_s": statistics.median(times)}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    args = parse_args(argv)
    torch.set_num_threads(args.threads)
    ref = load_benchmark_ref()
    item = ref.benchmark.objects[args.object]
    observation = object_observation(item.load(), n_points=args.points)
    rng = np.random.default_rng(args.seed)
    poses_np = candidate_poses(observation["points"], observation["normals"], args.n, rng)
    points = torch.from_numpy(observation["points"])
    poses = torch.from_numpy(poses_np)
    extent = np.ptp(observation["bounds"], axis=0)
    print(
        f"object {observation['object_id']} ({observation['family']}, "
        f"{extent[0]:.2f} x {extent[1]:.2f} x {extent[2]:.2f} m), {args.points} points, "
        f"{args.n} dual grasps, {args.threads} thread(s), best of {args.repeats}"
    )

    centres = torch.from_numpy(
        (poses_np[..., :3, :3] @ grasp_centre_local().astype(np.float32) + poses_np[..., :3, 3])
        .reshape(-1, 3)
        .copy()
    )
    a = np.random.default_rng(1).random((1024, 1024), dtype=np.float32)
    references = {
        "cdist": timed(lambda: torch.cdist(centres, points), args.repeats),
        "matmul_1024": timed(lambda: a @ a, args.repeats),
    }
    print(
        f"reference: torch.cdist ({len(centres)} x {len(points)}) "
        f"{references['cdist']['min_s'] * 1e3:.1f} ms; numpy 1024^2 matmul "
        f"{references['matmul_1024']['min_s'] * 1e3:.1f} ms"
    )

    models: dict[str, Any] = {}
    for model in (DualPointNetGPD(), CGDFClassifier()):
        model.eval()
        with torch.no_grad():
            timing = timed(lambda m=model: m(points, poses), args.repeats)
            entry: dict[str, Any] = {
                "parameters": count_parameters(model),
                "config": model.config.to_dict(),
                **timing,
                "grasps_per_s": args.n / timing["min_s"],
                "ratio_to_cdist": timing["min_s"] / references["cdist"]["min_s"],
                "ratio_to_matmul_1024": timing["min_s"] / references["matmul_1024"]["min_s"],
            }
            if isinstance(model, CGDFClassifier):
                entry["per_object"] = timed(lambda m=model: m(points, poses[:1]), args.repeats)
        if args.n == 10_000:
            entry["meets_2s_target"] = timing["min_s"] < TARGET_S
        models[model.name] = entry
        extra = (
            f", once per object {entry['per_object']['min_s'] * 1e3:.0f} ms"
            if "per_object" in entry
            else ""
        )
        print(
            f"{model.name:>18}: {timing['min_s']:.3f} s (median {timing['median_s']:.3f} s) "
            f"for {args.n} grasps = {entry['grasps_per_s']:,.0f} grasps/s; "
            f"{entry['ratio_to_cdist']:.1f} x cdist, {entry['ratio_to_matmul_1024']:.0f} x "
            f"matmul; {entry['parameters']:,} parameters{extra}"
        )
    if args.n == 10_000:
        for name, entry in models.items():
            verdict = "meets" if entry["meets_2s_target"] else "misses"
            print(f"{name} {verdict} the {TARGET_S:g} s target for 10,000 grasps on one core")

    result = {
        "n": args.n,
        "points": args.points,
        "threads": args.threads,
        "repeats": args.repeats,
        "object_id": observation["object_id"],
        "torch": torch.__version__,
        "references": references,
        "models": models,
    }
    if args.out is not None:
        write_json_atomic(args.out, result)
        print(f"wrote {args.out}")
    return result


if __name__ == "__main__":
    main()
