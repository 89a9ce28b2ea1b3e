"""CoACD convex decomposition: parts of a non-convex mesh, the on-disk cache, determinism, errors."""

from __future__ import annotations

import json
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import trimesh

pytest.importorskip("coacd")

from dataset_gen.errors import MeshError
from dataset_gen.objects import make_object, parts_to_mesh
from dataset_gen.procedural import make_procedural_object
from dataset_gen import decomposition as dec
from dataset_gen.decomposition import (
    DecompositionParameters,
    convex_decomposition,
    default_cache_dir,
    mesh_digest,
    object_parts,
)

# Coarse settings: the L-shape decomposes in well under a second.
FAST = DecompositionParameters(
    preprocess_resolution=20, resolution=500, mcts_nodes=10, mcts_iterations=20, mcts_max_depth=2
)


@pytest.fixture(scope="module")
def l_shape() -> trimesh.Trimesh:
    """A non-convex L: a 0.3 x 0.1 x 0.1 m bar with a 0.1 x 0.1 x 0.3 m post on one end."""
    bar = trimesh.creation.box(extents=[0.3, 0.1, 0.1])
    bar.apply_translation([0.1, 0.0, 0.0])
    post = trimesh.creation.box(extents=[0.1, 0.1, 0.3])
    post.apply_translation([0.0, 0.0, 0.1])
    mesh = trimesh.boolean.union([bar, post], engine="manifold")
    assert mesh.is_watertight
    assert mesh.volume < 0.9 * mesh.convex_hull.volume  # really non-convex
    return mesh


def _stacked(parts: tuple) -> np.ndarray:
    return np.concatenate([part.vertices for part in parts])


def test_l_shape_decomposes_into_hulls_that_cover_it(
    l_shape: trimesh.Trimesh, tmp_path: Path
) -> None:
    parts = convex_decomposition(l_shape, params=FAST, cache_dir=tmp_path)
    assert len(parts) >= 2
    lo, hi = l_shape.bounds
    for part in parts:
        assert part.kind == "mesh"
        np.testing.assert_array_equal(part.pose, np.eye(4))
        assert part.vertices.shape[1] == 3
        assert len(part.vertices) >= 4
        assert np.all(part.vertices >= lo - 1e-6)
        assert np.all(part.vertices <= hi + 1e-6)
    union_volume = parts_to_mesh(parts).volume
    assert union_volume == pytest.approx(l_shape.volume, rel=0.2)


def test_second_call_is_a_cache_hit_with_identical_parts(
    l_shape: trimesh.Trimesh, tmp_path: Path
) -> None:
    stats: dict = {}
    first = convex_decomposition(l_shape, params=FAST, cache_dir=tmp_path, stats=stats)
    assert stats["cache_hit"] is False
    path = stats["cache_path"]
    assert path == tmp_path / f"{mesh_digest(l_shape.vertices, l_shape.faces, FAST)}.json"
    data = json.loads(path.read_text())
    assert data["format"] == "dg16m-coacd"
    assert data["schema_version"] == 1
    assert data["parameters"] == FAST.to_dict()
    assert len(data["parts"]) == len(first)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp files left

    second = convex_decomposition(l_shape, params=FAST, cache_dir=tmp_path, stats=stats)
    assert stats["cache_hit"] is True
    assert len(second) == len(first)
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(a.vertices, b.vertices)


def test_changed_parameter_is_a_cache_miss(l_shape: trimesh.Trimesh, tmp_path: Path) -> None:
    stats: dict = {}
    convex_decomposition(l_shape, params=FAST, cache_dir=tmp_path, stats=stats)
    other = DecompositionParameters(**{**FAST.to_dict(), "threshold": 0.1})
    convex_decomposition(l_shape, params=other, cache_dir=tmp_path, stats=stats)
    assert stats["cache_hit"] is False
    assert len(list(tmp_path.glob("*.json"))) == 2


