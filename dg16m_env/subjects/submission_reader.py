"""Reading a submission file, only after it is validated in full (:func:`validate_submission`,
:func:`read_submission`; the schema is in :mod:`dg16m_env.subjects.submission`).

Validation (:func:`validate_submission`)
----------------------------------------
Every problem is reported, each with its place (``"file"``, ``"/"``, ``"attrs/benchmark"``,
``"objects/<id>/poses[3, 1]"``, ...), in this order, each stage reading nothing the previous
stage has not vetted:

1. the path: it exists, is a regular file, is at most :attr:`SubmissionLimits.max_file_bytes`
   (``os.stat``, before the file is opened) and is an HDF5 file HDF5 can open;
2. the root attributes (dtype and shape of each is checked before its value is read);
3. the tree, walked one level at a time without dereferencing a link: each member's link type
   is read first (soft and external links are reported, never followed), and groups outside
   the schema are reported, never entered (so hard-link cycles are harmless);
4. each dataset's header: dtype, shape, storage (external, virtual, filters, chunk size) and its
   declared uncompressed size, per dataset and summed over the file;
5. only then the values of the datasets that passed: finite, rigid, translations within
   :data:`~dg16m_env.subjects.submission.MAX_TRANSLATION` m.

A hard link that gives one dataset or group two names (``objects/b`` = ``objects/a``) is allowed:
it is an ordinary HDF5 name, the data is read (and counted against the size limits) once per
name, and the file means exactly what two copies would.
"""

from __future__ import annotations

import json
import math
import os
import stat
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from dataset_gen.hashing import file_sha256
from dataset_gen.io import hdf5_content_problem
from dg16m_env.subjects.submission import (
    _HEX64,
    ALLOWED_FILTERS,
    DATASETS,
    EMBEDDED,
    FORMAT,
    MAX_MEMBERS,
    ROOT_ATTRS,
    SCHEMA_VERSION,
    Problem,
    Submission,
    SubmissionError,
    SubmissionInvalid,
    SubmissionLimits,
    _check_object_id,
    _describe_dtype,
    _indices,
    _names,
    _show,
    hand_pose_faults,
)

__all__ = [
    "read_submission",
    "validate_submission",
]


@dataclass
class _Dataset:
    """A dataset whose header passed: read its values in the second pass."""

    place: str
    dataset: h5py.Dataset
    object_id: str
    name: str
    nbytes: int
    compression: str | None


@dataclass
class _Contents:
    poses: dict[str, np.ndarray] = field(default_factory=dict)
    scores: dict[str, np.ndarray] = field(default_factory=dict)
    benchmark: str = ""
    metadata: dict[str, Any] = field(default_factory=dict)
    stat: os.stat_result | None = None


