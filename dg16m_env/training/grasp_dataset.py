"""A dataset folder as torch datasets: one sample = one dual grasp, its labels and its object's cloud.

Each sample is a dict of numpy values (``torch.utils.data.default_collate`` stacks them into
tensors):

* ``cloud`` (P, 3) float32: the object's cloud in its object frame (m), the frame of the grasps;
  ``cloud="full"``: ``n_points`` points on the whole surface (area-weighted, seeded per object);
  ``cloud="partial"``: what the cloud track's depth cameras see of it
  (:mod:`dg16m_env.subjects.cloud_observation`, the cameras and noise seeded per object as the
  benchmark seeds them), ``n_points`` of its points;
* ``poses`` (2, 4, 4) float32: the two hand poses (Panda grasp frame -> object frame, m);
* ``force_closure`` bool: the dual grasp passes the paper's force-closure check;
* ``robust`` int8: 1 / 0 when the file carries the robust criterion (``motion_ratio`` <= 1, the
  generator's ``--selection robust``), -1 when it does not;
* ``object_index`` int64: the object's index in the dataset's ``object_ids`` (its objects of the
  chosen splits, sorted by id).

Clouds are made once per object and kept (``cloud_cache`` objects in memory, and in
``cache_dir`` on disk when given), so a training loop pays for an object's cloud once.

:class:`DualGraspDataset` is map-style (index -> sample, every dual grasp of the chosen splits
in file order); random access across thousands of objects reads a file per sample, so pair it
with :meth:`DualGraspDataset.object_sampler` (objects in a seeded order, each object's grasps
shuffled) or use :class:`DualGraspStream`, which streams object files with a shuffle buffer and
splits the objects among DataLoader workers. Randomness: ``seed`` and the epoch
(:meth:`DualGraspStream.set_epoch`), and the worker's id; never a global generator, so the same
seed, epoch and worker count give the same samples in the same order.
"""

from __future__ import annotations

import os
from collections import OrderedDict
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import h5py
import numpy as np

from dataset_gen.collection.recipe import SPLITS
from dataset_gen.io import read_manifest
from dataset_gen.objects.grasp_object import load_object
from dataset_gen.sources.object_source import object_seed
from dg16m_core.atomic import write_bytes_atomic
from dg16m_core.errors import Dg16mError

CloudKind = Literal["full", "partial"]
CLOUD_KINDS: tuple[str, ...] = ("full", "partial")


class TrainingDataError(Dg16mError, ValueError):
    """A folder that is not a dataset, a damaged object file, or bad loader arguments."""


@dataclass(frozen=True)
class ObjectRecord:
    """One object of a dataset: its id, split, grasp file and mesh file (absolute paths), how
    many dual grasps its file holds (the manifest's count) and the collection it came from (the
    data card's ``source`` column: the entry's ``origin.source``, e.g. ``"procedural"`` or
    ``"sweethome3d"``, else the entry's ``source``; empty when neither is recorded)."""

    object_id: str
    split: str
    grasps: Path
    mesh: Path
    pairs: int
    source: str = ""


def dataset_objects(folder: str | os.PathLike[str], splits: Sequence[str]) -> list[ObjectRecord]:
    """The finished objects of a dataset folder in the given splits, sorted by id.

    Raises:
        TrainingDataError: not a dataset folder, an unknown split, or a listed file missing.
    """
    root = Path(folder)
    unknown = [s for s in splits if s not in SPLITS]
    if unknown or not splits:
        raise TrainingDataError(f"splits: expected some of {SPLITS}, found {list(splits)}")
    try:
        manifest = read_manifest(root)
    except Dg16mError as exc:
        raise TrainingDataError(
            f"{root}: expected a dataset folder (made by 'dg16m dataset build'), found {exc}"
        ) from None
    if manifest["kind"] != "dataset":
        raise TrainingDataError(
            f"{root}: expected a dataset folder (manifest kind 'dataset'), found kind "
            f"{manifest['kind']!r}"
        )
    records = []
    for object_id, entry in sorted(manifest["entries"].items()):
        if entry["status"] != "ok" or entry.get("split") not in splits:
            continue
        grasps, mesh = root / entry["files"]["grasps"], root / entry["files"]["mesh"]
        for path in (grasps, mesh):
            if not path.is_file():
                raise TrainingDataError(
                    f"{object_id}: expected {path} (listed in {root}/manifest.json), found none"
                )
        records.append(
            ObjectRecord(
                object_id,
                str(entry["split"]),
                grasps,
                mesh,
                int(entry["pairs"]),
                str(entry.get("origin", {}).get("source") or entry.get("source", "")),
            )
        )
    if not records:
        raise TrainingDataError(f"{root}: expected objects in splits {list(splits)}, found none")
    return records


