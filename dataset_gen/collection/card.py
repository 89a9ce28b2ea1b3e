"""The dataset card, written with the data: counts, licences, parameters, a picture, Croissant.

:func:`write_card` writes, into the dataset folder::

    croissant.json          Croissant 1.0 JSON-LD metadata (what Hugging Face and Kaggle read):
                            the dataset, its licences, its files and a record set of objects
    card/README.md          the human card: counts per source and split, pass/fail balance,
                            size on disk, parameters and generator version, licences and
                            attribution, how the splits were checked, the picture
    card/summary.json       the same numbers, machine-readable (``dg16m dataset info``)
    card/objects.csv        one row per object: id, split, source, licence, creator, name,
                            dual grasps, passing, failing, files, geometry sha256
    card/sample.png         a sample of objects, each with a few of its passing dual grasps

Everything in it is a function of the folder's bytes (no clock time), so a resumed or a Ray
build writes the same card as an uninterrupted local one.
"""

from __future__ import annotations

import csv
import io
import json
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from dataset_gen.io import package_version, read_dg16m
from dataset_gen.objects.grasp_object import load_object
from dataset_gen.pipeline.render import render_grasp_sheet
from dataset_gen.sources.object_source import object_seed
from dg16m_core.atomic import write_bytes_atomic, write_json_atomic
from dg16m_core.hashing import file_sha256

from .recipe import SPLITS, DatasetError

CARD_FOLDER = "card"
CROISSANT_FILE = "croissant.json"
SUMMARY_FILE = "summary.json"
OBJECTS_FILE = "objects.csv"
SAMPLE_FILE = "sample.png"
SAMPLE_OBJECTS = 8
"""Objects in the card's picture (sources in turn)."""
SAMPLE_GRASPS = 3
"""Passing dual grasps drawn on each pictured object."""

LICENCE_URLS = {
    "MIT": "https://opensource.org/licenses/MIT",
    "CC0-1.0": "https://creativecommons.org/publicdomain/zero/1.0/",
    "CC-BY-3.0": "https://creativecommons.org/licenses/by/3.0/",
    "CC-BY-3.0-US": "https://creativecommons.org/licenses/by/3.0/us/",
    "Zlib": "https://opensource.org/licenses/Zlib",
}
"""Licence name (as the sources record it) -> its text's URL."""

CITATION = (
    "@article{dg16m2025, title={DG16M: A Large-Scale Dataset for Dual-Arm Grasping with "
    "Force-Optimized Grasps}, author={Karim, Md Faizal and Hashmi, Mohammed Saad and Bollimuntha, "
    "Shreya and Tapeti, Mahesh Reddy and Singh, Gaurav and Govindan, Nagamanikandan and Krishna, "
    "K Madhava}, journal={arXiv preprint arXiv:2503.08358}, year={2025}}"
)

OBJECT_COLUMNS = (
    "object_id",
    "split",
    "source",
    "licence",
    "creator",
    "name",
    "dual_grasps",
    "passing",
    "failing",
    "grasps_file",
    "mesh_file",
    "geometry_sha256",
)
"""The columns of ``card/objects.csv``, in order."""


DATA_SUFFIXES = (".h5", ".obj")
"""The files whose sizes the card adds up (the data; manifests record run times)."""


def _folder_bytes(folder: Path) -> int:
    """Bytes of the data files (:data:`DATA_SUFFIXES`) under ``folder``."""
    if not folder.is_dir():
        return 0
    return sum(p.stat().st_size for p in folder.rglob("*") if p.suffix in DATA_SUFFIXES)


