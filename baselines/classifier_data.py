"""Training data for the grasp classifiers: the dual grasps of a ``dg16m generate`` folder, each
with two labels (ours: the DG16M force-closure verdict; DA2's: :mod:`baselines.da2_labels`), and
each object's point cloud.

A folder written by ``dg16m generate`` holds ``grasps/<id>.h5`` (the DG16M release schema, read by
:func:`dataset_gen.io.read_dg16m`) and the meshes the files name (``object_file``, relative to the
folder). Each object becomes a :class:`ClassifierObject`:

* ``points`` (P, 3) float32: the cloud the ``classifier`` evaluator gives a classifier
  (:func:`dg16m_env.subjects.observation.surface_points` with the same seed stream as
  :func:`~dg16m_env.subjects.observation.object_observation`), so training and evaluation see the same
  kind of input;
* ``poses`` (N, 2, 4, 4) float32: the file's dual grasps as Panda hand poses (retargeted when
  the file was made for another gripper);
* ``labels["dg16m"]`` (N,) bool: in the file's ``passing_indices``; ``labels["da2"]`` (N,)
  bool: DA2's keep rule on the same four contacts (:func:`da2_passed`).

:class:`BatchSampler` draws training batches of B objects x n grasps, half positives and half
negatives per object where the object has both (the files hold 2,000 passing and 2,000 failing
pairs, DA2's labels are far less balanced).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from dataset_gen.io import read_dg16m
from dataset_gen.sources.object_source import object_seed
from dg16m_core.errors import Dg16mError
from dg16m_core.progress import progress_bar
from dg16m_env.benchmark.sources import file_poses
from dg16m_env.subjects.observation import DEFAULT_POINTS, surface_points

LABELS = ("dg16m", "da2")
"""The label sources: our force-closure verdicts, and DA2's frictionless criterion."""


def da2_passed(data: Any) -> np.ndarray:
    """(N,) bool DA2's keep rule on a grasp file's pairs, with ``zero_tol=GEOMETRIC_ZERO``.

    DA2's literal rule keeps a pair when its net unit-force wrench l8b is strictly positive;
    on our flat-faced objects about half the pairs are exactly antipodal, and whether their
    l8b is 0 or 1e-30 is decided by floating-point rounding (see :mod:`baselines.da2_labels`).
    Counting a net wrench below 1e-4 as zero makes the labels a function of the geometry; the
    literal rule would train on rounding noise.
    """
    from baselines.da2_labels import GEOMETRIC_ZERO, da2_labels_for_file

    return np.asarray(da2_labels_for_file(data, zero_tol=GEOMETRIC_ZERO).passed, dtype=bool)


class ClassifierDataError(Dg16mError, ValueError):
    """A training folder or argument that cannot be used."""


@dataclass(frozen=True, eq=False)
class ClassifierObject:
    """One object's training data (see the module docstring).

    Attributes:
        object_id: the file's stem.
        points: (P, 3) float32 surface points, object frame (m).
        poses: (N, 2, 4, 4) float32 Panda hand poses, grasp frame -> object frame (m).
        labels: label source -> (N,) bool.
        quality: (N,) float64 our Q(G) when the file stores it (``extras["quality"]``), else NaN.
    """

    object_id: str
    points: np.ndarray
    poses: np.ndarray
    labels: dict[str, np.ndarray]
    quality: np.ndarray

    def __repr__(self) -> str:
        counts = ", ".join(f"{k} {int(v.sum())}/{v.size}" for k, v in self.labels.items())
        return f"ClassifierObject({self.object_id!r}, {len(self.points)} points, {counts})"


def grasp_files(folder: str | os.PathLike[str]) -> list[Path]:
    """The ``grasps/*.h5`` files of a ``dg16m generate`` folder (or of a folder of files),
    sorted.

    Raises:
        ClassifierDataError: no such folder, or no files in it.
    """
    folder = Path(folder)
    root = folder / "grasps" if (folder / "grasps").is_dir() else folder
    files = sorted(root.glob("*.h5")) if root.is_dir() else []
    if not files:
        raise ClassifierDataError(
            f"{folder}: expected a 'dg16m generate' folder (grasps/<id>.h5 and meshes/), found "
            "no grasp files"
        )
    return files


