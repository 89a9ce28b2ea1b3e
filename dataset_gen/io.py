"""File formats: DG16M release grasp files, ACRONYM grasp files, dataset manifests.

Every reader validates what it reads and raises :class:`~dataset_gen.errors.GraspFileError` naming
the file, the key, what was expected and what was found. Every writer goes through
:func:`dataset_gen.atomic.atomic_path`, so a destination is either its old version or complete.
Nothing is ever unpickled: HDF5 datasets are checked for a numeric dtype before their data is
read, and the only string data read from HDF5 is ``object/file`` (and ACRONYM's ``gripper/type``).

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

ACRONYM grasp files (read only)
-------------------------------
=============================================  =========  ========================================
key                                            shape      meaning
=============================================  =========  ========================================
``grasps/transforms``                          (N, 4, 4)  Panda grasp poses, object mesh frame (m);
                                                          ACRONYM frame: x = closing, z = approach
``grasps/qualities/flex/object_in_gripper``    (N,)       1 when the FleX trial held the object
``grasps/qualities/flex/<other>``              (N,)       other FleX measurements (optional)
``object/file``, ``object/scale``              ()         mesh file and its scale
``object/mass``, ``object/com``                (), (3,)   optional: kg, m
``gripper/type``, ``gripper/configuration``    (), (K,)   optional: e.g. ``"panda"``, opening (m)
=============================================  =========  ========================================

``T_dg16m = T_acronym @ ACRONYM_TO_DG16M``: our x = ACRONYM x, our y = ACRONYM z (approach),
our z = x × y = ACRONYM -y; the origin is unchanged.

Manifest (``manifest.json``, one per dataset folder)
----------------------------------------------------
::

    {
      "format": "dg16m-manifest",
      "schema_version": 1,
      "kind": "objects" | "grasps" | "benchmark",
      "created_by": "dg16m <version>",
      "parameters": {...},                       # any JSON object
      "entries": {
        "<object_id>": {
          "status": "ok" | "failed",
          "files": {"<role>": "<relative path>"},  # may be empty
          "error": "<message>",                    # required when failed, absent when ok
          ...                                      # free fields
        }
      }
    }

No other top-level keys are allowed. File paths are relative to the folder, use ``/`` separators
and may not be absolute or contain ``..`` (a manifest must not point outside its folder). Object
ids are non-empty and contain no ``/``, ``\\`` or NUL and are not ``.`` or ``..``. JSON with
duplicate keys or NaN/Infinity is rejected. The manifest is written as indented JSON with sorted
keys (stable bytes). One writer process owns a folder's manifest: :func:`update_manifest_entry`
reads, modifies and atomically rewrites it without locking.
"""

from __future__ import annotations

import importlib.metadata
import json
import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any, Literal

import h5py
import numpy as np

from dataset_gen.atomic import atomic_path, write_json_atomic
from dataset_gen.errors import GraspFileError
from dataset_gen.objects import is_rigid

__all__ = [
    "ACRONYM_TO_DG16M",
    "DEFAULT_GZIP_LEVEL",
    "MANIFEST_KINDS",
    "MANIFEST_NAME",
    "RELEASE_KEYS",
    "RIGID_ATOL",
    "SCHEMA_VERSION",
    "AcronymGrasps",
    "DualGraspSet",
    "acronym_to_dg16m",
    "dg16m_to_acronym",
    "manifest_entry_path",
    "new_manifest",
    "package_version",
    "read_acronym",
    "read_dg16m",
    "read_manifest",
    "update_manifest_entry",
    "validate_manifest",
    "write_dg16m",
    "write_manifest",
]

PathLike = str | os.PathLike[str]

# --------------------------------------------------------------------------------------------
# Constants
# --------------------------------------------------------------------------------------------

SCHEMA_VERSION = 1
"""Version of the ``dg16m/`` extension group written by :func:`write_dg16m`."""

SUPPORTED_SCHEMA_VERSIONS = (1,)
"""``dg16m/`` schema versions :func:`read_dg16m` understands."""

RIGID_ATOL = 1e-5
"""Tolerance of the rigid-transform check (orthonormality, det, last row). Real files are rigid
to 2e-10 (ACRONYM) and 7e-16 (DG16M release); 1e-5 also admits poses that went through float32
(error ~1e-7) and still rejects any real scaling or shear."""

