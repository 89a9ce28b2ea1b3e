"""The text report of a benchmark: :func:`format_summary` prints what
:func:`~dg16m_env.benchmark.report.benchmark_report` gathered (per arm, the histogram of ``p``,
failure phases, invalid trials, re-seating, the two diagnostics, per family).
"""

from __future__ import annotations

import math
import os
import textwrap
from collections.abc import Mapping
from typing import Any

from dg16m_env.benchmark.model import Benchmark
from dg16m_env.benchmark.report import (
    ARM_DESCRIPTIONS,
    LEVEL_DESCRIPTIONS,
    MAX_OBJECT_LINES,
    benchmark_report,
)
from dg16m_env.physics.labels import LEVELS, UNCERTAIN

# --------------------------------------------------------------------------------------------
# Text
# --------------------------------------------------------------------------------------------


def percent(value: float | None) -> str:
    """A rate for people: ``" 42.5%"``, or ``"  n/a"`` when there is none."""
    return "  n/a" if value is None or not math.isfinite(value) else f"{100 * value:5.1f}%"


def _rate_ci(rate: Mapping[str, Any]) -> str:
    """``" 56.7% [3.3-96.7]"`` (percent) for an :func:`~dg16m_env.rates.object_rate` result;
    ``"   n/a"`` without rows."""
    if rate["rate"] is None:
        return f"{'n/a':>6s}"
    low, high = (percent(rate[k])[:-1].strip() for k in ("ci_low", "ci_high"))
    return f"{percent(rate['rate'])} [{low}-{high}]"


def _wrap(text: str, indent: str = "") -> list[str]:
    """``text`` as lines of at most 100 characters (continuations indented by ``indent``)."""
    return textwrap.wrap(text, width=100, subsequent_indent=indent, break_on_hyphens=False)


def trial_lines(summary: Mapping[str, Any]) -> list[str]:
    """Lines for :meth:`~dg16m_env.physics.trial.TrialResults.summary`: simulated, invalid, outcomes,
    the deepest penetration while held (mm), failures by phase."""
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


def _simulator_line(simulator: Mapping[str, Any], mujoco_version: str | None = None) -> str:
    """Which engine ran the trials (files without the key: C MuJoCo, the reference), with the
    MuJoCo version where the file records it (files written before 2026-12-03 do not)."""
    if simulator.get("name", "mujoco") == "mujoco":
        version = f" {mujoco_version}" if mujoco_version else ""
        return f"trials simulated by C MuJoCo{version} (the reference engine)"
    versions = ", ".join(
        f"{k} {simulator[k]}" for k in ("mujoco_warp", "warp", "mujoco") if k in simulator
    )
    return (
        f"trials simulated by MuJoCo Warp on {simulator.get('device', '?')} ({versions}; float32: "
        "labels agree with C MuJoCo's statistically, not bit for bit)"
    )


def _header_lines(report: Mapping[str, Any], path: str | os.PathLike[str] | None) -> list[str]:
    spec = report["perturbation"]
    k = spec["n_perturbations"]
    lines = [f"benchmark {path}"] if path is not None else []
    lines += [
        *_wrap(
            f"{report['objects']} objects, {report['pairs']} pairs (dual grasps), "
            f"{report['trials_per_pair']} trials per pair (K + 1: the nominal hand poses and "
            f"K = {k} perturbed ones, each hand moved d = {1000 * spec['translation']:g} mm "
            f"and turned theta = {spec['rotation_deg']:g} deg)",
            "  ",
        ),
        f"built by {report['created_by'] or 'an unknown package'}",
        *_wrap(
            _simulator_line(report.get("simulator") or {"name": "mujoco"}, report.get("mujoco")),
            "  ",
        ),
        "p = fraction of a pair's trials that held, at two levels:",
        *(f"  {level:8s} {LEVEL_DESCRIPTIONS[level]}" for level in LEVELS),
        "arms:",
        *(f"  {arm:9s} {ARM_DESCRIPTIONS.get(arm, arm)}" for arm in report["by_arm"]),
    ]
    return lines


