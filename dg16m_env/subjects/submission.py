"""Submission files: the dual grasps a predictor proposes for each benchmark object (HDF5).

Schema (``format = "dg16m-submission"``, ``schema_version = 1``)
----------------------------------------------------------------
Root attributes:

* ``format`` = ``"dg16m-submission"``, ``schema_version`` = 1 (integer);
* ``benchmark``: the sha256 (64 lower-case hex digits) of the benchmark file the grasps were
  made for, or ``"embedded"`` for the benchmark shipped with the package;
* ``metadata`` (optional): a JSON object (method name, team, free text), at most
  :attr:`SubmissionLimits.max_metadata_bytes` bytes.

One group per object, ``objects/<object_id>/``, for every object of the benchmark and no other:

* ``poses``: (K, 2, 4, 4) float32 or float64, the two hand poses of each of the K dual grasps,
  Panda grasp frame -> object frame (m; the dg16m grasp frame: +x closing, +y approach), each a
  finite rigid transform; 1 <= K <= :attr:`SubmissionLimits.max_grasps_per_object`;
* ``scores`` (optional): (K,) float32 or float64, finite, higher = better (ranks the grasps
  for top-k metrics).

Nothing else is allowed: no other datasets or groups, no other attributes, no soft or external
links, no external or virtual storage, no object, variable-length, string, compound, integer or
half-precision dtypes, no filters other than HDF5's own and LZF. A file is read only after it
passed validation, and never unpickled.

The format's constants, limits and errors live here, with the in-memory :class:`Submission`;
reading and validation are :mod:`dg16m_env.subjects.submission_reader`, writing is
:mod:`dg16m_env.subjects.submission_writer`.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import h5py
import numpy as np

from dg16m_core.errors import Dg16mError

__all__ = [
    "EMBEDDED",
    "FORMAT",
    "SCHEMA_VERSION",
    "Problem",
    "Submission",
    "SubmissionError",
    "SubmissionInvalid",
    "SubmissionLimits",
]


FORMAT = "dg16m-submission"
SCHEMA_VERSION = 1
EMBEDDED = "embedded"

MIB = 1 << 20
ROOT_ATTRS = ("format", "schema_version", "benchmark", "metadata")
"""The root attributes a submission may have (``metadata`` is optional)."""
DATASETS = ("poses", "scores")
"""The datasets an object group may hold (``scores`` is optional)."""
BOTTOM_ROW_ATOL = 1e-6
"""Largest deviation of a pose's bottom row from ``[0, 0, 0, 1]``."""
ROTATION_ATOL = 1e-4
"""Largest entry of ``|R^T R - I|`` of a pose's rotation (admits float32 round-off, ~1e-7)."""
MAX_TRANSLATION = 10.0
"""Sanity bound on a hand's distance from the object origin (m); benchmark objects are < 2 m."""
ALLOWED_FILTERS = {
    1: "gzip",
    2: "shuffle",
    3: "fletcher32",
    4: "szip",
    5: "nbit",
    6: "scaleoffset",
    32000: "lzf",
}
"""HDF5 filters a dataset may use (id -> name): HDF5's own and h5py's LZF. Any other id would make
HDF5 look for a plugin library, so it is refused before data is read."""
MAX_MEMBERS = 16
"""Most members (or attributes) a group other than ``objects`` may have before it is reported
without being listed (a file of a million junk names is refused in bounded time)."""
SHOW = 20
"""How many problems :class:`SubmissionInvalid` lists, and how many ids a problem names."""
FIRST = 3
"""How many bad grasps a value problem names."""

_HEX64 = re.compile(r"[0-9a-f]{64}")


class SubmissionError(Dg16mError, ValueError):
    """A submission that cannot be written or read (bad arguments, an invalid file)."""