class _Validator:
    """One validation of one file: collects every problem and, when there are none, the values."""

    def __init__(
        self,
        object_ids: Sequence[str] | None,
        benchmark_sha256: str | None,
        embedded: bool,
        limits: SubmissionLimits,
    ) -> None:
        if not isinstance(limits, SubmissionLimits):
            raise SubmissionError(
                f"limits: expected a SubmissionLimits, found {type(limits).__name__}"
            )
        if isinstance(object_ids, (str, bytes)):
            raise SubmissionError(
                f"object_ids: expected a sequence of object ids, found a single string "
                f"{_show(object_ids)}"
            )
        if object_ids is not None:
            object_ids = [_check_object_id(i, "object_ids") for i in object_ids]
        if benchmark_sha256 is not None and (
            not isinstance(benchmark_sha256, str) or not _HEX64.fullmatch(benchmark_sha256)
        ):
            raise SubmissionError(
                "benchmark_sha256: expected None or 64 lower-case hex digits, "
                f"found {_show(benchmark_sha256)}"
            )
        self.object_ids = None if object_ids is None else set(object_ids)
        self.benchmark_sha256 = benchmark_sha256
        self.embedded = bool(embedded)
        self.limits = limits
        self.problems: list[Problem] = []
        self.contents = _Contents()
        self.readable: list[_Dataset] = []

    def add(self, place: str, message: str) -> None:
        self.problems.append(Problem(place, message))

    @contextmanager
    def guard(self, place: str, doing: str) -> Iterator[None]:
        """Turn any error of h5py (a corrupt or truncated file) into a problem at ``place``."""
        try:
            yield
        except Exception as exc:  # h5py raises OSError, KeyError, RuntimeError, TypeError, ...
            self.add(
                place,
                f"expected a readable HDF5 file, found an error while {doing} "
                f"(corrupt or truncated?): {type(exc).__name__}: {_show(str(exc), 200)}",
            )

    # ---- the path ---------------------------------------------------------------------------

    def run(self, path: str | os.PathLike[str]) -> None:
        path = Path(path)
        try:
            st = os.stat(path)
        except FileNotFoundError:
            self.add("file", f"expected a submission file at {path}, found nothing there")
            return
        except OSError as exc:
            self.add("file", f"expected a readable file at {path}, found {exc.strerror}")
            return
        self.contents.stat = st
        if not stat.S_ISREG(st.st_mode):
            what = "a directory" if stat.S_ISDIR(st.st_mode) else "something else"
            self.add("file", f"expected a regular file at {path}, found {what}")
            return
        if st.st_size > self.limits.max_file_bytes:
            self.add(
                "file",
                f"expected at most {self.limits.max_file_bytes} bytes, found a file of "
                f"{st.st_size} bytes (over the limit; not opened)",
            )
            return
        try:
            problem = hdf5_content_problem(path)
        except OSError as exc:
            self.add("file", f"expected a readable file at {path}, found {exc.strerror}")
            return
        if problem is not None:
            self.add("file", f"expected an HDF5 file, found {problem}")
            return
        try:
            f = h5py.File(path, "r")
        except Exception as exc:
            self.add(
                "file",
                f"expected an HDF5 file HDF5 can open, found one it cannot (truncated or "
                f"corrupt): {_show(str(exc), 200)}",
            )
            return
        with f:
            with self.guard("/", "reading the root attributes"):
                self.root_attrs(f)
            with self.guard("/", "walking the tree"):
                self.tree(f)
            self.values()

    # ---- attributes -------------------------------------------------------------------------

    def attr_header(self, obj: h5py.HLObject, name: str) -> tuple[tuple[int, ...] | None, Any]:
        """(shape, dtype or the error that made its dtype unreadable) of an attribute."""
        aid = obj.attrs.get_id(name)
        try:
            dtype: Any = aid.dtype
        except Exception as exc:  # an HDF5 type h5py cannot map
            dtype = exc
        return aid.shape, dtype

    def string_attr(self, f: h5py.File, name: str) -> tuple[str | None, str | None]:
        """(value, None) of a scalar string attribute, or (None, what was found instead)."""
        shape, dtype = self.attr_header(f, name)
        if isinstance(dtype, Exception):
            return None, f"an unsupported datatype ({dtype})"
        if h5py.check_string_dtype(dtype) is None:
            return None, f"{_describe_dtype(dtype) or dtype.name + ' numbers'} (not a string)"
        if shape != ():
            return None, f"strings of shape {shape} (not a single string)"
        if dtype.itemsize > self.limits.max_metadata_bytes:
            return None, f"a fixed-length string of {dtype.itemsize} bytes (over the limit)"
        value = f.attrs[name]
        if isinstance(value, (bytes, np.bytes_)):
            try:
                value = bytes(value).decode("utf-8")
            except UnicodeDecodeError:
                return None, "bytes that are not UTF-8"
        return str(value), None

    def root_attrs(self, f: h5py.File) -> None:
        n = len(f.attrs)
        if n > MAX_MEMBERS:
            self.add(
                "/",
                f"expected at most {len(ROOT_ATTRS)} root attributes, found {n} (not listed)",
            )
            names = [name for name in ROOT_ATTRS if name in f.attrs]
        else:
            names = list(f.attrs.keys())
        for name in names:
            if name not in ROOT_ATTRS:
                self.add(
                    f"attrs/{name}",
                    f"expected only the root attributes {', '.join(ROOT_ATTRS)}, "
                    f"found an unknown attribute {name!r}",
                )
        checks: tuple[tuple[str, Callable[[h5py.File], None], str], ...] = (
            ("format", self.format_attr, f"expected {FORMAT!r}"),
            ("schema_version", self.version_attr, f"expected the integer {SCHEMA_VERSION}"),
            (
                "benchmark",
                self.benchmark_attr,
                f"expected the benchmark's sha256 (64 lower-case hex digits) or {EMBEDDED!r}",
            ),
            ("metadata", self.metadata_attr, ""),
        )
        for name, check, expected in checks:
            if name in names:
                with self.guard(f"attrs/{name}", f"reading the attribute {name!r}"):
                    check(f)
            elif expected:  # metadata is optional
                self.add(f"attrs/{name}", f"{expected}, found no {name!r} attribute")

    def format_attr(self, f: h5py.File) -> None:
        value, found = self.string_attr(f, "format")
        if value != FORMAT:
            self.add("attrs/format", f"expected {FORMAT!r}, found {found or _show(value)}")

    def version_attr(self, f: h5py.File) -> None:
        place = "attrs/schema_version"
        shape, dtype = self.attr_header(f, "schema_version")
        if isinstance(dtype, Exception):
            found: str | None = f"an unsupported datatype ({dtype})"
        elif dtype.kind not in "iu" or h5py.check_enum_dtype(dtype) is not None:
            found = _describe_dtype(dtype) or f"{dtype.name} numbers"
        elif shape != ():
            found = f"integers of shape {shape}"
        else:
            found = None
        if found is not None:
            self.add(
                place, f"expected the integer {SCHEMA_VERSION}, found {found} (not an integer)"
            )
            return
        version = int(f.attrs["schema_version"])
        if version != SCHEMA_VERSION:
            self.add(
                place,
                f"expected schema version {SCHEMA_VERSION}, found {version} "
                "(unsupported by this version of dg16m)",
            )

    def benchmark_attr(self, f: h5py.File) -> None:
        place = "attrs/benchmark"
        expected = f"the benchmark's sha256 (64 lower-case hex digits) or {EMBEDDED!r}"
        value, found = self.string_attr(f, "benchmark")
        if value is None:
            self.add(place, f"expected {expected}, found {found}")
            return
        if value == EMBEDDED:
            if not self.embedded:
                self.add(
                    place,
                    f"expected the sha256 of the benchmark being evaluated"
                    f"{f' ({self.benchmark_sha256[:12]}...)' if self.benchmark_sha256 else ''}, "
                    f"found {EMBEDDED!r}: the grasps were made for the embedded benchmark, "
                    "which is not the one being evaluated",
                )
        elif not _HEX64.fullmatch(value):
            self.add(place, f"expected {expected}, found {_show(value)}")
        elif self.benchmark_sha256 is not None and value != self.benchmark_sha256:
            self.add(
                place,
                f"expected the sha256 of the benchmark being evaluated "
                f"({self.benchmark_sha256}), found {value}: made for another benchmark",
            )
        self.contents.benchmark = value

    def metadata_attr(self, f: h5py.File) -> None:
        place = "attrs/metadata"
        value, found = self.string_attr(f, "metadata")
        if value is None:
            self.add(place, f"expected a JSON object (a string), found {found}")
            return
        size = len(value.encode("utf-8", "surrogatepass"))
        if size > self.limits.max_metadata_bytes:
            self.add(
                place,
                f"expected at most {self.limits.max_metadata_bytes} bytes, found {size} bytes "
                "(over the limit)",
            )
            return

        def no_constants(name: str) -> Any:
            raise ValueError(f"{name} is not JSON")

        try:
            meta = json.loads(value, parse_constant=no_constants)
        except (ValueError, RecursionError) as exc:
            self.add(place, f"expected a JSON object, found text that is not JSON ({exc})")
            return
        if not isinstance(meta, dict):
            self.add(place, f"expected a JSON object, found a JSON {type(meta).__name__}")
            return
        self.contents.metadata = meta

    def no_attrs(self, obj: h5py.HLObject, place: str) -> None:
        """Report every attribute of a group or dataset (the schema gives them none)."""
        n = len(obj.attrs)
        if n > MAX_MEMBERS:
            self.add(f"{place}.attrs", f"expected no attributes here, found {n} (not listed)")
            return
        for name in obj.attrs:
            self.add(f"{place}.attrs/{name}", f"expected no attributes here, found {name!r}")

    # ---- the tree ---------------------------------------------------------------------------

    def members(
        self, group: h5py.Group, prefix: str, cap: int = MAX_MEMBERS
    ) -> list[tuple[str, str, type | None]] | None:
        """(name, place, class) of each member of ``group``; reports soft, external and other
        links without dereferencing them (their class is None). None (and a problem) when the
        group has more than ``cap`` members: they are not listed."""
        n = len(group)
        if n > cap:
            self.add(
                prefix.rstrip("/") or "/",
                f"expected at most {cap} members here, found {n} (not read)",
            )
            return None
        out: list[tuple[str, str, type | None]] = []
        for name in list(group):
            place = f"{prefix}{name}"
            cls: type | None = None
            with self.guard(place, "reading a link"):
                link = group.get(name, getlink=True)
                if isinstance(link, h5py.SoftLink):
                    self.add(
                        place,
                        f"expected an object stored in this file, found a soft link to "
                        f"{_show(link.path)} (link; not followed)",
                    )
                elif isinstance(link, h5py.ExternalLink):
                    self.add(
                        place,
                        f"expected an object stored in this file, found an external link to "
                        f"{_show(link.path)} in the file {_show(link.filename)} (not followed)",
                    )
                elif not isinstance(link, h5py.HardLink):
                    self.add(
                        place,
                        f"expected an object stored in this file, found a link of type "
                        f"{type(link).__name__} (not followed)",
                    )
                else:
                    cls = group.get(name, getclass=True)
            out.append((name, place, cls))
        return out

    def tree(self, f: h5py.File) -> None:
        objects: h5py.Group | None = None
        root = self.members(f, "")
        if root is None:
            return
        for name, place, cls in root:
            if name == "objects" and cls is h5py.Group:
                objects = f["objects"]
            elif name == "objects" and cls is not None:
                self.add(place, f"expected a group of objects, found {_kind(cls)}")
            elif cls is not None:
                self.add(
                    place,
                    f"expected only the group 'objects' at the root, found {_kind(cls)} {name!r}",
                )
        if objects is None:
            if "objects" not in [name for name, _, _ in root]:
                self.add("/", "expected a group 'objects', found none")
            return
        self.no_attrs(objects, "objects")
        n = len(objects)
        if n == 0:
            self.add("objects", "expected one group per benchmark object, found an empty group")
        elif n > self.limits.max_objects:
            self.add(
                "objects",
                f"expected at most {self.limits.max_objects} object groups, found {n} "
                "(over the limit; not read)",
            )
            return
        present: list[str] = []
        groups: list[tuple[str, str]] = []
        for name, place, cls in self.members(objects, "objects/", n) or []:
            present.append(name)
            if cls is h5py.Group:
                groups.append((name, place))
            elif cls is not None:
                self.add(place, f"expected one group per object, found {_kind(cls)}")
        if self.object_ids is not None:
            unknown = sorted(set(present) - self.object_ids)
            missing = sorted(self.object_ids - set(present))
            if unknown:
                self.add(
                    "objects",
                    f"expected only the benchmark's {len(self.object_ids)} objects, found "
                    f"{len(unknown)} unknown object id(s): {_names(unknown)}",
                )
            if missing:
                self.add(
                    "objects",
                    f"expected a group for each of the benchmark's {len(self.object_ids)} "
                    f"objects, found {len(missing)} missing: {_names(missing)}",
                )
        for name, place in groups:
            with self.guard(place, "reading an object group"):
                self.object_group(objects[name], name, place)

    def object_group(self, group: h5py.Group, object_id: str, place: str) -> None:
        self.no_attrs(group, place)
        found: dict[str, h5py.Dataset] = {}
        listed = self.members(group, f"{place}/")
        if listed is None:
            return
        for name, child, cls in listed:
            if cls is None:
                continue
            if name in DATASETS and cls is h5py.Dataset:
                found[name] = group[name]
            elif cls is h5py.Group:
                self.add(
                    child,
                    f"expected only the datasets {' and '.join(DATASETS)}, found a nested group",
                )
            else:
                self.add(
                    child,
                    f"expected only the datasets {' and '.join(DATASETS)}, found "
                    f"{_kind(cls)} {name!r}",
                )
        k: int | None = None
        if "poses" in found:
            k = self.header(found["poses"], object_id, "poses", f"{place}/poses", None)
        elif "poses" not in [name for name, _, _ in listed]:
            self.add(place, "expected a dataset 'poses', found none")
        if "scores" in found:
            self.header(found["scores"], object_id, "scores", f"{place}/scores", k)

    def header(
        self, ds: h5py.Dataset, object_id: str, name: str, place: str, k: int | None
    ) -> int | None:
        """Check a dataset's attributes, dtype, shape and storage without reading its values.

        Returns:
            K (the number of dual grasps its shape declares) when the shape is right, else None.
        """
        ok = True
        self.no_attrs(ds, place)
        # dtype
        try:
            dtype: np.dtype | None = ds.dtype
        except Exception as exc:  # an HDF5 type h5py cannot map
            dtype = None
            ok = False
            self.add(
                place, f"expected float32 or float64 values, found an unsupported type ({exc})"
            )
        if dtype is not None:
            found = _describe_dtype(dtype)
            if found is not None:
                ok = False
                self.add(place, f"expected float32 or float64 values, found {found}")
        # shape
        shape = ds.shape
        good_k: int | None = None
        if name == "poses":
            expected = "(K, 2, 4, 4)"
            right = shape is not None and len(shape) == 4 and tuple(shape[1:]) == (2, 4, 4)
        else:
            expected = "(K,)" if k is None else f"({k},), matching the poses' K = {k}"
            right = shape is not None and len(shape) == 1 and (k is None or shape[0] == k)
        if shape is None:
            self.add(place, f"expected shape {expected}, found an empty (null) dataspace")
        elif not right:
            self.add(place, f"expected shape {expected}, found {tuple(shape)}")
        elif name == "poses":
            good_k = int(shape[0])
            limit = self.limits.max_grasps_per_object
            if good_k == 0:
                self.add(place, "expected at least one dual grasp (K >= 1), found K = 0")
                good_k = None
            elif good_k > limit:
                self.add(
                    place,
                    f"expected at most {limit} dual grasps per object, found K = {good_k} "
                    "(over the limit)",
                )
                good_k = None
        ok = ok and right and (name != "poses" or good_k is not None)
        # storage
        if ds.external is not None:
            ok = False
            files = sorted({str(entry[0]) for entry in ds.external})
            self.add(
                place,
                f"expected data stored in this file, found external storage in {_names(files)}",
            )
        if ds.is_virtual:
            ok = False
            self.add(place, "expected data stored in this file, found a virtual dataset")
        compression = None
        plist = ds.id.get_create_plist()
        for index in range(plist.get_nfilters()):
            code, _flags, _values, raw_name = plist.get_filter(index)
            if code not in ALLOWED_FILTERS:
                ok = False
                label = bytes(raw_name).decode("utf-8", "replace")
                self.add(
                    place,
                    f"expected filters among {', '.join(ALLOWED_FILTERS.values())}, found filter "
                    f"{code}{f' ({_show(label)})' if label else ''} (not read: HDF5 would look "
                    "for a plugin)",
                )
            elif code in (1, 4, 6, 32000):
                compression = ALLOWED_FILTERS[code]
        # declared size
        itemsize = dtype.itemsize if dtype is not None else ds.id.get_type().get_size()
        if shape is not None:
            declared = math.prod(shape) * itemsize
            limit = self.limits.max_dataset_bytes
            how = ""
            if compression:
                how = f" ({compression}-compressed, so the file itself can be small)"
            if declared > limit:
                ok = False
                self.add(
                    place,
                    f"expected at most {limit} bytes of data per dataset (uncompressed), found "
                    f"{declared} bytes declared by shape {tuple(shape)}{how}: it would inflate "
                    "past the limit",
                )
            if ds.chunks is not None:
                chunk = math.prod(ds.chunks) * itemsize
                if chunk > limit:
                    ok = False
                    self.add(
                        place,
                        f"expected chunks of at most {limit} bytes, found chunks of {chunk} "
                        f"bytes (shape {tuple(ds.chunks)}){how}: they would inflate past the "
                        "limit",
                    )
        else:
            declared = 0
        if ok:
            self.readable.append(_Dataset(place, ds, object_id, name, declared, compression))
        return good_k

    # ---- values -----------------------------------------------------------------------------

    def values(self) -> None:
        """Read and check the datasets whose headers passed, unless together they are too big."""
        total = sum(d.nbytes for d in self.readable)
        if total > self.limits.max_total_bytes:
            compressed = sorted({d.compression for d in self.readable if d.compression})
            how = f" ({', '.join(compressed)}-compressed)" if compressed else ""
            self.add(
                "/",
                f"expected at most {self.limits.max_total_bytes} bytes of data in all "
                f"(uncompressed), found datasets{how} declaring {total} bytes: they would "
                "inflate past the limit (not read)",
            )
            self.readable = []
            return
        for item in self.readable:
            with self.guard(item.place, "reading its values"):
                data = np.asarray(item.dataset[()], dtype=np.float64)
                check = self.poses_values if item.name == "poses" else self.scores_values
                if check(item.place, data):
                    target = self.contents.poses if item.name == "poses" else self.contents.scores
                    target[item.object_id] = data
        self.readable = []

    def bad_hands(
        self, place: str, mask: np.ndarray, rows: np.ndarray, total: int, message: str
    ) -> bool:
        """Report the (K', 2) ``mask`` of bad hand poses (``rows`` maps to dual-grasp index) out of
        ``total``; True when there are any."""
        bad = np.argwhere(mask)
        if not bad.size:
            return False
        bad[:, 0] = rows[bad[:, 0]]
        self.add(
            f"{place}[{bad[0, 0]}, {bad[0, 1]}]",
            f"{message} in {len(bad)} of {total} hand poses (first: {_indices(bad)})",
        )
        return True

    def poses_values(self, place: str, poses: np.ndarray) -> bool:
        """Check finite, rigid, bounded (K, 2, 4, 4) poses; True when all are."""
        k = len(poses)
        finite = np.isfinite(poses).reshape(k, -1).all(axis=1)
        ok = bool(finite.all())
        if not ok:
            bad = np.flatnonzero(~finite)
            rows = poses[bad]
            kinds = [w for w, m in (("NaN", np.isnan), ("inf", np.isinf)) if m(rows).any()]
            self.add(
                f"{place}[{bad[0]}]",
                f"expected finite values, found {' and '.join(kinds)} in {len(bad)} of {k} "
                f"dual grasps (first: {_indices(bad)})",
            )
        rows = np.flatnonzero(finite)
        checks = hand_pose_faults(poses[rows])
        for mask, message in checks:
            if self.bad_hands(place, mask, rows, 2 * k, message):
                ok = False
        return ok

    def scores_values(self, place: str, scores: np.ndarray) -> bool:
        """Check finite (K,) scores; True when they are."""
        bad = np.flatnonzero(~np.isfinite(scores))
        if not bad.size:
            return True
        kinds = [w for w, m in (("NaN", np.isnan), ("inf", np.isinf)) if m(scores[bad]).any()]
        self.add(
            f"{place}[{bad[0]}]",
            f"expected finite scores, found {' and '.join(kinds)} in {len(bad)} of "
            f"{len(scores)} (first: {_indices(bad)})",
        )
        return False


