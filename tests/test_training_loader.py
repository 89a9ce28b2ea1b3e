"""The training loader: a dataset folder as torch datasets (batch shapes and labels, the same
samples for the same seed, DataLoader workers that split the objects between them, clear errors
for a folder that is not a dataset and a damaged object file)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from torch.utils.data import DataLoader  # noqa: E402

from dataset_gen.collection.build import build_dataset  # noqa: E402
from dataset_gen.collection.recipe import DatasetRecipe  # noqa: E402
from dataset_gen.collection.splits import Exclusion  # noqa: E402
from dataset_gen.io import read_dg16m  # noqa: E402
from dg16m_env.training.grasp_dataset import (  # noqa: E402
    DualGraspDataset,
    DualGraspStream,
    TrainingDataError,
    dataset_objects,
    read_object_grasps,
)


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("loader") / "ds"
    recipe = DatasetRecipe(objects=4, sources=("procedural",), validation_fraction=0.3)
    build_dataset(out, recipe, Exclusion(), progress=False, card=False, log=lambda _: None)
    return out


def test_a_batch_holds_clouds_poses_and_labels(folder: Path) -> None:
    stream = DualGraspStream(folder, splits=("train", "validation"), n_points=256)
    batch = next(iter(DataLoader(stream, batch_size=32)))
    assert batch["cloud"].shape == (32, 256, 3)
    assert batch["cloud"].dtype == torch.float32
    assert batch["poses"].shape == (32, 2, 4, 4)
    assert batch["force_closure"].dtype == torch.bool
    assert batch["robust"].dtype == torch.int8
    assert set(batch["robust"].tolist()) == {-1}  # paper selection: the robust label is unknown
    rotations = batch["poses"][:, :, :3, :3].double()
    eye = torch.eye(3, dtype=torch.float64).expand_as(rotations)
    assert torch.allclose(rotations @ rotations.transpose(-1, -2), eye, atol=1e-5)


def test_the_map_dataset_gives_every_grasp_with_its_stored_label(folder: Path) -> None:
    data = DualGraspDataset(folder, splits=("train", "validation"), n_points=64)
    total = 0
    for k, record in enumerate(data.records):
        stored = read_dg16m(record.grasps)
        start = int(data.offsets[k])
        total += stored.n
        for row in (0, stored.n - 1):
            sample = data[start + row]
            assert sample["object_index"] == k
            np.testing.assert_array_equal(sample["poses"], stored.grasps[row].astype(np.float32))
            assert bool(sample["force_closure"]) == bool(stored.passed[row])
    assert len(data) == total
    with pytest.raises(IndexError, match="expected 0 <= index"):
        data[len(data)]
    order = data.object_sampler(seed=3)
    assert sorted(order) == list(range(len(data)))
    assert order == data.object_sampler(seed=3)
    assert order != data.object_sampler(seed=4)


def test_a_cloud_lies_on_its_object_and_the_grasps_frame(folder: Path) -> None:
    import trimesh

    data = DualGraspDataset(folder, splits=("train", "validation"), n_points=128)
    record = data.records[0]
    cloud = data[0]["cloud"]
    stored = read_dg16m(record.grasps)
    mesh = trimesh.load(record.mesh, force="mesh")
    mesh.apply_translation(-mesh.centroid)  # the release's object frame
    _, distance, _ = trimesh.proximity.closest_point(mesh, cloud.astype(np.float64))
    assert distance.max() < 1e-4
    contacts = stored.contact_points.reshape(-1, 3)
    _, distance, _ = trimesh.proximity.closest_point(mesh, contacts[:50])
    assert distance.max() < 1e-3  # the grasps' contacts are on the same surface


def test_the_same_seed_and_epoch_give_the_same_samples(folder: Path) -> None:
    def first(seed: int, epoch: int) -> torch.Tensor:
        stream = DualGraspStream(folder, n_points=32, seed=seed, grasps_per_object=40)
        stream.set_epoch(epoch)
        return next(iter(DataLoader(stream, batch_size=64)))["poses"]

    assert torch.equal(first(0, 0), first(0, 0))
    assert not torch.equal(first(0, 0), first(0, 1))
    assert not torch.equal(first(0, 0), first(1, 0))


def test_two_workers_split_the_objects_and_see_every_sample_once(folder: Path) -> None:
    stream = DualGraspStream(
        folder, splits=("train", "validation"), n_points=16, grasps_per_object=25
    )
    loader = DataLoader(stream, batch_size=20, num_workers=2)
    seen: list[tuple[int, bytes]] = []
    for batch in loader:
        for index, poses in zip(batch["object_index"].tolist(), batch["poses"], strict=True):
            seen.append((index, poses.numpy().tobytes()))
    assert len(seen) == 25 * len(stream.records)
    assert len(set(seen)) == len(seen)  # no sample twice
    assert {i for i, _ in seen} == set(range(len(stream.records)))


def test_a_folder_that_is_not_a_dataset_and_a_damaged_file_are_named(folder, tmp_path) -> None:
    with pytest.raises(TrainingDataError, match="expected a dataset folder"):
        DualGraspStream(tmp_path)
    with pytest.raises(TrainingDataError, match="expected some of"):
        DualGraspDataset(folder, splits=("test",))
    with pytest.raises(TrainingDataError, match="cloud: expected one of"):
        DualGraspDataset(folder, cloud="mesh")  # type: ignore[arg-type]
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    victim = sorted((copy / "grasps").iterdir())[0]
    victim.write_bytes(victim.read_bytes()[:1000])
    with pytest.raises(TrainingDataError, match="expected a DG16M grasp file"):
        read_object_grasps(victim)
    victim.unlink()
    with pytest.raises(TrainingDataError, match="listed in"):
        DualGraspDataset(copy, splits=("train", "validation"))


def test_a_partial_cloud_is_what_the_cloud_track_cameras_see(folder: Path) -> None:

    from dataset_gen.objects.grasp_object import load_object
    from dg16m_env.subjects.cloud_observation import CloudTrack, cloud_observation

    data = DualGraspDataset(folder, splits=("train", "validation"), cloud="partial", n_points=300)
    record = data.records[0]
    cloud = data[0]["cloud"].astype(np.float64)
    assert cloud.shape == (300, 3)
    obj = load_object(record.mesh, object_id=record.object_id, scale=1.0, allow_any_size=True)
    seen = cloud_observation(obj, CloudTrack(camera_seed=0, noise_seed=0))["points"]
    # every training point is one of the cameras' points, and they cover only part of the object
    distance = np.linalg.norm(cloud[:, None, :] - seen[None, :, :].astype(np.float64), axis=2)
    assert distance.min(axis=1).max() < 1e-6
    full = DualGraspDataset(folder, splits=("train", "validation"), n_points=300)[0]["cloud"]
    gap = np.linalg.norm(full[:, None, :] - seen[None, :, :], axis=2).min(axis=1)
    assert (gap > 0.02).mean() > 0.1  # the cameras miss parts of the object the full cloud has


def test_a_record_names_its_collection_as_the_data_card_does(folder: Path, tmp_path: Path) -> None:
    import json
    import shutil

    copy = tmp_path / "ds"
    shutil.copytree(folder, copy)
    manifest = json.loads((copy / "manifest.json").read_text())
    first, second = sorted(manifest["entries"])[:2]
    manifest["entries"][first]["origin"]["source"] = "sweethome3d"  # a mesh source's collection
    manifest["entries"][first]["source"] = "mesh"
    manifest["entries"][second].pop("origin")
    (copy / "manifest.json").write_text(json.dumps(manifest))
    records = {r.object_id: r for r in dataset_objects(copy, ("train", "validation"))}
    assert records[first].source == "sweethome3d"
    assert records[second].source == "procedural"  # no origin: the entry's own source
