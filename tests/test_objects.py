"""Loading, cleaning, validating, centring, scaling and mass properties of objects."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from dataset_gen.objects.grasp_object import (
    ConvexPart,
    clean_mesh,
    is_rigid,
    load_mesh,
    load_object,
    make_object,
    mass_properties,
    part_from_dict,
    parts_to_mesh,
)
from dg16m_core.errors import MeshError

BOX_EXTENTS = (0.4, 0.2, 0.1)


def _box() -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=BOX_EXTENTS)
    box.apply_translation([1.0, 2.0, 3.0])  # off-centre, to see centring
    return box


@pytest.mark.parametrize("suffix", [".obj", ".stl", ".ply", ".off", ".glb"])
def test_each_format_loads_a_closed_box(tmp_path: Path, suffix: str) -> None:
    path = tmp_path / f"box{suffix}"
    _box().export(path)
    obj = load_object(path)
    assert obj.is_watertight
    np.testing.assert_allclose(sorted(obj.extents), sorted(BOX_EXTENTS), atol=1e-6)
    np.testing.assert_allclose(obj.mesh.centroid, 0.0, atol=1e-9)
    np.testing.assert_allclose(obj.offset, [-1.0, -2.0, -3.0], atol=1e-6)
    assert obj.mass_properties.model == "solid"
    assert obj.mass_properties.volume == pytest.approx(0.4 * 0.2 * 0.1, rel=1e-5)  # STL is float32
    assert obj.object_id == "box"


def test_scene_geometries_are_concatenated_with_their_transforms(tmp_path: Path) -> None:
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.creation.box(extents=(0.1, 0.1, 0.1)), node_name="a")
    scene.add_geometry(
        trimesh.creation.box(extents=(0.1, 0.1, 0.1)),
        node_name="b",
        transform=trimesh.transformations.translation_matrix([0.5, 0, 0]),
    )
    path = tmp_path / "two.glb"
    scene.export(path)
    mesh, _ = load_mesh(path)
    assert len(mesh.split(only_watertight=False)) == 2
    assert mesh.extents[0] == pytest.approx(0.6, abs=1e-6)


def test_stl_soup_is_merged_into_a_watertight_mesh(tmp_path: Path) -> None:
    path = tmp_path / "box.stl"
    _box().export(path)
    mesh, report = load_mesh(path)
    assert mesh.is_watertight
    assert report.merged_vertices > 0  # STL stores 3 vertices per triangle


def test_duplicate_and_degenerate_faces_are_cleaned() -> None:
    box = _box()
    faces = np.concatenate([box.faces, box.faces[:3], [[0, 0, 1]]])
    mesh, report = clean_mesh(box.vertices, faces, name="dup")
    assert report.duplicate_faces == 3
    assert report.degenerate_faces == 1
    assert len(mesh.faces) == len(box.faces)
    assert mesh.is_watertight


# A corpus of broken meshes: each must give its own clear error naming the defect.
def _write(path: Path, content: str | bytes) -> Path:
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return path


TETRA = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"
BROKEN = {
    "missing": (None, "no such file"),
    "directory": ("DIR", "found a directory"),
    "unsupported.xyz": ("1 2 3\n", "unsupported mesh format '.xyz'"),
    "empty.obj": ("", r"expected a mesh with faces, found an empty file \(0 bytes\)"),
    "points_only.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces"),
    "nan.obj": (TETRA.replace("v 0 1 0", "v nan 1 0"), "1 vertices with NaN"),
    "inf.obj": (TETRA.replace("v 0 0 1", "v 0 0 inf"), "0 vertices with NaN and 1 with inf"),
    "degenerate.obj": (
        "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\n",
        "all 2 faces are degenerate",
    ),
    "flat.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n", "flat mesh .*along z"),
    "bad_index.obj": (TETRA + "f 1 2 9\n", "could not be parsed as OBJ"),
    "junk.stl": (bytes(range(256)) * 12, "expected triangle geometry, found nothing readable"),
    "truncated.off": ("OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n", "could not be parsed as OFF"),
    "text.glb": ("hello, not a binary glTF\n", "could not be parsed as GLB"),
    "truncated.ply": (
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n",
        "no faces",
    ),
}


@pytest.mark.parametrize("name", sorted(BROKEN))
def test_broken_mesh_corpus_gives_clear_errors(tmp_path: Path, name: str) -> None:
    content, message = BROKEN[name]
    path = tmp_path / name
    if content == "DIR":
        path.mkdir()
    elif content is not None:
        _write(path, content)
    with pytest.raises(MeshError, match=message) as info:
        load_object(path)
    assert str(path) in str(info.value)  # the error names the file


def test_absurd_and_tiny_extents_are_rejected_with_a_hint(tmp_path: Path) -> None:
    path = tmp_path / "big.obj"
    trimesh.creation.box(extents=(720.0, 340.0, 600.0)).export(path)
    with pytest.raises(MeshError, match=r"longest side 720 m: .*needs --scale 0\.001"):
        load_object(path)
    with pytest.raises(MeshError, match=r"at most 100 m, found 720 m.*scale=0.001"):
        load_object(path, allow_any_size=True)  # the hard limits hold even with the override
    obj = load_object(path, scale=0.001)
    assert obj.extents.max() == pytest.approx(0.72)
    with pytest.raises(MeshError, match=r"at least 0\.001 m"):
        load_object(path, scale=1e-9, allow_any_size=True)


def test_a_box_in_millimetres_is_not_an_80_m_object(tmp_path: Path) -> None:
    """An 80 mm box exported in millimetres reads as 80 m: refused, with the scale the one units
    rule gives 80 units (0.8 m in centimetres, what 'objects repair' guesses too)."""
    path = tmp_path / "box_mm.obj"
    trimesh.creation.box(extents=(80.0, 50.0, 30.0)).export(path)
    with pytest.raises(MeshError) as info:
        load_object(path)
    message = str(info.value)
    assert message.startswith(f"{path}: longest side 80 m: expected 0.05-5 m for a dual-arm")
    assert "a file in centimetres needs --scale 0.01 (0.8 m, the only unit giving" in message
    assert "--allow-any-size" in message
    assert load_object(path, scale=0.001).extents.max() == pytest.approx(0.08)
    assert load_object(path, allow_any_size=True).extents.max() == pytest.approx(80.0)


@pytest.mark.parametrize(
    ("extents", "scale", "hint"),
    [
        ((0.8, 0.5, 0.3), 0.001, "seems to be in metres already, so --scale 0.001 looks wrong"),
        ((8.0, 5.0, 3.0), None, "cannot guess the units (8 m in metres, 0.08 m in centimetres"),
        ((100.0, 1.0, 0.5), None, "a file in centimetres needs --scale 0.01 (1 m"),
        ((0.02, 0.01, 0.01), None, "pass --scale or --target-extent"),
        ((1e5, 1.0, 1.0), None, "pass --scale or --target-extent"),
    ],
)
def test_implausible_sizes_suggest_a_scale(
    tmp_path: Path, extents: tuple[float, ...], scale: float | None, hint: str
) -> None:
    path = tmp_path / "mesh.obj"
    trimesh.creation.box(extents=extents).export(path)
    with pytest.raises(MeshError, match=r"expected 0\.05-5 m for a dual-arm object") as info:
        load_object(path, scale=scale)
    assert hint in str(info.value)


def test_dual_arm_range_constants_match_the_messages() -> None:
    from dataset_gen.objects.grasp_object import DUAL_ARM_MAX_EXTENT_M, DUAL_ARM_MIN_EXTENT_M

    assert (DUAL_ARM_MIN_EXTENT_M, DUAL_ARM_MAX_EXTENT_M) == (0.05, 5.0)


def test_target_extent_outside_the_dual_arm_range_needs_the_override(tmp_path: Path) -> None:
    path = tmp_path / "box.obj"
    _box().export(path)
    with pytest.raises(MeshError, match="choose a --target-extent in that range"):
        load_object(path, target_extent=10.0)
    assert load_object(path, target_extent=10.0, allow_any_size=True).extents.max() == (
        pytest.approx(10.0)
    )


@pytest.mark.real_data
def test_the_shared_real_meshes_pass_the_size_check(real_data: Path) -> None:
    """The release airplane (0.72 m) and the ACRONYM mug (0.10 m) and table (0.20 m) at their
    files' scales are all within the dual-arm range: the check keeps the real data working."""
    from dataset_gen import io

    sizes = {"dg16m_airplane": load_object(real_data / "dg16m_airplane.obj").extents.max()}
    for name in ("acronym_mug_10f6e090", "acronym_table_99cf659a"):
        scale = io.read_acronym(real_data / f"{name}.h5").object_scale
        sizes[name] = load_object(real_data / f"{name}.obj", scale=scale).extents.max()
    assert sizes["dg16m_airplane"] == pytest.approx(0.72, abs=0.01)
    assert sizes["acronym_mug_10f6e090"] == pytest.approx(0.101, abs=0.002)
    assert sizes["acronym_table_99cf659a"] == pytest.approx(0.199, abs=0.002)


