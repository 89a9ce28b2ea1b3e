"""Recompute the force-closure verdicts of a DG16M-schema file and compare them with the stored ones.

:func:`verify_file` reads a grasp file (DG16M release schema), loads its mesh the way the released
code did (``trimesh.load(path, force="mesh")``, scaled by ``object/scale``, translated by
``-centroid``; no cleaning, which would drop coincident faces and change normals), finds the face
under every stored contact and re-runs :func:`dataset_gen.force_closure.evaluate` with those face
normals. The report says how many stored verdicts and losses are reproduced and why the others
are not.

Ambiguous normals
-----------------
A contact on an edge, or on a two-sided surface (two coincident faces with opposite normals, as
in many ShapeNet meshes), lies on several faces with different normals. Which one
``mesh.nearest.on_surface`` returns is a floating-point tie, so a reproduction can pick another
face than the released code did. The verifier resolves this in two ways:

* per pair: the face choices at a disagreeing pair's ambiguous contacts are enumerated (fewest
  changed contacts first, at most ``max_combinations``) until one reproduces the stored verdict
  (and, for stored failures, the stored loss within ``loss_rtol``);
* consistently: the released code computed one normal per contact point, so the choices implied
  by pairs with a unique reproducing choice are propagated to every pair that shares the point,
  and the whole file is re-evaluated with one face per distinct contact point. This is the strict
  test: a wrong convention or a wrong solver cannot be hidden by choosing faces pair by pair.

On a two-sided mesh the face choice can emulate the other convention (flipping every normal turns
one convention into the other), so the report also counts how many points needed a face other
than trimesh's; when most of them did, the file was probably made with the other convention.

The pieces live beside this module and their public names are re-exported here:
:mod:`dataset_gen.pipeline.verify_contacts` (the release mesh and the faces under the contacts),
:mod:`dataset_gen.pipeline.verify_choices` (face choices at ambiguous contacts: enumeration and
propagation) and :mod:`dataset_gen.pipeline.verify_report` (the report and its text).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from dataset_gen import io
from dataset_gen.force_closure import (
    CONVENTIONS,
    ForceClosureResult,
    evaluate,
    gravity_wrench,
)
from dataset_gen.force_closure.geometry import apply_grasp
from dataset_gen.pipeline.verify_choices import (
    CONE_TOLERANCE_N,
    LOSS_ATOL,
    MAX_TOTAL_COMBINATIONS,
    _Enumeration,
    _Verifier,
)
from dataset_gen.pipeline.verify_contacts import (
    OPPOSITE_NORMAL_DOT,
    SAME_NORMAL_DOT,
    BoolArray,
    ContactGeometry,
    FloatArray,
    IntArray,
    contact_geometry,
    load_release_mesh,
)
from dataset_gen.pipeline.verify_report import (
    TEXT_LIMIT,
    Disagreement,
    VerifyReport,
    _fmt_loss,
    format_report,
)
from dg16m_core.errors import Dg16mError, GraspFileError, MeshError
from dg16m_core.parameters import PAPER

#: Rounds of the consistent (one face per point) resolution.
MAX_CONSISTENT_ROUNDS = 6
#: Our solver's loss accuracy (relative) is at least this much tighter than the comparison's.
SOLVER_RTOL = 1e-5
#: More than this share of ambiguous points needing another face than trimesh's points to the
#: other convention (a tie-break agrees with trimesh's about half the time by chance).
SUSPECT_SWITCHED = 0.75
#: Extra array (``dg16m/<name>``) holding the generator's own outward contact normals.
NORMALS_EXTRA = "contact_normals"


# --------------------------------------------------------------------------------------------
# Main entry point
# --------------------------------------------------------------------------------------------


def verify_file(
    h5_path: str | Path,
    mesh_path: str | Path,
    *,
    convention: str = "physical",
    tolerance_m: float = 1e-6,
    loss_rtol: float = 1e-3,
    max_combinations: int = 256,
    mass: float = PAPER.mass,
    gravity: float = PAPER.gravity,
    mu: float = PAPER.mu,
    f_high: float = PAPER.f_high,
    threshold: float = PAPER.threshold,
    progress: bool = False,
) -> VerifyReport:
    """Recompute every stored dual grasp's force-closure verdict and compare.

    Args:
        h5_path: DG16M release-schema file.
        mesh_path: its object's mesh (loaded raw, see :func:`load_release_mesh`).
        convention: ``"physical"`` or ``"release"`` (use ``"release"`` for release files).
        tolerance_m: a contact is on a face when within this distance (m).
        loss_rtol: stored and recomputed losses of failing pairs agree when
            ``|L - L_stored| <= loss_rtol * L_stored + 1e-6``.
        max_combinations: face choices tried per disagreeing pair.
        mass, gravity, mu, f_high, threshold: force-closure parameters (release values).
        progress: progress bars for the force-closure solves.

    Raises:
        GraspFileError: the file is not a valid DG16M-schema file.
        MeshError: the mesh cannot be loaded, or does not match the file (most contacts off its
            surface).
        Dg16mError: bad arguments.
    """
    _check_arguments(convention, tolerance_m, loss_rtol, max_combinations)
    clock = _Clock()
    notes: list[str] = []
    h5_path, mesh_path = Path(h5_path), Path(mesh_path)
    data, mesh, geo = _read_inputs(h5_path, mesh_path, tolerance_m, clock, notes)
    fc_kwargs = _solver_settings(convention, mass, gravity, mu, f_high, threshold, loss_rtol)
    ver = _Verifier(
        data, geo, np.asarray(mesh.face_normals, dtype=np.float64), fc_kwargs, loss_rtol, progress
    )
    off = geo.distance > tolerance_m
    contact_info = _contact_summary(ver, off, tolerance_m, notes)
    normals, normals_source = _primary_normals(ver, h5_path, contact_info, notes)

    result = evaluate(data.contact_points, normals, progress=progress, **fc_kwargs)
    clock.lap("evaluate")
    dis = ver.disagreeing(result.passed, result.loss)
    failing_loss = _failing_loss_summary(ver, result)

    # per-pair resolution at ambiguous contacts (only mesh normals are ambiguous)
    resolvable = dis if normals_source == "mesh" else np.zeros(0, dtype=np.int64)
    found, n_evaluated = ver.enumerate(resolvable, {}, max_combinations)
    clock.lap("resolve")

    consistent: _Consistent | None = None
    convention_suspect = False
    if normals_source == "mesh" and dis.size:
        consistent = _resolve_consistently(ver, result, found, max_combinations)
        convention_suspect = _convention_suspect(consistent.summary, convention, notes)
        clock.lap("consistent")

    disagreements = _disagreements(ver, result, found, dis, off, consistent, threshold)
    stored_forces = _stored_forces_summary(ver, normals, consistent)
    clock.lap("stored_forces")
    _convention_notes(ver, result, convention, notes)

    parameters = {
        **fc_kwargs,
        "solver_loss_rtol": fc_kwargs["loss_rtol"],
        "loss_rtol": loss_rtol,  # the comparison's tolerance replaces the solver's
        "loss_atol": LOSS_ATOL,
        "tolerance_m": tolerance_m,
        "max_combinations": max_combinations,
        "combinations_evaluated": n_evaluated,
        "object_scale": data.object_scale,
    }
    return VerifyReport(
        file=str(h5_path),
        mesh=str(mesh_path),
        convention=convention,
        normals_source=normals_source,
        **_agreement_summary(ver, result, dis, disagreements),
        failing_loss=failing_loss,
        consistent=None if consistent is None else consistent.summary,
        convention_suspect=convention_suspect,
        contacts=contact_info,
        stored_forces=stored_forces,
        disagreements=sorted(disagreements, key=lambda d: (d.explained, d.index)),
        notes=notes,
        parameters=parameters,
        timings=clock.finish(),
    )


class _Clock:
    """Wall-clock time of each step of a verification (s, rounded to 0.1 ms)."""

    def __init__(self) -> None:
        self.timings: dict[str, float] = {}
        self.start = self.last = time.perf_counter()

    def lap(self, name: str) -> None:
        """Record the time since the previous lap as step ``name``."""
        now = time.perf_counter()
        self.timings[name] = round(now - self.last, 4)
        self.last = now

    def finish(self) -> dict[str, float]:
        """The steps' timings and the ``total``."""
        self.timings["total"] = round(time.perf_counter() - self.start, 4)
        return self.timings


