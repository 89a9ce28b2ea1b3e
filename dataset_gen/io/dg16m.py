"""DG16M release grasp files: one object's dual grasps (:class:`DualGraspSet`), read and written.

Grasp frame (dg16m and the DG16M release)
-----------------------------------------
A grasp is a (4, 4) rigid transform from the gripper frame to the object frame (metres). Gripper
frame: origin at the Panda hand's base (flange), x = closing axis (finger to finger),
y = approach axis (towards the object), z = x × y. Measured on the real release file: each arm's
two contact points lie on its x axis, their midpoint at y = +0.0675 m.

DG16M release schema (one ``<object_id>.h5`` per object)
---------------------------------------------------------
N dual grasps (pairs); arm 0 is ``grasps[:, 0]``, arm 1 is ``grasps[:, 1]``.

==============================  ===============  =======  ==========================================
key                             shape            dtype    meaning
==============================  ===============  =======  ==========================================
``grasps/grasps``               (N, 2, 4, 4)     float64  both arms' grasp poses, object frame (m)
``grasps/contact_points``       (N, 4, 3)        float64  contacts, object frame (m); rows 0, 1 are
                                                          arm 0's fingers, rows 2, 3 arm 1's
``grasps/contact_forces``       (N, 4, 3)        float64  optimal contact forces, object frame (N)
``grasps/loss_values``          (N,)             float64  force-closure loss L >= 0 (N, a norm)
``grasps/fc_passing_indices``   (P,)             int64    pairs that pass force closure
``grasps/fc_failed_indices``    (Q,)             int64    pairs that fail (disjoint from passing)
``object/file``                 ()               str      mesh file name (variable-length UTF-8)
``object/scale``                ()               number   mesh scale (release: int64 1; we: float64)
==============================  ===============  =======  ==========================================

dg16m extensions (only in the top-level group ``dg16m/``, so release readers still work)
-----------------------------------------------------------------------------------------
==================================  =====================================================
item                                meaning
==================================  =====================================================
``dg16m/<name>`` datasets           extra named numeric arrays (bool/int/uint/float), e.g.
                                    ``dg16m/quality (N,)``, ``dg16m/single_grasps (M, 4, 4)``
``dg16m.attrs["schema_version"]``   int, currently 1 (see ``SUPPORTED_SCHEMA_VERSIONS``)
``dg16m.attrs["metadata"]``         one JSON string (an object): parameters, seed, package
                                    version, gripper name, per-stage counts, ...
==================================  =====================================================

Files are written deterministically: the same :class:`DualGraspSet` gives the same bytes (no
object timestamps, no creation-order tracking, extras in sorted order, explicit chunk shapes).
By default arrays are gzip-compressed (level 4, byte shuffle, Fletcher-32 checksums) in chunks of
whole rows (about 512 KiB): 0.37 of the uncompressed size on the real release file.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from dg16m_core.atomic import atomic_path
from dg16m_core.errors import GraspFileError

from ._checks import (
    _NUMERIC_KINDS,
    PathLike,
    _arrays_equal,
    _as_array,
    _assign,
    _check_finite,
    _check_kind,
    _check_object_file,
    _check_positive,
    _check_rigid,
    _check_shape,
    _ConstantError,
    _frozen,
    _reject_constant,
)
from ._hdf5 import (
    _check_dataset,
    _check_present,
    _read_numeric,
    _read_scalar,
    _read_string,
    open_hdf5,
    write_array,
)
from .versions import SCHEMA_VERSION, SUPPORTED_SCHEMA_VERSIONS

LOSS_ATOL = 1e-9
"""A force-closure loss is a norm; values down to ``-LOSS_ATOL`` are accepted as solver rounding."""

DEFAULT_GZIP_LEVEL = 4
"""gzip level of :func:`write_dg16m`. Levels 6 and 9 gain < 1% on real data for 1.4-2x the time."""

EXTRAS_GROUP = "dg16m"
"""Top-level group holding dg16m's extensions to the release schema."""

