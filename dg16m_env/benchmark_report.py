"""Readable summaries of a benchmark: text, per-family rates and a figure."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from dg16m_env.benchmark import SOURCES, Benchmark
from dg16m_env.trial import PHASES


def _rate(values: np.ndarray) -> float | None:
    return float(values.mean()) if values.size else None


def summary_by_family(bench: Benchmark) -> dict[str, dict[str, Any]]:
    """Per object family ("" -> "mesh"): pairs, valid trials and success rates of
    force-closure-passing pairs and random pairs."""
    families = np.array([o.family or "mesh" for o in bench.objects])[bench.object_index]
    valid = bench.trials.valid
    random_rows = bench.source == SOURCES.index("random")
    out: dict[str, dict[str, Any]] = {}
    for family in sorted(set(families.tolist())):
        rows = (families == family) & valid
        out[family] = {
            "objects": len({int(i) for i in bench.object_index[families == family]}),
            "valid": int(rows.sum()),
            "success_rate": _rate(bench.labels[rows]),
            "success_rate_fc_passing": _rate(bench.labels[rows & bench.fc_passed]),
            "success_rate_random": _rate(bench.labels[rows & random_rows]),
        }
    return out


def percent(value: float | None) -> str:
    """A rate for people: ``" 42.5%"``, or ``"  n/a"`` when there is none."""
    return "  n/a" if value is None or not math.isfinite(value) else f"{100 * value:5.1f}%"


def trial_lines(summary: Mapping[str, Any]) -> list[str]:
    """Lines for :meth:`~dg16m_env.trial.TrialResults.summary`: simulated, invalid, outcomes,
    the deepest penetration while held, failures by phase."""
    ran = summary["trials"] - summary["invalid"]
    lines = [
        f"{ran} simulated, {summary['invalid']} invalid (open hands penetrate or overlap; not "
        f"run): {summary['success']} success, {summary['failed']} failed, "
        f"{summary['unstable']} unstable ({summary['ejected']} ejected)",
        f"deepest penetration while held: {1000 * summary['max_penetration_m']:.3f} mm",
    ]
    if summary["failing_phases"]:
        phases = ", ".join(f"{k} {v}" for k, v in summary["failing_phases"].items())
        lines.append(f"failures by phase: {phases}")
    return lines


def format_summary(bench: Benchmark) -> str:
    """A few lines for the terminal."""
    s = bench.summary()
    return "\n".join(
        [
            f"{s['objects']} objects, {s['pairs']} dual grasps",
            *trial_lines(s["trials"]),
            "sim success by pair source (simulated trials):",
            *(
                f"  {name:8s} {percent(row['sim_success_rate']):>7s} of {row['valid']} "
                f"({row['pairs']} pairs, {percent(row['fc_pass_fraction'])} pass force closure)"
                for name, row in s["by_source"].items()
            ),
            "sim success, all force-closure passing pairs (any source): "
            + percent(s["sim_success_rate_fc_passing"]),
            "sim success, all force-closure failing pairs (any source): "
            + percent(s["sim_success_rate_fc_failing"]),
        ]
    )


def plot_summary(bench: Benchmark, path: str | os.PathLike[str]) -> None:
    """Three panels: success rate by pair source, by family (FC-passing vs random), and the
    phase where failures happen. Written atomically as PNG."""
    from dataset_gen.figures import new_figure, save_png

    s = bench.summary()
    families = summary_by_family(bench)
    fig = new_figure(16, 4.5)
    axes = fig.subplots(1, 3, gridspec_kw={"width_ratios": [1, 2.2, 2]})
    names = list(s["by_source"])
    rates = [s["by_source"][n]["sim_success_rate"] or 0.0 for n in names]
    axes[0].bar(
        names,
        rates,
        color=["tab:green", "tab:red", "tab:gray", "tab:olive", "tab:brown"][: len(names)],
    )
    axes[0].set_ylim(0, 1)
    axes[0].set_ylabel("simulation success rate (valid trials)")
    axes[0].set_title("by pair source")
    for x, r in enumerate(rates):
        axes[0].text(x, r + 0.02, f"{100 * r:.0f}%", ha="center")
    fam = list(families)
    x = np.arange(len(fam))
    fc = [families[f]["success_rate_fc_passing"] or 0.0 for f in fam]
    rnd = [families[f]["success_rate_random"] or 0.0 for f in fam]
    axes[1].bar(x - 0.2, fc, 0.4, label="force-closure passing", color="tab:green")
    axes[1].bar(x + 0.2, rnd, 0.4, label="random", color="tab:gray")
    axes[1].set_xticks(x, fam, rotation=30, ha="right")
    axes[1].set_ylim(0, 1)
    axes[1].set_title("by family")
    axes[1].legend()
    counts = [int(np.sum(bench.trials.failing_phase == p)) for p in range(len(PHASES))]
    axes[2].bar(np.arange(len(PHASES)), counts, color="tab:red")
    axes[2].set_xticks(np.arange(len(PHASES)), PHASES, rotation=60, ha="right")
    axes[2].set_title("failing phase (count)")
    fig.suptitle(
        f"{s['objects']} objects, {s['pairs']} dual grasps; deepest penetration "
        f"{1000 * s['trials']['max_penetration_m']:.2f} mm"
    )
    fig.tight_layout()
    save_png(fig, path, dpi=110)