@dataclass(frozen=True)
class ObjectGrasps:
    """One object's dual grasps and labels as the loader reads them (float32 poses)."""

    poses: np.ndarray  # (N, 2, 4, 4) float32
    force_closure: np.ndarray  # (N,) bool
    robust: np.ndarray  # (N,) int8: 1, 0, or -1 unknown


def read_object_grasps(path: Path) -> ObjectGrasps:
    """The poses and labels of one grasp file (only the arrays a loader needs).

    Raises:
        TrainingDataError: the file cannot be read or lacks the release schema's arrays.
    """
    try:
        with h5py.File(path, "r") as f:
            poses = np.asarray(f["grasps/grasps"], dtype=np.float32)
            passing = np.asarray(f["grasps/fc_passing_indices"], dtype=np.int64)
            ratio = f.get("dg16m/motion_ratio")
            ratio = None if ratio is None else np.asarray(ratio, dtype=np.float64)
    except (OSError, KeyError, ValueError) as exc:
        raise TrainingDataError(
            f"{path}: expected a DG16M grasp file (grasps/grasps, grasps/fc_passing_indices), "
            f"found {type(exc).__name__}: {exc}"
        ) from None
    n = len(poses)
    if poses.shape[1:] != (2, 4, 4) or (passing.size and (passing.min() < 0 or passing.max() >= n)):
        raise TrainingDataError(
            f"{path}: expected (N, 2, 4, 4) poses and passing indices in [0, N), found "
            f"{poses.shape} and indices up to {passing.max() if passing.size else None}"
        )
    force_closure = np.zeros(n, dtype=bool)
    force_closure[passing] = True
    robust = np.full(n, -1, dtype=np.int8)
    if ratio is not None and ratio.shape == (n,):
        robust = np.where(force_closure & (ratio <= 1.0), 1, 0).astype(np.int8)
    return ObjectGrasps(poses, force_closure, robust)


def full_cloud(mesh_file: Path, n_points: int, seed: int, object_id: str) -> np.ndarray:
    """(n_points, 3) float32 points on the whole surface of the object (object frame: the
    mesh centred on its centroid, as the grasps), area-weighted, seeded by ``(seed, id)``."""
    import trimesh

    mesh = load_object(mesh_file, scale=1.0, allow_any_size=True).mesh
    rng_seed = object_seed(seed, f"cloud:{object_id}") % 2**32
    points, _ = trimesh.sample.sample_surface(mesh, n_points, seed=rng_seed)
    return np.asarray(points, dtype=np.float32)


def partial_cloud(mesh_file: Path, n_points: int, seed: int, object_id: str) -> np.ndarray:
    """(n_points, 3) float32 points the cloud track's depth cameras see of the object
    (:func:`dg16m_env.subjects.cloud_observation.cloud_observation` with its default cameras and
    Kinect-like noise, camera and noise seeds ``seed``, so a training cloud looks like what a
    cloud-track predictor is given), ``n_points`` of them drawn at random (with replacement
    when the cameras saw fewer), seeded by ``(seed, id)``.

    Raises:
        TrainingDataError: the cameras saw nothing of the object.
    """
    from dg16m_env.subjects.cloud_observation import CloudTrack, cloud_observation

    obj = load_object(mesh_file, object_id=object_id, scale=1.0, allow_any_size=True)
    points = cloud_observation(obj, CloudTrack(camera_seed=seed, noise_seed=seed))["points"]
    if len(points) == 0:
        raise TrainingDataError(
            f"{object_id}: expected the cameras to see the object, found nothing"
        )
    rng = np.random.default_rng(object_seed(seed, f"partial-cloud:{object_id}"))
    take = rng.choice(len(points), n_points, replace=len(points) < n_points)
    return np.ascontiguousarray(points[take], dtype=np.float32)


class _Clouds:
    """Each object's cloud, made once: an LRU of ``capacity`` in memory, and ``cache_dir``."""

    def __init__(
        self, kind: str, n_points: int, seed: int, capacity: int, cache_dir: Path | None
    ) -> None:
        self.kind, self.n_points, self.seed = kind, n_points, seed
        self.capacity, self.cache_dir = capacity, cache_dir
        self._memory: OrderedDict[str, np.ndarray] = OrderedDict()

    def _file(self, object_id: str) -> Path | None:
        if self.cache_dir is None:
            return None
        return self.cache_dir / f"{self.kind}-{self.n_points}-{self.seed}" / f"{object_id}.npy"

    def get(self, record: ObjectRecord) -> np.ndarray:
        cloud = self._memory.get(record.object_id)
        if cloud is not None:
            self._memory.move_to_end(record.object_id)
            return cloud
        file = self._file(record.object_id)
        if file is not None and file.is_file():
            cloud = np.load(file, allow_pickle=False)
        else:
            make = full_cloud if self.kind == "full" else partial_cloud
            cloud = make(record.mesh, self.n_points, self.seed, record.object_id)
            if file is not None:
                file.parent.mkdir(parents=True, exist_ok=True)
                buffer = _npy_bytes(cloud)
                write_bytes_atomic(file, buffer)
        self._memory[record.object_id] = cloud
        while len(self._memory) > self.capacity:
            self._memory.popitem(last=False)
        return cloud


