"""Readable summaries of a benchmark (schema v2): a text report, a JSON object and a figure.

Every pair (row) of a benchmark carries a success probability ``p`` over its K + 1 trials
(nominal + K perturbed hand poses) at two levels (:data:`dg16m_env.labels.LEVELS`): ``full``
(held through all twelve disturbances, the headline) and ``gravity`` (held under gravity, the
paper's level). The report reads, per arm (:data:`dg16m_env.benchmark.SOURCES`):

* FCE: the fraction of pairs passing force closure;
* GSR: the mean ``p`` over all pairs (an invalid trial counts as a failure) and over the pairs
  whose nominal trial is valid, each with an object-resampled 95 % confidence interval
  (:func:`dg16m_env.rates.object_rate`);
* the binary label rate (``p >= 0.5``) and the uncertain fraction (``0.2 < p < 0.8``);

then the histogram of ``p``, the phase where failed trials broke (every trial, not only the
nominal one), invalid trials (with their reasons per object) and the hands' penetration in the
nominal trials, re-seated hands (how many moved and how far, :mod:`dg16m_env.reseat`), and two
diagnostics of why grasps fail: per arm, the distance from the object's centre of mass to the
line through the hands' grasp centres (median, and GSR per distance bin; the weak mode of two
parallel-jaw grasps is rotation about that line) and the share of pairs with a hand that has
no contact at the end of *close*.

:func:`benchmark_report` gathers all of it as one JSON-ready dict (finite numbers or ``None``),
:func:`format_summary` prints it and :func:`plot_summary` draws it.
"""

from __future__ import annotations

import math
import os
import textwrap
from collections.abc import Mapping
from typing import Any

import numpy as np

from dataset_gen.json_values import json_ready
from dg16m_env.benchmark import SOURCES, Benchmark
from dg16m_env.labels import LEVELS, UNCERTAIN
from dg16m_env.reseat import shift_summary
from dg16m_env.trial import PHASES, InvalidReason, TrialStatus

ARM_DESCRIPTIONS = {
    "fc_pass": "force-closure passing pairs",
    "fc_fail": "force-closure failing pairs (loss above the failing threshold)",
    "random": "pairs drawn uniformly among the candidates",
    "farthest": "each grasp paired with the grasp farthest from it",
    "file_pass": "passing pairs of the DG16M files",
    "file_fail": "failing pairs of the DG16M files",
    "fc_robust": "robust pairs: passing, and held against every protocol load (beyond the paper)",
}
"""What each arm (pair source, :data:`~dg16m_env.benchmark.SOURCES`) holds, for people."""

LEVEL_DESCRIPTIONS = {
    "full": "held through close, gravity and all 12 disturbances (the headline)",
    "gravity": "held through close and gravity (the paper's level)",
}
"""What each level of :data:`~dg16m_env.labels.LEVELS` counts as held."""

ARM_COLORS = {
    "fc_pass": "tab:green",
    "fc_fail": "tab:red",
    "random": "tab:gray",
    "farthest": "tab:purple",
    "file_pass": "tab:cyan",
    "file_fail": "tab:brown",
    "fc_robust": "tab:olive",
}
"""One colour per arm in the figure."""

HISTOGRAM_BINS = ("0", "(0,0.2]", "(0.2,0.4]", "(0.4,0.6]", "(0.6,0.8]", "(0.8,1)", "1")
"""Bins of the text histogram of ``p``: exactly 0, five intervals of width 0.2, exactly 1."""

HAND_LINE_EDGES_MM = (50.0, 100.0, 150.0, 200.0, 300.0)
"""Inner edges (mm) of the hand-line-distance bins: < 50, 50-100, 100-150, 150-200, 200-300,
> 300 (a distance on an edge goes to the upper bin)."""

HAND_LINE_BINS = ("<50", "50-100", "100-150", "150-200", "200-300", ">300")
"""Labels (mm) of the bins of :data:`HAND_LINE_EDGES_MM`."""

MIN_CONTACTS = 1
"""A hand with fewer contacts than this at the end of *close* counts as without contact."""

MAX_OBJECT_LINES = 30
"""Per-object lines printed (invalid reasons, re-seating); the JSON holds every object."""

UNKNOWN_PHASE = "unknown"
"""Failure-phase key of a failed trial that recorded no phase (never seen; kept so that the
phase counts always add up to the failed trials)."""


