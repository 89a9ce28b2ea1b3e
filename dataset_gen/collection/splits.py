"""Object-level splits, and the check that no dataset object is a benchmark object.

Every object goes to one split, ``train`` or ``validation``, by its id alone
(:func:`split_of`): the same object lands in the same split in any build, whatever else the
dataset holds. An object is identified by its geometry (:func:`geometry_sha256`: the mesh the
generator grasped, as vertices and faces in the object frame), so a model that reaches the
dataset under another id or from another source is still recognised: :func:`check_disjoint`
refuses a dataset whose objects share a geometry with a benchmark object (or an id, or a source
file) and one where the same geometry sits in both splits.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dataset_gen.sources.object_source import object_seed

from .recipe import DatasetError

GEOMETRY_DECIMALS = 9
"""Vertices are rounded to this many decimals of a metre (1 nm) before hashing, so that a
last-bit difference of a float does not make a different object."""


def split_of(object_id: str, validation_fraction: float, seed: int = 0) -> str:
    """``"validation"`` for about ``validation_fraction`` of the ids, else ``"train"``: a
    uniform number in [0, 1) derived from ``(seed, object_id)`` (sha256) is compared with the
    fraction."""
    u = object_seed(seed, f"split:{object_id}") / 2.0**64
    return "validation" if u < validation_fraction else "train"


def geometry_sha256(vertices: np.ndarray, faces: np.ndarray) -> str:
    """sha256 (hex) of a mesh's geometry: vertices (V, 3) in m rounded to
    :data:`GEOMETRY_DECIMALS` as little-endian float64, then faces (F, 3) as little-endian
    int64, with their shapes."""
    v = np.round(np.asarray(vertices, dtype=np.float64), GEOMETRY_DECIMALS) + 0.0  # no -0.0
    f = np.asarray(faces, dtype=np.int64)
    digest = hashlib.sha256()
    digest.update(f"dg16m-geometry 1 {v.shape} {f.shape}\n".encode())
    digest.update(np.ascontiguousarray(v, dtype="<f8").tobytes())
    digest.update(np.ascontiguousarray(f, dtype="<i8").tobytes())
    return digest.hexdigest()


@dataclass(frozen=True)
class Exclusion:
    """What a dataset must not contain: the benchmarks' objects.

    Attributes:
        geometry: geometry sha256 (:func:`geometry_sha256`) -> ``"<benchmark>/<object id>"``.
        ids: object id -> benchmark name (an id reserved by a benchmark, e.g. a Sweet Home 3D
            model of the real benchmark).
        source_sha256: sha256 of a benchmark object's source file (an imported OBJ) ->
            ``"<benchmark>/<object id>"``.
        benchmarks: benchmark name -> its file's sha256 (recorded in the card).
    """

    geometry: Mapping[str, str] = field(default_factory=dict)
    ids: Mapping[str, str] = field(default_factory=dict)
    source_sha256: Mapping[str, str] = field(default_factory=dict)
    benchmarks: Mapping[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, sorted (the dataset's ``exclusion.json``)."""
        return {
            "benchmarks": dict(sorted(self.benchmarks.items())),
            "geometry_sha256": dict(sorted(self.geometry.items())),
            "ids": dict(sorted(self.ids.items())),
            "source_sha256": dict(sorted(self.source_sha256.items())),
        }


def check_disjoint(
    entries: Mapping[str, Mapping[str, Any]], exclusion: Exclusion
) -> dict[str, Any]:
    """Check a dataset's finished entries against the benchmarks and across its splits.

    Args:
        entries: the dataset manifest's entries (object id -> entry with ``status``,
            ``split``, ``geometry_sha256`` and optionally ``source_sha256``).
        exclusion: the benchmarks' objects.

    Returns:
        ``{"objects_checked", "benchmark_objects", "benchmarks", "shared": 0,
        "splits_shared": 0}`` for the card.

    Raises:
        DatasetError: an entry without its hash, an object that is a benchmark object (by id,
            geometry or source file), or one geometry in both splits; the message lists them.
    """
    shared: list[str] = []
    split_of_geometry: dict[str, tuple[str, str]] = {}
    across: list[str] = []
    checked = 0
    for object_id, entry in sorted(entries.items()):
        if entry.get("status") != "ok":
            continue
        geometry = entry.get("geometry_sha256")
        if not isinstance(geometry, str):
            raise DatasetError(
                f"{object_id}: expected its geometry_sha256 in the manifest, found "
                f"{geometry!r} (a folder of another kind of dataset?)"
            )
        checked += 1
        if object_id in exclusion.ids:
            shared.append(f"{object_id} (id of {exclusion.ids[object_id]})")
        if geometry in exclusion.geometry:
            shared.append(f"{object_id} (geometry of {exclusion.geometry[geometry]})")
        source = entry.get("source_sha256")
        if isinstance(source, str) and source in exclusion.source_sha256:
            shared.append(f"{object_id} (source file of {exclusion.source_sha256[source]})")
        split = str(entry.get("split"))
        first = split_of_geometry.setdefault(geometry, (split, object_id))
        if first[0] != split:
            across.append(f"{first[1]} ({first[0]}) and {object_id} ({split})")
    if shared:
        raise DatasetError(
            f"expected no benchmark object in the dataset, found {len(shared)}: "
            f"{'; '.join(shared[:10])}"
        )
    if across:
        raise DatasetError(
            f"expected each geometry in one split, found {len(across)} in both: "
            f"{'; '.join(across[:10])}"
        )
    return {
        "objects_checked": checked,
        "benchmark_objects": len(exclusion.geometry),
        "benchmarks": dict(sorted(exclusion.benchmarks.items())),
        "shared": 0,
        "splits_shared": 0,
    }
