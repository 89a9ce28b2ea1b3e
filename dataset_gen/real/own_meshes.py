"""Your own loose mesh files made into a mesh folder for ``dg16m benchmark build``.

``dg16m objects repair IN --out DIR`` (:func:`repair_meshes`) takes mesh files (a folder of them, or
single files) whose units, up axis and quality are unknown and writes, per mesh, ``DIR/<stem>.obj``:
one watertight body in metres, z up, with at most ``target_faces`` faces, made by the importer's
measured repair (:func:`dataset_gen.real.repair.repair_mesh`: filled-voxel remesh, largest piece,
Taubin smoothing, half-voxel inset, stepwise quadric decimation), with its deviation from the source
surface measured both ways (:func:`dataset_gen.real.repair.surface_deviation`). A mesh that is
already one watertight body within the face budget is only turned and scaled: repair only what needs
it. ``DIR/manifest.json`` (kind :data:`REPAIR_KIND`, written atomically after every mesh) records
per mesh the source file and its sha256, the up axis and the units decision (with ``warnings``), the
operations applied in words, the repair report, the deviation and the sha256 of the OBJ written.
``DIR`` holds nothing else, so ``dg16m benchmark build --meshes DIR`` reads it as any folder of
meshes in metres.

Up axis, per mesh (:func:`~dataset_gen.real.orientation.up_axis`)
----------------------------------------------------------------
Every mesh is written z up (gravity along -z in the simulator). ``--up y|z`` gives the sources' up
axis; ``--up auto`` (the default) takes z for a mesh dg16m wrote (a folder whose ``manifest.json``
dg16m wrote, or an OBJ whose header comment names dg16m), a COLLADA file's ``<up_axis>``, else the
format's convention: OBJ y up (the convention of the applications that write it: Sweet Home 3D,
Blender's default export), GLB/glTF y up (the specification; trimesh reads the coordinates as they
are, it does not turn them), STL, PLY, OFF and 3MF z up. A y-up mesh is turned +90 degrees about x
(:data:`~dataset_gen.real.orientation.Y_UP_TO_Z_UP`, the turn of the Sweet Home 3D importer), before
the units are decided (a rotation keeps the longest side). The axis and how it was decided (given,
detected, assumed) are printed and stored per mesh (``up``); ``up`` is part of the request a rerun
compares, so a changed ``--up``, or an entry of a version without it, redoes the mesh instead of
mixing axes.

Units, per mesh (:func:`decide_units`)
--------------------------------------
``--units m|cm|mm|inch`` gives the file's unit; ``--target-extent METRES`` scales every mesh to
that longest side. The result must lie in the dual-arm range
[:data:`~dataset_gen.objects.grasp_object.DUAL_ARM_MIN_EXTENT_M`,
:data:`~dataset_gen.objects.grasp_object.DUAL_ARM_MAX_EXTENT_M`] (0.05-5 m) either way. Without either flag
the unit is guessed, and the guess is refused rather than made wrong:

* the candidates are metres, centimetres and millimetres (:data:`~dataset_gen.objects.grasp_object.GUESSED_UNITS`); inches are
  never guessed (an inch file's 8-80 units read as plausible centimetres or metres just as
  often): pass ``--units inch``;
* a candidate is taken when the longest side it gives lies in
  :data:`~dataset_gen.objects.grasp_object.TYPICAL_EXTENT_M`,
  0.3-2 m, the size of a thing two arms lift (the benchmark's objects are 0.3-1.2 m; furniture
  longer than 2 m is not lifted by two Pandas). The range spans less than a factor of 10, so
  at most one candidate lies in it, and the files between (2-30 units: metres or centimetres?
  200-300 units: a 2.3 m sofa in centimetres or a 23 cm box in millimetres?) are asked about;
* no candidate in range: the mesh fails with the longest side it found, what each unit would
  make of it and the flags to pass. A chair of 9.02 units (9.02 m, or 9.02 cm) is asked about,
  never told to be centimetres; an armchair of 2.1 units is asked about, not taken as 2.1 m;
* a guess that makes a file of a unitless format (OBJ, STL, PLY, OFF) longer than
  :data:`~dataset_gen.objects.grasp_object.LARGE_GUESS_M` (1.5 m, table-sized) is kept with a
  warning (:func:`~dataset_gen.objects.grasp_object.large_guess_warning`).

The guess is :func:`~dataset_gen.objects.grasp_object.guess_units`, the one rule that ``objects
check`` and the size check of ``benchmark build`` and ``generate`` use too (a 100-unit bar is
1 m in centimetres for each). Only a units failure (:class:`UnitsError`, the entry's
``error_kind`` ``"units"``) is told to rerun with ``--units``; an empty or unreadable file fails
with its own reason.

The decision and what it assumed are printed for every mesh and stored in the manifest.
Measured on 60 raw Sweet Home 3D models (catalogue sizes known; ``bench/objects_repair.py``):
see BENCHMARKS.md ("Your own meshes").

Reruns: a mesh whose manifest entry is ok, made from a source with the same sha256 and the same
request (units flags, up axis, repair settings), whose OBJ is still there with its recorded sha256,
is kept; every other mesh is (re)done. So ``dg16m objects repair raw/chair.obj --out DIR --units
cm`` after a run that asked about the chair's units repairs only the chair. Nothing already written
is lost: a mesh that fails where an earlier run repaired it keeps the earlier OBJ and entry, with
the failure added as ``last_failure`` (the run still lists it as failed). One writer per folder.
"""