def _check_arguments(
    convention: str, tolerance_m: float, loss_rtol: float, max_combinations: int
) -> None:
    """Reject an unknown convention and out-of-range tolerances before anything is read."""
    if convention not in CONVENTIONS:
        raise Dg16mError(f"convention: expected one of {CONVENTIONS}, found {convention!r}")
    if not (tolerance_m > 0 and loss_rtol >= 0 and max_combinations >= 1):
        raise Dg16mError(
            "tolerance_m, loss_rtol, max_combinations: expected > 0, >= 0, >= 1, found "
            f"{tolerance_m}, {loss_rtol}, {max_combinations}"
        )


def _solver_settings(
    convention: str,
    mass: float,
    gravity: float,
    mu: float,
    f_high: float,
    threshold: float,
    loss_rtol: float,
) -> dict[str, Any]:
    """Keyword arguments of :func:`~dataset_gen.force_closure.evaluate` for the recomputation:
    the given parameters and a solver accuracy tighter than the comparison's ``loss_rtol``
    (``loss_rtol / 10``, within [1e-9, :data:`SOLVER_RTOL`])."""
    return {
        "convention": convention,
        "mass": mass,
        "gravity": gravity,
        "mu": mu,
        "f_high": f_high,
        "threshold": threshold,
        "loss_rtol": max(min(SOLVER_RTOL, loss_rtol / 10), 1e-9),
    }


