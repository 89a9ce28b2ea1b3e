"""Tests of the classifiers' training data (baselines.classifier_data), the training script
(baselines.train_classifier) and ``dg16m reproduce`` (baselines.reproduce) on tiny
configurations."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from baselines.classifier_data import (
    BatchSampler,
    ClassifierDataError,
    grasp_files,
    load_generated,
    split_objects,
)
from baselines.reproduce import ReproduceError, checkpoint_paths, fig4, table2, table3
from dataset_gen.io import read_dg16m
from dataset_gen.pipeline.generate import GenerationParameters, generate_dataset
from dataset_gen.sources.object_source import procedural_sources
from dataset_gen.sources.procedural import object_specs


@pytest.fixture(scope="module")
def generated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two procedural train objects from the generator (120 single-arm grasps each)."""
    out = tmp_path_factory.mktemp("generated") / "data"
    generate_dataset(
        procedural_sources(object_specs(2, seed=0, split="train")),
        out,
        GenerationParameters(seed=0, n_grasps=120),
        progress=False,
    )
    return out


def test_load_generated_objects(generated: Path) -> None:
    objects = load_generated(generated, n_points=256, progress=False)
    files = grasp_files(generated)
    assert [o.object_id for o in objects] == [f.stem for f in files]
    for obj, path in zip(objects, files, strict=True):
        data = read_dg16m(path)
        assert obj.points.shape == (256, 3)
        assert obj.points.dtype == np.float32
        assert obj.poses.shape == (len(data.grasps), 2, 4, 4)
        assert np.flatnonzero(obj.labels["dg16m"]).tolist() == sorted(data.passing_indices)
        assert obj.labels["da2"].dtype == bool
        assert obj.labels["da2"].shape == obj.labels["dg16m"].shape
        mesh = trimesh.load(generated / data.object_file, force="mesh")
        _, distance, _ = trimesh.proximity.closest_point(mesh, obj.points.astype(np.float64))
        assert distance.max() < 1e-5  # the cloud lies on the object's surface
    again = load_generated(generated, n_points=256, progress=False)
    assert all(np.array_equal(a.points, b.points) for a, b in zip(objects, again, strict=True))


def test_batches_are_balanced_and_seeded(generated: Path) -> None:
    objects = load_generated(generated, n_points=64, progress=False)
    sampler = BatchSampler(objects, "dg16m", 3, 8, np.random.default_rng(0))
    points, poses, labels = sampler.sample()
    assert points.shape == (3, 64, 3)
    assert poses.shape == (3, 8, 2, 4, 4)
    assert labels.shape == (3, 8)
    assert labels.sum(axis=1).tolist() == [4.0, 4.0, 4.0]  # both classes present per object
    twin = BatchSampler(objects, "dg16m", 3, 8, np.random.default_rng(0)).sample()
    assert np.array_equal(twin[1], poses)
    with pytest.raises(ClassifierDataError, match="even grasps_per_object"):
        BatchSampler(objects, "dg16m", 3, 7, np.random.default_rng(0))
    with pytest.raises(ClassifierDataError, match="expected one of"):
        BatchSampler(objects, "acronym", 3, 8, np.random.default_rng(0))


def test_split_objects_holds_out_whole_objects(generated: Path) -> None:
    objects = load_generated(generated, n_points=16, progress=False)
    train, val = split_objects(objects, 0.1, seed=0)
    assert len(train) == 1
    assert len(val) == 1
    assert {o.object_id for o in train} | {o.object_id for o in val} == {
        o.object_id for o in objects
    }
    with pytest.raises(ClassifierDataError, match=r"expected \[0, 1\)"):
        split_objects(objects, 1.0, seed=0)
    with pytest.raises(ClassifierDataError, match="no grasp files"):
        grasp_files(generated / "meshes")


def test_table3_tiny(tmp_path: Path) -> None:
    payload = table3(tmp_path, limit=1, k=1, progress=False)
    assert payload["objects"] == 10  # one object per family
    with (tmp_path / "table3.csv").open() as handle:
        rows = list(csv.reader(handle))
    assert [r[0] for r in rows[1:]] == ["random", "farthest", "force_closure"]
    assert rows[3][2] == "100.0"  # the paper's column
    fce = {s: payload["results"][s]["fce"]["metrics"]["fce"]["rate"] for s in payload["results"]}
    assert fce["force_closure"] == 1.0
    assert fce["random"] < fce["force_closure"]
    assert "| force_closure | 100.0 [100.0, 100.0] |" in (tmp_path / "table3.md").read_text()
    record = json.loads((tmp_path / "table3.json").read_text())
    assert record["results"]["random"]["gsr"]["seeds"]


