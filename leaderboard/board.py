"""The leaderboard: teams, submissions, a queue of scoring jobs with leases, and results.

:class:`Board` is the one object the service, the workers and the command line use; it puts
together the parts, each in its own module:

* :mod:`leaderboard.store`: the SQLite database (WAL mode; schema and migrations in
  :mod:`leaderboard.schema`), its connections and settings;
* :mod:`leaderboard.teams`: teams and their tokens;
* :mod:`leaderboard.files`: submission files stored by content hash
  (``<db stem>.files/<aa>/<sha256>.h5``, written atomically, never overwritten), uploads
  being received (``<db stem>.uploads/``), and what killed processes left there;
* :mod:`leaderboard.queue`: the scoring jobs, their claims and leases, and every state change
  as an event;
* :mod:`leaderboard.results`: reading submissions, counts and ranked results for the views;
* :mod:`leaderboard.tracks`: each submission's track (mesh or cloud, from its file's
  metadata) and provenance; standings are per track, never mixed;
* :mod:`leaderboard.query_checks`: the errors, and the checks of names, labels, ids and queries.

Any number of processes may open the same board. Submission files are validated
(:func:`dg16m_env.subjects.submission_reader.read_submission`, against the board's benchmark) before anything
is stored; a refused file changes nothing.
"""

from __future__ import annotations

import contextlib
import functools
import os
import sqlite3
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dg16m_env.subjects.submission import Problem, SubmissionInvalid, SubmissionLimits
from dg16m_env.subjects.submission_reader import read_submission

from .files import FileStore
from .query_checks import (
    FILE_NAME,
    LABEL_CHARS,
    MAX_ID,
    TEAM_NAME,
    BoardError,
    DuplicateError,
    ForbiddenError,
    NotFoundError,
    check_evaluators,
    check_file_name,
    check_id,
    check_label,
    check_team_name,
)
from .queue import Claim, NewSubmission, Queue
from .results import Results
from .store import BUSY_TIMEOUT_MS, Store
from .teams import Team, Teams
from .tracks import TrackError, track_of

__all__ = [
    "BUSY_TIMEOUT_MS",
    "DEFAULT_EVALUATORS",
    "FILE_NAME",
    "LABEL_CHARS",
    "MAX_ID",
    "TEAM_NAME",
    "BenchmarkSetting",
    "Board",
    "BoardError",
    "Claim",
    "DuplicateError",
    "ForbiddenError",
    "NotFoundError",
    "Team",
    "check_evaluators",
    "check_file_name",
    "check_id",
    "check_label",
    "check_team_name",
]

DEFAULT_EVALUATORS = ("fce", "gsr")
"""Evaluators a submission is scored with unless it (or the board) names others."""


@dataclass(frozen=True)
class BenchmarkSetting:
    """The benchmark a board scores against (stored in its settings).

    Attributes:
        path: the benchmark file; None for the benchmark shipped with dg16m.
        sha256: hex sha256 of its bytes (checked whenever it is loaded).
        object_ids: its object ids, in order (submissions are validated against them).
        mesh_root: folder of a mesh benchmark's meshes.
    """

    path: str | None
    sha256: str
    object_ids: tuple[str, ...]
    mesh_root: str | None = None

    @property
    def embedded(self) -> bool:
        return self.path is None


