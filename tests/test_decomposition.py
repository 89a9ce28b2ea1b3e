"""CoACD convex decomposition: parts of a non-convex mesh, the on-disk cache, determinism, errors."""

from __future__ import annotations

import json
import math
import re
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import trimesh

pytest.importorskip("coacd")

from shipped_meshes import FAST, MESHES

from dataset_gen.objects import decomposition as dec
from dataset_gen.objects.decomposition import (
    DecompositionParameters,
    DecompositionReport,
    convex_decomposition,
    decomposition_report,
    default_cache_dir,
    mesh_digest,
    needs_repair,
    object_parts,
    parts_to_obj,
)
from dataset_gen.objects.grasp_object import ConvexPart, make_object, parts_to_mesh
from dataset_gen.sources.procedural import make_procedural_object
from dg16m_core.cli import main
from dg16m_core.errors import MeshError


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
    assert data["schema_version"] == dec.CACHE_SCHEMA_VERSION == 2
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
        ("preprocess", "yes"),
        ("preprocess", None),
        ("merge", 1),
        ("decimate", "no"),
        ("max_ch_vertex", 3),
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
    with pytest.raises(ImportError, match=r"needs the 'coacd' package; reinstall dg16m") as info:
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


# --------------------------------------------------------------------------------------------
# Preprocessing choice, faithfulness of the hulls, the deviation report, the CLI
# --------------------------------------------------------------------------------------------


DEVIATION_BOUND_M = 1e-3
"""What the default settings must achieve on box-built solids: every hull point within 1 mm."""


def _box(extents: list[float], center: list[float]) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=extents)
    box.apply_translation(center)
    return box


@pytest.fixture(scope="module")
def thin_table() -> trimesh.Trimesh:
    """A 0.6 x 0.4 m table, 0.45 m high: a 3 cm top on four 2 x 2 cm legs (one solid)."""
    top = _box([0.6, 0.4, 0.03], [0.0, 0.0, 0.435])
    legs = [
        _box([0.02, 0.02, 0.43], [sx * 0.27, sy * 0.17, 0.215]) for sx in (-1, 1) for sy in (-1, 1)
    ]
    mesh = trimesh.boolean.union([top, *legs], engine="manifold")
    assert mesh.is_volume
    return mesh


def _vertex_deviation(mesh: trimesh.Trimesh, parts: tuple) -> float:
    """Largest distance (m) from a hull vertex outside the mesh to the mesh surface."""
    points = _stacked(parts)
    _, distance, _ = trimesh.proximity.closest_point(mesh, points)
    outside = dec._TriangleTree(mesh)(points) < 0.5
    return float(np.max(np.where(outside, distance, 0.0)))


