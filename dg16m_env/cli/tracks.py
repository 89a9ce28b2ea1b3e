"""The tracks of ``dg16m evaluate --predictor`` and ``dg16m submission make --predictor`` on the
command line: ``--track mesh|cloud`` and the cloud track's cameras and noise
(:mod:`dg16m_env.subjects.track`, :mod:`dg16m_env.subjects.cloud_observation`); heavy imports
happen inside the functions."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from dg16m_core.errors import Dg16mError


class TrackArgumentError(Dg16mError, ValueError):
    """A submission whose ``metadata["track"]`` names no track."""


def add_track_arguments(parser: argparse.ArgumentParser) -> None:
    """``--track``, ``--noise``, ``--cameras``, ``--camera-seed``, ``--noise-seed`` and
    ``--camera-resolution``."""
    cloud = parser.add_argument_group(
        "tracks (what the predictor sees; dg16m_env.subjects.cloud_observation)"
    )
    cloud.add_argument(
        "--track",
        choices=("mesh", "cloud"),
        default="mesh",
        help="mesh (default): the observation holds the object's mesh; cloud: only what the "
        "benchmark's depth cameras see (no mesh, no object id), and the predictor's process "
        "cannot read the benchmark (Linux Landlock)",
    )
    cloud.add_argument(
        "--noise",
        choices=("kinect", "none"),
        default="kinect",
        help="cloud track: the depth sensor's noise (default kinect: depth noise growing with "
        "distance, missing pixels at grazing angles and edges; none: ideal depth)",
    )
    cloud.add_argument(
        "--cameras", type=int, default=2, help="cloud track: depth cameras per object (default 2)"
    )
    cloud.add_argument(
        "--camera-seed",
        type=int,
        default=0,
        help="cloud track: seed of the camera placement (default 0, the benchmark's)",
    )
    cloud.add_argument(
        "--noise-seed",
        type=int,
        default=0,
        help="cloud track: seed of the sensor noise (default 0)",
    )
    cloud.add_argument(
        "--camera-resolution",
        type=int,
        default=128,
        metavar="PIXELS",
        help="cloud track: side of each square depth image (default 128)",
    )


def cloud_track(args: argparse.Namespace) -> Any:
    """The :class:`~dg16m_env.subjects.cloud_observation.CloudTrack` of ``--track cloud`` (None
    for the mesh track).

    Raises:
        ObservationError: a bad ``--cameras``, seed or resolution.
    """
    if args.track != "cloud":
        return None
    from dg16m_env.subjects.cloud_observation import CloudTrack

    return CloudTrack(
        n_cameras=args.cameras,
        resolution=args.camera_resolution,
        camera_seed=args.camera_seed,
        noise=args.noise,
        noise_seed=args.noise_seed,
    )


def file_metadata(path: Path) -> dict[str, Any]:
    """A submission file's root ``metadata`` (empty when it has none or it is not JSON)."""
    import json

    from dataset_gen.io import open_hdf5

    with open_hdf5(path, "HDF5 submission file") as f:
        raw = f.attrs.get("metadata")
    try:
        value = json.loads(raw.decode() if isinstance(raw, bytes) else str(raw))
    except (TypeError, ValueError):
        return {}
    return value if isinstance(value, dict) else {}


def file_track(path: Path) -> str:
    """The track a submission file declares (``"mesh"`` without one;
    :func:`dg16m_env.subjects.track.track_name`).

    Raises:
        TrackArgumentError: a ``"track"`` entry that names no track.
    """
    from dg16m_env.subjects.track import track_name

    try:
        return track_name(file_metadata(path))
    except ValueError as exc:
        raise TrackArgumentError(f"{path}: {exc}") from None


def same_track(args: argparse.Namespace, path: Path) -> bool:
    """Whether the submission at ``path`` was made on the track (and for the cloud track, the
    cameras and noise) that ``args`` asks for."""
    track = file_metadata(path).get("track")
    if not isinstance(track, dict):
        return args.track == "mesh"
    if track.get("name") != args.track:
        return False
    cloud = cloud_track(args)
    return cloud is None or all(track.get(k) == v for k, v in cloud.record().items())


def print_sandbox(run: Any, cloud: Any) -> None:
    """Say how a cloud-track run kept its predictor from the benchmark."""
    if cloud is None:
        return
    if (run.sandbox or "").startswith("landlock-"):  # else the run warned already
        print(f"cloud track: the predictor could not read the benchmark ({run.sandbox})")
