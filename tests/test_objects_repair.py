"""``dg16m objects repair`` (issue 41, part 1) and ``objects check``'s solid or shell (part 4).

Small meshes made with trimesh in ``tmp_path``: a table in pieces with a hole (a shell), the same
table in centimetres, a chair box in millimetres, a 9.02-unit chair whose units cannot be
guessed, and broken files among good ones. The repairs run on a coarse voxel grid
(``--pitch-fraction 0.05``) to stay fast; the settings are the importer's otherwise.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from dataset_gen.real.own_meshes import REPAIR_KIND, TYPICAL_EXTENT_M, decide_units
from dg16m_core.cli import main
from dg16m_core.errors import MeshError

FAST = ["--pitch-fraction", "0.05", "--no-progress"]


def table(scale: float = 1.0) -> trimesh.Trimesh:
    """A 0.8 x 0.5 x 0.74 m table as five overlapping boxes, its top missing two faces: not
    watertight, five pieces (what furniture files look like)."""
    top = trimesh.creation.box(extents=(0.8, 0.5, 0.04))
    top.apply_translation((0.0, 0.0, 0.72))
    top = trimesh.Trimesh(top.vertices, top.faces[2:], process=False)
    legs = [
        trimesh.creation.box(extents=(0.05, 0.05, 0.72)).apply_translation((x, y, 0.36))
        for x in (-0.35, 0.35)
        for y in (-0.2, 0.2)
    ]
    mesh = trimesh.util.concatenate([top, *legs])
    mesh.apply_scale(scale)
    return mesh


def _manifest(out: Path) -> dict:
    data = json.loads((out / "manifest.json").read_text())
    assert data["kind"] == REPAIR_KIND
    return data


def _one_solid(path: Path) -> trimesh.Trimesh:
    mesh = trimesh.load(path, force="mesh")
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.volume > 0
    assert mesh.body_count == 1
    return mesh


def test_a_shell_a_centimetre_and_a_millimetre_mesh_become_solids_in_metres(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    raw = tmp_path / "raw"
    raw.mkdir()
    table().export(raw / "table.obj")  # metres, a shell in five pieces
    table(100.0).export(raw / "table_cm.stl")  # the same in centimetres
    trimesh.creation.box(extents=(900.0, 450.0, 450.0)).export(raw / "chair_mm.ply")
    (raw / "table.mtl").write_text("newmtl wood\n")  # beside OBJ files: skipped
    out = tmp_path / "repaired"
    assert main(["objects", "repair", str(raw), "--out", str(out), *FAST]) == 0
    text = capsys.readouterr().out
    assert "units guessed: metres" in text
    assert "units guessed: centimetres" in text
    assert "units guessed: millimetres" in text
    assert "skipped 1 files that are not meshes (.mtl)" in text
    assert "3 meshes: 3 repaired, 0 failed" in text
    assert f"dg16m benchmark build --meshes {out}" in text

    manifest = _manifest(out)
    assert sorted(manifest["entries"]) == ["chair_mm", "table", "table_cm"]
    assert sorted(p.name for p in out.iterdir()) == [
        "chair_mm.obj",
        "manifest.json",
        "table.obj",
        "table_cm.obj",
    ]
    for object_id, scale in (("table", 1.0), ("table_cm", 0.01), ("chair_mm", 0.001)):
        entry = manifest["entries"][object_id]
        assert entry["status"] == "ok"
        assert entry["units"]["how"] == "guessed"
        assert entry["units"]["scale"] == pytest.approx(scale)
        source = Path(entry["source"]["file"])
        assert entry["source"]["sha256"] == hashlib.sha256(source.read_bytes()).hexdigest()
        mesh = _one_solid(out / entry["files"]["mesh"])
        assert (
            entry["sha256"]
            == hashlib.sha256((out / entry["files"]["mesh"]).read_bytes()).hexdigest()
        )
        assert entry["faces"] == len(mesh.faces) <= 2500
        assert set(entry["deviation_m"]) >= {"to_source_mean", "to_source_p95", "from_source_p95"}
        assert all(np.isfinite(v) for v in entry["deviation_m"].values())
        assert any(op.startswith(f"scaled by {scale:.6g} ") for op in entry["operations"])
    shell = manifest["entries"]["table"]
    assert not shell["source"]["watertight"]
    assert shell["source"]["pieces"] == 5
    assert any(op.startswith("filled-voxel remesh") for op in shell["operations"])
    assert shell["deviation_m"]["to_source_p95"] < 0.05  # within 5 cm on a 5 cm voxel grid
    for object_id in ("table", "table_cm"):  # one body of the table's size, in metres
        extents = manifest["entries"][object_id]["extents_m"]
        assert np.allclose(sorted(extents), [0.5, 0.74, 0.8], atol=0.05)
    # a box that is one watertight body within the budget is only scaled, not remeshed
    chair = manifest["entries"]["chair_mm"]
    assert chair["repair"] is None
    assert "kept as it is" in chair["operations"][-1]
    assert np.allclose(sorted(chair["extents_m"]), [0.45, 0.45, 0.9])

    # what `benchmark build --meshes OUT` reads: every mesh loads in metres, no size complaint
    from dataset_gen.objects.grasp_object import load_object
    from dataset_gen.sources.object_source import mesh_sources

    sources = mesh_sources(out)
    assert [s.object_id for s in sources] == ["chair_mm", "table", "table_cm"]
    for source in sources:
        obj = load_object(source.mesh)
        assert obj.mass_properties.model == "solid"

    # a rerun keeps everything (nothing redone, same bytes)
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.suffix == ".obj"}
    assert main(["objects", "repair", str(raw), "--out", str(out), *FAST]) == 0
    assert "3 meshes: 0 repaired, 3 kept from an earlier run, 0 failed" in capsys.readouterr().out
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.suffix == ".obj"} == before


def test_units_given_or_a_target_extent(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    raw = tmp_path / "raw"
    raw.mkdir()
    trimesh.creation.box(extents=(30.0, 20.0, 10.0)).export(raw / "crate.obj")  # inches
    out = tmp_path / "out"
    assert main(["objects", "repair", str(raw), "--out", str(out), "--units", "inch", *FAST]) == 0
    assert "units given: inches (30 units -> 0.762 m)" in capsys.readouterr().out
    entry = _manifest(out)["entries"]["crate"]
    assert entry["units"]["scale"] == pytest.approx(0.0254)
    assert max(entry["extents_m"]) == pytest.approx(0.762, abs=1e-6)
    # the same file at another request is redone, not kept
    assert main(["objects", "repair", str(raw), "--out", str(out), "--target-extent", "0.5"]) == 0
    assert "1 meshes: 1 repaired, 0 failed" in capsys.readouterr().out
    assert max(_manifest(out)["entries"]["crate"]["extents_m"]) == pytest.approx(0.5, abs=1e-6)
    # given units that make an implausible size fail the mesh, naming file, size and flags
    assert main(["objects", "repair", str(raw), "--out", str(out), "--units", "mm"]) == 1
    text = capsys.readouterr().out
    assert "FAIL crate.obj: longest side 30 units, 0.03 m in millimetres: expected 0.05-5 m" in text
    assert "--target-extent" in text
    assert "(the earlier crate.obj stays)" in text  # nothing written is lost
    entry = _manifest(out)["entries"]["crate"]
    assert entry["status"] == "ok"
    assert entry["last_failure"]["request"]["units"] == "mm"
    assert max(entry["extents_m"]) == pytest.approx(0.5, abs=1e-6)
    _one_solid(out / "crate.obj")


def test_the_units_guess_refuses_ambiguous_sizes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A 9.02-unit chair is 9.02 m or 9.02 cm: neither is a chair, so ask (never 'use cm');
    an armchair of 2.1 units is not taken as 2.1 m; a 2.3 m sofa in centimetres (230 units)
    could be a 23 cm box in millimetres: ask."""
    for longest in (9.02, 2.1, 230.0, 0.2, 2500.0):
        with pytest.raises(MeshError, match="cannot guess the units") as info:
            decide_units(longest, name="chair.obj")
        message = str(info.value)
        assert message.startswith(f"chair.obj: longest side {longest:.4g} units")
        assert "--units m|cm|mm|inch or --target-extent METRES" in message
    with pytest.raises(MeshError) as info:
        decide_units(9.02)
    assert "(9.02 m in metres, 0.0902 m in centimetres, 9.02 mm in millimetres; none" in str(
        info.value
    )
    for longest, units in ((0.8, "m"), (80.0, "cm"), (900.0, "mm"), (200.0, "cm"), (300.0, "mm")):
        decision = decide_units(longest)
        assert (decision.how, decision.units) == ("guessed", units), longest
        assert TYPICAL_EXTENT_M[0] <= decision.longest_side_m <= TYPICAL_EXTENT_M[1]

    # objects check's scale hint follows the same rule: the 9.02-unit chair is asked about
    raw = tmp_path / "raw"
    raw.mkdir()
    trimesh.creation.box(extents=(9.02, 4.5, 4.5)).export(raw / "chair.obj")
    assert main(["objects", "check", str(raw / "chair.obj")]) == 1
    assert (
        "cannot guess the units (9.02 m in metres, 0.0902 m in centimetres, 9.02 mm in "
        "millimetres; none in the typical 0.3-2 m of a dual-arm object): pass --scale or "
        "--target-extent ('dg16m objects check' and 'objects repair' take --units m|cm|mm|inch"
    ) in capsys.readouterr().out

    # through the command: the chair fails with its reason, the others are repaired, exit 1;
    # the chair rerun alone with its size joins the same folder and nothing is lost
    trimesh.creation.box(extents=(80.0, 40.0, 40.0)).export(raw / "stool.obj")
    out = tmp_path / "out"
    assert main(["objects", "repair", str(raw), "--out", str(out), *FAST]) == 1
    captured = capsys.readouterr()
    assert "FAIL chair.obj: longest side 9.02 units: cannot guess the units" in captured.out
    assert "1 failed: chair" in captured.err
    assert _manifest(out)["entries"]["chair"]["status"] == "failed"
    stool = (out / "stool.obj").read_bytes()
    chair = raw / "chair.obj"
    assert main(["objects", "repair", str(chair), "--out", str(out), "--target-extent", "0.9"]) == 0
    entries = _manifest(out)["entries"]
    assert entries["chair"]["status"] == "ok"
    assert entries["stool"]["status"] == "ok"
    assert max(entries["chair"]["extents_m"]) == pytest.approx(0.9, abs=1e-6)
    assert (out / "stool.obj").read_bytes() == stool