def _read_inputs(
    h5_path: Path, mesh_path: Path, tolerance_m: float, clock: _Clock, notes: list[str]
) -> tuple[io.DualGraspSet, trimesh.Trimesh, ContactGeometry]:
    """Read the grasp file and its mesh and find the faces under the contacts.

    Raises when the file has no pairs or when most contacts are off the mesh (wrong mesh or
    scale); notes a mesh file name other than the one the file names.
    """
    data = io.read_dg16m(h5_path)
    clock.lap("read")
    mesh = load_release_mesh(mesh_path, data.object_scale)
    clock.lap("mesh")
    if data.n == 0:
        raise GraspFileError(f"{h5_path}: expected at least one dual grasp, found none")

    geo = contact_geometry(mesh, data.contact_points, tolerance_m)
    off = geo.distance > tolerance_m
    if off.mean() > 0.5:
        raise MeshError(
            f"{mesh_path} does not match {h5_path}: expected the contacts on the mesh surface "
            f"(within {tolerance_m:g} m), found {int(off.sum())} of {len(off)} distinct contact "
            f"points off it, median distance {np.median(geo.distance):.3g} m (wrong mesh, or "
            f"object/scale {data.object_scale:g} does not fit it?)"
        )
    clock.lap("contacts")
    if Path(data.object_file).name != mesh_path.name:
        notes.append(f"the file names its mesh {data.object_file!r}; checked against {mesh_path}")
    return data, mesh, geo


def _contact_summary(
    ver: _Verifier, off: BoolArray, tolerance_m: float, notes: list[str]
) -> dict[str, Any]:
    """The report's ``contacts``: distinct points, distances, ambiguous faces (notes points off
    the mesh)."""
    geo = ver.geo
    ambiguous = geo.ambiguous
    contact_info = {
        "contacts": int(ver.data.n * 4),
        "distinct_points": len(geo.points),
        "max_distance_m": float(geo.distance.max()),
        "off_mesh_points": int(off.sum()),
        "ambiguous_points": int(ambiguous.sum()),
        "two_sided_points": int(geo.two_sided.sum()),
        "edge_points": int((ambiguous & ~geo.two_sided).sum()),
        "pairs_with_ambiguous_contacts": int(ambiguous[ver.point_of].any(axis=1).sum()),
        "tolerance_m": tolerance_m,
    }
    if off.any():
        notes.append(
            f"{int(off.sum())} distinct contact points are off the mesh by more than "
            f"{tolerance_m:g} m (max {geo.distance.max():.3g} m)"
        )
    return contact_info