from __future__ import annotations

import hashlib
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from dataset_gen.objects.grasp_object import (
    DUAL_ARM_MAX_EXTENT_M,
    DUAL_ARM_MIN_EXTENT_M,
    MESH_SUFFIXES,
    TYPICAL_EXTENT_M,
    UNIT_FACTORS,
    UNIT_NAMES,
    CleaningReport,
    clean_mesh,
    guess_units,
    large_guess_warning,
    load_mesh,
    read_mesh_arrays,
    unit_readings,
)
from dataset_gen.real.orientation import UP_CHOICES, UpAxis, turn_z_up, up_axis
from dataset_gen.real.repair import (
    RepairParameters,
    RepairReport,
    is_one_volume,
    obj_round_trip,
    repair_mesh,
    surface_deviation,
)
from dataset_gen.sources.object_source import object_seed
from dg16m_core.atomic import write_bytes_atomic
from dg16m_core.errors import Dg16mError, MeshError
from dg16m_core.hashing import file_sha256

REPAIR_KIND = "mesh-repair"
"""``kind`` of the manifest of a folder written by :func:`repair_meshes`."""

INPUT_SUFFIXES = (*MESH_SUFFIXES, ".3mf", ".dae")
"""Mesh files ``objects repair`` reads: what ``objects check`` reads, and 3MF; COLLADA
(``.dae``) when pycollada is installed (else each such file fails with the reason)."""

DEVIATION_SAMPLES = 5000
"""Points sampled on each surface for the deviation (as the importer)."""


class RepairInputError(MeshError):
    """Bad input to a whole repair run (no meshes, two files for one name, a bad ``--out``)."""


class UnitsError(MeshError):
    """A mesh's units cannot be guessed, or the given units make an implausible size: the one
    failure that ``--units`` or ``--target-extent`` fixes."""


