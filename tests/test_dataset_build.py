"""``dg16m dataset build`` end to end on a small dataset: the build, the splits (by id, disjoint
from both shipped benchmarks by geometry hash), resume and worker count giving the same bytes,
the card and its Croissant metadata, ``dg16m dataset info`` and ``dg16m inspect --dataset``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dataset_gen.collection import build as build_module
from dataset_gen.collection.build import build_dataset, check_member
from dataset_gen.collection.card import read_summary
from dataset_gen.collection.recipe import DatasetError, DatasetRecipe
from dataset_gen.collection.splits import Exclusion, check_disjoint, split_of
from dataset_gen.io import read_dg16m
from dg16m_core.cli import main
from dg16m_core.errors import Dg16mError
from dg16m_env.benchmark.exclusion import SHIPPED_EXCLUSION, benchmark_exclusion

RECIPE = DatasetRecipe(objects=6, sources=("procedural",), validation_fraction=0.3)


def _quiet(_: str) -> None:
    return None


@pytest.fixture(scope="module")
def exclusion() -> Exclusion:
    return benchmark_exclusion()


@pytest.fixture(scope="module")
def built(tmp_path_factory, exclusion) -> tuple[Path, build_module.DatasetBuild]:
    out = tmp_path_factory.mktemp("dataset") / "ds"
    return out, build_dataset(out, RECIPE, exclusion, progress=False, log=_quiet)


def _count_tasks(patch: pytest.MonkeyPatch) -> list[str]:
    """The ids of the objects the build runs its task on from now on (in order)."""
    done: list[str] = []
    task = build_module._task

    def counted(item, *args):
        done.append(item.object_id)
        return task(item, *args)

    patch.setattr(build_module, "_task", counted)
    return done


def _bytes(folder: Path) -> dict[str, bytes]:
    """Every file's bytes, by relative path (the data, the manifest and the card)."""
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def test_the_build_makes_every_object_with_its_split_and_origin(built) -> None:
    out, build = built
    entries = build.ok_entries()
    assert len(entries) == RECIPE.objects
    for object_id, entry in entries.items():
        assert entry["split"] == split_of(object_id, RECIPE.validation_fraction, 0)
        assert entry["origin"]["source"] == "procedural"
        assert entry["origin"]["licence"] == "MIT"
        data = read_dg16m(out / entry["files"]["grasps"])
        assert data.n == entry["pairs"] == entry["passing"] + entry["failing"]
        assert (out / entry["files"]["mesh"]).is_file()
        assert data.metadata["parameters"]["clearance_geometry"] == "mesh"
    assert {e["split"] for e in entries.values()} == {"train", "validation"}


def test_the_splits_are_checked_against_both_benchmarks_by_hash(built, exclusion) -> None:
    _out, build = built
    assert build.disjoint["benchmark_objects"] == 600
    assert set(build.disjoint["benchmarks"]) == {"procedural", "real"}
    assert build.disjoint["shared"] == 0
    entries = build.manifest["entries"]
    object_id, entry = next(iter(sorted(build.ok_entries().items())))
    as_benchmark = Exclusion(geometry={entry["geometry_sha256"]: "procedural/x"})
    with pytest.raises(DatasetError, match=f"expected no benchmark object.*{object_id}"):
        check_disjoint(entries, as_benchmark)
    with pytest.raises(DatasetError, match="id of real"):
        check_disjoint(entries, Exclusion(ids={object_id: "real"}))
    other_split = "validation" if entry["split"] == "train" else "train"
    twin = {**entries, "twin": {**entry, "split": other_split}}
    with pytest.raises(DatasetError, match="expected each geometry in one split"):
        check_disjoint(twin, Exclusion())


def test_the_shipped_exclusion_is_for_the_shipped_benchmark_files(exclusion) -> None:
    from dg16m_core.hashing import file_sha256
    from dg16m_env.benchmark.names import benchmark_file

    shipped = json.loads(SHIPPED_EXCLUSION.read_text())
    assert shipped["benchmarks"] == {
        name: file_sha256(benchmark_file(name)) for name in ("procedural", "real")
    }, "a shipped benchmark changed: run scripts/benchmark_exclusion.py"
    assert len(shipped["geometry_sha256"]) == 600
    assert dict(exclusion.geometry) == shipped["geometry_sha256"]


@pytest.mark.slow
def test_the_shipped_exclusion_equals_one_read_from_the_benchmarks(exclusion) -> None:
    from dg16m_env.benchmark.exclusion import computed_exclusion
    from dg16m_env.benchmark.names import benchmark_file

    files = {name: benchmark_file(name) for name in ("procedural", "real")}
    computed = computed_exclusion(files, dict(exclusion.benchmarks))
    assert computed.to_dict() == exclusion.to_dict()