def dataset_summary(
    folder: str | Path,
    manifest: Mapping[str, Any],
    *,
    disjoint: Mapping[str, Any],
    sources: Mapping[str, Any],
) -> dict[str, Any]:
    """The card's numbers (``card/summary.json``): counts per source and split, totals,
    pass/fail balance, failures, sizes on disk, licences, parameters, generator version, the
    split check and the imports' summaries."""
    folder = Path(folder)
    table: dict[str, dict[str, dict[str, int]]] = {}
    licences: dict[str, Counter[str]] = {}
    failed: dict[str, str] = {}
    for object_id, entry in sorted(manifest["entries"].items()):
        origin = entry.get("origin", {})
        source = str(origin.get("source", entry.get("source")))
        if entry["status"] != "ok":
            failed[object_id] = str(entry.get("error", ""))
            continue
        split = str(entry.get("split"))
        cell = table.setdefault(source, {}).setdefault(
            split, {"objects": 0, "dual_grasps": 0, "passing": 0, "failing": 0}
        )
        cell["objects"] += 1
        cell["dual_grasps"] += int(entry["pairs"])
        cell["passing"] += int(entry["passing"])
        cell["failing"] += int(entry["failing"])
        licences.setdefault(source, Counter())[str(origin.get("licence"))] += 1
    totals = {"objects": 0, "dual_grasps": 0, "passing": 0, "failing": 0}
    per_split = {split: dict.fromkeys(totals, 0) for split in SPLITS}
    for splits in table.values():
        for split, cell in splits.items():
            for key, value in cell.items():
                totals[key] += value
                per_split.setdefault(split, dict.fromkeys(totals, 0))[key] += value
    return {
        "format": "dg16m-dataset-card",
        "version": 1,
        "generator": manifest.get("created_by", f"dg16m {package_version()}"),
        "parameters": manifest["parameters"],
        "totals": totals,
        "passing_share": totals["passing"] / totals["dual_grasps"]
        if totals["dual_grasps"]
        else 0.0,
        "per_split": per_split,
        "per_source": {k: dict(sorted(v.items())) for k, v in sorted(table.items())},
        "licences": {k: dict(sorted(v.items())) for k, v in sorted(licences.items())},
        "failed_objects": len(failed),
        "failures": dict(list(failed.items())[:50]),
        "bytes": {
            "grasps": _folder_bytes(folder / "grasps"),
            "meshes": _folder_bytes(folder / "meshes"),
            "sources": _folder_bytes(folder / "sources"),
        },
        "splits_check": dict(disjoint),
        "imports": dict(sorted(sources.items())),
    }