# --------------------------------------------------------------------------------------------
# Units
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class UnitsDecision:
    """How a file's coordinates became metres.

    Attributes:
        how: ``"given"`` (``--units``), ``"target-extent"`` or ``"guessed"``.
        units: the file's unit (a key of :data:`UNIT_FACTORS`); ``None`` for a target extent.
        scale: metres per file unit applied.
        longest_side_file: the cleaned mesh's longest bounding-box side in file units.
        longest_side_m: the same after scaling (m).
    """

    how: str
    units: str | None
    scale: float
    longest_side_file: float
    longest_side_m: float

    def note(self) -> str:
        """One line for people: what was assumed and how to change it."""
        size = f"{_number(self.longest_side_file)} units -> {_length(self.longest_side_m)}"
        if self.how == "guessed":
            assert self.units is not None
            return (
                f"units guessed: {UNIT_NAMES[self.units]} ({size}; the only unit giving "
                f"{TYPICAL_EXTENT_M[0]:g}-{TYPICAL_EXTENT_M[1]:g} m; pass --units or "
                "--target-extent if wrong)"
            )
        if self.how == "given":
            assert self.units is not None
            return f"units given: {UNIT_NAMES[self.units]} ({size})"
        return f"scaled to the target extent ({size}, scale {self.scale:.6g})"

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "note": self.note()}


def _number(value: float) -> str:
    return f"{value:.4g}"


def _length(metres: float) -> str:
    if metres < 0.01:
        return f"{metres * 1000:.3g} mm"
    return f"{metres:.3g} m"


_FLAGS = "--units m|cm|mm|inch or --target-extent METRES (the longest side)"


def decide_units(
    longest_side: float,
    *,
    units: str | None = None,
    target_extent: float | None = None,
    name: str = "mesh",
) -> UnitsDecision:
    """The scale to metres of a mesh whose longest side is ``longest_side`` file units
    (module docstring, "Units").

    Raises:
        MeshError: the size in the given units is outside the dual-arm range, or no guessed
            unit gives a typical size; the message names ``name``, the extent and the flags.
    """
    longest = float(longest_side)
    if not (math.isfinite(longest) and longest > 0):
        raise MeshError(f"{name}: expected a positive finite longest side, found {longest!r}")
    if units is not None and target_extent is not None:
        raise MeshError(f"{name}: give either --units or --target-extent, not both")
    low, high = DUAL_ARM_MIN_EXTENT_M, DUAL_ARM_MAX_EXTENT_M
    if target_extent is not None:
        size = float(target_extent)
        if not (math.isfinite(size) and low <= size <= high):
            raise MeshError(
                f"--target-extent: expected a longest side of {low:g}-{high:g} m, found {size!r}"
            )
        return UnitsDecision("target-extent", None, size / longest, longest, size)
    if units is not None:
        if units not in UNIT_FACTORS:
            raise MeshError(f"--units: expected one of {', '.join(UNIT_FACTORS)}, found {units!r}")
        size = longest * UNIT_FACTORS[units]
        if not low <= size <= high:
            raise UnitsError(
                f"{name}: longest side {_number(longest)} units, {_length(size)} in "
                f"{UNIT_NAMES[units]}: expected {low:g}-{high:g} m for a dual-arm object; pass "
                f"other --units or --target-extent METRES"
            )
        return UnitsDecision("given", units, UNIT_FACTORS[units], longest, size)
    unit = guess_units(longest)  # the one rule, shared with objects check and build
    if unit is not None:
        factor = UNIT_FACTORS[unit]
        return UnitsDecision("guessed", unit, factor, longest, longest * factor)
    raise UnitsError(
        f"{name}: longest side {_number(longest)} units: cannot guess the units "
        f"({unit_readings(longest)}); pass {_FLAGS}"
    )


# --------------------------------------------------------------------------------------------
# One mesh
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RepairItem:
    """One source file of a run: its object id (the file stem), path and sha256."""

    object_id: str
    path: str
    sha256: str


