"""Tests of dataset_gen.io: DG16M release files, ACRONYM files, manifests.

Every malformed input is built at test time in ``tmp_path``; the real files come from
``../shared/data/real`` (the ``real_data`` fixture of conftest.py) and skip when it is absent.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

import dataset_gen.io as dio
from dataset_gen.io import (
    ACRONYM_TO_DG16M,
    MANIFEST_NAME,
    RELEASE_KEYS,
    DualGraspSet,
    acronym_to_dg16m,
    dg16m_to_acronym,
    manifest_entry_path,
    new_manifest,
    package_version,
    read_acronym,
    read_dg16m,
    read_manifest,
    update_manifest_entry,
    write_dg16m,
    write_manifest,
)
from dg16m_core.errors import GraspFileError

N = 12


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------


def random_poses(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Random rigid (…, 4, 4) transforms."""
    q, r = np.linalg.qr(rng.normal(size=(*shape, 3, 3)))
    q = q * np.sign(np.diagonal(r, axis1=-2, axis2=-1))[..., None, :]
    q[np.linalg.det(q) < 0, :, 0] *= -1.0
    T = np.zeros((*shape, 4, 4))
    T[..., :3, :3] = q
    T[..., :3, 3] = rng.normal(scale=0.2, size=(*shape, 3))
    T[..., 3, 3] = 1.0
    return T


def release_arrays(n: int = N, seed: int = 0) -> dict[str, Any]:
    """Valid release-schema content keyed by HDF5 key."""
    rng = np.random.default_rng(seed)
    half = n // 2
    loss = np.concatenate([rng.uniform(0, 1e-9, half), rng.uniform(0.5, 5.0, n - half)])
    return {
        "grasps/grasps": random_poses(rng, (n, 2)),
        "grasps/contact_points": rng.normal(size=(n, 4, 3)),
        "grasps/contact_forces": rng.normal(size=(n, 4, 3)),
        "grasps/loss_values": loss,
        "grasps/fc_passing_indices": np.arange(half, dtype=np.int64),
        "grasps/fc_failed_indices": np.arange(half, n, dtype=np.int64),
        "object/file": "thing.obj",
        "object/scale": 1,
    }


def make_set(n: int = N, seed: int = 0, **kwargs: Any) -> DualGraspSet:
    a = release_arrays(n, seed)
    fields = {
        "grasps": a["grasps/grasps"],
        "contact_points": a["grasps/contact_points"],
        "contact_forces": a["grasps/contact_forces"],
        "loss_values": a["grasps/loss_values"],
        "passing_indices": a["grasps/fc_passing_indices"],
        "failed_indices": a["grasps/fc_failed_indices"],
        "object_file": "thing.obj",
        "object_scale": 0.5,
    }
    fields.update(kwargs)
    return DualGraspSet(**fields)


def write_raw(path: Path, content: dict[str, Any]) -> Path:
    """Write ``content`` (HDF5 key -> value) with plain h5py, like the release code does."""
    with h5py.File(path, "w") as f:
        for key, value in content.items():
            if isinstance(value, str):
                f.create_dataset(key, data=value, dtype=h5py.string_dtype())
            else:
                f.create_dataset(key, data=value)
    return path


def object_times(path: Path) -> list[tuple[str, int, int, int, int]]:
    """(name, atime, mtime, ctime, btime) of every object in an HDF5 file."""
    out = []
    with h5py.File(path, "r") as f:
        items: list[tuple[str, Any]] = [("/", f)]
        f.visititems(lambda name, obj: items.append((name, obj)))
        for name, obj in items:
            info = h5py.h5o.get_info(obj.id)
            out.append((name, info.atime, info.mtime, info.ctime, info.btime))
    return out


# --------------------------------------------------------------------------------------------
# DualGraspSet in memory
# --------------------------------------------------------------------------------------------


