"""Issue 55, items 4, 5 and 6 (first half): models stand upright, one units rule, ``objects
check DIR``.

Small meshes written in ``tmp_path``: a tall thin post modelled y up (as OBJ files are by
convention), a 100-unit bar, a 1.9-unit table of a unitless format, an empty file. Boxes are one
watertight body within the face budget, so ``objects repair`` only turns and scales them and the
vertex mapping can be checked exactly.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from dataset_gen.objects.grasp_object import guess_units, large_guess_warning, load_object
from dataset_gen.real import sweethome3d
from dataset_gen.real.orientation import (
    DG16M_KINDS,
    Y_UP_TO_Z_UP,
    build_up_note,
    turn_z_up,
    up_axis,
)
from dataset_gen.real.own_meshes import REPAIR_KIND, decide_units
from dg16m_core.cli import main
from dg16m_core.errors import MeshError

FAST = ["--pitch-fraction", "0.05", "--no-progress"]


def y_up_post() -> trimesh.Trimesh:
    """A 0.2 x 0.1 m post 1 m tall, modelled y up (tall along +y), standing on y = 0 and set
    off the origin along z so that the turn's sign shows."""
    post = trimesh.creation.box(extents=(0.2, 1.0, 0.1))
    post.apply_translation((0.0, 0.5, 0.3))
    return post


def _entries(out: Path) -> dict:
    return json.loads((out / "manifest.json").read_text())["entries"]


def test_the_turn_is_a_right_handed_quarter_turn_about_x() -> None:
    assert np.linalg.det(Y_UP_TO_Z_UP) == pytest.approx(1.0)
    assert np.allclose(Y_UP_TO_Z_UP @ Y_UP_TO_Z_UP.T, np.eye(3))
    assert np.allclose(Y_UP_TO_Z_UP @ [0, 1, 0], [0, 0, 1])  # up stays up
    assert np.allclose(Y_UP_TO_Z_UP @ [0, 0, 1], [0, -1, 0])  # the front (+z) turns to -y
    post = y_up_post()
    turned = turn_z_up(post, "y")
    assert turned.volume == pytest.approx(post.volume)  # a rotation: winding stays outward
    assert np.argmax(turned.extents) == 2
    assert turn_z_up(post, "z") is post
    with pytest.raises(MeshError, match="--up: expected one of y, z, found 'x'"):
        turn_z_up(post, "x")
    # the Sweet Home 3D importer turns its models with the same matrix, and the folders it and
    # objects repair write are known z up
    assert sweethome3d.Y_UP_TO_Z_UP is Y_UP_TO_Z_UP
    assert {REPAIR_KIND, sweethome3d.IMPORT_KIND} <= set(DG16M_KINDS)


def test_a_y_up_obj_comes_out_z_up_and_up_z_keeps_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    raw = tmp_path / "raw"
    raw.mkdir()
    post = y_up_post()
    post.export(raw / "post.obj")
    out = tmp_path / "out"
    assert main(["objects", "repair", str(raw), "--out", str(out), *FAST]) == 0
    text = capsys.readouterr().out
    assert "up axis y (assumed: OBJ files are y up by convention; pass --up z if wrong)" in text
    assert "turned z up (+90 deg about x)" in text
    entry = _entries(out)["post"]
    assert entry["up"]["axis"] == "y"
    assert entry["up"]["how"] == "assumed"
    assert entry["request"]["up"] == "auto"
    assert any(op.startswith("turned from y up to z up") for op in entry["operations"])
    repaired = trimesh.load(out / "post.obj", process=False, force="mesh")
    assert "metres, z up" in (out / "post.obj").read_text().splitlines()[0]
    # the vertex mapping: (x, y, z) -> (x, -z, y), nothing else (a 1-unit post is metres)
    expected = np.asarray(post.vertices) @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]).T
    assert np.allclose(np.sort(repaired.vertices, axis=0), np.sort(expected, axis=0))
    assert np.allclose(repaired.bounds, [[-0.1, -0.35, 0.0], [0.1, -0.25, 1.0]])
    assert np.argmax(repaired.extents) == 2  # the tall post stands: longest along z

    # a rerun with another --up redoes the mesh (never kept from the other setting)
    assert main(["objects", "repair", str(raw), "--out", str(out), "--up", "z", *FAST]) == 0
    text = capsys.readouterr().out
    assert "1 meshes: 1 repaired, 0 failed" in text
    assert "up axis z (given: --up z), kept z up" in text
    kept = trimesh.load(out / "post.obj", process=False, force="mesh")
    assert np.allclose(kept.bounds, post.bounds)
    assert _entries(out)["post"]["up"]["how"] == "given"

    # an entry written before the up axis existed (no "up" in its request) is redone too
    manifest = json.loads((out / "manifest.json").read_text())
    del manifest["entries"]["post"]["request"]["up"]
    (out / "manifest.json").write_text(json.dumps(manifest))
    assert main(["objects", "repair", str(raw), "--out", str(out), "--up", "z", *FAST]) == 0
    assert "1 meshes: 1 repaired, 0 failed" in capsys.readouterr().out
    assert main(["objects", "repair", str(raw), "--out", str(out), "--up", "z", *FAST]) == 0
    assert "1 meshes: 0 repaired, 1 kept from an earlier run" in capsys.readouterr().out