class Board:
    """One leaderboard: a SQLite database and its folders of submission files and uploads.

    Args:
        db: the database file (created with its folder when absent).
        benchmark: a new board's benchmark file (default: the one shipped with dg16m);
            ignored when the board exists (its benchmark is fixed at creation).
        mesh_root: folder of a mesh benchmark's meshes (new boards).
        evaluators: a new board's default evaluators (default fce, gsr).
        title: a new board's title.
        max_attempts: claims of one job before it is failed (workers keep dying on it).
        limits: the submission file limits (default :class:`SubmissionLimits`).
        clock: the time source (s since the epoch); tests pass a fake one.
        create: make the board when ``db`` does not exist (else refuse).

    Attributes:
        db, files, uploads: the database, the file store and the uploads folder.
        store: the database's connections (:class:`~leaderboard.store.Store`).
        team_store: the teams (:class:`~leaderboard.teams.Teams`).
        file_store: the files (:class:`~leaderboard.files.FileStore`).
        jobs: the queue (:class:`~leaderboard.queue.Queue`).
        rows: the read side for the views (:class:`~leaderboard.results.Results`).

    Raises:
        NotFoundError: no board at ``db`` and ``create`` is False.
        SchemaError: a database of a newer dg16m, or not a leaderboard.
        BenchmarkError: a new board's benchmark file is missing or malformed.
    """

    def __init__(
        self,
        db: str | os.PathLike[str],
        *,
        benchmark: str | os.PathLike[str] | None = None,
        mesh_root: str | os.PathLike[str] | None = None,
        evaluators: Sequence[str] = DEFAULT_EVALUATORS,
        title: str = "dg16m leaderboard",
        max_attempts: int = 3,
        limits: SubmissionLimits | None = None,
        clock: Callable[[], float] = time.time,
        create: bool = True,
    ) -> None:
        if not create and not Path(db).is_file():
            raise NotFoundError(
                f"--db: expected a leaderboard database, found nothing at {db} (make one with "
                "'dg16m leaderboard init' or 'dg16m leaderboard team add')"
            )
        if max_attempts < 1:
            raise BoardError(f"max_attempts: expected >= 1, found {max_attempts}")
        self.db = Path(db)
        self.files = self.db.parent / f"{self.db.stem}.files"
        self.uploads = self.db.parent / f"{self.db.stem}.uploads"
        self.max_attempts = max_attempts
        self.limits = limits or SubmissionLimits()
        self.clock = clock
        self.store = Store(self.db)
        self.team_store = Teams(self.store, clock)
        self.file_store = FileStore(self.files, self.uploads)
        self.jobs = Queue(self.store, clock, max_attempts)
        self.rows = Results(self.store)
        self._benchmark_ref: Any = None  # loaded by _initialise or benchmark_ref()
        if self.setting("benchmark") is None:
            self._initialise(benchmark, mesh_root, check_evaluators(list(evaluators)), title)

    # -- the database and settings -----------------------------------------------------------

    def read(self) -> contextlib.AbstractContextManager[sqlite3.Connection]:
        """A connection for reads (a consistent snapshot inside one ``with``)."""
        return self.store.read()

    def write(self) -> contextlib.AbstractContextManager[sqlite3.Connection]:
        """A connection inside one ``BEGIN IMMEDIATE`` transaction (see :meth:`Store.write`)."""
        return self.store.write()

    def setting(self, key: str) -> Any:
        """A setting's value (JSON-decoded), or None."""
        return self.store.setting(key)

    def integrity_check(self) -> str:
        """SQLite's ``PRAGMA integrity_check`` (``"ok"`` for a sound database)."""
        return self.store.integrity_check()

    def _initialise(
        self,
        benchmark: str | os.PathLike[str] | None,
        mesh_root: str | os.PathLike[str] | None,
        evaluators: list[str],
        title: str,
    ) -> None:
        from dg16m_env.evaluators import load_benchmark_ref

        ref = load_benchmark_ref(benchmark, mesh_root)
        setting = {
            "path": None if ref.embedded else str(ref.path.resolve()),
            "sha256": ref.sha256,
            "object_ids": ref.object_ids,
            "mesh_root": None if mesh_root is None else str(Path(mesh_root).resolve()),
        }
        self.store.add_settings(
            {
                "benchmark": setting,
                "evaluators": evaluators,
                "title": check_label(title),
                "created_at": self.clock(),
            }
        )
        self._benchmark_ref = ref

    @functools.cached_property
    def benchmark(self) -> BenchmarkSetting:
        """The board's benchmark."""
        data = self.setting("benchmark")
        return BenchmarkSetting(
            path=data["path"],
            sha256=data["sha256"],
            object_ids=tuple(data["object_ids"]),
            mesh_root=data["mesh_root"],
        )

    @functools.cached_property
    def evaluators(self) -> list[str]:
        """The evaluators a submission is scored with unless it names others."""
        return list(self.setting("evaluators"))

    @functools.cached_property
    def title(self) -> str:
        return str(self.setting("title"))

    def benchmark_ref(self) -> Any:
        """The board's benchmark loaded (:class:`~dg16m_env.evaluators.BenchmarkRef`), cached.

        Raises:
            BoardError: the benchmark file changed since the board was made.
        """
        if self._benchmark_ref is None:
            from dg16m_env.evaluators import load_benchmark_ref

            setting = self.benchmark
            ref = load_benchmark_ref(setting.path, setting.mesh_root)
            if ref.sha256 != setting.sha256:
                raise BoardError(
                    f"benchmark {ref.path}: expected sha256 {setting.sha256[:12]}... (the file "
                    f"this board was made with), found {ref.sha256[:12]}...: the file changed"
                )
            self._benchmark_ref = ref
        return self._benchmark_ref

    # -- teams -------------------------------------------------------------------------------

    def add_team(self, name: str) -> tuple[Team, str]:
        """A new team and its token (see :meth:`Teams.add`)."""
        return self.team_store.add(name)

    def rotate_token(self, name: str) -> str:
        """A new token for a team (see :meth:`Teams.rotate_token`)."""
        return self.team_store.rotate_token(name)

    def teams(self) -> list[Team]:
        """Every team, by creation."""
        return self.team_store.all()

    def team(self, name: str) -> Team:
        """The team called ``name`` (see :meth:`Teams.named`)."""
        return self.team_store.named(name)

    def authenticate(self, token: str) -> Team | None:
        """The team holding ``token``, or None (constant-time comparison with every hash)."""
        return self.team_store.authenticate(token)

    # -- submissions -------------------------------------------------------------------------

    def file_path(self, sha256: str) -> Path:
        """Where the submission file with this content hash is stored."""
        return self.file_store.path(sha256)

    def submit(
        self,
        team: Team,
        path: str | os.PathLike[str],
        *,
        filename: str | None = None,
        label: str | None = None,
        evaluators: Sequence[str] | str | None = None,
    ) -> int:
        """Validate a submission file, store it and queue it; returns the submission id.

        The file is read twice (validated and hashed in one pass by ``read_submission``, then
        copied into the store) and hashed once; it must not change meanwhile (its size, inode
        and modification time are compared before and after).

        Args:
            team: the submitting team.
            path: the file (copied into the board's file store; left where it is).
            filename: the name to record (default the path's name); a plain file name.
            label: the name shown on the board (default the file's metadata ``method``, else
                the file name without its extension).
            (the track, ``mesh`` or ``cloud``, and its provenance come from the file's metadata
            ``track``: see :mod:`leaderboard.tracks`)
            evaluators: evaluator names (default the board's).

        Raises:
            BoardError: a bad file name, label or evaluator name, or a file that changed.
            SubmissionInvalid: the file has problems (all listed), or its metadata names a
                track that is not ``mesh`` or ``cloud``; nothing was stored.
            DuplicateError: this team already submitted the same file for the same evaluators.
        """
        filename = check_file_name(Path(path).name if filename is None else filename)
        names = check_evaluators(self.evaluators if evaluators is None else evaluators)
        setting = self.benchmark
        before = _identity(path)  # None: missing, and read_submission says so
        try:
            submission = read_submission(
                path,
                object_ids=setting.object_ids,
                benchmark_sha256=setting.sha256,
                embedded=setting.embedded,
                limits=self.limits,
            )
        except SubmissionInvalid as exc:
            raise SubmissionInvalid(exc.problems, filename) from None
        try:
            track, provenance = track_of(submission.metadata)
        except TrackError as exc:
            raise SubmissionInvalid([Problem("attrs/metadata", exc.message)], filename) from None
        sha256 = submission.sha256
        label = check_label(_label_of(submission.metadata, filename) if label is None else label)
        same = self.jobs.duplicate(team.id, sha256, names)
        if same is not None:
            raise DuplicateError(
                f"submission: expected a new file, found the same file (sha256 "
                f"{sha256[:12]}...) already submitted as #{same} for {','.join(names)}",
                same,
            )
        size = os.stat(path).st_size if before is None else before[2]
        with self.file_store.kept(path, sha256, size):
            if before is None or _identity(path) != before:
                raise BoardError(
                    f"{path}: expected a file that stays put, found it changed while stored"
                )
            return self.jobs.enqueue(
                NewSubmission(
                    team.id, team.name, sha256, size, filename, label, names, track, provenance
                )
            )

    def submission_row(self, submission_id: int) -> sqlite3.Row:
        """The submission's row joined with its team's name and its job.

        Raises:
            NotFoundError: no such submission (or an id no row can have).
        """
        return self.rows.submission_row(submission_id)

    def submissions(self, team: Team | None = None) -> list[sqlite3.Row]:
        """Submissions (of one team, or all), newest first, as :meth:`submission_row`."""
        return self.rows.submissions(team)

    def own_submission(self, team: Team, submission_id: int) -> sqlite3.Row:
        """A submission of ``team`` (see :meth:`Results.own_submission`)."""
        return self.rows.own_submission(team, submission_id)

    def submission_times(self, team: Team, since: float) -> list[float]:
        """Times of the team's submissions at or after ``since`` (the rate limiter's memory)."""
        return self.rows.submission_times(team, since)

    def remove_orphans(self) -> list[Path]:
        """Remove files killed processes left (see :meth:`FileStore.remove_orphans`)."""
        return self.file_store.remove_orphans(self.rows.references, self.rows.referenced_files)

    # -- the queue ---------------------------------------------------------------------------

    def requeue_stale(self) -> list[int]:
        """Re-queue every running job whose lease expired; returns their submission ids."""
        return self.jobs.requeue_stale()

    def claim(self, worker: str, lease_s: float, submission_id: int | None = None) -> Claim | None:
        """Claim the oldest queued job (or the given one) for ``lease_s`` (see
        :meth:`Queue.claim`); None when nothing is queued."""
        return self.jobs.claim(worker, lease_s, submission_id)

    def renew(self, claim: Claim, lease_s: float) -> bool:
        """Extend a claim's lease by ``lease_s`` from now; False when the claim was lost."""
        return self.jobs.renew(claim, lease_s)

    def holds(self, claim: Claim) -> bool:
        """Whether ``claim`` is still current (its results would be accepted)."""
        return self.jobs.holds(claim)

    def finish(self, claim: Claim, results: Mapping[str, Any], log: str) -> bool:
        """Store a claim's results (see :meth:`Queue.finish`); False when the claim was lost.

        Raises:
            BoardError: a result of only some of the benchmark's objects (``dg16m evaluate
                --objects / --limit``, marked partial), or of another number of objects than
                the board's benchmark holds: the board never ranks such a result; or a result
                whose subject declares another track than the submission's.
        """
        track = self.submission_row(claim.submission_id)["track"]
        for name, result in results.items():
            check_full_result(name, result, len(self.benchmark.object_ids))
            check_result_track(name, result, track)
        return self.jobs.finish(claim, results, log)

    def fail(self, claim: Claim, error: str, log: str) -> bool:
        """Mark a claim's submission failed with ``error``; False when the claim was lost."""
        return self.jobs.fail(claim, error, log)

    def events(self, submission_id: int) -> list[sqlite3.Row]:
        """Every state change of a submission, oldest first."""
        return self.jobs.events(submission_id)

    def queue(self, team: Team | None = None) -> list[sqlite3.Row]:
        """Jobs not done (queued and running, with their lease deadlines), oldest first; of
        one team when given."""
        return self.jobs.jobs(None if team is None else team.id)

    # -- results -----------------------------------------------------------------------------

    def counts(self) -> dict[str, int]:
        """Teams, submissions, and submissions per status."""
        return self.rows.counts()

    def results(self, submission_id: int) -> dict[str, dict[str, Any]]:
        """A submission's results: evaluator name -> ``EvaluationResult.to_dict()``."""
        return self.rows.results(submission_id)

    def scored(self) -> list[sqlite3.Row]:
        """Every stored result of a scored submission with its submission, team, track and rank
        (within its track and evaluator), best headline score first per track and evaluator
        (ties: earlier submission first)."""
        return self.rows.scored()

    def scored_totals(self, *, track: str) -> dict[str, int]:
        """Scored results of one track per evaluator."""
        return self.rows.scored_totals(track=track)

    def scored_page(
        self, evaluator: str, offset: int, limit: int, *, track: str
    ) -> list[sqlite3.Row]:
        """One page of an evaluator's ranked results in one track (see
        :meth:`Results.scored_page`)."""
        return self.rows.scored_page(evaluator, offset, limit, track=track)


