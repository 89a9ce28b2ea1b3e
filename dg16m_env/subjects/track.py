"""Benchmark tracks: what a predictor saw, as its submission records it.

Two tracks: ``"mesh"`` (the predictor's observation holds the object's mesh,
:func:`dg16m_env.subjects.observation.object_observation`) and ``"cloud"`` (only what the
benchmark's depth cameras see, :mod:`dg16m_env.subjects.cloud_observation`). A submission written
by ``dg16m evaluate --predictor`` / ``dg16m submission make --predictor`` records its track in the
root ``metadata`` JSON under ``"track"``::

    {"name": "cloud", "harness_version": 1, "package_version": "...", "noise": "kinect",
     "noise_seed": 0, "cameras": 2, "camera_seed": 0, "resolution": 128, "fovy_deg": 45.0,
     "predictor_sha256": "...", "sandbox": "landlock-abi-7"}

(a mesh-track run: ``{"name": "mesh", "harness_version", "package_version",
"predictor_sha256"}``). The record is self-declared: a file can say anything, as the tracks of
GraspNet-1Billion do. A submission without the key is mesh-track by construction
(:func:`track_name`).
"""

from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import os
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

TRACKS = ("mesh", "cloud")
"""The track names; the first is the default."""

HARNESS_VERSION = 1
"""Version of what the harness hands a predictor (the observations, the cloud track's cameras
and noise model, the sandbox); bumped when any of them changes."""

DATA_FOLDER = Path(__file__).resolve().parents[1] / "data"
"""The package's data folder (the shipped benchmarks)."""


def track_name(metadata: Mapping[str, Any] | None) -> str:
    """The track a submission's ``metadata`` declares: ``metadata["track"]["name"]`` when it is
    one of :data:`TRACKS`, ``"mesh"`` when there is no ``"track"`` key.

    Raises:
        ValueError: a ``"track"`` that is not an object with a known ``"name"``.
    """
    if not metadata or "track" not in metadata:
        return TRACKS[0]
    track = metadata["track"]
    name = track.get("name") if isinstance(track, Mapping) else None
    if name not in TRACKS:
        raise ValueError(
            f"metadata track: expected an object with 'name' one of {TRACKS}, found {track!r}"
        )
    return str(name)


def _source_file(target: str, path: Sequence[str]) -> Path | None:
    """The source file of a ``module:attr`` or ``file.py:attr`` target, found without importing
    it (None when not found)."""
    module, _, _ = target.rpartition(":")
    if module.endswith(".py"):
        file = Path(module).resolve()
        return file if file.is_file() else None
    search: list[str] | None = [*path, *sys.path]
    spec = None
    for depth, part in enumerate(module.split(".")):
        spec = importlib.machinery.PathFinder.find_spec(part, search)
        if spec is None and depth == 0:
            # a top-level package another finder knows (an editable install): asking for a
            # top-level name imports nothing
            spec = importlib.util.find_spec(part)
        if spec is None:
            return None
        search = list(spec.submodule_search_locations or [])
    origin = getattr(spec, "origin", None)
    return Path(origin) if origin and os.path.isfile(origin) else None


def predictor_sha256(target: str, path: Sequence[str] = ()) -> str:
    """The sha256 (hex) of the source file of a predictor's target (``"unknown"`` when it cannot
    be found without importing the target). Other modules it imports and files it reads are not
    hashed."""
    file = _source_file(target, path)
    if file is None:
        return "unknown"
    return hashlib.sha256(file.read_bytes()).hexdigest()


def forbidden_paths(
    benchmark: str | os.PathLike[str], mesh_root: str | os.PathLike[str] | None
) -> list[Path]:
    """What a cloud-track predictor's process must not read: the benchmark file, its mesh folder
    (if any) and the package's data folder (:data:`DATA_FOLDER`)."""
    out = [Path(benchmark), DATA_FOLDER]
    if mesh_root is not None:
        out.append(Path(mesh_root))
    return out


def track_record(
    name: str,
    target: str,
    *,
    path: Iterable[str] = (),
    cloud: Mapping[str, Any] | None = None,
    sandbox: str | None = None,
) -> dict[str, Any]:
    """The ``"track"`` entry of a predictor's submission metadata (module docstring).

    Args:
        name: a name of :data:`TRACKS`.
        target: the predictor's target (its source file is hashed).
        path: folders searched first for the target's module.
        cloud: the cloud track's parameters
            (:meth:`dg16m_env.subjects.cloud_observation.CloudTrack.record`).
        sandbox: what the predictor's processes reported (cloud track).
    """
    from dg16m_core.distribution import package_version

    if name not in TRACKS:
        raise ValueError(f"track: expected one of {TRACKS}, found {name!r}")
    record: dict[str, Any] = {
        "name": name,
        "harness_version": HARNESS_VERSION,
        "package_version": package_version(),
    }
    if name == "cloud":
        record.update(dict(cloud or {}))
        record["sandbox"] = sandbox or "none"
    record["predictor_sha256"] = predictor_sha256(target, tuple(path))
    return record


__all__ = [
    "DATA_FOLDER",
    "HARNESS_VERSION",
    "TRACKS",
    "forbidden_paths",
    "predictor_sha256",
    "track_name",
    "track_record",
]
