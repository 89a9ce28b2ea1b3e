"""Reading and writing HDF5 datasets safely and deterministically, for every grasp file format.

Readers refuse soft and external links and check a dataset's dtype before its data is read (so
nothing is ever unpickled); :func:`write_array` creates a dataset without timestamps and with
explicit whole-row chunks, so equal data gives equal bytes.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from dg16m_core.errors import GraspFileError

from ._checks import _check_kind, _describe_dtype

CHUNK_BYTES = 512 * 1024
"""Target chunk size of compressed datasets (whole rows; below h5py's 1 MiB chunk cache)."""


def hdf5_content_problem(path: str | os.PathLike[str]) -> str | None:
    """What a regular file that cannot be HDF5 is, said before HDF5 tries to open it: ``"an
    empty file (0 bytes)"`` or ``"a file without the HDF5 signature (it starts with b'...')"``;
    ``None`` when it may be one. The one check behind "expected an HDF5 file, found ..." in
    :func:`open_hdf5` (``dg16m inspect``, ``dg16m submission validate``) and in the submission
    validator (``dg16m evaluate``).

    Raises:
        OSError: the file cannot be read.
    """
    path = Path(path)
    if path.stat().st_size == 0:
        return "an empty file (0 bytes)"
    try:
        is_hdf5 = bool(h5py.is_hdf5(path))
    except Exception:  # a file h5py cannot even probe
        is_hdf5 = False
    if is_hdf5:
        return None
    with open(path, "rb") as handle:
        start = handle.read(8)
    return f"a file without the HDF5 signature (it starts with {start!r})"


def open_hdf5(path: Path, what: str = "HDF5 grasp file") -> h5py.File:
    """Open a user's HDF5 file (``what``, for messages) for reading, turning every failure into
    :class:`GraspFileError`."""
    path = Path(path)
    if not path.exists():
        raise GraspFileError(f"{path}: expected an {what}, found nothing at this path")
    if not path.is_file():
        raise GraspFileError(f"{path}: expected an {what}, found a directory/non-file")
    try:
        problem = hdf5_content_problem(path)
    except OSError as exc:
        raise GraspFileError(
            f"{path}: expected a readable {what}, found {exc.strerror or exc}"
        ) from exc
    if problem is not None:
        raise GraspFileError(f"{path}: expected an HDF5 file, found {problem}")
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