LOSS_ATOL = 1e-9
"""A force-closure loss is a norm; values down to ``-LOSS_ATOL`` are accepted as solver rounding."""

DEFAULT_GZIP_LEVEL = 4
"""gzip level of :func:`write_dg16m`. Levels 6 and 9 gain < 1% on real data for 1.4-2x the time."""

CHUNK_BYTES = 512 * 1024
"""Target chunk size of compressed datasets (whole rows; below h5py's 1 MiB chunk cache)."""

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

ACRONYM_REQUIRED_KEYS = (
    "grasps/transforms",
    "grasps/qualities/flex/object_in_gripper",
    "object/file",
    "object/scale",
)
"""Datasets :func:`read_acronym` needs."""

_ACRONYM_FLEX = "grasps/qualities/flex"

ACRONYM_TO_DG16M = np.array(
    [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, -1.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]
)
"""(4, 4) rotation C with ``T_dg16m = T_acronym @ C``. Its columns are our axes written in the
ACRONYM gripper frame: x = (1, 0, 0), y = (0, 0, 1) (ACRONYM approach), z = x × y = (0, -1, 0)."""
ACRONYM_TO_DG16M.setflags(write=False)

MANIFEST_NAME = "manifest.json"
"""File name of a dataset folder's manifest."""

MANIFEST_FORMAT = "dg16m-manifest"
MANIFEST_SCHEMA_VERSION = 1
SUPPORTED_MANIFEST_VERSIONS = (1,)
MANIFEST_KINDS = ("objects", "grasps", "benchmark")
MANIFEST_STATUSES = ("ok", "failed")
_MANIFEST_KEYS = ("format", "schema_version", "kind", "created_by", "parameters", "entries")

_NUMERIC_KINDS = "biuf"
_WINDOWS_DRIVE = re.compile(r"^[A-Za-z]:")


# --------------------------------------------------------------------------------------------
# Frame conversion
# --------------------------------------------------------------------------------------------


def acronym_to_dg16m(transforms: np.ndarray) -> np.ndarray:
    """Convert (..., 4, 4) ACRONYM Panda grasp poses to the dg16m grasp frame.

    ``T_dg16m = T_acronym @ ACRONYM_TO_DG16M``: the closing axis (x) and the origin are kept, the
    approach axis moves from z to y. Returns a new float64 array of the same shape.
    """
    T = np.asarray(transforms, dtype=np.float64)
    if T.ndim < 2 or T.shape[-2:] != (4, 4):
        raise ValueError(f"transforms: expected shape (..., 4, 4), found {T.shape}")
    return T @ ACRONYM_TO_DG16M


def dg16m_to_acronym(transforms: np.ndarray) -> np.ndarray:
    """Inverse of :func:`acronym_to_dg16m`: (..., 4, 4) dg16m grasp poses to ACRONYM's frame."""
    T = np.asarray(transforms, dtype=np.float64)
    if T.ndim < 2 or T.shape[-2:] != (4, 4):
        raise ValueError(f"transforms: expected shape (..., 4, 4), found {T.shape}")
    return T @ ACRONYM_TO_DG16M.T


# --------------------------------------------------------------------------------------------
# Validation helpers (messages name the HDF5 key; readers prefix the file)
# --------------------------------------------------------------------------------------------


def _describe_dtype(dtype: np.dtype) -> str:
    """Human description of an (HDF5-derived) numpy dtype for error messages."""
    string_info = h5py.check_string_dtype(dtype)
    if string_info is not None:
        kind = "variable-length" if string_info.length is None else "fixed-length"
        return f"{kind} strings"
    if h5py.check_vlen_dtype(dtype) is not None:
        return "variable-length sequences"
    if h5py.check_ref_dtype(dtype) is not None:
        return "object references"
    if dtype.kind == "O":
        return "Python objects"
    if dtype.kind == "U":
        return "unicode strings"
    if dtype.kind == "S":
        return "byte strings"
    if dtype.kind == "V":
        return f"compound/opaque records ({dtype})"
    if dtype.kind == "b":
        return "booleans"
    return str(dtype)


def _check_kind(key: str, dtype: np.dtype, kinds: str, expected: str) -> None:
    """Raise unless ``dtype.kind`` is one of ``kinds`` (and not a string/reference type)."""
    if dtype.kind not in kinds or h5py.check_string_dtype(dtype) is not None:
        raise GraspFileError(f"{key}: expected {expected} values, found {_describe_dtype(dtype)}")