def _kind(cls: type) -> str:
    if cls is h5py.Dataset:
        return "a dataset"
    if cls is h5py.Group:
        return "a group"
    if cls is h5py.Datatype:
        return "a named datatype"
    return f"an HDF5 {cls.__name__}"


def _validate(
    path: str | os.PathLike[str],
    object_ids: Sequence[str] | None,
    benchmark_sha256: str | None,
    embedded: bool,
    limits: SubmissionLimits,
) -> tuple[list[Problem], _Contents]:
    validator = _Validator(object_ids, benchmark_sha256, embedded, limits)
    validator.run(path)
    return validator.problems, validator.contents


def validate_submission(
    path: str | os.PathLike[str],
    *,
    object_ids: Sequence[str] | None = None,
    benchmark_sha256: str | None = None,
    embedded: bool = True,
    limits: SubmissionLimits = SubmissionLimits(),
) -> list[Problem]:
    """Every problem of a submission file (see the module docstring), each with its place.

    Reads the file only (never modifies it), never follows a soft or external link, never reads
    external or virtual storage, and reads a dataset's values only after its dtype, shape,
    storage and declared size passed. A corrupt or truncated file gives problems, not errors.

    Args:
        path: the submission file.
        object_ids: the benchmark's object ids; None skips the unknown / missing checks.
        benchmark_sha256: sha256 of the benchmark being evaluated; None accepts any.
        embedded: whether the benchmark being evaluated is the embedded one; when False, a
            file made for ``"embedded"`` is a problem.
        limits: size limits.

    Returns:
        The problems, in file order (empty for a valid file).

    Raises:
        SubmissionError: bad arguments (not a problem of the file).
    """
    return _validate(path, object_ids, benchmark_sha256, embedded, limits)[0]


