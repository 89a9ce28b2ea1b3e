"""Dataset manifests (``manifest.json``): created, validated, read, updated and written atomically.

Manifest (``manifest.json``, one per dataset folder)
----------------------------------------------------
::

    {
      "format": "dg16m-manifest",
      "schema_version": 1,
      "kind": "objects" | "grasps" | "benchmark" | "dataset" | ...,  # MANIFEST_KINDS
      "created_by": "dg16m <version>",
      "parameters": {...},                       # any JSON object
      "entries": {
        "<object_id>": {
          "status": "ok" | "failed",
          "files": {"<role>": "<relative path>"},  # may be empty
          "error": "<message>",                    # required when failed, absent when ok
          ...                                      # free fields
        }
      }
    }

No other top-level keys are allowed. File paths are relative to the folder, use ``/`` separators
and may not be absolute or contain ``..`` (a manifest must not point outside its folder). Object
ids are non-empty and contain no ``/``, ``\\`` or NUL and are not ``.`` or ``..``. JSON with
duplicate keys or NaN/Infinity is rejected. The manifest is written as indented JSON with sorted
keys (stable bytes). One writer process owns a folder's manifest: :func:`update_manifest_entry`
reads, modifies and atomically rewrites it without locking.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from pathlib import Path, PurePosixPath
from typing import Any

from dg16m_core.atomic import write_json_atomic
from dg16m_core.errors import GraspFileError

from ._checks import PathLike, _ConstantError, _reject_constant
from .versions import MANIFEST_SCHEMA_VERSION, SUPPORTED_MANIFEST_VERSIONS, package_version

MANIFEST_NAME = "manifest.json"
"""File name of a dataset folder's manifest."""

MANIFEST_FORMAT = "dg16m-manifest"

MANIFEST_KINDS = (
    "objects",
    "grasps",
    "benchmark",
    "sweethome3d-import",
    "mesh-repair",
    "dataset",
    "pybullet-import",
)
MANIFEST_STATUSES = ("ok", "failed")
_MANIFEST_KEYS = ("format", "schema_version", "kind", "created_by", "parameters", "entries")
_WINDOWS_DRIVE = re.compile(r"^[A-Za-z]:")