def _primary_normals(
    ver: _Verifier, h5_path: Path, contact_info: dict[str, Any], notes: list[str]
) -> tuple[FloatArray, str]:
    """``(N, 4, 3)`` normals of the first evaluation and their source.

    From the file (``"file"``) when it stores ``dg16m/contact_normals`` (checked, normalised,
    and counted against the faces under the contacts in ``contact_info``), else trimesh's face
    choice (``"mesh"``).
    """
    data = ver.data
    file_normals = data.extras.get(NORMALS_EXTRA)
    if file_normals is None:
        return ver.normals_for(), "mesh"
    file_normals = np.asarray(file_normals, dtype=np.float64)
    if file_normals.shape != (data.n, 4, 3) or not np.isfinite(file_normals).all():
        raise GraspFileError(
            f"{h5_path}: dg16m/{NORMALS_EXTRA}: expected finite values of shape "
            f"({data.n}, 4, 3), found shape {file_normals.shape}"
        )
    lengths = np.linalg.norm(file_normals, axis=-1)
    if (lengths < 1e-9).any():
        raise GraspFileError(
            f"{h5_path}: dg16m/{NORMALS_EXTRA}: expected non-zero normals, found "
            f"{int((lengths < 1e-9).sum())} zero vectors"
        )
    normals = file_normals / lengths[..., None]
    matched = 0
    for i, k in itertools.product(range(data.n), range(4)):
        faces = ver.geo.options[int(ver.point_of[i, k])]
        if (ver.face_normals[faces] @ normals[i, k]).max() >= 0.9999:
            matched += 1
    contact_info["file_normals_matching_a_face"] = matched
    notes.append(
        f"normals from the file (dg16m/{NORMALS_EXTRA}); {matched} of {data.n * 4} match "
        "the normal of a face under the contact"
    )
    return normals, "file"


def _failing_loss_summary(ver: _Verifier, result: ForceClosureResult) -> dict[str, Any]:
    """The report's ``failing_loss``: stored against recomputed losses of pairs both call
    failing (full rank)."""
    labelled, stored_pass = ver.labelled, ver.stored_pass
    both_fail = np.flatnonzero(labelled & ~stored_pass & ~result.passed & result.rank_ok)
    stored_l = ver.data.loss_values[both_fail]
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.abs(result.loss[both_fail] - stored_l) / np.where(stored_l > 0, stored_l, np.nan)
    rel = rel[np.isfinite(rel)]
    return {
        "compared": int(both_fail.size),
        "within_tolerance": int(ver.loss_matches(result.loss[both_fail], both_fail).sum()),
        "median_relative_difference": float(np.median(rel)) if rel.size else None,
        "max_relative_difference": float(rel.max()) if rel.size else None,
        "loss_rtol": ver.loss_rtol,
    }


@dataclass
class _Consistent:
    """The consistent resolution (one face per distinct contact point) of a file.

    Attributes:
        summary: the report's ``consistent`` (rounds, points fixed, agreement, ...).
        ok: ``(N,)`` pairs reproduced with the resolved faces.
        normals: ``(N, 4, 3)`` the resolved normals.
    """

    summary: dict[str, Any]
    ok: BoolArray
    normals: FloatArray