@pytest.mark.parametrize(
    "garbage",
    [
        b"not json at all {",
        b"\xff\xfe\x00 binary",
        b"[1, 2, 3]",
        b'{"format": "something-else", "schema_version": 1}',
        b"",
    ],
)
def test_corrupt_cache_file_is_recomputed_and_repaired(
    l_shape: trimesh.Trimesh, tmp_path: Path, garbage: bytes
) -> None:
    stats: dict = {}
    first = convex_decomposition(l_shape, params=FAST, cache_dir=tmp_path, stats=stats)
    path = stats["cache_path"]
    path.write_bytes(garbage)
    again = convex_decomposition(l_shape, params=FAST, cache_dir=tmp_path, stats=stats)
    assert stats["cache_hit"] is False
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a.vertices, b.vertices)
    assert json.loads(path.read_text())["format"] == "dg16m-coacd"  # repaired
    convex_decomposition(l_shape, params=FAST, cache_dir=tmp_path, stats=stats)
    assert stats["cache_hit"] is True


def test_cache_file_with_bad_parts_is_not_trusted(l_shape: trimesh.Trimesh, tmp_path: Path) -> None:
    stats: dict = {}
    convex_decomposition(l_shape, params=FAST, cache_dir=tmp_path, stats=stats)
    path = stats["cache_path"]
    data = json.loads(path.read_text())
    data["parts"][0]["vertices"] = [[0.0, 0.0, float("nan")]]
    path.write_text(json.dumps(data))
    parts = convex_decomposition(l_shape, params=FAST, cache_dir=tmp_path, stats=stats)
    assert stats["cache_hit"] is False
    assert all(len(part.vertices) >= 4 for part in parts)


