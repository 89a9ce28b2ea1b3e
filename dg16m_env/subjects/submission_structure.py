"""What a submission file is made of, checked before any dataset's values are read: stages 2 to 4
of :func:`~dg16m_env.subjects.submission_reader.validate_submission` (see that module for the
stages and their order).

* :class:`RootAttributes`: the root attributes, the dtype and shape of each checked before its
  value is read;
* :class:`TreeWalk`: the tree, one level at a time without dereferencing a link (soft and
  external links are reported, never followed; groups outside the schema are reported, never
  entered), and each dataset's header (:meth:`TreeWalk.header`: dtype, shape, storage, the
  uncompressed size it declares): a dataset that passes is listed for the values stage.

These are security checks against hostile files (external links, virtual datasets, filters that
would load a plugin, compression bombs): each reads only what the previous one vetted. Every
problem goes to a :class:`ProblemLog` with its place; an h5py error becomes a problem at its
place (:meth:`ProblemLog.guard`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import h5py
import numpy as np

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
    SubmissionLimits,
    _describe_dtype,
    _names,
    _show,
)
from dg16m_env.subjects.track import track_name


@dataclass
class ReadableDataset:
    """A dataset whose header passed: read its values in the second pass."""

    place: str
    dataset: h5py.Dataset
    object_id: str
    name: str
    nbytes: int
    compression: str | None


@dataclass
class Contents:
    """What a validation read: the values of the datasets that passed, the root attributes, the
    file's ``os.stat`` before it was opened."""

    poses: dict[str, np.ndarray] = field(default_factory=dict)
    scores: dict[str, np.ndarray] = field(default_factory=dict)
    benchmark: str = ""
    metadata: dict[str, Any] = field(default_factory=dict)
    stat: os.stat_result | None = None


class ProblemLog:
    """The problems of one validation, in the order they were found."""

    def __init__(self) -> None:
        self.problems: list[Problem] = []

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

    def no_attrs(self, obj: h5py.HLObject, place: str) -> None:
        """Report every attribute of a group or dataset (the schema gives them none)."""
        n = len(obj.attrs)
        if n > MAX_MEMBERS:
            self.add(f"{place}.attrs", f"expected no attributes here, found {n} (not listed)")
            return
        for name in obj.attrs:
            self.add(f"{place}.attrs/{name}", f"expected no attributes here, found {name!r}")


def _kind(cls: type) -> str:
    if cls is h5py.Dataset:
        return "a dataset"
    if cls is h5py.Group:
        return "a group"
    if cls is h5py.Datatype:
        return "a named datatype"
    return f"an HDF5 {cls.__name__}"


# ---- attributes -----------------------------------------------------------------------------


