"""Reading a submission file, only after it is validated in full (:func:`validate_submission`,
:func:`read_submission`; the schema is in :mod:`dg16m_env.subjects.submission`).

Validation (:func:`validate_submission`)
----------------------------------------
Every problem is reported, each with its place (``"file"``, ``"/"``, ``"attrs/benchmark"``,
``"objects/<id>/poses[3, 1]"``, ...), in this order, each stage reading nothing the previous
stage has not vetted:

1. the path: it exists, is a regular file, is at most :attr:`SubmissionLimits.max_file_bytes`
   (``os.stat``, before the file is opened) and is an HDF5 file HDF5 can open;
2. the root attributes (dtype and shape of each is checked before its value is read);
3. the tree, walked one level at a time without dereferencing a link: each member's link type
   is read first (soft and external links are reported, never followed), and groups outside
   the schema are reported, never entered (so hard-link cycles are harmless);
4. each dataset's header: dtype, shape, storage (external, virtual, filters, chunk size) and its
   declared uncompressed size, per dataset and summed over the file;
5. only then the values of the datasets that passed: finite, rigid, translations within
   :data:`~dg16m_env.subjects.submission.MAX_TRANSLATION` m.

Stages 1 and 5 are here, stages 2 to 4 in :mod:`dg16m_env.subjects.submission_structure`.

A hard link that gives one dataset or group two names (``objects/b`` = ``objects/a``) is allowed:
it is an ordinary HDF5 name, the data is read (and counted against the size limits) once per
name, and the file means exactly what two copies would.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Sequence
from pathlib import Path

import h5py
import numpy as np

from dataset_gen.io import hdf5_content_problem
from dg16m_core.hashing import file_sha256
from dg16m_env.subjects.submission import (
    _HEX64,
    Problem,
    Submission,
    SubmissionError,
    SubmissionInvalid,
    SubmissionLimits,
    _check_object_id,
    _indices,
    _show,
    hand_pose_faults,
)
from dg16m_env.subjects.submission_structure import (
    Contents,
    ProblemLog,
    ReadableDataset,
    RootAttributes,
    TreeWalk,
)

__all__ = [
    "read_submission",
    "validate_submission",
]


class _Validator:
    """One validation of one file: collects every problem and, when there are none, the values.

    Stage 1 (the path) is here; the root attributes, the tree and the datasets' headers are
    checked by :mod:`dg16m_env.subjects.submission_structure`, then :meth:`values` reads the
    datasets that passed."""

    def __init__(
        self,
        object_ids: Sequence[str] | None,
        benchmark_sha256: str | None,
        embedded: bool,
        limits: SubmissionLimits,
    ) -> None:
        if not isinstance(limits, SubmissionLimits):
            raise SubmissionError(
                f"limits: expected a SubmissionLimits, found {type(limits).__name__}"
            )
        if isinstance(object_ids, (str, bytes)):
            raise SubmissionError(
                f"object_ids: expected a sequence of object ids, found a single string "
                f"{_show(object_ids)}"
            )
        if object_ids is not None:
            object_ids = [_check_object_id(i, "object_ids") for i in object_ids]
        if benchmark_sha256 is not None and (
            not isinstance(benchmark_sha256, str) or not _HEX64.fullmatch(benchmark_sha256)
        ):
            raise SubmissionError(
                "benchmark_sha256: expected None or 64 lower-case hex digits, "
                f"found {_show(benchmark_sha256)}"
            )
        self.object_ids = None if object_ids is None else set(object_ids)
        self.benchmark_sha256 = benchmark_sha256
        self.embedded = bool(embedded)
        self.limits = limits
        self.log = ProblemLog()
        self.problems = self.log.problems
        self.contents = Contents()
        self.readable: list[ReadableDataset] = []

    # ---- the path ---------------------------------------------------------------------------

    def run(self, path: str | os.PathLike[str]) -> None:
        path = Path(path)
        f = self.open(path)
        if f is None:
            return
        with f:
            attributes = RootAttributes(
                self.log,
                self.limits,
                embedded=self.embedded,
                benchmark_sha256=self.benchmark_sha256,
                contents=self.contents,
            )
            with self.log.guard("/", "reading the root attributes"):
                attributes.check(f)
            with self.log.guard("/", "walking the tree"):
                TreeWalk(self.log, self.limits, self.object_ids, self.readable).walk(f)
            self.values()

    def open(self, path: Path) -> h5py.File | None:
        """The file opened for reading once its path passed, else None (and a problem)."""
        add = self.log.add
        try:
            st = os.stat(path)
        except FileNotFoundError:
            add("file", f"expected a submission file at {path}, found nothing there")
            return None
        except OSError as exc:
            add("file", f"expected a readable file at {path}, found {exc.strerror}")
            return None
        self.contents.stat = st
        if not stat.S_ISREG(st.st_mode):
            what = "a directory" if stat.S_ISDIR(st.st_mode) else "something else"
            add("file", f"expected a regular file at {path}, found {what}")
            return None
        if st.st_size > self.limits.max_file_bytes:
            add(
                "file",
                f"expected at most {self.limits.max_file_bytes} bytes, found a file of "
                f"{st.st_size} bytes (over the limit; not opened)",
            )
            return None
        try:
            problem = hdf5_content_problem(path)
        except OSError as exc:
            add("file", f"expected a readable file at {path}, found {exc.strerror}")
            return None
        if problem is not None:
            add("file", f"expected an HDF5 file, found {problem}")
            return None
        try:
            return h5py.File(path, "r")
        except Exception as exc:
            add(
                "file",
                f"expected an HDF5 file HDF5 can open, found one it cannot (truncated or "
                f"corrupt): {_show(str(exc), 200)}",
            )
            return None

    # ---- values -----------------------------------------------------------------------------

    def values(self) -> None:
        """Read and check the datasets whose headers passed, unless together they are too big."""
        total = sum(d.nbytes for d in self.readable)
        if total > self.limits.max_total_bytes:
            compressed = sorted({d.compression for d in self.readable if d.compression})
            how = f" ({', '.join(compressed)}-compressed)" if compressed else ""
            self.log.add(
                "/",
                f"expected at most {self.limits.max_total_bytes} bytes of data in all "
                f"(uncompressed), found datasets{how} declaring {total} bytes: they would "
                "inflate past the limit (not read)",
            )
            self.readable.clear()
            return
        for item in self.readable:
            with self.log.guard(item.place, "reading its values"):
                data = np.asarray(item.dataset[()], dtype=np.float64)
                check = _poses_values if item.name == "poses" else _scores_values
                if check(self.log, item.place, data):
                    target = self.contents.poses if item.name == "poses" else self.contents.scores
                    target[item.object_id] = data
        self.readable.clear()


def _bad_hands(
    log: ProblemLog, place: str, mask: np.ndarray, rows: np.ndarray, total: int, message: str
) -> bool:
    """Report the (K', 2) ``mask`` of bad hand poses (``rows`` maps to dual-grasp index) out of
    ``total``; True when there are any."""
    bad = np.argwhere(mask)
    if not bad.size:
        return False
    bad[:, 0] = rows[bad[:, 0]]
    log.add(
        f"{place}[{bad[0, 0]}, {bad[0, 1]}]",
        f"{message} in {len(bad)} of {total} hand poses (first: {_indices(bad)})",
    )
    return True


def _poses_values(log: ProblemLog, place: str, poses: np.ndarray) -> bool:
    """Check finite, rigid, bounded (K, 2, 4, 4) poses; True when all are."""
    k = len(poses)
    finite = np.isfinite(poses).reshape(k, -1).all(axis=1)
    ok = bool(finite.all())
    if not ok:
        bad = np.flatnonzero(~finite)
        rows = poses[bad]
        kinds = [w for w, m in (("NaN", np.isnan), ("inf", np.isinf)) if m(rows).any()]
        log.add(
            f"{place}[{bad[0]}]",
            f"expected finite values, found {' and '.join(kinds)} in {len(bad)} of {k} "
            f"dual grasps (first: {_indices(bad)})",
        )
    rows = np.flatnonzero(finite)
    checks = hand_pose_faults(poses[rows])
    for mask, message in checks:
        if _bad_hands(log, place, mask, rows, 2 * k, message):
            ok = False
    return ok


def _scores_values(log: ProblemLog, place: str, scores: np.ndarray) -> bool:
    """Check finite (K,) scores; True when they are."""
    bad = np.flatnonzero(~np.isfinite(scores))
    if not bad.size:
        return True
    kinds = [w for w, m in (("NaN", np.isnan), ("inf", np.isinf)) if m(scores[bad]).any()]
    log.add(
        f"{place}[{bad[0]}]",
        f"expected finite scores, found {' and '.join(kinds)} in {len(bad)} of "
        f"{len(scores)} (first: {_indices(bad)})",
    )
    return False


def _validate(
    path: str | os.PathLike[str],
    object_ids: Sequence[str] | None,
    benchmark_sha256: str | None,
    embedded: bool,
    limits: SubmissionLimits,
) -> tuple[list[Problem], Contents]:
    validator = _Validator(object_ids, benchmark_sha256, embedded, limits)
    validator.run(path)
    return validator.problems, validator.contents


def validate_submission(
    path: str | os.PathLike[str],
    *,
    object_ids: Sequence[str] | None = None,
    benchmark_sha256: str | None = None,
    embedded: bool = True,
    limits: SubmissionLimits = SubmissionLimits(),
) -> list[Problem]:
    """Every problem of a submission file (see the module docstring), each with its place.

    Reads the file only (never modifies it), never follows a soft or external link, never reads
    external or virtual storage, and reads a dataset's values only after its dtype, shape,
    storage and declared size passed. A corrupt or truncated file gives problems, not errors.

    Args:
        path: the submission file.
        object_ids: the benchmark's object ids; None skips the unknown / missing checks.
        benchmark_sha256: sha256 of the benchmark being evaluated; None accepts any.
        embedded: whether the benchmark being evaluated is the embedded one; when False, a
            file made for ``"embedded"`` is a problem.
        limits: size limits.

    Returns:
        The problems, in file order (empty for a valid file).

    Raises:
        SubmissionError: bad arguments (not a problem of the file).
    """
    return _validate(path, object_ids, benchmark_sha256, embedded, limits)[0]


def read_submission(
    path: str | os.PathLike[str],
    *,
    object_ids: Sequence[str] | None = None,
    benchmark_sha256: str | None = None,
    embedded: bool = True,
    limits: SubmissionLimits = SubmissionLimits(),
) -> Submission:
    """Validate and read a submission file (read-only; the values come from the validation pass).

    Args:
        path: the submission file.
        object_ids, benchmark_sha256, embedded, limits: as :func:`validate_submission`.

    Returns:
        The submission: float64 poses (K, 2, 4, 4) and scores (K,), the benchmark attribute, the
        metadata and the file's sha256.

    Raises:
        SubmissionInvalid: the file has problems (its
            :attr:`~dg16m_env.subjects.submission.SubmissionInvalid.problems` lists all).
        SubmissionError: the file changed while it was read.
    """
    problems, contents = _validate(path, object_ids, benchmark_sha256, embedded, limits)
    if problems:
        raise SubmissionInvalid(problems, path)
    try:
        sha256 = file_sha256(path)
        after = os.stat(path)
    except OSError as exc:
        raise SubmissionError(
            f"{path}: expected a file that stays put, found it gone while read ({exc.strerror})"
        ) from None
    before = contents.stat
    same = before is not None and all(
        getattr(before, k) == getattr(after, k)
        for k in ("st_dev", "st_ino", "st_size", "st_mtime_ns")
    )
    if not same:
        raise SubmissionError(
            f"{path}: expected a file that stays put, found it changed while read"
        )
    return Submission(
        poses=contents.poses,
        scores=contents.scores,
        benchmark=contents.benchmark,
        metadata=contents.metadata,
        sha256=sha256,
    )
