"""Real meshes end to end: decomposition, validity, trial rate and success per arm, beside procedural.

For every mesh of ``--meshes`` (default: the shipped ``tests/data/meshes``, in metres, and, when present, the
ACRONYM table and mug of ``../shared/data/real`` scaled to 0.8 m and 0.5 m) and for ``--procedural``
objects of the procedural benchmark split (the first of each family), one process, one
core, in the same run:

1. **decomposition** (meshes): CoACD with the default :class:`DecompositionParameters` into a fresh
   cache (time measured), again from the cache (time measured), and the hull-to-mesh deviation
   (:func:`dataset_gen.objects.decomposition.decomposition_report`);
2. **pairs** exactly as ``dg16m benchmark build --robust N`` draws them (:func:`sampled_pairs`:
   the open-hand clearance rule against the same parts, the paper's four arms and ``fc_robust``);
3. **labels**: :func:`dg16m_env.physics.labels.success_probability` (nominal + K perturbed trials);
   trials/s = trials / seconds of that call.

Prints per object: hulls, deviation p95 / max (mm), decomposition seconds (fresh, cached), trials/s,
invalid share of the nominal trials of force-closure-passing pairs and of all pairs, and GSR (mean
success probability, full protocol; invalid = 0) per arm. Then the means over the real meshes and
over the procedural objects, and the ratio of their trial rates (the target: real >= half the
procedural rate).

    nice -n 19 .venv/bin/python bench/real_meshes.py                    # ~10-15 min
    .venv/bin/python bench/real_meshes.py --procedural 3 --perturbations 2 --json runs/real.json
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from dataset_gen.objects.decomposition import decomposition_report, object_parts
from dataset_gen.sources.object_source import ObjectSource, mesh_sources, object_seed
from dg16m_core.atomic import write_json_atomic
from dg16m_core.json_values import json_ready
from dg16m_env.benchmark.arms import sampled_pairs
from dg16m_env.benchmark.model import SOURCES, BenchmarkParameters
from dg16m_env.benchmark.sources import procedural_benchmark_sources
from dg16m_env.physics.labels import PerturbationSpec, row_seeds, success_probability
from dg16m_env.physics.scene import compile_scene

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "data" / "real"
ARMS = ("fc_pass", "fc_robust", "fc_fail", "random", "farthest")


ACRONYM = {"acronym_table_99cf659a": 0.8, "acronym_mug_10f6e090": 0.5}
"""ACRONYM meshes of ``../shared/data/real`` and the longest side they are scaled to (m)."""


def default_meshes() -> list[Path]:
    return sorted((ROOT / "tests" / "data" / "meshes").glob("*.obj"))


def measure(source: ObjectSource, params: BenchmarkParameters) -> dict[str, Any]:
    """One object's row of the table (see the module docstring)."""
    obj = source.load(params.mass)
    out: dict[str, Any] = {"object": source.object_id, "faces": len(obj.mesh.faces)}
    if obj.parts:
        parts = obj.parts
        out.update(hulls=len(parts), kind="procedural")
    else:
        start = time.perf_counter()
        parts = object_parts(obj)
        out["decomposition_s"] = time.perf_counter() - start
        start = time.perf_counter()
        object_parts(obj)
        out["cached_s"] = time.perf_counter() - start
        report = decomposition_report(obj.mesh, parts).to_dict()
        out.update(kind="mesh", hulls=len(parts), deviation=report)
    rng = np.random.default_rng(object_seed(params.seed, f"benchmark:{obj.object_id}"))
    start = time.perf_counter()
    rows = sampled_pairs(obj, params, rng)
    out["pairs_s"] = time.perf_counter() - start
    scene = compile_scene(obj, params=params.scene, parts=parts)
    n = len(rows["poses"])
    start = time.perf_counter()
    labels = success_probability(
        scene,
        rows["poses"],
        spec=params.perturbation,
        seeds=row_seeds(params.perturbation.seed, obj.object_id, n),
        protocol=params.protocol,
    )
    seconds = time.perf_counter() - start
    trials = n * params.perturbation.trials
    out["trials"] = trials
    out["trials_per_s"] = trials / seconds
    valid = labels.nominal.valid
    p = labels.p_success
    out["arms"] = {}
    for arm in ARMS:
        mask = rows["source"] == SOURCES.index(arm)
        if mask.any():
            out["arms"][arm] = {
                "pairs": int(mask.sum()),
                "gsr": float(p[mask].mean()),
                "gsr_gravity": float(labels.p_gravity[mask].mean()),
                "invalid": float((~valid[mask]).mean()),
            }
    out["invalid_all"] = float((~valid).mean())
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--meshes", type=Path, nargs="*", default=None)
    parser.add_argument("--procedural", type=int, default=10)
    parser.add_argument("--robust", type=int, default=40, help="fc_robust pairs per object")
    parser.add_argument("--perturbations", type=int, default=PerturbationSpec().n_perturbations)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)

    params = BenchmarkParameters(
        n_robust=args.robust, perturbation=PerturbationSpec(n_perturbations=args.perturbations)
    )
    procedural: list[ObjectSource] = []
    for item in procedural_benchmark_sources():  # the first object of each family
        if len(procedural) < args.procedural and item.source.family not in {
            s.family for s in procedural
        }:
            procedural.append(item.source)
    results = []
    with tempfile.TemporaryDirectory() as work:
        folder = Path(work) / "meshes"
        folder.mkdir()
        for path in args.meshes if args.meshes is not None else default_meshes():
            shutil.copy(path, folder / path.name)
        if args.meshes is None:
            for name, size in ACRONYM.items():  # in their own units: scale to a dual-arm size
                if (SHARED / f"{name}.obj").is_file():
                    mesh = trimesh.load(SHARED / f"{name}.obj", force="mesh")
                    mesh.apply_scale(size / float(np.max(mesh.extents)))
                    mesh.export(folder / f"{name}.obj")
        os.environ["DG16M_CACHE_DIR"] = str(Path(work) / "cache")  # fresh: real CoACD times
        for source in mesh_sources(folder) + procedural:
            row = measure(source, params)
            results.append(row)
            print(format_row(row), flush=True)
    summary = summarise(results)
    print(summary["text"])
    if args.json:
        write_json_atomic(args.json, json_ready({"rows": results, "summary": summary}))
    return 0


