"""Tests of dg16m_env.subjects.submission: writing, validating and reading submission files.

Every bad file is built at test time in ``tmp_path`` with h5py directly. Each must be refused by
:func:`read_submission` with the specific problem (place and message), and neither it nor any
file next to it (an existing results file, the target of a link, raw external storage) may
change. The real DG16M file comes from ``../shared/data/real`` (skipped when absent).
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from dataset_gen.io import DualGraspSet, read_dg16m, write_dg16m
from dg16m_core.hashing import file_sha256
from dg16m_env.benchmark.sources import retarget_poses
from dg16m_env.subjects.submission import (
    EMBEDDED,
    FORMAT,
    SCHEMA_VERSION,
    Problem,
    Submission,
    SubmissionError,
    SubmissionInvalid,
    SubmissionLimits,
)
from dg16m_env.subjects.submission_reader import read_submission, validate_submission
from dg16m_env.subjects.submission_writer import submission_from_dg16m, write_submission

IDS = ("mug-1", "table 1000000 (é)")
"""Benchmark object ids of the tests (one with odd characters that HDF5 names allow)."""
SHA = "ab" * 32
"""A benchmark sha256 the tests evaluate against."""
K = 3


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------


def rigid(k: int = K, seed: int = 0) -> np.ndarray:
    """(k, 2, 4, 4) random rigid hand poses within 0.3 m of the origin."""
    rng = np.random.default_rng(seed)
    q, r = np.linalg.qr(rng.normal(size=(k, 2, 3, 3)))
    q = q * np.sign(np.diagonal(r, axis1=-2, axis2=-1))[..., None, :]
    q[np.linalg.det(q) < 0, :, 0] *= -1.0
    T = np.zeros((k, 2, 4, 4))
    T[..., :3, :3] = q
    T[..., :3, 3] = rng.uniform(-0.3, 0.3, size=(k, 2, 3))
    T[..., 3, 3] = 1.0
    return T


def write_raw(
    path: Path,
    *,
    attrs: dict[str, Any] | None = None,
    drop: tuple[str, ...] = (),
    objects: dict[str, dict[str, Any]] | None = None,
    edit: Callable[[h5py.File], None] | None = None,
) -> Path:
    """A submission written with plain h5py: valid unless changed by the arguments.

    Args:
        path: the file.
        attrs: root attributes to set (over the valid ones).
        drop: root attributes to leave out.
        objects: object id -> {dataset name -> array}; default: valid poses and scores for IDS.
        edit: called with the open file last, for anything else.
    """
    root = {"format": FORMAT, "schema_version": SCHEMA_VERSION, "benchmark": SHA}
    root.update(attrs or {})
    if objects is None:
        objects = {
            i: {"poses": rigid(seed=n), "scores": np.arange(K, dtype=float)}
            for n, i in enumerate(IDS)
        }
    with h5py.File(path, "w") as f:
        for name, value in root.items():
            if name not in drop:
                f.attrs[name] = value
        group = f.create_group("objects")
        for object_id, datasets in objects.items():
            g = group.create_group(object_id)
            for name, value in datasets.items():
                g.create_dataset(name, data=value)
        if edit is not None:
            edit(f)
    return path


def with_poses(poses: Any = None, scores: Any = None, **kwargs: Any) -> dict[str, Any]:
    """write_raw arguments whose first object gets ``poses`` (and ``scores``) instead."""
    first: dict[str, Any] = {"poses": rigid() if poses is None else poses}
    if scores is not None:
        first["scores"] = scores
    return {"objects": {IDS[0]: first, IDS[1]: {"poses": rigid(seed=1)}}, **kwargs}


def edited(poses_edit: Callable[[np.ndarray], Any]) -> dict[str, Any]:
    """write_raw arguments whose first object's valid poses went through ``poses_edit``."""
    poses = rigid()
    out = poses_edit(poses)
    return with_poses(poses if out is None else out)


def snapshot(folder: Path) -> dict[str, str]:
    """Relative path -> sha256 of every file under ``folder``."""
    return {
        str(p.relative_to(folder)): file_sha256(p) for p in sorted(folder.rglob("*")) if p.is_file()
    }


# --------------------------------------------------------------------------------------------
# Round trip
# --------------------------------------------------------------------------------------------


