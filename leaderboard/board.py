"""The leaderboard store: teams, submissions, a queue of scoring jobs with leases, and results.

A board is a SQLite database in WAL mode (schema and migrations in :mod:`leaderboard.schema`)
and, beside it, a folder of submission files stored by content hash
(``<db stem>.files/<aa>/<sha256>.h5``, written atomically, never overwritten). Any number of
processes may open the same board: the service, several workers and the command line. Every
write is one ``BEGIN IMMEDIATE`` transaction; each process opens its own connections.

Life of a submission::

    submit -> queued -> running (claimed by a worker, with a lease) -> scored | failed
                 ^__________|  lease expired (worker died): re-queued, or failed after
                               ``max_attempts`` claims

A claim is a lease with a deadline that the worker renews while it scores
(:meth:`Board.renew`). A claim whose deadline passed is re-queued by the next
:meth:`Board.claim` (or :meth:`Board.requeue_stale`), with an event saying whose lease
expired; results are accepted only from the current claim (:meth:`Board.finish`), so a
submission is scored once even when a worker that lost its lease comes back. Every state
change is an event (:meth:`Board.events`).

Submission files are validated (:func:`dg16m_env.submission.validate_submission`, against the
board's benchmark) before anything is stored; a refused file changes nothing.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import re
import shutil
import sqlite3
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dataset_gen.atomic import atomic_path
from dataset_gen.errors import Dg16mError
from dataset_gen.hashing import file_sha256
from dg16m_env.submission import (
    SubmissionInvalid,
    SubmissionLimits,
    read_submission,
)

from .schema import migrate
from .tokens import find_token, new_token, token_sha256

DEFAULT_EVALUATORS = ("fce", "gsr")
"""Evaluators a submission is scored with unless it (or the board) names others."""
TEAM_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9 ._-]{0,63}$")
"""Team names: 1-64 letters, digits, space, dot, underscore, hyphen; not starting with a sign."""
FILE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$")
"""Uploaded file names: a plain name (no folders, no ``..``, no spaces or control characters)."""
LABEL_CHARS = 80
"""Longest label (the name shown on the board)."""
BUSY_TIMEOUT_MS = 30_000
_SUBMISSIONS = (
    "SELECT s.*, t.name AS team, j.state AS job_state, j.attempts, j.worker, "
    "j.lease_expires_at FROM submissions s JOIN teams t ON t.id = s.team_id "
    "LEFT JOIN jobs j ON j.submission_id = s.id"
)
"""A submission's row with its team's name and its job (see :meth:`Board.submission_row`)."""


class BoardError(Dg16mError, ValueError):
    """A request the board refuses; :attr:`status` is the HTTP status the service answers."""

    status = 400


class NotFoundError(BoardError):
    """No such team or submission."""

    status = 404


class ForbiddenError(BoardError):
    """A team asked for another team's submission."""

    status = 403


class DuplicateError(BoardError):
    """The same file with the same evaluators was already submitted by this team."""

    status = 409

    def __init__(self, message: str, submission_id: int):
        super().__init__(message)
        self.submission_id = submission_id


@dataclass(frozen=True)
class Team:
    """A team: ``id``, ``name`` and creation time (s since the epoch)."""

    id: int
    name: str
    created_at: float


@dataclass(frozen=True)
class Claim:
    """A worker's lease on one submission's scoring job.

    Attributes:
        submission_id: the submission.
        claim: id of this claim (results are accepted only with the current one).
        worker: who holds it.
        lease_expires_at: deadline (s since the epoch); renew before it passes.
        attempt: 1 for the first claim of the job, 2 after one re-queue, ...
    """

    submission_id: int
    claim: str
    worker: str
    lease_expires_at: float
    attempt: int


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


def check_team_name(name: Any) -> str:
    """``name`` if it is a valid team name.

    Raises:
        BoardError: anything else, saying what a name may hold.
    """
    if not isinstance(name, str) or not TEAM_NAME.match(name) or name != name.strip():
        raise BoardError(
            "team: expected 1-64 letters, digits, spaces, '.', '_' or '-' starting with a "
            f"letter or digit, found {name!r}"
        )
    return name


