"""Object library folders: meshes, convex parts and a manifest, written and read back.

Layout of a folder written by ``dg16m objects make``::

    DIR/manifest.json            kind "objects" (schema in dataset_gen.io)
    DIR/meshes/<object_id>.obj   watertight union mesh, object frame (m), centred at its centroid
    DIR/parts/<object_id>.json   {"format": "dg16m-parts", "schema_version": 1,
                                  "object_id": ..., "parts": [ConvexPart.to_dict(), ...]}

Meshes are written already centred and scaled, so loading them with ``scale=1`` and centring
again is the identity (up to floating-point rounding of the OBJ text, 1e-10 m).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from dataset_gen import io
from dataset_gen.objects.grasp_object import (
    DEFAULT_MASS_KG,
    ConvexPart,
    GraspObject,
    load_object,
    part_from_dict,
)
from dataset_gen.sources import procedural
from dg16m_core.atomic import write_bytes_atomic, write_json_atomic
from dg16m_core.checks import check_number
from dg16m_core.errors import MeshError

PARTS_FORMAT = "dg16m-parts"
PARTS_SCHEMA_VERSION = 1


def object_entry(obj: GraspObject, mesh_file: str, parts_file: str | None) -> dict[str, Any]:
    """Manifest entry describing ``obj`` (JSON-ready)."""
    props = obj.mass_properties
    files = {"mesh": mesh_file}
    if parts_file is not None:
        files["parts"] = parts_file
    return {
        "status": "ok",
        "files": files,
        "extents_m": [round(float(e), 6) for e in obj.extents],
        "watertight": obj.is_watertight,
        "mass_kg": props.mass,
        "volume_m3": None if props.volume is None else round(props.volume, 9),
        "n_faces": len(obj.mesh.faces),
        "n_parts": None if obj.parts is None else len(obj.parts),
        **obj.metadata,
    }


def write_parts(path: str | os.PathLike[str], object_id: str, parts: Sequence[ConvexPart]) -> None:
    """Write convex parts as JSON (atomic)."""
    write_json_atomic(
        path,
        {
            "format": PARTS_FORMAT,
            "schema_version": PARTS_SCHEMA_VERSION,
            "object_id": object_id,
            "parts": [part.to_dict() for part in parts],
        },
    )


def read_parts(path: str | os.PathLike[str]) -> list[ConvexPart]:
    """Read a parts file written by :func:`write_parts`; raises MeshError when malformed."""
    path = Path(path)
    try:
        payload = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise MeshError(f"{path}: no such parts file") from None
    except json.JSONDecodeError as exc:
        raise MeshError(f"{path}: expected JSON, found a parse error at line {exc.lineno}") from exc
    if not isinstance(payload, dict) or payload.get("format") != PARTS_FORMAT:
        raise MeshError(f"{path}: expected a {PARTS_FORMAT!r} file, found {str(payload)[:60]!r}")
    if payload.get("schema_version") != PARTS_SCHEMA_VERSION:
        raise MeshError(
            f"{path}: expected schema_version {PARTS_SCHEMA_VERSION}, "
            f"found {payload.get('schema_version')!r}"
        )
    parts = payload.get("parts")
    if not isinstance(parts, list) or not parts:
        raise MeshError(f"{path}: expected a non-empty list of parts, found {type(parts).__name__}")
    return [part_from_dict(p) for p in parts]


def write_procedural_library(
    out: str | os.PathLike[str],
    specs: Sequence[tuple[str, int]],
    *,
    mass: float = DEFAULT_MASS_KG,
    on_object: Callable[[str], None] | None = None,
) -> Path:
    """Build the procedural objects ``specs`` ((family, seed) pairs) into folder ``out``.

    Objects already listed as ok in the manifest with their files present are kept as they are
    (a rerun finishes an interrupted one). Returns the manifest path. The mass, every spec and an
    existing manifest are checked before anything is written.

    Raises:
        MeshError: a bad mass, or ``out`` holds a manifest of another kind.
        ProceduralError: an unknown family or a seed outside its split.
    """
    out = Path(out)
    mass = check_number("mass", mass, error=MeshError)
    for family, seed in specs:
        procedural.split_of(family, seed)  # ProceduralError before any folder is made
    manifest = _read_or_new_manifest(out, mass)
    (out / "meshes").mkdir(parents=True, exist_ok=True)
    (out / "parts").mkdir(parents=True, exist_ok=True)
    entries: dict[str, Any] = manifest["entries"]
    for family, seed in specs:
        oid = procedural.object_id(family, seed)
        if not _is_finished(out, entries.get(oid)):
            _write_object(out, manifest, family, seed, mass)
        if on_object:
            on_object(oid)
    return io.write_manifest(out, manifest)


def _is_finished(out: Path, entry: dict[str, Any] | None) -> bool:
    return bool(
        entry
        and entry.get("status") == "ok"
        and all((out / f).exists() for f in entry["files"].values())
    )


def _write_object(out: Path, manifest: dict[str, Any], family: str, seed: int, mass: float) -> None:
    """Build one object, write its mesh and parts, record it and rewrite the manifest."""
    oid = procedural.object_id(family, seed)
    obj = procedural.make_procedural_object(family, seed, mass=mass)
    mesh_file, parts_file = f"meshes/{oid}.obj", f"parts/{oid}.json"
    write_bytes_atomic(out / mesh_file, obj.mesh.export(file_type="obj").encode("utf-8"))
    write_parts(out / parts_file, oid, obj.parts or ())
    manifest["entries"][oid] = object_entry(obj, mesh_file, parts_file)
    io.write_manifest(out, manifest)


def _read_or_new_manifest(out: Path, mass: float) -> dict[str, Any]:
    if (out / io.MANIFEST_NAME).exists():
        manifest = io.read_manifest(out)
        if manifest["kind"] != "objects":
            raise MeshError(
                f"{out}: expected an objects folder, found a manifest of kind {manifest['kind']!r}"
            )
        found = manifest.get("parameters", {}).get("mass_kg")
        if found is not None and found != mass:
            raise MeshError(
                f"{out}: expected objects of {mass:g} kg to add to this folder, found a folder "
                f"made with {found:g} kg (use another --out)"
            )
        return manifest
    return io.new_manifest("objects", parameters={"mass_kg": mass, "source": "procedural"})


def load_library(folder: str | os.PathLike[str], limit: int | None = None) -> list[GraspObject]:
    """The ok objects of a library folder (the first ``limit`` of them), with their convex parts,
    in manifest order. The manifest is read once."""
    folder = Path(folder)
    manifest = io.read_manifest(folder)
    ids = _ok_ids(manifest)[:limit]
    return [_load_entry(folder, manifest, oid, mass=None) for oid in ids]


def library_ids(folder: str | os.PathLike[str]) -> list[str]:
    """Ids of the objects listed as ok in ``folder``'s manifest."""
    return _ok_ids(io.read_manifest(folder))


