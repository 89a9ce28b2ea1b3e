"""The board's tracks: what a predictor saw, read from its submission file, never ranked together.

* ``mesh``: the predictor was handed the object's mesh (every h5 submission without a track,
  and every board row from before tracks existed);
* ``cloud``: the predictor saw only the benchmark's depth cameras (``dg16m evaluate --predictor
  X --track cloud``). Self-declared, as the tracks of GraspNet-1Billion are: the file carries the
  harness's provenance (its metadata ``track`` object: harness version, noise model and seed,
  cameras, sandbox, the predictor's code hash); the server records and shows it, it does not
  rerun the predictor.

A submission's track comes from its root attribute ``metadata`` (a JSON object), key ``track``:
``{"name": "cloud", "harness_version": ..., "noise": ..., ...}``. No metadata, or no ``track``
key: mesh. A ``track`` that is not an object naming a known track, or whose JSON is over
:data:`MAX_PROVENANCE_BYTES`, is refused (:func:`track_of`). The whole object is kept as the
submission's provenance.

Standings are computed within one track only (:mod:`leaderboard.results` ranks per track and
evaluator); every view, page and command shows one table per track per evaluator.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from dg16m_env.subjects.track import TRACKS

from .query_checks import InvalidParameterError

DEFAULT_TRACK = "mesh"
"""The track of a submission that names none."""
MAX_PROVENANCE_BYTES = 4096
"""Largest ``track`` object kept (bytes of its compact, key-sorted JSON)."""


@dataclass(frozen=True)
class TrackInfo:
    """How the board presents one track.

    Attributes:
        name: ``"mesh"`` or ``"cloud"``.
        title: the heading of its tables.
        self_declared: whether its entries' conditions are declared by the submitter (their
            provenance), not enforced by the server.
    """

    name: str
    title: str
    self_declared: bool


TRACK_INFO: dict[str, TrackInfo] = {
    "mesh": TrackInfo("mesh", "Mesh track: predictors see the object's mesh", False),
    "cloud": TrackInfo(
        "cloud",
        "Cloud track: predictors see only the benchmark's depth cameras (self-declared: the "
        "submission carries the harness's provenance; the server does not rerun it)",
        True,
    ),
}
"""Each track's heading (see :class:`TrackInfo`)."""

PROVENANCE_FIELDS = (
    ("harness_version", "Harness version"),
    ("noise", "Noise"),
    ("noise_seed", "Noise seed"),
    ("cameras", "Cameras"),
    ("camera_seed", "Camera seed"),
    ("sandbox", "Sandbox"),
    ("predictor_sha256", "Predictor sha256"),
)
"""The provenance keys the board shows for a cloud entry, with their labels, in this order."""


class TrackError(ValueError):
    """A submission's ``track`` the board refuses; :attr:`message` says what was expected."""

    def __init__(self, message: str):
        super().__init__(message)
        self.message = message


def _found(value: Any) -> str:
    """A short description of a found value for an error message."""
    text = json.dumps(value, sort_keys=True, default=str)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{type(value).__name__} {text}"


def track_of(metadata: Any) -> tuple[str, str | None]:
    """A submission's track and provenance from its metadata.

    Args:
        metadata: the file's ``metadata`` (a JSON object as a dict; anything else, or no
            ``track`` key: mesh track).

    Returns:
        The track name and the ``track`` object as compact key-sorted JSON (None when the
        metadata names no track).

    Raises:
        TrackError: a ``track`` that is not an object whose ``name`` is a known track, or
            whose JSON is over :data:`MAX_PROVENANCE_BYTES` bytes.
    """
    if not isinstance(metadata, Mapping) or "track" not in metadata:
        return DEFAULT_TRACK, None
    track = metadata["track"]
    names = " or ".join(repr(t) for t in TRACKS)
    if not isinstance(track, Mapping):
        raise TrackError(
            f"track: expected track name {names} in an object "
            f'({{"name": "cloud", ...}}), found {_found(track)}'
        )
    name = track.get("name")
    if not isinstance(name, str) or name not in TRACKS:
        raise TrackError(f"track: expected track name {names}, found {_found(name)}")
    try:
        provenance = json.dumps(dict(track), sort_keys=True, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise TrackError(f"track: expected a JSON object, found {exc}") from None
    size = len(provenance.encode("utf-8"))
    if size > MAX_PROVENANCE_BYTES:
        raise TrackError(
            f"track: expected at most {MAX_PROVENANCE_BYTES} bytes of provenance JSON, found {size}"
        )
    return name, provenance


def check_track(value: Any) -> str:
    """A track name from a query or a command line.

    Raises:
        InvalidParameterError: (422) anything but a known track name.
    """
    if not isinstance(value, str) or value not in TRACKS:
        names = " or ".join(repr(t) for t in TRACKS)
        raise InvalidParameterError(f"track: expected track name {names}, found {value!r}")
    return value


def provenance_rows(provenance: Any) -> list[tuple[str, str]]:
    """A cloud entry's provenance as (label, text) rows for a page or a terminal: the keys of
    :data:`PROVENANCE_FIELDS` (missing ones as ``"not declared"``; the predictor's sha256
    shortened to 12 hex digits), then any other key of the object except ``name``."""
    if not isinstance(provenance, Mapping):
        return []
    rows = []
    for key, label in PROVENANCE_FIELDS:
        value = provenance.get(key)
        if value is None:
            text = "not declared"
        elif key == "predictor_sha256" and isinstance(value, str):
            text = value[:12]
        else:
            text = value if isinstance(value, str) else json.dumps(value, sort_keys=True)
        rows.append((label, text))
    known = {key for key, _ in PROVENANCE_FIELDS} | {"name"}
    for key in sorted(str(k) for k in provenance if k not in known):
        value = provenance[key]
        rows.append((key, value if isinstance(value, str) else json.dumps(value, sort_keys=True)))
    return rows


def provenance_summary(provenance: Any) -> str:
    """One line of a cloud entry's provenance (noise, cameras, sandbox, predictor sha256
    short), e.g. ``"noise default (seed 0) · cameras 2 · sandbox process · predictor
    0123456789ab"``; empty for none."""
    if not isinstance(provenance, Mapping):
        return ""
    rows = dict(provenance_rows(provenance))
    noise = rows["Noise"]
    if provenance.get("noise_seed") is not None:
        noise += f" (seed {rows['Noise seed']})"
    return (
        f"noise {noise} · cameras {rows['Cameras']} · sandbox {rows['Sandbox']} · "
        f"predictor {rows['Predictor sha256']}"
    )