def _as_array(value: Any, key: str, kinds: str, expected: str) -> np.ndarray:
    """``np.asarray(value)`` after checking its dtype kind (no conversion of strings/objects)."""
    arr = np.asarray(value)
    _check_kind(key, arr.dtype, kinds, expected)
    return arr


def _frozen(arr: np.ndarray, dtype: type | np.dtype) -> np.ndarray:
    """A read-only C-contiguous copy of ``arr`` as ``dtype``."""
    out = np.array(arr, dtype=dtype, order="C", copy=True)
    out.setflags(write=False)
    return out


def _check_shape(key: str, shape: tuple[int, ...], expected: tuple[int, ...], why: str) -> None:
    if tuple(shape) != expected:
        raise GraspFileError(f"{key}: expected {expected}{why}, found {tuple(shape)}")


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


def _check_finite(key: str, arr: np.ndarray, unit: str = "pair") -> None:
    """Raise if ``arr`` has NaN or inf; report counts and the first bad row."""
    finite = np.isfinite(arr)
    if finite.all():
        return
    n_nan = int(np.isnan(arr).sum())
    n_inf = int(np.isinf(arr).sum())
    bad_rows = ~finite.reshape(len(arr), -1).all(axis=1) if arr.ndim else np.array([True])
    first = int(np.flatnonzero(bad_rows)[0])
    raise GraspFileError(
        f"{key}: expected finite values, found {n_nan} NaN and {n_inf} inf in "
        f"{int(bad_rows.sum())} {unit}(s) (first: {unit} {first})"
    )


def _check_rigid(key: str, transforms: np.ndarray, unit: str) -> None:
    """Raise unless every (..., 4, 4) transform is rigid within :data:`RIGID_ATOL`."""
    mask = np.asarray(is_rigid(transforms, atol=RIGID_ATOL))
    if mask.all():
        return
    bad = np.argwhere(~mask)
    first = ", ".join(f"{name} {int(i)}" for name, i in zip((unit, "arm"), bad[0], strict=False))
    raise GraspFileError(
        f"{key}: expected rigid transforms (orthonormal rotation with det +1, last row 0 0 0 1, "
        f"tolerance {RIGID_ATOL:g}), found {len(bad)} of {mask.size} not rigid (first: {first})"
    )


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


def _check_object_file(key: str, value: Any) -> str:
    if not isinstance(value, str) or not value or "\x00" in value:
        raise GraspFileError(f"{key}: expected a non-empty string without NUL, found {value!r}")
    return value


def _check_positive(key: str, value: Any) -> float:
    if isinstance(value, np.ndarray) and value.size == 1:
        value = value.reshape(()).item()
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise GraspFileError(f"{key}: expected a positive finite number, found {value!r}")
    out = float(value)
    if not (math.isfinite(out) and out > 0):
        raise GraspFileError(f"{key}: expected a positive finite number, found {out!r}")
    return out


def _arrays_equal(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is b
    return a.dtype == b.dtype and a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=True))


# --------------------------------------------------------------------------------------------
# DG16M release files
# --------------------------------------------------------------------------------------------


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

        object.__setattr__(self, "grasps", frozen["grasps/grasps"])
        object.__setattr__(self, "contact_points", frozen["grasps/contact_points"])
        object.__setattr__(self, "contact_forces", frozen["grasps/contact_forces"])
        object.__setattr__(self, "loss_values", loss)
        object.__setattr__(self, "passing_indices", passing)
        object.__setattr__(self, "failed_indices", failed)
        object.__setattr__(self, "object_file", object_file)
        object.__setattr__(self, "object_scale", object_scale)
        object.__setattr__(self, "extras", dict(sorted(extras.items())))
        object.__setattr__(self, "metadata", metadata)

    @property
    def n(self) -> int:
        """Number of dual grasps (pairs) N."""
        return int(self.grasps.shape[0])

    @property
    def passed(self) -> np.ndarray:
        """(N,) bool: True for the pairs listed in ``passing_indices``."""
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


def _open_h5(path: Path) -> h5py.File:
    """Open a user's HDF5 file for reading, turning every failure into :class:`GraspFileError`."""
    if not path.exists():
        raise GraspFileError(f"{path}: expected an HDF5 grasp file, found nothing at this path")
    if not path.is_file():
        raise GraspFileError(f"{path}: expected an HDF5 grasp file, found a directory/non-file")
    try:
        return h5py.File(path, "r")
    except Exception as exc:  # h5py raises OSError, ValueError, ... for foreign files
        raise GraspFileError(
            f"{path}: expected an HDF5 file, found something HDF5 cannot open ({exc})"
        ) from exc