def _ok_ids(manifest: dict[str, Any]) -> list[str]:
    return [oid for oid, entry in manifest["entries"].items() if entry.get("status") == "ok"]


def load_library_object(
    folder: str | os.PathLike[str], object_id: str, mass: float | None = None
) -> GraspObject:
    """Load one object of a library folder (mesh + parts, already in the object frame)."""
    folder = Path(folder)
    return _load_entry(folder, io.read_manifest(folder), object_id, mass)


def _load_entry(
    folder: Path, manifest: dict[str, Any], object_id: str, mass: float | None
) -> GraspObject:
    entry = manifest["entries"].get(object_id)
    if entry is None:
        raise MeshError(f"{folder}: expected object {object_id!r} in the manifest, found no entry")
    files = entry["files"]
    parts_path = (
        io.manifest_entry_path(folder, manifest, object_id, "parts") if "parts" in files else None
    )
    obj = load_object(
        io.manifest_entry_path(folder, manifest, object_id, "mesh"),
        object_id=object_id,
        mass=mass if mass is not None else float(entry.get("mass_kg", DEFAULT_MASS_KG)),
        center=False,
        parts=None if parts_path is None else read_parts(parts_path),
    )
    obj.metadata.update({k: entry[k] for k in ("family", "seed", "split") if k in entry})
    return obj