@dataclass(frozen=True)
class SubmissionLimits:
    """Bounds a submission file must respect (checked before any data is read).

    Attributes:
        max_grasps_per_object: most dual grasps K per object.
        max_file_bytes: largest file size (bytes, checked with ``os.stat`` before opening).
        max_dataset_bytes: largest declared uncompressed size of one dataset (bytes): shape
            times item size, whatever its compression; also bounds one chunk.
        max_total_bytes: largest sum of the declared uncompressed sizes of all datasets (bytes).
        max_metadata_bytes: largest ``metadata`` attribute (bytes of UTF-8).
        max_objects: most object groups.

    Raises:
        SubmissionError: a field that is not a positive integer.
    """

    max_grasps_per_object: int = 100
    max_file_bytes: int = 256 * MIB
    max_dataset_bytes: int = 64 * MIB
    max_total_bytes: int = 512 * MIB
    max_metadata_bytes: int = 65536
    max_objects: int = 10000

    def __post_init__(self) -> None:
        for spec in fields(self):
            value = getattr(self, spec.name)
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
                raise SubmissionError(
                    f"SubmissionLimits.{spec.name}: expected a positive integer, "
                    f"found {type(value).__name__} {value!r}"
                )
            if value < 1:
                raise SubmissionError(
                    f"SubmissionLimits.{spec.name}: expected a positive integer, found {value}"
                )
            object.__setattr__(self, spec.name, int(value))


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a submission file.

    Attributes:
        place: where: ``"file"`` (the path itself), ``"/"`` (the whole file), ``"attrs/<name>"``
            (a root attribute), or an HDF5 path, with an index for values
            (``"objects/table-1000000/poses[3, 1]"``: dual grasp 3, hand 1).
        message: what was expected and what was found.
    """

    place: str
    message: str

    def __str__(self) -> str:
        return f"{self.place}: {self.message}"


class SubmissionInvalid(SubmissionError):  # noqa: N818  (the name the evaluators use)
    """A submission file with problems; :attr:`problems` lists every one.

    Args:
        problems: what is wrong (at least one).
        path: the file, named in the message when given.

    Attributes:
        problems: every problem found, in the order found.
        path: the file (None when not given).
    """

    def __init__(self, problems: Sequence[Problem], path: str | os.PathLike[str] | None = None):
        self.problems: list[Problem] = list(problems)
        self.path = None if path is None else str(path)
        n = len(self.problems)
        where = f"{self.path}: " if self.path is not None else ""
        lines = [f"{where}expected a valid submission file, found {n} problem(s):"]
        lines += [f"  {problem}" for problem in self.problems[:SHOW]]
        if n > SHOW:
            lines.append(f"  ... and {n - SHOW} more")
        super().__init__("\n".join(lines))

    def __reduce__(self) -> tuple[Any, ...]:  # pickles across worker processes
        return (type(self), (self.problems, self.path))


@dataclass(frozen=True, eq=False)
class Submission:
    """Dual grasps per benchmark object (object frame, m).

    Attributes:
        poses: object id -> (K, 2, 4, 4) float64 hand poses.
        scores: object id -> (K,) float64 scores, for the objects that have them.
        benchmark: sha256 of the benchmark file, or ``"embedded"``.
        metadata: JSON-ready free-form facts (method, team, ...).
        sha256: the sha256 of the file it was read from ("" when made in memory).
    """

    poses: dict[str, np.ndarray]
    scores: dict[str, np.ndarray] = field(default_factory=dict)
    benchmark: str = EMBEDDED
    metadata: dict[str, Any] = field(default_factory=dict)
    sha256: str = ""

    @property
    def object_ids(self) -> list[str]:
        """The object ids, sorted."""
        return sorted(self.poses)

    @property
    def n_grasps(self) -> int:
        """Dual grasps over all objects."""
        return sum(len(p) for p in self.poses.values())

    def __repr__(self) -> str:  # arrays: count them
        return (
            f"Submission({len(self.poses)} objects, {self.n_grasps} dual grasps, "
            f"{len(self.scores)} scored, benchmark {self.benchmark[:12]!r})"
        )


def _check_benchmark_name(benchmark: Any) -> str:
    if not isinstance(benchmark, str) or (
        benchmark != EMBEDDED and not _HEX64.fullmatch(benchmark)
    ):
        raise SubmissionError(
            f"benchmark: expected a sha256 (64 lower-case hex digits) or {EMBEDDED!r}, "
            f"found {_show(benchmark)}"
        )
    return benchmark


def _check_object_id(object_id: Any, where: str) -> str:
    if not isinstance(object_id, str) or object_id in ("", ".", "..") or "/" in object_id:
        raise SubmissionError(
            f"{where}: expected object ids that are HDF5 names (non-empty strings without '/', "
            f"not '.' or '..'), found {_show(object_id)}"
        )
    return object_id


# --------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------


def _show(value: Any, limit: int = 60) -> str:
    """``repr(value)``, shortened to about ``limit`` characters."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _names(values: Sequence[str]) -> str:
    """The first :data:`SHOW` of ``values`` (sorted), quoted, with the count of the rest."""
    shown = ", ".join(repr(v) for v in sorted(values)[:SHOW])
    return shown + (f" and {len(values) - SHOW} more" if len(values) > SHOW else "")


