"""The objects of a dataset, from each source, as :class:`DatasetItem` records.

* ``procedural``: the train seeds of every procedural family
  (:func:`dataset_gen.sources.procedural.object_specs`, seeds from ``procedural_seed``; the
  benchmark's seeds are another range, and the build checks geometry hashes too). Made by dg16m
  (MIT).
* ``sweethome3d``: every usable model of Debian's ``sweethome3d-furniture``
  (:func:`dataset_gen.real.sweethome3d.usable_entries`) that is not a benchmark id, imported
  into ``<dataset>/sources/sweethome3d/`` (repaired, in metres, with ``ATTRIBUTION.md``); a
  model whose imported file is a benchmark object's file (by sha256) is left out. CC0 or
  CC-BY-3.0 per library.
* ``pybullet``: the 1,000 ``random_urdfs`` of an installed pybullet, sized for two arms, in
  ``<dataset>/sources/pybullet/`` (:mod:`dataset_gen.real.pybullet_objects`; zlib).

An item knows its split (:func:`dataset_gen.collection.splits.split_of`), its origin (source,
licence, creator, name) and, for an imported model, the sha256 of its file and its path inside
the dataset folder.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dataset_gen.real import pybullet_objects, sweethome3d
from dataset_gen.sources.object_source import ObjectSource, procedural_sources
from dataset_gen.sources.procedural import object_specs

from .recipe import DatasetError, DatasetRecipe
from .splits import Exclusion, split_of

SOURCES_FOLDER = "sources"
PROCEDURAL_LICENCE = "MIT"
PROCEDURAL_CREATOR = "dg16m procedural families (dataset_gen.sources.procedural)"


@dataclass(frozen=True)
class DatasetItem:
    """One object of a dataset.

    Attributes:
        object_id: unique in the dataset.
        source: how to load it (:class:`~dataset_gen.sources.object_source.ObjectSource`).
        split: ``"train"`` or ``"validation"``.
        origin: JSON-ready ``{"source", "licence", "creator", "name"}`` (+ ``"library"``, ``"url"``
            where known), recorded in the manifest entry and the card.
        mesh_file: for an imported model, its file relative to the dataset folder.
        source_sha256: for an imported model, the sha256 of that file.
    """

    object_id: str
    source: ObjectSource
    split: str
    origin: Mapping[str, Any] = field(default_factory=dict)
    mesh_file: str | None = None
    source_sha256: str | None = None


def procedural_items(count: int, recipe: DatasetRecipe, *, start: int = 0) -> list[DatasetItem]:
    """Procedural objects ``start`` to ``start + count - 1`` of the train order (families in
    turn, seeds from ``recipe.procedural_seed``)."""
    specs = object_specs(start + count, seed=recipe.procedural_seed, split="train")[start:]
    return [
        DatasetItem(
            object_id=source.object_id,
            source=source,
            split=split_of(source.object_id, recipe.validation_fraction, recipe.split_seed),
            origin={
                "source": "procedural",
                "licence": PROCEDURAL_LICENCE,
                "creator": PROCEDURAL_CREATOR,
                "name": f"{source.family} (seed {source.family_seed})",
            },
        )
        for source in procedural_sources(specs)
    ]


def _imported_items(
    folder: Path,
    manifest: Mapping[str, Any],
    recipe: DatasetRecipe,
    exclusion: Exclusion,
    origin_of: Any,
) -> tuple[list[DatasetItem], dict[str, str]]:
    """Items for the ``ok`` entries of an import folder's manifest, and the ids left out
    because their file is a benchmark object's file (id -> benchmark object)."""
    items: list[DatasetItem] = []
    left_out: dict[str, str] = {}
    relative = folder.relative_to(folder.parents[1])  # sources/<name>
    for object_id, entry in sorted(manifest["entries"].items()):
        if entry.get("status") != "ok":
            continue
        sha256 = str(entry["sha256"])
        if sha256 in exclusion.source_sha256:
            left_out[object_id] = exclusion.source_sha256[sha256]
            continue
        mesh = folder / entry["files"]["mesh"]
        items.append(
            DatasetItem(
                object_id=object_id,
                source=ObjectSource(object_id=object_id, mesh=mesh, scale=1.0),
                split=split_of(object_id, recipe.validation_fraction, recipe.split_seed),
                origin=origin_of(entry),
                mesh_file=f"{relative.as_posix()}/{entry['files']['mesh']}",
                source_sha256=sha256,
            )
        )
    return items, left_out