def test_a_resumed_and_a_two_worker_build_give_the_same_bytes(built, exclusion, tmp_path) -> None:
    out, build = built
    expected = _bytes(out)
    # two workers, another folder
    other = tmp_path / "two"
    build_dataset(other, RECIPE, exclusion, workers=2, progress=False, log=_quiet)
    assert _bytes(other) == expected
    # an interrupted run: one object's file lost, its entry gone; the rerun redoes only it
    victim = sorted(build.ok_entries())[2]
    (other / "grasps" / f"{victim}.h5").unlink()
    manifest = json.loads((other / "manifest.json").read_text())
    del manifest["entries"][victim]
    (other / "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True))
    with pytest.MonkeyPatch.context() as patch:
        done = _count_tasks(patch)
        build_dataset(other, RECIPE, exclusion, progress=False, log=_quiet)
    assert done == [victim]
    assert _bytes(other) == expected


def test_a_folder_of_another_recipe_is_refused(built, exclusion) -> None:
    out, _ = built
    other = DatasetRecipe(objects=6, sources=("procedural",), validation_fraction=0.1)
    with pytest.raises(DatasetError, match="same parameters"):
        build_dataset(out, other, exclusion, progress=False, log=_quiet)
    with pytest.raises(DatasetError, match="same benchmarks"):
        build_dataset(out, RECIPE, Exclusion(benchmarks={"x": "0" * 64}), log=_quiet)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"objects": 0}, "objects: expected at least 1"),
        ({"sources": ("sweethome3d",)}, "including procedural"),
        ({"sources": ("procedural", "shapenet")}, "expected distinct names"),
        ({"validation_fraction": 0.7}, r"validation_fraction: expected a number in \[0, 0.5\]"),
        ({"pybullet_limit": 0}, "pybullet_limit: expected None or an integer >= 1"),
    ],
)
def test_a_bad_recipe_says_what_was_expected(kwargs, message) -> None:
    with pytest.raises(DatasetError, match=message):
        DatasetRecipe(**kwargs)