def objects_csv(manifest: Mapping[str, Any]) -> str:
    """``card/objects.csv``: one row per finished object (:data:`OBJECT_COLUMNS`)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(OBJECT_COLUMNS)
    for object_id, entry in sorted(manifest["entries"].items()):
        if entry["status"] != "ok":
            continue
        origin = entry.get("origin", {})
        files = entry["files"]
        writer.writerow(
            [
                object_id,
                entry["split"],
                origin.get("source", ""),
                origin.get("licence", ""),
                origin.get("creator", ""),
                origin.get("name", ""),
                entry["pairs"],
                entry["passing"],
                entry["failing"],
                files["grasps"],
                files.get("mesh", ""),
                entry["geometry_sha256"],
            ]
        )
    return buffer.getvalue()


def _field(name: str, data_type: str, description: str) -> dict[str, Any]:
    return {
        "@type": "cr:Field",
        "@id": f"objects/{name}",
        "name": name,
        "description": description,
        "dataType": data_type,
        "source": {"fileObject": {"@id": "objects-table"}, "extract": {"column": name}},
    }


CROISSANT_CONTEXT: dict[str, Any] = {
    "@language": "en",
    "@vocab": "https://schema.org/",
    "citeAs": "cr:citeAs",
    "column": "cr:column",
    "conformsTo": "dct:conformsTo",
    "cr": "http://mlcommons.org/croissant/",
    "rai": "http://mlcommons.org/croissant/RAI/",
    "data": {"@id": "cr:data", "@type": "@json"},
    "dataType": {"@id": "cr:dataType", "@type": "@vocab"},
    "dct": "http://purl.org/dc/terms/",
    "examples": {"@id": "cr:examples", "@type": "@json"},
    "extract": "cr:extract",
    "field": "cr:field",
    "fileProperty": "cr:fileProperty",
    "fileObject": "cr:fileObject",
    "fileSet": "cr:fileSet",
    "format": "cr:format",
    "includes": "cr:includes",
    "isLiveDataset": "cr:isLiveDataset",
    "jsonPath": "cr:jsonPath",
    "key": "cr:key",
    "md5": "cr:md5",
    "parentField": "cr:parentField",
    "path": "cr:path",
    "recordSet": "cr:recordSet",
    "references": "cr:references",
    "regex": "cr:regex",
    "repeated": "cr:repeated",
    "replace": "cr:replace",
    "sc": "https://schema.org/",
    "separator": "cr:separator",
    "source": "cr:source",
    "subField": "cr:subField",
    "transform": "cr:transform",
}
"""The Croissant 1.0 JSON-LD context (the specification's)."""


def croissant(summary: Mapping[str, Any], folder: Path, name: str) -> dict[str, Any]:
    """Croissant 1.0 JSON-LD for the dataset in ``folder`` (its ``card/objects.csv`` must be
    written already: its sha256 is recorded)."""
    totals = summary["totals"]
    licences = sorted({lic for counts in summary["licences"].values() for lic in counts})
    table = folder / CARD_FOLDER / OBJECTS_FILE
    distribution: list[dict[str, Any]] = [
        {
            "@type": "cr:FileObject",
            "@id": "objects-table",
            "name": "objects-table",
            "description": "One row per object: split, source, licence, counts, files.",
            "contentUrl": f"{CARD_FOLDER}/{OBJECTS_FILE}",
            "encodingFormat": "text/csv",
            "sha256": file_sha256(table),
        },
        {
            "@type": "cr:FileSet",
            "@id": "grasp-files",
            "name": "grasp-files",
            "description": (
                "One HDF5 file per object in the DG16M release schema (grasps/grasps "
                "(N, 2, 4, 4), contact points and forces, losses, passing and failing indices) "
                "with dg16m extras (dg16m/): dataset_gen.io.dg16m."
            ),
            "encodingFormat": "application/x-hdf5",
            "includes": "grasps/*.h5",
        },
        {
            "@type": "cr:FileSet",
            "@id": "mesh-files",
            "name": "mesh-files",
            "description": "Object meshes (OBJ, metres): procedural ones and imported models.",
            "encodingFormat": "model/obj",
            "includes": ["meshes/*.obj", "sources/*/*.obj"],
        },
    ]
    fields = [
        _field("object_id", "sc:Text", "The object's id (its grasp file is grasps/<id>.h5)."),
        _field("split", "sc:Text", "train or validation (by object)."),
        _field("source", "sc:Text", "procedural, sweethome3d or pybullet."),
        _field("licence", "sc:Text", "The object's licence."),
        _field("creator", "sc:Text", "Who made the object's model."),
        _field("name", "sc:Text", "The model's name in its source."),
        _field("dual_grasps", "sc:Integer", "Dual grasps stored for the object."),
        _field("passing", "sc:Integer", "Of them, passing force closure."),
        _field("failing", "sc:Integer", "Of them, failing (loss above the release's 0.5)."),
        _field("grasps_file", "sc:Text", "The object's grasp file, relative to the dataset."),
        _field("mesh_file", "sc:Text", "The object's mesh, relative to the dataset."),
        _field("geometry_sha256", "sc:Text", "sha256 of the object's geometry."),
    ]
    return {
        "@context": CROISSANT_CONTEXT,
        "@type": "sc:Dataset",
        "name": name,
        "description": (
            f"Dual-arm grasps in the DG16M release schema: {totals['objects']} objects, "
            f"{totals['dual_grasps']} dual grasps ({totals['passing']} passing and "
            f"{totals['failing']} failing force closure), made by {summary['generator']}. "
            "Object-level train/validation splits, disjoint by geometry hash from the dg16m "
            "benchmarks."
        ),
        "conformsTo": "http://mlcommons.org/croissant/1.0",
        "citeAs": CITATION,
        "license": sorted({LICENCE_URLS.get(lic, lic) for lic in licences}),
        "url": "https://arxiv.org/abs/2503.08358",
        "version": "1.0.0",
        "keywords": ["dual-arm grasping", "force closure", "robotics", "DG16M"],
        "distribution": distribution,
        "recordSet": [
            {
                "@type": "cr:RecordSet",
                "@id": "objects",
                "name": "objects",
                "description": "The dataset's objects with their split, origin and counts.",
                "key": {"@id": "objects/object_id"},
                "field": fields,
            }
        ],
    }


def _sample_ids(manifest: Mapping[str, Any], seed: int) -> list[str]:
    """Up to :data:`SAMPLE_OBJECTS` finished objects, taking sources in turn (seeded)."""
    by_source: dict[str, list[str]] = {}
    for object_id, entry in sorted(manifest["entries"].items()):
        if entry["status"] == "ok" and entry.get("passing", 0) > 0:
            source = str(entry.get("origin", {}).get("source", entry.get("source")))
            by_source.setdefault(source, []).append(object_id)
    rng = np.random.default_rng(object_seed(seed, "card-sample"))
    queues = {s: list(rng.permutation(ids)) for s, ids in sorted(by_source.items())}
    chosen: list[str] = []
    while len(chosen) < SAMPLE_OBJECTS and any(queues.values()):
        for ids in queues.values():
            if ids and len(chosen) < SAMPLE_OBJECTS:
                chosen.append(str(ids.pop(0)))
    return chosen


def render_sample(folder: Path, manifest: Mapping[str, Any], out: Path, seed: int = 0) -> Path:
    """``card/sample.png``: sampled objects with :data:`SAMPLE_GRASPS` passing dual grasps
    each (object frame: the mesh centred on its centroid, as the grasps are)."""
    items = []
    for object_id in _sample_ids(manifest, seed):
        entry = manifest["entries"][object_id]
        data = read_dg16m(folder / entry["files"]["grasps"])
        obj = load_object(folder / entry["files"]["mesh"], scale=1.0, allow_any_size=True)
        rng = np.random.default_rng(object_seed(seed, f"card-grasps:{object_id}"))
        picked = rng.choice(data.passing_indices, SAMPLE_GRASPS, replace=False)
        source = entry.get("origin", {}).get("source", "")
        label = f"{object_id}\n{source}, {entry['split']}, {entry['passing']} passing"
        items.append((label, obj.mesh, data.grasps[np.sort(picked)]))
    if not items:
        raise DatasetError(
            "card: expected at least one object with a passing dual grasp, found none"
        )
    return render_grasp_sheet(
        items, out, title="A sample of the dataset: objects with three passing dual grasps each"
    )


def _markdown_table(summary: Mapping[str, Any]) -> list[str]:
    lines = [
        "| source | split | objects | dual grasps | passing | failing | passing share |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for source, splits in summary["per_source"].items():
        for split, cell in splits.items():
            share = cell["passing"] / cell["dual_grasps"] if cell["dual_grasps"] else 0.0
            lines.append(
                f"| {source} | {split} | {cell['objects']:,} | {cell['dual_grasps']:,} | "
                f"{cell['passing']:,} | {cell['failing']:,} | {100 * share:.1f}% |"
            )
    t = summary["totals"]
    lines.append(
        f"| **all** | | **{t['objects']:,}** | **{t['dual_grasps']:,}** | {t['passing']:,} | "
        f"{t['failing']:,} | {100 * summary['passing_share']:.1f}% |"
    )
    return lines


def card_markdown(summary: Mapping[str, Any], name: str) -> str:
    """``card/README.md``, the human card."""
    t = summary["totals"]
    size = sum(summary["bytes"].values())
    check = summary["splits_check"]
    recipe = summary["parameters"]["recipe"]
    generation = summary["parameters"]["generation"]
    licence_lines = [
        f"- {source}: " + ", ".join(f"{lic} ({n:,} objects)" for lic, n in counts.items())
        for source, counts in summary["licences"].items()
    ]
    bench = ", ".join(f"{k} (sha256 {v[:12]})" for k, v in check.get("benchmarks", {}).items())
    parts = [
        f"# {name}",
        "",
        f"{t['objects']:,} objects, {t['dual_grasps']:,} dual grasps ({t['passing']:,} passing "
        f"and {t['failing']:,} failing force closure), {size / 1e9:.2f} GB on disk. Made by "
        f"`{summary['generator']}` with `dg16m dataset build`.",
        "",
        "![a sample of objects with passing dual grasps](sample.png)",
        "",
        "## Counts",
        "",
        *_markdown_table(summary),
        "",
        f"Objects that failed (no dual grasp to store): {summary['failed_objects']} (reasons in "
        "`card/summary.json`). Sizes: "
        + ", ".join(f"{k} {v / 1e6:,.1f} MB" for k, v in summary["bytes"].items())
        + ".",
        "",
        "## Splits",
        "",
        f"By object: {100 * recipe['validation_fraction']:g}% of the objects (drawn from their ids "
        f"with split seed {recipe['split_seed']}) are in `validation`, the rest in `train`. "
        f"Checked by geometry hash: {check['objects_checked']:,} objects against "
        f"{check['benchmark_objects']:,} benchmark objects ({bench or 'none'}): "
        f"{check['shared']} shared, and {check['splits_shared']} geometries in both splits.",
        "",
        "## Parameters",
        "",
        "```json",
        json.dumps(generation, indent=1, sort_keys=True),
        "```",
        "",
        "The recipe (`dg16m dataset build` options):",
        "",
        "```json",
        json.dumps(recipe, indent=1, sort_keys=True),
        "```",
        "",
        "## Licences and attribution",
        "",
        *licence_lines,
        "",
        "Each object's source, licence and creator are in `card/objects.csv`. Imported furniture "
        "carries its attribution and the list of changes made to it (CC-BY-3.0 asks for both) in "
        "`sources/sweethome3d/ATTRIBUTION.md`.",
        "",
        "## Files",
        "",
        "- `grasps/<id>.h5`: one object's dual grasps, DG16M release schema with dg16m extras "
        "(see the docs' file formats page); `meshes/<id>.obj` or `sources/<source>/<id>.obj`: "
        "its mesh (metres; the grasps are in the frame of the mesh centred on its centroid).",
        "- `manifest.json`: per object its split, origin, files, counts and geometry sha256.",
        "- `croissant.json`: Croissant 1.0 metadata.",
        "",
        "## Citation",
        "",
        "```bibtex",
        CITATION,
        "```",
        "",
    ]
    return "\n".join(parts)


def write_card(
    folder: str | Path,
    manifest: Mapping[str, Any],
    *,
    disjoint: Mapping[str, Any],
    sources: Mapping[str, Any],
    name: str = "dg16m-dataset",
    seed: int = 0,
) -> dict[str, Any]:
    """Write the card files (module docstring) atomically; returns the summary."""
    folder = Path(folder)
    card = folder / CARD_FOLDER
    card.mkdir(exist_ok=True)
    summary = dataset_summary(folder, manifest, disjoint=disjoint, sources=sources)
    write_bytes_atomic(card / OBJECTS_FILE, objects_csv(manifest).encode())
    render_sample(folder, manifest, card / SAMPLE_FILE, seed=seed)
    write_json_atomic(card / SUMMARY_FILE, summary)
    write_bytes_atomic(card / "README.md", card_markdown(summary, name).encode())
    write_json_atomic(folder / CROISSANT_FILE, croissant(summary, folder, name))
    return summary


def read_summary(folder: str | Path) -> dict[str, Any]:
    """A dataset's ``card/summary.json``.

    Raises:
        DatasetError: no card there, or not a card.
    """
    path = Path(folder) / CARD_FOLDER / SUMMARY_FILE
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DatasetError(
            f"{folder}: expected a dataset folder with {CARD_FOLDER}/{SUMMARY_FILE} (made by "
            "'dg16m dataset build'), found none"
        ) from None
    except (OSError, ValueError) as exc:
        raise DatasetError(f"{path}: expected a dataset card (JSON), found {exc}") from None
    if not isinstance(summary, dict) or summary.get("format") != "dg16m-dataset-card":
        raise DatasetError(f"{path}: expected format 'dg16m-dataset-card', found another file")
    return summary