def check_full_result(name: str, result: Any, n_objects: int) -> None:
    """Refuse a result that did not score the whole benchmark (see :meth:`Board.finish`).

    Args:
        name: the evaluator's name.
        result: an :class:`~dg16m_env.evaluators.EvaluationResult` (or anything with
            ``to_dict()``).
        n_objects: the board's benchmark's number of objects.

    Raises:
        BoardError: a partial result.
    """
    record = result.to_dict().get("benchmark") if hasattr(result, "to_dict") else None
    if not isinstance(record, Mapping) or not record:
        return  # a result without a benchmark record (e.g. a policy's): nothing to check
    objects = record.get("objects")
    if (
        record.get("partial")
        or record.get("subset")
        or (isinstance(objects, int) and objects != n_objects)
    ):
        raise BoardError(
            f"{name}: expected a result over the benchmark's {n_objects} objects, found a "
            f"partial one ({objects} objects, from 'dg16m evaluate --objects/--limit'): the "
            "board never ranks partial results; score the whole benchmark"
        )


def check_result_track(name: str, result: Any, track: str) -> None:
    """Refuse a result whose subject record names another track than the submission's (the
    board ranks it in the submission's track: the two must agree).

    Args:
        name: the evaluator's name.
        result: an :class:`~dg16m_env.evaluators.EvaluationResult` (or anything with
            ``to_dict()``); one without a subject track is not checked.
        track: the submission's track.

    Raises:
        BoardError: the tracks differ.
    """
    record = result.to_dict().get("subject") if hasattr(result, "to_dict") else None
    found = record.get("track") if isinstance(record, Mapping) else None
    if found is not None and found != track:
        raise BoardError(
            f"{name}: expected a result of a {track}-track submission, found one whose subject "
            f"declares the {found!r} track"
        )


def _identity(path: str | os.PathLike[str]) -> tuple[int, int, int, int] | None:
    """What tells that a file was not changed (device, inode, size, modification time), or
    None when it cannot be read."""
    try:
        info = os.stat(path)
    except OSError:
        return None
    return info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns


def _label_of(metadata: Mapping[str, Any], filename: str) -> str:
    """A submission's label: its metadata ``method`` when that is a usable label, else the file
    name's stem."""
    method = metadata.get("method")
    if isinstance(method, str):
        with contextlib.suppress(BoardError):
            return check_label(method)
    return Path(filename).stem[:LABEL_CHARS] or filename
