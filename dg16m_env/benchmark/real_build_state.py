"""A real-benchmark build carried between machines: its import and its finished objects.

``dg16m benchmark build-real`` resumes from its folder, but the whole build is about 14
core-hours and the import under an hour: on machines that do not keep their disks between
sessions (a CI runner, a rented box) a folder is lost long before the build is done. This module
packs what a build cannot cheaply make again into a folder that can be committed or copied, and
unpacks it on the next machine, so the build goes on where it stopped.

State folder layout (written by :func:`save_build_state`)::

    <state>/STATE.json              format "dg16m-real-build-state", schema_version 1, counts
    <state>/meshes/manifest.json    the import's manifest (sources, licences, sha256 per OBJ)
    <state>/meshes/ATTRIBUTION.md   the import's attribution
    <state>/meshes/<id>.obj.xz      each imported OBJ file, xz-compressed (its bytes exactly)
    <state>/build/manifest.json     the build's manifest (finished, rejected and failed objects)
    <state>/build/sources.json      the mesh sha256 each object was built from
    <state>/build/objects/<id>.h5.xz  each finished object's benchmark file, xz-compressed

Saving is incremental (a file whose bytes are already there is not rewritten, so a state kept
in git grows by the new objects only; xz takes an object file from about 190 KB to 100 KB, half
of an HDF5 file of one object being its headers) and removes object files the build no longer lists.
Restoring checks every OBJ against the sha256 its import manifest records and every listed
object file against its presence, and refuses to overwrite a folder that differs.
"""

from __future__ import annotations

import hashlib
import json
import lzma
import os
from pathlib import Path
from typing import Any

from dataset_gen.io.manifest import MANIFEST_NAME, read_manifest
from dg16m_core.atomic import write_bytes_atomic, write_json_atomic
from dg16m_env.benchmark.model import BenchmarkError
from dg16m_env.benchmark.real import import_entries

STATE_FORMAT = "dg16m-real-build-state"
STATE_SCHEMA_VERSION = 1
STATE_FILE = "STATE.json"
MESHES = "meshes"
BUILD = "build"
BUILD_FILES = (MANIFEST_NAME, "sources.json")
"""Files of a build folder carried besides its object files."""

_XZ_PRESET = 9 | lzma.PRESET_EXTREME


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _write_if_changed(path: Path, data: bytes) -> bool:
    """Write ``data`` atomically unless ``path`` already holds it; True when written."""
    if path.is_file() and path.read_bytes() == data:
        return False
    write_bytes_atomic(path, data)
    return True


def _pack(path: Path, data: bytes) -> bool:
    """Write ``data`` xz-compressed at ``path`` unless it already holds them; True when written."""
    if path.is_file() and _unpack(path) == data:
        return False
    write_bytes_atomic(path, lzma.compress(data, preset=_XZ_PRESET))
    return True


def _unpack(path: Path) -> bytes:
    try:
        return lzma.decompress(path.read_bytes())
    except lzma.LZMAError as exc:
        raise BenchmarkError(f"{path}: expected xz data, found {exc}") from None


def save_build_state(
    meshes: str | os.PathLike[str],
    build: str | os.PathLike[str] | None,
    to: str | os.PathLike[str],
) -> dict[str, int]:
    """Pack an import folder and (optionally) a build folder into the state folder ``to``.

    Every OBJ the import lists as ``ok`` is checked against its recorded sha256 before it is
    packed; the build's object files are those its manifest lists as ``ok``.

    Returns:
        Counts: ``meshes`` and ``objects`` carried, ``written`` files written this time,
        ``removed`` object files dropped because the build no longer lists them.

    Raises:
        BenchmarkError: not an import folder, an OBJ missing or differing from its hash, a
            build without its manifest or with a listed object file missing.
    """
    source, state = Path(meshes), Path(to)
    entries = import_entries(source)
    written = 0
    carried = 0
    for object_id, entry in sorted(entries.items()):
        if entry.get("status") != "ok":
            continue
        path = source / entry["files"]["mesh"]
        if not path.is_file():
            raise BenchmarkError(f"{object_id}: expected its mesh {path}, found none")
        data = path.read_bytes()
        if _sha256(data) != entry["sha256"]:
            raise BenchmarkError(
                f"{path}: expected sha256 {entry['sha256']} (the import manifest), found "
                f"{_sha256(data)}"
            )
        written += _pack(state / MESHES / f"{path.name}.xz", data)
        carried += 1
    for name in (MANIFEST_NAME, "ATTRIBUTION.md"):
        if (source / name).is_file():
            written += _write_if_changed(state / MESHES / name, (source / name).read_bytes())
    objects = removed = 0
    if build is not None:
        folder = Path(build)
        if not (folder / MANIFEST_NAME).is_file():
            raise BenchmarkError(
                f"{folder}: expected a build folder with {MANIFEST_NAME}, found none"
            )
        manifest = read_manifest(folder)
        listed = set()
        for object_id, entry in sorted(manifest["entries"].items()):
            if entry.get("status") != "ok":
                continue
            relative = entry["files"]["benchmark"]
            if not (folder / relative).is_file():
                raise BenchmarkError(
                    f"{folder}: expected {relative} for finished object {object_id}, found none"
                )
            written += _pack(state / BUILD / f"{relative}.xz", (folder / relative).read_bytes())
            listed.add(f"{relative}.xz")
            objects += 1
        for path in sorted((state / BUILD / "objects").glob("*.xz")):
            if f"objects/{path.name}" not in listed:
                path.unlink()
                removed += 1
        for name in BUILD_FILES:
            if (folder / name).is_file():
                written += _write_if_changed(state / BUILD / name, (folder / name).read_bytes())
    counts = {"meshes": carried, "objects": objects, "written": written, "removed": removed}
    write_json_atomic(
        state / STATE_FILE,
        {
            "format": STATE_FORMAT,
            "schema_version": STATE_SCHEMA_VERSION,
            "meshes": carried,
            "objects": objects,
        },
    )
    return counts