def format_row(row: dict[str, Any]) -> str:
    dev = row.get("deviation")
    dev_text = (
        f"{1e3 * dev['deviation_p95']:5.2f}/{1e3 * dev['deviation_max']:5.2f} mm"
        if dev
        else "    exact     "
    )
    decomp = (
        f"{row['decomposition_s']:5.1f} s ({row['cached_s']:.2f} s cached)"
        if "decomposition_s" in row
        else "        -            "
    )
    arms = "  ".join(
        f"{arm} {100 * a['gsr']:5.1f}%"
        + (f" inv {100 * a['invalid']:.0f}%" if a["invalid"] else "")
        for arm, a in row["arms"].items()
    )
    return (
        f"{row['object']:<24} hulls {row['hulls']:>3}  dev {dev_text}  decomp {decomp}  "
        f"{row['trials_per_s']:6.1f} trials/s  invalid {100 * row['invalid_all']:4.1f}%  {arms}"
    )


def summarise(results: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    lines = []
    for kind in ("mesh", "procedural"):
        rows = [r for r in results if r["kind"] == kind]
        if not rows:
            continue
        entry: dict[str, Any] = {
            "objects": len(rows),
            "trials_per_s": float(np.mean([r["trials_per_s"] for r in rows])),
            "invalid_all": float(np.mean([r["invalid_all"] for r in rows])),
            "arms": {},
        }
        for arm in ARMS:  # pooled over the arm's pairs (GSR is a mean over grasps)
            values = [r["arms"][arm] for r in rows if arm in r["arms"]]
            if values:
                pairs = np.array([v["pairs"] for v in values], dtype=np.float64)
                entry["arms"][arm] = {
                    "objects": len(values),
                    "pairs": int(pairs.sum()),
                    "gsr": float(np.average([v["gsr"] for v in values], weights=pairs)),
                    "invalid": float(np.average([v["invalid"] for v in values], weights=pairs)),
                }
        out[kind] = entry
        arms = "  ".join(
            f"{arm} {100 * a['gsr']:.1f}% ({a['pairs']} pairs on {a['objects']} objects, "
            f"invalid {100 * a['invalid']:.1f}%)"
            for arm, a in entry["arms"].items()
        )
        lines.append(
            f"{kind:<10} {entry['objects']} objects, {entry['trials_per_s']:.1f} trials/s, "
            f"invalid {100 * entry['invalid_all']:.1f}%: {arms}"
        )
    if "mesh" in out and "procedural" in out:
        ratio = out["mesh"]["trials_per_s"] / out["procedural"]["trials_per_s"]
        out["trial_rate_ratio"] = ratio
        lines.append(f"trial rate, real meshes / procedural: {ratio:.2f} (target >= 0.5)")
    out["text"] = "\n".join(lines)
    return out


if __name__ == "__main__":
    raise SystemExit(main())
