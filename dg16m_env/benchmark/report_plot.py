"""The figure of a benchmark report: :func:`plot_summary` draws what
:func:`~dg16m_env.benchmark.report.benchmark_report` gathered on a :class:`matplotlib.figure.Figure`
(GSR per arm with its confidence interval, the histogram of ``p``, failure phases, penetration,
the hand-line diagnostic and contacts after *close*).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from dg16m_env.benchmark.model import Benchmark
from dg16m_env.benchmark.report import (
    ARM_COLORS,
    LEVEL_DESCRIPTIONS,
    benchmark_report,
)
from dg16m_env.physics.labels import LEVELS

# --------------------------------------------------------------------------------------------
# Figure
# --------------------------------------------------------------------------------------------


def _arm_color(arm: str) -> str:
    return ARM_COLORS.get(arm, "tab:blue")


def _plot_gsr(ax: Any, report: Mapping[str, Any]) -> None:
    from matplotlib.patches import Patch

    arms = list(report["by_arm"])
    x = np.arange(len(arms))
    width = 0.38
    styles = {"full": {"alpha": 1.0, "hatch": None}, "gravity": {"alpha": 0.45, "hatch": "//"}}
    for j, level in enumerate(LEVELS):
        rates = [report["by_arm"][a][level]["gsr"] for a in arms]
        value = np.array([100 * (r["rate"] or 0.0) for r in rates])
        low = np.array([100 * (r["ci_low"] if r["ci_low"] is not None else 0.0) for r in rates])
        high = np.array([100 * (r["ci_high"] if r["ci_high"] is not None else 0.0) for r in rates])
        offset = (j - 0.5) * width
        ax.bar(
            x + offset,
            value,
            width,
            yerr=np.vstack([value - low, high - value]),
            capsize=4,
            color=[_arm_color(a) for a in arms],
            edgecolor="black",
            linewidth=0.6,
            **styles[level],
        )
        for xi, v, h in zip(x + offset, value, high, strict=True):
            ax.text(xi, h + 1.5, f"{v:.0f}%", ha="center", va="bottom", fontsize=8)
    ax.set_xticks(x, arms)
    ax.set_ylim(0, 112)
    ax.set_xlabel("arm (pair source)")
    ax.set_ylabel("GSR: mean success probability p (%)")
    ax.set_title("(a) GSR per arm, all pairs, with object-resampled 95% CI")
    ax.legend(
        handles=[
            Patch(
                facecolor="lightgray",
                edgecolor="black",
                label=f"{level}: {LEVEL_DESCRIPTIONS[level].split(' (')[0]}",
                **styles[level],
            )
            for level in LEVELS
        ],
        loc="upper right",
        fontsize=8,
    )
    ax.grid(axis="y", alpha=0.3)


def _arm_bars(ax: Any, x: np.ndarray, bars: Sequence[tuple[str, Any, str]]) -> None:
    """Side by side at each ``x``, one bar per arm: ``(arm, heights, legend label)``."""
    width = 0.8 / max(1, len(bars))
    for j, (arm, heights, label) in enumerate(bars):
        ax.bar(
            x + (j - (len(bars) - 1) / 2) * width,
            heights,
            width,
            color=_arm_color(arm),
            label=label,
        )


def _plot_histogram(ax: Any, report: Mapping[str, Any]) -> None:
    hist = report["p_histogram"]
    values = hist["values"]
    arms = list(hist["exact"])
    x = np.arange(len(values))
    bars = []
    for arm in arms:
        counts = np.array(hist["exact"][arm], dtype=np.float64)
        share = 100 * counts / counts.sum() if counts.sum() else counts
        bars.append((arm, share, f"{arm} ({int(counts.sum())} pairs)"))
    _arm_bars(ax, x, bars)
    trials = hist["trials_per_pair"]
    ax.set_xticks(x, [f"{k}/{trials}" for k in range(trials + 1)])
    ax.set_xlabel(f"success probability p (trials held of {trials}), {hist['level']} level")
    ax.set_ylabel("pairs of the arm (%)")
    ax.set_title(f"(b) distribution of p per arm ({hist['level']} level)")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)


def _plot_phases(ax: Any, report: Mapping[str, Any]) -> None:
    phases = report["failure_phases"]
    names = list(phases["pooled"]["phases"])
    arms = list(phases["by_arm"])
    x = np.arange(len(names))
    top = 0
    bars = []
    for arm in arms:
        counts = [phases["by_arm"][arm]["phases"].get(n, 0) for n in names]
        top = max(top, *counts)
        trials = phases["by_arm"][arm]["trials"]
        bars.append((arm, counts, f"{arm} ({sum(counts)} of {trials} trials)"))
    _arm_bars(ax, x, bars)
    ax.set_xticks(x, names, rotation=50, ha="right")
    ax.set_xlabel("phase where the trial first broke the bounds")
    ax.set_ylabel("failed trials (log scale)")
    ax.set_title("(c) failure phase of failed trials (all K+1 trials, per arm)")
    if top > 0:
        ax.set_yscale("log")
        ax.set_ylim(0.7, top * 2.5)
        ax.legend(fontsize=8)
    else:
        ax.text(0.5, 0.5, "no failed trial", transform=ax.transAxes, ha="center")
    ax.grid(axis="y", alpha=0.3)


def _plot_penetration(ax: Any, bench: Benchmark, report: Mapping[str, Any]) -> None:
    values = 1000 * bench.trials.max_penetration[bench.trials.valid]
    pen = report["penetration"]
    ax.set_title("(d) penetration while held, valid nominal trials (pooled over arms)")
    ax.set_xlabel("deepest penetration of the hands into the object (mm)")
    ax.set_ylabel("nominal trials (log scale)")
    if not values.size:
        ax.text(0.5, 0.5, "no valid nominal trial", transform=ax.transAxes, ha="center")
        return
    top = float(values.max())
    ax.hist(values, bins=40, range=(0.0, top if top > 0 else 1e-3), color="tab:blue")
    ax.set_yscale("log")
    ax.set_ylim(bottom=0.7)
    ax.axvline(
        1000 * pen["p99_m"],
        color="tab:orange",
        linestyle="--",
        label=f"99th percentile {1000 * pen['p99_m']:.3f} mm",
    )
    ax.axvline(1000 * pen["max_m"], color="tab:red", label=f"max {1000 * pen['max_m']:.3f} mm")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)


def _plot_hand_line(ax: Any, report: Mapping[str, Any]) -> None:
    line = report["hand_line"]
    ax.set_title("(e) GSR vs distance of the centre of mass from the hand line")
    ax.set_xlabel("distance from the centre of mass to the line through the grasp centres (mm)")
    ax.set_ylabel("GSR: mean p, full level (%)")
    if line is None:
        ax.text(0.5, 0.5, "not stored (older file)", transform=ax.transAxes, ha="center")
        return
    x = np.arange(len(line["bins"]))
    for arm, row in line["by_arm"].items():
        gsr = np.array([np.nan if g is None else 100 * g for g in row["gsr"]["full"]])
        ax.plot(
            x,
            gsr,
            marker="o",
            color=_arm_color(arm),
            label=f"{arm} (median {1000 * row['median_m']:.0f} mm)",
        )
    ax.set_xticks(x, line["bins"])
    ax.set_ylim(-3, 103)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)


#: Contacts of the weaker hand shown one by one in panel (f); more are pooled in the last bin.
CONTACT_BINS = 8


def _plot_contacts(ax: Any, bench: Benchmark, report: Mapping[str, Any]) -> None:
    """(f) The weaker hand's contacts at the end of *close* (the fewer of the two hands), per
    arm over its valid nominal trials; the shaded bins are the hands "without contact" that
    the report counts (their number in the legend). A benchmark whose hands all touch the
    object still shows how firmly they do."""
    contacts = report["contacts_after_close"]
    least = contacts["min_contacts"]
    ax.set_title(
        f"(f) contacts of the weaker hand at the end of close (< {least}: without contact)"
    )
    ax.set_xlabel("contacts of the hand with fewer contacts, end of close")
    ax.set_ylabel("valid nominal trials of the arm (%)")
    valid = bench.trials.valid
    if not contacts["by_arm"] or not valid.any():
        ax.text(0.5, 0.5, "no valid nominal trial", transform=ax.transAxes, ha="center")
        return
    weaker = np.minimum(bench.trials.contacts_after_close.min(axis=1), CONTACT_BINS)
    x = np.arange(CONTACT_BINS + 1)
    bars = []
    for arm, row in contacts["by_arm"].items():
        counts = np.bincount(weaker[bench.arm_rows(arm) & valid], minlength=x.size)
        share = 100 * counts / counts.sum() if counts.sum() else counts.astype(np.float64)
        label = f"{arm}: {row['without_contact']} of {row['valid']} without contact"
        bars.append((arm, share, label))
    if least > 0:
        ax.axvspan(-0.5, least - 0.5, color="tab:red", alpha=0.12, linewidth=0)
    _arm_bars(ax, x, bars)
    ax.set_xticks(x, [*(str(i) for i in range(CONTACT_BINS)), f">={CONTACT_BINS}"])
    ax.set_xlim(-0.5, CONTACT_BINS + 0.5)
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)


def plot_summary(
    bench: Benchmark,
    path: str | os.PathLike[str],
    report: Mapping[str, Any] | None = None,
) -> None:
    """A 2 x 3 figure, written atomically as PNG: (a) GSR per arm at both levels with
    confidence intervals, (b) the distribution of ``p`` per arm (full level), (c) the failure
    phases of all failed trials per arm (log scale), (d) the penetration of the valid nominal
    trials (mm, log scale), (e) GSR per hand-line-distance bin per arm (when stored), (f) the
    contacts of the weaker hand after close per arm (those without contact shaded).
    ``report``: the benchmark's :func:`benchmark_report` when already computed. Never touches
    pyplot or the matplotlib backend."""
    from dg16m_core.figures import new_figure, save_png

    report = benchmark_report(bench) if report is None else report
    fig = new_figure(22, 10.5)
    axes = fig.subplots(2, 3)
    _plot_gsr(axes[0, 0], report)
    _plot_histogram(axes[0, 1], report)
    _plot_phases(axes[1, 0], report)
    _plot_penetration(axes[1, 1], bench, report)
    _plot_hand_line(axes[0, 2], report)
    _plot_contacts(axes[1, 2], bench, report)
    spec = report["perturbation"]
    fig.suptitle(
        f"{report['objects']} objects, {report['pairs']} pairs x {report['trials_per_pair']} "
        f"trials (nominal + {spec['n_perturbations']} perturbed: d = "
        f"{1000 * spec['translation']:g} mm, theta = {spec['rotation_deg']:g} deg); "
        f"{report['created_by'] or ''}"
    )
    fig.tight_layout()
    save_png(fig, path, dpi=110)