def _arm_lines(report: Mapping[str, Any]) -> list[str]:
    low, high = UNCERTAIN
    lines = [
        "",
        *_wrap(
            "per arm: FCE = fraction of pairs passing force closure; GSR = mean p (%) with its "
            "object-resampled 95% CI, over all pairs (invalid trials count as failures) and "
            "over the pairs whose nominal trial is valid; label = fraction with p >= 0.5; "
            f"uncertain = fraction with {low:g} < p < {high:g}"
        ),
        f"{'arm':9s} {'pairs':>5s} {'objs':>4s} {'valid':>5s} {'FCE':>6s}  {'level':7s}  "
        f"{'GSR all [95% CI]':20s}  {'GSR valid [95% CI]':20s}  {'label':>6s}  "
        f"{'uncertain':>9s}",
    ]
    for arm, row in report["by_arm"].items():
        for i, level in enumerate(LEVELS):
            entry = row[level]
            lead = (
                f"{arm:9s} {row['pairs']:5d} {row['objects']:4d} {row['valid']:5d} "
                f"{percent(row['fce']):>6s}"
                if i == 0
                else " " * 33
            )
            lines.append(
                f"{lead}  {level:7s}  {_rate_ci(entry['gsr']):20s}  "
                f"{_rate_ci(entry['gsr_valid']):20s}  {percent(entry['label_rate']):>6s}  "
                f"{percent(entry['uncertain_fraction']):>9s}"
            )
    return lines


def _histogram_lines(report: Mapping[str, Any]) -> list[str]:
    hist = report["p_histogram"]
    bins = hist["bins"]
    values = ", ".join(f"{v:.2g}" for v in hist["values"])
    lines = [
        "",
        f"pairs per value of p, {hist['level']} level (p takes the values {values}):",
        f"{'arm':9s} " + " ".join(f"{b:>9s}" for b in bins) + f" {'total':>6s}",
    ]
    for arm, counts in hist["counts"].items():
        lines.append(f"{arm:9s} " + " ".join(f"{c:9d}" for c in counts) + f" {sum(counts):6d}")
    uncertain = report["uncertain"]
    low, high = UNCERTAIN
    lines.append(
        f"uncertain pairs ({low:g} < p < {high:g}), all arms: "
        + ", ".join(
            f"{level} {percent(uncertain[level]['fraction']).strip()} "
            f"({uncertain[level]['pairs']} of {report['pairs']})"
            for level in LEVELS
        )
    )
    return lines


def _phase_lines(report: Mapping[str, Any]) -> list[str]:
    phases = report["failure_phases"]
    columns = {"all arms": phases["pooled"], **phases["by_arm"]}
    width = max(9, *(len(name) for name in columns))
    names = list(phases["pooled"]["phases"])

    def row(label: str, values: list[int]) -> str:
        return f"{label:10s}" + "".join(f" {v:>{width}d}" for v in values)

    lines = [
        "",
        *_wrap(
            f"failure phase of failed trials (status failed or unstable; all "
            f"{report['trials_per_pair']} trials of every pair), pooled and per arm:"
        ),
        f"{'phase':10s}" + "".join(f" {name:>{width}s}" for name in columns),
        row("trials", [c["trials"] for c in columns.values()]),
    ]
    lines += [row(name, [c["phases"].get(name, 0) for c in columns.values()]) for name in names]
    lines.append(row("all failed", [c["failed"] + c["unstable"] for c in columns.values()]))
    unstable = phases["pooled"]["unstable"]
    if unstable:
        lines.append(f"  ({unstable} of them unstable: non-finite or implausibly fast states)")
    return lines


def _nominal_lines(report: Mapping[str, Any]) -> list[str]:
    invalid = report["invalid"]
    reasons = ", ".join(f"{k} {v}" for k, v in invalid["nominal_reasons"].items())
    pen = report["penetration"]
    lines = [
        "",
        *_wrap(
            f"invalid trials (not run: an open hand in the object or the hands overlap; they "
            f"count as failures): {invalid['invalid']} of {invalid['trials']} trials; nominal "
            f"{invalid['nominal_invalid']} of {invalid['nominal_trials']}"
            + (f" ({reasons})" if reasons else ""),
            "  ",
        ),
    ]
    by_object = report["invalid_by_object"]
    if by_object:
        lines.append(f"invalid nominal trials by object ({len(by_object)} objects):")
        for object_id, counts in list(by_object.items())[:MAX_OBJECT_LINES]:
            text = ", ".join(f"{reason} {count}" for reason, count in counts.items())
            lines += _wrap(f"  {object_id}: {text}", "    ")
        if len(by_object) > MAX_OBJECT_LINES:
            lines.append(f"  ... and {len(by_object) - MAX_OBJECT_LINES} more objects (--json)")
    if pen["trials"]:
        lines += _wrap(
            f"penetration of the hands while held, {pen['trials']} valid nominal trials: max "
            f"{1000 * pen['max_m']:.3f} mm, 99th percentile {1000 * pen['p99_m']:.3f} mm",
            "  ",
        )
    else:
        lines.append("penetration of the hands while held: no valid nominal trial")
    return lines


