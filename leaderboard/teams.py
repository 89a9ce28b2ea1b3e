"""Teams and their tokens: made with a name, a token shown once (only its sha256 is stored,
:mod:`leaderboard.tokens`), rotated on request, matched in constant time."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from .query_checks import BoardError, NotFoundError, check_team_name
from .store import Store
from .tokens import find_token, new_token, token_sha256


@dataclass(frozen=True)
class Team:
    """A team: ``id``, ``name`` and creation time (s since the epoch)."""

    id: int
    name: str
    created_at: float


class Teams:
    """The teams of one board.

    Args:
        store: the board's database.
        clock: the time source (s since the epoch).
    """

    def __init__(self, store: Store, clock: Callable[[], float]) -> None:
        self.store, self.clock = store, clock

    def add(self, name: str) -> tuple[Team, str]:
        """A new team and its token (shown once: only its hash is stored).

        Raises:
            BoardError: a bad name, or a team of that name exists.
        """
        check_team_name(name)
        token = new_token()
        now = self.clock()
        with self.store.write() as conn:
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
        with self.store.write() as conn:
            cursor = conn.execute(
                "UPDATE teams SET token_sha256 = ? WHERE name = ?", (token_sha256(token), name)
            )
            if cursor.rowcount != 1:
                raise NotFoundError(f"team: expected an existing team, found {name!r}")
        return token

    def all(self) -> list[Team]:
        """Every team, by creation."""
        with self.store.read() as conn:
            rows = conn.execute("SELECT id, name, created_at FROM teams ORDER BY id").fetchall()
        return [Team(r["id"], r["name"], r["created_at"]) for r in rows]

    def named(self, name: str) -> Team:
        """The team called ``name``.

        Raises:
            NotFoundError: no such team.
        """
        teams = self.all()
        for team in teams:
            if team.name == name:
                return team
        known = ", ".join(t.name for t in teams) or "none yet"
        raise NotFoundError(f"team: expected one of the board's teams ({known}), found {name!r}")

    def authenticate(self, token: str) -> Team | None:
        """The team holding ``token``, or None (constant-time comparison with every hash)."""
        with self.store.read() as conn:
            rows = conn.execute("SELECT id, name, created_at, token_sha256 FROM teams").fetchall()
        return find_token(
            token, [(r["token_sha256"], Team(r["id"], r["name"], r["created_at"])) for r in rows]
        )