def _describe_dtype(dtype: np.dtype) -> str | None:
    """None for float32/float64, else what the dtype is, for "expected ..., found ..."."""
    string = h5py.check_string_dtype(dtype)
    if string is not None:
        return f"{'variable' if string.length is None else 'fixed'}-length strings"
    if h5py.check_vlen_dtype(dtype) is not None:
        return "variable-length sequences (an object dtype)"
    if h5py.check_ref_dtype(dtype) is not None:
        return "object references"
    if dtype.kind == "O":
        return "Python objects (an object dtype)"
    if dtype.subdtype is not None:
        return f"an array datatype ({dtype.subdtype[0]} x {dtype.subdtype[1]})"
    if dtype.names is not None:
        return f"a compound datatype (fields {', '.join(dtype.names)})"
    if dtype.kind == "V":
        return f"opaque data ({dtype.itemsize} bytes)"
    if dtype.kind == "b":
        return "booleans"
    if h5py.check_enum_dtype(dtype) is not None:
        return f"an enumeration ({dtype.name})"
    if dtype.kind in "iu":
        return f"integers ({dtype.name})"
    if dtype.kind == "c":
        return f"complex numbers ({dtype.name})"
    if dtype.kind == "f":
        if dtype.itemsize in (4, 8):
            return None
        if dtype.itemsize == 2:
            return "float16 (half precision)"
        return f"{dtype.itemsize * 8}-bit floats (extended precision)"
    if dtype.kind in "SU":
        return "strings"
    if dtype.kind in "mM":
        return "times"
    return str(dtype)


def _indices(rows: np.ndarray) -> str:
    """``[3], [5], [8]`` / ``[3, 1], [5, 0]`` for the first :data:`FIRST` rows of indices."""
    return ", ".join(
        "[" + ", ".join(str(int(i)) for i in np.atleast_1d(r)) + "]" for r in rows[:FIRST]
    )


def hand_pose_faults(poses: np.ndarray) -> list[tuple[np.ndarray, str]]:
    """The checks a submission makes of finite hand poses, one mask each.

    Args:
        poses: (K, 2, 4, 4) finite hand poses (m).

    Returns:
        ``[(faulty (K, 2) bool, "expected ..., found ..."), ...]``: bottom row, rotation
        (orthonormal), reflection (det R < 0) and reach (translation within
        :data:`MAX_TRANSLATION`), in that order. Also used by :mod:`dg16m_env.subjects.predictor`, so a
        predictor's output is judged exactly as a file would be.
    """
    with np.errstate(all="ignore"):
        bottom = np.abs(poses[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])).max(axis=-1)
        R = poses[..., :3, :3]
        gram = np.swapaxes(R, -1, -2) @ R
        ortho = np.abs(gram - np.eye(3)).max(axis=(-2, -1))
        det = np.linalg.det(R) if len(R) else np.zeros((0, 2))
        reach = np.linalg.norm(poses[..., :3, 3], axis=-1)
    return [
        (
            ~(bottom <= BOTTOM_ROW_ATOL),
            f"expected a rigid transform with bottom row [0, 0, 0, 1] (within "
            f"{BOTTOM_ROW_ATOL:g}), found another bottom row",
        ),
        (
            ~(ortho < ROTATION_ATOL),
            f"expected a rotation (|R^T R - I| < {ROTATION_ATOL:g}), found a scaled or sheared "
            "matrix (not rigid)",
        ),
        (det < 0, "expected a rotation (det R = +1), found a reflection (det R < 0)"),
        (
            ~(reach <= MAX_TRANSLATION),
            f"expected hands within {MAX_TRANSLATION:g} m of the object origin, found a "
            "translation beyond that sanity bound",
        ),
    ]