def read_source(path: Path) -> tuple[trimesh.Trimesh, CleaningReport]:
    """A source mesh cleaned as ``objects check`` cleans it, in the file's units; also reads
    :data:`INPUT_SUFFIXES` beyond :data:`~dataset_gen.objects.grasp_object.MESH_SUFFIXES`.

    Raises:
        MeshError: missing, empty, unparsable, no faces, NaN/inf, flat (see
            :func:`~dataset_gen.objects.grasp_object.load_mesh`), or COLLADA without pycollada.
    """
    suffix = path.suffix.lower()
    if suffix in MESH_SUFFIXES:
        return load_mesh(path)
    if suffix == ".dae":
        try:
            import collada  # noqa: F401  (pycollada, trimesh's COLLADA reader)
        except ImportError:
            raise MeshError(
                f"{path}: COLLADA (.dae) files need the pycollada package, found it missing "
                "(pip install pycollada, or export the mesh as OBJ, PLY or GLB)"
            ) from None
    if path.stat().st_size == 0:
        raise MeshError(f"{path}: expected a mesh with faces, found an empty file (0 bytes)")
    vertices, faces = read_mesh_arrays(path)
    return clean_mesh(vertices, faces, name=str(path))


def operations(
    units: UnitsDecision,
    cleaning: CleaningReport,
    report: RepairReport | None,
    params: RepairParameters,
    faces: int,
    up: UpAxis | None = None,
) -> list[str]:
    """What was done to a source, in order, in words (the manifest's ``operations``)."""
    done = []
    words = cleaning.words()
    if words:
        done.append(f"cleaned: {words}")
    if up is not None and up.axis == "y":
        done.append(f"turned from y up to z up, +90 deg about x (up axis {up.how}: {up.why})")
    how = {"guessed": "units guessed", "given": "units given"}.get(units.how, "target extent")
    unit = f": {UNIT_NAMES[units.units]}" if units.units else ""
    done.append(
        f"scaled by {units.scale:.6g} to a longest side of {units.longest_side_m:.4g} m "
        f"({how}{unit})"
    )
    if report is None:
        done.append(
            f"already one watertight body of {faces} faces (budget {params.target_faces}): "
            "kept as it is"
        )
        return done
    done.append(f"filled-voxel remesh at {1000 * report.pitch:.2f} mm ({report.voxel_faces} faces)")
    if report.pieces_dropped:
        done.append(f"largest piece kept ({report.pieces_dropped} smaller pieces dropped)")
    if params.smooth_iterations:
        done.append(f"Taubin smoothing ({params.smooth_iterations} iterations)")
    if report.inset:
        done.append(f"surface moved in by {1000 * report.inset:.2f} mm")
    fixes = f", {report.meshfix_calls} MeshFix repairs" if report.meshfix_calls else ""
    done.append(
        f"quadric decimation to {report.faces} faces in {report.decimation_steps} steps{fixes}"
    )
    return done