def _check_state(state: Path) -> dict[str, Any]:
    try:
        header = json.loads((state / STATE_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise BenchmarkError(
            f"{state}: expected a build state folder with {STATE_FILE}, found "
            f"{type(exc).__name__}: {exc}"
        ) from None
    if header.get("format") != STATE_FORMAT or header.get("schema_version") != STATE_SCHEMA_VERSION:
        raise BenchmarkError(
            f"{state / STATE_FILE}: expected format {STATE_FORMAT!r} schema_version "
            f"{STATE_SCHEMA_VERSION}, found {header.get('format')!r} "
            f"{header.get('schema_version')!r}"
        )
    return header


def _restore_file(path: Path, data: bytes) -> bool:
    """Write ``data`` at ``path`` if absent; True when written. A different file is refused."""
    if path.is_file():
        if path.read_bytes() != data:
            raise BenchmarkError(
                f"{path}: expected it absent or equal to the state's copy, found different bytes "
                "(restore into an empty folder, or remove it first)"
            )
        return False
    write_bytes_atomic(path, data)
    return True


def restore_build_state(
    state: str | os.PathLike[str],
    meshes: str | os.PathLike[str],
    build: str | os.PathLike[str] | None = None,
) -> dict[str, int]:
    """Unpack a state folder: the import into ``meshes`` and (when given) the build into
    ``build``. Files already there with the same bytes are kept; different ones are refused.

    Returns:
        Counts: ``meshes`` and ``objects`` restored (written or already there), ``written``.

    Raises:
        BenchmarkError: not a state folder, a packed OBJ whose bytes differ from the import
            manifest's sha256, a listed object file missing, or a target file that differs.
    """
    root = Path(state)
    _check_state(root)
    entries = import_entries(root / MESHES)
    target = Path(meshes)
    written = restored = 0
    for object_id, entry in sorted(entries.items()):
        if entry.get("status") != "ok":
            continue
        name = entry["files"]["mesh"]
        packed = root / MESHES / f"{name}.xz"
        if not packed.is_file():
            raise BenchmarkError(f"{root}: expected {MESHES}/{name}.xz for {object_id}, found none")
        data = _unpack(packed)
        if _sha256(data) != entry["sha256"]:
            raise BenchmarkError(
                f"{packed}: expected an OBJ with sha256 {entry['sha256']}, found {_sha256(data)}"
            )
        written += _restore_file(target / name, data)
        restored += 1
    for name in ("ATTRIBUTION.md", MANIFEST_NAME):  # the manifest last: it marks the import done
        if (root / MESHES / name).is_file():
            written += _restore_file(target / name, (root / MESHES / name).read_bytes())
    objects = 0
    if build is not None and (root / BUILD / MANIFEST_NAME).is_file():
        folder = Path(build)
        manifest = read_manifest(root / BUILD)
        for object_id, entry in sorted(manifest["entries"].items()):
            if entry.get("status") != "ok":
                continue
            relative = entry["files"]["benchmark"]
            packed = root / BUILD / f"{relative}.xz"
            if not packed.is_file():
                raise BenchmarkError(
                    f"{root / BUILD}: expected {relative}.xz for finished object {object_id}, "
                    "found none"
                )
            written += _restore_file(folder / relative, _unpack(packed))
            objects += 1
        for name in BUILD_FILES[::-1]:  # the manifest last
            if (root / BUILD / name).is_file():
                written += _restore_file(folder / name, (root / BUILD / name).read_bytes())
    return {"meshes": restored, "objects": objects, "written": written}