def _resolve_consistently(
    ver: _Verifier, result: ForceClosureResult, found: _Enumeration, max_combinations: int
) -> _Consistent:
    """Fix one face per contact point from the per-pair matches (:meth:`_Verifier.propagate`),
    re-evaluate the whole file with those faces and enumerate again for the pairs still
    disagreeing, for at most :data:`MAX_CONSISTENT_ROUNDS` rounds."""
    data = ver.data
    fixed: dict[int, int] = {}
    matches = found.matches
    rounds = deduced = guessed = 0
    c_result = result
    while rounds < MAX_CONSISTENT_ROUNDS:
        rounds += 1
        new_deduced, new_guessed = ver.propagate(matches, fixed)
        deduced += new_deduced
        guessed += new_guessed
        if not new_deduced + new_guessed:
            break
        c_result = evaluate(data.contact_points, ver.normals_for(fixed), **ver.fc_kwargs)
        c_dis = ver.disagreeing(c_result.passed, c_result.loss)
        if not c_dis.size:
            break
        more, _ = ver.enumerate(c_dis, fixed, max_combinations)
        matches = more.matches
    c_dis = ver.disagreeing(c_result.passed, c_result.loss)
    consistent_ok = np.ones(data.n, dtype=bool)
    consistent_ok[c_dis] = False
    labelled, stored_pass = ver.labelled, ver.stored_pass
    n_lab = int(labelled.sum())
    c_verdict = c_result.passed == stored_pass
    summary = {
        "rounds": rounds,
        "points_fixed": len(fixed),
        "points_deduced": deduced,
        "points_guessed": guessed,
        "points_switched": sum(1 for pos in fixed.values() if pos != 0),
        "ambiguous_points": int(ver.geo.ambiguous.sum()),
        "agreement": float(c_verdict[labelled].mean()),
        "agreement_full": float((labelled & consistent_ok).sum() / n_lab),
        "pass_to_fail": int((labelled & stored_pass & ~c_result.passed).sum()),
        "fail_to_pass": int((labelled & ~stored_pass & c_result.passed).sum()),
        "disagreeing": [int(i) for i in c_dis],
    }
    return _Consistent(summary, consistent_ok, ver.normals_for(fixed))


def _convention_suspect(summary: dict[str, Any], convention: str, notes: list[str]) -> bool:
    """Whether the consistent resolution switched most ambiguous points away from trimesh's
    face (on two-sided meshes that emulates the other convention); notes it when it did."""
    switched, ambiguous = summary["points_switched"], summary["ambiguous_points"]
    if not (ambiguous and switched > SUSPECT_SWITCHED * ambiguous):
        return False
    other = "release" if convention == "physical" else "physical"
    notes.append(
        f"the consistent resolution switched {switched} of {ambiguous} "
        f"ambiguous points away from trimesh's face: the file was probably made with "
        f"--convention {other}"
    )
    return True


def _disagreements(
    ver: _Verifier,
    result: ForceClosureResult,
    found: _Enumeration,
    dis: IntArray,
    off: BoolArray,
    consistent: _Consistent | None,
    threshold: float,
) -> list[Disagreement]:
    """A :class:`Disagreement` with its reason for every disagreeing pair, in index order."""
    geo = ver.geo
    contact_ambiguous = geo.ambiguous[ver.point_of]  # (N, 4)
    contact_off = off[ver.point_of]
    out = []
    for i in dis:
        i = int(i)
        out.append(
            _describe(
                i,
                ver,
                result,
                found,
                contact_ambiguous[i],
                geo.two_sided[ver.point_of[i]],
                contact_off[i],
                geo.distance[ver.point_of[i]],
                threshold,
                None if consistent is None else bool(consistent.ok[i]),
            )
        )
    return out