def repair_one(
    item: RepairItem,
    out: str,
    units: str | None,
    target_extent: float | None,
    params: RepairParameters,
    up: str = "auto",
) -> dict[str, Any]:
    """Repair one source into ``out/<id>.obj``, turned z up from its up axis
    (:func:`~dataset_gen.real.orientation.up_axis` of ``up``); returns its manifest entry
    (``status`` "ok", or "failed" with ``error`` and ``error_kind``: ``"units"`` for a
    :class:`UnitsError`, else ``"mesh"``). Never raises for a bad mesh: a broken file, no faces, NaN
    vertices, units that cannot be guessed or a repair that fails are the entry's ``error``."""
    start = time.perf_counter()
    path = Path(item.path)
    entry: dict[str, Any] = {
        "source": {"file": str(path), "sha256": item.sha256},
        "request": request_of(units, target_extent, params, up),
    }
    try:
        axis = up_axis(path, up)
        entry["up"] = axis.to_dict()
        mesh, cleaning = read_source(path)
        entry["source"].update(
            faces=len(mesh.faces),
            vertices=len(mesh.vertices),
            extents_file_units=[float(v) for v in mesh.extents],
            watertight=bool(mesh.is_watertight),
            pieces=int(mesh.body_count),
        )
        decision = decide_units(
            float(np.max(mesh.extents)), units=units, target_extent=target_extent, name=path.name
        )
        entry["units"] = decision.to_dict()
        scaled = turn_z_up(mesh, axis.axis).copy()
        scaled.apply_scale(decision.scale)
        if decision.how == "guessed":
            assert decision.units is not None
            warning = large_guess_warning(decision.units, scaled.extents, path.suffix)
            if warning:
                entry["warnings"] = [warning]
        repaired, report = _repair(scaled, params)
        rng = np.random.default_rng(object_seed(0, f"mesh-repair-deviation:{item.sha256}"))
        deviation = surface_deviation(repaired, scaled, samples=DEVIATION_SAMPLES, rng=rng)
    except UnitsError as exc:
        return _failed(entry, str(exc), path, start, "units")
    except Dg16mError as exc:
        return _failed(entry, str(exc), path, start)
    except Exception as exc:  # a third-party library's error on odd input: this mesh only
        error = f"{type(exc).__name__}: {exc} (an unexpected error; please report it)"
        return _failed(entry, error, path, start)
    text = repaired.export(file_type="obj", include_normals=False, include_texture=False)
    header = (
        f"# {item.object_id}: repaired by dg16m objects repair from {path.name} "
        f"(sha256 {item.sha256[:16]}...), metres, z up; see manifest.json\n"
    )
    data = (header + text).encode()
    name = f"{item.object_id}.obj"
    write_bytes_atomic(Path(out) / name, data)
    return {
        **entry,
        "status": "ok",
        "files": {"mesh": name},
        "sha256": hashlib.sha256(data).hexdigest(),
        "extents_m": [float(v) for v in repaired.extents],
        "faces": len(repaired.faces),
        "volume_m3": float(repaired.volume),
        "operations": operations(decision, cleaning, report, params, len(repaired.faces), axis),
        "repair": None if report is None else {**params.to_dict(), **report.to_dict()},
        "deviation_m": deviation.to_dict(),
        "seconds": time.perf_counter() - start,
    }


def _failed(
    entry: dict[str, Any], error: str, path: Path, start: float, kind: str = "mesh"
) -> dict[str, Any]:
    for prefix in (f"{path}: ", f"{path.name}: "):  # the entry names its file already
        if error.startswith(prefix):
            error = error[len(prefix) :]
    return {
        **entry,
        "status": "failed",
        "files": {},
        "error": error,
        "error_kind": kind,
        "seconds": time.perf_counter() - start,
    }


def _repair(
    scaled: trimesh.Trimesh, params: RepairParameters
) -> tuple[trimesh.Trimesh, RepairReport | None]:
    """``scaled`` as it is when it is already one watertight body within the face budget (after
    the OBJ round trip a reader does), else :func:`~dataset_gen.real.repair.repair_mesh`'s result."""
    if len(scaled.faces) <= params.target_faces:
        read_back = obj_round_trip(scaled)
        if is_one_volume(read_back):
            return read_back, None
    return repair_mesh(scaled, params)


def request_of(
    units: str | None,
    target_extent: float | None,
    params: RepairParameters,
    up: str = "auto",
) -> dict[str, Any]:
    """What a run asked for one mesh: a kept mesh must have been made with the same (an entry
    of an older version, without ``up``, is redone: it was written with the source's axis)."""
    return {
        "units": units,
        "target_extent_m": None if target_extent is None else float(target_extent),
        "up": up,
        "repair": params.to_dict(),
    }


# --------------------------------------------------------------------------------------------
# A run over many meshes
# --------------------------------------------------------------------------------------------


