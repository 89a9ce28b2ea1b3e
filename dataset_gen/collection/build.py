"""Build a dataset: import the sources, generate every object, check the splits, write the card.

:func:`build_dataset` writes, into one folder::

    manifest.json                  kind "dataset": per object its status, files, split, origin
                                   (source, licence, creator, name), geometry sha256 and counts
    grasps/<id>.h5                 the object's dual grasps (DG16M release schema + dg16m/ extras,
                                   gzip-compressed in chunks: dataset_gen.io.dg16m)
    meshes/<id>.obj                a procedural object's mesh
    sources/sweethome3d/           imported furniture (<id>.obj, manifest.json, ATTRIBUTION.md)
    sources/pybullet/              imported random_urdfs (with --sources ...,pybullet)
    exclusion.json                 the benchmark objects it was checked against (hashes)
    card/                          the dataset card (dataset_gen.collection.card)

Every object's random stream comes from ``(seed, object id)`` (the generator's rule), each file
is written atomically and the manifest records an object once its files are there, so a rerun
after Ctrl-C, SIGTERM or ``kill -9`` does only the rest and the folder ends with the same bytes
whatever the worker count or backend (``card/`` aside, which records how long the run took).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dataset_gen.pipeline.generate import (
    GenerationParameters,
    generate_object,
    source_kind,
    write_object,
)
from dataset_gen.pipeline.parallel import Backend, run_resumable
from dg16m_core.atomic import write_json_atomic
from dg16m_core.errors import Dg16mError
from dg16m_core.hashing import file_sha256

from .card import write_card
from .recipe import DatasetError, DatasetRecipe
from .sources import DatasetItem, procedural_items, pybullet_items, sweethome3d_items
from .splits import Exclusion, check_disjoint, geometry_sha256

DATASET_KIND = "dataset"
EXCLUSION_FILE = "exclusion.json"
MANIFEST_EVERY_S = 10.0
"""The dataset's manifest is rewritten at most this often (s) while objects finish (and when
the run ends or is interrupted): rewriting thousands of entries after every object would cost
more than the objects."""
MAX_TOP_UPS = 3
"""Rounds of extra procedural objects a build adds when failed objects leave it short."""


def dataset_parameters() -> GenerationParameters:
    """The generator's parameters of a dataset: the release's
    (:data:`~dg16m_core.parameters.PAPER`: 500 single-arm grasps, up to 2,000 passing and 2,000 failing pairs per object), the
    physical convention, and open hands checked against the exact mesh (no CoACD: the dataset
    is not simulated, and the mesh is the truth the decomposition approximates)."""
    return GenerationParameters(clearance_geometry="mesh")


def _task(item: DatasetItem, out: str, params: GenerationParameters) -> dict[str, Any]:
    """Load, hash, generate and write one object; its manifest entry (``failed`` with the
    reason for an object that cannot be loaded or yields no dual grasp)."""
    base: dict[str, Any] = {"split": item.split, "origin": dict(item.origin)}
    if item.source_sha256 is not None:
        base["source_sha256"] = item.source_sha256
    try:
        obj = item.source.load(params.mass)
        geometry = geometry_sha256(obj.mesh.vertices, obj.mesh.faces)
        data = generate_object(obj, params, object_file=item.source.object_file)
    except Dg16mError as exc:  # a broken mesh or an unusable object fails only its own entry
        kind = source_kind(item.source)
        return {"status": "failed", "files": {}, "error": str(exc), "source": kind, **base}
    entry = write_object(item.source, obj, data, out, params)
    entry.update(base)
    entry["geometry_sha256"] = geometry
    if entry["status"] == "ok":
        entry["sha256"] = file_sha256(Path(out) / entry["files"]["grasps"])
        if item.mesh_file is not None:
            entry["files"]["mesh"] = item.mesh_file
    return entry


@dataclass
class DatasetBuild:
    """What :func:`build_dataset` did.

    Attributes:
        manifest: the dataset's manifest.
        sources: per imported source, its import summary.
        disjoint: the split check's record (:func:`~dataset_gen.collection.splits.check_disjoint`).
        items: every object the build asked for, in order.
        summary: the card's numbers (:func:`~dataset_gen.collection.card.dataset_summary`;
            empty when the build wrote no card).
    """

    manifest: dict[str, Any]
    sources: dict[str, Any] = field(default_factory=dict)
    disjoint: dict[str, Any] = field(default_factory=dict)
    items: list[DatasetItem] = field(default_factory=list)
    summary: dict[str, Any] = field(default_factory=dict)

    def ok_entries(self) -> dict[str, dict[str, Any]]:
        """The finished objects' entries."""
        return {k: e for k, e in self.manifest["entries"].items() if e["status"] == "ok"}


