"""Writing submission files: :func:`write_submission` (atomic; the file it writes passes
:func:`~dg16m_env.subjects.submission_reader.validate_submission`) and
:func:`submission_from_dg16m` (a submission from a folder of DG16M files).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from dg16m_core.atomic import atomic_path
from dg16m_env.subjects.submission import (
    EMBEDDED,
    FORMAT,
    SCHEMA_VERSION,
    SubmissionError,
    _check_benchmark_name,
    _check_object_id,
    _show,
)

__all__ = [
    "PartialSubmissionWarning",
    "submission_from_dg16m",
    "write_submission",
]


def write_submission(
    path: str | os.PathLike[str],
    poses: Mapping[str, np.ndarray],
    *,
    scores: Mapping[str, np.ndarray] | None = None,
    benchmark: str = EMBEDDED,
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Write a submission file atomically (float64 poses and scores, uncompressed).

    The values are written as given (no finiteness or rigidity check): validate the result with
    :func:`~dg16m_env.subjects.submission_reader.validate_submission`. A file for the shipped
    benchmark (``"embedded"``) that holds only some of its objects is written with a
    :class:`PartialSubmissionWarning` saying how to score those objects on purpose
    (``dg16m evaluate --objects`` / ``--limit``: a partial run; a full evaluation refuses the
    file).

    Args:
        path: the file to write.
        poses: object id -> (K, 2, 4, 4) hand poses (m).
        scores: object id -> (K,) scores (optional, any subset of the objects).
        benchmark: sha256 of the benchmark file, or ``"embedded"``.
        metadata: JSON-ready facts to store.

    Returns:
        ``path``.

    Raises:
        SubmissionError: shapes that do not match, object ids that are not HDF5 names, a
            benchmark that is neither a sha256 nor ``"embedded"``, or metadata that is not JSON.
    """
    benchmark = _check_benchmark_name(benchmark)
    scores = dict(scores or {})
    unknown = sorted(set(scores) - set(poses))
    if unknown:
        raise SubmissionError(f"scores: expected ids among the poses' objects, found {unknown[:3]}")
    try:
        meta = json.dumps(dict(metadata or {}), sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise SubmissionError(f"metadata: expected a JSON object, found {exc}") from None
    arrays: dict[str, tuple[np.ndarray, np.ndarray | None]] = {}
    for object_id, value in poses.items():
        _check_object_id(object_id, "poses")
        p = np.asarray(value, dtype=np.float64)
        if p.ndim != 4 or p.shape[1:] != (2, 4, 4):
            raise SubmissionError(
                f"objects/{object_id}/poses: expected shape (K, 2, 4, 4), found {p.shape}"
            )
        s = None
        if object_id in scores:
            s = np.asarray(scores[object_id], dtype=np.float64)
            if s.shape != (len(p),):
                raise SubmissionError(
                    f"objects/{object_id}/scores: expected shape ({len(p)},), found {s.shape}"
                )
        arrays[object_id] = (p, s)
    path = Path(path)
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs["format"] = FORMAT
        f.attrs["schema_version"] = SCHEMA_VERSION
        f.attrs["benchmark"] = benchmark
        f.attrs["metadata"] = meta
        group = f.create_group("objects")
        for object_id in sorted(arrays):
            p, s = arrays[object_id]
            g = group.create_group(object_id)
            g.create_dataset("poses", data=p)
            if s is not None:
                g.create_dataset("scores", data=s)
    if benchmark == EMBEDDED:
        _warn_if_partial(path, set(arrays))
    return path


class PartialSubmissionWarning(UserWarning):
    """A submission written for the shipped benchmark that leaves some of its objects out."""


def _embedded_ids() -> frozenset[str]:
    from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK

    with h5py.File(EMBEDDED_BENCHMARK, "r") as f:
        return frozenset(s.decode() for s in f["objects/ids"][()])


def _warn_if_partial(path: Path, written: set[str]) -> None:
    """Say so when a shipped-benchmark submission holds only some of its objects (all of them
    the benchmark's): a full evaluation refuses it; ``dg16m evaluate --objects`` / ``--limit``
    scores it as a partial run."""
    import warnings

    expected = _embedded_ids()
    if not written or not written <= expected or written == expected:
        return
    warnings.warn(
        f"{path}: expected dual grasps for all {len(expected)} objects of the shipped benchmark, "
        f"found {len(written)}; a full evaluation refuses a submission that leaves objects out "
        "(each would count as a failure). To score only these objects on purpose, run "
        f"'dg16m evaluate {path} --objects IDS' (IDS: their ids, comma-separated or a file with "
        "one id a line; or '--limit N' when they are the benchmark's first N objects): the "
        "result is marked partial and a leaderboard never ranks it",
        PartialSubmissionWarning,
        stacklevel=3,
    )


# --------------------------------------------------------------------------------------------
# From DG16M release files
# --------------------------------------------------------------------------------------------


def _grasp_files(
    folder_or_files: str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | Mapping[str, Any],
) -> Callable[[str], Path]:
    """object id -> its DG16M file, from a folder, a list of ``<id>.h5`` files or a mapping."""
    if isinstance(folder_or_files, Mapping):
        by_id = {str(k): Path(v) for k, v in folder_or_files.items()}
    elif isinstance(folder_or_files, (str, os.PathLike)):
        folder = Path(folder_or_files)
        if not folder.is_dir():
            by_id = {folder.stem: folder}
        else:
            return lambda object_id: folder / f"{object_id}.h5"
    else:
        by_id = {}
        for item in folder_or_files:
            file = Path(item)
            if file.stem in by_id:
                raise SubmissionError(
                    f"folder_or_files: expected one file per object id, found {by_id[file.stem]} "
                    f"and {file} for {file.stem!r}"
                )
            by_id[file.stem] = file
    return lambda object_id: by_id.get(object_id, Path(f"<no file given for {object_id!r}>"))


def submission_from_dg16m(
    folder_or_files: str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | Mapping[str, Any],
    object_ids: Sequence[str],
    *,
    k: int = 10,
    seed: int = 0,
    gripper: str | None = None,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Submission poses and scores from DG16M release-schema files (one ``<object_id>.h5`` each).

    For each object, up to ``k`` of its force-closure passing pairs are drawn (seeded by ``seed``
    and the object id), topped up with failing pairs when fewer pass
    (:func:`dg16m_env.benchmark.arms.choose_file_pairs`); their poses are moved to the Panda frame
    (:func:`dg16m_env.benchmark.sources.file_poses`) and scored by ``-loss`` (higher = better).

    Args:
        folder_or_files: a folder of ``<object_id>.h5`` files, a list of such files (the id is
            the file name's stem), or a mapping object id -> file.
        object_ids: the objects to include, in order.
        k: dual grasps per object (at most).
        seed: global seed of the draws.
        gripper: the gripper whose frame the files' poses use (default: what each file
            records, else robotiq_2f85, the release's).

    Returns:
        ``(poses, scores)``: object id -> (K, 2, 4, 4) float64 Panda hand poses (m), and
        object id -> (K,) float64 scores, ready for :func:`write_submission`.

    Raises:
        SubmissionError: bad arguments, a missing file, or a file without pairs.
        GraspFileError: a file that is not a valid DG16M file.
    """
    from dataset_gen.io import read_dg16m
    from dataset_gen.sources.object_source import object_seed
    from dg16m_env.benchmark.arms import choose_file_pairs
    from dg16m_env.benchmark.sources import file_poses

    if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)) or k < 1:
        raise SubmissionError(f"k: expected a positive integer, found {k!r}")
    if isinstance(object_ids, (str, bytes)):
        raise SubmissionError(f"object_ids: expected a sequence of ids, found {_show(object_ids)}")
    ids = [_check_object_id(i, "object_ids") for i in object_ids]
    if len(set(ids)) != len(ids):
        repeated = sorted({i for i in ids if ids.count(i) > 1})
        raise SubmissionError(f"object_ids: expected distinct ids, found repeated {repeated[:3]}")
    file_of = _grasp_files(folder_or_files)
    poses: dict[str, np.ndarray] = {}
    scores: dict[str, np.ndarray] = {}
    for object_id in ids:
        path = file_of(object_id)
        if not path.is_file():
            raise SubmissionError(
                f"{object_id}: expected a DG16M grasp file at {path}, found nothing there"
            )
        data = read_dg16m(path)
        rng = np.random.default_rng(object_seed(seed, "submission:" + object_id))
        passing, failing = choose_file_pairs(data, int(k), 0, rng, fill=True)
        rows = np.concatenate([passing, failing]).astype(np.int64)
        if rows.size == 0:
            raise SubmissionError(f"{path}: expected at least one dual grasp, found none")
        poses[object_id] = file_poses(data, rows, gripper)
        scores[object_id] = -np.asarray(data.loss_values[rows], dtype=np.float64)
    return poses, scores