def test_round_trip(tmp_path: Path) -> None:
    poses = {IDS[0]: rigid(seed=0), IDS[1]: rigid(k=5, seed=1).astype(np.float32)}
    scores = {IDS[0]: np.array([0.5, -1.0, 2.0])}
    meta = {"method": "test", "team": "dg16m", "notes": ["ünïcode", 1, 2.5]}
    path = write_submission(tmp_path / "sub.h5", poses, scores=scores, benchmark=SHA, metadata=meta)
    assert validate_submission(path, object_ids=IDS, benchmark_sha256=SHA, embedded=False) == []
    before = file_sha256(path)
    sub = read_submission(path, object_ids=list(IDS), benchmark_sha256=SHA, embedded=False)
    assert isinstance(sub, Submission)
    assert sub.object_ids == sorted(IDS)
    for object_id, value in poses.items():
        assert sub.poses[object_id].dtype == np.float64
        np.testing.assert_array_equal(sub.poses[object_id], value.astype(np.float64))
    assert sub.scores.keys() == scores.keys()
    np.testing.assert_array_equal(sub.scores[IDS[0]], scores[IDS[0]])
    assert sub.metadata == meta
    assert sub.benchmark == SHA
    assert sub.sha256 == before == file_sha256(path)
    assert sub.n_grasps == 8
    assert "2 objects, 8 dual grasps, 1 scored" in repr(sub)


def test_round_trip_embedded_without_object_ids(tmp_path: Path) -> None:
    path = write_submission(tmp_path / "sub.h5", {"x": rigid()})
    sub = read_submission(path)
    assert sub.benchmark == EMBEDDED
    assert sub.metadata == {}
    assert sub.scores == {}
    # "embedded" is fine whatever the sha256, as long as the evaluated benchmark is the embedded one
    assert validate_submission(path, benchmark_sha256=SHA, embedded=True) == []


def test_float32_and_round_off_poses_are_valid(tmp_path: Path) -> None:
    poses = rigid(k=50, seed=3).astype(np.float32)
    path = write_raw(tmp_path / "sub.h5", **with_poses(poses))
    sub = read_submission(path, object_ids=IDS)
    np.testing.assert_array_equal(sub.poses[IDS[0]], poses.astype(np.float64))


def test_hard_link_duplicate_is_valid(tmp_path: Path) -> None:
    """A hard link is an ordinary HDF5 name: two ids sharing one group mean two equal copies
    (read, and counted against the size limits, once per name)."""

    def link(f: h5py.File) -> None:
        f["objects"][IDS[1]] = f["objects"][IDS[0]]

    path = write_raw(tmp_path / "sub.h5", objects={IDS[0]: {"poses": rigid()}}, edit=link)
    sub = read_submission(path, object_ids=IDS)
    np.testing.assert_array_equal(sub.poses[IDS[0]], sub.poses[IDS[1]])
    # counted twice: 2 x 768 bytes over a 1000-byte total
    problems = validate_submission(path, limits=SubmissionLimits(max_total_bytes=1000))
    assert [p.place for p in problems] == ["/"]


def test_write_submission_refuses_bad_arguments(tmp_path: Path) -> None:
    with pytest.raises(SubmissionError, match="benchmark: expected a sha256"):
        write_submission(tmp_path / "a.h5", {"x": rigid()}, benchmark="ABC")
    with pytest.raises(SubmissionError, match="expected object ids that are HDF5 names"):
        write_submission(tmp_path / "a.h5", {"a/b": rigid()})
    with pytest.raises(SubmissionError, match=r"objects/x/poses: expected shape \(K, 2, 4, 4\)"):
        write_submission(tmp_path / "a.h5", {"x": np.zeros((3, 4, 4))})
    with pytest.raises(SubmissionError, match=r"objects/x/scores: expected shape \(3,\)"):
        write_submission(tmp_path / "a.h5", {"x": rigid()}, scores={"x": np.zeros(2)})
    with pytest.raises(SubmissionError, match="metadata: expected a JSON object"):
        write_submission(tmp_path / "a.h5", {"x": rigid()}, metadata={"x": float("nan")})
    assert not list(tmp_path.iterdir())


# --------------------------------------------------------------------------------------------
# The corpus of bad submissions
# --------------------------------------------------------------------------------------------


@dataclass
class Bad:
    """One kind of bad submission.

    Attributes:
        build: writes the bad file at the given path (the folder may hold helper files).
        place: substring of the expected problem's place.
        message: substring of its message.
        kwargs: read_submission arguments beyond ``object_ids=IDS, benchmark_sha256=SHA``.
    """

    build: Callable[[Path], Any]
    place: str
    message: str
    kwargs: dict[str, Any] = field(default_factory=dict)


def _text(path: Path) -> None:
    path.write_text("format,poses\nnot,hdf5\n")