def test_use_cache_false_is_deterministic_and_writes_nothing(
    l_shape: trimesh.Trimesh, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("DG16M_CACHE_DIR", str(tmp_path))
    stats: dict = {}
    a = convex_decomposition(l_shape, params=FAST, use_cache=False, stats=stats)
    assert stats["cache_hit"] is False
    assert stats["cache_path"] is None
    b = convex_decomposition(l_shape, params=FAST, use_cache=False)
    assert len(a) == len(b)
    for pa, pb in zip(a, b, strict=True):
        np.testing.assert_array_equal(pa.vertices, pb.vertices)
    assert not any(tmp_path.iterdir())


def test_default_cache_dir_follows_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("DG16M_CACHE_DIR", str(tmp_path / "dg"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_cache_dir() == tmp_path / "dg" / "coacd"
    monkeypatch.delenv("DG16M_CACHE_DIR")
    assert default_cache_dir() == tmp_path / "xdg" / "dg16m" / "coacd"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert default_cache_dir() == Path.home() / ".cache" / "dg16m" / "coacd"


def test_digest_depends_on_geometry_and_parameters(l_shape: trimesh.Trimesh) -> None:
    v, f = np.asarray(l_shape.vertices), np.asarray(l_shape.faces)
    digest = mesh_digest(v, f, FAST)
    assert len(digest) == 64
    assert int(digest, 16) >= 0
    assert mesh_digest(v, f.astype(np.int32), FAST) == digest  # bytes are normalised to int64
    assert mesh_digest(v.tolist(), f.tolist(), FAST) == digest
    assert mesh_digest(v + 1e-9, f, FAST) != digest
    assert mesh_digest(v, f[::-1], FAST) != digest
    assert mesh_digest(v, f, DecompositionParameters(**{**FAST.to_dict(), "seed": 1})) != digest


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("threshold", 0.0),
        ("threshold", 1.5),
        ("threshold", float("nan")),
        ("threshold", "0.05"),
        ("threshold", True),
        ("max_convex_hulls", 0),
        ("max_convex_hulls", -2),
        ("resolution", 0),
        ("preprocess_resolution", 2.5),
        ("mcts_nodes", 0),
        ("mcts_iterations", -1),
        ("mcts_max_depth", 0),
        ("seed", -1),
        ("seed", 2**32),
        ("seed", True),
    ],
)
def test_bad_parameters_raise(field: str, value: object) -> None:
    with pytest.raises(MeshError, match=rf"{field}: expected .*found"):
        DecompositionParameters(**{field: value})


def test_parameters_map_onto_run_coacd() -> None:
    import inspect

    import coacd

    accepted = set(inspect.signature(coacd.run_coacd).parameters)
    assert set(DecompositionParameters().coacd_kwargs()) <= accepted


def test_bad_input_raises_mesh_error(tmp_path: Path) -> None:
    with pytest.raises(MeshError, match=r"expected a trimesh.Trimesh, found ndarray"):
        convex_decomposition(np.zeros((4, 3)), cache_dir=tmp_path)  # type: ignore[arg-type]
    with pytest.raises(MeshError, match=r"expected a triangle mesh, found 0 vertices"):
        convex_decomposition(trimesh.Trimesh(), cache_dir=tmp_path)
    box = trimesh.creation.box()
    vertices = np.array(box.vertices)
    vertices[2, 1] = np.nan
    nan_box = trimesh.Trimesh(vertices=vertices, faces=box.faces, process=False)
    with pytest.raises(MeshError, match=r"expected finite vertex coordinates, found 1 vert"):
        convex_decomposition(nan_box, cache_dir=tmp_path, name="nan_box")
    with pytest.raises(MeshError, match=r"params: expected DecompositionParameters, found dict"):
        convex_decomposition(box, params={"threshold": 0.1}, cache_dir=tmp_path)  # type: ignore[arg-type]
    assert not any(tmp_path.iterdir())


def _fake_coacd(hulls: list[np.ndarray]) -> types.SimpleNamespace:
    def run_coacd(mesh: object, **kwargs: object) -> list:
        return [[h, np.zeros((0, 3), dtype=np.int32)] for h in hulls]

    return types.SimpleNamespace(Mesh=lambda v, f: None, run_coacd=run_coacd)


def test_degenerate_hulls_are_dropped(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    cube = np.array(trimesh.creation.box().vertices)
    flat = cube.copy()
    flat[:, 2] = 0.0
    fake = _fake_coacd([cube, flat, cube[:3], np.repeat(cube[:1], 6, axis=0)])
    monkeypatch.setattr(dec, "_import_coacd", lambda: fake)
    parts = convex_decomposition(trimesh.creation.box(), use_cache=False)
    assert len(parts) == 1
    np.testing.assert_array_equal(np.unique(parts[0].vertices, axis=0), np.unique(cube, axis=0))

    monkeypatch.setattr(dec, "_import_coacd", lambda: _fake_coacd([flat, cube[:3]]))
    with pytest.raises(MeshError, match=r"^thin_plate: expected .* found 2 hulls"):
        convex_decomposition(trimesh.creation.box(), use_cache=False, name="thin_plate")


def test_missing_coacd_says_how_to_install(
    monkeypatch: pytest.MonkeyPatch, l_shape: trimesh.Trimesh
) -> None:
    monkeypatch.setitem(sys.modules, "coacd", None)
    with pytest.raises(ImportError, match=r"install dg16m\[sim\]") as info:
        convex_decomposition(l_shape, use_cache=False)
    assert not isinstance(info.value, MeshError)


def test_object_parts_keeps_procedural_parts_without_coacd(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    obj = make_procedural_object("table", 0)  # seed 0: a train seed, valid for every family
    assert obj.parts

    def no_coacd(*args: object, **kwargs: object) -> None:
        raise AssertionError("CoACD must not run for an object with parts")

    monkeypatch.setattr(dec, "convex_decomposition", no_coacd)
    monkeypatch.setattr(dec, "_import_coacd", no_coacd)
    assert object_parts(obj) == tuple(obj.parts)


def test_object_parts_decomposes_a_mesh_without_parts(
    l_shape: trimesh.Trimesh, tmp_path: Path
) -> None:
    obj = make_object(l_shape, object_id="l_shape")
    assert obj.parts is None
    stats: dict = {}
    parts = object_parts(obj, params=FAST, cache_dir=tmp_path, stats=stats)
    assert stats["cache_hit"] is False
    assert len(parts) >= 2
    lo, hi = obj.mesh.bounds
    assert np.all(_stacked(parts) >= lo - 1e-6)
    assert np.all(_stacked(parts) <= hi + 1e-6)
    with pytest.raises(MeshError, match=r"expected a GraspObject, found Trimesh"):
        object_parts(l_shape)  # type: ignore[arg-type]
