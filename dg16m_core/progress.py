"""Progress bars every dg16m command uses: a tqdm bar on a terminal, plain lines in a log.

On a terminal (stderr is a tty) :func:`progress_bar` is an ordinary tqdm bar. Anywhere else (a
log file, a pipe, CI, ``nohup``) tqdm would write thousands of carriage-return updates into the
file; there the bar is a :class:`LineProgress`, which writes one plain line (no ``\\r``) at most
every :data:`LOG_INTERVAL_S` seconds, and a last line when it closes::

    generate: 12/40 object (30%), 0:25 elapsed, 0.48 object/s, ~0:58 left

Both kinds take the same calls (iteration, ``update``, ``set_postfix``, ``set_description``,
``write``, ``close``, ``with``), so a call site does not care which one it got. ``enabled=False``
gives a bar that shows nothing (``--no-progress``). Write a message between updates with
:func:`progress_write` (it keeps a terminal bar intact).
"""

from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Iterable, Iterator
from typing import IO, Any

LOG_INTERVAL_S = 5.0
"""Seconds between two lines of a :class:`LineProgress` (the last line comes on close)."""


def is_terminal(stream: IO[str] | None = None) -> bool:
    """Whether ``stream`` (default: stderr) is an interactive terminal."""
    stream = sys.stderr if stream is None else stream
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty is not None and isatty())
    except ValueError:  # a closed stream
        return False


def progress_bar(
    iterable: Iterable[Any] | None = None,
    *,
    total: float | None = None,
    desc: str = "",
    unit: str = "it",
    enabled: bool = True,
    initial: float = 0,
    leave: bool = True,
    stream: IO[str] | None = None,
    interval: float = LOG_INTERVAL_S,
    **tqdm_options: Any,
) -> Any:
    """A progress bar over ``iterable`` (or advanced with ``update``), on ``stream`` (stderr).

    Args:
        iterable: what to iterate over (its length is the total unless ``total`` is given).
        total: the number of units expected (None: unknown).
        desc, unit: the bar's label and the name of one unit.
        enabled: False gives a bar that shows nothing.
        initial: units already done (a resumed run).
        leave: keep the bar (the last line in a log) when it closes.
        stream: where the bar goes (default: stderr).
        interval: seconds between two lines when ``stream`` is not a terminal.
        tqdm_options: further tqdm options, used on a terminal only (e.g. ``smoothing``).

    Returns:
        a tqdm bar on a terminal, a :class:`LineProgress` elsewhere, a silent tqdm bar if not
        ``enabled``.
    """
    from tqdm import tqdm

    if not enabled:
        return tqdm(iterable, total=total, disable=True)
    if is_terminal(stream):
        return tqdm(
            iterable,
            total=total,
            desc=desc,
            unit=unit,
            initial=initial,
            leave=leave,
            file=stream,
            **tqdm_options,
        )
    return LineProgress(
        iterable,
        total=total,
        desc=desc,
        unit=unit,
        initial=initial,
        leave=leave,
        stream=stream,
        interval=interval,
    )


def progress_write(message: str, file: IO[str] | None = None) -> None:
    """Print ``message`` (default: to stdout) without breaking a terminal progress bar."""
    from tqdm import tqdm

    tqdm.write(message, file=file)