def find_meshes(
    inputs: Sequence[str | Path],
    suffixes: Sequence[str] = INPUT_SUFFIXES,
    one_per_stem: bool = True,
) -> tuple[list[Path], list[Path]]:
    """The mesh files named by ``inputs`` (folders, not recursive, and single files), sorted
    per folder, and the other files of those folders (skipped: ``.mtl``, textures, notes, hidden
    files). ``suffixes``: the mesh files' suffixes (``objects check`` reads
    :data:`~dataset_gen.objects.grasp_object.MESH_SUFFIXES`).

    Raises:
        RepairInputError: an input that is missing or is a file of another kind, no mesh file at
            all, or (``one_per_stem``) two files for one object id (the file stem).
    """
    meshes: list[Path] = []
    skipped: list[Path] = []
    for given in inputs:
        path = Path(given)
        if path.is_dir():
            for child in sorted(path.iterdir()):
                if not child.is_file():
                    continue
                is_mesh = child.suffix.lower() in suffixes and not child.name.startswith(".")
                (meshes if is_mesh else skipped).append(child)
        elif path.is_file():
            if path.suffix.lower() not in suffixes:
                raise RepairInputError(
                    f"{path}: expected a folder or a mesh file ({', '.join(suffixes)}), "
                    f"found a {path.suffix or 'suffix-less'} file"
                )
            meshes.append(path)
        else:
            raise RepairInputError(
                f"{path}: expected a folder of mesh files or a mesh file, found nothing there"
            )
    unique: dict[Path, Path] = {}
    for path in meshes:
        unique.setdefault(path.resolve(), path)
    meshes = list(unique.values())
    if not meshes:
        others = f" (only {len(skipped)} other files)" if skipped else ""
        raise RepairInputError(
            f"{', '.join(map(str, inputs))}: expected mesh files ({', '.join(suffixes)}), "
            f"found none{others}"
        )
    stems: dict[str, Path] = {}
    for path in meshes if one_per_stem else ():
        if path.stem in stems:
            raise RepairInputError(
                f"expected one mesh file per object id (the file stem), found {stems[path.stem]} "
                f"and {path} (both would write {path.stem}.obj); rename one"
            )
        stems[path.stem] = path
    return meshes, skipped


@dataclass
class RepairRun:
    """What :func:`repair_meshes` did: the folder's manifest and the ids by outcome."""

    out: Path
    manifest: dict[str, Any]
    repaired: list[str]
    kept: list[str]
    failed: list[str]
    skipped: list[Path]

    @property
    def ids(self) -> list[str]:
        return [*self.repaired, *self.kept, *self.failed]


def _check_out(out: Path, meshes: Sequence[Path]) -> dict[str, Any] | None:
    """The manifest already in ``out`` (``None`` for a new folder); refuses an ``out`` that is
    a file, that holds source meshes, or that holds another kind of folder."""
    from dataset_gen.io import read_manifest

    if out.exists() and not out.is_dir():
        raise RepairInputError(f"--out: expected a folder, found a file {out}")
    parents = {p.parent.resolve() for p in meshes}
    if out.exists() and out.resolve() in parents:
        raise RepairInputError(
            f"--out {out}: expected a folder other than the one holding the source meshes (the "
            "repaired OBJ files would replace them, and a build would read both)"
        )
    if not out.is_dir():
        return None
    if not (out / "manifest.json").is_file():
        strangers = sorted(p.name for p in out.iterdir() if p.suffix.lower() in INPUT_SUFFIXES)
        if strangers:
            raise RepairInputError(
                f"--out {out}: expected a new folder or one written by 'dg16m objects repair', "
                f"found mesh files without its manifest.json ({', '.join(strangers[:3])}"
                f"{', ...' if len(strangers) > 3 else ''}); use another --out"
            )
        return None
    manifest = read_manifest(out)
    if manifest["kind"] != REPAIR_KIND:
        raise RepairInputError(
            f"--out {out}: expected a new folder or one written by 'dg16m objects repair' "
            f"(manifest kind {REPAIR_KIND!r}), found kind {manifest['kind']!r}; use another --out"
        )
    return manifest


def _still_there(out: Path, entry: Mapping[str, Any] | None) -> bool:
    """Whether ``entry`` is ok and its OBJ is in ``out`` with the recorded sha256."""
    if not entry or entry.get("status") != "ok":
        return False
    mesh = out / entry["files"]["mesh"]
    return mesh.is_file() and file_sha256(mesh) == entry.get("sha256")


