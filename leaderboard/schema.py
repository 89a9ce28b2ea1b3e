"""The leaderboard database schema and its versioned migrations (SQLite).

The schema version is SQLite's ``PRAGMA user_version``. :func:`migrate` applies every migration
above the file's version in order, each in its own ``BEGIN IMMEDIATE`` transaction together
with the new version number, so a migration is applied completely or not at all, and two
processes opening the same file never both apply one.

History
-------
1. The local board: ``settings`` (key -> JSON value: the benchmark the board scores against,
   its default evaluators, its title), ``teams`` (name, sha256 of the token, never the token),
   ``submissions`` (team, file sha256, size, file name, label, evaluators, time, status,
   error, scoring log) and ``results`` (one row per submission and evaluator: the
   :class:`~dg16m_env.evaluators.EvaluationResult` as JSON, with its headline score).
2. The service's queue: ``jobs`` (one per submission: state, attempts, the worker holding it,
   the claim id and the lease deadline) and ``events`` (every state change, with time, worker
   and message). Submissions of a version-1 board that were queued or running become queued
   jobs; every existing submission gets an event saying it predates the queue.
3. Tracks: ``submissions.track`` (``'mesh'``: the predictor saw the object's mesh, or
   ``'cloud'``: only the benchmark's depth cameras, from the file's metadata ``track``) and
   ``submissions.provenance`` (the file's ``track`` object as JSON, NULL when it had none).
   Every submission of an older board is mesh-track (no submission before had a track).

All times are seconds since the Unix epoch (UTC).
"""

from __future__ import annotations

import sqlite3
from dataclasses import dataclass

from dg16m_core.errors import Dg16mError


class SchemaError(Dg16mError, RuntimeError):
    """A database this version of dg16m cannot use (newer schema, not a leaderboard)."""


@dataclass(frozen=True)
class Migration:
    """One schema step: ``version`` is the schema version after ``sql`` ran."""

    version: int
    summary: str
    sql: str


MIGRATIONS: tuple[Migration, ...] = (
    Migration(
        1,
        "teams, submissions and results (the local board)",
        """
        CREATE TABLE settings (
            key   TEXT PRIMARY KEY,
            value TEXT NOT NULL                     -- JSON
        );
        CREATE TABLE teams (
            id           INTEGER PRIMARY KEY,
            name         TEXT NOT NULL UNIQUE,
            token_sha256 TEXT NOT NULL UNIQUE,      -- hex sha256 of the token
            created_at   REAL NOT NULL
        );
        CREATE TABLE submissions (
            id          INTEGER PRIMARY KEY,
            team_id     INTEGER NOT NULL REFERENCES teams(id),
            file_sha256 TEXT NOT NULL,              -- the stored file: files/<aa>/<sha256>.h5
            size        INTEGER NOT NULL,           -- bytes
            filename    TEXT NOT NULL,              -- as uploaded (display only, never a path)
            label       TEXT NOT NULL,
            evaluators  TEXT NOT NULL,              -- JSON list of names
            created_at  REAL NOT NULL,
            status      TEXT NOT NULL
                        CHECK (status IN ('queued', 'running', 'scored', 'failed')),
            error       TEXT,
            log         TEXT NOT NULL DEFAULT ''
        );
        CREATE INDEX submissions_by_team ON submissions (team_id, created_at);
        CREATE TABLE results (
            submission_id     INTEGER NOT NULL REFERENCES submissions(id),
            evaluator         TEXT NOT NULL,
            evaluator_version TEXT NOT NULL,
            score             REAL,                 -- the headline rate (NULL: nothing scored)
            result            TEXT NOT NULL,        -- EvaluationResult.to_dict() as JSON
            created_at        REAL NOT NULL,
            PRIMARY KEY (submission_id, evaluator)
        );
        """,
    ),
    Migration(
        2,
        "the service's queue: jobs with leases, and every state change as an event",
        """
        CREATE TABLE jobs (
            submission_id    INTEGER PRIMARY KEY REFERENCES submissions(id),
            state            TEXT NOT NULL CHECK (state IN ('queued', 'running', 'done')),
            attempts         INTEGER NOT NULL DEFAULT 0,
            worker           TEXT,
            claim            TEXT,                  -- id of the current claim (a lease)
            lease_expires_at REAL,
            queued_at        REAL NOT NULL,
            updated_at       REAL NOT NULL
        );
        CREATE INDEX jobs_by_state ON jobs (state, queued_at);
        CREATE TABLE events (
            id            INTEGER PRIMARY KEY,
            submission_id INTEGER NOT NULL REFERENCES submissions(id),
            at            REAL NOT NULL,
            state         TEXT NOT NULL,
            worker        TEXT,
            message       TEXT NOT NULL
        );
        CREATE INDEX events_by_submission ON events (submission_id, id);
        UPDATE submissions SET status = 'queued' WHERE status = 'running';
        INSERT INTO jobs (submission_id, state, queued_at, updated_at)
            SELECT id, CASE WHEN status = 'queued' THEN 'queued' ELSE 'done' END,
                   created_at, created_at
            FROM submissions;
        INSERT INTO events (submission_id, at, state, message)
            SELECT id, created_at, status, 'recorded before the queue existed (schema 1)'
            FROM submissions;
        """,
    ),
    Migration(
        3,
        "tracks: each submission's track (mesh or cloud) and its self-declared provenance",
        """
        ALTER TABLE submissions ADD COLUMN track TEXT NOT NULL DEFAULT 'mesh'
            CHECK (track IN ('mesh', 'cloud'));
        ALTER TABLE submissions ADD COLUMN provenance TEXT;   -- JSON object, or NULL
        CREATE INDEX submissions_by_track ON submissions (track, status);
        """,
    ),
)
SCHEMA_VERSION = MIGRATIONS[-1].version
"""The schema version this code writes."""