def load_object(
    path: str | os.PathLike[str],
    *,
    n_points: int = DEFAULT_POINTS,
    seed: int = 0,
    mesh_root: str | os.PathLike[str] | None = None,
):
    """One grasp file's :class:`ClassifierObject` (its mesh is found relative to the file's
    folder's parent, where ``dg16m generate --procedural`` writes it, else in ``mesh_root``:
    the ``--meshes`` folder of a ``dg16m generate --meshes`` dataset).

    Raises:
        ClassifierDataError: the mesh is missing or the file has no contact normals.
        GraspFileError: a malformed grasp file.
    """
    path = Path(path)
    data = read_dg16m(path)
    places = [path.parent.parent / data.object_file]
    if mesh_root is not None:
        places.append(Path(mesh_root) / data.object_file)
    found = [p for p in places if p.is_file()]
    if not found:
        raise ClassifierDataError(
            f"{path}: expected its mesh at {' or '.join(str(p) for p in places)} (the file's "
            "object_file), found nothing (a 'dg16m generate --meshes' dataset: pass its mesh "
            "folder as mesh_root)"
        )
    mesh_path = found[0]
    mesh = trimesh.load(mesh_path, force="mesh", process=False)
    vertices = np.asarray(mesh.vertices, dtype=np.float64) * data.object_scale
    faces = np.asarray(mesh.faces, dtype=np.int64)
    rng = np.random.default_rng(object_seed(seed, f"observation:{path.stem}"))
    points, _ = surface_points(vertices, faces, n_points, rng)
    poses = file_poses(data, np.arange(len(data.grasps)))
    passed = np.zeros(len(data.grasps), dtype=bool)
    passed[data.passing_indices] = True
    quality = data.extras.get("quality")
    return ClassifierObject(
        object_id=path.stem,
        points=points.astype(np.float32),
        poses=poses.astype(np.float32),
        labels={"dg16m": passed, "da2": da2_passed(data)},
        quality=np.full(len(passed), np.nan)
        if quality is None
        else np.asarray(quality, dtype=np.float64),
    )


def load_generated(
    folder: str | os.PathLike[str],
    *,
    n_points: int = DEFAULT_POINTS,
    seed: int = 0,
    limit: int | None = None,
    progress: bool = True,
    mesh_root: str | os.PathLike[str] | None = None,
) -> list[ClassifierObject]:
    """Every object of a ``dg16m generate`` folder (the first ``limit`` by file name); meshes
    as :func:`load_object` finds them."""
    files = grasp_files(folder)[:limit]
    return [
        load_object(f, n_points=n_points, seed=seed, mesh_root=mesh_root)
        for f in progress_bar(files, desc="objects", unit="obj", enabled=progress)
    ]


def split_objects(
    objects: Sequence[ClassifierObject], val_fraction: float, seed: int
) -> tuple[list[ClassifierObject], list[ClassifierObject]]:
    """``(train, validation)``: a seeded random ``val_fraction`` of the objects (at least one
    when there are two or more) held out whole.

    Raises:
        ClassifierDataError: ``val_fraction`` outside [0, 1).
    """
    if not 0.0 <= val_fraction < 1.0:
        raise ClassifierDataError(f"val_fraction: expected [0, 1), found {val_fraction}")
    order = np.random.default_rng(seed).permutation(len(objects))
    n_val = round(val_fraction * len(objects))
    if val_fraction > 0 and len(objects) >= 2:
        n_val = max(n_val, 1)
    held = set(order[:n_val].tolist())
    train = [o for i, o in enumerate(objects) if i not in held]
    val = [o for i, o in enumerate(objects) if i in held]
    return train, val


class BatchSampler:
    """Training batches of ``objects_per_batch`` objects x ``grasps_per_object`` grasps.

    Per object, half the grasps are drawn from its positives and half from its negatives
    (with replacement) when it has both, else all from the class it has.

    Args:
        objects: the training objects.
        label: a key of :data:`LABELS`.
        objects_per_batch: B.
        grasps_per_object: n (even).
        rng: the random stream.
    """

    def __init__(
        self,
        objects: Sequence[ClassifierObject],
        label: str,
        objects_per_batch: int,
        grasps_per_object: int,
        rng: np.random.Generator,
    ) -> None:
        if label not in LABELS:
            raise ClassifierDataError(f"label: expected one of {LABELS}, found {label!r}")
        if not objects:
            raise ClassifierDataError("objects: expected at least one, found none")
        if objects_per_batch < 1 or grasps_per_object < 2 or grasps_per_object % 2:
            raise ClassifierDataError(
                "expected objects_per_batch >= 1 and an even grasps_per_object >= 2, found "
                f"{objects_per_batch} and {grasps_per_object}"
            )
        self.objects, self.label = list(objects), label
        self.b, self.n, self.rng = objects_per_batch, grasps_per_object, rng
        self._positives = [np.flatnonzero(o.labels[label]) for o in self.objects]
        self._negatives = [np.flatnonzero(~o.labels[label]) for o in self.objects]

    def sample(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``points (B, P, 3)`` float32, ``poses (B, n, 2, 4, 4)`` float32, ``labels (B, n)``
        float32 (1 = positive)."""
        chosen = self.rng.integers(0, len(self.objects), size=self.b)
        points, poses, labels = [], [], []
        for k in chosen:
            pos, neg = self._positives[k], self._negatives[k]
            if pos.size and neg.size:
                rows = np.concatenate(
                    [
                        self.rng.choice(pos, self.n // 2, replace=True),
                        self.rng.choice(neg, self.n // 2, replace=True),
                    ]
                )
            else:
                rows = self.rng.choice(pos if pos.size else neg, self.n, replace=True)
            obj = self.objects[k]
            points.append(obj.points)
            poses.append(obj.poses[rows])
            labels.append(obj.labels[self.label][rows])
        return (
            np.stack(points),
            np.stack(poses),
            np.stack(labels).astype(np.float32),
        )