def new_manifest(kind: str, parameters: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """An empty manifest of ``kind`` ("objects", "grasps" or "benchmark") made by this version."""
    manifest = {
        "format": MANIFEST_FORMAT,
        "schema_version": MANIFEST_SCHEMA_VERSION,
        "kind": kind,
        "created_by": f"dg16m {package_version()}",
        "parameters": dict(parameters or {}),
        "entries": {},
    }
    return validate_manifest(manifest)


class _DuplicateKeyError(ValueError):
    """A JSON object with a repeated key (raised from ``object_pairs_hook``)."""


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKeyError(f"expected unique keys, found {key!r} twice in one object")
        out[key] = value
    return out


def _check_relative_path(where: str, value: Any) -> str:
    """A manifest file path: relative, '/'-separated, no '..', inside the folder."""
    if not isinstance(value, str) or not value:
        raise GraspFileError(f"{where}: expected a non-empty relative path, found {value!r}")
    if "\x00" in value or "\\" in value:
        raise GraspFileError(
            f"{where}: expected a relative path with '/' separators, found {value!r}"
        )
    pure = PurePosixPath(value)
    if pure.is_absolute() or _WINDOWS_DRIVE.match(value):
        raise GraspFileError(
            f"{where}: expected a path relative to the manifest's folder, found absolute {value!r}"
        )
    if ".." in pure.parts:
        raise GraspFileError(
            f"{where}: expected a path inside the manifest's folder, found '..' in {value!r}"
        )
    return value


def _check_object_id(where: str, object_id: Any) -> str:
    if (
        not isinstance(object_id, str)
        or not object_id
        or object_id in (".", "..")
        or any(c in object_id for c in "/\\\x00")
    ):
        raise GraspFileError(
            f"{where}: expected an object id (non-empty, no '/', '\\' or NUL, not '.' or '..'), "
            f"found {object_id!r}"
        )
    return object_id


def _check_entry(where: str, entry: Any) -> None:
    if not isinstance(entry, dict):
        raise GraspFileError(f"{where}: expected an object, found {type(entry).__name__}")
    status = entry.get("status")
    if status not in MANIFEST_STATUSES:
        raise GraspFileError(
            f"{where}.status: expected one of {list(MANIFEST_STATUSES)}, found {status!r}"
        )
    files = entry.get("files")
    if not isinstance(files, dict):
        raise GraspFileError(
            f"{where}.files: expected an object of role -> relative path, "
            f"found {type(files).__name__ if 'files' in entry else 'nothing'}"
        )
    for role, rel in files.items():
        _check_relative_path(f"{where}.files.{role}", rel)
    if status == "failed":
        if not isinstance(entry.get("error"), str):
            raise GraspFileError(
                f"{where}.error: expected an error message (string) for a failed entry, "
                f"found {entry.get('error')!r}"
            )
    elif "error" in entry:
        raise GraspFileError(f"{where}.error: expected no error for status 'ok', found one")


def validate_manifest(manifest: Any, source: str = "manifest") -> dict[str, Any]:
    """Check ``manifest`` against the schema in the module docstring; return it unchanged.

    Args:
        manifest: the parsed manifest.
        source: prefix of error messages (the file path when read from disk).

    Raises:
        GraspFileError: wrong format marker, unsupported version, unknown kind, unexpected or
            missing keys, bad entries (status, files, error), unsafe paths, non-JSON values.
    """
    if not isinstance(manifest, dict):
        raise GraspFileError(
            f"{source}: expected a JSON object at top level, found {type(manifest).__name__}"
        )
    if manifest.get("format") != MANIFEST_FORMAT:
        raise GraspFileError(
            f"{source}: format: expected {MANIFEST_FORMAT!r}, found {manifest.get('format')!r}"
        )
    version = manifest.get("schema_version")
    if (
        isinstance(version, bool)
        or not isinstance(version, int)
        or version not in SUPPORTED_MANIFEST_VERSIONS
    ):
        raise GraspFileError(
            f"{source}: schema_version: expected one of {list(SUPPORTED_MANIFEST_VERSIONS)} "
            f"(supported by dg16m {package_version()}), found {version!r}"
        )
    missing = [key for key in _MANIFEST_KEYS if key not in manifest]
    if missing:
        raise GraspFileError(f"{source}: expected keys {list(_MANIFEST_KEYS)}, missing {missing}")
    unexpected = sorted(set(manifest) - set(_MANIFEST_KEYS))
    if unexpected:
        raise GraspFileError(
            f"{source}: expected only keys {list(_MANIFEST_KEYS)}, found also {unexpected}"
        )
    if manifest["kind"] not in MANIFEST_KINDS:
        raise GraspFileError(
            f"{source}: kind: expected one of {list(MANIFEST_KINDS)}, found {manifest['kind']!r}"
        )
    if not isinstance(manifest["created_by"], str):
        raise GraspFileError(
            f"{source}: created_by: expected a string, found {manifest['created_by']!r}"
        )
    for key in ("parameters", "entries"):
        if not isinstance(manifest[key], dict):
            raise GraspFileError(
                f"{source}: {key}: expected an object, found {type(manifest[key]).__name__}"
            )
    for object_id, entry in manifest["entries"].items():
        _check_object_id(f"{source}: entries", object_id)
        _check_entry(f"{source}: entries.{object_id}", entry)
    try:
        json.dumps(manifest, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise GraspFileError(
            f"{source}: expected JSON values only (finite numbers, string keys), found {exc}"
        ) from exc
    return manifest


def write_manifest(folder: PathLike, manifest: Mapping[str, Any]) -> Path:
    """Validate and atomically write ``folder/manifest.json`` (sorted keys, stable bytes).

    Returns the manifest's path. Raises :class:`GraspFileError` when ``manifest`` is invalid
    (nothing is written then).
    """
    path = Path(folder) / MANIFEST_NAME
    payload = validate_manifest(dict(manifest), source=str(path))
    write_json_atomic(path, payload)
    return path


def read_manifest(folder: PathLike) -> dict[str, Any]:
    """Read and validate ``folder/manifest.json``.

    Raises:
        GraspFileError: no manifest, not UTF-8, malformed JSON (with line and column), duplicate
            keys, NaN/Infinity, or any schema violation (see :func:`validate_manifest`).
    """
    path = Path(folder) / MANIFEST_NAME
    if not path.is_file():
        raise GraspFileError(f"{path}: expected a dg16m manifest, found no such file")
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise GraspFileError(f"{path}: expected UTF-8 JSON, found {exc}") from exc
    try:
        manifest = json.loads(
            text, object_pairs_hook=_no_duplicates, parse_constant=_reject_constant
        )
    except json.JSONDecodeError as exc:
        raise GraspFileError(
            f"{path}: expected JSON, found malformed JSON at line {exc.lineno}, column "
            f"{exc.colno}: {exc.msg}"
        ) from exc
    except (_DuplicateKeyError, _ConstantError) as exc:
        raise GraspFileError(f"{path}: {exc}") from exc
    return validate_manifest(manifest, source=str(path))


def update_manifest_entry(
    folder: PathLike,
    object_id: str,
    entry: Mapping[str, Any],
    *,
    kind: str | None = None,
    parameters: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Set ``entries[object_id] = entry`` in ``folder/manifest.json`` and rewrite it atomically.

    Creates the manifest (``kind`` and ``parameters`` required then) when the folder has none.
    With an existing manifest, ``parameters`` is ignored and ``kind``, when given, must match.
    The entry replaces any previous one for ``object_id`` (no merge). No locking: one writer
    process owns a folder's manifest. Returns the manifest as written.

    Raises:
        GraspFileError: the existing manifest is invalid or of another kind, or the entry is
            invalid (bad status, unsafe path, ...).
        ValueError: no manifest exists and ``kind`` is None.
    """
    path = Path(folder) / MANIFEST_NAME
    if path.exists():
        manifest = read_manifest(folder)
        if kind is not None and manifest["kind"] != kind:
            raise GraspFileError(f"{path}: kind: expected {kind!r}, found {manifest['kind']!r}")
    else:
        if kind is None:
            raise ValueError(f"{path} does not exist: pass kind= to create it")
        manifest = new_manifest(kind, parameters)
    _check_object_id(f"{path}: entries", object_id)
    manifest["entries"][object_id] = dict(entry)
    write_manifest(folder, manifest)
    return manifest


def manifest_entry_path(
    folder: PathLike, manifest: Mapping[str, Any], object_id: str, role: str
) -> Path:
    """``folder`` joined with the stored path ``entries[object_id].files[role]``.

    The stored path is re-checked (relative, no ``..``) before it is joined to ``folder``.

    Raises:
        GraspFileError: no such entry or role, or an unsafe path.
    """
    entries = manifest.get("entries", {})
    if object_id not in entries:
        raise GraspFileError(f"{folder}: entries: expected {object_id!r}, found no such entry")
    files = entries[object_id].get("files", {})
    if role not in files:
        raise GraspFileError(
            f"{folder}: entries.{object_id}.files: expected role {role!r}, found {sorted(files)}"
        )
    rel = _check_relative_path(f"{folder}: entries.{object_id}.files.{role}", files[role])
    return Path(folder) / PurePosixPath(rel)


def failed_entries(manifest: Mapping[str, Any], ids: Sequence[str] | None = None) -> dict[str, str]:
    """The objects of ``manifest`` (of ``ids``, default all) whose entry is ``failed``, each with
    its reason; the lines ``  failed <id>: <reason>`` that ``dg16m generate`` and ``dg16m
    benchmark build`` print come from :func:`failure_lines`."""
    entries = manifest["entries"]
    wanted = list(entries) if ids is None else [i for i in ids if i in entries]
    return {i: _reason(entries[i]) for i in wanted if entries[i]["status"] == "failed"}


def _reason(entry: Mapping[str, Any]) -> str:
    """A failed entry's reason: its ``verdict`` in words and stage where it has them (a
    rejected benchmark object), then the error itself."""
    error = str(entry.get("error", "?"))
    if not entry.get("verdict"):
        return error
    return f"rejected at stage {entry.get('stage', '?')}: {entry['verdict']} ({error})"


def failure_lines(failed: Mapping[str, str]) -> list[str]:
    """One line per failed object: ``  failed <id>: <reason>``."""
    return [f"  failed {object_id}: {reason}" for object_id, reason in failed.items()]