RELEASE_KEYS = (
    "grasps/grasps",
    "grasps/contact_points",
    "grasps/contact_forces",
    "grasps/loss_values",
    "grasps/fc_passing_indices",
    "grasps/fc_failed_indices",
    "object/file",
    "object/scale",
)
"""Datasets every DG16M release file has (and the only ones it has)."""


def _check_release_shapes(shapes: Mapping[str, tuple[int, ...]]) -> int:
    """Check the release arrays' shapes against each other; return N."""
    g = tuple(shapes["grasps/grasps"])
    if len(g) != 4 or g[1:] != (2, 4, 4):
        raise GraspFileError(f"grasps/grasps: expected (N, 2, 4, 4), found {g}")
    n = g[0]
    why = " to match grasps/grasps"
    _check_shape("grasps/contact_points", shapes["grasps/contact_points"], (n, 4, 3), why)
    _check_shape("grasps/contact_forces", shapes["grasps/contact_forces"], (n, 4, 3), why)
    _check_shape("grasps/loss_values", shapes["grasps/loss_values"], (n,), why)
    for key in ("grasps/fc_passing_indices", "grasps/fc_failed_indices"):
        if len(shapes[key]) != 1:
            raise GraspFileError(f"{key}: expected a 1-D array (P,), found {tuple(shapes[key])}")
    return n


def _check_indices(key: str, value: Any, n: int) -> np.ndarray:
    """Validate 1-D unique integer indices in [0, n); return them as read-only int64."""
    arr = np.asarray(value)
    if arr.size == 0 and arr.dtype.kind in "iuf":
        arr = arr.astype(np.int64)
    _check_kind(key, arr.dtype, "iu", "integer")
    if arr.ndim != 1:
        raise GraspFileError(f"{key}: expected a 1-D array of indices, found shape {arr.shape}")
    if arr.size:
        low, high = int(arr.min()), int(arr.max())
        if low < 0 or high >= n:
            bad = int(arr[(arr < 0) | (arr >= n)][0])
            raise GraspFileError(
                f"{key}: expected indices in [0, {n}) (N = {n} pairs), found values in "
                f"[{low}, {high}] (first bad: {bad})"
            )
    out = _frozen(arr, np.int64)
    uniq, counts = np.unique(out, return_counts=True)
    if len(uniq) != len(out):
        dup = uniq[counts > 1]
        raise GraspFileError(
            f"{key}: expected unique indices, found {len(dup)} repeated (first: {int(dup[0])})"
        )
    return out