def test_dual_grasp_set_properties_and_normalisation() -> None:
    data = make_set(
        extras={"quality": np.arange(N, dtype=np.float32)},
        metadata={"seed": np.int64(3), "mu": 0.4, "shape": (1, 2)},
    )
    assert data.n == N
    assert data.passed.dtype == bool
    assert data.passed.sum() == N // 2
    assert data.passed[: N // 2].all()
    assert data.grasps.dtype == np.float64
    assert data.passing_indices.dtype == np.int64
    assert not data.grasps.flags.writeable
    assert data.extras["quality"].dtype == np.float32
    assert data.metadata == {"seed": 3, "mu": 0.4, "shape": [1, 2]}
    assert data == make_set(
        extras={"quality": np.arange(N, dtype=np.float32)},
        metadata={"seed": 3, "mu": 0.4, "shape": [1, 2]},
    )
    assert data != make_set()
    assert "n=12" in repr(data)


def test_empty_set_round_trips(tmp_path: Path) -> None:
    data = DualGraspSet(
        grasps=np.zeros((0, 2, 4, 4)),
        contact_points=np.zeros((0, 4, 3)),
        contact_forces=np.zeros((0, 4, 3)),
        loss_values=np.zeros(0),
        passing_indices=[],
        failed_indices=[],
        object_file="empty.obj",
        object_scale=1.0,
    )
    write_dg16m(tmp_path / "empty.h5", data)
    assert read_dg16m(tmp_path / "empty.h5") == data


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"object_scale": 0.0}, r"object/scale: expected a positive finite number"),
        ({"object_file": ""}, r"object/file: expected a non-empty string"),
        ({"loss_values": np.full(N, -1.0)}, r"grasps/loss_values: expected values >= 0"),
        ({"extras": {"a/b": np.zeros(3)}}, r"dg16m/: expected extra names"),
        ({"extras": {"names": np.array(["x", "y"])}}, r"dg16m/names: expected numeric"),
        ({"extras": {"objs": np.array([{}], dtype=object)}}, r"found Python objects"),
        ({"metadata": {"bad": float("nan")}}, r"metadata.*JSON-serialisable"),
        ({"metadata": {"bad": object()}}, r"metadata.*JSON-serialisable"),
        ({"passing_indices": np.array([0.0, 1.0])}, r"expected integer values, found float64"),
    ],
)
def test_dual_grasp_set_rejects(kwargs: dict[str, Any], match: str) -> None:
    with pytest.raises(GraspFileError, match=match):
        make_set(**kwargs)


def test_tiny_negative_loss_is_rounding() -> None:
    loss = release_arrays()["grasps/loss_values"].copy()
    loss[0] = -1e-12
    assert make_set(loss_values=loss).loss_values[0] == -1e-12


# --------------------------------------------------------------------------------------------
# Writing and reading DG16M files
# --------------------------------------------------------------------------------------------