def test_the_axis_auto_assumes_or_detects(tmp_path: Path) -> None:
    box = trimesh.creation.box(extents=(0.5, 0.4, 0.3))
    for name, axis, how in (
        ("a.obj", "y", "assumed"),
        ("a.glb", "y", "assumed"),
        ("a.stl", "z", "assumed"),
        ("a.ply", "z", "assumed"),
        ("a.off", "z", "assumed"),
    ):
        box.export(tmp_path / name)
        found = up_axis(tmp_path / name)
        assert (found.axis, found.how) == (axis, how), name
    dae = tmp_path / "z.dae"
    dae.write_text("<COLLADA><asset><up_axis>Z_UP</up_axis></asset></COLLADA>")
    assert (up_axis(dae).axis, up_axis(dae).how) == ("z", "detected")
    dae.write_text("<COLLADA><asset></asset></COLLADA>")
    assert (up_axis(dae).axis, up_axis(dae).how) == ("y", "assumed")
    written = tmp_path / "mine.obj"
    written.write_text(
        "# mine: repaired by dg16m objects repair, metres, z up\n" + box.export(file_type="obj")
    )
    assert (up_axis(written).axis, up_axis(written).how) == ("z", "detected")
    assert up_axis(tmp_path / "a.obj", "z").how == "given"
    with pytest.raises(MeshError, match="--up: expected one of auto, y, z"):
        up_axis(tmp_path / "a.obj", "x")