def _agreement_summary(
    ver: _Verifier, result: ForceClosureResult, dis: IntArray, disagreements: list[Disagreement]
) -> dict[str, Any]:
    """The report's counts of labelled pairs and agreement shares, with the primary normals
    and after the per-pair face choices that explain disagreements."""
    n = ver.data.n
    stored_pass, labelled = ver.stored_pass, ver.labelled
    n_lab = int(labelled.sum())
    verdict_ok = result.passed == stored_pass
    explained = np.zeros(n, dtype=bool)
    explained[[d.index for d in disagreements if d.explained]] = True
    resolved_verdict = verdict_ok | explained
    resolved_full = np.ones(n, dtype=bool)
    resolved_full[dis] = False
    resolved_full |= explained
    primary_full = np.ones(n, dtype=bool)
    primary_full[dis] = False
    return {
        "pairs": n,
        "stored_passing": int(stored_pass.sum()),
        "stored_failing": int((labelled & ~stored_pass).sum()),
        "unlabelled": int((~labelled).sum()),
        "agreement": float(verdict_ok[labelled].mean()) if n_lab else 1.0,
        "agreement_full": float((labelled & primary_full).sum() / max(n_lab, 1)),
        "pass_to_fail": int((labelled & stored_pass & ~result.passed).sum()),
        "fail_to_pass": int((labelled & ~stored_pass & result.passed).sum()),
        "rank_deficient": int((~result.rank_ok).sum()),
        "resolved_agreement": float(resolved_verdict[labelled].mean()) if n_lab else 1.0,
        "resolved_agreement_full": float((labelled & resolved_full).sum() / max(n_lab, 1)),
        "resolved_fail_to_pass": int((labelled & ~stored_pass & result.passed & ~explained).sum()),
    }


def _stored_forces_summary(
    ver: _Verifier, normals: FloatArray, consistent: _Consistent | None
) -> dict[str, Any]:
    """The report's ``stored_forces`` against the final normals (the consistent resolution's
    when it ran, with the primary normals' cone count beside them)."""
    if consistent is None:
        return _check_stored_forces(ver.data, normals, ver, ver.fc_kwargs)
    stored_forces = _check_stored_forces(ver.data, consistent.normals, ver, ver.fc_kwargs)
    primary_check = _check_stored_forces(ver.data, normals, ver, ver.fc_kwargs)
    stored_forces["pairs_outside_cones_primary_normals"] = primary_check["pairs_outside_cones"]
    return stored_forces


def _convention_notes(
    ver: _Verifier, result: ForceClosureResult, convention: str, notes: list[str]
) -> None:
    """Notes on the convention: a release file checked with the physical one, or metadata
    naming another convention than the one checked."""
    data = ver.data
    verdict_ok = result.passed == ver.stored_pass
    if convention == "physical" and not data.metadata and verdict_ok[ver.labelled].mean() < 0.9:
        notes.append(
            "this looks like a DG16M release file (no dg16m metadata) and few verdicts agree: "
            "the release's verdicts use --convention release"
        )
    stored_convention = data.metadata.get("convention")
    if isinstance(stored_convention, str) and stored_convention != convention:
        notes.append(f"the file's metadata says convention {stored_convention!r}")


def _contacts_text(indices: list[int]) -> str:
    return ",".join(str(k) for k in indices)