@pytest.mark.parametrize("shape", ["l_shape", "thin_table"])
def test_default_hulls_stay_within_a_millimetre_of_box_built_solids(
    shape: str, request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    mesh = request.getfixturevalue(shape)
    stats: dict = {}
    parts = convex_decomposition(mesh, cache_dir=tmp_path, stats=stats)  # the defaults
    assert stats["preprocess"] == "off"  # watertight: no voxel remesh
    assert _vertex_deviation(mesh, parts) < DEVIATION_BOUND_M
    report = decomposition_report(mesh, parts, samples=5000, stats=stats)
    assert report.inside_test
    assert report.deviation_max < DEVIATION_BOUND_M
    assert report.deviation_p95 < 0.1e-3
    assert abs(report.extra_volume) < 0.02


def test_forced_voxel_preprocessing_moves_hulls_off_a_watertight_mesh(
    l_shape: trimesh.Trimesh, tmp_path: Path
) -> None:
    # CoACD's voxel remesh (what its own "auto" does to meshes it wrongly calls non-manifold)
    # rebuilds the surface on a grid: the hulls end up millimetres outside the mesh.
    on = DecompositionParameters(
        **{**FAST.to_dict(), "preprocess": "on", "preprocess_resolution": 50}
    )
    auto = DecompositionParameters(**{**FAST.to_dict(), "preprocess": "auto"})
    assert on.preprocess_mode(l_shape) == "on"
    assert auto.preprocess_mode(l_shape) == "off"
    stats_on: dict = {}
    stats_auto: dict = {}
    remeshed = convex_decomposition(l_shape, params=on, cache_dir=tmp_path, stats=stats_on)
    kept = convex_decomposition(l_shape, params=auto, cache_dir=tmp_path, stats=stats_auto)
    assert (stats_on["preprocess"], stats_auto["preprocess"]) == ("on", "off")
    bad = decomposition_report(l_shape, remeshed, samples=4000)
    good = decomposition_report(l_shape, kept, samples=4000)
    assert bad.deviation_max > 3e-3  # millimetres out (measured 6.8 mm, p95 3.5 mm)
    assert bad.deviation_p95 > 1e-3
    assert good.deviation_max < DEVIATION_BOUND_M


def test_coacd_own_auto_remeshes_a_watertight_real_mesh_and_ours_does_not(
    tmp_path: Path,
) -> None:
    # The shipped dining chair is watertight and manifold (trimesh, manifold3d), yet CoACD's
    # own preprocess_mode="auto" voxel-remeshes it: every hull vertex ends up outside the mesh
    # (measured median 4.3 mm). Ours keeps the surface: the hull vertices lie on it (CoACD cuts
    # and hulls the mesh itself).
    import coacd

    from dataset_gen.objects.grasp_object import load_object

    mesh = load_object(MESHES / "dining_chair.obj").mesh
    assert mesh.is_volume
    assert not needs_repair(mesh)
    kwargs = FAST.coacd_kwargs("off") | {"preprocess_mode": "auto", "preprocess_resolution": 50}
    theirs = coacd.run_coacd(coacd.Mesh(mesh.vertices, mesh.faces.astype(np.int32)), **kwargs)
    theirs_vertices = np.concatenate([np.asarray(hull) for hull, _ in theirs])
    stats: dict = {}
    ours = convex_decomposition(mesh, params=FAST, cache_dir=tmp_path, stats=stats)
    assert stats["preprocess"] == "off"
    tree = dec._TriangleTree(mesh)

    def outside(points: np.ndarray) -> np.ndarray:
        return np.where(tree.contains(points), 0.0, tree.distance(points))

    assert np.median(outside(theirs_vertices)) > 2e-3
    assert np.mean(outside(theirs_vertices) > 1e-3) > 0.9
    assert outside(_stacked(ours)).max() < 0.1e-3  # on the surface (measured 0.07 mm)


def test_auto_preprocessing_repairs_only_meshes_that_are_not_a_volume(tmp_path: Path) -> None:
    box = trimesh.creation.box(extents=[0.2, 0.1, 0.1])
    open_box = trimesh.Trimesh(vertices=box.vertices, faces=box.faces[1:], process=False)
    flipped = trimesh.Trimesh(vertices=box.vertices, faces=box.faces[:, ::-1], process=False)
    assert not needs_repair(box)
    assert needs_repair(open_box)  # not watertight
    assert needs_repair(flipped)  # negative volume
    params = DecompositionParameters(**{**FAST.to_dict(), "preprocess": "auto"})
    assert params.preprocess_mode(box) == "off"
    assert params.preprocess_mode(open_box) == "on"
    assert params.preprocess_mode(flipped) == "on"
    assert params.coacd_kwargs("on")["preprocess_mode"] == "on"
    assert "preprocess" not in params.coacd_kwargs()
    with pytest.raises(MeshError, match=r"preprocess_mode: expected 'on' or 'off', found 'auto'"):
        params.coacd_kwargs("auto")  # CoACD's own "auto" is never passed on
    off = DecompositionParameters(**{**FAST.to_dict(), "preprocess": "off"})
    assert off.preprocess_mode(open_box) == "off"
    stats: dict = {}
    parts = convex_decomposition(open_box, params=params, cache_dir=tmp_path, stats=stats)
    assert stats["preprocess"] == "on"
    assert parts
    report = decomposition_report(open_box, parts, samples=2000, stats=stats)
    assert not report.inside_test
    assert math.isnan(report.extra_volume)
    assert report.to_dict()["extra_volume"] is None
    assert "unsigned: not a volume" in report.format()


def test_report_matches_the_known_answer_for_the_hull_of_an_l(l_shape: trimesh.Trimesh) -> None:
    # The hull of the L adds a triangular prism (legs 0.2 m, depth 0.1 m): 0.002 m^3 on the
    # L's 0.005 m^3, i.e. +40 %; its farthest point (the middle of the slanted face) is 0.1 m
    # from both inner faces of the L.
    hull = (ConvexPart(kind="mesh", pose=np.eye(4), vertices=l_shape.convex_hull.vertices),)
    report = decomposition_report(l_shape, hull, samples=20000, seed=3)
    assert isinstance(report, DecompositionReport)
    assert report.hulls == 1
    assert report.faces == len(l_shape.faces)
    assert report.watertight
    assert report.inside_test
    assert report.deviation_max == pytest.approx(0.1, abs=2e-3)
    assert report.deviation_max <= 0.1 + 1e-9
    assert report.extra_volume == pytest.approx(0.4, abs=0.02)
    # Area share of the prism's surface that lies outside the L: a positive p95, and a mean
    # well below the max.
    assert 0.02 < report.deviation_p95 < report.deviation_max
    assert 0.0 < report.deviation_mean < report.deviation_p95
    again = decomposition_report(l_shape, hull, samples=20000, seed=3)
    assert again.to_dict() | {"report_seconds": 0} == report.to_dict() | {"report_seconds": 0}
    json.dumps(report.to_dict(), allow_nan=False)


def test_report_counts_internal_walls_and_exact_parts_as_zero() -> None:
    # Two boxes glued face to face without a union: coincident faces of opposite orientation
    # inside the solid (an internal double wall, as in real meshes). Ray parity and the
    # closest face's normal misjudge points near such walls; the winding number does not.
    left = _box([0.1, 0.1, 0.1], [-0.05, 0.0, 0.0])
    right = _box([0.1, 0.1, 0.1], [0.05, 0.0, 0.0])
    glued = trimesh.util.concatenate([left, right])
    assert glued.is_volume
    parts = tuple(
        ConvexPart(kind="box", pose=trimesh.transformations.translation_matrix(c), size=[0.05] * 3)
        for c in ([-0.05, 0.0, 0.0], [0.05, 0.0, 0.0])
    )
    report = decomposition_report(glued, parts, samples=5000)
    assert report.deviation_max < 1e-9
    assert report.extra_volume == pytest.approx(0.0, abs=0.01)
    probe = np.array([[0.001, 0.0, 0.0], [-0.0005, 0.02, 0.01], [0.0, 0.0, 0.0501]])
    np.testing.assert_array_equal(dec._TriangleTree(glued)(probe) > 0.5, [True, True, False])


def test_report_rejects_bad_input(l_shape: trimesh.Trimesh) -> None:
    hull = (ConvexPart(kind="mesh", pose=np.eye(4), vertices=l_shape.convex_hull.vertices),)
    with pytest.raises(MeshError, match=r"expected at least one convex part, found none"):
        decomposition_report(l_shape, ())
    with pytest.raises(MeshError, match=r"samples: expected an integer >= 100, found 10"):
        decomposition_report(l_shape, hull, samples=10)
    with pytest.raises(MeshError, match=r"parts\[0\]: expected a ConvexPart, found ndarray"):
        decomposition_report(l_shape, (np.zeros((4, 3)),))  # type: ignore[arg-type]


def test_winding_number_is_exact_near_and_far(thin_table: trimesh.Trimesh) -> None:
    rng = np.random.default_rng(5)
    lo, hi = thin_table.bounds
    points = lo - 0.05 + rng.random((600, 3)) * (hi - lo + 0.1)
    tree = dec._TriangleTree(thin_table)
    fast = tree(points)
    exact = _brute_winding(thin_table, points)
    np.testing.assert_allclose(fast, exact, atol=0.1)
    np.testing.assert_array_equal(fast > 0.5, exact > 0.5)


def _brute_winding(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Sum of the solid angles of all faces over 4 pi (van Oosterom and Strackee)."""
    result = []
    for p in points:
        a, b, c = (mesh.triangles[:, k] - p for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        numerator = np.einsum("ij,ij->i", a, np.cross(b, c))
        denominator = (
            la * lb * lc
            + np.einsum("ij,ij->i", a, b) * lc
            + np.einsum("ij,ij->i", b, c) * la
            + np.einsum("ij,ij->i", c, a) * lb
        )
        result.append(np.sum(2 * np.arctan2(numerator, denominator)) / (4 * np.pi))
    return np.array(result)


def test_cache_key_changes_with_preprocess_and_every_knob(l_shape: trimesh.Trimesh) -> None:
    v, f = np.asarray(l_shape.vertices), np.asarray(l_shape.faces)
    base = mesh_digest(v, f, FAST)
    changed = {
        "preprocess": "on",
        "merge": False,
        "decimate": True,
        "max_ch_vertex": 64,
    }
    digests = {
        key: mesh_digest(v, f, DecompositionParameters(**{**FAST.to_dict(), key: value}))
        for key, value in changed.items()
    }
    assert base not in digests.values()
    assert len(set(digests.values())) == len(changed)
    assert set(FAST.to_dict()) >= {"preprocess", "merge", "decimate", "max_ch_vertex"}


def test_parts_to_obj_writes_one_object_per_hull(tmp_path: Path) -> None:
    parts = (
        ConvexPart(kind="mesh", pose=np.eye(4), vertices=trimesh.creation.box().vertices),
        ConvexPart(kind="box", pose=np.eye(4), size=[0.1, 0.2, 0.3]),
    )
    text = parts_to_obj(parts)
    assert text.count("\no hull_") == 2
    path = tmp_path / "hulls.obj"
    path.write_text(text)
    scene = trimesh.load_scene(path, split_objects=True, group_material=False)
    meshes = list(scene.geometry.values())
    assert len(meshes) == 2
    assert all(m.is_volume for m in meshes)
    assert sorted(round(m.volume, 6) for m in meshes) == [0.048, 1.0]


def _write_l(path: Path, l_shape: trimesh.Trimesh) -> Path:
    l_shape.export(path)
    return path


def test_cli_decompose_prints_reports_and_writes_files(
    l_shape: trimesh.Trimesh, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mesh = _write_l(tmp_path / "ell.obj", l_shape)
    out, report, cache = tmp_path / "out", tmp_path / "all.json", tmp_path / "cache"
    argv = ["objects", "decompose", str(mesh), "--threshold", "0.05", "--samples", "2000"]
    argv += ["--out", str(out), "--json", str(report), "--cache-dir", str(cache)]
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    line = next(x for x in lines if x.startswith(str(mesh)))
    assert "26 faces, watertight, preprocess off;" in line
    assert re.search(r"\d+ hulls; deviation max \d+\.\d\d / p95 \d+\.\d\d / mean", line)
    assert re.search(r"extra volume [+-]\d+\.\d%", line)
    assert ", cached in " in line
    assert str(cache) in line
    assert sorted(p.name for p in out.iterdir()) == ["ell.json", "ell.obj"]
    hulls = trimesh.load_scene(out / "ell.obj", split_objects=True, group_material=False)
    entry = json.loads((out / "ell.json").read_text())
    assert entry["report"]["hulls"] == len(hulls.geometry) >= 2
    assert entry["parameters"]["threshold"] == 0.05
    assert entry["parameters"]["preprocess"] == "auto"
    assert entry["report"]["preprocess"] == "off"
    everything = json.loads(report.read_text())
    assert everything["format"] == "dg16m-decomposition"
    assert [m["mesh"] for m in everything["meshes"]] == [str(mesh)]
    # Second run: a cache hit, same hulls.
    assert main(argv) == 0
    assert "(cache hit " in capsys.readouterr().out
    assert json.loads((out / "ell.json").read_text())["report"]["hulls"] == entry["report"]["hulls"]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--threshold", "2"], r"--threshold: expected a number in \(0, 1\], found 2\.0"),
        (["--threshold", "0"], r"--threshold: expected a number in \(0, 1\], found 0\.0"),
        (["--samples", "5"], r"--samples: expected an integer >= 100, found 5"),
        (["MISSING"], r"MISSING\.obj: no such file"),
        (["BROKEN"], r"BROKEN\.obj: expected a triangle mesh, found PointCloud"),
    ],
)
def test_cli_decompose_bad_input_exits_2_and_writes_nothing(
    l_shape: trimesh.Trimesh,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    message: str,
) -> None:
    good = _write_l(tmp_path / "ell.obj", l_shape)
    (tmp_path / "broken.obj").write_text("v 0 0 0\nv 1 0 0\n")
    names = {"MISSING": str(tmp_path / "missing.obj"), "BROKEN": str(tmp_path / "broken.obj")}
    extra = [names.get(x, x) for x in extra]
    message = message.replace("MISSING", "missing").replace("BROKEN", "broken")
    out, report = tmp_path / "out", tmp_path / "all.json"
    argv = ["objects", "decompose", str(good), *extra, "--out", str(out), "--json", str(report)]
    argv += ["--cache-dir", str(tmp_path / "cache")]
    assert main(argv) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("dg16m objects: error: ")
    assert re.search(message, err[0])
    assert not out.exists()
    assert not report.exists()
    assert not (tmp_path / "cache").exists()


def test_cli_decompose_rejects_bad_preprocess_and_has_examples(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit) as info:
        main(["objects", "decompose", "x.obj", "--preprocess", "maybe"])
    assert info.value.code == 2
    assert "invalid choice: 'maybe'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:
        main(["objects", "decompose", "--help"])
    assert info.value.code == 0
    text = capsys.readouterr().out
    assert "examples:" in text
    assert "dg16m objects decompose" in text


def test_cli_decompose_rejects_clashing_outputs_before_any_work(
    l_shape: trimesh.Trimesh, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first = _write_l(tmp_path / "a" / "ell.obj", l_shape)
    second = _write_l(tmp_path / "b" / "ell.obj", l_shape)
    cache = tmp_path / "cache"
    out = tmp_path / "out"
    argv = ["objects", "decompose", str(first), str(second), "--cache-dir", str(cache)]
    assert main([*argv, "--out", str(out)]) == 2
    assert "--out: expected mesh files with distinct names" in capsys.readouterr().err
    a_file = tmp_path / "file.txt"
    a_file.write_text("keep")
    assert main([*argv[:3], "--out", str(a_file)]) == 2
    assert "--out: expected a folder, found the file" in capsys.readouterr().err
    assert main([*argv[:3], "--json", str(tmp_path / "a")]) == 2
    assert "--json: expected a file name, found the folder" in capsys.readouterr().err
    assert a_file.read_text() == "keep"
    assert not out.exists()
    assert not cache.exists()
