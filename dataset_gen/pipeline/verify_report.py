"""The report of :func:`~dataset_gen.pipeline.verify.verify_file` and its text.

:class:`VerifyReport` holds what a verification found (counts, agreement shares, the consistent
resolution's summary, notes, parameters, timings), one :class:`Disagreement` per pair whose
recomputed verdict or loss differs from the stored one, and :func:`format_report` (the command's
output, :meth:`VerifyReport.format_text`). The checking itself lives in :mod:`dataset_gen.pipeline.verify`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from dg16m_core.json_values import json_ready

#: Text output lists at most this many disagreeing pairs.
TEXT_LIMIT = 20


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------


@dataclass
class Disagreement:
    """One pair whose recomputed verdict or loss differs from the stored one (primary normals).

    Attributes:
        index: pair index in the file.
        kind: ``"verdict"`` (pass/fail differs) or ``"loss"`` (both fail, losses differ).
        stored_passed, stored_loss: what the file says.
        passed, loss: our recomputation with the primary normals (loss None when rank-deficient).
        explained: a face choice at the pair's ambiguous contacts reproduces the stored result.
        reason: one line saying why the pair disagrees.
        switched_contacts: contacts (0-3) given another face in the reproducing choice.
        resolved_loss: our loss with that choice.
        consistent: the pair is reproduced with one face per contact point over the whole file
            (None when that resolution did not run).
    """

    index: int
    kind: str
    stored_passed: bool
    stored_loss: float
    passed: bool
    loss: float | None
    explained: bool
    reason: str
    switched_contacts: list[int] | None = None
    resolved_loss: float | None = None
    consistent: bool | None = None


@dataclass
class VerifyReport:
    """What :func:`~dataset_gen.pipeline.verify.verify_file` found. ``to_dict()`` is JSON-serialisable;
    ``format_text()`` is the command's output.

    Counts refer to labelled pairs (in ``fc_passing_indices`` or ``fc_failed_indices``).
    ``agreement`` is the share of labelled pairs whose verdict we reproduce with the primary
    normals; ``resolved_agreement`` after per-pair face choices at ambiguous contacts;
    ``consistent_agreement`` with one face per distinct contact point (None when not run). The
    ``*_full`` variants also require the stored loss of failing pairs to match.
    ``convention_suspect`` is set when the consistent resolution had to switch most ambiguous
    points away from trimesh's face (on two-sided meshes that emulates the other convention).
    """

    file: str
    mesh: str
    convention: str
    normals_source: str
    pairs: int
    stored_passing: int
    stored_failing: int
    unlabelled: int
    agreement: float
    agreement_full: float
    pass_to_fail: int
    fail_to_pass: int
    rank_deficient: int
    failing_loss: dict[str, Any]
    resolved_agreement: float
    resolved_agreement_full: float
    resolved_fail_to_pass: int
    consistent: dict[str, Any] | None
    convention_suspect: bool
    contacts: dict[str, Any]
    stored_forces: dict[str, Any]
    disagreements: list[Disagreement]
    notes: list[str] = field(default_factory=list)
    parameters: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def unexplained(self) -> list[Disagreement]:
        """Disagreements no face choice at ambiguous contacts explains."""
        return [d for d in self.disagreements if not d.explained]

    @property
    def ok(self) -> bool:
        """Every disagreement is explained by ambiguous normals, no contact is off the mesh and
        the face choices do not point to the other convention (what ``--strict`` checks)."""
        return (
            not self.unexplained
            and not self.convention_suspect
            and self.contacts["off_mesh_points"] == 0
        )

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict (NaN and inf become None)."""
        out = json_ready(asdict(self))
        out["unexplained"] = [d.index for d in self.unexplained]
        return out

    def format_text(self, limit: int = TEXT_LIMIT) -> str:
        """The human-readable report (at most ``limit`` disagreements listed)."""
        return format_report(self, limit=limit)


# --------------------------------------------------------------------------------------------
# Text
# --------------------------------------------------------------------------------------------


def _fmt_loss(value: float | None) -> str:
    return "n/a (rank-deficient)" if value is None or not np.isfinite(value) else f"{value:.4g}"


def _pct(value: float) -> str:
    return f"{100 * value:.2f}%"


