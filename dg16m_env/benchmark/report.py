"""Readable summaries of a benchmark (schema v2): a text report, a JSON object and a figure.

Every pair (row) of a benchmark carries a success probability ``p`` over its K + 1 trials
(nominal + K perturbed hand poses) at two levels (:data:`dg16m_env.physics.labels.LEVELS`): ``full``
(held through all twelve disturbances, the headline) and ``gravity`` (held under gravity, the
paper's level). The report reads, per arm (:data:`dg16m_env.benchmark.model.SOURCES`):

* FCE: the fraction of pairs passing force closure;
* GSR: the mean ``p`` over all pairs (an invalid trial counts as a failure) and over the pairs
  whose nominal trial is valid, each with an object-resampled 95 % confidence interval
  (:func:`dg16m_env.rates.object_rate`);
* the binary label rate (``p >= 0.5``) and the uncertain fraction (``0.2 < p < 0.8``);

then the histogram of ``p``, the phase where failed trials broke (every trial, not only the
nominal one), invalid trials (with their reasons per object) and the hands' penetration in the
nominal trials, re-seated hands (how many moved and how far, :mod:`dg16m_env.physics.reseat`), and two
diagnostics of why grasps fail: per arm, the distance from the object's centre of mass to the
line through the hands' grasp centres (median, and GSR per distance bin; the weak mode of two
parallel-jaw grasps is rotation about that line) and the share of pairs with a hand that has
no contact at the end of *close*.

:func:`benchmark_report` gathers all of it as one JSON-ready dict (finite numbers or ``None``),
:func:`~dg16m_env.benchmark.report_text.format_summary` prints it and
:func:`~dg16m_env.benchmark.report_plot.plot_summary` draws it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dg16m_core.json_values import json_ready
from dg16m_env.benchmark.model import SOURCES, Benchmark
from dg16m_env.physics.labels import LEVELS
from dg16m_env.physics.reseat import shift_summary
from dg16m_env.physics.trial_protocol import PHASES, InvalidReason, TrialStatus

ARM_DESCRIPTIONS = {
    "fc_pass": "force-closure passing pairs",
    "fc_fail": "force-closure failing pairs (loss above the failing threshold)",
    "random": "pairs drawn uniformly among the candidates",
    "farthest": "each grasp paired with the grasp farthest from it",
    "file_pass": "passing pairs of the DG16M files",
    "file_fail": "failing pairs of the DG16M files",
    "fc_robust": "robust pairs: passing, and held against every protocol load (beyond the paper)",
}
"""What each arm (pair source, :data:`~dg16m_env.benchmark.model.SOURCES`) holds, for people."""

LEVEL_DESCRIPTIONS = {
    "full": "held through close, gravity and all 12 disturbances (the headline)",
    "gravity": "held through close and gravity (the paper's level)",
}
"""What each level of :data:`~dg16m_env.physics.labels.LEVELS` counts as held."""

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
    """The arms (:data:`~dg16m_env.benchmark.model.SOURCES`) that have at least one row, in order."""
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
    (:data:`~dg16m_env.physics.trial.PHASES`).

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
    (:class:`~dg16m_env.physics.trial.InvalidReason` names in lower case; objects without invalid rows
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