def test_target_extent_and_scale_are_exclusive(tmp_path: Path) -> None:
    path = tmp_path / "box.obj"
    _box().export(path)
    obj = load_object(path, target_extent=1.0)
    assert obj.extents.max() == pytest.approx(1.0)
    assert obj.scale == pytest.approx(2.5)
    with pytest.raises(MeshError, match="either scale or target_extent"):
        load_object(path, scale=2.0, target_extent=1.0)
    with pytest.raises(MeshError, match="positive"):
        load_object(path, scale=-1.0)


def test_file_to_object_maps_file_points(tmp_path: Path) -> None:
    path = tmp_path / "box.obj"
    box = _box()
    box.export(path)
    obj = load_object(path, scale=0.5)
    mapped = obj.file_to_object(box.vertices)
    assert trimesh.proximity.signed_distance(obj.mesh, mapped).__abs__().max() < 1e-9


def test_mass_properties_of_a_solid_box_match_the_formula() -> None:
    box = trimesh.creation.box(extents=(0.4, 0.2, 0.1))
    props = mass_properties(box, mass=6.0)
    a, b, c = 0.4, 0.2, 0.1
    expected = 6.0 / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    np.testing.assert_allclose(props.inertia, expected, atol=1e-12)
    np.testing.assert_allclose(props.center_of_mass, 0.0, atol=1e-12)
    assert props.density == pytest.approx(6.0 / (a * b * c))