# --------------------------------------------------------------------------------------------
# Numbers
# --------------------------------------------------------------------------------------------


def present_arms(bench: Benchmark) -> list[str]:
    """The arms (:data:`~dg16m_env.benchmark.SOURCES`) that have at least one row, in order."""
    return [name for k, name in enumerate(SOURCES) if bool(np.any(bench.source == k))]


def held_counts(bench: Benchmark, level: str = "full") -> np.ndarray:
    """(N,) int64: how many of each row's K + 1 trials held at ``level`` (``p * (K + 1)``,
    exactly)."""
    if level not in LEVELS:
        bench.labels.p(level)  # raises LabelError naming the levels
    held = bench.labels.held if level == "full" else bench.labels.held_gravity
    return held.sum(axis=1).astype(np.int64)


def p_histogram(bench: Benchmark, level: str = "full") -> dict[str, Any]:
    """Pairs per value of ``p`` at ``level``, per arm.

    Returns:
        ``{"level", "trials_per_pair", "bins", "counts", "values", "exact"}``: ``counts[arm]``
        holds the pairs in each of :data:`HISTOGRAM_BINS` (they add up to the arm's pairs);
        ``exact[arm]`` the pairs at each possible value ``values`` = 0, 1/(K+1), ..., 1 of ``p``.
    """
    trials = bench.labels.spec.trials
    held = held_counts(bench, level)
    # Bin j in 1..5 holds 0.2 (j - 1) < p <= 0.2 j, i.e. (j - 1) T < 5 k <= j T (integers).
    fifths = -(-5 * held // trials)  # ceil(5 k / T): the j with (j - 1) T < 5 k <= j T
    bin_index = np.where(held == 0, 0, np.where(held == trials, 6, fifths))
    counts: dict[str, list[int]] = {}
    exact: dict[str, list[int]] = {}
    for arm in present_arms(bench):
        rows = bench.arm_rows(arm)
        counts[arm] = np.bincount(bin_index[rows], minlength=len(HISTOGRAM_BINS)).tolist()
        exact[arm] = np.bincount(held[rows], minlength=trials + 1).tolist()
    return {
        "level": level,
        "trials_per_pair": trials,
        "bins": list(HISTOGRAM_BINS),
        "counts": counts,
        "values": [k / trials for k in range(trials + 1)],
        "exact": exact,
    }


def _phase_counts(status: np.ndarray, phase: np.ndarray) -> dict[str, Any]:
    failed = (status == TrialStatus.FAILED) | (status == TrialStatus.UNSTABLE)
    hits = phase[failed].astype(np.int64)
    named = np.bincount(hits[hits >= 0], minlength=len(PHASES))
    phases = {name: int(named[i]) for i, name in enumerate(PHASES)}
    unknown = int(np.sum(hits < 0))
    if unknown:
        phases[UNKNOWN_PHASE] = unknown
    return {
        "trials": int(status.size),
        "failed": int(np.sum(status == TrialStatus.FAILED)),
        "unstable": int(np.sum(status == TrialStatus.UNSTABLE)),
        "phases": phases,
    }


def failure_phases(bench: Benchmark) -> dict[str, Any]:
    """Where failed trials broke, over every trial (nominal and perturbed), pooled and per arm.

    A trial counts when its status is FAILED or UNSTABLE; its phase is its ``failing_phase``
    (:data:`~dg16m_env.trial.PHASES`).

    Returns:
        ``{"pooled": entry, "by_arm": {arm: entry}}``, each entry ``{"trials", "failed",
        "unstable", "phases": {phase: trials}}`` (the phase counts add up to failed +
        unstable).
    """
    status = bench.labels.status
    phase = bench.labels.failing_phase
    by_arm = {}
    for arm in present_arms(bench):
        rows = bench.arm_rows(arm)
        by_arm[arm] = _phase_counts(status[rows], phase[rows])
    return {"pooled": _phase_counts(status, phase), "by_arm": by_arm}


def invalid_trials(bench: Benchmark) -> dict[str, Any]:
    """Trials that were not run (an open hand in the object, the hands overlapping).

    Returns:
        ``{"trials", "invalid", "nominal_trials", "nominal_invalid", "nominal_reasons"}``: over
        all K + 1 trials, then over the nominal ones with their reasons (only the nominal
        trials record one).
    """
    status = bench.labels.status
    nominal = bench.trials
    return {
        "trials": int(status.size),
        "invalid": int(np.sum(status == TrialStatus.INVALID)),
        "nominal_trials": nominal.n,
        "nominal_invalid": int(np.sum(~nominal.valid)),
        "nominal_reasons": nominal.invalid_reasons(),
    }


def invalid_by_object(bench: Benchmark) -> dict[str, dict[str, int]]:
    """Per object with invalid nominal trials, in object order: ``{object_id: {reason: rows}}``
    (:class:`~dg16m_env.trial.InvalidReason` names in lower case; objects without invalid rows
    are left out)."""
    reasons = bench.trials.invalid_reason.astype(np.int64)
    out: dict[str, dict[str, int]] = {}
    for k, obj in enumerate(bench.objects):
        rows = bench.object_index == k
        counts = np.bincount(reasons[rows], minlength=len(InvalidReason))
        entry = {
            InvalidReason(r).name.lower(): int(c)
            for r, c in enumerate(counts)
            if r != InvalidReason.NONE and c
        }
        if entry:
            out[obj.object_id] = entry
    return out


def reseat_report(bench: Benchmark) -> dict[str, Any]:
    """How many hands re-seating moved, and how far (``grasps/reseat_shift``).

    Returns:
        ``{"objects", "hands", "moved", "median_m", "max_m", "by_object"}``: the objects built
        with re-seating on (``reseat_max`` > 0) and their hands, with :func:`shift_summary`
        over them; ``by_object[id]`` = ``{"reseat_max_m", "hands", "moved", "median_m",
        "max_m", "invalid_rows"}`` for each such object (its rows still invalid after it).
    """
    on = [k for k, o in enumerate(bench.objects) if o.reseat_max > 0]
    rows = np.isin(bench.object_index, on)
    by_object: dict[str, Any] = {}
    for k in on:
        mine = bench.object_index == k
        by_object[bench.objects[k].object_id] = {
            "reseat_max_m": bench.objects[k].reseat_max,
            "hands": int(2 * mine.sum()),
            **shift_summary(bench.reseat_shift[mine]),
            "invalid_rows": int(np.sum(mine & ~bench.trials.valid)),
        }
    return {
        "objects": len(on),
        "hands": int(2 * rows.sum()),
        **shift_summary(bench.reseat_shift[rows]),
        "by_object": by_object,
    }


def hand_line_bins(distance: np.ndarray) -> np.ndarray:
    """(N,) index into :data:`HAND_LINE_BINS` of each hand-line distance (m)."""
    return np.searchsorted(np.array(HAND_LINE_EDGES_MM) / 1000.0, distance, side="right")


def hand_line(bench: Benchmark) -> dict[str, Any] | None:
    """Success against the distance from the centre of mass to the line through the two hands'
    grasp centres, per arm; ``None`` when the file does not store the distance (older files).

    Returns:
        ``{"bins", "by_arm": {arm: {"pairs", "median_m", "counts", "gsr"}}}``: ``counts`` and
        ``gsr`` (mean ``p`` at each level, ``None`` in empty bins) per bin of
        :data:`HAND_LINE_BINS` (mm).
    """
    distance = bench.hand_line_distance
    if distance is None:
        return None
    index = hand_line_bins(distance)
    by_arm: dict[str, Any] = {}
    for arm in present_arms(bench):
        rows = bench.arm_rows(arm)
        entry: dict[str, Any] = {
            "pairs": int(rows.sum()),
            "median_m": float(np.median(distance[rows])),
            "counts": np.bincount(index[rows], minlength=len(HAND_LINE_BINS)).tolist(),
            "gsr": {},
        }
        for level in LEVELS:
            p = bench.p(level)
            entry["gsr"][level] = [
                _mean(p[rows & (index == b)]) for b in range(len(HAND_LINE_BINS))
            ]
        by_arm[arm] = entry
    return {"bins": list(HAND_LINE_BINS), "by_arm": by_arm}


def contacts_after_close(bench: Benchmark) -> dict[str, Any]:
    """Pairs whose nominal trial ran but left a hand with fewer than :data:`MIN_CONTACTS`
    contacts at the end of *close* (``sim/contacts_after_close``), per arm and pooled.

    Returns:
        ``{"min_contacts", "pooled": entry, "by_arm": {arm: entry}}``, each entry ``{"valid",
        "without_contact", "share"}`` (over the valid nominal trials; ``share`` ``None``
        without any).
    """
    valid = bench.trials.valid
    short = bench.trials.contacts_after_close.min(axis=1) < MIN_CONTACTS

    def entry(rows: np.ndarray) -> dict[str, Any]:
        ran = rows & valid
        return {
            "valid": int(ran.sum()),
            "without_contact": int((ran & short).sum()),
            "share": _mean(short[ran].astype(np.float64)),
        }

    return {
        "min_contacts": MIN_CONTACTS,
        "pooled": entry(np.ones(bench.n, dtype=bool)),
        "by_arm": {arm: entry(bench.arm_rows(arm)) for arm in present_arms(bench)},
    }


def penetration(bench: Benchmark) -> dict[str, Any]:
    """The hands' deepest penetration of the object while held, over the valid nominal trials.

    Returns:
        ``{"trials", "max_m", "p99_m"}``: valid nominal trials, the maximum and the 99th
        percentile (m; ``None`` without valid trials).
    """
    values = bench.trials.max_penetration[bench.trials.valid]
    if not values.size:
        return {"trials": 0, "max_m": None, "p99_m": None}
    return {
        "trials": int(values.size),
        "max_m": float(values.max()),
        "p99_m": float(np.percentile(values, 99)),
    }


def uncertain_overall(bench: Benchmark) -> dict[str, Any]:
    """Pairs with ``UNCERTAIN[0] < p < UNCERTAIN[1]`` over all arms, per level.

    Returns:
        ``{level: {"pairs", "fraction"}}`` (``fraction`` ``None`` for an empty benchmark).
    """
    out: dict[str, Any] = {}
    for level in LEVELS:
        flags = bench.labels.uncertain(level)
        out[level] = {
            "pairs": int(flags.sum()),
            "fraction": float(flags.mean()) if flags.size else None,
        }
    return out


def _mean(values: np.ndarray) -> float | None:
    return float(values.mean()) if values.size else None


def summary_by_family(bench: Benchmark) -> dict[str, dict[str, Any]]:
    """Per object family (``""`` -> ``"mesh"``): objects, pairs, pairs whose nominal trial is
    valid, and at each level the GSR (mean ``p`` over pairs, no confidence interval) of all
    pairs, of the ``fc_pass`` arm and of the ``random`` arm (``None`` where the family has no
    such pairs)."""
    families = np.array([o.family or "mesh" for o in bench.objects], dtype=object)
    row_family = families[bench.object_index] if bench.n else np.array([], dtype=object)
    valid = bench.trials.valid
    fc_pass = bench.source == SOURCES.index("fc_pass")
    random = bench.source == SOURCES.index("random")
    out: dict[str, dict[str, Any]] = {}
    for family in sorted(set(families.tolist())):
        rows = row_family == family
        entry: dict[str, Any] = {
            "objects": int(np.sum(families == family)),
            "pairs": int(rows.sum()),
            "valid": int((rows & valid).sum()),
        }
        for level in LEVELS:
            p = bench.p(level)
            entry[level] = {
                "gsr": _mean(p[rows]),
                "gsr_fc_pass": _mean(p[rows & fc_pass]),
                "gsr_random": _mean(p[rows & random]),
            }
        out[family] = entry
    return out


def benchmark_report(bench: Benchmark, *, n_resamples: int = 2000, seed: int = 0) -> dict[str, Any]:
    """Everything ``dg16m benchmark info`` shows, JSON-ready (finite numbers or ``None``).

    Returns:
        :meth:`Benchmark.summary` (at the top level: ``objects``, ``pairs``,
        ``trials_per_pair``, ``perturbation``, ``nominal_trials``, ``by_arm``), plus
        ``created_by`` (the package that built it), ``simulator`` (the engine that ran the
        trials: ``{"name": "mujoco"}`` unless the file names another), ``mujoco`` (the MuJoCo
        version that simulated them, ``None`` for files written before it was recorded),
        ``p_histogram`` (:func:`p_histogram`, full level), ``uncertain``
        (:func:`uncertain_overall`), ``failure_phases`` (:func:`failure_phases`), ``invalid``
        (:func:`invalid_trials`), ``penetration`` (:func:`penetration`, m), ``by_family``
        (:func:`summary_by_family`),
        ``invalid_by_object`` (:func:`invalid_by_object`), ``reseat`` (:func:`reseat_report`),
        ``hand_line`` (:func:`hand_line`, ``None`` for older files) and
        ``contacts_after_close`` (:func:`contacts_after_close`).
    """
    summary = bench.summary(n_resamples=n_resamples, seed=seed)
    return json_ready(
        {
            **summary,
            "created_by": bench.metadata.get("created_by"),
            "simulator": bench.metadata.get("simulator", {"name": "mujoco"}),
            "mujoco": bench.metadata.get("mujoco"),
            "p_histogram": p_histogram(bench, "full"),
            "uncertain": uncertain_overall(bench),
            "failure_phases": failure_phases(bench),
            "invalid": invalid_trials(bench),
            "penetration": penetration(bench),
            "by_family": summary_by_family(bench),
            "invalid_by_object": invalid_by_object(bench),
            "reseat": reseat_report(bench),
            "hand_line": hand_line(bench),
            "contacts_after_close": contacts_after_close(bench),
        }
    )


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
    """Lines for :meth:`~dg16m_env.trial.TrialResults.summary`: simulated, invalid, outcomes,
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


def _plot_histogram(ax: Any, report: Mapping[str, Any]) -> None:
    hist = report["p_histogram"]
    values = hist["values"]
    arms = list(hist["exact"])
    x = np.arange(len(values))
    width = 0.8 / max(1, len(arms))
    for j, arm in enumerate(arms):
        counts = np.array(hist["exact"][arm], dtype=np.float64)
        share = 100 * counts / counts.sum() if counts.sum() else counts
        ax.bar(
            x + (j - (len(arms) - 1) / 2) * width,
            share,
            width,
            color=_arm_color(arm),
            label=f"{arm} ({int(counts.sum())} pairs)",
        )
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
    width = 0.8 / max(1, len(arms))
    top = 0
    for j, arm in enumerate(arms):
        counts = [phases["by_arm"][arm]["phases"].get(n, 0) for n in names]
        top = max(top, *counts)
        ax.bar(
            x + (j - (len(arms) - 1) / 2) * width,
            counts,
            width,
            color=_arm_color(arm),
            label=f"{arm} ({sum(counts)} of {phases['by_arm'][arm]['trials']} trials)",
        )
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


def _plot_contacts(ax: Any, report: Mapping[str, Any]) -> None:
    contacts = report["contacts_after_close"]
    arms = list(contacts["by_arm"])
    share = [100 * (contacts["by_arm"][a]["share"] or 0.0) for a in arms]
    ax.bar(np.arange(len(arms)), share, color=[_arm_color(a) for a in arms], edgecolor="black")
    for xi, arm in enumerate(arms):
        row = contacts["by_arm"][arm]
        ax.text(xi, share[xi], f"{row['without_contact']}/{row['valid']}", ha="center", va="bottom")
    ax.set_xticks(np.arange(len(arms)), arms)
    ax.set_xlabel("arm (pair source)")
    ax.set_ylabel("valid nominal trials (%)")
    ax.set_title(
        f"(f) a hand with < {contacts['min_contacts']} contact at the end of close, per arm"
    )
    ax.set_ylim(0, max(5.0, 1.2 * max(share, default=0.0)))
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
    share of valid nominal trials with a hand without contact after close, per arm.
    ``report``: the benchmark's :func:`benchmark_report` when already computed. Never touches
    pyplot or the matplotlib backend."""
    from dataset_gen.figures import new_figure, save_png

    report = benchmark_report(bench) if report is None else report
    fig = new_figure(22, 10.5)
    axes = fig.subplots(2, 3)
    _plot_gsr(axes[0, 0], report)
    _plot_histogram(axes[0, 1], report)
    _plot_phases(axes[1, 0], report)
    _plot_penetration(axes[1, 1], bench, report)
    _plot_hand_line(axes[0, 2], report)
    _plot_contacts(axes[1, 2], report)
    spec = report["perturbation"]
    fig.suptitle(
        f"{report['objects']} objects, {report['pairs']} pairs x {report['trials_per_pair']} "
        f"trials (nominal + {spec['n_perturbations']} perturbed: d = "
        f"{1000 * spec['translation']:g} mm, theta = {spec['rotation_deg']:g} deg); "
        f"{report['created_by'] or ''}"
    )
    fig.tight_layout()
    save_png(fig, path, dpi=110)