def schema_version(conn: sqlite3.Connection) -> int:
    """The database's schema version (0 for an empty file)."""
    return int(conn.execute("PRAGMA user_version").fetchone()[0])


def migrate(conn: sqlite3.Connection, target: int = SCHEMA_VERSION) -> list[int]:
    """Bring the database to schema ``target``; returns the versions applied (maybe none).

    ``conn`` must be in autocommit mode (``isolation_level=None``).

    Raises:
        SchemaError: the database is newer than this code, or is not a leaderboard.
    """
    if not 0 <= target <= SCHEMA_VERSION:
        raise SchemaError(f"target: expected 0..{SCHEMA_VERSION}, found {target}")
    applied: list[int] = []
    for step in MIGRATIONS:
        if step.version > target:
            break
        conn.execute("BEGIN IMMEDIATE")
        try:
            current = schema_version(conn)
            if current > SCHEMA_VERSION:
                raise SchemaError(
                    f"expected a leaderboard database of schema version <= {SCHEMA_VERSION}, "
                    f"found {current}: it was written by a newer dg16m (upgrade dg16m)"
                )
            if current == 0 and step.version == 1 and _has_foreign_tables(conn):
                raise SchemaError(
                    "expected an empty file or a dg16m leaderboard database, found another "
                    "SQLite database (tables but no schema version)"
                )
            if current >= step.version:
                conn.execute("ROLLBACK")
                continue
            for statement in _statements(step.sql):
                conn.execute(statement)
            conn.execute(f"PRAGMA user_version = {int(step.version)}")
            conn.execute("COMMIT")
        except BaseException:
            if conn.in_transaction:
                conn.execute("ROLLBACK")
            raise
        applied.append(step.version)
    return applied


def _has_foreign_tables(conn: sqlite3.Connection) -> bool:
    return conn.execute("SELECT count(*) FROM sqlite_master").fetchone()[0] > 0


def _statements(sql: str) -> list[str]:
    """The statements of a migration script (``executescript`` would commit the transaction);
    ``--`` comments are dropped, and no statement of ours has a ``;`` inside a string."""
    lines = [line.split("--", 1)[0] for line in sql.splitlines()]
    return [s.strip() for s in "\n".join(lines).split(";") if s.strip()]
