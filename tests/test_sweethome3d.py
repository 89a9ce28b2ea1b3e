"""The Sweet Home 3D importer: catalogue parsing, the filter, sizing, repair and the import
folder (manifest, attribution). A synthetic library (a zip written here) covers every branch
on any machine; the real Debian package's CC0 models are used where it is installed."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
import trimesh

from dataset_gen.real.repair import (
    MAX_SIZE_LOSS,
    RepairParameters,
    is_one_volume,
    repair_mesh,
    size_loss,
    surface_deviation,
)
from dataset_gen.real.sweethome3d import (
    DEFAULT_ROOT,
    SIZE_RANGE_M,
    CatalogEntry,
    SweetHomeError,
    catalog_mesh,
    exclusion_reason,
    head_word,
    import_library,
    library_files,
    parse_properties,
    read_catalog,
    read_catalogs,
    select_entries,
    target_longest_side,
)
from dg16m_core.cli import main as cli_main
from dg16m_core.errors import MeshError

pytest.importorskip("skimage")
pytest.importorskip("fast_simplification")

SMALL = RepairParameters(target_faces=400, pitch_fraction=0.04)
"""A coarse repair: quick on the test models."""


def _entry(**fields: object) -> CatalogEntry:
    base: dict[str, object] = {
        "object_id": "lib-thing",
        "library": "Lib",
        "catalog_id": "Lib#thing",
        "name": "Thing",
        "category": "Kitchen",
        "creator": "Someone",
        "tags": "",
        "model": "lib/thing/thing.obj",
        "width": 60.0,
        "depth": 40.0,
        "height": 80.0,
        "licence": "CC-BY-3.0",
    }
    base.update(fields)
    return CatalogEntry(**base)  # type: ignore[arg-type]


def _obj(mesh: trimesh.Trimesh) -> bytes:
    return mesh.export(file_type="obj").encode()


def _stool() -> trimesh.Trimesh:
    """A stool in centimetres, y up, as separate overlapping pieces (not a volume)."""
    seat = trimesh.creation.box((40, 4, 40))
    seat.apply_translation((0, 45, 0))
    legs = []
    for x in (-17, 17):
        for z in (-17, 17):
            leg = trimesh.creation.box((4, 44, 4))
            leg.apply_translation((x, 22, z))
            legs.append(leg)
    return trimesh.util.concatenate([seat, *legs])


def _library(folder: Path, *, broken: bool = False) -> Path:
    """A two- or three-model library ``Lib.sh3f`` in ``folder``."""
    props = [
        "# test catalogue",
        "id=Test",
        "license=Creative Commons Attribution 3.0",
        "id#1=Lib#stool",
        "name#1=Stool \\u00e9",
        "category#1=Kitchen",
        "creator#1=Ann",
        "model#1=/lib/stool/stool.obj",
        "width#1=40",
        "depth#1=40",
        "height#1=47",
        "id#2=Lib#plant",
        "name#2=Green plant",
        "category#2=Living room",
        "creator#2=Bob",
        "model#2=/lib/plant/plant.obj",
        "width#2=30",
        "depth#2=30",
        "height#2=90",
        "id#3=Lib#crate",
        "name#3=Crate",
        "category#3=Miscellaneous",
        "creator#3=Cy",
        "model#3=/lib/crate/crate.obj",
        "width#3=50",
        "depth#3=30",
        "height#3=40",
    ]
    path = folder / "Lib.sh3f"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("PluginFurnitureCatalog.properties", "\n".join(props) + "\n")
        archive.writestr("lib/stool/stool.obj", _obj(_stool()))
        archive.writestr("lib/stool/LICENSE.txt", "CC-BY-3.0 by Ann")
        archive.writestr("lib/plant/plant.obj", _obj(trimesh.creation.icosphere()))
        crate = b"v 0 0 0\nv 1 0 0\n" if broken else _obj(trimesh.creation.box((50, 40, 30)))
        archive.writestr("lib/crate/crate.obj", crate)
    return path


def test_properties_parsing_handles_escapes_continuations_and_comments() -> None:
    text = "# c\n! c\nkey=value\nname#1=Caf\\u00e9 \\\n  bar\nspaced : x y\nempty=\n"
    props = parse_properties(text)
    assert props == {"key": "value", "name#1": "Café bar", "spaced": "x y", "empty": ""}


@pytest.mark.parametrize(
    ("fields", "reason"),
    [
        ({"category": "Characters"}, "category 'Characters'"),
        ({"door_or_window": True}, "door or window"),
        ({"name": "Ficus tree"}, "plant (tree)"),
        ({"name": "Oriental rug"}, "textile (rug)"),
        ({"name": "Hanging clothes"}, "textile (clothes)"),
        ({"height": 2.0}, "flat or thin"),  # 60 / 2 = 30
        ({}, None),
        ({"height": 6.0}, None),  # 60 / 6 = 10: a book or a plate (filter version 3)
        ({"name": "Air mattress"}, "textile (mattress)"),
        # lamps are rigid objects (filter version 2)
        ({"category": "Lights", "name": "Desk lamp"}, None),
        ({"light": True}, None),
        # a textile word that is not the head noun, or only in the tags, is not a textile
        ({"name": "Towel rack"}, None),
        ({"name": "Chair with cushion"}, None),
        ({"name": "Clothes washing machine", "tags": "clothes"}, None),
        ({"tags": "Rug, floor"}, None),
    ],
)
def test_filter_rule(fields: dict[str, object], reason: str | None) -> None:
    found = exclusion_reason(_entry(**fields))
    assert (found is None) if reason is None else (found is not None and found.startswith(reason))


def test_size_rule_keeps_real_sizes_in_range_and_draws_others_seeded() -> None:
    assert target_longest_side(_entry(height=80.0), 0) == pytest.approx(0.8)
    big = _entry(object_id="lib-bed", width=200.0)
    drawn = target_longest_side(big, 0)
    assert SIZE_RANGE_M[0] <= drawn <= SIZE_RANGE_M[1]
    assert target_longest_side(big, 0) == drawn
    assert target_longest_side(big, 1) != drawn
    tiny = _entry(object_id="lib-cup", width=8.0, depth=8.0, height=10.0)
    assert SIZE_RANGE_M[0] <= target_longest_side(tiny, 0) <= SIZE_RANGE_M[1]


def test_catalog_mesh_sizes_to_the_catalogue_and_turns_z_up() -> None:
    # a model 2 x 1 x 3 units (x, y, z) whose catalogue says 60 x 40 (depth, z) x 80 (height, y)
    model = trimesh.creation.box((2.0, 1.0, 3.0))
    mesh, info = catalog_mesh(_entry(), model, seed=0)
    np.testing.assert_allclose(mesh.extents, [0.6, 0.4, 0.8], atol=1e-9)  # width, depth, height
    np.testing.assert_allclose(mesh.bounds.mean(axis=0), 0.0, atol=1e-12)
    assert info["scale"] == pytest.approx(1.0)
    assert info["proportion_mismatch"] > 0.1  # 2:1:3 against 60:80:40 is not the same shape
    turned = _entry(model_rotation=(1, 0, 0, 0, 0, 1, 0, -1, 0))
    mesh, _ = catalog_mesh(turned, model, seed=0)
    np.testing.assert_allclose(mesh.extents, [0.6, 0.4, 0.8], atol=1e-9)


def test_repair_makes_one_watertight_volume_within_the_budget() -> None:
    stool = _stool()
    stool.apply_scale(0.01)  # metres
    assert not stool.is_watertight or stool.body_count > 1
    repaired, report = repair_mesh(stool, RepairParameters(target_faces=600, pitch_fraction=0.02))
    assert is_one_volume(repaired)
    assert len(repaired.faces) <= 600
    assert report.source_pieces == 5
    assert report.decimation_steps >= 1
    deviation = surface_deviation(repaired, stool, samples=2000, rng=np.random.default_rng(0))
    assert deviation.to_source_p95 < 0.02  # within two voxels of the model
    assert deviation.from_source_p95 < 0.02
    again, _ = repair_mesh(stool, RepairParameters(target_faces=600, pitch_fraction=0.02))
    np.testing.assert_array_equal(again.vertices, repaired.vertices)  # deterministic


def test_head_word_is_the_noun_a_name_is_about() -> None:
    assert head_word("Paper towel holder") == "holder"
    assert head_word("Chair with cushion") == "chair"
    assert head_word("Table, round (wood)") == "table"
    assert head_word("Folded clothes") == "clothes"
    assert head_word("42") == ""


def _two_boxes(gap: float) -> trimesh.Trimesh:
    """A 0.4 m box and a 0.1 m one ``gap`` m beside it along x (m): two pieces."""
    big = trimesh.creation.box((0.4, 0.4, 0.4))
    small = trimesh.creation.box((0.1, 0.1, 0.1))
    small.apply_translation((0.25 + gap, 0.0, 0.0))
    return trimesh.util.concatenate([big, small])


def test_repair_refuses_to_keep_only_part_of_a_model() -> None:
    """Pieces apart: only the largest is kept, the model loses a third of its length at either
    voxel size; the repair says so instead of returning a fragment."""
    model = _two_boxes(gap=0.1)
    assert size_loss(trimesh.creation.box((0.4, 0.4, 0.4)), model) == pytest.approx(0.2 / 0.6)
    with pytest.raises(MeshError, match="expected the repaired mesh to keep the model's extents"):
        repair_mesh(model, SMALL)


def test_repair_refuses_an_empty_mesh() -> None:
    with pytest.raises(Exception, match="expected a triangle mesh to repair"):
        repair_mesh(trimesh.Trimesh(np.zeros((3, 3)), np.zeros((0, 3), dtype=int)))


def test_missing_package_names_what_to_install(tmp_path: Path) -> None:
    with pytest.raises(SweetHomeError, match="apt-get install -y sweethome3d-furniture"):
        library_files(tmp_path / "nowhere")


def test_import_writes_meshes_manifest_and_attribution(tmp_path: Path) -> None:
    root = tmp_path / "libs"
    root.mkdir()
    _library(root, broken=True)
    entries = read_catalog(root / "Lib.sh3f")
    assert [e.name for e in entries] == ["Stool é", "Green plant", "Crate"]
    assert entries[0].licence_files == ("lib/stool/LICENSE.txt",)
    chosen = select_entries(entries)
    assert [e.object_id for e in chosen] == ["lib-stool", "lib-crate"]  # the plant is dropped
    with pytest.raises(SweetHomeError, match="lib-plant is excluded: plant"):
        select_entries(entries, ids=["lib-plant"])
    out = tmp_path / "out"
    manifest = import_library(out, chosen, root=root, repair=SMALL, progress=False)
    stool = manifest["entries"]["lib-stool"]
    assert stool["status"] == "ok"
    assert manifest["entries"]["lib-crate"]["status"] == "failed"  # two vertices, no faces
    mesh = trimesh.load(out / "lib-stool.obj", force="mesh")
    assert mesh.is_watertight
    assert max(mesh.extents) == pytest.approx(0.47, abs=0.02)  # its catalogue size, z up
    assert mesh.extents[2] == pytest.approx(0.47, abs=0.02)
    import hashlib

    assert stool["sha256"] == hashlib.sha256((out / "lib-stool.obj").read_bytes()).hexdigest()
    source = stool["source"]
    # a library we do not know takes the licence its catalogue states
    assert (source["creator"], source["licence"], source["category"]) == (
        "Ann",
        "Creative Commons Attribution 3.0",
        "Kitchen",
    )
    assert {"to_source_p95", "from_source_p95"} <= set(stool["deviation_m"])
    attribution = (out / "ATTRIBUTION.md").read_text(encoding="utf-8")
    assert "lib-stool" in attribution
    assert "Ann" in attribution
    assert "rebuilt as one watertight volume" in attribution  # "modified: ..."
    assert "lib-crate" not in attribution  # only what was written
    # resumable: a second run changes nothing it had written
    before = (out / "lib-stool.obj").read_bytes()
    import_library(out, chosen, root=root, repair=SMALL, progress=False)
    assert (out / "lib-stool.obj").read_bytes() == before


def test_import_command_exit_status_and_list(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = tmp_path / "libs"
    root.mkdir()
    _library(root, broken=True)
    code = cli_main(["objects", "import-sweethome3d", "--root", str(root), "--list"])
    assert code == 0
    assert "drop lib-plant" in capsys.readouterr().out
    args = ["objects", "import-sweethome3d", "--root", str(root), "--out", str(tmp_path / "o")]
    code = cli_main([*args, "--target-faces", "400", "--pitch-fraction", "0.04", "--no-progress"])
    printed = capsys.readouterr().out
    assert code == 1
    assert "FAIL lib-crate" in printed
    assert "1 of 2 models" in printed
    code = cli_main(["objects", "import-sweethome3d", "--root", str(tmp_path / "none"), "--list"])
    assert code == 2
    assert "apt-get install -y sweethome3d-furniture" in capsys.readouterr().err


needs_package = pytest.mark.skipif(
    not DEFAULT_ROOT.is_dir(),
    reason="Debian's sweethome3d-furniture is not installed (apt-get install -y "
    "sweethome3d-furniture)",
)


@needs_package
def test_real_catalogue_and_filter() -> None:
    entries = read_catalogs()
    assert len(entries) == 820
    assert len({e.object_id for e in entries}) == 820
    kept = select_entries(entries)
    assert len(kept) == 574  # filter version 3 (542 with version 2, 489 with version 1)
    licences = {e.library: e.licence for e in entries}
    assert licences["BlendSwap-CC-0"] == "CC0-1.0"
    assert licences["Scopia"] == "CC-BY-3.0"


@needs_package
def test_real_cc0_models_import(tmp_path: Path) -> None:
    ids = ["blendswap-cc-0-mamadeira", "blendswap-cc-0-bookcase"]
    chosen = select_entries(read_catalogs(), ids=ids)
    manifest = import_library(tmp_path, chosen, repair=RepairParameters(), progress=False)
    for object_id in ids:
        entry = manifest["entries"][object_id]
        assert entry["status"] == "ok", entry.get("error")
        assert entry["source"]["licence"] == "CC0-1.0"
        assert entry["faces"] <= RepairParameters().target_faces
        assert entry["deviation_m"]["to_source_mean"] < 0.01
        mesh = trimesh.load(tmp_path / f"{object_id}.obj", force="mesh")
        assert is_one_volume(mesh)
        assert SIZE_RANGE_M[0] - 1e-6 <= max(mesh.extents) <= SIZE_RANGE_M[1] + 1e-6
    stored = json.loads((tmp_path / "manifest.json").read_text())
    assert stored["kind"] == "sweethome3d-import"


@pytest.mark.slow  # 30-45 s: the finer grid of the toilet brush is the smallest voxel, 3 mm
@needs_package
def test_a_model_that_loses_parts_is_repaired_finer_or_refused(tmp_path: Path) -> None:
    """Two CC0 models whose first repair keeps only part of them: the toilet brush keeps its
    extents on the finer grid (the smallest voxel, 3 mm); the shower loses its pipes on both
    grids and is refused with the reason, not imported as a fragment."""
    ids = ["blendswap-cc-0-toiletbrush", "blendswap-cc-0-shower"]
    chosen = select_entries(read_catalogs(), ids=ids)
    manifest = import_library(tmp_path, chosen, progress=False)
    brush = manifest["entries"]["blendswap-cc-0-toiletbrush"]
    assert brush["status"] == "ok", brush.get("error")
    assert brush["repair"]["pitch"] == pytest.approx(RepairParameters().min_pitch)
    assert brush["repair"]["size_loss"] <= MAX_SIZE_LOSS
    shower = manifest["entries"]["blendswap-cc-0-shower"]
    assert shower["status"] == "failed"
    assert "expected the repaired mesh to keep the model's extents" in shower["error"]
    assert not (tmp_path / "blendswap-cc-0-shower.obj").exists()