def _exclusion_sha256(exclusion: Exclusion) -> str:
    text = json.dumps(exclusion.to_dict(), sort_keys=True).encode()
    return hashlib.sha256(text).hexdigest()


def _write_exclusion(out: Path, exclusion: Exclusion) -> None:
    """Write ``exclusion.json``; refuse a folder checked against other benchmarks."""
    path = out / EXCLUSION_FILE
    wanted = exclusion.to_dict()
    if path.is_file():
        try:
            found = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise DatasetError(
                f"{path}: expected the benchmarks' hashes (JSON), found {exc}"
            ) from None
        if found != wanted:
            raise DatasetError(
                f"{out}: expected a dataset checked against the same benchmarks to resume, found "
                f"{EXCLUSION_FILE} of others (benchmarks {found.get('benchmarks')}); use another "
                "--out"
            )
        return
    write_json_atomic(path, wanted)


def build_dataset(
    out: str | Path,
    recipe: DatasetRecipe,
    exclusion: Exclusion,
    *,
    params: GenerationParameters | None = None,
    workers: int = 1,
    backend: Backend = "local",
    address: str | None = None,
    progress: bool = True,
    card: bool = True,
    retry_failed: bool = False,
    log: Callable[[str], None] = print,
) -> DatasetBuild:
    """Build (or resume) the dataset ``recipe`` describes into ``out`` (module docstring).

    Args:
        out: the dataset folder.
        recipe: objects, sources, splits, seeds.
        exclusion: the benchmarks' objects (ids, geometry and source-file hashes).
        params: the generator's parameters (default :func:`dataset_parameters`).
        workers, backend, address: local processes, or Ray (``backend="ray"``).
        progress: progress bars.
        card: write the card (:func:`~dataset_gen.collection.card.write_card`) at the end.
        retry_failed: try again the imports and objects that failed in an earlier run (by
            default their verdicts are kept: with the same recipe and parameters they fail the
            same way).
        log: where one-line stage messages go.

    Raises:
        DatasetError: a missing source, a folder of another dataset (other recipe, parameters
            or benchmarks), or a dataset object shared with a benchmark or across splits.
    """
    out = Path(out)
    params = params if params is not None else dataset_parameters()
    if out.exists() and not out.is_dir():
        raise DatasetError(f"--out: expected a folder, found a file {out}")
    out.mkdir(parents=True, exist_ok=True)
    _write_exclusion(out, exclusion)
    build = DatasetBuild(manifest={})
    others: list[DatasetItem] = []
    if "sweethome3d" in recipe.sources:
        log("importing Sweet Home 3D models that are not in a benchmark ...")
        items, summary = sweethome3d_items(
            out,
            recipe,
            exclusion,
            ids=recipe.sweethome3d_ids,
            workers=workers,
            progress=progress,
            retry_failed=retry_failed,
        )
        others += items
        build.sources["sweethome3d"] = summary
    if "pybullet" in recipe.sources:
        log("importing pybullet's random_urdfs ...")
        items, summary = pybullet_items(
            out,
            recipe,
            exclusion,
            limit=recipe.pybullet_limit,
            workers=workers,
            progress=progress,
            retry_failed=retry_failed,
        )
        others += items
        build.sources["pybullet"] = summary
    n_procedural = max(recipe.objects - len(others), 0)
    build.items = others + procedural_items(n_procedural, recipe)
    parameters = {
        "recipe": recipe.to_dict(),
        "generation": params.to_dict(),
        "exclusion_sha256": _exclusion_sha256(exclusion),
    }
    missing = 0
    for round_ in range(MAX_TOP_UPS + 1):
        if round_:
            log(f"{missing} objects short of {recipe.objects}: adding {missing} procedural ones")
        build.manifest = run_resumable(
            _task,
            build.items,
            (str(out.resolve()), params),
            root=out,
            kind=DATASET_KIND,
            parameters=parameters,
            folders=("grasps", "meshes"),
            error=DatasetError,
            workers=workers,
            backend=backend,
            address=address,
            progress=progress,
            desc="dataset",
            write_every_s=MANIFEST_EVERY_S,
            keep_failed=not retry_failed,
        )
        missing = recipe.objects - len(build.ok_entries())
        if missing <= 0:
            break
        build.items += procedural_items(missing, recipe, start=n_procedural)
        n_procedural += missing
    build.disjoint = check_disjoint(build.manifest["entries"], exclusion)
    if card:
        log("writing the card ...")
        build.summary = write_card(
            out, build.manifest, disjoint=build.disjoint, sources=build.sources
        )
    return build