def _describe(
    i: int,
    ver: _Verifier,
    result: Any,
    found: _Enumeration,
    ambiguous: BoolArray,
    two_sided: BoolArray,
    off: BoolArray,
    distance: FloatArray,
    threshold: float,
    consistent: bool | None,
) -> Disagreement:
    """The :class:`Disagreement` of pair ``i`` with its reason."""
    stored_passed = bool(ver.stored_pass[i])
    stored_loss = float(ver.data.loss_values[i])
    ours_passed = bool(result.passed[i])
    ours_loss = float(result.loss[i]) if np.isfinite(result.loss[i]) else None
    kind = "verdict" if ours_passed != stored_passed else "loss"
    amb = [k for k in range(4) if ambiguous[k]]
    base = Disagreement(
        index=i,
        kind=kind,
        stored_passed=stored_passed,
        stored_loss=stored_loss,
        passed=ours_passed,
        loss=ours_loss,
        explained=False,
        reason="",
        consistent=consistent,
    )
    if i in found.first:
        choice, loss = found.first[i]
        switched = [k for k in range(4) if choice[k] != 0]
        sided = [k for k in amb if two_sided[k]]
        edges = [k for k in amb if not two_sided[k]]
        where = []
        if sided:
            where.append(f"{_contacts_text(sided)} on coincident opposite faces")
        if edges:
            where.append(f"{_contacts_text(edges)} on edges")
        reason = (
            f"ambiguous normals (contacts {'; '.join(where)}); reproduced with another face at "
            f"contacts {switched}"
        )
        if not stored_passed:
            reason += f" (loss {loss:.4g}, stored {stored_loss:.4g})"
        base.explained = True
        base.reason = reason
        base.switched_contacts = switched
        base.resolved_loss = loss
        return base
    evaluated, possible = found.searched.get(i, (0, 0))
    if stored_passed == (stored_loss > threshold):
        verdict = "pass" if stored_passed else "fail"
        base.reason = (
            f"the stored verdict ({verdict}) contradicts the stored loss {stored_loss:.4g} "
            f"(threshold {threshold:g})"
        )
    elif off.any():
        k = int(np.argmax(np.where(off, distance, -1.0)))
        base.reason = f"contact {k} off the mesh by {distance[k]:.3g} m"
    elif not result.rank_ok[i]:
        base.reason = "rank-deficient (collinear contacts)"
    elif kind == "verdict" and max(stored_loss, ours_loss or 0.0) <= 100 * threshold:
        base.reason = (
            f"loss near the threshold (ours {_fmt_loss(ours_loss)}, stored {stored_loss:.4g})"
        )
    elif len(amb) == 4 and evaluated:
        what = "stored loss" if not stored_passed else "stored pass"
        base.reason = (
            f"all four contacts on ambiguous faces, no face choice reproduces {what} "
            f"(stored {stored_loss:.4g}, ours {_fmt_loss(ours_loss)})"
        )
    else:
        base.reason = f"stored loss {stored_loss:.4g} vs ours {_fmt_loss(ours_loss)}"
        if amb and evaluated:
            base.reason += f" (no face choice at ambiguous contacts {amb} reproduces it)"
    if evaluated and evaluated < possible:
        base.reason += f" [searched {evaluated} of {possible} face choices]"
    return base


def _check_stored_forces(
    data: io.DualGraspSet, normals: FloatArray, ver: _Verifier, fc_kwargs: dict[str, Any]
) -> dict[str, Any]:
    """Residual of the stored forces against the stored loss, and their friction-cone fit."""
    forces = data.contact_forces
    w = gravity_wrench(fc_kwargs["mass"], fc_kwargs["gravity"])
    residual = np.linalg.norm(apply_grasp(data.contact_points, forces) + w, axis=1)
    violation = ver.cone_violation(np.arange(data.n), normals)
    stored = data.loss_values
    passing = ver.stored_pass & ver.labelled
    failing = ver.labelled & ~ver.stored_pass
    out: dict[str, Any] = {
        "residual_vs_loss_max_abs_passing": (
            float(np.abs(residual - stored)[passing].max()) if passing.any() else None
        ),
        "residual_max_passing": float(residual[passing].max()) if passing.any() else None,
        "cone_violation_max_n": float(violation.max()),
        "pairs_outside_cones": int((violation > CONE_TOLERANCE_N).sum()),
        "pairs_outside_cones_passing": int((violation[passing] > CONE_TOLERANCE_N).sum()),
        "max_force_n": float(np.linalg.norm(forces, axis=-1).max()),
    }
    if failing.any():
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.abs(residual - stored)[failing] / stored[failing]
        rel = rel[np.isfinite(rel)]
        out["residual_vs_loss_median_rel_failing"] = float(np.median(rel)) if rel.size else None
        out["residual_vs_loss_max_rel_failing"] = float(rel.max()) if rel.size else None
    return out


__all__ = [
    "CONE_TOLERANCE_N",
    "LOSS_ATOL",
    "MAX_TOTAL_COMBINATIONS",
    "OPPOSITE_NORMAL_DOT",
    "SAME_NORMAL_DOT",
    "TEXT_LIMIT",
    "ContactGeometry",
    "Disagreement",
    "VerifyReport",
    "contact_geometry",
    "format_report",
    "load_release_mesh",
    "verify_file",
]