def _check_present(path: Path, f: h5py.File, keys: tuple[str, ...], what: str) -> None:
    """Raise listing every key of ``keys`` that is missing or not a dataset."""
    missing = [key for key in keys if key not in f]
    if missing:
        raise GraspFileError(
            f"{path}: expected a {what} file with datasets {', '.join(keys)}; "
            f"missing: {', '.join(missing)}"
        )
    for key in keys:
        _check_dataset(path, f, key)


def _check_dataset(path: Path, f: h5py.File, key: str) -> h5py.Dataset:
    """``f[key]`` after checking it is a dataset reached through hard links only.

    Soft and external links are refused: an external link would make us read another file.
    """
    parts = key.split("/")
    for depth in range(1, len(parts) + 1):
        prefix = "/".join(parts[:depth])
        link = f.get(prefix, getlink=True)
        if not isinstance(link, h5py.HardLink):
            raise GraspFileError(
                f"{path}: {prefix}: expected an object stored in this file, "
                f"found a {type(link).__name__}"
            )
    item = f[key]
    if not isinstance(item, h5py.Dataset):
        raise GraspFileError(f"{path}: {key}: expected a dataset, found a group")
    return item


def _read_data(path: Path, ds: h5py.Dataset) -> Any:
    """Read a whole dataset (after its dtype has been checked)."""
    try:
        return ds[()]
    except OSError as exc:
        raise GraspFileError(f"{path}: {ds.name.lstrip('/')}: could not read data ({exc})") from exc


def _read_numeric(path: Path, ds: h5py.Dataset, kinds: str, expected: str) -> np.ndarray:
    key = ds.name.lstrip("/")
    try:
        _check_kind(key, ds.dtype, kinds, expected)
    except GraspFileError as exc:
        raise GraspFileError(f"{path}: {exc}") from None
    return np.asarray(_read_data(path, ds))


def _read_string(path: Path, ds: h5py.Dataset) -> str:
    """Read a scalar (or single-element) string dataset as UTF-8 text."""
    key = ds.name.lstrip("/")
    if h5py.check_string_dtype(ds.dtype) is None:
        raise GraspFileError(f"{path}: {key}: expected a string, found {_describe_dtype(ds.dtype)}")
    if ds.shape not in ((), (1,)):
        raise GraspFileError(f"{path}: {key}: expected a scalar string, found shape {ds.shape}")
    value = np.asarray(_read_data(path, ds)).reshape(()).item()
    if isinstance(value, bytes):
        try:
            value = value.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise GraspFileError(f"{path}: {key}: expected UTF-8 text, found {exc}") from exc
    return str(value)


def _read_scalar(path: Path, ds: h5py.Dataset) -> float:
    key = ds.name.lstrip("/")
    if ds.shape not in ((), (1,)):
        raise GraspFileError(f"{path}: {key}: expected a scalar, found shape {ds.shape}")
    value = _read_numeric(path, ds, "iuf", "numeric")
    return float(value.reshape(()))


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
    with _open_h5(path) as f:
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