def format_seconds(seconds: float) -> str:
    """``m:ss`` or ``h:mm:ss``."""
    if not math.isfinite(seconds):
        return "?"
    minutes, secs = divmod(round(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"


class LineProgress:
    """A progress bar for logs: one plain line at most every ``interval`` seconds, and one when
    it closes (if ``leave``); never a carriage return. The calls are tqdm's."""

    disable = False

    def __init__(
        self,
        iterable: Iterable[Any] | None = None,
        *,
        total: float | None = None,
        desc: str = "",
        unit: str = "it",
        initial: float = 0,
        leave: bool = True,
        stream: IO[str] | None = None,
        interval: float = LOG_INTERVAL_S,
    ) -> None:
        if total is None and iterable is not None and hasattr(iterable, "__len__"):
            total = len(iterable)  # type: ignore[arg-type]
        self.iterable = iterable
        self.total = total
        self.desc = desc
        self.unit = unit
        self.n = initial
        self.initial = initial
        self.leave = leave
        self.stream = stream
        self.interval = float(interval)
        self.postfix = ""
        self.lines = 0
        """The lines written so far."""
        self.closed = False
        self._start = time.monotonic()
        self._last = self._start
        self._lock = threading.Lock()

    # -- tqdm's calls ----------------------------------------------------------------------
    def __iter__(self) -> Iterator[Any]:
        if self.iterable is None:
            raise TypeError("LineProgress: expected an iterable to iterate over, found None")
        try:
            for item in self.iterable:
                yield item
                self.update(1)
        finally:
            self.close()

    def __len__(self) -> int:
        return int(self.total or 0)

    def __enter__(self) -> LineProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def update(self, n: float = 1) -> None:
        """Advance by ``n`` units; writes a line if ``interval`` seconds passed since the last."""
        with self._lock:
            self.n += n
            now = time.monotonic()
            finished = self.total is not None and self.n >= self.total  # close() says it
            if now - self._last >= self.interval and not self.closed and not finished:
                self._emit(now)

    def refresh(self) -> None:
        """Write a line now."""
        with self._lock:
            if not self.closed:
                self._emit(time.monotonic())

    def set_postfix(
        self, ordered_dict: dict[str, Any] | None = None, refresh: bool = True, **kwargs: Any
    ) -> None:
        """Values shown after the counts (``failed=2``); shown with the next line."""
        values = {**(ordered_dict or {}), **kwargs}
        self.postfix = ", ".join(f"{k}={v}" for k, v in values.items())

    def set_description(self, desc: str | None = None, refresh: bool = True) -> None:
        self.desc = desc or ""

    def clear(self, nolock: bool = False) -> None:
        """Nothing to clear in a log."""

    def close(self) -> None:
        """The last line (if ``leave``, and unless the bar stopped before any progress, e.g.
        at an error: the error is the news); later calls do nothing."""
        with self._lock:
            if self.closed:
                return
            done = self.total is not None and self.n >= self.total
            if self.leave and (self.n > self.initial or done):
                self._emit(time.monotonic(), final=True)
            self.closed = True

    @staticmethod
    def write(
        message: str, file: IO[str] | None = None, end: str = "\n", nolock: bool = False
    ) -> None:
        """Print ``message`` (default: to stdout), as ``tqdm.write`` does."""
        out = sys.stdout if file is None else file
        out.write(message + end)
        out.flush()

    # -- the line ---------------------------------------------------------------------------
    def line(self, now: float | None = None, final: bool = False) -> str:
        """The text of one line: counts, elapsed time, rate and (while running) time left."""
        elapsed = (time.monotonic() if now is None else now) - self._start
        done = self.n - self.initial
        rate = done / elapsed if elapsed > 0 else float("nan")
        n = f"{self.n:g}"
        if self.total:
            counts = f"{n}/{self.total:g} {self.unit} ({100.0 * self.n / self.total:.0f}%)"
        else:
            counts = f"{n} {self.unit}"
        parts = [counts, f"{format_seconds(elapsed)} elapsed"]
        if math.isfinite(rate) and done > 0:
            speed = f"{rate:.3g} {self.unit}/s" if rate >= 1 else f"{1 / rate:.3g} s/{self.unit}"
            parts.append(speed)
            if self.total and not final and rate > 0:
                parts.append(f"~{format_seconds((self.total - self.n) / rate)} left")
        if final:
            parts.append("done" if self.total is None or self.n >= self.total else "stopped")
        if self.postfix:
            parts.append(self.postfix)
        label = f"{self.desc}: " if self.desc else ""
        return label + ", ".join(parts)

    def _emit(self, now: float, final: bool = False) -> None:
        out = sys.stderr if self.stream is None else self.stream
        try:
            out.write(self.line(now, final) + "\n")
            out.flush()
        except (ValueError, OSError):  # a closed or broken stream: progress is not worth an error
            return
        self._last = now
        self.lines += 1


__all__ = [
    "LOG_INTERVAL_S",
    "LineProgress",
    "format_seconds",
    "is_terminal",
    "progress_bar",
    "progress_write",
]
