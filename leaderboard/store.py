"""The board's SQLite database: connections, transactions and settings.

A board is one SQLite file in WAL mode (schema and migrations in :mod:`leaderboard.schema`).
Any number of processes may open it at once (the service, several workers, the command line):
each opens its own short-lived connections, every write is one ``BEGIN IMMEDIATE``
transaction, and a reader sees one consistent snapshot inside a ``with store.read()`` block.
"""

from __future__ import annotations

import contextlib
import json
import os
import sqlite3
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from .schema import migrate

BUSY_TIMEOUT_MS = 30_000
"""How long a connection waits for another process's write lock before it gives up."""


class Store:
    """Connections to one board's database (made, with its folder, when absent; migrated to
    the current schema when older).

    Args:
        db: the database file.

    Raises:
        SchemaError: a database of a newer dg16m, or not a leaderboard.
    """

    def __init__(self, db: str | os.PathLike[str]) -> None:
        self.db = Path(db)
        self.db.parent.mkdir(parents=True, exist_ok=True)
        with contextlib.closing(self.connect()) as conn:
            conn.execute("PRAGMA journal_mode=WAL")
            migrate(conn)

    def connect(self) -> sqlite3.Connection:
        """A new connection in autocommit mode (rows as :class:`sqlite3.Row`)."""
        conn = sqlite3.connect(self.db, isolation_level=None, timeout=BUSY_TIMEOUT_MS / 1000)
        conn.row_factory = sqlite3.Row
        conn.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
        conn.execute("PRAGMA foreign_keys = ON")
        conn.execute("PRAGMA synchronous = NORMAL")  # WAL: durable at checkpoints, never corrupt
        return conn

    @contextlib.contextmanager
    def read(self) -> Iterator[sqlite3.Connection]:
        """A connection for reads (a consistent snapshot inside one ``with``)."""
        with contextlib.closing(self.connect()) as conn:
            conn.execute("BEGIN")
            try:
                yield conn
            finally:
                conn.execute("ROLLBACK")

    @contextlib.contextmanager
    def write(self) -> Iterator[sqlite3.Connection]:
        """A connection inside one ``BEGIN IMMEDIATE`` transaction: committed when the block
        ends, rolled back when it raises."""
        with contextlib.closing(self.connect()) as conn:
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

    def add_settings(self, values: Mapping[str, Any]) -> None:
        """Store settings that are not set yet (a set one is kept: the first writer wins)."""
        with self.write() as conn:
            for key, value in values.items():
                conn.execute(
                    "INSERT OR IGNORE INTO settings (key, value) VALUES (?, ?)",
                    (key, json.dumps(value)),
                )

    def integrity_check(self) -> str:
        """SQLite's ``PRAGMA integrity_check`` (``"ok"`` for a sound database)."""
        with self.read() as conn:
            return "; ".join(r[0] for r in conn.execute("PRAGMA integrity_check").fetchall())