def _mm(value: float | None) -> str:
    return "n/a" if value is None else f"{1000 * value:.1f} mm"


def _reseat_lines(report: Mapping[str, Any]) -> list[str]:
    reseat = report["reseat"]
    if not reseat["objects"]:
        return ["", "re-seating: off (every hand at its given pose)"]
    lines = [
        "",
        *_wrap(
            f"re-seating (open hands that started inside the object moved back along their "
            f"approach axis; this changes the grasps): {reseat['objects']} objects, "
            f"{reseat['moved']} of {reseat['hands']} hands moved, median "
            f"{_mm(reseat['median_m'])}, max {_mm(reseat['max_m'])}",
            "  ",
        ),
    ]
    for object_id, row in list(reseat["by_object"].items())[:MAX_OBJECT_LINES]:
        lines += _wrap(
            f"  {object_id}: limit {_mm(row['reseat_max_m'])}, {row['moved']} of {row['hands']} "
            f"hands moved (median {_mm(row['median_m'])}, max {_mm(row['max_m'])}); "
            f"{row['invalid_rows']} rows still invalid",
            "    ",
        )
    if len(reseat["by_object"]) > MAX_OBJECT_LINES:
        more = len(reseat["by_object"]) - MAX_OBJECT_LINES
        lines.append(f"  ... and {more} more objects (--json)")
    return lines


def _diagnostic_lines(report: Mapping[str, Any]) -> list[str]:
    lines = [
        "",
        *_wrap(
            "hand-line distance: from the object's centre of mass to the line through the two "
            "hands' grasp centres (a dual grasp turns most easily about that line)"
        ),
    ]
    line = report["hand_line"]
    if line is None:
        lines.append("  not stored (older file; rebuild to get it)")
    else:
        lines.append("GSR (mean p, full level) by distance bin (mm), pairs in brackets:")
        lines.append(f"{'arm':9s} {'median':>9s} " + " ".join(f"{b:>12s}" for b in line["bins"]))
        for arm, row in line["by_arm"].items():
            cells = " ".join(
                f"{percent(g).strip() + f' ({c})':>12s}"
                for g, c in zip(row["gsr"]["full"], row["counts"], strict=True)
            )
            lines.append(f"{arm:9s} {_mm(row['median_m']):>9s} {cells}")
    contacts = report["contacts_after_close"]
    lines.append(
        f"a hand without contact at the end of close (< {contacts['min_contacts']} contact), "
        "share of valid nominal trials:"
    )
    lines += _wrap(
        "  "
        + ", ".join(
            f"{arm} {percent(row['share']).strip()} ({row['without_contact']} of {row['valid']})"
            for arm, row in {"all": contacts["pooled"], **contacts["by_arm"]}.items()
        ),
        "  ",
    )
    return lines


def _family_lines(report: Mapping[str, Any]) -> list[str]:
    families = report["by_family"]
    width = max([len("family"), *(len(name) for name in families)])
    lines = [
        "",
        "by family: GSR (mean p, no CI) of all pairs, fc_pass pairs and random pairs",
        f"{'family':{width}s} {'objs':>4s} {'pairs':>5s}  "
        + "  ".join(f"{level + ': all':>13s} {'fc_pass':>7s} {'random':>7s}" for level in LEVELS),
    ]
    for family, row in families.items():
        cells = "  ".join(
            f"{percent(row[level]['gsr']):>13s} {percent(row[level]['gsr_fc_pass']):>7s} "
            f"{percent(row[level]['gsr_random']):>7s}"
            for level in LEVELS
        )
        lines.append(f"{family:{width}s} {row['objects']:4d} {row['pairs']:5d}  {cells}")
    return lines


def format_summary(
    bench: Benchmark,
    report: Mapping[str, Any] | None = None,
    *,
    path: str | os.PathLike[str] | None = None,
) -> str:
    """The text report of ``dg16m benchmark info`` (see the module docstring).

    Args:
        bench: the benchmark.
        report: its :func:`benchmark_report` when already computed.
        path: the file it was read from, named in the first line.
    """
    report = benchmark_report(bench) if report is None else report
    return "\n".join(
        [
            *_header_lines(report, path),
            *_arm_lines(report),
            *_histogram_lines(report),
            *_phase_lines(report),
            *_nominal_lines(report),
            *_reseat_lines(report),
            *_diagnostic_lines(report),
            *_family_lines(report),
        ]
    )
