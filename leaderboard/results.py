"""Reading a board for its views: submissions' rows, counts, results, and the scored rows
ranked per track and evaluator (a page at a time; tracks are never ranked together).

Every id that comes in is checked (:func:`~leaderboard.query_checks.check_id`) before it reaches
SQLite, so an id past SQLite's 64-bit integers is "not found", never an overflow.
"""

from __future__ import annotations

import json
import sqlite3
from typing import Any

from .query_checks import ForbiddenError, NotFoundError, check_id
from .store import Store
from .teams import Team
from .tracks import check_track

STATUSES = ("queued", "running", "scored", "failed")
"""A submission's states (see :mod:`leaderboard.queue`)."""
_SUBMISSIONS = (
    "SELECT s.*, t.name AS team, j.state AS job_state, j.attempts, j.worker, "
    "j.lease_expires_at FROM submissions s JOIN teams t ON t.id = s.team_id "
    "LEFT JOIN jobs j ON j.submission_id = s.id"
)
"""A submission's row with its team's name and its job (see :meth:`Results.submission_row`)."""
_SCORED = (
    "SELECT s.track, r.evaluator, r.evaluator_version, r.score, r.result, s.id AS submission, "
    "s.label, s.created_at, s.filename, s.provenance, t.name AS team, "
    "RANK() OVER (PARTITION BY s.track, r.evaluator ORDER BY r.score IS NULL, r.score DESC) "
    "AS rank FROM results r JOIN submissions s ON s.id = r.submission_id "
    "JOIN teams t ON t.id = s.team_id WHERE s.status = 'scored'"
)
"""Scored results with their competition rank per track and evaluator (equal scores share a
rank; a mesh-track and a cloud-track result are never ranked against each other)."""
_ORDER = (
    " ORDER BY CASE track WHEN 'mesh' THEN 0 ELSE 1 END, track, evaluator, score IS NULL, "
    "score DESC, created_at, submission"
)


class Results:
    """The read side of one board.

    Args:
        store: the board's database.
    """

    def __init__(self, store: Store) -> None:
        self.store = store

    def submission_row(self, submission_id: int) -> sqlite3.Row:
        """The submission's row joined with its team's name and its job.

        Raises:
            NotFoundError: no such submission (or not an id at all).
        """
        sid = check_id(submission_id)
        with self.store.read() as conn:
            row = conn.execute(_SUBMISSIONS + " WHERE s.id = ?", (sid,)).fetchone()
        if row is None:
            raise NotFoundError(f"submission: expected an existing id, found #{sid}")
        return row

    def submissions(self, team: Team | None = None) -> list[sqlite3.Row]:
        """Submissions (of one team, or all), newest first, as :meth:`submission_row`."""
        query = _SUBMISSIONS
        args: tuple[Any, ...] = ()
        if team is not None:
            query += " WHERE s.team_id = ?"
            args = (team.id,)
        with self.store.read() as conn:
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
                f"submission #{row['id']}: expected one of team {team.name!r}'s "
                "submissions, found another team's (only its team may see its details)"
            )
        return row

    def submission_times(self, team: Team, since: float) -> list[float]:
        """Times of the team's submissions at or after ``since`` (the rate limiter's memory)."""
        with self.store.read() as conn:
            rows = conn.execute(
                "SELECT created_at FROM submissions WHERE team_id = ? AND created_at >= ? "
                "ORDER BY created_at",
                (team.id, since),
            ).fetchall()
        return [float(r["created_at"]) for r in rows]

    def references(self, sha256: str) -> bool:
        """Whether a stored submission refers to the file with this hash."""
        with self.store.read() as conn:
            row = conn.execute(
                "SELECT 1 FROM submissions WHERE file_sha256 = ? LIMIT 1", (sha256,)
            ).fetchone()
        return row is not None

    def referenced_files(self) -> set[str]:
        """The hashes of every file a stored submission refers to."""
        with self.store.read() as conn:
            rows = conn.execute("SELECT DISTINCT file_sha256 FROM submissions").fetchall()
        return {r[0] for r in rows}

    def counts(self) -> dict[str, int]:
        """Teams, submissions, and submissions per status."""
        with self.store.read() as conn:
            out = {
                "teams": conn.execute("SELECT count(*) FROM teams").fetchone()[0],
                "submissions": conn.execute("SELECT count(*) FROM submissions").fetchone()[0],
            }
            for status in STATUSES:
                out[status] = conn.execute(
                    "SELECT count(*) FROM submissions WHERE status = ?", (status,)
                ).fetchone()[0]
        return out

    def results(self, submission_id: int) -> dict[str, dict[str, Any]]:
        """A submission's results: evaluator name -> ``EvaluationResult.to_dict()``."""
        sid = check_id(submission_id)
        with self.store.read() as conn:
            rows = conn.execute(
                "SELECT evaluator, result FROM results WHERE submission_id = ? ORDER BY evaluator",
                (sid,),
            ).fetchall()
        return {r["evaluator"]: json.loads(r["result"]) for r in rows}

    def scored(self) -> list[sqlite3.Row]:
        """Every stored result of a scored submission with its submission, team, track and
        rank (within its track and evaluator), mesh track first, best headline score first per
        track and evaluator (ties: earlier submission first)."""
        with self.store.read() as conn:
            return conn.execute(f"SELECT * FROM ({_SCORED}){_ORDER}").fetchall()

    def scored_totals(self, *, track: str) -> dict[str, int]:
        """Scored results of one track per evaluator (the rows of each evaluator's table in
        that track).

        Raises:
            InvalidParameterError: an unknown track.
        """
        track = check_track(track)
        with self.store.read() as conn:
            rows = conn.execute(
                "SELECT r.evaluator, count(*) AS n FROM results r "
                "JOIN submissions s ON s.id = r.submission_id "
                "WHERE s.status = 'scored' AND s.track = ? GROUP BY r.evaluator",
                (track,),
            ).fetchall()
        return {r["evaluator"]: int(r["n"]) for r in rows}

    def scored_page(
        self, evaluator: str, offset: int, limit: int, *, track: str
    ) -> list[sqlite3.Row]:
        """Rows ``offset .. offset + limit`` of one evaluator's ranked results in one track (as
        :meth:`scored`; ranks count every row of the track before the page).

        Raises:
            InvalidParameterError: an unknown track.
        """
        track = check_track(track)
        with self.store.read() as conn:
            return conn.execute(
                f"SELECT * FROM ({_SCORED} AND r.evaluator = ? AND s.track = ?){_ORDER} "
                "LIMIT ? OFFSET ?",
                (evaluator, track, limit, offset),
            ).fetchall()