class RootAttributes:
    """Checks the root attributes; the benchmark and the metadata go to ``contents``."""

    def __init__(
        self,
        log: ProblemLog,
        limits: SubmissionLimits,
        *,
        embedded: bool,
        benchmark_sha256: str | None,
        contents: Contents,
    ) -> None:
        self.log, self.limits, self.contents = log, limits, contents
        self.embedded, self.benchmark_sha256 = embedded, benchmark_sha256

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

    def check(self, f: h5py.File) -> None:
        """Every root attribute: known names, then each of the schema's."""
        n = len(f.attrs)
        if n > MAX_MEMBERS:
            self.log.add(
                "/",
                f"expected at most {len(ROOT_ATTRS)} root attributes, found {n} (not listed)",
            )
            names = [name for name in ROOT_ATTRS if name in f.attrs]
        else:
            names = list(f.attrs.keys())
        for name in names:
            if name not in ROOT_ATTRS:
                self.log.add(
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
                with self.log.guard(f"attrs/{name}", f"reading the attribute {name!r}"):
                    check(f)
            elif expected:  # metadata is optional
                self.log.add(f"attrs/{name}", f"{expected}, found no {name!r} attribute")

    def format_attr(self, f: h5py.File) -> None:
        value, found = self.string_attr(f, "format")
        if value != FORMAT:
            self.log.add("attrs/format", f"expected {FORMAT!r}, found {found or _show(value)}")

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
            self.log.add(
                place, f"expected the integer {SCHEMA_VERSION}, found {found} (not an integer)"
            )
            return
        version = int(f.attrs["schema_version"])
        if version != SCHEMA_VERSION:
            self.log.add(
                place,
                f"expected schema version {SCHEMA_VERSION}, found {version} "
                "(unsupported by this version of dg16m)",
            )

    def benchmark_attr(self, f: h5py.File) -> None:
        place = "attrs/benchmark"
        expected = f"the benchmark's sha256 (64 lower-case hex digits) or {EMBEDDED!r}"
        value, found = self.string_attr(f, "benchmark")
        if value is None:
            self.log.add(place, f"expected {expected}, found {found}")
            return
        if value == EMBEDDED:
            if not self.embedded:
                self.log.add(
                    place,
                    f"expected the sha256 of the benchmark being evaluated"
                    f"{f' ({self.benchmark_sha256[:12]}...)' if self.benchmark_sha256 else ''}, "
                    f"found {EMBEDDED!r}: the grasps were made for the embedded benchmark, "
                    "which is not the one being evaluated",
                )
        elif not _HEX64.fullmatch(value):
            self.log.add(place, f"expected {expected}, found {_show(value)}")
        elif self.benchmark_sha256 is not None and value != self.benchmark_sha256:
            self.log.add(
                place,
                f"expected the sha256 of the benchmark being evaluated "
                f"({self.benchmark_sha256}), found {value}: made for another benchmark",
            )
        self.contents.benchmark = value

    def metadata_attr(self, f: h5py.File) -> None:
        place = "attrs/metadata"
        value, found = self.string_attr(f, "metadata")
        if value is None:
            self.log.add(place, f"expected a JSON object (a string), found {found}")
            return
        size = len(value.encode("utf-8", "surrogatepass"))
        if size > self.limits.max_metadata_bytes:
            self.log.add(
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
            self.log.add(place, f"expected a JSON object, found text that is not JSON ({exc})")
            return
        if not isinstance(meta, dict):
            self.log.add(place, f"expected a JSON object, found a JSON {type(meta).__name__}")
            return
        try:  # the track it declares (none: the mesh track), dg16m_env.subjects.track
            track_name(meta)
        except ValueError as exc:
            self.log.add(place, str(exc))
            return
        self.contents.metadata = meta


# ---- the tree -------------------------------------------------------------------------------


class TreeWalk:
    """Walks the tree (links not followed) and checks each dataset's header; the datasets that
    pass go to ``readable``."""

    def __init__(
        self,
        log: ProblemLog,
        limits: SubmissionLimits,
        object_ids: set[str] | None,
        readable: list[ReadableDataset],
    ) -> None:
        self.log, self.limits = log, limits
        self.object_ids, self.readable = object_ids, readable

    def members(
        self, group: h5py.Group, prefix: str, cap: int = MAX_MEMBERS
    ) -> list[tuple[str, str, type | None]] | None:
        """(name, place, class) of each member of ``group``; reports soft, external and other
        links without dereferencing them (their class is None). None (and a problem) when the
        group has more than ``cap`` members: they are not listed."""
        n = len(group)
        if n > cap:
            self.log.add(
                prefix.rstrip("/") or "/",
                f"expected at most {cap} members here, found {n} (not read)",
            )
            return None
        out: list[tuple[str, str, type | None]] = []
        for name in list(group):
            place = f"{prefix}{name}"
            cls: type | None = None
            with self.log.guard(place, "reading a link"):
                link = group.get(name, getlink=True)
                if isinstance(link, h5py.SoftLink):
                    self.log.add(
                        place,
                        f"expected an object stored in this file, found a soft link to "
                        f"{_show(link.path)} (link; not followed)",
                    )
                elif isinstance(link, h5py.ExternalLink):
                    self.log.add(
                        place,
                        f"expected an object stored in this file, found an external link to "
                        f"{_show(link.path)} in the file {_show(link.filename)} (not followed)",
                    )
                elif not isinstance(link, h5py.HardLink):
                    self.log.add(
                        place,
                        f"expected an object stored in this file, found a link of type "
                        f"{type(link).__name__} (not followed)",
                    )
                else:
                    cls = group.get(name, getclass=True)
            out.append((name, place, cls))
        return out

    def walk(self, f: h5py.File) -> None:
        """The root's members, then the group ``objects`` and each object's group."""
        objects: h5py.Group | None = None
        root = self.members(f, "")
        if root is None:
            return
        for name, place, cls in root:
            if name == "objects" and cls is h5py.Group:
                objects = f["objects"]
            elif name == "objects" and cls is not None:
                self.log.add(place, f"expected a group of objects, found {_kind(cls)}")
            elif cls is not None:
                self.log.add(
                    place,
                    f"expected only the group 'objects' at the root, found {_kind(cls)} {name!r}",
                )
        if objects is None:
            if "objects" not in [name for name, _, _ in root]:
                self.log.add("/", "expected a group 'objects', found none")
            return
        self.objects(objects)

    def objects(self, objects: h5py.Group) -> None:
        """The group ``objects``: its size, its members against the benchmark's ids, then each
        object's group."""
        self.log.no_attrs(objects, "objects")
        n = len(objects)
        if n == 0:
            self.log.add("objects", "expected one group per benchmark object, found an empty group")
        elif n > self.limits.max_objects:
            self.log.add(
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
                self.log.add(place, f"expected one group per object, found {_kind(cls)}")
        if self.object_ids is not None:
            unknown = sorted(set(present) - self.object_ids)
            missing = sorted(self.object_ids - set(present))
            if unknown:
                self.log.add(
                    "objects",
                    f"expected only the benchmark's {len(self.object_ids)} objects, found "
                    f"{len(unknown)} unknown object id(s): {_names(unknown)}",
                )
            if missing:
                self.log.add(
                    "objects",
                    f"expected a group for each of the benchmark's {len(self.object_ids)} "
                    f"objects, found {len(missing)} missing: {_names(missing)}",
                )
        for name, place in groups:
            with self.log.guard(place, "reading an object group"):
                self.object_group(objects[name], name, place)

    def object_group(self, group: h5py.Group, object_id: str, place: str) -> None:
        self.log.no_attrs(group, place)
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
                self.log.add(
                    child,
                    f"expected only the datasets {' and '.join(DATASETS)}, found a nested group",
                )
            else:
                self.log.add(
                    child,
                    f"expected only the datasets {' and '.join(DATASETS)}, found "
                    f"{_kind(cls)} {name!r}",
                )
        k: int | None = None
        if "poses" in found:
            k = self.header(found["poses"], object_id, "poses", f"{place}/poses", None)
        elif "poses" not in [name for name, _, _ in listed]:
            self.log.add(place, "expected a dataset 'poses', found none")
        if "scores" in found:
            self.header(found["scores"], object_id, "scores", f"{place}/scores", k)

    def header(
        self, ds: h5py.Dataset, object_id: str, name: str, place: str, k: int | None
    ) -> int | None:
        """Check a dataset's attributes, dtype, shape and storage without reading its values;
        list it in ``readable`` when all pass.

        Returns:
            K (the number of dual grasps its shape declares) when the shape is right, else None.
        """
        self.log.no_attrs(ds, place)
        dtype, dtype_ok = _header_dtype(self.log, ds, place)
        shape = ds.shape
        good_k, shape_ok = _header_shape(self.log, self.limits, shape, name, place, k)
        compression, storage_ok = _header_storage(self.log, ds, place)
        declared, size_ok = _header_size(
            self.log, self.limits, ds, shape, dtype, compression, place
        )
        if dtype_ok and shape_ok and storage_ok and size_ok:
            self.readable.append(ReadableDataset(place, ds, object_id, name, declared, compression))
        return good_k


# ---- a dataset's header ---------------------------------------------------------------------


def _header_dtype(log: ProblemLog, ds: h5py.Dataset, place: str) -> tuple[np.dtype | None, bool]:
    """(the dtype or None when h5py cannot map it, whether it is float32 or float64)."""
    try:
        dtype: np.dtype | None = ds.dtype
    except Exception as exc:  # an HDF5 type h5py cannot map
        log.add(place, f"expected float32 or float64 values, found an unsupported type ({exc})")
        return None, False
    found = _describe_dtype(dtype)
    if found is not None:
        log.add(place, f"expected float32 or float64 values, found {found}")
        return dtype, False
    return dtype, True


def _header_shape(
    log: ProblemLog,
    limits: SubmissionLimits,
    shape: tuple[int, ...] | None,
    name: str,
    place: str,
    k: int | None,
) -> tuple[int | None, bool]:
    """(K when the shape of ``poses`` is right and K is within the limits, whether the shape
    passed): ``poses`` (K, 2, 4, 4), ``scores`` (K,) with the poses' K."""
    good_k: int | None = None
    if name == "poses":
        expected = "(K, 2, 4, 4)"
        right = shape is not None and len(shape) == 4 and tuple(shape[1:]) == (2, 4, 4)
    else:
        expected = "(K,)" if k is None else f"({k},), matching the poses' K = {k}"
        right = shape is not None and len(shape) == 1 and (k is None or shape[0] == k)
    if shape is None:
        log.add(place, f"expected shape {expected}, found an empty (null) dataspace")
    elif not right:
        log.add(place, f"expected shape {expected}, found {tuple(shape)}")
    elif name == "poses":
        good_k = int(shape[0])
        limit = limits.max_grasps_per_object
        if good_k == 0:
            log.add(place, "expected at least one dual grasp (K >= 1), found K = 0")
            good_k = None
        elif good_k > limit:
            log.add(
                place,
                f"expected at most {limit} dual grasps per object, found K = {good_k} "
                "(over the limit)",
            )
            good_k = None
    return good_k, right and (name != "poses" or good_k is not None)


def _header_storage(log: ProblemLog, ds: h5py.Dataset, place: str) -> tuple[str | None, bool]:
    """(the compression, whether the data is stored in this file with allowed filters only)."""
    ok = True
    if ds.external is not None:
        ok = False
        files = sorted({str(entry[0]) for entry in ds.external})
        log.add(
            place,
            f"expected data stored in this file, found external storage in {_names(files)}",
        )
    if ds.is_virtual:
        ok = False
        log.add(place, "expected data stored in this file, found a virtual dataset")
    compression = None
    plist = ds.id.get_create_plist()
    for index in range(plist.get_nfilters()):
        code, _flags, _values, raw_name = plist.get_filter(index)
        if code not in ALLOWED_FILTERS:
            ok = False
            label = bytes(raw_name).decode("utf-8", "replace")
            log.add(
                place,
                f"expected filters among {', '.join(ALLOWED_FILTERS.values())}, found filter "
                f"{code}{f' ({_show(label)})' if label else ''} (not read: HDF5 would look "
                "for a plugin)",
            )
        elif code in (1, 4, 6, 32000):
            compression = ALLOWED_FILTERS[code]
    return compression, ok


def _header_size(
    log: ProblemLog,
    limits: SubmissionLimits,
    ds: h5py.Dataset,
    shape: tuple[int, ...] | None,
    dtype: np.dtype | None,
    compression: str | None,
    place: str,
) -> tuple[int, bool]:
    """(the uncompressed bytes the shape declares, whether they and a chunk's are within the
    per-dataset limit): a compressed dataset could inflate far past its size in the file."""
    itemsize = dtype.itemsize if dtype is not None else ds.id.get_type().get_size()
    if shape is None:
        return 0, True
    ok = True
    declared = math.prod(shape) * itemsize
    limit = limits.max_dataset_bytes
    how = ""
    if compression:
        how = f" ({compression}-compressed, so the file itself can be small)"
    if declared > limit:
        ok = False
        log.add(
            place,
            f"expected at most {limit} bytes of data per dataset (uncompressed), found "
            f"{declared} bytes declared by shape {tuple(shape)}{how}: it would inflate "
            "past the limit",
        )
    if ds.chunks is not None:
        chunk = math.prod(ds.chunks) * itemsize
        if chunk > limit:
            ok = False
            log.add(
                place,
                f"expected chunks of at most {limit} bytes, found chunks of {chunk} "
                f"bytes (shape {tuple(ds.chunks)}){how}: they would inflate past the "
                "limit",
            )
    return declared, ok
