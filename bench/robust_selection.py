"""Does the disturbance motion ratio (dataset_gen.grasps.robust) predict simulated success? No new trials.

Reads a benchmark file (default: the shipped procedural one), computes every row's disturbance
motion ratio from its stored contacts and its object's mass properties, and sets it beside the
stored success probabilities: per arm, the share of rows the robust criterion keeps (ratio <= 1),
their mean success against the rest, the ranking quality (ROC AUC of -ratio against the binary
label) and, for comparison, the same for the simpler predictor the criterion explains: the
distance from the centre of mass to the hand line. ``--plot`` draws mean success against the
ratio per arm. It also times the criterion against the paper's own gravity-only check on the same
pairs (a ratio measured in the same run).

    .venv/bin/python bench/robust_selection.py
    .venv/bin/python bench/robust_selection.py --benchmark runs/mine/benchmark.h5 \
        --meshes meshes/ --json runs/robust.json --plot runs/robust.png
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from baselines.da2_labels import roc_auc
from dataset_gen.force_closure import evaluate
from dataset_gen.grasps.robust import disturbance_motion
from dg16m_core.atomic import write_json_atomic
from dg16m_core.json_values import json_ready
from dg16m_env.benchmark.file import read_benchmark
from dg16m_env.benchmark.model import SOURCES
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK

BINS = (0.0, 0.25, 0.5, 1.0, 2.0, 4.0, np.inf)


def hand_line_distance(points: np.ndarray, com: np.ndarray) -> np.ndarray:
    """(N,) distance from ``com`` to the line through the two hands' contact midpoints (m)."""
    a = points[:, 0:2].mean(axis=1)
    b = points[:, 2:4].mean(axis=1)
    u = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    v = com - a
    return np.linalg.norm(v - np.einsum("ij,ij->i", v, u)[:, None] * u, axis=1)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--benchmark", type=Path, default=EMBEDDED_BENCHMARK)
    parser.add_argument("--meshes", type=Path, default=None, help="mesh folder of mesh objects")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--plot", type=Path, default=None)
    args = parser.parse_args(argv)

    bench = read_benchmark(args.benchmark)
    params = bench.parameters()
    protocol = params.protocol.disturbances()
    ratio = np.full(bench.n, np.nan)
    distance = np.full(bench.n, np.nan)
    robust_seconds = paper_seconds = 0.0
    for index, item in enumerate(bench.objects):
        props = item.load(args.meshes).mass_properties
        rows = bench.object_rows(item.object_id)
        points, normals = bench.contact_points[rows], bench.contact_normals[rows]
        if not np.all(np.isfinite(normals)):
            print(f"{item.object_id}: no stored normals (a DG16M file's pairs); skipped")
            continue
        start = time.perf_counter()
        motion = disturbance_motion(
            points,
            normals,
            center_of_mass=props.center_of_mass,
            inertia=props.inertia * (params.mass / props.mass),
            protocol=protocol,
            **params.force_closure_kwargs(),
        )
        robust_seconds += time.perf_counter() - start
        start = time.perf_counter()
        evaluate(points, normals, **params.force_closure_kwargs())
        paper_seconds += time.perf_counter() - start
        ratio[rows] = motion.ratio
        distance[rows] = hand_line_distance(points, props.center_of_mass)
        print(f"\r{index + 1}/{len(bench.objects)} objects", end="", file=sys.stderr)
    print(file=sys.stderr)

    p, label = bench.p(), bench.label()
    report: dict[str, Any] = {"benchmark": str(args.benchmark), "arms": {}}
    print(f"{'arm':<10} {'rows':>6} {'kept':>6} {'p kept':>7} {'p rest':>7} {'p all':>6} "
          f"{'AUC ratio':>9} {'AUC dist':>8}")  # fmt: skip
    for arm in SOURCES:
        rows = np.flatnonzero((bench.source == SOURCES.index(arm)) & np.isfinite(distance))
        if rows.size == 0:
            continue
        kept = ratio[rows] <= 1.0
        score = -np.where(np.isfinite(ratio[rows]), ratio[rows], 1e9)
        entry = {
            "rows": int(rows.size),
            "kept": int(kept.sum()),
            "mean_p_kept": float(p[rows][kept].mean()) if kept.any() else None,
            "mean_p_rest": float(p[rows][~kept].mean()) if (~kept).any() else None,
            "mean_p": float(p[rows].mean()),
            "auc_ratio": roc_auc(score, label[rows]),
            "auc_hand_line_distance": roc_auc(-distance[rows], label[rows]),
            "by_ratio": [
                {
                    "bin": [lo, hi],
                    "rows": int(m.sum()),
                    "mean_p": float(p[rows][m].mean()) if m.any() else None,
                }
                for lo, hi in itertools.pairwise(BINS)
                for m in [(ratio[rows] > lo) & (ratio[rows] <= hi) if lo > 0 else ratio[rows] <= hi]
            ],
        }
        report["arms"][arm] = entry

        def fmt(value: float | None) -> str:
            return "    -  " if value is None else f"{value:7.3f}"

        print(
            f"{arm:<10} {entry['rows']:>6} {entry['kept']:>6} {fmt(entry['mean_p_kept'])} "
            f"{fmt(entry['mean_p_rest'])} {entry['mean_p']:6.3f} {entry['auc_ratio']:9.3f} "
            f"{entry['auc_hand_line_distance']:8.3f}"
        )
    report["seconds"] = {"robust": robust_seconds, "paper": paper_seconds}
    report["time_ratio_robust_over_paper"] = robust_seconds / max(paper_seconds, 1e-9)
    print(
        f"time: robust criterion {robust_seconds:.2f} s, the paper's check on the same pairs "
        f"{paper_seconds:.2f} s (ratio {report['time_ratio_robust_over_paper']:.1f})"
    )
    if args.json:
        write_json_atomic(args.json, json_ready(report))
    if args.plot:
        from matplotlib.figure import Figure

        fig = Figure(figsize=(7, 4.5), constrained_layout=True)
        ax = fig.add_subplot()
        centres = np.arange(len(BINS) - 1)
        for arm, entry in report["arms"].items():
            values = [b["mean_p"] if b["rows"] >= 10 else np.nan for b in entry["by_ratio"]]
            ax.plot(centres, values, marker="o", label=f"{arm} ({entry['rows']} rows)")
        ax.set_xticks(centres)
        ax.set_xticklabels(
            [
                f"{lo:g}-{hi:g}" if np.isfinite(hi) else f"> {lo:g}"
                for lo, hi in itertools.pairwise(BINS)
            ]
        )
        ax.axvline(2.5, color="grey", linestyle=":", label="robust: ratio <= 1")
        ax.set_xlabel("disturbance motion ratio (predicted motion / protocol bound)")
        ax.set_ylabel("mean success probability (simulated)")
        ax.set_ylim(0, 1.02)
        ax.legend(fontsize=8)
        fig.savefig(args.plot, dpi=120)
        print(f"plot: {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