def _npy_bytes(array: np.ndarray) -> bytes:
    import io

    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=False)
    return buffer.getvalue()


def _open(
    folder: str | os.PathLike[str],
    splits: Sequence[str],
    cloud: str,
    n_points: int,
    seed: int,
    cloud_cache: int,
    cache_dir: str | os.PathLike[str] | None,
) -> tuple[list[ObjectRecord], _Clouds]:
    """The objects of ``folder``'s ``splits`` and their cloud cache (both datasets' set-up).

    Raises:
        TrainingDataError: bad arguments, or not a dataset folder.
    """
    if cloud not in CLOUD_KINDS:
        raise TrainingDataError(f"cloud: expected one of {CLOUD_KINDS}, found {cloud!r}")
    for name, value in (("n_points", n_points), ("cloud_cache", cloud_cache)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise TrainingDataError(f"{name}: expected an integer >= 1, found {value!r}")
    records = dataset_objects(folder, tuple(splits))
    cache = Path(cache_dir) if cache_dir is not None else None
    return records, _Clouds(cloud, n_points, seed, cloud_cache, cache)


def _sample(
    clouds: _Clouds, record: ObjectRecord, grasps: ObjectGrasps, row: int, index: int
) -> dict[str, Any]:
    return {
        "cloud": clouds.get(record),
        "poses": grasps.poses[row],
        "force_closure": grasps.force_closure[row],
        "robust": grasps.robust[row],
        "object_index": np.int64(index),
    }


def _torch_dataset_base(iterable: bool) -> type:
    """``torch.utils.data.Dataset`` / ``IterableDataset`` (imported on use: torch is optional)."""
    try:
        from torch.utils.data import Dataset, IterableDataset
    except ImportError:
        raise TrainingDataError(
            "expected torch for the training datasets (pip install 'dg16m[learn]'), found none"
        ) from None
    return IterableDataset if iterable else Dataset


class DualGraspDataset(_torch_dataset_base(False)):  # type: ignore[misc]
    """Every dual grasp of a dataset folder's ``splits`` as a map-style torch dataset (module
    docstring).

    Args:
        folder: a dataset folder (``dg16m dataset build``).
        splits: which splits (default ``("train",)``).
        cloud: ``"full"`` (surface samples) or ``"partial"`` (the cloud track's cameras).
        n_points: points per cloud.
        seed: seed of the clouds.
        cloud_cache: objects whose clouds are kept in memory.
        grasp_cache: objects whose grasps are kept in memory.
        cache_dir: a folder to keep clouds in across runs (None: memory only).

    Raises:
        TrainingDataError: not a dataset folder, no object in the splits, bad arguments.
    """

    def __init__(
        self,
        folder: str | os.PathLike[str],
        *,
        splits: Sequence[str] = ("train",),
        cloud: CloudKind = "full",
        n_points: int = 1024,
        seed: int = 0,
        cloud_cache: int = 8192,
        grasp_cache: int = 64,
        cache_dir: str | os.PathLike[str] | None = None,
    ) -> None:
        self.records, self._clouds = _open(
            folder, splits, cloud, n_points, seed, cloud_cache, cache_dir
        )
        self.object_ids = [r.object_id for r in self.records]
        self.seed = seed
        self._grasps: OrderedDict[int, ObjectGrasps] = OrderedDict()
        self._grasp_cache = max(1, int(grasp_cache))
        counts = np.array([r.pairs for r in self.records], dtype=np.int64)
        self.offsets = np.concatenate([[0], np.cumsum(counts)])

    def __len__(self) -> int:
        return int(self.offsets[-1])

    def _object_grasps(self, index: int) -> ObjectGrasps:
        grasps = self._grasps.get(index)
        if grasps is None:
            record = self.records[index]
            grasps = read_object_grasps(record.grasps)
            if len(grasps.poses) != record.pairs:
                raise TrainingDataError(
                    f"{record.grasps}: expected the {record.pairs} dual grasps its dataset's "
                    f"manifest lists, found {len(grasps.poses)} (a file changed since the build)"
                )
            self._grasps[index] = grasps
            while len(self._grasps) > self._grasp_cache:
                self._grasps.popitem(last=False)
        else:
            self._grasps.move_to_end(index)
        return grasps

    def __getitem__(self, item: int) -> dict[str, Any]:
        item = int(item)
        if not 0 <= item < len(self):
            raise IndexError(f"index: expected 0 <= index < {len(self)}, found {item}")
        index = int(np.searchsorted(self.offsets, item, side="right") - 1)
        row = item - int(self.offsets[index])
        return _sample(self._clouds, self.records[index], self._object_grasps(index), row, index)

    def object_cloud(self, index: int) -> np.ndarray:
        """(n_points, 3) float32 cloud of object ``index`` (of ``object_ids``), cached."""
        return self._clouds.get(self.records[index])

    def object_grasps(self, index: int) -> ObjectGrasps:
        """The dual grasps and labels of object ``index`` (of ``object_ids``), cached.

        Raises:
            TrainingDataError: a file that cannot be read or holds another count than the
                manifest's.
        """
        return self._object_grasps(index)

    def object_sampler(self, seed: int = 0, epoch: int = 0) -> list[int]:
        """All indices, objects in a seeded order and each object's grasps shuffled within it
        (pass as ``sampler=`` to a DataLoader: each object file is read once per epoch)."""
        rng = np.random.default_rng(object_seed(seed, f"sampler:{epoch}") % 2**63)
        order: list[int] = []
        for index in rng.permutation(len(self.records)):
            start, stop = int(self.offsets[index]), int(self.offsets[index + 1])
            order.extend((start + rng.permutation(stop - start)).tolist())
        return order


class DualGraspStream(_torch_dataset_base(True)):  # type: ignore[misc]
    """The dual grasps of a dataset folder's ``splits`` streamed object file by object file
    (module docstring): per epoch the objects in a seeded order, split among the DataLoader's
    workers (worker ``w`` of ``W`` takes every ``W``-th), their grasps mixed in a buffer of
    ``shuffle_objects`` objects.

    Args: as :class:`DualGraspDataset`, plus ``shuffle_objects`` (objects mixed at a time) and
        ``grasps_per_object`` (at most this many of an object's grasps per epoch, drawn
        at random; None: all).
    """

    def __init__(
        self,
        folder: str | os.PathLike[str],
        *,
        splits: Sequence[str] = ("train",),
        cloud: CloudKind = "full",
        n_points: int = 1024,
        seed: int = 0,
        shuffle_objects: int = 8,
        grasps_per_object: int | None = None,
        cloud_cache: int = 8192,
        cache_dir: str | os.PathLike[str] | None = None,
    ) -> None:
        self.records, self._clouds = _open(
            folder, splits, cloud, n_points, seed, cloud_cache, cache_dir
        )
        self.object_ids = [r.object_id for r in self.records]
        self.seed, self.epoch = seed, 0
        for name, value in (
            ("shuffle_objects", shuffle_objects),
            ("grasps_per_object", 1 if grasps_per_object is None else grasps_per_object),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise TrainingDataError(f"{name}: expected an integer >= 1, found {value!r}")
        self.shuffle_objects = shuffle_objects
        self.grasps_per_object = grasps_per_object

    def set_epoch(self, epoch: int) -> None:
        """Choose the epoch (another order of objects and grasps)."""
        self.epoch = int(epoch)

    def __iter__(self) -> Iterator[dict[str, Any]]:
        from torch.utils.data import get_worker_info

        info = get_worker_info()
        worker, workers = (0, 1) if info is None else (info.id, info.num_workers)
        rng = np.random.default_rng(
            object_seed(self.seed, f"stream:{self.epoch}:{worker}:{workers}") % 2**63
        )
        order = np.random.default_rng(
            object_seed(self.seed, f"stream-order:{self.epoch}") % 2**63
        ).permutation(len(self.records))
        mine = order[worker::workers]
        for start in range(0, len(mine), self.shuffle_objects):
            group = mine[start : start + self.shuffle_objects]
            rows: list[tuple[int, int]] = []
            loaded: dict[int, ObjectGrasps] = {}
            for index in group:
                grasps = read_object_grasps(self.records[index].grasps)
                loaded[int(index)] = grasps
                n = len(grasps.poses)
                take = np.arange(n)
                if self.grasps_per_object is not None and n > self.grasps_per_object:
                    take = np.sort(rng.choice(n, self.grasps_per_object, replace=False))
                rows.extend((int(index), int(r)) for r in take)
            for k in rng.permutation(len(rows)):
                index, row = rows[k]
                yield _sample(self._clouds, self.records[index], loaded[index], row, index)
