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
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from . import io
from .errors import Dg16mError, GraspFileError, MeshError
from .force_closure import (
    CONVENTIONS,
    ForceClosureResult,
    evaluate,
    gravity_wrench,
    project_cone_ball,
)
from .force_closure.geometry import apply_grasp
from .json_values import json_ready
from .parameters import PAPER

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

#: Two face normals are the same choice when their dot product is at least this.
SAME_NORMAL_DOT = 1.0 - 1e-10
#: Two face normals are opposite (two-sided surface) when their dot product is at most this.
OPPOSITE_NORMAL_DOT = -1.0 + 1e-6
#: Absolute slack of the loss comparison (N), added to ``loss_rtol * stored``.
LOSS_ATOL = 1e-6
#: At most this many alternative face choices are evaluated per round over the whole file.
MAX_TOTAL_COMBINATIONS = 200_000
#: Rounds of the consistent (one face per point) resolution.
MAX_CONSISTENT_ROUNDS = 6
#: A stored force "sits in its cone" when it is within this distance (N) of the cone-ball.
CONE_TOLERANCE_N = 1e-4
#: Our solver's loss accuracy (relative) is at least this much tighter than the comparison's.
SOLVER_RTOL = 1e-5
#: More than this share of ambiguous points needing another face than trimesh's points to the
#: other convention (a tie-break agrees with trimesh's about half the time by chance).
SUSPECT_SWITCHED = 0.75
#: Text output lists at most this many disagreeing pairs.
TEXT_LIMIT = 20
#: Extra array (``dg16m/<name>``) holding the generator's own outward contact normals.
NORMALS_EXTRA = "contact_normals"


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
    """What :func:`verify_file` found. ``to_dict()`` is JSON-serialisable; ``format_text()`` is the
    command's output.

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
# Mesh and contact geometry
# --------------------------------------------------------------------------------------------


def load_release_mesh(path: str | Path, scale: float) -> trimesh.Trimesh:
    """Load ``path`` as the released code did: ``trimesh.load(path, force="mesh")`` (trimesh's
    default processing, no cleaning), scaled by ``scale``, translated by ``-centroid``.

    Raises:
        MeshError: missing or unreadable file, or no triangles in it.
    """
    path = Path(path)
    if not path.exists():
        raise MeshError(f"{path}: no such file")
    if path.is_dir():
        raise MeshError(f"{path}: expected a mesh file, found a directory")
    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as exc:  # third-party parsers raise anything on hostile input
        raise MeshError(
            f"{path}: could not be loaded as a triangle mesh ({type(exc).__name__}: {exc})"
        ) from exc
    if not isinstance(mesh, trimesh.Trimesh):
        raise MeshError(f"{path}: expected a triangle mesh, found {type(mesh).__name__}")
    if len(mesh.faces) == 0 or not np.isfinite(mesh.vertices).all():
        raise MeshError(
            f"{path}: expected finite vertices and at least one triangle, found "
            f"{len(mesh.vertices)} vertices and {len(mesh.faces)} faces"
        )
    if mesh.area <= 0:
        raise MeshError(f"{path}: expected a surface with positive area, found area 0")
    mesh.apply_scale(float(scale))
    mesh.apply_translation(-mesh.centroid)
    return mesh


@dataclass
class ContactGeometry:
    """Faces under the distinct contact points of a file.

    Attributes:
        points: ``(U, 3)`` distinct contact points.
        inverse: ``(N * 4,)`` index into ``points`` of each contact (pair-major).
        distance: ``(U,)`` distance to the mesh (m).
        primary: ``(U,)`` face returned by ``mesh.nearest.on_surface`` (trimesh's choice).
        options: per point, faces with pairwise different normals, primary first (one face when
            the point is unambiguous or off the mesh).
        two_sided: ``(U,)`` some of the point's faces have opposite normals.
    """

    points: FloatArray
    inverse: IntArray
    distance: FloatArray
    primary: IntArray
    options: list[list[int]]
    two_sided: BoolArray

    @property
    def ambiguous(self) -> BoolArray:
        """``(U,)`` points on several faces with different normals."""
        return np.array([len(o) > 1 for o in self.options], dtype=bool)


def contact_geometry(
    mesh: trimesh.Trimesh, contact_points: FloatArray, tolerance_m: float
) -> ContactGeometry:
    """Nearest face, distance and the set of faces (within ``tolerance_m``) under each distinct
    contact point of ``contact_points`` ``(N, 4, 3)``."""
    flat = np.asarray(contact_points, dtype=np.float64).reshape(-1, 3)
    points, inverse = np.unique(flat, axis=0, return_inverse=True)
    inverse = np.asarray(inverse, dtype=np.int64).reshape(-1)
    _, distance, primary = mesh.nearest.on_surface(points)
    primary = np.asarray(primary, dtype=np.int64)
    normals = np.asarray(mesh.face_normals, dtype=np.float64)
    valid_face = np.linalg.norm(normals, axis=1) > 0.5

    ids, counts = mesh.triangles_tree.intersection_v(points - tolerance_m, points + tolerance_m)
    ids = np.asarray(ids, dtype=np.int64)
    rows = np.repeat(np.arange(len(points)), np.asarray(counts, dtype=np.int64))
    if ids.size:
        close = trimesh.triangles.closest_point(mesh.triangles[ids], points[rows])
        near = np.linalg.norm(close - points[rows], axis=1) <= tolerance_m
        near &= valid_face[ids]
        ids, rows = ids[near], rows[near]
    order = np.lexsort((ids, rows))
    ids, rows = ids[order], rows[order]
    starts = np.searchsorted(rows, np.arange(len(points) + 1))

    options: list[list[int]] = []
    two_sided = np.zeros(len(points), dtype=bool)
    for u in range(len(points)):
        first = int(primary[u])
        if not valid_face[first]:  # a degenerate face won: take the nearest usable one
            candidates = ids[starts[u] : starts[u + 1]]
            if candidates.size == 0:
                raise MeshError(
                    f"contact point {points[u].tolist()} lies on a degenerate face {first} "
                    "(zero area, no normal) and on no other face"
                )
            first = int(candidates[0])
            primary[u] = first
        chosen = [first]
        if distance[u] <= tolerance_m:
            for face in ids[starts[u] : starts[u + 1]]:
                dots = normals[chosen] @ normals[face]
                if dots.max() < SAME_NORMAL_DOT:
                    chosen.append(int(face))
                    two_sided[u] |= bool(dots.min() <= OPPOSITE_NORMAL_DOT)
        options.append(chosen)
    return ContactGeometry(points, inverse, np.asarray(distance), primary, options, two_sided)


# --------------------------------------------------------------------------------------------
# Face-choice enumeration
# --------------------------------------------------------------------------------------------


def _choice_positions(sizes: list[int], cap: int) -> Iterator[tuple[int, ...]]:
    """Positions into each contact's option list, all-zero excluded, fewest non-zero first."""
    varying = [k for k, s in enumerate(sizes) if s > 1]
    produced = 0
    for count in range(1, len(varying) + 1):
        for subset in itertools.combinations(varying, count):
            for picks in itertools.product(*(range(1, sizes[k]) for k in subset)):
                if produced >= cap:
                    return
                choice = [0] * len(sizes)
                for k, pick in zip(subset, picks, strict=True):
                    choice[k] = pick
                produced += 1
                yield tuple(choice)


@dataclass
class _Enumeration:
    """Reproducing face choices of a batch of pairs (choices are option indices per contact)."""

    matches: dict[int, list[tuple[int, ...]]]
    first: dict[int, tuple[tuple[int, ...], float]]  # pair -> (choice, loss) of the best match
    searched: dict[int, tuple[int, int]]  # pair -> (evaluated, possible)


class _Verifier:
    """Shared state of one verification (file, mesh geometry, stored labels, evaluate settings)."""

    def __init__(
        self,
        data: io.DualGraspSet,
        geometry: ContactGeometry,
        face_normals: FloatArray,
        fc_kwargs: dict[str, Any],
        loss_rtol: float,
        progress: bool,
    ) -> None:
        self.data = data
        self.geo = geometry
        self.face_normals = face_normals
        self.fc_kwargs = fc_kwargs
        self.loss_rtol = loss_rtol
        self.progress = progress
        n = data.n
        self.stored_pass = np.zeros(n, dtype=bool)
        self.stored_pass[data.passing_indices] = True
        self.labelled = self.stored_pass.copy()
        self.labelled[data.failed_indices] = True
        self.point_of = geometry.inverse.reshape(n, 4)

    def normals_for(self, choice: dict[int, int] | None = None) -> FloatArray:
        """``(N, 4, 3)`` mesh normals with the primary face, or ``choice[point]`` option index."""
        faces = self.geo.primary.copy()
        for u, pos in (choice or {}).items():
            faces[u] = self.geo.options[u][pos]
        return self.face_normals[faces[self.point_of]]

    def cone_violation(self, pairs: IntArray, normals: FloatArray) -> FloatArray:
        """``(len(pairs),)`` largest distance (N) of a stored force from its friction cone-ball."""
        forces = self.data.contact_forces[pairs]
        axes = normals if self.fc_kwargs["convention"] == "release" else -normals
        projected = project_cone_ball(forces, axes, self.fc_kwargs["mu"], self.fc_kwargs["f_high"])
        return np.linalg.norm(forces - projected, axis=-1).max(axis=1)

    def loss_matches(self, loss: FloatArray, pairs: IntArray) -> BoolArray:
        stored = self.data.loss_values[pairs]
        with np.errstate(invalid="ignore"):
            close = np.abs(loss - stored) <= self.loss_rtol * stored + LOSS_ATOL
        return np.where(np.isnan(loss), False, close)

    def reproduces(self, passed: BoolArray, loss: FloatArray, pairs: IntArray) -> BoolArray:
        """Whether (passed, loss) reproduce the stored verdict (and loss of stored failures)."""
        stored = self.stored_pass[pairs]
        return (passed == stored) & (stored | self.loss_matches(loss, pairs))

    def disagreeing(self, passed: BoolArray, loss: FloatArray) -> IntArray:
        everything = np.arange(self.data.n)
        ok = self.reproduces(passed, loss, everything)
        return np.flatnonzero(self.labelled & ~ok)

    def enumerate(
        self, pairs: IntArray, fixed: dict[int, int], max_per_pair: int
    ) -> tuple[_Enumeration, int]:
        """Evaluate alternative faces at the unfixed ambiguous contacts of ``pairs`` in one batch.

        At most ``max_per_pair`` choices per pair, fewer when the batch would exceed
        :data:`MAX_TOTAL_COMBINATIONS` (but at least 15, every choice of four two-faced contacts).
        Returns the reproducing choices and the number of choices evaluated.
        """
        found = _Enumeration({}, {}, {})
        rows: list[int] = []
        faces: list[list[int]] = []
        choices: list[tuple[int, ...]] = []
        plans = []
        for i in pairs:
            opts = []
            for u in self.point_of[i]:
                u = int(u)
                all_opts = self.geo.options[u]
                if u in fixed or len(all_opts) == 1:
                    base = fixed.get(u, 0)
                    opts.append([base])
                else:
                    opts.append(list(range(len(all_opts))))
            sizes = [len(o) for o in opts]
            if max(sizes) > 1:
                plans.append((int(i), opts, sizes))
        cap = min(max_per_pair, max(15, MAX_TOTAL_COMBINATIONS // max(len(plans), 1)))
        for i, opts, sizes in plans:
            possible = int(np.prod(sizes)) - 1
            evaluated = 0
            for pos in _choice_positions(sizes, cap):
                choice = tuple(opts[k][p] for k, p in enumerate(pos))
                points = self.point_of[i]
                # the same point twice in a pair must get the same face
                if any(
                    choice[a] != choice[b]
                    for a in range(4)
                    for b in range(a + 1, 4)
                    if points[a] == points[b]
                ):
                    continue
                rows.append(i)
                choices.append(choice)
                faces.append([self.geo.options[int(points[k])][choice[k]] for k in range(4)])
                evaluated += 1
            found.searched[i] = (evaluated, possible)
        if not rows:
            return found, 0
        row_arr = np.asarray(rows, dtype=np.int64)
        normals = self.face_normals[np.asarray(faces, dtype=np.int64)]
        result = evaluate(
            self.data.contact_points[row_arr],
            normals,
            progress=self.progress,
            **self.fc_kwargs,
        )
        ok = self.reproduces(result.passed, result.loss, row_arr)
        gap = np.abs(result.loss - self.data.loss_values[row_arr])
        outside = self.cone_violation(row_arr, normals) > CONE_TOLERANCE_N
        ranked: dict[int, list[tuple[bool, float, int]]] = {}
        for j in np.flatnonzero(ok):
            # choices whose cones hold the stored forces first; then for stored failures the
            # loss closest to the stored one; then enumeration order (fewest changes first)
            score = 0.0 if self.stored_pass[rows[j]] else float(gap[j])
            ranked.setdefault(rows[j], []).append((bool(outside[j]), score, int(j)))
        for i, entries in ranked.items():
            entries.sort()
            found.matches[i] = [choices[j] for _, _, j in entries]
            best = entries[0][2]
            found.first[i] = (choices[best], float(result.loss[best]))
        return found, len(rows)

    def _live(
        self, i: int, matches: dict[int, list[tuple[int, ...]]], fixed: dict[int, int]
    ) -> list[tuple[int, ...]]:
        points = [int(u) for u in self.point_of[i]]
        return [
            c for c in matches[i] if all(fixed.get(u, c[k]) == c[k] for k, u in enumerate(points))
        ]

    def _open_points(self, i: int, fixed: dict[int, int]) -> list[int]:
        return [
            k
            for k, u in enumerate(self.point_of[i])
            if int(u) not in fixed and len(self.geo.options[int(u)]) > 1
        ]

    def propagate(
        self, matches: dict[int, list[tuple[int, ...]]], fixed: dict[int, int]
    ) -> tuple[int, int]:
        """Choose one face per point so that every pair in ``matches`` keeps a reproducing choice.

        Deduction first: a point is fixed when all of a pair's remaining reproducing choices
        agree on it. When that stalls, the pair with the fewest remaining choices takes its best
        one (a guess) and deduction resumes. Pairs left without a consistent choice are skipped
        (they show up as disagreements when the file is re-evaluated).

        Returns:
            (points fixed by deduction, points fixed by a guess).
        """
        deduced = guessed = 0
        while True:
            changed = True
            while changed:
                changed = False
                for i in sorted(matches):
                    live = self._live(i, matches, fixed)
                    if not live:
                        continue
                    for k in self._open_points(i, fixed):
                        values = {c[k] for c in live}
                        if len(values) == 1:
                            fixed[int(self.point_of[i, k])] = values.pop()
                            deduced += 1
                            changed = True
            open_pairs = []
            for i in sorted(matches):
                live = self._live(i, matches, fixed)
                if live and self._open_points(i, fixed):
                    open_pairs.append((len(live), i, live[0]))
            if not open_pairs:
                return deduced, guessed
            _, i, choice = min(open_pairs)
            for k in self._open_points(i, fixed):
                fixed[int(self.point_of[i, k])] = choice[k]
                guessed += 1


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


def _fmt_loss(value: float | None) -> str:
    return "n/a (rank-deficient)" if value is None or not np.isfinite(value) else f"{value:.4g}"


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


# --------------------------------------------------------------------------------------------
# Text
# --------------------------------------------------------------------------------------------


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
    "ContactGeometry",
    "Disagreement",
    "VerifyReport",
    "contact_geometry",
    "format_report",
    "load_release_mesh",
    "verify_file",
]