def write_array(group: h5py.Group, name: str, arr: np.ndarray, level: int | None) -> None:
    """Create one dataset deterministically: no timestamps, explicit whole-row chunks."""
    data = arr.astype(arr.dtype.newbyteorder("<"), copy=False) if arr.dtype.itemsize > 1 else arr
    options: dict[str, Any] = {"track_times": False}
    if level is not None and data.ndim >= 1 and data.size > 0:
        row_bytes = data.itemsize * math.prod(data.shape[1:])
        rows = max(1, min(data.shape[0], CHUNK_BYTES // row_bytes))
        options.update(
            chunks=(rows, *data.shape[1:]),
            compression="gzip",
            compression_opts=level,
            shuffle=True,
            fletcher32=True,
        )
    group.create_dataset(name, data=data, **options)


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


# --------------------------------------------------------------------------------------------
# ACRONYM files
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False, repr=False)
class AcronymGrasps:
    """Single-arm Panda grasps of one object from an ACRONYM file, validated.

    Attributes:
        transforms_acronym: (N, 4, 4) float64 raw ACRONYM poses, gripper to object mesh frame
            (m); ACRONYM gripper frame: x = closing axis, z = approach axis.
        success: (N,) bool FleX label ``object_in_gripper``.
        object_file: mesh path as stored (relative to the ACRONYM root).
        object_scale: scale applied to the mesh file (positive).
        object_mass: kg, or None when absent.
        object_com: (3,) float64 centre of mass in the scaled mesh frame (m), or None.
        gripper_type: e.g. ``"panda"``, or None.
        gripper_configuration: (K,) float64 gripper opening parameters (m), or None.
        qualities: every (N,) dataset under ``grasps/qualities/flex`` as float64, by name.
        transforms: (N, 4, 4) float64 the same poses in the dg16m grasp frame (computed:
            ``transforms_acronym @ ACRONYM_TO_DG16M``; x = closing, y = approach).
    """

    transforms_acronym: np.ndarray
    success: np.ndarray
    object_file: str
    object_scale: float
    object_mass: float | None = None
    object_com: np.ndarray | None = None
    gripper_type: str | None = None
    gripper_configuration: np.ndarray | None = None
    qualities: dict[str, np.ndarray] = field(default_factory=dict)
    transforms: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        key = "grasps/transforms"
        T = _as_array(self.transforms_acronym, key, "f", "float")
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise GraspFileError(f"{key}: expected (N, 4, 4), found {T.shape}")
        n = T.shape[0]
        _check_finite(key, T, "grasp")
        T = _frozen(T, np.float64)
        _check_rigid(key, T, "grasp")
        skey = f"{_ACRONYM_FLEX}/object_in_gripper"
        s = _as_array(self.success, skey, "biuf", "0/1 or bool")
        _check_shape(skey, s.shape, (n,), " to match grasps/transforms")
        if s.dtype.kind != "b" and not np.isin(s, (0, 1)).all():
            bad = np.flatnonzero(~np.isin(s, (0, 1)))
            raise GraspFileError(
                f"{skey}: expected 0/1 labels, found {len(bad)} other value(s) "
                f"(first: grasp {int(bad[0])} = {s[bad[0]]!r})"
            )
        success = _frozen(s, bool)
        object_file = _check_object_file("object/file", self.object_file)
        object_scale = _check_positive("object/scale", self.object_scale)
        mass = (
            None if self.object_mass is None else _check_positive("object/mass", self.object_mass)
        )
        com = None
        if self.object_com is not None:
            com = _as_array(self.object_com, "object/com", "iuf", "numeric")
            _check_shape("object/com", com.shape, (3,), "")
            _check_finite("object/com", com.reshape(1, 3), "row")
            com = _frozen(com, np.float64)
        gripper_type = self.gripper_type
        if gripper_type is not None and not isinstance(gripper_type, str):
            raise GraspFileError(f"gripper/type: expected a string, found {gripper_type!r}")
        config = None
        if self.gripper_configuration is not None:
            config = _as_array(
                self.gripper_configuration, "gripper/configuration", "iuf", "numeric"
            )
            if config.ndim != 1:
                raise GraspFileError(f"gripper/configuration: expected (K,), found {config.shape}")
            _check_finite("gripper/configuration", config.reshape(1, -1), "row")
            config = _frozen(config, np.float64)
        qualities: dict[str, np.ndarray] = {}
        for name, value in dict(self.qualities).items():
            qkey = f"{_ACRONYM_FLEX}/{name}"
            q = _as_array(value, qkey, "biuf", "numeric")
            _check_shape(qkey, q.shape, (n,), " to match grasps/transforms")
            qualities[str(name)] = _frozen(q, np.float64)
        converted = _frozen(acronym_to_dg16m(T), np.float64)

        object.__setattr__(self, "transforms_acronym", T)
        object.__setattr__(self, "success", success)
        object.__setattr__(self, "object_file", object_file)
        object.__setattr__(self, "object_scale", object_scale)
        object.__setattr__(self, "object_mass", mass)
        object.__setattr__(self, "object_com", com)
        object.__setattr__(self, "gripper_configuration", config)
        object.__setattr__(self, "qualities", dict(sorted(qualities.items())))
        object.__setattr__(self, "transforms", converted)

    @property
    def n(self) -> int:
        """Number of grasps N."""
        return int(self.transforms_acronym.shape[0])

    def __repr__(self) -> str:
        return (
            f"AcronymGrasps(n={self.n}, success={int(self.success.sum())}, "
            f"object_file={self.object_file!r}, object_scale={self.object_scale!r}, "
            f"gripper_type={self.gripper_type!r})"
        )


def read_acronym(path: PathLike) -> AcronymGrasps:
    """Read an ACRONYM grasp file (single-arm Panda grasps with FleX labels).

    Raises:
        GraspFileError: not an HDF5 file, required keys missing, wrong dtype or shape, non-finite
            or non-rigid transforms, labels other than 0/1, bad optional fields.
    """
    path = Path(path)
    with _open_h5(path) as f:
        _check_present(path, f, ACRONYM_REQUIRED_KEYS, "ACRONYM grasp")
        ds = f["grasps/transforms"]
        if len(ds.shape) != 3 or ds.shape[1:] != (4, 4):
            raise GraspFileError(f"{path}: grasps/transforms: expected (N, 4, 4), found {ds.shape}")
        transforms = _read_numeric(path, ds, "f", "float")
        success = _read_numeric(path, f[f"{_ACRONYM_FLEX}/object_in_gripper"], "biuf", "0/1")
        qualities: dict[str, np.ndarray] = {}
        for name in f[_ACRONYM_FLEX]:
            item = _check_dataset(path, f, f"{_ACRONYM_FLEX}/{name}")
            if item.shape != ds.shape[:1]:
                raise GraspFileError(
                    f"{path}: {_ACRONYM_FLEX}/{name}: expected {ds.shape[:1]} to match "
                    f"grasps/transforms, found {item.shape}"
                )
            qualities[name] = _read_numeric(path, item, "biuf", "numeric")
        object_file = _read_string(path, f["object/file"])
        object_scale = _read_scalar(path, f["object/scale"])
        optional: dict[str, Any] = {}
        if "object/mass" in f:
            optional["object_mass"] = _read_scalar(path, _check_dataset(path, f, "object/mass"))
        for key, attr in (
            ("object/com", "object_com"),
            ("gripper/configuration", "gripper_configuration"),
        ):
            if key in f:
                optional[attr] = _read_numeric(path, _check_dataset(path, f, key), "iuf", "numeric")
        if "gripper/type" in f:
            optional["gripper_type"] = _read_string(path, _check_dataset(path, f, "gripper/type"))
    try:
        return AcronymGrasps(
            transforms_acronym=transforms,
            success=success,
            object_file=object_file,
            object_scale=object_scale,
            qualities=qualities,
            **optional,
        )
    except GraspFileError as exc:
        raise GraspFileError(f"{path}: {exc}") from None


def detect_format(path: PathLike) -> Literal["dg16m", "acronym"]:
    """Which grasp file format ``path`` holds: ``"dg16m"`` (``grasps/grasps``) or ``"acronym"``
    (``grasps/transforms``). Raises :class:`GraspFileError` for anything else."""
    path = Path(path)
    with _open_h5(path) as f:
        if "grasps/grasps" in f:
            return "dg16m"
        if "grasps/transforms" in f:
            return "acronym"
        found = sorted(f.keys())
    raise GraspFileError(
        f"{path}: expected a DG16M file (grasps/grasps) or an ACRONYM file (grasps/transforms), "
        f"found top-level keys {found}"
    )


# --------------------------------------------------------------------------------------------
# Manifest
# --------------------------------------------------------------------------------------------


def package_version() -> str:
    """The installed dg16m version, or ``"0+unknown"`` when the distribution is not installed."""
    try:
        return importlib.metadata.version("dg16m")
    except importlib.metadata.PackageNotFoundError:
        return "0+unknown"


def new_manifest(kind: str, parameters: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """An empty manifest of ``kind`` ("objects", "grasps" or "benchmark") made by this version."""
    manifest = {
        "format": MANIFEST_FORMAT,
        "schema_version": MANIFEST_SCHEMA_VERSION,
        "kind": kind,
        "created_by": f"dg16m {package_version()}",
        "parameters": dict(parameters or {}),
        "entries": {},
    }
    return validate_manifest(manifest)


class _ConstantError(ValueError):
    """NaN/Infinity in JSON (raised from ``parse_constant``)."""


class _DuplicateKeyError(ValueError):
    """A JSON object with a repeated key (raised from ``object_pairs_hook``)."""


def _reject_constant(name: str) -> Any:
    raise _ConstantError(f"expected finite JSON numbers, found {name}")


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKeyError(f"expected unique keys, found {key!r} twice in one object")
        out[key] = value
    return out


def _check_relative_path(where: str, value: Any) -> str:
    """A manifest file path: relative, '/'-separated, no '..', inside the folder."""
    if not isinstance(value, str) or not value:
        raise GraspFileError(f"{where}: expected a non-empty relative path, found {value!r}")
    if "\x00" in value or "\\" in value:
        raise GraspFileError(
            f"{where}: expected a relative path with '/' separators, found {value!r}"
        )
    pure = PurePosixPath(value)
    if pure.is_absolute() or _WINDOWS_DRIVE.match(value):
        raise GraspFileError(
            f"{where}: expected a path relative to the manifest's folder, found absolute {value!r}"
        )
    if ".." in pure.parts:
        raise GraspFileError(
            f"{where}: expected a path inside the manifest's folder, found '..' in {value!r}"
        )
    return value


def _check_object_id(where: str, object_id: Any) -> str:
    if (
        not isinstance(object_id, str)
        or not object_id
        or object_id in (".", "..")
        or any(c in object_id for c in "/\\\x00")
    ):
        raise GraspFileError(
            f"{where}: expected an object id (non-empty, no '/', '\\' or NUL, not '.' or '..'), "
            f"found {object_id!r}"
        )
    return object_id


def _check_entry(where: str, entry: Any) -> None:
    if not isinstance(entry, dict):
        raise GraspFileError(f"{where}: expected an object, found {type(entry).__name__}")
    status = entry.get("status")
    if status not in MANIFEST_STATUSES:
        raise GraspFileError(
            f"{where}.status: expected one of {list(MANIFEST_STATUSES)}, found {status!r}"
        )
    files = entry.get("files")
    if not isinstance(files, dict):
        raise GraspFileError(
            f"{where}.files: expected an object of role -> relative path, "
            f"found {type(files).__name__ if 'files' in entry else 'nothing'}"
        )
    for role, rel in files.items():
        _check_relative_path(f"{where}.files.{role}", rel)
    if status == "failed":
        if not isinstance(entry.get("error"), str):
            raise GraspFileError(
                f"{where}.error: expected an error message (string) for a failed entry, "
                f"found {entry.get('error')!r}"
            )
    elif "error" in entry:
        raise GraspFileError(f"{where}.error: expected no error for status 'ok', found one")


def validate_manifest(manifest: Any, source: str = "manifest") -> dict[str, Any]:
    """Check ``manifest`` against the schema in the module docstring; return it unchanged.

    Args:
        manifest: the parsed manifest.
        source: prefix of error messages (the file path when read from disk).

    Raises:
        GraspFileError: wrong format marker, unsupported version, unknown kind, unexpected or
            missing keys, bad entries (status, files, error), unsafe paths, non-JSON values.
    """
    if not isinstance(manifest, dict):
        raise GraspFileError(
            f"{source}: expected a JSON object at top level, found {type(manifest).__name__}"
        )
    if manifest.get("format") != MANIFEST_FORMAT:
        raise GraspFileError(
            f"{source}: format: expected {MANIFEST_FORMAT!r}, found {manifest.get('format')!r}"
        )
    version = manifest.get("schema_version")
    if (
        isinstance(version, bool)
        or not isinstance(version, int)
        or version not in SUPPORTED_MANIFEST_VERSIONS
    ):
        raise GraspFileError(
            f"{source}: schema_version: expected one of {list(SUPPORTED_MANIFEST_VERSIONS)} "
            f"(supported by dg16m {package_version()}), found {version!r}"
        )
    missing = [key for key in _MANIFEST_KEYS if key not in manifest]
    if missing:
        raise GraspFileError(f"{source}: expected keys {list(_MANIFEST_KEYS)}, missing {missing}")
    unexpected = sorted(set(manifest) - set(_MANIFEST_KEYS))
    if unexpected:
        raise GraspFileError(
            f"{source}: expected only keys {list(_MANIFEST_KEYS)}, found also {unexpected}"
        )
    if manifest["kind"] not in MANIFEST_KINDS:
        raise GraspFileError(
            f"{source}: kind: expected one of {list(MANIFEST_KINDS)}, found {manifest['kind']!r}"
        )
    if not isinstance(manifest["created_by"], str):
        raise GraspFileError(
            f"{source}: created_by: expected a string, found {manifest['created_by']!r}"
        )
    for key in ("parameters", "entries"):
        if not isinstance(manifest[key], dict):
            raise GraspFileError(
                f"{source}: {key}: expected an object, found {type(manifest[key]).__name__}"
            )
    for object_id, entry in manifest["entries"].items():
        _check_object_id(f"{source}: entries", object_id)
        _check_entry(f"{source}: entries.{object_id}", entry)
    try:
        json.dumps(manifest, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise GraspFileError(
            f"{source}: expected JSON values only (finite numbers, string keys), found {exc}"
        ) from exc
    return manifest


def write_manifest(folder: PathLike, manifest: Mapping[str, Any]) -> Path:
    """Validate and atomically write ``folder/manifest.json`` (sorted keys, stable bytes).

    Returns the manifest's path. Raises :class:`GraspFileError` when ``manifest`` is invalid
    (nothing is written then).
    """
    path = Path(folder) / MANIFEST_NAME
    payload = validate_manifest(dict(manifest), source=str(path))
    write_json_atomic(path, payload)
    return path


def read_manifest(folder: PathLike) -> dict[str, Any]:
    """Read and validate ``folder/manifest.json``.

    Raises:
        GraspFileError: no manifest, not UTF-8, malformed JSON (with line and column), duplicate
            keys, NaN/Infinity, or any schema violation (see :func:`validate_manifest`).
    """
    path = Path(folder) / MANIFEST_NAME
    if not path.is_file():
        raise GraspFileError(f"{path}: expected a dg16m manifest, found no such file")
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise GraspFileError(f"{path}: expected UTF-8 JSON, found {exc}") from exc
    try:
        manifest = json.loads(
            text, object_pairs_hook=_no_duplicates, parse_constant=_reject_constant
        )
    except json.JSONDecodeError as exc:
        raise GraspFileError(
            f"{path}: expected JSON, found malformed JSON at line {exc.lineno}, column "
            f"{exc.colno}: {exc.msg}"
        ) from exc
    except (_DuplicateKeyError, _ConstantError) as exc:
        raise GraspFileError(f"{path}: {exc}") from exc
    return validate_manifest(manifest, source=str(path))


def update_manifest_entry(
    folder: PathLike,
    object_id: str,
    entry: Mapping[str, Any],
    *,
    kind: str | None = None,
    parameters: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Set ``entries[object_id] = entry`` in ``folder/manifest.json`` and rewrite it atomically.

    Creates the manifest (``kind`` and ``parameters`` required then) when the folder has none.
    With an existing manifest, ``parameters`` is ignored and ``kind``, when given, must match.
    The entry replaces any previous one for ``object_id`` (no merge). No locking: one writer
    process owns a folder's manifest. Returns the manifest as written.

    Raises:
        GraspFileError: the existing manifest is invalid or of another kind, or the entry is
            invalid (bad status, unsafe path, ...).
        ValueError: no manifest exists and ``kind`` is None.
    """
    path = Path(folder) / MANIFEST_NAME
    if path.exists():
        manifest = read_manifest(folder)
        if kind is not None and manifest["kind"] != kind:
            raise GraspFileError(f"{path}: kind: expected {kind!r}, found {manifest['kind']!r}")
    else:
        if kind is None:
            raise ValueError(f"{path} does not exist: pass kind= to create it")
        manifest = new_manifest(kind, parameters)
    _check_object_id(f"{path}: entries", object_id)
    manifest["entries"][object_id] = dict(entry)
    write_manifest(folder, manifest)
    return manifest


def manifest_entry_path(
    folder: PathLike, manifest: Mapping[str, Any], object_id: str, role: str
) -> Path:
    """``folder`` joined with the stored path ``entries[object_id].files[role]``.

    The stored path is re-checked (relative, no ``..``) before it is joined to ``folder``.

    Raises:
        GraspFileError: no such entry or role, or an unsafe path.
    """
    entries = manifest.get("entries", {})
    if object_id not in entries:
        raise GraspFileError(f"{folder}: entries: expected {object_id!r}, found no such entry")
    files = entries[object_id].get("files", {})
    if role not in files:
        raise GraspFileError(
            f"{folder}: entries.{object_id}.files: expected role {role!r}, found {sorted(files)}"
        )
    rel = _check_relative_path(f"{folder}: entries.{object_id}.files.{role}", files[role])
    return Path(folder) / PurePosixPath(rel)