def _sweethome3d_origin(entry: Mapping[str, Any]) -> dict[str, Any]:
    source = entry["source"]
    return {
        "source": "sweethome3d",
        "licence": source.get("licence"),
        "creator": source.get("creator"),
        "name": source.get("name"),
        "library": source.get("library"),
        "modified": entry.get("modified"),
    }


def sweethome3d_items(
    out: Path,
    recipe: DatasetRecipe,
    exclusion: Exclusion,
    *,
    root: str | Path = sweethome3d.DEFAULT_ROOT,
    ids: Sequence[str] | None = None,
    workers: int = 1,
    progress: bool = True,
    retry_failed: bool = False,
) -> tuple[list[DatasetItem], dict[str, Any]]:
    """Import the usable Sweet Home 3D models that are not benchmark ids into
    ``out/sources/sweethome3d`` (resumable) and return their items and a summary (usable,
    imported, failed with reasons, left out as benchmark files). ``ids``: only these models
    (of the usable ones; for a small dataset or a test). Models whose import failed in an
    earlier run keep their verdict unless ``retry_failed``.

    Raises:
        DatasetError: the furniture libraries are not installed.
    """
    try:
        entries = sweethome3d.usable_entries(sweethome3d.read_catalogs(root))
    except sweethome3d.SweetHomeError as exc:
        raise DatasetError(f"sources: sweethome3d: {exc}; or leave it out of --sources") from None
    if ids is not None:
        entries = [e for e in entries if e.object_id in set(ids)]
    chosen = [e for e in entries if e.object_id not in exclusion.ids]
    folder = out / SOURCES_FOLDER / "sweethome3d"
    manifest = sweethome3d.import_library(
        folder,
        chosen,
        root=root,
        seed=recipe.import_seed,
        workers=workers,
        progress=progress,
        keep_failed=not retry_failed,
    )
    items, left_out = _imported_items(folder, manifest, recipe, exclusion, _sweethome3d_origin)
    return items, _import_summary(len(entries), len(entries) - len(chosen), manifest, left_out)


def _pybullet_origin(entry: Mapping[str, Any]) -> dict[str, Any]:
    return {
        "source": "pybullet",
        "licence": pybullet_objects.LICENCE,
        "creator": pybullet_objects.CREATOR,
        "name": entry["source"]["file"],
        "url": pybullet_objects.SOURCE_URL,
    }


def pybullet_items(
    out: Path,
    recipe: DatasetRecipe,
    exclusion: Exclusion,
    *,
    limit: int | None = None,
    workers: int = 1,
    progress: bool = True,
    retry_failed: bool = False,
) -> tuple[list[DatasetItem], dict[str, Any]]:
    """Import pybullet's ``random_urdfs`` (the first ``limit``, default all) into
    ``out/sources/pybullet`` (resumable) and return their items and a summary.

    Raises:
        DatasetError: pybullet is not installed.
    """
    try:
        found = pybullet_objects.random_urdfs()[:limit]
    except pybullet_objects.PybulletObjectsError as exc:
        raise DatasetError(str(exc)) from None
    folder = out / SOURCES_FOLDER / "pybullet"
    manifest = pybullet_objects.import_random_urdfs(
        folder,
        found,
        seed=recipe.import_seed,
        workers=workers,
        progress=progress,
        keep_failed=not retry_failed,
    )
    items, left_out = _imported_items(folder, manifest, recipe, exclusion, _pybullet_origin)
    return items, _import_summary(len(found), 0, manifest, left_out)


def _import_summary(
    available: int, benchmark_ids: int, manifest: Mapping[str, Any], left_out: Mapping[str, str]
) -> dict[str, Any]:
    entries = manifest["entries"]
    failed = {k: str(e.get("error")) for k, e in sorted(entries.items()) if e["status"] != "ok"}
    return {
        "available": available,
        "benchmark_ids_left_out": benchmark_ids,
        "imported": sum(e["status"] == "ok" for e in entries.values()),
        "import_failed": len(failed),
        "import_failures": failed,
        "benchmark_files_left_out": dict(sorted(left_out.items())),
    }