def _finished(out: Path, entry: Mapping[str, Any] | None, item: RepairItem, request: Any) -> bool:
    if not entry or entry.get("request") != request:
        return False
    if entry.get("source", {}).get("sha256") != item.sha256:
        return False
    return _still_there(out, entry)


def repair_meshes(
    inputs: Sequence[str | Path],
    out: str | Path,
    *,
    units: str | None = None,
    target_extent: float | None = None,
    params: RepairParameters | None = None,
    up: str = "auto",
    workers: int = 1,
    progress: bool = True,
    on_entry: Callable[[str, Mapping[str, Any], bool], None] | None = None,
) -> RepairRun:
    """Repair every mesh of ``inputs`` into ``out`` (module docstring).

    Args:
        inputs: folders of mesh files (not recursive) and mesh files.
        out: the output folder (created; a folder of an earlier run is added to).
        units: the files' unit (a key of :data:`UNIT_FACTORS`); ``None`` guesses per mesh.
        target_extent: scale every mesh to this longest side (m) instead.
        params: the repair's settings (default: the importer's).
        up: the sources' up axis, ``"y"`` or ``"z"``, or ``"auto"`` (per file,
            :func:`~dataset_gen.real.orientation.up_axis`); every mesh is written z up.
        workers: processes (1: this one).
        progress: show a progress bar over the meshes.
        on_entry: called with ``(object_id, entry, kept)`` for every mesh, as it is done (or at
            once for a mesh kept from an earlier run).

    Returns:
        The run; ``failed`` lists the meshes whose entry holds an ``error``.

    Raises:
        RepairInputError: bad input as a whole (see :func:`find_meshes`, a bad ``out``, bad
            ``units``, ``target_extent`` or ``up``); nothing is written then.
    """
    from dataset_gen.io import new_manifest, write_manifest
    from dataset_gen.pipeline.parallel import (
        check_backend,
        remembered_interrupts,
        remove_stale_temporaries,
        run_tasks,
    )

    params = params or RepairParameters()
    check_backend("local", workers, RepairInputError)
    if units is not None and target_extent is not None:
        raise RepairInputError("give either --units or --target-extent, not both")
    if units is not None and units not in UNIT_FACTORS:
        raise RepairInputError(
            f"--units: expected one of {', '.join(UNIT_FACTORS)}, found {units!r}"
        )
    if up not in UP_CHOICES:
        raise RepairInputError(f"--up: expected one of {', '.join(UP_CHOICES)}, found {up!r}")
    if target_extent is not None:
        low, high = DUAL_ARM_MIN_EXTENT_M, DUAL_ARM_MAX_EXTENT_M
        if not (isinstance(target_extent, (int, float)) and low <= target_extent <= high):
            raise RepairInputError(
                f"--target-extent: expected a longest side of {low:g}-{high:g} m, found "
                f"{target_extent!r}"
            )
    meshes, skipped = find_meshes(inputs)
    out = Path(out)
    manifest = _check_out(out, meshes)
    if manifest is None:
        manifest = new_manifest(
            REPAIR_KIND,
            {"typical_extent_m": list(TYPICAL_EXTENT_M), "deviation_samples": DEVIATION_SAMPLES},
        )
    out.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(out, (".",))
    request = request_of(units, target_extent, params, up)
    items = [RepairItem(p.stem, str(p), file_sha256(p)) for p in meshes]
    run = RepairRun(out, manifest, [], [], [], skipped)
    todo = []
    for item in items:
        entry = manifest["entries"].get(item.object_id)
        if _finished(out, entry, item, request):
            run.kept.append(item.object_id)
            if on_entry is not None:
                on_entry(item.object_id, entry, True)
        else:
            todo.append(item)
    bar = None
    if progress:
        from dg16m_core.progress import progress_bar

        bar = progress_bar(total=len(items), initial=len(run.kept), unit="mesh", desc="repair")
    try:
        with remembered_interrupts() as interrupted:
            results = run_tasks(
                repair_one, todo, (str(out), units, target_extent, params, up), workers=workers
            )
            try:
                for item, entry in results:
                    earlier = manifest["entries"].get(item.object_id)
                    if entry["status"] != "ok" and _still_there(out, earlier):
                        # nothing written is lost: the earlier mesh stays, with this failure
                        assert earlier is not None
                        failure = {
                            k: entry[k] for k in ("source", "request", "error", "error_kind")
                        }
                        manifest["entries"][item.object_id] = {**earlier, "last_failure": failure}
                        entry = {**entry, "kept_earlier": earlier["files"]["mesh"]}
                    else:
                        manifest["entries"][item.object_id] = entry
                    manifest["entries"] = dict(sorted(manifest["entries"].items()))
                    write_manifest(out, manifest)
                    (run.repaired if entry["status"] == "ok" else run.failed).append(item.object_id)
                    if on_entry is not None:
                        on_entry(item.object_id, entry, False)
                    if bar is not None:
                        bar.update(1)
                    if interrupted():  # a Ctrl-C that Python swallowed during the task
                        raise KeyboardInterrupt
            finally:
                results.close()
    finally:
        if bar is not None:
            bar.close()
    if not (out / "manifest.json").is_file():  # every mesh kept: the manifest is already there
        write_manifest(out, manifest)
    return run