def test_broken_files_fail_alone(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    raw = tmp_path / "raw"
    raw.mkdir()
    trimesh.creation.box(extents=(0.6, 0.4, 0.4)).export(raw / "a_box.obj")
    (raw / "b_empty.obj").write_bytes(b"")
    (raw / "c_points.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    (raw / "d_nan.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n")
    (raw / "e_garbage.glb").write_bytes(b"glTF\x02\x00\x00\x00garbage")
    trimesh.creation.box(extents=(0.5, 0.5, 0.5)).export(raw / "f_box.obj")
    out = tmp_path / "out"
    assert main(["objects", "repair", str(raw), "--out", str(out), *FAST]) == 1
    captured = capsys.readouterr()
    assert "FAIL b_empty.obj: expected a mesh with faces, found an empty file" in captured.out
    assert "--units" not in captured.err  # no units advice for broken files
    assert "FAIL c_points.obj: expected a triangle mesh, found PointCloud" in captured.out
    assert "FAIL d_nan.obj: expected finite vertex coordinates, found 1 vertices with NaN" in (
        captured.out
    )
    assert "FAIL e_garbage.glb: could not be parsed as GLB" in captured.out
    assert "6 meshes: 2 repaired, 4 failed" in captured.out
    entries = _manifest(out)["entries"]
    assert [k for k, e in entries.items() if e["status"] == "ok"] == ["a_box", "f_box"]
    for key in ("b_empty", "c_points", "d_nan", "e_garbage"):
        assert entries[key]["error"]
        assert entries[key]["files"] == {}
    assert sorted(p.name for p in out.glob("*.obj")) == ["a_box.obj", "f_box.obj"]
    _one_solid(out / "a_box.obj")


def test_bad_input_as_a_whole_is_refused_before_anything_is_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    raw = tmp_path / "raw"
    raw.mkdir()
    trimesh.creation.box(extents=(0.6, 0.4, 0.4)).export(raw / "box.obj")
    trimesh.creation.box(extents=(0.6, 0.4, 0.4)).export(raw / "box.stl")
    out = tmp_path / "out"
    assert main(["objects", "repair", str(raw), "--out", str(out)]) == 2
    assert "expected one mesh file per object id" in capsys.readouterr().err
    assert not out.exists()
    (raw / "box.stl").unlink()
    assert main(["objects", "repair", str(raw), "--out", str(raw)]) == 2
    assert "other than the one holding the source meshes" in capsys.readouterr().err
    assert main(["objects", "repair", str(tmp_path / "none"), "--out", str(out)]) == 2
    assert "found nothing there" in capsys.readouterr().err
    assert main(["objects", "repair", str(raw), "--out", str(out), "--target-extent", "40"]) == 2
    assert "--target-extent: expected a longest side of 0.05-5 m" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # argparse: one or the other
        main(
            [
                "objects",
                "repair",
                str(raw),
                "--out",
                str(out),
                "--units",
                "cm",
                "--target-extent",
                "1",
            ]
        )
    assert not out.exists()


def test_objects_check_tells_a_solid_from_a_shell(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    shell = tmp_path / "table.obj"
    table().export(shell)
    solid = tmp_path / "box.obj"
    trimesh.creation.box(extents=(0.6, 0.4, 0.4)).export(solid)
    assert main(["objects", "check", str(shell), str(solid)]) == 0  # both load: exit 0
    lines = capsys.readouterr().out.splitlines()
    shell_verdict = lines[lines.index(next(x for x in lines if str(shell) in x)) + 1]
    assert shell_verdict.strip().startswith("shell, not a solid (not watertight: ")
    assert "5 separate pieces" in shell_verdict
    assert "benchmark build treats it as a shell" in shell_verdict
    assert "run 'dg16m objects repair' first to make it one watertight solid" in shell_verdict
    solid_verdict = lines[lines.index(next(x for x in lines if str(solid) in x)) + 1]
    assert solid_verdict.strip().startswith("solid (watertight, one closed volume)")
    assert "2 meshes: 1 solid, 1 shell, 0 failed" in lines
    assert any(
        x.startswith("to make the shells watertight solids: dg16m objects repair") for x in lines
    )
