"""The queue of scoring jobs: one job per submission, claimed by workers with leases.

Life of a submission::

    submit -> queued -> running (claimed by a worker, with a lease) -> scored | failed
                 ^__________|  lease expired (worker died): re-queued, or failed after
                               ``max_attempts`` claims

A claim is a lease with a deadline that the worker renews while it scores
(:meth:`Queue.renew`). A claim whose deadline passed is re-queued by the next
:meth:`Queue.claim` (or :meth:`Queue.requeue_stale`), with an event saying whose lease
expired; results are accepted only from the current claim (:meth:`Queue.finish`), so a
submission is scored once even when a worker that lost its lease comes back. Every state
change is an event (:meth:`Queue.events`).
"""

from __future__ import annotations

import json
import math
import sqlite3
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from .query_checks import BoardError, DuplicateError, check_id
from .store import Store


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
class NewSubmission:
    """What :meth:`Queue.enqueue` records of a validated, stored submission file."""

    team_id: int
    team_name: str
    sha256: str
    size: int
    filename: str
    label: str
    evaluators: list[str]
    track: str = "mesh"
    provenance: str | None = None  # the file's metadata "track" object as JSON


class Queue:
    """The jobs of one board.

    Args:
        store: the board's database.
        clock: the time source (s since the epoch).
        max_attempts: claims of one job before it is failed (workers keep dying on it).
    """

    def __init__(self, store: Store, clock: Callable[[], float], max_attempts: int) -> None:
        if max_attempts < 1:
            raise BoardError(f"max_attempts: expected >= 1, found {max_attempts}")
        self.store, self.clock, self.max_attempts = store, clock, max_attempts

    # -- submissions in ----------------------------------------------------------------------

    def duplicate(self, team_id: int, sha256: str, names: list[str]) -> int | None:
        """The team's earlier submission of the same file for the same evaluators (not failed),
        or None."""
        with self.store.read() as conn:
            return _duplicate(conn, team_id, sha256, names)

    def enqueue(self, new: NewSubmission) -> int:
        """Record a submission and queue its job (one transaction); returns its id.

        Raises:
            DuplicateError: a concurrent twin was recorded first.
        """
        now = self.clock()
        with self.store.write() as conn:
            same = _duplicate(conn, new.team_id, new.sha256, new.evaluators)
            if same is not None:
                raise DuplicateError(f"submission: already submitted as #{same}", same)
            cursor = conn.execute(
                "INSERT INTO submissions (team_id, file_sha256, size, filename, label, "
                "evaluators, created_at, status, track, provenance) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, 'queued', ?, ?)",
                (
                    new.team_id,
                    new.sha256,
                    new.size,
                    new.filename,
                    new.label,
                    json.dumps(new.evaluators),
                    now,
                    new.track,
                    new.provenance,
                ),
            )
            sid = int(cursor.lastrowid or 0)
            conn.execute(
                "INSERT INTO jobs (submission_id, state, queued_at, updated_at) "
                "VALUES (?, 'queued', ?, ?)",
                (sid, now, now),
            )
            self._event(
                conn,
                sid,
                "queued",
                None,
                f"submitted by {new.team_name}: {new.filename} ({new.track} track)",
            )
        return sid

    # -- claims and leases -------------------------------------------------------------------

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
        with self.store.write() as conn:
            return self._requeue_stale(conn, self.clock())

    def claim(self, worker: str, lease_s: float, submission_id: int | None = None) -> Claim | None:
        """Claim the oldest queued job (or the given submission's, if queued) for ``lease_s``.

        Expired leases are re-queued first, so a job left by a dead worker is claimed again.

        Returns:
            The claim, or None when nothing is queued.
        """
        if not (math.isfinite(lease_s) and lease_s > 0):
            raise BoardError(f"lease_s: expected a positive number of seconds, found {lease_s}")
        if submission_id is not None:
            submission_id = check_id(submission_id)
        now = self.clock()
        with self.store.write() as conn:
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
        with self.store.write() as conn:
            cursor = conn.execute(
                "UPDATE jobs SET lease_expires_at = ?, updated_at = ? WHERE submission_id = ? "
                "AND claim = ? AND state = 'running' AND lease_expires_at >= ?",
                (now + lease_s, now, claim.submission_id, claim.claim, now),
            )
        return cursor.rowcount == 1

    def holds(self, claim: Claim) -> bool:
        """Whether ``claim`` is still the job's current claim (its results would be taken)."""
        with self.store.read() as conn:
            return _holding(conn, claim)

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
        with self.store.write() as conn:
            if not _holding(conn, claim):
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
            _close(conn, claim, now, "scored", None, log)
            scores = ", ".join(f"{n} {_percent(r.score)}" for n, r in results.items())
            self._event(conn, sid, "scored", claim.worker, scores or "scored")
        return True

    def fail(self, claim: Claim, error: str, log: str) -> bool:
        """Mark a claim's submission failed with ``error``; False when the claim was lost."""
        now = self.clock()
        with self.store.write() as conn:
            if not _holding(conn, claim):
                return False
            _close(conn, claim, now, "failed", error, log)
            self._event(conn, claim.submission_id, "failed", claim.worker, error)
        return True

    # -- reads -------------------------------------------------------------------------------

    def events(self, submission_id: int) -> list[sqlite3.Row]:
        """Every state change of a submission, oldest first."""
        sid = check_id(submission_id)
        with self.store.read() as conn:
            return conn.execute(
                "SELECT at, state, worker, message FROM events WHERE submission_id = ? ORDER BY id",
                (sid,),
            ).fetchall()

    def jobs(self, team_id: int | None = None) -> list[sqlite3.Row]:
        """Jobs not done (queued and running, with their lease deadlines), oldest first; of
        one team when ``team_id`` is given."""
        query = (
            "SELECT j.*, s.label, t.name AS team FROM jobs j "
            "JOIN submissions s ON s.id = j.submission_id JOIN teams t ON t.id = s.team_id "
            "WHERE j.state != 'done'"
        )
        args: tuple[Any, ...] = ()
        if team_id is not None:
            query += " AND s.team_id = ?"
            args = (team_id,)
        with self.store.read() as conn:
            return conn.execute(query + " ORDER BY j.queued_at, j.submission_id", args).fetchall()


def _duplicate(conn: sqlite3.Connection, team_id: int, sha256: str, names: list[str]) -> int | None:
    row = conn.execute(
        "SELECT id FROM submissions WHERE team_id = ? AND file_sha256 = ? AND evaluators = ? "
        "AND status != 'failed'",
        (team_id, sha256, json.dumps(names)),
    ).fetchone()
    return None if row is None else int(row["id"])


def _holding(conn: sqlite3.Connection, claim: Claim) -> bool:
    row = conn.execute(
        "SELECT 1 FROM jobs WHERE submission_id = ? AND claim = ? AND state = 'running'",
        (claim.submission_id, claim.claim),
    ).fetchone()
    return row is not None


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


def _percent(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.1f}%"