def check_file_name(name: Any) -> str:
    """``name`` if it is a plain file name (what an upload may call itself).

    Raises:
        BoardError: a path (``/``, ``\\``, ``..``), an empty or hidden name, odd characters.
    """
    if not isinstance(name, str) or not FILE_NAME.match(name) or ".." in name:
        raise BoardError(
            "file name: expected a plain name of letters, digits, '.', '_' and '-' (like "
            f"mine.h5, no folders), found {str(name)[:200]!r}"
        )
    return name


def check_label(label: Any) -> str:
    """A label for the board: printable, at most :data:`LABEL_CHARS` characters.

    Raises:
        BoardError: not a string, empty, too long or with control characters.
    """
    if (
        not isinstance(label, str)
        or not label.strip()
        or len(label) > LABEL_CHARS
        or not label.isprintable()
    ):
        raise BoardError(
            f"label: expected 1-{LABEL_CHARS} printable characters, found {str(label)[:200]!r}"
        )
    return label.strip()


def check_evaluators(names: Sequence[str] | str) -> list[str]:
    """Registered evaluators of submission files, in the given order, without repeats.

    Raises:
        BoardError: an unknown name, or an evaluator of something else than submissions.
    """
    from dg16m_env.evaluators import evaluator_class
    from dg16m_env.evaluators import names as registered

    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    out: list[str] = []
    for name in names:
        if name not in registered():
            raise BoardError(
                f"evaluators: expected names of {', '.join(registered())}, found {name!r}"
            )
        kind = evaluator_class(name).subject_kind
        if kind != "submission":
            raise BoardError(
                f"evaluators: expected evaluators of submission files, found {name!r} (it "
                f"scores a {kind})"
            )
        if name not in out:
            out.append(name)
    if not out:
        raise BoardError("evaluators: expected at least one name (e.g. fce,gsr), found none")
    return out