def format_report(report: VerifyReport, *, limit: int = TEXT_LIMIT) -> str:
    """The report as text: summary lines, then up to ``limit`` disagreeing pairs."""
    c = report.contacts
    lines = [
        f"{report.file} on {report.mesh} (convention {report.convention}, "
        f"scale {report.parameters.get('object_scale', 1):g})",
        f"  pairs            {report.pairs} ({report.stored_passing} stored passing, "
        f"{report.stored_failing} stored failing"
        + (f", {report.unlabelled} unlabelled)" if report.unlabelled else ")"),
        f"  contacts         {c['contacts']} ({c['distinct_points']} distinct points), max "
        f"distance to the mesh {c['max_distance_m']:.2g} m, {c['off_mesh_points']} off it; "
        f"{c['ambiguous_points']} on ambiguous faces ({c['two_sided_points']} two-sided, "
        f"{c['edge_points']} edges)",
        "  normals          "
        + (
            "from the file (dg16m/contact_normals)"
            if report.normals_source == "file"
            else "mesh face normals (trimesh nearest.on_surface, the release's choice)"
        ),
        f"  agreement        {_pct(report.agreement)} of verdicts with primary normals "
        f"({report.pass_to_fail} stored pass -> ours fail, {report.fail_to_pass} stored fail -> "
        f"ours pass); {_pct(report.agreement_full)} with failing losses too",
    ]
    fl = report.failing_loss
    if fl["compared"]:
        lines.append(
            f"  failing losses   {fl['within_tolerance']} of {fl['compared']} match within "
            f"{fl['loss_rtol']:g} relative (median rel. diff {fl['median_relative_difference']:.2g}, "
            f"max {fl['max_relative_difference']:.3g})"
        )
    n_dis = len(report.disagreements)
    n_unexpl = len(report.unexplained)
    if report.normals_source == "mesh":
        lines.append(
            f"  resolved         {_pct(report.resolved_agreement)} of verdicts "
            f"({_pct(report.resolved_agreement_full)} with losses) after per-pair face choices "
            f"at ambiguous contacts; {n_dis - n_unexpl} of {n_dis} disagreements explained, "
            f"{report.resolved_fail_to_pass} stored fail -> ours pass left"
        )
    if report.consistent is not None:
        cs = report.consistent
        lines.append(
            f"  consistent       one face per contact point ({cs['points_switched']} of "
            f"{cs['ambiguous_points']} ambiguous points switched from trimesh's face): "
            f"{_pct(cs['agreement'])} of verdicts, {_pct(cs['agreement_full'])} with losses "
            f"({len(cs['disagreeing'])} pairs left)"
        )
    sf = report.stored_forces
    which = "resolved" if report.consistent is not None else "primary"
    forces_line = (
        f"  stored forces    max force {sf['max_force_n']:.3g} N; {sf['pairs_outside_cones']} "
        f"pairs outside the {report.convention} friction cones of the {which} normals (max "
        f"violation {sf['cone_violation_max_n']:.2g} N, {sf['pairs_outside_cones_passing']} "
        "passing"
        + (
            f"; {sf['pairs_outside_cones_primary_normals']} with primary normals)"
            if "pairs_outside_cones_primary_normals" in sf
            else ")"
        )
    )
    if sf.get("residual_max_passing") is not None:
        forces_line += (
            f"; residual on passes max {sf['residual_max_passing']:.2g} N "
            f"(|residual - stored loss| <= {sf['residual_vs_loss_max_abs_passing']:.2g})"
        )
    if sf.get("residual_vs_loss_median_rel_failing") is not None:
        forces_line += (
            f"; on failures residual/stored loss rel. diff median "
            f"{sf['residual_vs_loss_median_rel_failing']:.2g}"
        )
    lines.append(forces_line)
    for note in report.notes:
        lines.append(f"  note             {note}")
    lines.append(f"  disagreements    {n_dis} ({n_unexpl} not explained by ambiguous normals)")
    for d in report.disagreements[:limit]:
        stored = "pass" if d.stored_passed else "fail"
        ours = "pass" if d.passed else "fail"
        lines.append(
            f"    {d.index}: stored {stored} ({d.stored_loss:.4g}), ours {ours} "
            f"({_fmt_loss(d.loss)}): {d.reason}"
        )
    if n_dis > limit:
        lines.append(f"    ... {n_dis - limit} more (see --json)")
    t = report.timings
    detail = ", ".join(f"{k} {v:.2f}" for k, v in t.items() if k != "total")
    lines.append(f"  time             {t.get('total', 0.0):.2f} s ({detail})")
    return "\n".join(lines)


__all__ = [
    "TEXT_LIMIT",
    "Disagreement",
    "VerifyReport",
    "format_report",
]