def test_objects_check_takes_a_folder_and_reports_the_axis(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    raw = tmp_path / "raw"
    raw.mkdir()
    y_up_post().export(raw / "post.obj")
    trimesh.creation.box(extents=(0.6, 0.4, 0.3)).export(raw / "crate.stl")
    (raw / "post.mtl").write_text("newmtl wood\n")
    assert main(["objects", "check", str(raw)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"found 2 mesh files in {raw} (skipped 1 other files)"
    text = "\n".join(lines)
    assert f"ok   {raw / 'crate.stl'}" in text
    assert f"ok   {raw / 'post.obj'}" in text
    assert (
        "up axis z (assumed: STL files are z up by convention (CAD, 3D printing); pass --up y "
        "if wrong): 0.300 m tall along z; stands as 'benchmark build' reads it"
    ) in text
    assert (
        "up axis y (assumed: OBJ files are y up by convention; pass --up z if wrong): 1.000 m "
        "tall along y; 'benchmark build' reads files z up, so it would lie on its side"
    ) in text
    assert "2 meshes: 2 solid, 0 shell, 0 failed" in text
    assert "1 y up (post): 'benchmark build' would simulate them on their side" in text
    assert main(["objects", "check", str(raw), "--up", "z"]) == 0
    text = capsys.readouterr().out
    assert text.count("up axis z (given: --up z)") == 2
    assert "y up (" not in text
    # the repaired folder: z up and metres, as dg16m wrote them
    out = tmp_path / "out"
    assert main(["objects", "repair", str(raw), "--out", str(out), *FAST]) == 0
    capsys.readouterr()
    assert main(["objects", "check", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"found 2 mesh files in {out} (skipped 1 other files)" in text
    assert text.count("up axis z (detected: a folder written by dg16m (mesh-repair), z up)") == 2
    assert "1.000 m tall along z" in text
    assert text.count("units: metres (a folder written by dg16m (mesh-repair))") == 2
    assert build_up_note(out) == "up axis: every mesh read z up (2 meshes)"
    assert "1 of 2 may be y up (post.obj: OBJ files are y up by convention)" in build_up_note(raw)
    # nothing to check is bad input (exit 2), with what was found
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "notes.txt").write_text("x")
    assert main(["objects", "check", str(empty)]) == 2
    assert "expected mesh files (.obj, .stl, .ply, .off, .glb, .gltf), found none" in (
        capsys.readouterr().err
    )


def test_one_units_rule_for_repair_check_and_build(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A 100-unit bar: 1 m in centimetres for repair, check and the build's size check alike."""
    raw = tmp_path / "raw"
    raw.mkdir()
    trimesh.creation.box(extents=(100.0, 1.0, 0.5)).export(raw / "bar.stl")
    assert guess_units(100.0) == "cm"
    assert decide_units(100.0).units == "cm"
    out = tmp_path / "out"
    assert main(["objects", "repair", str(raw), "--out", str(out), *FAST]) == 0
    assert "units guessed: centimetres (100 units -> 1 m" in capsys.readouterr().out
    assert _entries(out)["bar"]["units"]["scale"] == pytest.approx(0.01)
    assert main(["objects", "check", str(raw / "bar.stl")]) == 1
    assert "a file in centimetres needs --scale 0.01 (1 m, " in capsys.readouterr().out
    with pytest.raises(MeshError, match=r"a file in centimetres needs --scale 0\.01 \(1 m, "):
        load_object(raw / "bar.stl")  # what benchmark build and generate load meshes with
    assert main(["objects", "check", str(raw / "bar.stl"), "--units", "cm"]) == 0
    text = capsys.readouterr().out
    assert "units given: centimetres" in text
    assert "1.000 x 0.010 x 0.005 m (scale 0.01)" in text


def test_a_table_sized_guess_of_a_unitless_file_is_warned_about(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    raw = tmp_path / "raw"
    raw.mkdir()
    trimesh.creation.box(extents=(1.9, 0.9, 0.75)).export(raw / "table.stl")  # z up
    trimesh.creation.box(extents=(1.2, 0.6, 0.75)).export(raw / "desk.stl")
    out = tmp_path / "out"
    assert main(["objects", "repair", str(raw), "--out", str(out), *FAST]) == 0
    text = capsys.readouterr().out
    warning = (
        "WARNING guessed metres: the object is 1.9 m long (1.90 x 0.90 x 0.75 m), large for two "
        "arms, and STL files have no units; pass --units m|cm|mm|inch if that is wrong"
    )
    assert text.count(warning) == 1
    entries = _entries(out)
    assert entries["table"]["warnings"] == [warning.removeprefix("WARNING ")]
    assert "warnings" not in entries["desk"]
    assert main(["objects", "check", str(raw)]) == 0  # the same warning, from the same rule
    assert capsys.readouterr().out.count(warning) == 1
    # given units, or a format with units, are not warned about
    assert main(["objects", "check", str(raw), "--units", "m"]) == 0
    assert "WARNING" not in capsys.readouterr().out
    assert large_guess_warning("m", (1.9, 0.9, 0.75), ".glb") is None
    assert large_guess_warning("m", (1.4, 0.9, 0.75), ".obj") is None


def test_an_empty_or_broken_file_gets_its_own_error_and_no_units_advice(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    raw = tmp_path / "raw"
    raw.mkdir()
    (raw / "empty.obj").write_bytes(b"")
    (raw / "points.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    out = tmp_path / "out"
    assert main(["objects", "repair", str(raw), "--out", str(out), *FAST]) == 1
    captured = capsys.readouterr()
    assert "FAIL empty.obj: expected a mesh with faces, found an empty file (0 bytes)" in (
        captured.out
    )
    assert "--units" not in captured.out + captured.err
    assert "2 failed: empty, points (reasons above and in the manifest)" in captured.err
    assert {e["error_kind"] for e in _entries(out).values()} == {"mesh"}
    assert main(["objects", "check", str(raw)]) == 1
    captured = capsys.readouterr()
    assert "expected a mesh with faces, found an empty file (0 bytes)" in captured.out
    assert "--units" not in captured.out + captured.err
    # a units failure is the one told to rerun with --units
    trimesh.creation.box(extents=(9.02, 4.5, 4.5)).export(raw / "chair.obj")
    assert main(["objects", "repair", str(raw), "--out", str(out), *FAST]) == 1
    err = capsys.readouterr().err
    assert "rerun chair alone with its own --units or --target-extent" in err
    assert _entries(out)["chair"]["error_kind"] == "units"