def read_submission(
    path: str | os.PathLike[str],
    *,
    object_ids: Sequence[str] | None = None,
    benchmark_sha256: str | None = None,
    embedded: bool = True,
    limits: SubmissionLimits = SubmissionLimits(),
) -> Submission:
    """Validate and read a submission file (read-only; the values come from the validation pass).

    Args:
        path: the submission file.
        object_ids, benchmark_sha256, embedded, limits: as :func:`validate_submission`.

    Returns:
        The submission: float64 poses (K, 2, 4, 4) and scores (K,), the benchmark attribute, the
        metadata and the file's sha256.

    Raises:
        SubmissionInvalid: the file has problems (its
            :attr:`~dg16m_env.subjects.submission.SubmissionInvalid.problems` lists all).
        SubmissionError: the file changed while it was read.
    """
    problems, contents = _validate(path, object_ids, benchmark_sha256, embedded, limits)
    if problems:
        raise SubmissionInvalid(problems, path)
    try:
        sha256 = file_sha256(path)
        after = os.stat(path)
    except OSError as exc:
        raise SubmissionError(
            f"{path}: expected a file that stays put, found it gone while read ({exc.strerror})"
        ) from None
    before = contents.stat
    same = before is not None and all(
        getattr(before, k) == getattr(after, k)
        for k in ("st_dev", "st_ino", "st_size", "st_mtime_ns")
    )
    if not same:
        raise SubmissionError(
            f"{path}: expected a file that stays put, found it changed while read"
        )
    return Submission(
        poses=contents.poses,
        scores=contents.scores,
        benchmark=contents.benchmark,
        metadata=contents.metadata,
        sha256=sha256,
    )