def _truncated(path: Path) -> None:
    write_raw(path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _oversized(path: Path) -> None:
    write_raw(path)


def _other_file(path: Path, name: str) -> Path:
    other = path.parent / name
    with h5py.File(other, "w") as f:
        f.create_dataset("poses", data=rigid())
        f.create_group("g").create_dataset("poses", data=rigid())
    return other


def _soft_link(f: h5py.File) -> None:
    g = f["objects"][IDS[0]]
    del g["poses"]
    g["poses"] = h5py.SoftLink(f"/objects/{IDS[1]}/poses")


def _external_link(path: Path) -> None:
    other = _other_file(path, "other.h5")

    def edit(f: h5py.File) -> None:
        del f["objects"][IDS[1]]
        f["objects"][IDS[1]] = h5py.ExternalLink(str(other), "/g")

    write_raw(path, edit=edit)


def _external_storage(path: Path) -> None:
    raw = path.parent / "raw.bin"
    raw.write_bytes(rigid().tobytes())

    def edit(f: h5py.File) -> None:
        g = f["objects"][IDS[0]]
        del g["poses"]
        g.create_dataset("poses", (K, 2, 4, 4), "<f8", external=[(str(raw), 0, raw.stat().st_size)])

    write_raw(path, edit=edit)


def _virtual(path: Path) -> None:
    other = _other_file(path, "source.h5")

    def edit(f: h5py.File) -> None:
        layout = h5py.VirtualLayout(shape=(K, 2, 4, 4), dtype="f8")
        layout[:] = h5py.VirtualSource(str(other), "poses", shape=(K, 2, 4, 4))
        g = f["objects"][IDS[0]]
        del g["poses"]
        g.create_virtual_dataset("poses", layout)

    write_raw(path, edit=edit)


def _typed(dtype: Any, data: Any = None) -> Callable[[Path], None]:
    """A first object whose poses have ``dtype`` (shape (K, 2, 4, 4) unless data is given)."""

    def build(path: Path) -> None:
        def edit(f: h5py.File) -> None:
            g = f["objects"][IDS[0]]
            del g["poses"]
            if data is None:
                g.create_dataset("poses", (K, 2, 4, 4), dtype=dtype)
            else:
                g.create_dataset("poses", data=data, dtype=dtype)

        write_raw(path, edit=edit)

    return build


def _vlen(path: Path) -> None:
    def edit(f: h5py.File) -> None:
        g = f["objects"][IDS[0]]
        del g["poses"]
        ds = g.create_dataset("poses", (K,), dtype=h5py.vlen_dtype(np.float64))
        ds[0] = np.arange(32.0)

    write_raw(path, edit=edit)


def _unknown_filter(path: Path) -> None:
    def edit(f: h5py.File) -> None:
        g = f["objects"][IDS[0]]
        del g["poses"]
        shape = (K, 2, 4, 4)
        g.create_dataset(
            "poses", shape, "f8", chunks=shape, compression=32015, allow_unknown_filter=True
        )

    write_raw(path, edit=edit)


def _junk(f: h5py.File) -> None:
    g = f["objects"][IDS[0]]
    for i in range(20):
        g.create_group(f"junk{i}")
        g.attrs[f"a{i}"] = i


def _compressed_bomb(path: Path) -> None:
    def edit(f: h5py.File) -> None:
        g = f["objects"][IDS[0]]
        del g["poses"], g["scores"]
        g.create_dataset("poses", data=np.zeros((100, 2, 4, 4)), compression="gzip")

    write_raw(path, edit=edit)


def _big_chunks(path: Path) -> None:
    def edit(f: h5py.File) -> None:
        g = f["objects"][IDS[0]]
        del g["poses"]
        g.create_dataset("poses", data=rigid(), maxshape=(None, 2, 4, 4), chunks=(1000, 2, 4, 4))

    write_raw(path, edit=edit)


def _scaled(T: np.ndarray) -> None:
    T[1, 0, :3, :3] *= 1.01


def _reflected(T: np.ndarray) -> None:
    T[2, 1, :3, 0] *= -1.0


def _bottom_row(T: np.ndarray) -> None:
    T[0, 1, 3, 0] = 1e-3


def _far(T: np.ndarray) -> None:
    T[1, 1, :3, 3] = [0.0, 20.0, 0.0]


def _nan(T: np.ndarray) -> None:
    T[1, 0, 0, 3] = np.nan


def _inf(T: np.ndarray) -> None:
    T[2, 1, 2, 2] = -np.inf


def _raw(**kwargs: Any) -> Callable[[Path], Path]:
    return lambda path: write_raw(path, **kwargs)


def _add(make: Callable[[h5py.File], Any]) -> Callable[[Path], Path]:
    """A valid file, then ``make(f)``."""
    return _raw(edit=make)


def _corrupt(path: Path) -> None:
    """A group's symbol-table node overwritten: HDF5 opens the file, then fails inside it."""
    write_raw(path)
    data = bytearray(path.read_bytes())
    at = data.rfind(b"SNOD")
    assert at > 0
    data[at : at + 4] = b"XXXX"
    path.write_bytes(bytes(data))


POSES = f"objects/{IDS[0]}/poses"
SCORES = f"objects/{IDS[0]}/scores"
SMALL = SubmissionLimits

CORPUS: dict[str, Bad] = {
    # the file itself
    "text_file": Bad(_text, "file", "without the HDF5 signature"),
    "empty_file": Bad(lambda p: p.write_bytes(b""), "file", "empty file"),
    "truncated_hdf5": Bad(_truncated, "file", "truncated or corrupt"),
    "missing_file": Bad(lambda p: None, "file", "found nothing there"),
    "directory": Bad(lambda p: p.mkdir(), "file", "found a directory"),
    "oversized_file": Bad(
        _oversized, "file", "over the limit; not opened", {"limits": SMALL(max_file_bytes=1000)}
    ),
    "corrupt_inside": Bad(_corrupt, "", "corrupt or truncated?"),
    # root attributes
    "wrong_format": Bad(
        _raw(attrs={"format": "dg16m-benchmark"}), "attrs/format", "found 'dg16m-benchmark'"
    ),
    "missing_format": Bad(_raw(drop=("format",)), "attrs/format", "no 'format' attribute"),
    "missing_schema_version": Bad(
        _raw(drop=("schema_version",)), "attrs/schema_version", "no 'schema_version' attribute"
    ),
    "schema_version_2": Bad(
        _raw(attrs={"schema_version": 2}), "attrs/schema_version", "found 2 (unsupported"
    ),
    "schema_version_float": Bad(
        _raw(attrs={"schema_version": 1.0}), "attrs/schema_version", "(not an integer)"
    ),
    "schema_version_string": Bad(
        _raw(attrs={"schema_version": "1"}), "attrs/schema_version", "strings (not an integer)"
    ),
    "missing_benchmark": Bad(
        _raw(drop=("benchmark",)), "attrs/benchmark", "no 'benchmark' attribute"
    ),
    "benchmark_not_hex": Bad(
        _raw(attrs={"benchmark": "my-benchmark"}), "attrs/benchmark", "found 'my-benchmark'"
    ),
    "benchmark_upper_case_hex": Bad(
        _raw(attrs={"benchmark": SHA.upper()}), "attrs/benchmark", "64 lower-case hex digits"
    ),
    "benchmark_not_string": Bad(
        _raw(attrs={"benchmark": 7}), "attrs/benchmark", "integers (int64) (not a string)"
    ),
    "other_benchmark": Bad(
        _raw(attrs={"benchmark": "cd" * 32}), "attrs/benchmark", "made for another benchmark"
    ),
    "embedded_for_other_benchmark": Bad(
        _raw(attrs={"benchmark": EMBEDDED}),
        "attrs/benchmark",
        "embedded benchmark, which is not the one being evaluated",
        {"embedded": False},
    ),
    "metadata_not_json": Bad(
        _raw(attrs={"metadata": "{method: x"}), "attrs/metadata", "text that is not JSON"
    ),
    "metadata_nan": Bad(
        _raw(attrs={"metadata": '{"x": NaN}'}), "attrs/metadata", "(NaN is not JSON)"
    ),
    "metadata_not_object": Bad(
        _raw(attrs={"metadata": "[1, 2]"}), "attrs/metadata", "found a JSON list"
    ),
    "metadata_not_string": Bad(
        _raw(attrs={"metadata": np.arange(3)}), "attrs/metadata", "(not a string)"
    ),
    "metadata_too_big": Bad(
        _raw(attrs={"metadata": '{"notes": "' + "x" * 200 + '"}'}),
        "attrs/metadata",
        "over the limit",
        {"limits": SMALL(max_metadata_bytes=100)},
    ),
    "metadata_too_deep": Bad(
        _raw(attrs={"metadata": "[" * 20000 + "]" * 20000}), "attrs/metadata", "recursion"
    ),
    "unknown_root_attr": Bad(
        _raw(attrs={"pickle": np.void(b"\x80\x04")}), "attrs/pickle", "unknown attribute"
    ),
    # the tree
    "extra_root_dataset": Bad(
        _add(lambda f: f.create_dataset("extra", data=np.zeros(3))),
        "extra",
        "expected only the group 'objects' at the root, found a dataset",
    ),
    "extra_root_group": Bad(_add(lambda f: f.create_group("more")), "more", "found a group 'more'"),
    "no_objects_group": Bad(
        _add(lambda f: f.__delitem__("objects")), "/", "expected a group 'objects'"
    ),
    "objects_is_dataset": Bad(
        _add(lambda f: (f.__delitem__("objects"), f.create_dataset("objects", data=1))),
        "objects",
        "expected a group of objects, found a dataset",
    ),
    "empty_objects": Bad(_raw(objects={}), "objects", "found an empty group"),
    "missing_object": Bad(
        _raw(objects={IDS[0]: {"poses": rigid()}}), "objects", f"1 missing: {IDS[1]!r}"
    ),
    "unknown_object": Bad(
        _add(lambda f: f["objects"].create_group("chair-9").create_dataset("poses", data=rigid())),
        "objects",
        "1 unknown object id(s): 'chair-9'",
    ),
    "too_many_objects": Bad(
        _raw(), "objects", "at most 1 object groups, found 2", {"limits": SMALL(max_objects=1)}
    ),
    "object_is_dataset": Bad(
        _add(
            lambda f: (
                f["objects"].__delitem__(IDS[1]),
                f["objects"].create_dataset(IDS[1], data=rigid()),
            )
        ),
        f"objects/{IDS[1]}",
        "expected one group per object, found a dataset",
    ),
    "no_poses": Bad(
        _raw(objects={IDS[0]: {"scores": np.zeros(K)}, IDS[1]: {"poses": rigid()}}),
        f"objects/{IDS[0]}",
        "expected a dataset 'poses', found none",
    ),
    "extra_dataset_in_object": Bad(
        _add(lambda f: f["objects"][IDS[0]].create_dataset("widths", data=np.ones(K))),
        f"objects/{IDS[0]}/widths",
        "found a dataset 'widths'",
    ),
    "nested_group": Bad(
        _add(lambda f: f["objects"][IDS[0]].create_group("more")),
        f"objects/{IDS[0]}/more",
        "found a nested group",
    ),
    "hard_link_cycle": Bad(
        _add(lambda f: f["objects"][IDS[0]].__setitem__("loop", f["/"])),
        f"objects/{IDS[0]}/loop",
        "found a nested group",
    ),
    "soft_link": Bad(_add(_soft_link), POSES, "found a soft link"),
    "dangling_soft_link": Bad(
        _raw(
            **with_poses(
                edit=lambda f: f[POSES.rsplit("/", 1)[0]].__setitem__(
                    "scores", h5py.SoftLink("/nowhere")
                )
            )
        ),
        SCORES,
        "soft link to '/nowhere'",
    ),
    "external_link": Bad(_external_link, f"objects/{IDS[1]}", "external link to '/g'"),
    "named_datatype": Bad(
        _add(lambda f: f["objects"][IDS[0]].__setitem__("type", np.dtype("f8"))),
        f"objects/{IDS[0]}/type",
        "found a named datatype",
    ),
    "many_members": Bad(
        _add(_junk), f"objects/{IDS[0]}", "at most 16 members here, found 22 (not read)"
    ),
    "many_attributes": Bad(
        _add(_junk), f"objects/{IDS[0]}.attrs", "expected no attributes here, found 20"
    ),
    "many_root_attributes": Bad(
        _add(lambda f: [f.attrs.__setitem__(f"x{i}", i) for i in range(20)]),
        "/",
        "found 23 (not listed)",
    ),
    "dataset_attribute": Bad(
        _add(lambda f: f["objects"][IDS[0]]["poses"].attrs.__setitem__("units", "mm")),
        f"{POSES}.attrs/units",
        "expected no attributes",
    ),
    # dataset headers
    "external_storage": Bad(_external_storage, POSES, "external storage in"),
    "virtual_dataset": Bad(_virtual, POSES, "found a virtual dataset"),
    "vlen_dtype": Bad(_vlen, POSES, "variable-length sequences (an object dtype)"),
    "string_dtype": Bad(
        _typed(h5py.string_dtype(), np.array(["a", "b", "c"], dtype=object)),
        POSES,
        "found variable-length strings",
    ),
    "fixed_string_dtype": Bad(_typed("S8"), POSES, "found fixed-length strings"),
    "integer_dtype": Bad(_typed("i8"), POSES, "found integers (int64)"),
    "bool_dtype": Bad(_typed("?"), POSES, "found booleans"),
    "float16_dtype": Bad(_typed("f2"), POSES, "found float16 (half precision)"),
    "longdouble_dtype": Bad(_typed(np.longdouble), POSES, "extended precision"),
    "complex_dtype": Bad(_typed("c16"), POSES, "found complex numbers"),
    "compound_dtype": Bad(
        _typed(np.dtype([("t", "f8", (3,)), ("q", "f8", (4,))]), None),
        POSES,
        "a compound datatype (fields t, q)",
    ),
    "opaque_dtype": Bad(_typed(np.dtype("V16")), POSES, "opaque data"),
    "wrong_poses_shape": Bad(
        _raw(**with_poses(np.tile(np.eye(4), (K, 1, 1)))),
        POSES,
        "expected shape (K, 2, 4, 4), found (3, 4, 4)",
    ),
    "scalar_poses": Bad(_raw(**with_poses(np.float64(1.0))), POSES, "found ()"),
    "null_dataspace_poses": Bad(
        _raw(**with_poses(h5py.Empty("f8"))), POSES, "an empty (null) dataspace"
    ),
    "zero_grasps": Bad(_raw(**with_poses(np.zeros((0, 2, 4, 4)))), POSES, "found K = 0"),
    "too_many_grasps": Bad(
        _raw(),
        POSES,
        "at most 2 dual grasps per object, found K = 3 (over the limit)",
        {"limits": SMALL(max_grasps_per_object=2)},
    ),
    "scores_shape_mismatch": Bad(
        _raw(**with_poses(scores=np.zeros(K + 1))), SCORES, "matching the poses' K = 3, found (4,)"
    ),
    "scores_2d": Bad(_raw(**with_poses(scores=np.zeros((K, 1)))), SCORES, "found (3, 1)"),
    "scores_integer": Bad(
        _raw(**with_poses(scores=np.arange(K))), SCORES, "found integers (int64)"
    ),
    "unknown_filter": Bad(_unknown_filter, POSES, "found filter 32015"),
    "compressed_bomb": Bad(
        _compressed_bomb,
        POSES,
        "25600 bytes declared by shape (100, 2, 4, 4) (gzip-compressed, so the file itself can "
        "be small): it would inflate past the limit",
        {"limits": SMALL(max_dataset_bytes=4096)},
    ),
    "huge_chunks": Bad(
        _big_chunks, POSES, "chunks of 256000 bytes", {"limits": SMALL(max_dataset_bytes=65536)}
    ),
    "total_over_limit": Bad(
        _raw(),
        "/",
        "declaring 1584 bytes: they would inflate past the limit",
        {"limits": SMALL(max_total_bytes=1000)},
    ),
    # values
    "nan_poses": Bad(_raw(**edited(_nan)), f"{POSES}[1]", "expected finite values, found NaN in 1"),
    "inf_poses": Bad(_raw(**edited(_inf)), f"{POSES}[2]", "expected finite values, found inf in 1"),
    "scaled_rotation": Bad(_raw(**edited(_scaled)), f"{POSES}[1, 0]", "scaled or sheared"),
    "reflection": Bad(_raw(**edited(_reflected)), f"{POSES}[2, 1]", "a reflection (det R < 0)"),
    "bad_bottom_row": Bad(_raw(**edited(_bottom_row)), f"{POSES}[0, 1]", "bottom row [0, 0, 0, 1]"),
    "huge_translation": Bad(_raw(**edited(_far)), f"{POSES}[1, 1]", "sanity bound"),
    "zero_poses": Bad(_raw(**with_poses(np.zeros((K, 2, 4, 4)))), f"{POSES}[0, 0]", "in 6 of 6"),
    "nan_scores": Bad(
        _raw(**with_poses(scores=np.array([0.0, np.nan, 1.0]))),
        f"{SCORES}[1]",
        "expected finite scores, found NaN",
    ),
    "inf_scores": Bad(
        _raw(**with_poses(scores=np.array([0.0, 1.0, np.inf]))), f"{SCORES}[2]", "found inf"
    ),
}


@pytest.mark.parametrize("kind", sorted(CORPUS))
def test_bad_submission_is_refused(tmp_path: Path, kind: str) -> None:
    bad = CORPUS[kind]
    path = tmp_path / "sub.h5"
    (tmp_path / "results.json").write_text('{"score": 1}')  # an existing output next to it
    bad.build(path)
    before = snapshot(tmp_path)
    kwargs = {"object_ids": IDS, "benchmark_sha256": SHA, **bad.kwargs}
    with pytest.raises(SubmissionInvalid) as info:
        read_submission(path, **kwargs)
    problems = info.value.problems
    hits = [p for p in problems if bad.place in p.place and bad.message in p.message]
    assert hits, f"no problem at {bad.place!r} with {bad.message!r} in {problems}"
    assert str(hits[0]) in str(info.value) or len(problems) > 20
    assert validate_submission(path, **kwargs) == problems  # the same, every time
    assert snapshot(tmp_path) == before  # nothing written, created or changed


def test_corpus_is_large() -> None:
    assert len(CORPUS) >= 24
    assert len({(b.place, b.message) for b in CORPUS.values()}) == len(CORPUS)


def test_every_problem_is_reported(tmp_path: Path) -> None:
    """Three objects with a different problem each, plus a bad attribute: four problems."""
    far = rigid()
    far[0, 1, :3, 3] = 50.0
    objects = {
        "a": {"poses": np.zeros((0, 2, 4, 4))},
        "b": {"poses": rigid().astype(np.float16)},
        "c": {"poses": far},
    }
    path = write_raw(tmp_path / "sub.h5", objects=objects, attrs={"benchmark": "nope"})
    problems = validate_submission(path, object_ids=["a", "b", "c"])
    assert [p.place for p in problems] == [
        "attrs/benchmark",
        "objects/a/poses",
        "objects/b/poses",
        "objects/c/poses[0, 1]",
    ]
    assert "K = 0" in problems[1].message
    assert "float16" in problems[2].message
    assert "sanity bound" in problems[3].message


def test_bad_values_name_the_first_few(tmp_path: Path) -> None:
    poses = rigid(k=10)
    poses[[2, 5, 7, 9], 1, :3, :3] *= 2.0
    path = write_raw(tmp_path / "sub.h5", objects={"x": {"poses": poses}})
    (problem,) = validate_submission(path)
    assert problem.place == "objects/x/poses[2, 1]"
    assert "in 4 of 20 hand poses (first: [2, 1], [5, 1], [7, 1])" in problem.message


def test_values_are_not_read_when_headers_fail(tmp_path: Path, monkeypatch: Any) -> None:
    """A dataset over the limit (or any header problem) is never read."""
    reads: list[str] = []
    original = h5py.Dataset.__getitem__

    def spy(self: h5py.Dataset, key: Any) -> Any:
        reads.append(self.name)
        return original(self, key)

    monkeypatch.setattr(h5py.Dataset, "__getitem__", spy)
    path = tmp_path / "sub.h5"
    _compressed_bomb(path)
    problems = validate_submission(path, limits=SubmissionLimits(max_dataset_bytes=4096))
    assert {p.place for p in problems} == {POSES}  # declared size and chunk size
    assert f"/{POSES}" not in reads
    assert reads == [f"/objects/{IDS[1]}/poses", f"/objects/{IDS[1]}/scores"]
    reads.clear()
    validate_submission(path, limits=SubmissionLimits(max_total_bytes=1000))
    assert reads == []  # over the total: nothing is read at all


def test_submission_invalid_message_and_pickle(tmp_path: Path) -> None:
    problems = [Problem(f"objects/o{i}/poses", "expected this, found that") for i in range(25)]
    exc = SubmissionInvalid(problems, tmp_path / "x.h5")
    text = str(exc)
    assert "found 25 problem(s)" in text
    assert "objects/o19/poses: expected this, found that" in text
    assert "objects/o20/poses" not in text
    assert "... and 5 more" in text
    assert isinstance(exc, SubmissionError)
    assert isinstance(exc, ValueError)
    again = pickle.loads(pickle.dumps(exc))
    assert again.problems == problems
    assert str(again) == text
    assert str(Problem("/", "m")) == "/: m"


@pytest.mark.parametrize(
    "change",
    [
        {"max_grasps_per_object": 0},
        {"max_file_bytes": -1},
        {"max_objects": True},
        {"max_total_bytes": 1.5},
        {"max_metadata_bytes": "10"},
    ],
)
def test_limits_validate_their_fields(change: dict[str, Any]) -> None:
    name = next(iter(change))
    with pytest.raises(SubmissionError, match=f"SubmissionLimits.{name}: expected a positive"):
        SubmissionLimits(**change)


def test_limits_defaults() -> None:
    limits = SubmissionLimits()
    assert limits.max_grasps_per_object == 100
    assert limits.max_file_bytes == 256 << 20
    assert limits.max_metadata_bytes == 65536
    assert limits.max_objects == 10000
    assert limits.max_dataset_bytes <= limits.max_total_bytes


def test_validate_refuses_bad_arguments(tmp_path: Path) -> None:
    path = write_submission(tmp_path / "s.h5", {"x": rigid()})
    with pytest.raises(SubmissionError, match="object_ids: expected a sequence"):
        validate_submission(path, object_ids="x")
    with pytest.raises(SubmissionError, match="benchmark_sha256: expected"):
        validate_submission(path, benchmark_sha256="xyz")
    with pytest.raises(SubmissionError, match="limits: expected a SubmissionLimits"):
        validate_submission(path, limits={"max_objects": 3})  # type: ignore[arg-type]


def test_read_only_file_is_read(tmp_path: Path) -> None:
    path = write_submission(tmp_path / "s.h5", {"x": rigid()})
    os.chmod(path, 0o444)
    try:
        assert read_submission(path).sha256 == file_sha256(path)
    finally:
        os.chmod(path, 0o644)


# --------------------------------------------------------------------------------------------
# From DG16M files
# --------------------------------------------------------------------------------------------


def _dg16m_set(n: int, n_pass: int, seed: int = 0) -> DualGraspSet:
    rng = np.random.default_rng(seed)
    loss = np.concatenate([rng.uniform(0, 1e-6, n_pass), rng.uniform(0.5, 5.0, n - n_pass)])
    return DualGraspSet(
        grasps=rigid(k=n, seed=seed),
        contact_points=rng.normal(size=(n, 4, 3)),
        contact_forces=rng.normal(size=(n, 4, 3)),
        loss_values=loss,
        passing_indices=np.arange(n_pass),
        failed_indices=np.arange(n_pass, n),
        object_file="thing.obj",
        object_scale=1.0,
        metadata={"gripper": "panda"},
    )


def _rows_of(poses: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """For each (2, 4, 4) of ``poses``, its index in ``candidates`` (N, 2, 4, 4)."""
    dist = np.abs(poses[:, None] - candidates[None]).reshape(len(poses), len(candidates), -1)
    rows = dist.max(axis=-1).argmin(axis=1)
    np.testing.assert_allclose(candidates[rows], poses, atol=1e-12)
    return rows


def test_submission_from_small_dg16m_files(tmp_path: Path) -> None:
    write_dg16m(tmp_path / "few.h5", _dg16m_set(12, n_pass=2, seed=0))
    write_dg16m(tmp_path / "many.h5", _dg16m_set(30, n_pass=20, seed=1))
    poses, scores = submission_from_dg16m(tmp_path, ["few", "many"], k=5, seed=3)
    assert list(poses) == ["few", "many"]
    few = read_dg16m(tmp_path / "few.h5")
    many = read_dg16m(tmp_path / "many.h5")
    # "few": both passing pairs, topped up with 3 failing; the file's gripper is the Panda's
    rows = _rows_of(poses["few"], few.grasps)
    assert rows.shape == (5,)
    assert set(rows[:2]) == {0, 1}
    assert all(r >= 2 for r in rows[2:])
    np.testing.assert_array_equal(scores["few"], -few.loss_values[rows])
    # "many": 5 passing pairs only, higher scores than any failing pair
    rows = _rows_of(poses["many"], many.grasps)
    assert len(set(rows)) == 5
    assert all(r < 20 for r in rows)
    np.testing.assert_array_equal(scores["many"], -many.loss_values[rows])
    # seeded: the same again, another draw with another seed
    again, _ = submission_from_dg16m(
        [tmp_path / "few.h5", tmp_path / "many.h5"], ["many"], k=5, seed=3
    )
    np.testing.assert_array_equal(again["many"], poses["many"])
    other, _ = submission_from_dg16m(tmp_path, ["many"], k=5, seed=4)
    assert not np.array_equal(other["many"], poses["many"])
    # a valid submission
    path = write_submission(tmp_path / "out" / "sub.h5", poses, scores=scores)
    sub = read_submission(path, object_ids=["few", "many"])
    np.testing.assert_array_equal(sub.scores["many"], scores["many"])


def test_submission_from_dg16m_errors(tmp_path: Path) -> None:
    write_dg16m(tmp_path / "a.h5", _dg16m_set(4, n_pass=2))
    with pytest.raises(SubmissionError, match="ghost: expected a DG16M grasp file at"):
        submission_from_dg16m(tmp_path, ["a", "ghost"])
    with pytest.raises(SubmissionError, match="ghost: expected a DG16M grasp file"):
        submission_from_dg16m([tmp_path / "a.h5"], ["ghost"])
    with pytest.raises(SubmissionError, match="k: expected a positive integer"):
        submission_from_dg16m(tmp_path, ["a"], k=0)
    with pytest.raises(SubmissionError, match="expected distinct ids"):
        submission_from_dg16m(tmp_path, ["a", "a"])
    with pytest.raises(SubmissionError, match="one file per object id"):
        submission_from_dg16m([tmp_path / "a.h5", tmp_path / "x" / "a.h5"], ["a"])


def test_submission_from_real_dg16m(real_data: Path, tmp_path: Path) -> None:
    file = real_data / "dg16m_airplane.h5"
    poses, scores = submission_from_dg16m(real_data, ["dg16m_airplane"], k=10, seed=0)
    assert poses["dg16m_airplane"].shape == (10, 2, 4, 4)
    data = read_dg16m(file)
    moved = retarget_poses(data.grasps, "robotiq_2f85")  # the release's gripper -> Panda
    rows = _rows_of(poses["dg16m_airplane"], moved)
    assert np.isin(rows, data.passing_indices).all()
    assert len(set(rows)) == 10
    np.testing.assert_array_equal(scores["dg16m_airplane"], -data.loss_values[rows])
    # the Panda's contacts sit deeper: poses moved along their approach axis (+y), not turned
    shift = poses["dg16m_airplane"][..., :3, 3] - data.grasps[rows][..., :3, 3]
    approach = data.grasps[rows][..., :3, 1]
    np.testing.assert_allclose(np.cross(shift, approach), 0.0, atol=1e-12)
    assert np.abs(shift).max() > 1e-3
    same, _ = submission_from_dg16m([file], ["dg16m_airplane"], k=10, seed=0)
    np.testing.assert_array_equal(same["dg16m_airplane"], poses["dg16m_airplane"])
    path = write_submission(tmp_path / "s.h5", poses, scores=scores)
    assert validate_submission(path, object_ids=["dg16m_airplane"]) == []


def test_a_partial_submission_for_the_shipped_benchmark_says_how_to_score_a_few(
    tmp_path: Path,
) -> None:
    import warnings

    from dg16m_env.benchmark.file import read_benchmark
    from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
    from dg16m_env.subjects.submission_writer import PartialSubmissionWarning

    ids = [o.object_id for o in read_benchmark(EMBEDDED_BENCHMARK).objects]
    three = tmp_path / "three.h5"
    with pytest.warns(PartialSubmissionWarning, match=r"all 300 objects.*found 3") as caught:
        path = write_submission(three, {i: rigid() for i in ids[:3]})
    message = str(caught[0].message)  # how to score them on purpose: a partial evaluation
    assert f"'dg16m evaluate {three} --objects IDS'" in message
    assert "'--limit N'" in message
    assert "marked partial" in message
    assert path.is_file()  # written all the same (a user may mean it)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        write_submission(tmp_path / "all.h5", {i: rigid(1) for i in ids})
        write_submission(tmp_path / "small.h5", {i: rigid() for i in ids[:3]}, benchmark=SHA)