def test_round_trip_with_extras_and_metadata(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    extras = {
        "quality": rng.uniform(size=N),
        "single_grasps": random_poses(rng, (7,)),
        "pair_arms": rng.integers(0, 7, size=(N, 2)),
        "in_collision": rng.uniform(size=N) > 0.5,
        "scalar": np.float64(2.5),
    }
    metadata = {"parameters": {"mu": 0.4, "f_high": 70.0}, "seed": 7, "gripper": "panda"}
    data = make_set(extras=extras, metadata=metadata)
    for level in (dio.DEFAULT_GZIP_LEVEL, None):
        path = tmp_path / f"obj_{level}.h5"
        write_dg16m(path, data, compression_level=level)
        back = read_dg16m(path)
        assert back == data
        assert back.extras.keys() == extras.keys()
        for name, value in extras.items():
            np.testing.assert_array_equal(back.extras[name], value)
            assert back.extras[name].dtype == np.asarray(value).dtype
        assert back.metadata == metadata


def test_writes_are_byte_identical_and_untimed(tmp_path: Path) -> None:
    extras_a = {"b": np.arange(3), "a": np.ones(N)}
    extras_b = {"a": np.ones(N), "b": np.arange(3)}  # insertion order must not matter
    write_dg16m(tmp_path / "one.h5", make_set(extras=extras_a, metadata={"x": 1, "y": 2}))
    write_dg16m(tmp_path / "two.h5", make_set(extras=extras_b, metadata={"y": 2, "x": 1}))
    assert (tmp_path / "one.h5").read_bytes() == (tmp_path / "two.h5").read_bytes()
    times = object_times(tmp_path / "one.h5")
    assert len(times) > 10
    assert all(t[1:] == (0, 0, 0, 0) for t in times), times


def test_release_reader_view(tmp_path: Path) -> None:
    path = tmp_path / "obj.h5"
    write_dg16m(path, make_set(extras={"quality": np.ones(N)}, metadata={"seed": 1}))
    datasets: list[str] = []
    with h5py.File(path, "r") as f:
        assert set(f.keys()) == {"grasps", "object", "dg16m"}
        f.visititems(
            lambda name, obj: datasets.append(name) if isinstance(obj, h5py.Dataset) else None
        )
        assert f["grasps/grasps"].dtype == np.float64
        assert f["grasps/fc_passing_indices"].dtype == np.int64
        assert f["object/file"].asstr()[()] == "thing.obj"
        assert h5py.check_string_dtype(f["object/file"].dtype).encoding == "utf-8"
        assert f["object/scale"][()] == 0.5
        assert f["dg16m"].attrs["schema_version"] == 1
        assert json.loads(f["dg16m"].attrs["metadata"]) == {"seed": 1}
    assert {d for d in datasets if not d.startswith("dg16m/")} == set(RELEASE_KEYS)
    assert {d for d in datasets if d.startswith("dg16m/")} == {"dg16m/quality"}


def test_plain_release_layout_reads(tmp_path: Path) -> None:
    """A file written like the release code (int64 scale, no dg16m group) reads."""
    path = write_raw(tmp_path / "release.h5", release_arrays())
    data = read_dg16m(path)
    assert data.object_scale == 1.0
    assert data.extras == {}
    assert data.metadata == {}


def test_failed_write_keeps_old_file_and_leaves_no_temp(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "obj.h5"
    write_dg16m(path, make_set(seed=0))
    before = path.read_bytes()
    original = dio.write_array
    calls = {"n": 0}

    def failing(*args: Any, **kwargs: Any) -> None:
        calls["n"] += 1
        if calls["n"] == 3:
            raise RuntimeError("disk full (simulated)")
        original(*args, **kwargs)

    monkeypatch.setattr(dio.dg16m, "write_array", failing)  # the name write_dg16m calls
    with pytest.raises(RuntimeError, match="simulated"):
        write_dg16m(path, make_set(seed=1))
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["obj.h5"]


def test_write_rejects_bad_arguments(tmp_path: Path) -> None:
    with pytest.raises(TypeError, match="DualGraspSet"):
        write_dg16m(tmp_path / "x.h5", {"grasps": 1})  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="compression_level"):
        write_dg16m(tmp_path / "x.h5", make_set(), compression_level=12)
    assert not list(tmp_path.iterdir())


# --------------------------------------------------------------------------------------------
# Malformed DG16M files: each with its own message
# --------------------------------------------------------------------------------------------


def _mutated(**changes: Any) -> Callable[[Path], Path]:
    """A builder writing the valid release content with ``changes`` (None drops a key)."""

    def build(path: Path) -> Path:
        content = release_arrays()
        for key, value in changes.items():
            key = key.replace("__", "/")
            if value is None:
                del content[key]
            else:
                content[key] = value(content[key]) if callable(value) else value
        return write_raw(path, content)

    return build


def _text_file(path: Path) -> Path:
    path.write_text("grasps,loss\n1,2\n")
    return path


def _scaled_rotation(g: np.ndarray) -> np.ndarray:
    g = g.copy()
    g[3, 1, :3, :3] *= 1.01
    return g


def _nan_forces(f: np.ndarray) -> np.ndarray:
    f = f.copy()
    f[5, 2, 1] = np.nan
    return f


def _group_instead(path: Path) -> Path:
    content = release_arrays()
    del content["grasps/loss_values"]
    write_raw(path, content)
    with h5py.File(path, "a") as f:
        f.create_group("grasps/loss_values")
    return path


def _external_link(path: Path) -> Path:
    other = path.with_name("other.h5")
    with h5py.File(other, "w") as f:
        f["x"] = np.zeros(N)
    content = release_arrays()
    del content["grasps/loss_values"]
    write_raw(path, content)
    with h5py.File(path, "a") as f:
        f["grasps/loss_values"] = h5py.ExternalLink(str(other), "/x")
    return path


def _dg16m_version_2(path: Path) -> Path:
    write_dg16m(path, make_set())
    with h5py.File(path, "a") as f:
        f["dg16m"].attrs["schema_version"] = 2
    return path


def _bad_metadata(path: Path) -> Path:
    write_dg16m(path, make_set())
    with h5py.File(path, "a") as f:
        f["dg16m"].attrs["metadata"] = '{"seed": 1,'
    return path


def _vlen_extra(path: Path) -> Path:
    write_dg16m(path, make_set())
    with h5py.File(path, "a") as f:
        ds = f["dg16m"].create_dataset("ragged", (2,), dtype=h5py.vlen_dtype(np.float64))
        ds[0] = np.arange(3.0)
        ds[1] = np.arange(1.0)
    return path


MALFORMED: dict[str, tuple[Callable[[Path], Path], str]] = {
    "text_file": (_text_file, r"expected an HDF5 file, found a file without the HDF5 signature"),
    "missing_loss": (
        _mutated(grasps__loss_values=None),
        r"missing: grasps/loss_values$",
    ),
    "missing_two": (
        _mutated(grasps__loss_values=None, object__file=None),
        r"missing: grasps/loss_values, object/file$",
    ),
    "shape_mismatch": (
        _mutated(grasps__contact_points=np.zeros((N, 3, 3))),
        r"grasps/contact_points: expected \(12, 4, 3\) to match grasps/grasps, "
        r"found \(12, 3, 3\)",
    ),
    "grasps_shape": (
        _mutated(grasps__grasps=lambda g: g[:, 0]),
        r"grasps/grasps: expected \(N, 2, 4, 4\), found \(12, 4, 4\)",
    ),
    "nan_forces": (
        _mutated(grasps__contact_forces=_nan_forces),
        r"grasps/contact_forces: expected finite values, found 1 NaN and 0 inf in 1 pair\(s\) "
        r"\(first: pair 5\)",
    ),
    "non_rigid": (
        _mutated(grasps__grasps=_scaled_rotation),
        r"grasps/grasps: expected rigid transforms .* found 1 of 24 not rigid "
        r"\(first: pair 3, arm 1\)",
    ),
    "index_out_of_range": (
        _mutated(grasps__fc_passing_indices=np.array([0, 1, 12])),
        r"grasps/fc_passing_indices: expected indices in \[0, 12\) .* found values in \[0, 12\]",
    ),
    "negative_index": (
        _mutated(grasps__fc_failed_indices=np.array([-1, 7])),
        r"grasps/fc_failed_indices: expected indices in \[0, 12\)",
    ),
    "overlapping_indices": (
        _mutated(grasps__fc_failed_indices=np.array([5, 6, 7])),
        r"expected disjoint sets, found 1 pair\(s\) in both \(first: 5\)",
    ),
    "duplicate_indices": (
        _mutated(grasps__fc_passing_indices=np.array([0, 1, 1])),
        r"grasps/fc_passing_indices: expected unique indices, found 1 repeated \(first: 1\)",
    ),
    "string_loss": (
        _mutated(grasps__loss_values=lambda v: np.array([str(x) for x in v], dtype=object)),
        r"grasps/loss_values: expected float values, found variable-length strings",
    ),
    "int_grasps": (
        _mutated(grasps__grasps=lambda g: g.astype(np.int64)),
        r"grasps/grasps: expected float values, found int64",
    ),
    "float_indices": (
        _mutated(grasps__fc_passing_indices=np.arange(6.0)),
        r"grasps/fc_passing_indices: expected integer values, found float64",
    ),
    "negative_loss": (
        _mutated(grasps__loss_values=lambda v: -v),
        r"grasps/loss_values: expected values >= 0",
    ),
    "numeric_object_file": (
        _mutated(object__file=np.int64(3)),
        r"object/file: expected a string, found int64",
    ),
    "zero_scale": (_mutated(object__scale=0), r"object/scale: expected a positive finite"),
    "string_scale": (
        _mutated(object__scale="big"),
        r"object/scale: expected numeric values, found variable-length strings",
    ),
    "group_not_dataset": (_group_instead, r"grasps/loss_values: expected a dataset, found a group"),
    "external_link": (_external_link, r"grasps/loss_values: .* found a ExternalLink"),
    "dg16m_version": (_dg16m_version_2, r"schema_version'\]: expected one of \[1\], found 2"),
    "dg16m_bad_metadata": (_bad_metadata, r"found malformed JSON at line 1, column 12"),
    "dg16m_vlen_extra": (_vlen_extra, r"dg16m/ragged: expected numeric .* variable-length seq"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_dg16m_files(tmp_path: Path, case: str) -> None:
    build, match = MALFORMED[case]
    path = build(tmp_path / f"{case}.h5")
    with pytest.raises(GraspFileError, match=match) as excinfo:
        read_dg16m(path)
    assert str(path) in str(excinfo.value)


def test_missing_and_directory_paths(tmp_path: Path) -> None:
    with pytest.raises(GraspFileError, match="found nothing at this path"):
        read_dg16m(tmp_path / "absent.h5")
    with pytest.raises(GraspFileError, match="found a directory"):
        read_dg16m(tmp_path)


# --------------------------------------------------------------------------------------------
# Real files
# --------------------------------------------------------------------------------------------


@pytest.mark.real_data
def test_real_release_file(real_data: Path, tmp_path: Path) -> None:
    original = real_data / "dg16m_airplane.h5"
    data = read_dg16m(original)
    assert data.n == 4000
    assert len(data.passing_indices) == 2000
    assert len(data.failed_indices) == 2000
    assert data.passed.sum() == 2000
    assert data.object_file == "airplane.obj"
    assert data.object_scale == 1.0
    assert data.loss_values[data.passing_indices].max() < 1e-8
    assert data.loss_values[data.failed_indices].min() >= 0.5
    net = data.contact_forces[data.passing_indices].sum(axis=1)
    np.testing.assert_allclose(net, np.tile([0.0, 0.0, 60.0], (2000, 1)), atol=1e-3)

    rewritten = tmp_path / "airplane.h5"
    write_dg16m(rewritten, data)
    assert read_dg16m(rewritten) == data
    assert os.path.getsize(rewritten) < 0.5 * os.path.getsize(original)


@pytest.mark.real_data
@pytest.mark.parametrize(
    ("name", "fraction", "gripper"),
    [("acronym_mug_10f6e090.h5", 0.645, "panda"), ("acronym_table_99cf659a.h5", 0.7795, "panda")],
)
def test_real_acronym_files(real_data: Path, name: str, fraction: float, gripper: str) -> None:
    path = real_data / name
    if not path.is_file():
        pytest.skip(f"{path} not available")
    grasps = read_acronym(path)
    assert grasps.n == 2000
    assert grasps.success.dtype == bool
    assert grasps.success.mean() == pytest.approx(fraction)
    assert grasps.gripper_type == gripper
    assert grasps.object_file.endswith(".obj")
    assert grasps.object_scale > 0
    assert grasps.object_mass is not None
    assert grasps.object_mass > 0
    assert grasps.object_com is not None
    assert grasps.object_com.shape == (3,)
    np.testing.assert_array_equal(grasps.gripper_configuration, [0.04])
    assert "object_in_gripper" in grasps.qualities
    T, A = grasps.transforms, grasps.transforms_acronym
    np.testing.assert_array_equal(T[:, :3, 1], A[:, :3, 2])  # approach on our +y
    np.testing.assert_array_equal(T[:, :3, 0], A[:, :3, 0])  # same closing axis
    np.testing.assert_array_equal(T[:, :3, 3], A[:, :3, 3])  # same origin
    np.testing.assert_allclose(np.cross(T[:, :3, 0], T[:, :3, 1]), T[:, :3, 2], atol=1e-9)


# --------------------------------------------------------------------------------------------
# ACRONYM format (synthetic)
# --------------------------------------------------------------------------------------------


def acronym_content(n: int = 6) -> dict[str, Any]:
    rng = np.random.default_rng(2)
    return {
        "grasps/transforms": random_poses(rng, (n,)),
        "grasps/qualities/flex/object_in_gripper": np.array([1, 0] * (n // 2)),
        "object/file": "meshes/Mug/x.obj",
        "object/scale": 0.01,
    }


def test_acronym_conversion_constant() -> None:
    C = ACRONYM_TO_DG16M
    np.testing.assert_array_equal(C[:3, 0], [1, 0, 0])
    np.testing.assert_array_equal(C[:3, 1], [0, 0, 1])
    np.testing.assert_array_equal(C[:3, 2], [0, -1, 0])
    assert np.linalg.det(C[:3, :3]) == pytest.approx(1.0)
    assert not C.flags.writeable
    T = random_poses(np.random.default_rng(3), (5, 2))
    np.testing.assert_allclose(dg16m_to_acronym(acronym_to_dg16m(T)), T, atol=1e-15)
    with pytest.raises(ValueError, match=r"\(\.\.\., 4, 4\)"):
        acronym_to_dg16m(np.eye(3))


def test_acronym_minimal_file(tmp_path: Path) -> None:
    grasps = read_acronym(write_raw(tmp_path / "a.h5", acronym_content()))
    assert grasps.success.tolist() == [True, False] * 3
    assert grasps.object_mass is None
    assert grasps.gripper_type is None


def _acronym_non_rigid(T: np.ndarray) -> np.ndarray:
    T = T.copy()
    T[2, :3, :3] *= 2.0
    return T


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("grasps/transforms", None, r"missing: grasps/transforms$"),
        ("grasps/transforms", _acronym_non_rigid, r"found 1 of 6 not rigid \(first: grasp 2\)"),
        (
            "grasps/qualities/flex/object_in_gripper",
            np.array([1, 0, 2, 0, 1, 0]),
            r"object_in_gripper: expected 0/1 labels, found 1 other value\(s\)",
        ),
        (
            "grasps/qualities/flex/object_in_gripper",
            np.ones(5),
            r"object_in_gripper: expected \(6,\) to match grasps/transforms, found \(5,\)",
        ),
        ("object/mass", -1.0, r"object/mass: expected a positive finite number"),
        ("object/com", np.array([0.0, np.nan, 0.0]), r"object/com: expected finite values"),
        ("gripper/type", 3, r"gripper/type: expected a string, found int64"),
    ],
)
def test_malformed_acronym_files(tmp_path: Path, key: str, value: Any, match: str) -> None:
    content = acronym_content()
    if value is None:
        del content[key]
    else:
        content[key] = value(content[key]) if callable(value) else value
    path = write_raw(tmp_path / "a.h5", content)
    with pytest.raises(GraspFileError, match=match) as excinfo:
        read_acronym(path)
    assert str(path) in str(excinfo.value)


# --------------------------------------------------------------------------------------------
# Manifest
# --------------------------------------------------------------------------------------------


def test_manifest_round_trip_and_stable_bytes(tmp_path: Path) -> None:
    manifest = new_manifest("grasps", {"mu": 0.4, "seed": 0})
    manifest["entries"]["mug"] = {"status": "ok", "files": {"grasps": "grasps/mug.h5"}, "n": 4}
    manifest["entries"]["cup"] = {"status": "failed", "files": {}, "error": "mesh is empty"}
    path = write_manifest(tmp_path, manifest)
    assert path == tmp_path / MANIFEST_NAME
    assert read_manifest(tmp_path) == manifest
    first = path.read_bytes()
    write_manifest(tmp_path, json.loads(json.dumps(manifest)))
    assert path.read_bytes() == first
    text = first.decode()
    assert text.index('"cup"') < text.index('"mug"')
    assert manifest["created_by"] == f"dg16m {package_version()}"
    assert manifest_entry_path(tmp_path, manifest, "mug", "grasps") == tmp_path / "grasps/mug.h5"


def test_update_manifest_entry(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="kind="):
        update_manifest_entry(tmp_path, "mug", {"status": "ok", "files": {}})
    update_manifest_entry(
        tmp_path, "mug", {"status": "ok", "files": {"grasps": "mug.h5"}}, kind="grasps"
    )
    update_manifest_entry(tmp_path, "cup", {"status": "failed", "files": {}, "error": "boom"})
    update_manifest_entry(tmp_path, "mug", {"status": "failed", "files": {}, "error": "redo"})
    manifest = read_manifest(tmp_path)
    assert manifest["kind"] == "grasps"
    assert manifest["entries"] == {
        "cup": {"status": "failed", "files": {}, "error": "boom"},
        "mug": {"status": "failed", "files": {}, "error": "redo"},
    }
    with pytest.raises(GraspFileError, match="kind: expected 'objects', found 'grasps'"):
        update_manifest_entry(tmp_path, "x", {"status": "ok", "files": {}}, kind="objects")
    with pytest.raises(GraspFileError, match=r"\.\."):
        update_manifest_entry(tmp_path, "x", {"status": "ok", "files": {"g": "../x.h5"}})
    assert read_manifest(tmp_path) == manifest  # a rejected update writes nothing
    assert sorted(p.name for p in tmp_path.iterdir()) == [MANIFEST_NAME]


def _manifest_text(**changes: Any) -> str:
    manifest = {
        "format": "dg16m-manifest",
        "schema_version": 1,
        "kind": "objects",
        "created_by": "dg16m 0.1.0",
        "parameters": {},
        "entries": {"mug": {"status": "ok", "files": {"mesh": "meshes/mug.obj"}}},
    }
    manifest.update(changes)
    return json.dumps(manifest, indent=2)


def _entry(**entry: Any) -> str:
    return _manifest_text(entries={"mug": {"status": "ok", "files": {}, **entry}})


BAD_MANIFESTS: dict[str, tuple[str, str]] = {
    "bad_json": (
        '{\n  "format": "dg16m-manifest",\n  "kind": objects\n}\n',
        r"malformed JSON at line 3, column 11",
    ),
    "wrong_version": (
        _manifest_text(schema_version=2),
        r"schema_version: expected one of \[1\] \(supported by dg16m .*\), found 2",
    ),
    "absolute_path": (
        _entry(files={"mesh": "/etc/passwd"}),
        r"entries\.mug\.files\.mesh: expected a path relative .* found absolute '/etc/passwd'",
    ),
    "dotdot_path": (
        _entry(files={"mesh": "meshes/../../secret.obj"}),
        r"entries\.mug\.files\.mesh: expected a path inside the manifest's folder, found '\.\.'",
    ),
    "windows_path": (_entry(files={"mesh": "C:/x.obj"}), r"found absolute 'C:/x.obj'"),
    "backslash_path": (_entry(files={"mesh": "a\\b.obj"}), r"with '/' separators"),
    "unknown_kind": (_manifest_text(kind="meshes"), r"kind: expected one of .* found 'meshes'"),
    "wrong_format": (_manifest_text(format="other"), r"format: expected 'dg16m-manifest'"),
    "extra_key": (_manifest_text(extra=1), r"found also \['extra'\]"),
    "bad_status": (_entry(status="done"), r"entries\.mug\.status: expected one of"),
    "failed_without_error": (_entry(status="failed"), r"entries\.mug\.error: expected an error"),
    "ok_with_error": (_entry(error="x"), r"expected no error for status 'ok'"),
    "files_missing": (
        _manifest_text(entries={"mug": {"status": "ok"}}),
        r"entries\.mug\.files: expected an object .* found nothing",
    ),
    "bad_object_id": (
        _manifest_text(entries={"../mug": {"status": "ok", "files": {}}}),
        r"entries: expected an object id",
    ),
    "duplicate_key": ('{"kind": "objects", "kind": "grasps"}', r"found 'kind' twice"),
    "nan": ('{"parameters": {"mu": NaN}}', r"expected finite JSON numbers, found NaN"),
    "not_object": ("[1, 2]", r"expected a JSON object at top level, found list"),
}


@pytest.mark.parametrize("case", sorted(BAD_MANIFESTS))
def test_malformed_manifests(tmp_path: Path, case: str) -> None:
    text, match = BAD_MANIFESTS[case]
    (tmp_path / MANIFEST_NAME).write_text(text)
    with pytest.raises(GraspFileError, match=match) as excinfo:
        read_manifest(tmp_path)
    assert str(tmp_path / MANIFEST_NAME) in str(excinfo.value)


def test_manifest_missing_and_invalid_write(tmp_path: Path) -> None:
    with pytest.raises(GraspFileError, match="found no such file"):
        read_manifest(tmp_path)
    manifest = new_manifest("objects")
    manifest["entries"]["mug"] = {"status": "ok", "files": {"mesh": "/abs.obj"}}
    with pytest.raises(GraspFileError, match="absolute"):
        write_manifest(tmp_path, manifest)
    assert not (tmp_path / MANIFEST_NAME).exists()
    with pytest.raises(GraspFileError, match="kind"):
        new_manifest("meshes")


def test_detect_format(tmp_path: Path, real_data: Path) -> None:
    assert dio.detect_format(real_data / "dg16m_airplane.h5") == "dg16m"
    assert dio.detect_format(real_data / "acronym_mug_10f6e090.h5") == "acronym"
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as handle:
        handle.create_dataset("points", data=np.zeros(3))
    with pytest.raises(GraspFileError, match=r"found top-level keys \['points'\]"):
        dio.detect_format(other)


# --------------------------------------------------------------------------------------------
# Package layout: one module per format behind the names of the former single module
# --------------------------------------------------------------------------------------------


def test_package_reexports_every_public_name() -> None:
    import importlib

    for name in dio.__all__:
        assert hasattr(dio, name), name
    # each format's module owns its names; the package hands out the very same objects
    owners = {
        "dg16m": ("DualGraspSet", "read_dg16m", "write_dg16m", "RELEASE_KEYS", "EXTRAS_GROUP"),
        "acronym": ("AcronymGrasps", "read_acronym", "acronym_to_dg16m", "ACRONYM_TO_DG16M"),
        "manifest": ("read_manifest", "write_manifest", "MANIFEST_NAME", "MANIFEST_KINDS"),
        "versions": ("package_version", "SCHEMA_VERSION", "SUPPORTED_MANIFEST_VERSIONS"),
        "detect": ("detect_format",),
        "_hdf5": ("write_array", "CHUNK_BYTES"),
        "_checks": ("RIGID_ATOL",),
    }
    for module, names in owners.items():
        mod = importlib.import_module(f"dataset_gen.io.{module}")
        for name in names:
            assert getattr(dio, name) is getattr(mod, name), (module, name)
