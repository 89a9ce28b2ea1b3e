"""The service's limits (:class:`ServiceConfig`) and the per-team rate limit of uploads
(:class:`RateLimiter`).

Imports :mod:`leaderboard.query_checks` (its errors) and, for types only, the board.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING

from .query_checks import BoardError

if TYPE_CHECKING:
    from .board import Board, Team

MIB = 1 << 20


@dataclass(frozen=True)
class ServiceConfig:
    """Limits of the service.

    Attributes:
        max_upload_bytes: largest upload (bytes); also bounded by the board's file limit.
        rate_limit: uploads a team may make per ``rate_window_s`` (refused and failed ones
            count).
        rate_window_s: the rate limit's sliding window (s).
        header_timeout_s: time for a request's line and headers to arrive (s).
        max_header_bytes: largest request line and headers (bytes; more: 431).
        body_idle_timeout_s: longest pause between two chunks of an upload's body (s).
        upload_timeout_s: longest time to receive an upload's body (s).
        shutdown_timeout_s: on SIGTERM, time given to requests in flight before they are
            abandoned (s).
    """

    max_upload_bytes: int = 64 * MIB
    rate_limit: int = 10
    rate_window_s: float = 3600.0
    header_timeout_s: float = 10.0
    max_header_bytes: int = 32 * 1024
    body_idle_timeout_s: float = 30.0
    upload_timeout_s: float = 600.0
    shutdown_timeout_s: float = 5.0

    def __post_init__(self) -> None:
        if self.max_upload_bytes < 1 or self.rate_limit < 1 or not self.rate_window_s > 0:
            raise BoardError(
                "service: expected a positive upload limit, rate limit and window, found "
                f"{self.max_upload_bytes}, {self.rate_limit}, {self.rate_window_s}"
            )
        timeouts = (
            self.header_timeout_s,
            self.body_idle_timeout_s,
            self.upload_timeout_s,
            self.shutdown_timeout_s,
        )
        if not all(t > 0 for t in timeouts) or self.max_header_bytes < 1024:
            raise BoardError(
                "service: expected positive timeouts and a header limit of at least 1024 "
                f"bytes, found timeouts {timeouts} and {self.max_header_bytes} bytes"
            )


class RateLimiter:
    """Per-team sliding-window counter of uploads (thread-safe).

    A team's window starts from its submissions stored in the board (so a restart forgets only
    refused uploads), then counts every upload that passed the limiter in this process.
    """

    def __init__(self, board: Board, limit: int, window_s: float):
        self.board, self.limit, self.window_s = board, limit, window_s
        self._times: dict[int, deque[float]] = {}
        self._lock = threading.Lock()

    def admit(self, team: Team) -> float | None:
        """Count an upload; None when admitted, else seconds until the next is allowed."""
        now = time.time()
        with self._lock:
            times = self._times.get(team.id)
            if times is None:
                times = deque(self.board.submission_times(team, now - self.window_s))
                self._times[team.id] = times
            while times and times[0] <= now - self.window_s:
                times.popleft()
            if len(times) >= self.limit:
                return max(1.0, times[0] + self.window_s - now)
            times.append(now)
            return None