def entry_line(object_id: str, entry: Mapping[str, Any], kept: bool = False) -> str:
    """One line about a mesh's manifest entry, for people."""
    source = Path(entry["source"]["file"]).name
    if entry["status"] != "ok":
        kept_earlier = entry.get("kept_earlier")
        earlier = f" (the earlier {kept_earlier} stays)" if kept_earlier else ""
        return f"FAIL {source}: {entry['error']}{earlier}"
    src = entry["source"]
    dev = entry["deviation_m"]
    state = "watertight" if src["watertight"] else "not watertight"
    pieces = f"{src['pieces']} piece{'s' if src['pieces'] != 1 else ''}"
    what = "kept from an earlier run" if kept else f"{entry['seconds']:.1f} s"
    warnings = "".join(f"\n     WARNING {w}" for w in entry.get("warnings", ()))
    up = f"{entry['up']['note']}; " if "up" in entry else ""
    return (
        f"ok   {source} -> {entry['files']['mesh']}: {up}{entry['units']['note']}; source "
        f"{src['faces']} faces, {pieces}, {state} -> one watertight body of {entry['faces']} "
        f"faces, {' x '.join(f'{v:.3f}' for v in entry['extents_m'])} m; deviation mean "
        f"{1000 * dev['to_source_mean']:.1f} mm, p95 {1000 * dev['to_source_p95']:.1f} mm "
        f"(source to repaired p95 {1000 * dev['from_source_p95']:.1f} mm); {what}{warnings}"
    )


def repair_summary(entries: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """Counts, and p10/p50/p90 over the ok meshes of faces, seconds and deviations (mm)."""
    ok = [e for e in entries.values() if e["status"] == "ok"]
    out: dict[str, Any] = {"meshes": len(entries), "ok": len(ok), "failed": len(entries) - len(ok)}
    if ok:

        def pct(values: Sequence[float]) -> list[float]:
            return [round(float(v), 3) for v in np.percentile(values, [10, 50, 90])]

        out["faces_p10_p50_p90"] = pct([e["faces"] for e in ok])
        out["seconds_p10_p50_p90"] = pct([e["seconds"] for e in ok])
        for key in ("to_source_mean", "to_source_p95", "from_source_p95"):
            out[f"{key}_mm_p10_p50_p90"] = pct([1000 * e["deviation_m"][key] for e in ok])
    return out
