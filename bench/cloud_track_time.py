"""What ``--track cloud`` adds to an evaluation: the cloud observation against the mesh one.

Per object of the first ``--objects`` of the procedural benchmark and of the real one (on one
core), times, ``--repeats`` times (the minimum kept):

* ``load``: rebuilding the benchmark object (both tracks pay it);
* ``mesh``: :func:`dg16m_env.subjects.observation.object_observation` (2048 points and the mesh);
* ``cloud``: :func:`dg16m_env.subjects.cloud_observation.cloud_observation` with the defaults
  (two 128 x 128 ray-cast depth cameras, the ``kinect`` noise model, normals estimated from the
  depth) and with ``noise="none"``;
* the pickled size of each observation (what is sent to the predictor's process);

then, end to end, ``submission_from_predictor`` with a trivial predictor (the mean of the cloud)
on the procedural objects, once per track: the difference divided by the object count is what
the cloud track adds per object with the sandbox (Landlock: a walk from ``/`` and a few hundred
rules, once per child process) included.

Target (issue 54): ``--track cloud`` adds <= 0.5 s per object to an evaluation.

    nice -n 19 .venv/bin/python bench/cloud_track_time.py                  # ~1 min
    .venv/bin/python bench/cloud_track_time.py --objects 10 --out runs/cloud_track_time.json
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import json
import pickle
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

PREDICTOR = """
import numpy as np


def predict(obs):
    centre = np.asarray(obs["points"], dtype=np.float64).mean(axis=0)
    p = np.tile(np.eye(4), (1, 2, 1, 1))
    p[0, 0, :3, 3] = centre + (0.3, 0.0, 0.0)
    p[0, 1, :3, 3] = centre - (0.3, 0.0, 0.0)
    return p
"""


def _best(fn: Callable[[], Any], repeats: int) -> tuple[float, Any]:
    """The least wall time of ``repeats`` calls (s) and the last value."""
    times, value = [], None
    for _ in range(repeats):
        started = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - started)
    return min(times), value


def per_object(benchmark: str | None, n: int, repeats: int) -> dict[str, Any]:
    """Times (s) and sizes (bytes) per object of the first ``n`` objects of a benchmark."""
    from dg16m_env.evaluators import load_benchmark_ref
    from dg16m_env.subjects.cloud_observation import CloudTrack, cloud_observation
    from dg16m_env.subjects.observation import object_observation

    ref = load_benchmark_ref(benchmark)
    rows = []
    ideal = CloudTrack(noise="none")
    for obj in ref.benchmark.objects[:n]:
        load_s, grasp_object = _best(lambda o=obj: o.load(ref.mesh_root), repeats)
        mesh_s, mesh = _best(lambda g=grasp_object: object_observation(g), repeats)
        cloud_s, cloud = _best(lambda g=grasp_object: cloud_observation(g), repeats)
        ideal_s, _ = _best(lambda g=grasp_object: cloud_observation(g, ideal), repeats)
        rows.append(
            {
                "object_id": obj.object_id,
                "load_s": load_s,
                "mesh_s": mesh_s,
                "cloud_s": cloud_s,
                "cloud_ideal_s": ideal_s,
                "mesh_bytes": len(pickle.dumps(mesh)),
                "cloud_bytes": len(pickle.dumps(cloud)),
                "cloud_points": len(cloud["points"]),
            }
        )
    summary: dict[str, Any] = {"objects": len(rows)}
    for key in ("load_s", "mesh_s", "cloud_s", "cloud_ideal_s", "mesh_bytes", "cloud_bytes"):
        values = [r[key] for r in rows]
        summary[key] = {
            "median": statistics.median(values),
            "mean": statistics.fmean(values),
            "max": max(values),
        }
    summary["cloud_minus_mesh_s_mean"] = summary["cloud_s"]["mean"] - summary["mesh_s"]["mean"]
    summary["cloud_over_mesh_ratio"] = summary["cloud_s"]["mean"] / summary["mesh_s"]["mean"]
    return {"summary": summary, "rows": rows}


def end_to_end(n: int) -> dict[str, Any]:
    """Wall seconds of ``submission_from_predictor`` with a trivial predictor on the first ``n``
    procedural objects, per track, and the difference per object."""
    from dg16m_env.evaluators import load_benchmark_ref
    from dg16m_env.subjects.predictor import submission_from_predictor
    from dg16m_env.subjects.predictor_process import PredictorSpec

    ref = load_benchmark_ref(None).first(n)
    out: dict[str, Any] = {"objects": n}
    with tempfile.TemporaryDirectory() as folder:
        file = Path(folder) / "trivial_predictor.py"
        file.write_text(PREDICTOR)
        for track in ("mesh", "cloud"):
            started = time.perf_counter()
            _, run = submission_from_predictor(
                PredictorSpec(f"{file}:predict"),
                Path(folder) / f"{track}.h5",
                benchmark=ref,
                track=track,
                progress=False,
            )
            out[f"{track}_s"] = time.perf_counter() - started
            out[f"{track}_failed"] = len(run.errors)
            out[f"{track}_sandbox"] = run.sandbox
    out["added_per_object_s"] = (out["cloud_s"] - out["mesh_s"]) / n
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", type=int, default=20, help="objects per benchmark")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=None, help="write the numbers as JSON")
    args = parser.parse_args()
    report = {
        "procedural": per_object(None, args.objects, args.repeats),
        "real": per_object("real", args.objects, args.repeats),
        "end_to_end": end_to_end(args.objects),
    }
    for name in ("procedural", "real"):
        s = report[name]["summary"]
        print(
            f"{name:<10} {s['objects']} objects: mesh {s['mesh_s']['mean'] * 1e3:.1f} ms, cloud "
            f"{s['cloud_s']['mean'] * 1e3:.1f} ms (max {s['cloud_s']['max'] * 1e3:.1f}, ideal "
            f"{s['cloud_ideal_s']['mean'] * 1e3:.1f}) per object, ratio "
            f"{s['cloud_over_mesh_ratio']:.1f}x, added {s['cloud_minus_mesh_s_mean'] * 1e3:.1f} "
            f"ms; pickled {s['mesh_bytes']['mean'] / 1e3:.0f} kB vs "
            f"{s['cloud_bytes']['mean'] / 1e3:.0f} kB"
        )
    e = report["end_to_end"]
    print(
        f"end to end, {e['objects']} objects, trivial predictor: mesh {e['mesh_s']:.2f} s, cloud "
        f"{e['cloud_s']:.2f} s ({e['cloud_sandbox']}): {e['added_per_object_s'] * 1e3:.0f} ms "
        "added per object (target <= 500 ms)"
    )
    if args.out is not None:
        from dg16m_core.atomic import write_text_atomic

        write_text_atomic(args.out, json.dumps(report, indent=1) + "\n")
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