class Board:
    """One leaderboard: a SQLite database and its folder of submission files.

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
        self.max_attempts = max_attempts
        self.limits = limits or SubmissionLimits()
        self.clock = clock
        self._benchmark_ref: Any = None  # loaded by _initialise or benchmark_ref()
        self.db.parent.mkdir(parents=True, exist_ok=True)
        with contextlib.closing(self._connect()) as conn:
            conn.execute("PRAGMA journal_mode=WAL")
            migrate(conn)
        if self.setting("benchmark") is None:
            self._initialise(benchmark, mesh_root, check_evaluators(list(evaluators)), title)

    # ---------------------------------------------------------------------------------------
    # Connections and settings
    # ---------------------------------------------------------------------------------------

    def _connect(self) -> sqlite3.Connection:
        conn = sqlite3.connect(self.db, isolation_level=None, timeout=BUSY_TIMEOUT_MS / 1000)
        conn.row_factory = sqlite3.Row
        conn.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
        conn.execute("PRAGMA foreign_keys = ON")
        conn.execute("PRAGMA synchronous = NORMAL")  # WAL: durable at checkpoints, never corrupt
        return conn

    @contextlib.contextmanager
    def read(self) -> Iterator[sqlite3.Connection]:
        """A connection for reads (a consistent snapshot inside one ``with``)."""
        with contextlib.closing(self._connect()) as conn:
            conn.execute("BEGIN")
            try:
                yield conn
            finally:
                conn.execute("ROLLBACK")

    @contextlib.contextmanager
    def write(self) -> Iterator[sqlite3.Connection]:
        """A connection inside one ``BEGIN IMMEDIATE`` transaction: committed when the block
        ends, rolled back when it raises."""
        with contextlib.closing(self._connect()) as conn:
            conn.execute("BEGIN IMMEDIATE")
            try:
                yield conn
            except BaseException:
                conn.execute("ROLLBACK")
                raise
            conn.execute("COMMIT")

    def setting(self, key: str) -> Any:
        """A setting's value (JSON-decoded), or None."""
        with self.read() as conn:
            row = conn.execute("SELECT value FROM settings WHERE key = ?", (key,)).fetchone()
        return None if row is None else json.loads(row["value"])

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
        values = {
            "benchmark": setting,
            "evaluators": evaluators,
            "title": check_label(title),
            "created_at": self.clock(),
        }
        with self.write() as conn:
            for key, value in values.items():
                conn.execute(
                    "INSERT OR IGNORE INTO settings (key, value) VALUES (?, ?)",
                    (key, json.dumps(value)),
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

    # ---------------------------------------------------------------------------------------
    # Teams
    # ---------------------------------------------------------------------------------------

    def add_team(self, name: str) -> tuple[Team, str]:
        """A new team and its token (shown once: only its hash is stored).

        Raises:
            BoardError: a bad name, or a team of that name exists.
        """
        check_team_name(name)
        token = new_token()
        now = self.clock()
        with self.write() as conn:
            if conn.execute("SELECT 1 FROM teams WHERE name = ?", (name,)).fetchone():
                raise BoardError(f"team: expected a new name, found {name!r} already taken")
            cursor = conn.execute(
                "INSERT INTO teams (name, token_sha256, created_at) VALUES (?, ?, ?)",
                (name, token_sha256(token), now),
            )
        return Team(int(cursor.lastrowid or 0), name, now), token

    def rotate_token(self, name: str) -> str:
        """A new token for a team (the old one stops working).

        Raises:
            NotFoundError: no such team.
        """
        token = new_token()
        with self.write() as conn:
            cursor = conn.execute(
                "UPDATE teams SET token_sha256 = ? WHERE name = ?", (token_sha256(token), name)
            )
            if cursor.rowcount != 1:
                raise NotFoundError(f"team: expected an existing team, found {name!r}")
        return token

    def teams(self) -> list[Team]:
        """Every team, by creation."""
        with self.read() as conn:
            rows = conn.execute("SELECT id, name, created_at FROM teams ORDER BY id").fetchall()
        return [Team(r["id"], r["name"], r["created_at"]) for r in rows]

    def team(self, name: str) -> Team:
        """The team called ``name``.

        Raises:
            NotFoundError: no such team.
        """
        for team in self.teams():
            if team.name == name:
                return team
        known = ", ".join(t.name for t in self.teams()) or "none yet"
        raise NotFoundError(f"team: expected one of the board's teams ({known}), found {name!r}")

    def authenticate(self, token: str) -> Team | None:
        """The team holding ``token``, or None (constant-time comparison with every hash)."""
        with self.read() as conn:
            rows = conn.execute("SELECT id, name, created_at, token_sha256 FROM teams").fetchall()
        return find_token(
            token, [(r["token_sha256"], Team(r["id"], r["name"], r["created_at"])) for r in rows]
        )

    # ---------------------------------------------------------------------------------------
    # Submissions
    # ---------------------------------------------------------------------------------------

    def file_path(self, sha256: str) -> Path:
        """Where the submission file with this content hash is stored."""
        if not re.fullmatch(r"[0-9a-f]{64}", sha256):
            raise BoardError(f"sha256: expected 64 hex digits, found {sha256!r}")
        return self.files / sha256[:2] / f"{sha256}.h5"

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

        Args:
            team: the submitting team.
            path: the file (copied into the board's file store; left where it is).
            filename: the name to record (default the path's name); a plain file name.
            label: the name shown on the board (default the file's metadata ``method``, else
                the file name without its extension).
            evaluators: evaluator names (default the board's).

        Raises:
            BoardError: a bad file name, label or evaluator name.
            SubmissionInvalid: the file has problems (all listed); nothing was stored.
            DuplicateError: this team already submitted the same file for the same evaluators.
        """
        filename = check_file_name(Path(path).name if filename is None else filename)
        names = check_evaluators(self.evaluators if evaluators is None else evaluators)
        setting = self.benchmark
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
        sha256 = submission.sha256
        size = os.stat(path).st_size
        if label is None:
            label = _label_of(submission.metadata, filename)
        label = check_label(label)
        with self.read() as conn:
            same = self._duplicate(conn, team.id, sha256, names)
        if same is not None:
            raise DuplicateError(
                f"submission: expected a new file, found the same file (sha256 "
                f"{sha256[:12]}...) already submitted as #{same} for {','.join(names)}",
                same,
            )
        self._store_file(path, sha256)
        now = self.clock()
        with self.write() as conn:
            same = self._duplicate(conn, team.id, sha256, names)  # a concurrent twin
            if same is not None:
                raise DuplicateError(f"submission: already submitted as #{same}", same)
            cursor = conn.execute(
                "INSERT INTO submissions (team_id, file_sha256, size, filename, label, "
                "evaluators, created_at, status) VALUES (?, ?, ?, ?, ?, ?, ?, 'queued')",
                (team.id, sha256, size, filename, label, json.dumps(names), now),
            )
            sid = int(cursor.lastrowid or 0)
            conn.execute(
                "INSERT INTO jobs (submission_id, state, queued_at, updated_at) "
                "VALUES (?, 'queued', ?, ?)",
                (sid, now, now),
            )
            self._event(conn, sid, "queued", None, f"submitted by {team.name}: {filename}")
        return sid

    @staticmethod
    def _duplicate(
        conn: sqlite3.Connection, team_id: int, sha256: str, names: list[str]
    ) -> int | None:
        row = conn.execute(
            "SELECT id FROM submissions WHERE team_id = ? AND file_sha256 = ? AND evaluators = ? "
            "AND status != 'failed'",
            (team_id, sha256, json.dumps(names)),
        ).fetchone()
        return None if row is None else int(row["id"])

    def _store_file(self, path: str | os.PathLike[str], sha256: str) -> Path:
        """Copy the file into the content store (atomically; an existing copy is kept)."""
        destination = self.file_path(sha256)
        if destination.is_file() and file_sha256(destination) == sha256:
            return destination
        with atomic_path(destination) as tmp:
            shutil.copyfile(path, tmp)
            if file_sha256(tmp) != sha256:
                raise BoardError(
                    f"{path}: expected a file that stays put, found it changed while stored"
                )
        return destination

    def submission_row(self, submission_id: int) -> sqlite3.Row:
        """The submission's row joined with its team's name and its job.

        Raises:
            NotFoundError: no such submission.
        """
        with self.read() as conn:
            row = conn.execute(
                _SUBMISSIONS + " WHERE s.id = ?",
                (submission_id,),
            ).fetchone()
        if row is None:
            raise NotFoundError(f"submission: expected an existing id, found #{submission_id}")
        return row

    def submissions(self, team: Team | None = None) -> list[sqlite3.Row]:
        """Submissions (of one team, or all), newest first, as :meth:`submission_row`."""
        query = _SUBMISSIONS
        args: tuple[Any, ...] = ()
        if team is not None:
            query += " WHERE s.team_id = ?"
            args = (team.id,)
        with self.read() as conn:
            return conn.execute(query + " ORDER BY s.id DESC", args).fetchall()

    def own_submission(self, team: Team, submission_id: int) -> sqlite3.Row:
        """A submission of ``team``.

        Raises:
            NotFoundError: no such submission.
            ForbiddenError: it belongs to another team.
        """
        row = self.submission_row(submission_id)
        if row["team_id"] != team.id:
            raise ForbiddenError(
                f"submission #{submission_id}: expected one of team {team.name!r}'s "
                "submissions, found another team's (only its team may see its details)"
            )
        return row

    def submission_times(self, team: Team, since: float) -> list[float]:
        """Times of the team's submissions at or after ``since`` (the rate limiter's memory)."""
        with self.read() as conn:
            rows = conn.execute(
                "SELECT created_at FROM submissions WHERE team_id = ? AND created_at >= ? "
                "ORDER BY created_at",
                (team.id, since),
            ).fetchall()
        return [float(r["created_at"]) for r in rows]

    # ---------------------------------------------------------------------------------------
    # The queue
    # ---------------------------------------------------------------------------------------

    def _event(
        self, conn: sqlite3.Connection, sid: int, state: str, worker: str | None, message: str
    ) -> None:
        conn.execute(
            "INSERT INTO events (submission_id, at, state, worker, message) VALUES (?, ?, ?, ?, ?)",
            (sid, self.clock(), state, worker, message),
        )

    def _requeue_stale(self, conn: sqlite3.Connection, now: float) -> list[int]:
        """Re-queue (or fail, after ``max_attempts``) running jobs whose lease expired."""
        stale = conn.execute(
            "SELECT submission_id, worker, attempts, lease_expires_at FROM jobs "
            "WHERE state = 'running' AND lease_expires_at < ?",
            (now,),
        ).fetchall()
        for row in stale:
            sid, worker = int(row["submission_id"]), row["worker"]
            lapsed = (
                f"the lease of worker {worker} expired {now - row['lease_expires_at']:.0f} s ago"
            )
            if row["attempts"] >= self.max_attempts:
                error = (
                    f"scoring did not finish in {row['attempts']} attempts (the workers died or "
                    f"lost their lease; last: {lapsed})"
                )
                conn.execute(
                    "UPDATE jobs SET state = 'done', claim = NULL, lease_expires_at = NULL, "
                    "updated_at = ? WHERE submission_id = ?",
                    (now, sid),
                )
                conn.execute(
                    "UPDATE submissions SET status = 'failed', error = ? WHERE id = ?",
                    (error, sid),
                )
                self._event(conn, sid, "failed", worker, error)
            else:
                conn.execute(
                    "UPDATE jobs SET state = 'queued', claim = NULL, worker = NULL, "
                    "lease_expires_at = NULL, updated_at = ? WHERE submission_id = ?",
                    (now, sid),
                )
                conn.execute("UPDATE submissions SET status = 'queued' WHERE id = ?", (sid,))
                self._event(conn, sid, "queued", worker, f"re-queued: {lapsed}")
        return [int(r["submission_id"]) for r in stale]

    def requeue_stale(self) -> list[int]:
        """Re-queue every running job whose lease expired; returns their submission ids."""
        with self.write() as conn:
            return self._requeue_stale(conn, self.clock())

    def claim(self, worker: str, lease_s: float, submission_id: int | None = None) -> Claim | None:
        """Claim the oldest queued job (or the given submission's, if queued) for ``lease_s``.

        Expired leases are re-queued first, so a job left by a dead worker is claimed again.

        Returns:
            The claim, or None when nothing is queued.
        """
        if not (math.isfinite(lease_s) and lease_s > 0):
            raise BoardError(f"lease_s: expected a positive number of seconds, found {lease_s}")
        now = self.clock()
        with self.write() as conn:
            self._requeue_stale(conn, now)
            if submission_id is None:
                row = conn.execute(
                    "SELECT submission_id, attempts FROM jobs WHERE state = 'queued' "
                    "ORDER BY queued_at, submission_id LIMIT 1"
                ).fetchone()
            else:
                row = conn.execute(
                    "SELECT submission_id, attempts FROM jobs WHERE state = 'queued' "
                    "AND submission_id = ?",
                    (submission_id,),
                ).fetchone()
            if row is None:
                return None
            sid, attempt = int(row["submission_id"]), int(row["attempts"]) + 1
            claim = uuid.uuid4().hex
            deadline = now + lease_s
            conn.execute(
                "UPDATE jobs SET state = 'running', attempts = ?, worker = ?, claim = ?, "
                "lease_expires_at = ?, updated_at = ? WHERE submission_id = ?",
                (attempt, worker, claim, deadline, now, sid),
            )
            conn.execute("UPDATE submissions SET status = 'running' WHERE id = ?", (sid,))
            self._event(conn, sid, "running", worker, f"claimed (attempt {attempt})")
        return Claim(sid, claim, worker, deadline, attempt)

    def renew(self, claim: Claim, lease_s: float) -> bool:
        """Extend a claim's lease by ``lease_s`` from now; False when the claim was lost."""
        now = self.clock()
        with self.write() as conn:
            cursor = conn.execute(
                "UPDATE jobs SET lease_expires_at = ?, updated_at = ? WHERE submission_id = ? "
                "AND claim = ? AND state = 'running' AND lease_expires_at >= ?",
                (now + lease_s, now, claim.submission_id, claim.claim, now),
            )
        return cursor.rowcount == 1

    def _holding(self, conn: sqlite3.Connection, claim: Claim) -> bool:
        row = conn.execute(
            "SELECT 1 FROM jobs WHERE submission_id = ? AND claim = ? AND state = 'running'",
            (claim.submission_id, claim.claim),
        ).fetchone()
        return row is not None

    def finish(self, claim: Claim, results: Mapping[str, Any], log: str) -> bool:
        """Store a claim's results and mark the submission scored, in one transaction.

        Args:
            claim: the worker's claim.
            results: evaluator name -> :class:`~dg16m_env.evaluators.EvaluationResult`.
            log: the scoring log (shown to the team).

        Returns:
            False (and nothing stored) when the claim is no longer current: the lease expired
            and the job was re-queued or claimed by another worker.
        """
        now = self.clock()
        with self.write() as conn:
            if not self._holding(conn, claim):
                return False
            sid = claim.submission_id
            for name, result in results.items():
                conn.execute(
                    "INSERT INTO results (submission_id, evaluator, evaluator_version, score, "
                    "result, created_at) VALUES (?, ?, ?, ?, ?, ?)",
                    (
                        sid,
                        name,
                        result.evaluator_version,
                        result.score,
                        json.dumps(result.to_dict(), allow_nan=False),
                        now,
                    ),
                )
            self._close(conn, claim, now, "scored", None, log)
            scores = ", ".join(f"{n} {_percent(r.score)}" for n, r in results.items())
            self._event(conn, sid, "scored", claim.worker, scores or "scored")
        return True

    def fail(self, claim: Claim, error: str, log: str) -> bool:
        """Mark a claim's submission failed with ``error``; False when the claim was lost."""
        now = self.clock()
        with self.write() as conn:
            if not self._holding(conn, claim):
                return False
            self._close(conn, claim, now, "failed", error, log)
            self._event(conn, claim.submission_id, "failed", claim.worker, error)
        return True

    @staticmethod
    def _close(
        conn: sqlite3.Connection,
        claim: Claim,
        now: float,
        status: str,
        error: str | None,
        log: str,
    ) -> None:
        conn.execute(
            "UPDATE jobs SET state = 'done', claim = NULL, lease_expires_at = NULL, "
            "updated_at = ? WHERE submission_id = ?",
            (now, claim.submission_id),
        )
        conn.execute(
            "UPDATE submissions SET status = ?, error = ?, log = ? WHERE id = ?",
            (status, error, log, claim.submission_id),
        )

    def events(self, submission_id: int) -> list[sqlite3.Row]:
        """Every state change of a submission, oldest first."""
        with self.read() as conn:
            return conn.execute(
                "SELECT at, state, worker, message FROM events WHERE submission_id = ? ORDER BY id",
                (submission_id,),
            ).fetchall()

    def queue(self) -> list[sqlite3.Row]:
        """Jobs not done (queued and running, with their lease deadlines), oldest first."""
        with self.read() as conn:
            return conn.execute(
                "SELECT j.*, s.label, t.name AS team FROM jobs j "
                "JOIN submissions s ON s.id = j.submission_id JOIN teams t ON t.id = s.team_id "
                "WHERE j.state != 'done' ORDER BY j.queued_at, j.submission_id"
            ).fetchall()

    def counts(self) -> dict[str, int]:
        """Teams, submissions, and submissions per status."""
        with self.read() as conn:
            out = {
                "teams": conn.execute("SELECT count(*) FROM teams").fetchone()[0],
                "submissions": conn.execute("SELECT count(*) FROM submissions").fetchone()[0],
            }
            for status in ("queued", "running", "scored", "failed"):
                out[status] = conn.execute(
                    "SELECT count(*) FROM submissions WHERE status = ?", (status,)
                ).fetchone()[0]
        return out

    def results(self, submission_id: int) -> dict[str, dict[str, Any]]:
        """A submission's results: evaluator name -> ``EvaluationResult.to_dict()``."""
        with self.read() as conn:
            rows = conn.execute(
                "SELECT evaluator, result FROM results WHERE submission_id = ? ORDER BY evaluator",
                (submission_id,),
            ).fetchall()
        return {r["evaluator"]: json.loads(r["result"]) for r in rows}

    def scored(self) -> list[sqlite3.Row]:
        """Every stored result of a scored submission with its submission and team, best
        headline score first per evaluator (ties: earlier submission first)."""
        with self.read() as conn:
            return conn.execute(
                "SELECT r.evaluator, r.evaluator_version, r.score, r.result, s.id AS submission, "
                "s.label, s.created_at, s.filename, t.name AS team FROM results r "
                "JOIN submissions s ON s.id = r.submission_id JOIN teams t ON t.id = s.team_id "
                "WHERE s.status = 'scored' ORDER BY r.evaluator, r.score IS NULL, r.score DESC, "
                "s.created_at, s.id"
            ).fetchall()

    def integrity_check(self) -> str:
        """SQLite's ``PRAGMA integrity_check`` (``"ok"`` for a sound database)."""
        with self.read() as conn:
            return "; ".join(r[0] for r in conn.execute("PRAGMA integrity_check").fetchall())


def _percent(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.1f}%"


def _label_of(metadata: Mapping[str, Any], filename: str) -> str:
    """A submission's label: its metadata ``method`` when that is a usable label, else the file
    name's stem."""
    method = metadata.get("method")
    if isinstance(method, str):
        with contextlib.suppress(BoardError):
            return check_label(method)
    return Path(filename).stem[:LABEL_CHARS] or filename