def test_fig4_tiny(generated: Path, tmp_path: Path) -> None:
    payload = fig4(tmp_path, data=generated, progress=False)
    assert payload["files"] == 2
    assert (tmp_path / "fig4.png").stat().st_size > 10_000
    ours = payload["q_by_dg16m_label"]
    assert 0.0 <= ours["auc"] <= 1.0
    table = payload["agreement"]
    total = sum(table[k] for k in ("both_pass", "ours_only", "da2_only", "both_fail"))
    assert total == table["n"] == payload["pairs"]
    assert json.loads((tmp_path / "fig4.json").read_text())["pairs"] == payload["pairs"]


def test_table2_needs_checkpoints(tmp_path: Path) -> None:
    with pytest.raises(ReproduceError, match="found none"):
        checkpoint_paths(tmp_path)
    with pytest.raises(ReproduceError, match=r"cgdf-dg16m\.pt"):
        table2(tmp_path / "out", checkpoints=tmp_path, limit=1)


def test_meshes_of_a_dataset_made_from_a_mesh_folder(generated: Path, tmp_path: Path) -> None:
    """A ``generate --meshes`` dataset names meshes relative to its ``--meshes`` folder: without
    ``mesh_root`` the loader says where it looked and what to pass; with it, the same objects."""
    import shutil

    data = tmp_path / "data"
    shutil.copytree(generated, data)
    meshes = tmp_path / "meshes"
    shutil.move(data / "meshes", meshes)
    for path in grasp_files(data):  # object_file "meshes/<id>.obj" now lives under tmp_path
        assert (tmp_path / read_dg16m(path).object_file).is_file()
    with pytest.raises(ClassifierDataError, match="pass its mesh folder as mesh_root"):
        load_generated(data, n_points=64, progress=False)
    moved = load_generated(data, n_points=64, progress=False, mesh_root=tmp_path)
    original = load_generated(generated, n_points=64, progress=False)
    assert all(np.array_equal(a.points, b.points) for a, b in zip(moved, original, strict=True))


def test_training_takes_objects_of_several_folders(generated: Path, tmp_path: Path) -> None:
    """``--more-data``: the objects of further folders join ``--data``'s (the real training
    split beside the procedural one); an object in two folders is refused."""
    import shutil

    from baselines.train_classifier import Args, main

    files = grasp_files(generated)
    folders = []
    for keep in files:  # one folder per object, each with its own grasps/ and meshes/
        folder = tmp_path / keep.stem
        shutil.copytree(generated, folder)
        for other in files:
            if other != keep:
                (folder / "grasps" / other.name).unlink()
        folders.append(folder)
    small = {
        "steps": 2,
        "eval_every": 2,
        "objects_per_batch": 1,
        "grasps_per_object": 4,
        "val_grasps": 16,
        "evaluate": False,
    }
    out = tmp_path / "out"
    main(Args(data=folders[0], more_data=str(folders[1]), out=out, val_fraction=0.5, **small))
    run = json.loads((out / "cgdf-dg16m-results.json").read_text(encoding="utf-8"))
    assert run["train_objects"] + run["held_out_objects"] == len(files) == 2
    with pytest.raises(ClassifierDataError, match="expected distinct objects"):
        main(Args(data=generated, more_data=str(folders[0]), out=out, **small))


def test_training_script_and_table2_tiny(generated: Path, tmp_path: Path) -> None:
    from baselines.train_classifier import Args, main

    checkpoints = tmp_path / "checkpoints"
    for model in ("cgdf", "pointnetgpd"):
        args = Args(
            model=model,
            labels="dg16m",
            data=generated,
            out=checkpoints,
            steps=3,
            eval_every=3,
            objects_per_batch=1,
            grasps_per_object=4,
            val_grasps=16,
            threads=1,
            evaluate=False,
        )
        run = main(args)
        assert run["steps"] == 3
        assert len(run["history"]) == 1
        assert run["history"][0]["val_auc"] is None or 0.0 <= run["history"][0]["val_auc"] <= 1.0
        for suffix in (".pt", "-curve.png", "-history.json", "-results.json"):
            assert (checkpoints / f"{model}-dg16m{suffix}").is_file()
    payload = table2(tmp_path / "table2", checkpoints=checkpoints, limit=1, k=2, progress=False)
    assert set(payload["results"]) == {"cgdf-dg16m", "pointnetgpd-dg16m"}
    assert payload["objects"] == 10
    table = (tmp_path / "table2" / "table2.md").read_text()
    assert "| cgdf | dg16m |" in table
    assert "| 88.73 |" in table  # the paper's number beside ours
    chance = [line for line in table.splitlines() if "random ranking (expected)" in line]
    assert len(chance) == 1
    assert "—" not in chance[0].split("|")[3]  # the expected FCE of a random ranking
    result = payload["results"]["cgdf-dg16m"]
    assert result["metrics"]["fce_top2"]["objects"] == 10
    assert result["training"]["steps"] == 3