def ok_items(build: DatasetBuild) -> Sequence[DatasetItem]:
    """The items whose object was built."""
    ok = build.ok_entries()
    return [item for item in build.items if item.object_id in ok]


def entries_by_split(entries: Mapping[str, Mapping[str, Any]]) -> dict[str, list[str]]:
    """``{"train": [ids], "validation": [ids]}`` of the finished entries, sorted."""
    out: dict[str, list[str]] = {"train": [], "validation": []}
    for object_id, entry in sorted(entries.items()):
        if entry.get("status") == "ok":
            out.setdefault(str(entry.get("split")), []).append(object_id)
    return out


def check_member(folder: str | Path, file: str | Path) -> dict[str, Any]:
    """Check that ``file`` is the grasp file the dataset ``folder`` lists for its object (the
    object id is the file's stem): same bytes (sha256) as when the dataset was built.

    Returns:
        The object's manifest entry.

    Raises:
        DatasetError: ``folder`` is not a dataset, the object is not in it (or failed), or the
            file's sha256 differs from the one recorded (a file of another dataset, or a
            changed or truncated one).
    """
    from dataset_gen.io import read_manifest

    folder, file = Path(folder), Path(file)
    try:
        manifest = read_manifest(folder)
    except Dg16mError as exc:
        raise DatasetError(f"--dataset {folder}: expected a dataset folder, found {exc}") from None
    if manifest["kind"] != DATASET_KIND:
        raise DatasetError(
            f"--dataset {folder}: expected a dataset folder (manifest kind 'dataset'), found "
            f"kind {manifest['kind']!r}"
        )
    object_id = file.stem
    entry = manifest["entries"].get(object_id)
    if entry is None or entry["status"] != "ok":
        raise DatasetError(
            f"{file}: expected a grasp file of an object of {folder}, found no finished object "
            f"{object_id!r} in its manifest"
        )
    found, recorded = file_sha256(file), entry.get("sha256")
    if found != recorded:
        raise DatasetError(
            f"{file}: expected the grasp file {folder} was built with (sha256 "
            f"{str(recorded)[:12]}), found other bytes (sha256 {found[:12]}): a file of another "
            "dataset, or one changed or cut short since"
        )
    return dict(entry)


def dataset_folder_of(file: str | Path) -> Path | None:
    """The dataset folder a grasp file sits in (``<dataset>/grasps/<id>.h5``), or None."""
    path = Path(file).resolve()
    folder = path.parent.parent
    if path.parent.name != "grasps" or not (folder / "manifest.json").is_file():
        return None
    try:
        kind = json.loads((folder / "manifest.json").read_text(encoding="utf-8")).get("kind")
    except (OSError, ValueError, AttributeError):
        return None
    return folder if kind == DATASET_KIND else None