def test_open_mesh_gets_a_shell_model_with_exact_inertia() -> None:
    # An open unit square in the xy plane: shell inertia m/12 (a^2 + b^2) about z.
    square = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]])
    props = mass_properties(square, mass=3.0)
    assert props.model == "shell"
    assert props.volume is None
    np.testing.assert_allclose(props.center_of_mass, [0.5, 0.5, 0.0], atol=1e-12)
    np.testing.assert_allclose(props.inertia[2, 2], 3.0 / 12.0 * 2.0, atol=1e-12)
    np.testing.assert_allclose(props.inertia[0, 0], 3.0 / 12.0, atol=1e-12)


def test_parts_follow_scaling_and_centring() -> None:
    parts = [
        ConvexPart("box", np.eye(4), (0.5, 0.05, 0.05)),
        ConvexPart(
            "cylinder", trimesh.transformations.translation_matrix([0.5, 0, 0.2]), (0.03, 0.2)
        ),
    ]
    union = parts_to_mesh(parts)
    assert union.is_watertight
    obj = make_object(union, object_id="t", parts=parts, scale=2.0)
    placed = parts_to_mesh(obj.parts)
    np.testing.assert_allclose(placed.bounds, obj.mesh.bounds, atol=1e-6)
    assert part_from_dict(obj.parts[1].to_dict()).size == pytest.approx((0.06, 0.4))


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"kind": "sphere", "pose": np.eye(4).tolist(), "size": [1]}, "expected one of"),
        ({"kind": "box", "pose": np.eye(4).tolist(), "size": [1, 1]}, "expected 3 positive"),
        ({"kind": "box", "pose": (2 * np.eye(4)).tolist(), "size": [1, 1, 1]}, "rigid"),
        ({"kind": "box"}, "with 'kind' and 'pose'"),
        ({"kind": "mesh", "pose": np.eye(4).tolist(), "vertices": [[0, 0, 0]]}, "V>=4"),
    ],
)
def test_malformed_parts_are_rejected(data: dict, message: str) -> None:
    with pytest.raises(MeshError, match=message):
        part_from_dict(data)


def test_is_rigid_mask() -> None:
    T = np.stack([np.eye(4)] * 4)
    T[1, :3, :3] *= 1.01  # scaled
    T[2, 0, 0] = -1.0  # reflection
    T[3, 0, 3] = np.nan
    assert is_rigid(T).tolist() == [True, False, False, False]
    assert is_rigid(np.eye(4)) is True


@pytest.mark.real_data
def test_real_airplane_mesh_matches_the_release_frame(real_data: Path) -> None:
    import h5py

    obj = load_object(real_data / "dg16m_airplane.obj")
    assert not obj.is_watertight
    assert obj.mass_properties.model == "shell"
    np.testing.assert_allclose(obj.extents, [0.720653, 0.339507, 0.604479], atol=1e-6)
    with h5py.File(real_data / "dg16m_airplane.h5", "r") as handle:
        contacts = handle["grasps/contact_points"][:200].reshape(-1, 3)
    _, distance, _ = trimesh.proximity.closest_point(obj.mesh, contacts)
    assert distance.max() < 1e-9  # stored contacts lie on the mesh translated by -centroid


def test_contact_sheet_tick_labels_do_not_touch() -> None:
    """Each small 3D view's tick labels stand apart (they ran together at five ticks a side)."""
    from dataset_gen.pipeline.render import _setup_axes
    from dataset_gen.sources.procedural import make_procedural_object
    from dg16m_core.figures import new_figure

    fig = new_figure(3.0, 3.0)
    ax = fig.add_subplot(1, 1, 1, projection="3d")
    _setup_axes(ax, make_procedural_object("bench", 0).mesh, None, (25.0, -60.0))
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        lo, hi = sorted(axis.get_view_interval())
        shown = [
            t
            for t, at in zip(axis.get_ticklabels(), axis.get_majorticklocs(), strict=True)
            if lo <= at <= hi and t.get_text()
        ]
        boxes = [t.get_window_extent(renderer) for t in shown]
        assert 2 <= len(boxes) <= 4
        for i, a in enumerate(boxes):
            assert not any(a.overlaps(b) for b in boxes[i + 1 :]), a