def _json_default(value: Any) -> Any:
    """``json.dumps`` hook: numpy scalars and arrays become Python numbers and lists."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _metadata_json(metadata: Mapping[str, Any]) -> str:
    """Canonical compact JSON of a metadata mapping (sorted keys, no NaN)."""
    try:
        return json.dumps(
            metadata,
            sort_keys=True,
            separators=(",", ":"),
            allow_nan=False,
            ensure_ascii=False,
            default=_json_default,
        )
    except (TypeError, ValueError) as exc:
        raise GraspFileError(
            f"{EXTRAS_GROUP}.attrs['metadata']: expected a JSON-serialisable mapping with string "
            f"keys and finite numbers, found an unserialisable value ({exc})"
        ) from exc


def _check_extra_name(name: Any) -> str:
    if (
        not isinstance(name, str)
        or not name
        or name in (".", "..")
        or "/" in name
        or "\x00" in name
    ):
        raise GraspFileError(
            f"{EXTRAS_GROUP}/: expected extra names that are non-empty strings without '/' or NUL "
            f"(and not '.' or '..'), found {name!r}"
        )
    return name


@dataclass(frozen=True, eq=False, repr=False)
class DualGraspSet:
    """One object's dual grasps in the DG16M release schema, plus dg16m extras.

    All arrays are stored as read-only C-contiguous copies (float64 / int64). Construction
    validates everything and raises :class:`GraspFileError` naming the release key at fault.

    Attributes:
        grasps: (N, 2, 4, 4) float64 grasp poses of arm 0 and arm 1, gripper to object frame (m).
        contact_points: (N, 4, 3) float64 contacts in the object frame (m); rows 0, 1 belong to
            arm 0, rows 2, 3 to arm 1.
        contact_forces: (N, 4, 3) float64 contact forces in the object frame (N).
        loss_values: (N,) float64 force-closure loss (N; a residual norm, >= 0).
        passing_indices: (P,) int64 unique pair indices in [0, N) that pass force closure.
        failed_indices: (Q,) int64 unique pair indices in [0, N) that fail; disjoint from passing.
        object_file: mesh file name (non-empty string).
        object_scale: mesh scale factor (positive).
        extras: named numeric (bool/int/uint/float) arrays of any shape, stored under ``dg16m/``.
        metadata: JSON-serialisable mapping (normalised through JSON: tuples become lists, numpy
            scalars Python numbers), stored as ``dg16m.attrs["metadata"]``.
    """

    grasps: np.ndarray
    contact_points: np.ndarray
    contact_forces: np.ndarray
    loss_values: np.ndarray
    passing_indices: np.ndarray
    failed_indices: np.ndarray
    object_file: str
    object_scale: float
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        arrays = {
            "grasps/grasps": _as_array(self.grasps, "grasps/grasps", "f", "float"),
            "grasps/contact_points": _as_array(
                self.contact_points, "grasps/contact_points", "f", "float"
            ),
            "grasps/contact_forces": _as_array(
                self.contact_forces, "grasps/contact_forces", "f", "float"
            ),
            "grasps/loss_values": _as_array(self.loss_values, "grasps/loss_values", "f", "float"),
        }
        shapes = {key: arr.shape for key, arr in arrays.items()}
        shapes["grasps/fc_passing_indices"] = np.shape(self.passing_indices)
        shapes["grasps/fc_failed_indices"] = np.shape(self.failed_indices)
        n = _check_release_shapes(shapes)
        for key, arr in arrays.items():
            _check_finite(key, arr)
        frozen = {key: _frozen(arr, np.float64) for key, arr in arrays.items()}
        _check_rigid("grasps/grasps", frozen["grasps/grasps"], "pair")
        loss = frozen["grasps/loss_values"]
        if loss.size and loss.min() < -LOSS_ATOL:
            neg = np.flatnonzero(loss < -LOSS_ATOL)
            raise GraspFileError(
                f"grasps/loss_values: expected values >= 0 (a residual norm), found {len(neg)} "
                f"negative (first: pair {int(neg[0])} = {loss[neg[0]]:g})"
            )
        passing = _check_indices("grasps/fc_passing_indices", self.passing_indices, n)
        failed = _check_indices("grasps/fc_failed_indices", self.failed_indices, n)
        shared = np.intersect1d(passing, failed)
        if shared.size:
            raise GraspFileError(
                "grasps/fc_passing_indices and grasps/fc_failed_indices: expected disjoint sets, "
                f"found {shared.size} pair(s) in both (first: {int(shared[0])})"
            )
        object_file = _check_object_file("object/file", self.object_file)
        object_scale = _check_positive("object/scale", self.object_scale)

        if not isinstance(self.extras, Mapping):
            raise GraspFileError(
                f"{EXTRAS_GROUP}/: expected a mapping of name -> array, "
                f"found {type(self.extras).__name__}"
            )
        extras: dict[str, np.ndarray] = {}
        for name, value in self.extras.items():
            key = f"{EXTRAS_GROUP}/{_check_extra_name(name)}"
            arr = _as_array(value, key, _NUMERIC_KINDS, "numeric (bool/int/uint/float)")
            extras[name] = _frozen(arr, arr.dtype.newbyteorder("="))
        if not isinstance(self.metadata, Mapping):
            raise GraspFileError(
                f"{EXTRAS_GROUP}.attrs['metadata']: expected a mapping, "
                f"found {type(self.metadata).__name__}"
            )
        metadata = json.loads(_metadata_json(self.metadata))

        _assign(
            self,
            grasps=frozen["grasps/grasps"],
            contact_points=frozen["grasps/contact_points"],
            contact_forces=frozen["grasps/contact_forces"],
            loss_values=loss,
            passing_indices=passing,
            failed_indices=failed,
            object_file=object_file,
            object_scale=object_scale,
            extras=dict(sorted(extras.items())),
            metadata=metadata,
        )

    @property
    def n(self) -> int:
        """Number of dual grasps (pairs) N."""
        return int(self.grasps.shape[0])

    @property
    def passed(self) -> np.ndarray:
        """(N,) bool, True for the pairs listed in ``passing_indices``."""
        mask = np.zeros(self.n, dtype=bool)
        mask[self.passing_indices] = True
        return mask

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, DualGraspSet):
            return NotImplemented
        names = (
            "grasps",
            "contact_points",
            "contact_forces",
            "loss_values",
            "passing_indices",
            "failed_indices",
        )
        return (
            all(_arrays_equal(getattr(self, k), getattr(other, k)) for k in names)
            and self.object_file == other.object_file
            and self.object_scale == other.object_scale
            and self.extras.keys() == other.extras.keys()
            and all(_arrays_equal(v, other.extras[k]) for k, v in self.extras.items())
            and self.metadata == other.metadata
        )

    __hash__ = None  # type: ignore[assignment]  # mutable-looking contents: not hashable

    def __repr__(self) -> str:
        return (
            f"DualGraspSet(n={self.n}, passing={len(self.passing_indices)}, "
            f"failed={len(self.failed_indices)}, object_file={self.object_file!r}, "
            f"object_scale={self.object_scale!r}, extras={sorted(self.extras)}, "
            f"metadata_keys={sorted(self.metadata)})"
        )


def _read_extras(path: Path, f: h5py.File) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read the ``dg16m/`` group: (extras, metadata); both empty for a plain release file."""
    if EXTRAS_GROUP not in f:
        return {}, {}
    group = f[EXTRAS_GROUP]
    if not isinstance(group, h5py.Group):
        raise GraspFileError(f"{path}: {EXTRAS_GROUP}: expected a group, found a dataset")
    version = group.attrs.get("schema_version")
    if isinstance(version, np.generic):
        version = version.item()
    if (
        version is None
        or isinstance(version, bool)
        or not isinstance(version, int)
        or int(version) not in SUPPORTED_SCHEMA_VERSIONS
    ):
        raise GraspFileError(
            f"{path}: {EXTRAS_GROUP}.attrs['schema_version']: expected one of "
            f"{list(SUPPORTED_SCHEMA_VERSIONS)}, found {version!r}"
        )
    raw = group.attrs.get("metadata", "{}")
    if isinstance(raw, bytes):
        try:
            raw = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise GraspFileError(
                f"{path}: {EXTRAS_GROUP}.attrs['metadata']: expected UTF-8 JSON, found {exc}"
            ) from exc
    if not isinstance(raw, str):
        raise GraspFileError(
            f"{path}: {EXTRAS_GROUP}.attrs['metadata']: expected a JSON string, "
            f"found {type(raw).__name__}"
        )
    try:
        metadata = json.loads(raw, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise GraspFileError(
            f"{path}: {EXTRAS_GROUP}.attrs['metadata']: expected JSON, found malformed JSON at "
            f"line {exc.lineno}, column {exc.colno}: {exc.msg}"
        ) from exc
    except _ConstantError as exc:
        raise GraspFileError(f"{path}: {EXTRAS_GROUP}.attrs['metadata']: {exc}") from exc
    if not isinstance(metadata, dict):
        raise GraspFileError(
            f"{path}: {EXTRAS_GROUP}.attrs['metadata']: expected a JSON object, "
            f"found {type(metadata).__name__}"
        )
    extras: dict[str, np.ndarray] = {}
    for name in group:
        item = _check_dataset(path, f, f"{EXTRAS_GROUP}/{name}")
        extras[name] = _read_numeric(path, item, _NUMERIC_KINDS, "numeric (bool/int/uint/float)")
    return extras, metadata


def read_dg16m(path: PathLike) -> DualGraspSet:
    """Read one object's DG16M release file (``<id>.h5``), with dg16m extras when present.

    Works on files of the original release (``object/scale`` int64, no ``dg16m/`` group) and on
    files from :func:`write_dg16m`. Keys outside the schema are ignored.

    Raises:
        GraspFileError: the path is not an HDF5 file, required keys are missing, a dtype or shape
            is wrong, values are not finite, transforms are not rigid, indices are out of range,
            repeated or overlapping, or the ``dg16m/`` group is malformed.
    """
    path = Path(path)
    with open_hdf5(path) as f:
        _check_present(path, f, RELEASE_KEYS, "DG16M release")
        float_keys = RELEASE_KEYS[:4]
        index_keys = RELEASE_KEYS[4:6]
        for key in float_keys:
            try:
                _check_kind(key, f[key].dtype, "f", "float")
            except GraspFileError as exc:
                raise GraspFileError(f"{path}: {exc}") from None
        for key in index_keys:
            if f[key].size:
                try:
                    _check_kind(key, f[key].dtype, "iu", "integer")
                except GraspFileError as exc:
                    raise GraspFileError(f"{path}: {exc}") from None
        try:
            _check_release_shapes({key: f[key].shape for key in RELEASE_KEYS[:6]})
        except GraspFileError as exc:
            raise GraspFileError(f"{path}: {exc}") from None
        arrays = {key: _read_numeric(path, f[key], "iuf", "numeric") for key in RELEASE_KEYS[:6]}
        object_file = _read_string(path, f["object/file"])
        object_scale = _read_scalar(path, f["object/scale"])
        extras, metadata = _read_extras(path, f)
    try:
        return DualGraspSet(
            grasps=arrays["grasps/grasps"],
            contact_points=arrays["grasps/contact_points"],
            contact_forces=arrays["grasps/contact_forces"],
            loss_values=arrays["grasps/loss_values"],
            passing_indices=arrays["grasps/fc_passing_indices"],
            failed_indices=arrays["grasps/fc_failed_indices"],
            object_file=object_file,
            object_scale=object_scale,
            extras=extras,
            metadata=metadata,
        )
    except GraspFileError as exc:
        raise GraspFileError(f"{path}: {exc}") from None


def write_dg16m(
    path: PathLike, data: DualGraspSet, *, compression_level: int | None = DEFAULT_GZIP_LEVEL
) -> None:
    """Write ``data`` to ``path`` in the DG16M release schema plus the ``dg16m/`` group.

    Atomic (a temporary file is moved into place) and deterministic: equal data gives equal
    bytes. Release keys are float64/int64 as in the release; ``object/scale`` is float64.

    Args:
        path: destination ``.h5`` file; parent folders are created.
        data: the grasp set (already validated by construction).
        compression_level: gzip level 0-9 for non-empty arrays (with byte shuffle and Fletcher-32
            checksums), or None for uncompressed contiguous datasets like the release.
    """
    if not isinstance(data, DualGraspSet):
        raise TypeError(f"data: expected a DualGraspSet, found {type(data).__name__}")
    if compression_level is not None and (
        isinstance(compression_level, bool)
        or not isinstance(compression_level, int)
        or not 0 <= compression_level <= 9
    ):
        raise ValueError(f"compression_level: expected None or 0-9, found {compression_level!r}")
    metadata_json = _metadata_json(data.metadata)
    release = {
        "grasps": data.grasps,
        "contact_points": data.contact_points,
        "contact_forces": data.contact_forces,
        "loss_values": data.loss_values,
        "fc_passing_indices": data.passing_indices,
        "fc_failed_indices": data.failed_indices,
    }
    with atomic_path(path) as tmp, h5py.File(tmp, "w", track_order=False) as f:
        grasps = f.create_group("grasps", track_order=False)
        for name, arr in release.items():
            write_array(grasps, name, arr, compression_level)
        obj = f.create_group("object", track_order=False)
        obj.create_dataset(
            "file", data=data.object_file, dtype=h5py.string_dtype("utf-8"), track_times=False
        )
        obj.create_dataset("scale", data=np.float64(data.object_scale), track_times=False)
        ext = f.create_group(EXTRAS_GROUP, track_order=False)
        ext.attrs.create("schema_version", np.int64(SCHEMA_VERSION))
        ext.attrs.create("metadata", metadata_json, dtype=h5py.string_dtype("utf-8"))
        for name in sorted(data.extras):
            write_array(ext, name, data.extras[name], compression_level)
