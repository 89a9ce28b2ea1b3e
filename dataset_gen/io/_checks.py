"""Validation shared by the grasp file formats (messages name the HDF5 key; readers add the file).

Every check raises :class:`~dg16m_core.errors.GraspFileError` saying what was expected and what
was found. Nothing here reads a file: see :mod:`dataset_gen.io._hdf5` for that.
"""

from __future__ import annotations

import math
import os
from typing import Any

import h5py
import numpy as np

from dataset_gen.objects.grasp_object import is_rigid
from dg16m_core.errors import GraspFileError

PathLike = str | os.PathLike[str]

RIGID_ATOL = 1e-5
"""Tolerance of the rigid-transform check (orthonormality, det, last row). Real files are rigid
to 2e-10 (ACRONYM) and 7e-16 (DG16M release); 1e-5 also admits poses that went through float32
(error ~1e-7) and still rejects any real scaling or shear."""

_NUMERIC_KINDS = "biuf"


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


def _assign(instance: object, **values: Any) -> None:
    """Set validated, normalised field values on a frozen dataclass (from its ``__post_init__``)."""
    for name, value in values.items():
        object.__setattr__(instance, name, value)


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


class _ConstantError(ValueError):
    """NaN/Infinity in JSON (raised from ``parse_constant``)."""


def _reject_constant(name: str) -> Any:
    raise _ConstantError(f"expected finite JSON numbers, found {name}")
