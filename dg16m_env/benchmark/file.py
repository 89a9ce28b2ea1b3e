"""The benchmark file (HDF5): :func:`write_benchmark` (atomic and deterministic: equal data,
equal bytes) and :func:`read_benchmark` (validates the schema below), with the carried meshes and
convex hulls, optionally on a grid (:func:`grid_multiples`, :func:`~dg16m_env.benchmark.file_lazy.on_grid`).

File schema (``format = "dg16m-benchmark"``, ``schema_version = 2``)
----------------------------------------------------------------------
Root attributes: ``format``, ``schema_version``, ``metadata`` (JSON: parameters, with scene,
protocol and perturbation; phases, status names, sources, package version; ``mujoco``, the
MuJoCo version that simulated the trials, in files written since 2026-12-03; ``simulator``, only
for another engine than C MuJoCo; ``reseat``, only when
some object was re-seated: per such object :meth:`dg16m_env.physics.reseat.Reseat.summary`, i.e. the
limit, hands, hands penetrating before, hands not cleared, hands moved with the median and
largest shift).

``OUT/manifest.json`` records per object its pairs, trials, labels, invalid nominal trials with
their reasons (``invalid_reasons``: ``hand0_penetrates``, ``hand1_penetrates``,
``hands_overlap``) and, when re-seated, the same ``reseat`` summary.

``objects/`` (O rows): ``ids`` (str), ``families`` (str, "" for meshes), ``seeds`` (int64, -1 for
meshes), ``files`` (str: mesh file, relative to the build's mesh folder, "" for procedural),
``scales`` (float64), ``masses`` (float64, kg), ``parts`` (str: JSON list of
:meth:`~dataset_gen.objects.grasp_object.ConvexPart.to_dict`, object frame, m); optional (absent in files
written before them): ``centers_of_mass`` ((O, 3) float64, m, object frame: where the trial
applies the weight; absent = not known, ``None``), ``reseat_max`` ((O,) float64, m: the
re-seating limit the object was built with, 0 = off; absent = 0).

Mesh objects also carry (only when some object is a mesh): their meshes as read from their
files, ``mesh_counts`` ((O, 2) int64: vertices and faces per object, 0 for procedural ones),
``mesh_vertices`` ((sum V, 3) float64, m, the file's frame; or int32 multiples of
``10**-decimals`` m, ``decimals`` its attribute, when that holds every coordinate exactly, as
an OBJ file's fixed-point text does: read as ``multiples / 10**decimals`` in float64, with
``mesh_negative_zeros`` (int64 flat indices, present when any) set to -0.0),
``mesh_faces`` ((sum F, 3) int32, indices into the object's own vertices) and ``mesh_sha256`` ((O,) str,
:func:`dg16m_core.hashing.mesh_sha256` of the arrays; "" for procedural ones; a stored mesh
that does not hash to it is refused on reading; the carried mesh is the object, so no mesh folder
is read for it); and their convex hulls as arrays instead of JSON (``parts`` is then ``"[]"``):
``hull_objects`` ((O,) int32 hulls per object), ``hull_counts`` ((H,) int32 vertices per hull)
and ``hull_vertices`` ((sum, 3) float64, or float32 when every value is exactly a float32; m,
object frame; or int32 multiples of its attribute ``grid_m`` (m) when the benchmark was built
with ``hull_grid``, read as ``multiples * grid_m`` in float64, the vertices simulated).

``grasps/`` (N rows): ``object_index`` (int32 row of ``objects/``), ``poses`` (N, 2, 4, 4) float64
hand poses gripper -> object frame (m, dg16m grasp frame of the Panda hand),
``contact_points`` (N, 4, 3) float64 (m), ``contact_normals`` (N, 4, 3) float64 outward unit
normals (NaN when the source file has none), ``source`` (int8, index into :data:`SOURCES`),
``fc_passed`` (bool), ``fc_loss`` (float64, N: force-closure residual); optional:
``reseat_shift`` ((N, 2) float64, m: how far each hand was moved back along its approach axis
by re-seating, 0 = not moved; absent = zeros) and ``hand_line_distance`` ((N,) float64, m: the
distance from the object's centre of mass to the line through the two hands' grasp centres,
:func:`dg16m_env.physics.trial.grasp_centres`; the weak mode of two parallel-jaw grasps is rotation
about that line; absent = not known, ``None``).

``sim/`` (N rows, see :class:`dg16m_env.physics.trial.TrialResults`): ``status`` (int8
:class:`~dg16m_env.physics.trial.TrialStatus`), ``success`` (bool, the nominal trial held),
``failing_phase`` (int8 index into :data:`~dg16m_env.physics.trial.PHASES`, -1 none),
``invalid_reason`` (int8), ``max_displacement`` (float64, m), ``max_rotation_deg`` (float64),
``max_penetration`` (float64, m), ``contacts_after_close`` and ``contacts_final`` ((N, 2)
int16), ``ejected`` (bool): the nominal trial's full result.

``labels/`` (N rows, see :class:`dg16m_env.physics.labels.GraspLabels`; K = ``n_perturbations``):
``trial_status`` and ``trial_phase`` ((N, K + 1) int8: every trial's status and failing phase,
column 0 the nominal trial), ``seeds`` (int64 per-row perturbation seeds), ``p_success`` and
``p_gravity`` (float64: the success probabilities at the two levels; checked against
``trial_status`` / ``trial_phase`` on reading), ``label`` (bool, ``p_success >= 0.5``).

Version 1 files (one trial per pair, three pair sources) are refused with a message that says
so; rebuild them with ``dg16m benchmark build``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from dataset_gen.io import (
    hdf5_content_problem,
    write_array,
)
from dataset_gen.objects.grasp_object import (
    ConvexPart,
    part_from_dict,
)
from dg16m_core.atomic import atomic_path
from dg16m_core.errors import Dg16mError
from dg16m_core.hashing import mesh_sha256
from dg16m_env.benchmark.file_lazy import (
    MAX_DECIMALS,
    LazyBenchmarkObject,
    LazyReader,
    from_decimals,
    on_grid,
    read_checked,
)
from dg16m_env.benchmark.model import (
    FLOAT_SIM,
    FORMAT,
    SCHEMA_VERSION,
    SOURCES,
    Benchmark,
    BenchmarkError,
    BenchmarkObject,
    BenchmarkParameters,
)
from dg16m_env.physics.labels import GraspLabels, LabelError
from dg16m_env.physics.trial_protocol import PHASES, TrialResults, TrialStatus

# --------------------------------------------------------------------------------------------
# File I/O
# --------------------------------------------------------------------------------------------


def _strings(group: h5py.Group, name: str, values: Sequence[str]) -> None:
    group.create_dataset(
        name, data=list(values), dtype=h5py.string_dtype("utf-8"), track_times=False
    )


def write_benchmark(path: str | os.PathLike[str], bench: Benchmark, *, level: int = 4) -> None:
    """Write ``bench`` to ``path`` atomically and deterministically (equal data, equal bytes)."""
    metadata = json.dumps(bench.metadata, sort_keys=True, allow_nan=False)
    with atomic_path(path) as tmp, h5py.File(tmp, "w", track_order=False) as f:
        f.attrs.create("format", FORMAT, dtype=h5py.string_dtype("utf-8"))
        f.attrs.create("schema_version", np.int64(SCHEMA_VERSION))
        f.attrs.create("metadata", metadata, dtype=h5py.string_dtype("utf-8"))
        objects = f.create_group("objects", track_order=False)
        _strings(objects, "ids", [o.object_id for o in bench.objects])
        _strings(objects, "families", [o.family for o in bench.objects])
        _strings(objects, "files", [o.file for o in bench.objects])
        hulls = [_hull_parts(o) for o in bench.objects]
        _strings(
            objects,
            "parts",
            [
                "[]"
                if h is not None
                else json.dumps([p.to_dict() for p in o.parts], sort_keys=True)
                for o, h in zip(bench.objects, hulls, strict=True)
            ],
        )
        if any(h is not None for h in hulls):
            grid = bench.metadata.get("parameters", {}).get("hull_grid")
            _write_hulls(objects, hulls, level, grid)
        write_array(objects, "seeds", np.array([o.seed for o in bench.objects], np.int64), None)
        write_array(objects, "scales", np.array([o.scale for o in bench.objects]), None)
        write_array(objects, "masses", np.array([o.mass for o in bench.objects]), None)
        write_array(
            objects, "reseat_max", np.array([o.reseat_max for o in bench.objects], float), None
        )
        if any(o.has_mesh for o in bench.objects):
            _write_meshes(objects, bench.objects, level)
        if bench.objects and all(o.center_of_mass is not None for o in bench.objects):
            centers = np.array([o.center_of_mass for o in bench.objects], dtype=np.float64)
            write_array(objects, "centers_of_mass", centers, None)
        grasps = f.create_group("grasps", track_order=False)
        write_array(grasps, "object_index", bench.object_index.astype(np.int32), level)
        write_array(grasps, "poses", bench.poses.astype(np.float64), level)
        write_array(grasps, "contact_points", bench.contact_points.astype(np.float64), level)
        write_array(grasps, "contact_normals", bench.contact_normals.astype(np.float64), level)
        write_array(grasps, "source", bench.source.astype(np.int8), level)
        write_array(grasps, "fc_passed", bench.fc_passed.astype(bool), level)
        write_array(grasps, "fc_loss", bench.fc_loss.astype(np.float64), level)
        write_array(grasps, "reseat_shift", bench.reseat_shift.astype(np.float64), level)
        if bench.hand_line_distance is not None:
            distance = bench.hand_line_distance.astype(np.float64)
            write_array(grasps, "hand_line_distance", distance, level)
        sim = f.create_group("sim", track_order=False)
        for name in TrialResults.ARRAY_FIELDS:
            write_array(sim, name, np.asarray(getattr(bench.trials, name)), level)
        write_array(sim, "success", bench.trials.success, level)
        labels = f.create_group("labels", track_order=False)
        write_array(labels, "trial_status", bench.labels.status.astype(np.int8), level)
        write_array(labels, "trial_phase", bench.labels.failing_phase.astype(np.int8), level)
        write_array(labels, "seeds", bench.labels.seeds.astype(np.int64), level)
        write_array(labels, "p_success", bench.labels.p_success, level)
        write_array(labels, "p_gravity", bench.labels.p_gravity, level)
        write_array(labels, "label", bench.labels.label(), level)


def _hull_parts(obj: BenchmarkObject) -> list[np.ndarray] | None:
    """A mesh object's parts as hull vertex arrays when every part is a hull in the object
    frame (CoACD's), stored as arrays (``objects/hull_*``); else ``None`` (parts as JSON)."""
    if obj.family or not obj.parts:
        return None
    identity = np.eye(4)
    if not all(
        p.kind == "mesh" and p.vertices is not None and np.array_equal(p.pose, identity)
        for p in obj.parts
    ):
        return None
    return [np.asarray(p.vertices, dtype=np.float64) for p in obj.parts]


def _write_hulls(
    objects: h5py.Group,
    hulls: Sequence[list[np.ndarray] | None],
    level: int,
    grid: float | None = None,
) -> None:
    per_object = np.array([0 if h is None else len(h) for h in hulls], dtype=np.int32)
    arrays = [v for h in hulls if h is not None for v in h]
    write_array(objects, "hull_objects", per_object, None)
    write_array(objects, "hull_counts", np.array([len(v) for v in arrays], dtype=np.int32), level)
    vertices = np.concatenate(arrays).reshape(-1, 3)
    if grid is not None:
        multiples = grid_multiples(vertices, grid)
        fits = np.abs(multiples).max(initial=0) < 2**31
        if fits and same_bits(on_grid(multiples, grid), vertices):  # built on the grid
            write_array(objects, "hull_vertices", multiples.astype(np.int32), level)
            objects["hull_vertices"].attrs.create("grid_m", np.float64(grid))
            return
    single = vertices.astype(np.float32)
    if np.array_equal(single.astype(np.float64), vertices):  # exactly float32: half the bytes
        vertices = single
    write_array(objects, "hull_vertices", vertices, level)


def _read_hulls(f: h5py.File, path: Path, o: int) -> list[list[ConvexPart]]:
    """The parts stored as hull arrays (``objects/hull_*``), per object (empty when none)."""
    if "objects/hull_objects" not in f:
        return [[] for _ in range(o)]
    per_object = read_checked(f, path, "objects/hull_objects", (o,), "i")
    counts = read_checked(f, path, "objects/hull_counts", (int(per_object.sum()),), "i")
    vertices = read_checked(f, path, "objects/hull_vertices", (None, 3), "fi")
    if vertices.dtype.kind == "i":
        grid = f["objects/hull_vertices"].attrs.get("grid_m")
        if grid is None or not np.isfinite(grid) or not float(grid) > 0:
            raise BenchmarkError(
                f"{path}: objects/hull_vertices: expected integer multiples with a positive "
                f"'grid_m' attribute (m), found grid_m {grid!r}"
            )
        vertices = on_grid(vertices, float(grid))
    if per_object.min(initial=0) < 0 or counts.min(initial=4) < 4 or counts.sum() != len(vertices):
        raise BenchmarkError(
            f"{path}: objects/hull_counts: expected counts >= 4 summing to the "
            f"{len(vertices)} hull vertices stored, found sum {int(counts.sum())}"
        )
    out: list[list[ConvexPart]] = []
    starts = np.concatenate([[0], np.cumsum(counts)])
    k = 0
    identity = np.eye(4)
    for n in per_object.tolist():
        parts = []
        for _ in range(n):
            block = vertices[starts[k] : starts[k + 1]].astype(np.float64)
            try:
                parts.append(ConvexPart("mesh", identity, (), block))
            except Dg16mError as exc:
                raise BenchmarkError(f"{path}: objects/hull_vertices, hull {k}: {exc}") from None
            k += 1
        out.append(parts)
    return out


def _write_meshes(objects: h5py.Group, items: Sequence[BenchmarkObject], level: int) -> None:
    counts = np.array(
        [
            (len(o.mesh_vertices), len(o.mesh_faces))
            if o.mesh_vertices is not None and o.mesh_faces is not None
            else (0, 0)
            for o in items
        ],
        dtype=np.int64,
    ).reshape(-1, 2)
    vertices = [o.mesh_vertices for o in items if o.mesh_vertices is not None]
    faces = [o.mesh_faces for o in items if o.mesh_faces is not None]
    write_array(objects, "mesh_counts", counts, None)
    stacked = np.concatenate(vertices).astype(np.float64).reshape(-1, 3)
    decimals = _decimal_places(stacked)
    if decimals is None:
        write_array(objects, "mesh_vertices", stacked, level)
    else:
        multiples = np.round(stacked * 10.0**decimals).astype(np.int32)
        write_array(objects, "mesh_vertices", multiples, level)
        objects["mesh_vertices"].attrs.create("decimals", np.int64(decimals))
        negative_zeros = np.flatnonzero(np.signbit(stacked) & (stacked == 0))
        if negative_zeros.size:  # an OBJ file's "-0.00000000": kept, for the hash
            write_array(objects, "mesh_negative_zeros", negative_zeros.astype(np.int64), level)
    write_array(objects, "mesh_faces", np.concatenate(faces).astype(np.int32).reshape(-1, 3), level)
    _strings(objects, "mesh_sha256", [o.mesh_sha256 for o in items])


def _decimal_places(vertices: np.ndarray) -> int | None:
    """The fewest decimal places (<= :data:`MAX_DECIMALS`) that hold every coordinate exactly
    as an int32 multiple (a mesh read from an OBJ file's fixed-point text: 8 for trimesh's),
    or None (stored as float64)."""
    for decimals in range(MAX_DECIMALS + 1):
        scaled = np.round(vertices * 10.0**decimals)
        if np.abs(scaled).max(initial=0) >= 2**31:
            return None
        if same_bits(from_decimals(scaled.astype(np.int64), decimals), vertices + 0.0):
            return decimals  # (-0.0 + 0.0 is 0.0: negative zeros are stored apart)
    return None


def _read_meshes(
    f: h5py.File, path: Path, o: int
) -> list[tuple[np.ndarray, np.ndarray, str] | None]:
    """The carried meshes (``objects/mesh_*``), checked against their hashes; ``None`` for an
    object without one (procedural) or when the file carries none."""
    if "objects/mesh_counts" not in f:
        return [None] * o
    counts = read_checked(f, path, "objects/mesh_counts", (o, 2), "i")
    vertices = read_checked(f, path, "objects/mesh_vertices", (None, 3), "fi")
    if vertices.dtype.kind == "i":
        decimals = f["objects/mesh_vertices"].attrs.get("decimals")
        if decimals is None or not 0 <= int(decimals) <= MAX_DECIMALS:
            raise BenchmarkError(
                f"{path}: objects/mesh_vertices: expected integer multiples with a 'decimals' "
                f"attribute in [0, {MAX_DECIMALS}], found decimals {decimals!r}"
            )
        vertices = from_decimals(vertices, int(decimals))
        if "objects/mesh_negative_zeros" in f:
            zeros = read_checked(f, path, "objects/mesh_negative_zeros", (None,), "i")
            if zeros.size and (zeros.min() < 0 or zeros.max() >= vertices.size):
                raise BenchmarkError(
                    f"{path}: objects/mesh_negative_zeros: expected flat indices in "
                    f"[0, {vertices.size}), found [{zeros.min()}, {zeros.max()}]"
                )
            vertices.reshape(-1)[zeros] = -0.0
    faces = read_checked(f, path, "objects/mesh_faces", (None, 3), "i")
    hashes = [s.decode() for s in read_checked(f, path, "objects/mesh_sha256", (o,), "OS")]
    if (
        counts.min(initial=0) < 0
        or counts[:, 0].sum() != len(vertices)
        or counts[:, 1].sum() != len(faces)
    ):
        raise BenchmarkError(
            f"{path}: objects/mesh_counts: expected counts summing to the {len(vertices)} "
            f"vertices and {len(faces)} faces stored, found sums {counts.sum(axis=0).tolist()}"
        )
    out: list[tuple[np.ndarray, np.ndarray, str] | None] = []
    v0 = f0 = 0
    for i, (nv, nf) in enumerate(counts.tolist()):
        if nv == 0:
            out.append(None)
            continue
        v, fc = vertices[v0 : v0 + nv].astype(np.float64), faces[f0 : f0 + nf].astype(np.int64)
        v0, f0 = v0 + nv, f0 + nf
        if fc.size and (fc.min() < 0 or fc.max() >= nv):
            raise BenchmarkError(
                f"{path}: objects/mesh_faces of object {i}: expected indices in [0, {nv}), "
                f"found [{fc.min()}, {fc.max()}]"
            )
        if mesh_sha256(v, fc) != hashes[i]:
            raise BenchmarkError(
                f"{path}: objects/mesh_sha256 of object {i}: expected the stored mesh to hash to "
                f"{hashes[i]}, found {mesh_sha256(v, fc)} (the mesh bytes were changed)"
            )
        out.append((v, fc, hashes[i]))
    return out


def read_benchmark(path: str | os.PathLike[str], *, lazy: bool = False) -> Benchmark:
    """Read a benchmark file (validating the schema in the module docstring).

    ``lazy=True`` reads the index only (ids, rows, labels, sizes of the stored parts and
    meshes): each object's parts and carried mesh are read from the file when first used
    (:class:`LazyBenchmarkObject`; same values as an eager read, checked then: a broken part
    or a mesh that does not hash to its ``mesh_sha256`` raises :class:`BenchmarkError` at that
    use, as does a file changed since it was read). An environment reads the 300-object real
    benchmark this way in a fraction of a second.

    Raises:
        BenchmarkError: not a benchmark file, wrong version, missing or mis-shaped datasets,
            indices out of range, non-finite poses.
    """
    path = Path(path)
    with _open_benchmark(path) as f:
        metadata = _read_header(f, path)
        columns = _read_object_columns(f, path)
        o = len(columns.ids)
        if lazy:
            reader: LazyReader | None = LazyReader(f, path, columns.parts_json)
            meshes: list[tuple[np.ndarray, np.ndarray, str] | None] = [None] * o
            hulls: list[list[ConvexPart]] = [[] for _ in range(o)]
        else:
            reader = None
            meshes = _read_meshes(f, path, o)
            hulls = _read_hulls(f, path, o)
        index, arrays = _read_grasp_arrays(f, path)
        n = index.size
        sim = {}
        for name in TrialResults.ARRAY_FIELDS:
            shape: tuple[int | None, ...] = (n, 2) if name.startswith("contacts") else (n,)
            kinds = "f" if name in FLOAT_SIM else ("b" if name == "ejected" else "i")
            sim[name] = read_checked(f, path, f"sim/{name}", shape, kinds)
        try:
            parameters = BenchmarkParameters.from_dict(metadata.get("parameters", {}))
        except Dg16mError as exc:
            raise BenchmarkError(f"{path}: metadata: {exc}") from None
        trials = parameters.perturbation.trials
        label_arrays = {
            "status": read_checked(f, path, "labels/trial_status", (n, trials), "i"),
            "failing_phase": read_checked(f, path, "labels/trial_phase", (n, trials), "i"),
            "seeds": read_checked(f, path, "labels/seeds", (n,), "i"),
        }
        stored_p = {
            "p_success": read_checked(f, path, "labels/p_success", (n,), "f"),
            "p_gravity": read_checked(f, path, "labels/p_gravity", (n,), "f"),
        }
        stored_label = read_checked(f, path, "labels/label", (n,), "b")
    _check_values(path, columns, index, arrays, label_arrays)
    objects = _benchmark_objects(path, columns, reader, meshes, hulls)
    try:
        labels = GraspLabels(
            nominal=TrialResults(**sim, protocol=parameters.protocol),
            spec=parameters.perturbation,
            status=label_arrays["status"].astype(np.int8),
            failing_phase=label_arrays["failing_phase"].astype(np.int8),
            seeds=label_arrays["seeds"].astype(np.int64),
        )
    except LabelError as exc:
        raise BenchmarkError(f"{path}: labels: {exc}") from None
    _check_stored_labels(path, labels, stored_p, stored_label)
    return Benchmark(
        objects=objects,
        object_index=index.astype(np.int32),
        labels=labels,
        metadata=metadata,
        **arrays,
    )


def _open_benchmark(path: Path) -> h5py.File:
    """``path`` opened for reading, once it is known to be an HDF5 file."""
    if not path.is_file():  # then the words the other commands use (hdf5_content_problem)
        found = "a directory" if path.is_dir() else "nothing at this path"
        raise BenchmarkError(f"{path}: expected a dg16m benchmark HDF5 file, found {found}")
    try:
        problem = hdf5_content_problem(path)
    except OSError as exc:
        problem = f"an unreadable file ({exc.strerror or exc})"
    if problem is not None:
        raise BenchmarkError(f"{path}: expected an HDF5 file, found {problem}")
    try:
        return h5py.File(path, "r")
    except (OSError, FileNotFoundError) as exc:
        raise BenchmarkError(
            f"{path}: expected a dg16m benchmark HDF5 file, found: {exc}"
        ) from None


def _read_header(f: h5py.File, path: Path) -> dict[str, Any]:
    """The root attributes checked (format, schema version): the metadata."""
    fmt = f.attrs.get("format")
    fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
    if fmt != FORMAT:
        raise BenchmarkError(f"{path}: expected format {FORMAT!r}, found {fmt!r}")
    version = int(f.attrs.get("schema_version", -1))
    if version == 1:
        raise BenchmarkError(
            f"{path}: expected schema_version {SCHEMA_VERSION}, found 1: a version 1 "
            "benchmark labels each pair with one trial at the exact pose (written before "
            "benchmark protocol v2); "
            "version 2 labels are success probabilities over perturbed trials. Rebuild it "
            "with `dg16m benchmark build` (the shipped benchmark is version 2)"
        )
    if version != SCHEMA_VERSION:
        raise BenchmarkError(f"{path}: expected schema_version {SCHEMA_VERSION}, found {version}")
    try:
        return json.loads(f.attrs["metadata"])
    except (KeyError, ValueError) as exc:
        raise BenchmarkError(f"{path}: expected JSON metadata, found: {exc}") from None


@dataclass(frozen=True)
class _ObjectColumns:
    """The per-object datasets of ``objects/`` (O rows), as read."""

    ids: list[str]
    families: list[str]
    files: list[str]
    parts_json: list[str]
    seeds: np.ndarray
    scales: np.ndarray
    masses: np.ndarray
    reseat_max: np.ndarray
    centers: np.ndarray | None


def _read_object_columns(f: h5py.File, path: Path) -> _ObjectColumns:
    ids = [s.decode() for s in read_checked(f, path, "objects/ids", (None,), "OS")]
    o = len(ids)
    return _ObjectColumns(
        ids=ids,
        families=[s.decode() for s in read_checked(f, path, "objects/families", (o,), "OS")],
        files=[s.decode() for s in read_checked(f, path, "objects/files", (o,), "OS")],
        parts_json=[s.decode() for s in read_checked(f, path, "objects/parts", (o,), "OS")],
        seeds=read_checked(f, path, "objects/seeds", (o,), "i"),
        scales=read_checked(f, path, "objects/scales", (o,), "f"),
        masses=read_checked(f, path, "objects/masses", (o,), "f"),
        reseat_max=(
            read_checked(f, path, "objects/reseat_max", (o,), "f")
            if "objects/reseat_max" in f
            else np.zeros(o)
        ),
        centers=(
            read_checked(f, path, "objects/centers_of_mass", (o, 3), "f")
            if "objects/centers_of_mass" in f
            else None
        ),
    )


def _read_grasp_arrays(f: h5py.File, path: Path) -> tuple[np.ndarray, dict[str, Any]]:
    """``grasps/object_index`` and the other ``grasps/`` datasets (by :class:`Benchmark`
    field)."""
    index = read_checked(f, path, "grasps/object_index", (None,), "i")
    n = index.size
    arrays = {
        "poses": read_checked(f, path, "grasps/poses", (n, 2, 4, 4), "f"),
        "contact_points": read_checked(f, path, "grasps/contact_points", (n, 4, 3), "f"),
        "contact_normals": read_checked(f, path, "grasps/contact_normals", (n, 4, 3), "f"),
        "source": read_checked(f, path, "grasps/source", (n,), "i"),
        "fc_passed": read_checked(f, path, "grasps/fc_passed", (n,), "b"),
        "fc_loss": read_checked(f, path, "grasps/fc_loss", (n,), "f"),
        "reseat_shift": (
            read_checked(f, path, "grasps/reseat_shift", (n, 2), "f")
            if "grasps/reseat_shift" in f
            else np.zeros((n, 2))
        ),
        "hand_line_distance": (
            read_checked(f, path, "grasps/hand_line_distance", (n,), "f")
            if "grasps/hand_line_distance" in f
            else None
        ),
    }
    return index, arrays


def _check_values(
    path: Path,
    columns: _ObjectColumns,
    index: np.ndarray,
    arrays: dict[str, Any],
    label_arrays: dict[str, np.ndarray],
) -> None:
    """The values' ranges: trial codes and phases, object rows, finite poses, the optional
    distances, pair sources."""
    n, o = index.size, len(columns.ids)
    codes = label_arrays["status"]
    if n and not np.isin(codes, [s.value for s in TrialStatus]).all():
        raise BenchmarkError(
            f"{path}: labels/trial_status: expected TrialStatus codes 0-{len(TrialStatus) - 1}, "
            f"found {int(codes[~np.isin(codes, [s.value for s in TrialStatus])][0])}"
        )
    phases = label_arrays["failing_phase"]
    if n and (phases.min() < -1 or phases.max() >= len(PHASES)):
        raise BenchmarkError(
            f"{path}: labels/trial_phase: expected values in [-1, {len(PHASES)}), found "
            f"[{phases.min()}, {phases.max()}]"
        )
    if n and (index.min() < 0 or index.max() >= o):
        raise BenchmarkError(
            f"{path}: grasps/object_index: expected values in [0, {o}), found "
            f"[{index.min()}, {index.max()}]"
        )
    if not np.isfinite(arrays["poses"]).all():
        raise BenchmarkError(f"{path}: grasps/poses: expected finite poses, found NaN/inf")
    optional = {
        "grasps/reseat_shift": arrays["reseat_shift"],
        "grasps/hand_line_distance": arrays["hand_line_distance"],
        "objects/reseat_max": columns.reseat_max,
        "objects/centers_of_mass": columns.centers,
    }
    for key, values in optional.items():
        if values is None or not values.size:
            continue
        if not np.isfinite(values).all():
            raise BenchmarkError(f"{path}: {key}: expected finite values, found NaN/inf")
        if key != "objects/centers_of_mass" and values.min() < 0:
            raise BenchmarkError(
                f"{path}: {key}: expected values >= 0 m, found {float(values.min())!r}"
            )
    if n and (arrays["source"].min() < 0 or arrays["source"].max() >= len(SOURCES)):
        raise BenchmarkError(f"{path}: grasps/source: expected values in [0, {len(SOURCES)})")


def _benchmark_objects(
    path: Path,
    columns: _ObjectColumns,
    reader: LazyReader | None,
    meshes: list[tuple[np.ndarray, np.ndarray, str] | None],
    hulls: list[list[ConvexPart]],
) -> list[BenchmarkObject]:
    """The objects of the columns: lazy ones (read on use through ``reader``) or with their
    parts, hulls and carried meshes."""
    c = columns
    objects: list[BenchmarkObject] = []
    for i in range(len(c.ids)):
        center = None if c.centers is None else c.centers[i].astype(np.float64)
        if reader is not None:
            objects.append(
                LazyBenchmarkObject(
                    reader,
                    i,
                    object_id=c.ids[i],
                    family=c.families[i],
                    seed=int(c.seeds[i]),
                    file=c.files[i],
                    scale=float(c.scales[i]),
                    mass=float(c.masses[i]),
                    center_of_mass=center,
                    reseat_max=float(c.reseat_max[i]),
                )
            )
            continue
        try:
            parts = tuple(part_from_dict(p) for p in json.loads(c.parts_json[i]))
        except (ValueError, TypeError, Dg16mError) as exc:
            raise BenchmarkError(f"{path}: objects/parts[{i}] ({c.ids[i]}): {exc}") from None
        parts = (*parts, *hulls[i])
        mesh = meshes[i]
        objects.append(
            BenchmarkObject(
                c.ids[i],
                c.families[i],
                int(c.seeds[i]),
                c.files[i],
                float(c.scales[i]),
                float(c.masses[i]),
                parts,
                center_of_mass=center,
                reseat_max=float(c.reseat_max[i]),
                **(
                    {}
                    if mesh is None
                    else dict(
                        zip(("mesh_vertices", "mesh_faces", "mesh_sha256"), mesh, strict=True)
                    )
                ),
            )
        )
    return objects


def _check_stored_labels(
    path: Path,
    labels: GraspLabels,
    stored_p: dict[str, np.ndarray],
    stored_label: np.ndarray,
) -> None:
    """The stored success probabilities and labels are those the trials give."""
    for name, stored in stored_p.items():
        derived = getattr(labels, name)
        if not np.array_equal(stored, derived):
            row = int(np.argmax(stored != derived))
            raise BenchmarkError(
                f"{path}: labels/{name}: expected the fraction of held trials in "
                f"labels/trial_status, found {stored[row]!r} against {derived[row]!r} in row {row}"
            )
    if not np.array_equal(stored_label, labels.label()):
        row = int(np.argmax(stored_label != labels.label()))
        raise BenchmarkError(
            f"{path}: labels/label: expected p_success >= 0.5, found {bool(stored_label[row])} "
            f"with p_success {labels.p_success[row]!r} in row {row}"
        )


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two float64 arrays hold the same bytes (so -0.0 differs from 0.0, as in a
    hash)."""
    a, b = np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def grid_multiples(vertices: np.ndarray, grid: float) -> np.ndarray:
    """(V, 3) vertices (m) -> (V, 3) int64 nearest multiples of ``grid`` (m)."""
    return np.round(np.asarray(vertices, dtype=np.float64) / grid).astype(np.int64)