def test_the_card_counts_what_the_manifest_holds(built) -> None:
    out, build = built
    summary = read_summary(out)
    entries = build.ok_entries()
    assert summary["totals"]["objects"] == len(entries)
    assert summary["totals"]["dual_grasps"] == sum(e["pairs"] for e in entries.values())
    assert summary["totals"]["passing"] == sum(e["passing"] for e in entries.values())
    per_split = summary["per_split"]
    assert per_split["train"]["objects"] + per_split["validation"]["objects"] == len(entries)
    assert summary["bytes"]["grasps"] == sum(p.stat().st_size for p in (out / "grasps").iterdir())
    rows = (out / "card" / "objects.csv").read_text().splitlines()
    assert len(rows) == 1 + len(entries)
    readme = (out / "card" / "README.md").read_text()
    assert f"{summary['totals']['dual_grasps']:,} dual grasps" in readme
    assert "0 shared" in readme
    png = (out / "card" / "sample.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_croissant_metadata_validates_and_reads(built) -> None:
    mlc = pytest.importorskip("mlcroissant")
    out, build = built
    dataset = mlc.Dataset(jsonld=str(out / "croissant.json"))
    records = list(dataset.records("objects"))
    assert len(records) == len(build.ok_entries())
    ids = sorted(r["objects/object_id"].decode() for r in records)
    assert ids == sorted(build.ok_entries())
    first = min(records, key=lambda r: r["objects/object_id"])
    entry = build.ok_entries()[first["objects/object_id"].decode()]
    assert first["objects/dual_grasps"] == entry["pairs"]
    assert first["objects/split"].decode() == entry["split"]


def test_dataset_info_prints_the_card(built, capsys) -> None:
    out, build = built
    assert main(["dataset", "info", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"{len(build.ok_entries())} objects" in text
    assert "0 shared" in text
    assert main(["dataset", "info", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["format"] == "dg16m-dataset-card"
    assert main(["dataset", "info", str(out / "grasps")]) == 2
    assert "expected a dataset folder" in capsys.readouterr().err


def test_inspect_checks_a_file_against_its_dataset(built, tmp_path, capsys) -> None:
    out, build = built
    object_id = sorted(build.ok_entries())[0]
    file = out / "grasps" / f"{object_id}.h5"
    assert main(["inspect", str(file)]) == 0
    assert "sha256 as built" in capsys.readouterr().out
    # the same object made with another seed: another dataset's file
    from dataset_gen.pipeline.generate import GenerationParameters, generate_object
    from dataset_gen.sources.object_source import procedural_sources
    from dataset_gen.sources.procedural import parse_object_id

    family, seed = parse_object_id(object_id)
    (source,) = procedural_sources([(family, seed)])
    params = GenerationParameters(seed=1, clearance_geometry="mesh", n_grasps=40)
    from dataset_gen.io import write_dg16m

    foreign = tmp_path / f"{object_id}.h5"
    write_dg16m(foreign, generate_object(source.load(6.0), params, object_file="x.obj"))
    assert main(["inspect", str(foreign), "--dataset", str(out)]) == 2
    assert "a file of another dataset" in capsys.readouterr().err
    # a truncated copy of the dataset's own file
    cut = tmp_path / "cut" / f"{object_id}.h5"
    cut.parent.mkdir()
    cut.write_bytes(file.read_bytes()[: file.stat().st_size // 2])
    assert main(["inspect", str(cut), "--dataset", str(out)]) == 2
    assert "expected" in capsys.readouterr().err
    with pytest.raises(DatasetError, match="no finished object"):
        check_member(out, tmp_path / "nothing-0000000.h5")


def test_sweethome3d_models_of_the_real_benchmark_are_left_out(tmp_path, exclusion) -> None:
    from dataset_gen.real.sweethome3d import DEFAULT_ROOT, library_files

    try:
        library_files(DEFAULT_ROOT)
    except Dg16mError as exc:
        pytest.skip(f"sweethome3d-furniture is not installed: {exc}")
    from dataset_gen.collection.sources import sweethome3d_items

    benchmark_id = next(i for i, name in exclusion.ids.items() if name == "real")
    recipe = DatasetRecipe(objects=2, sources=("procedural", "sweethome3d"))
    items, summary = sweethome3d_items(
        tmp_path,
        recipe,
        exclusion,
        ids=["blendswap-cc-0-chairwithcushion", benchmark_id],
        progress=False,
    )
    assert [i.object_id for i in items] == ["blendswap-cc-0-chairwithcushion"]
    assert summary["benchmark_ids_left_out"] == 1
    (item,) = items
    assert item.origin["licence"] in {"CC0-1.0", "CC-BY-3.0"}
    assert item.mesh_file == "sources/sweethome3d/blendswap-cc-0-chairwithcushion.obj"
    assert (tmp_path / "sources" / "sweethome3d" / "ATTRIBUTION.md").is_file()


def test_pybullet_objects_are_scaled_for_two_arms(tmp_path) -> None:
    pytest.importorskip("pybullet_data")
    from dataset_gen.real.pybullet_objects import import_random_urdfs, random_urdfs
    from dataset_gen.real.sweethome3d import SIZE_RANGE_M

    manifest = import_random_urdfs(tmp_path, random_urdfs()[:2], progress=False)
    for entry in manifest["entries"].values():
        assert entry["status"] == "ok", entry
        assert SIZE_RANGE_M[0] <= max(entry["extents_m"]) <= SIZE_RANGE_M[1] + 1e-9
        assert entry["licence"] == "Zlib"
        assert entry["pieces"] >= 1
    again = import_random_urdfs(tmp_path / "again", random_urdfs()[:2], progress=False)
    assert {k: e["sha256"] for k, e in again["entries"].items()} == {
        k: e["sha256"] for k, e in manifest["entries"].items()
    }


def test_a_resume_keeps_failures_unless_asked_to_retry(built, exclusion, tmp_path) -> None:
    out, build = built
    copy = tmp_path / "copy"
    import shutil

    shutil.copytree(out, copy)
    victim = sorted(build.ok_entries())[0]
    manifest = json.loads((copy / "manifest.json").read_text())
    manifest["entries"][victim] = {
        "status": "failed",
        "files": {},
        "error": "made up",
        "split": "x",
    }
    (copy / "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True))
    with pytest.MonkeyPatch.context() as patch:
        done = _count_tasks(patch)
        kept = build_dataset(copy, RECIPE, exclusion, progress=False, card=False, log=_quiet)
        assert victim not in done  # its verdict is kept ...
        assert kept.manifest["entries"][victim]["error"] == "made up"
        assert len(done) == 1  # ... and one more procedural object makes up the count
        assert len(kept.ok_entries()) == RECIPE.objects
        done.clear()
        build_dataset(
            copy, RECIPE, exclusion, progress=False, card=False, retry_failed=True, log=_quiet
        )
    assert done == [victim]
