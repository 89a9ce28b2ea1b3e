"""Workers: claim queued submissions, score them with the registered evaluators, store results.

Run any number of them on one board (``dg16m leaderboard worker``). Each claim is a lease that a
background thread renews every third of its length while the evaluators run; a worker killed
mid-scoring (SIGKILL, a crash, a lost machine) stops renewing, its lease expires, and the next
claim by any worker re-queues the job (after ``max_attempts`` claims it is failed with a
message saying so). A worker that lost its lease (it was paused past the deadline) has its
results refused, so every submission is scored once.

What the team sees of a scoring run is its log: when it started, each evaluator's headline and
time, and the error with its traceback when scoring failed.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any, Literal

from dataset_gen.errors import Dg16mError
from dataset_gen.parallel import Backend

from .board import Board, BoardError, Claim

Outcome = Literal["scored", "failed", "lost"]
ERROR_CHARS = 4000
"""Longest error message stored with a failed submission (the log has all of it)."""


@dataclass(frozen=True)
class WorkerOptions:
    """How a worker claims and scores.

    Attributes:
        lease_s: length of a claim's lease (s); renewed every ``lease_s / 3`` while scoring.
        poll_s: wait between looks at an empty queue (s).
        workers: local processes per scoring run (the evaluators' pool).
        backend: ``"local"`` or ``"ray"`` (GSR's trials on a Ray cluster).
        address: Ray address (``auto`` or host:port).
        seed: seed of the confidence intervals.
        max_jobs: stop after this many jobs (None: no limit).
        idle_exit_s: stop after the queue was empty this long (s; None: wait forever).
    """

    lease_s: float = 60.0
    poll_s: float = 1.0
    workers: int = 1
    backend: Backend = "local"
    address: str | None = None
    seed: int = 0
    max_jobs: int | None = None
    idle_exit_s: float | None = None

    def __post_init__(self) -> None:
        for name in ("lease_s", "poll_s"):
            value = getattr(self, name)
            if not value > 0:
                raise BoardError(f"{name}: expected a positive number of seconds, found {value}")
        if self.workers < 1:
            raise BoardError(f"workers: expected >= 1, found {self.workers}")
        if self.max_jobs is not None and self.max_jobs < 1:
            raise BoardError(f"max_jobs: expected >= 1 or None, found {self.max_jobs}")


def worker_name() -> str:
    """``host:pid``: who holds a claim (shown in the events)."""
    return f"{socket.gethostname()}:{os.getpid()}"


def iso_time(seconds: float) -> str:
    """``2026-11-30T06:10:00Z`` (UTC, whole seconds)."""
    return datetime.fromtimestamp(seconds, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


class _Heartbeat(threading.Thread):
    """Renews a claim's lease every ``lease_s / 3`` until stopped; records a lost lease."""

    def __init__(self, board: Board, claim: Claim, lease_s: float):
        super().__init__(name=f"lease-{claim.submission_id}", daemon=True)
        self.board, self.claim, self.lease_s = board, claim, lease_s
        self.stopped = threading.Event()
        self.lost = False

    def run(self) -> None:
        while not self.stopped.wait(self.lease_s / 3):
            if not self.board.renew(self.claim, self.lease_s):
                self.lost = True
                return


class _Log:
    """The scoring log: timestamped lines."""

    def __init__(self, clock: Callable[[], float]):
        self.clock = clock
        self.lines: list[str] = []

    def __call__(self, message: str) -> None:
        for line in message.rstrip("\n").splitlines() or [""]:
            self.lines.append(f"{iso_time(self.clock())} {line}")

    @property
    def text(self) -> str:
        return "\n".join(self.lines) + "\n"


def score_claim(board: Board, claim: Claim, options: WorkerOptions) -> Outcome:
    """Score a claimed submission and store the outcome.

    Input problems (a :class:`~dataset_gen.errors.Dg16mError`, e.g. a file that no longer
    validates) fail the submission with their message; any other exception is a bug or a
    broken environment: it fails the submission with its traceback in the log, and is printed
    on stderr for the board's operator.

    Returns:
        ``"scored"``, ``"failed"``, or ``"lost"`` when the lease was lost meanwhile (nothing
        stored; another worker scores it).
    """
    from dg16m_env.evaluators import submission_evaluators
    from dg16m_env.evaluators.result import format_rate

    log = _Log(board.clock)
    log(f"claimed by {claim.worker} (attempt {claim.attempt})")
    heartbeat = _Heartbeat(board, claim, options.lease_s)
    heartbeat.start()
    results: dict[str, Any] = {}
    error: str | None = None
    try:
        row = board.submission_row(claim.submission_id)
        names = json.loads(row["evaluators"])
        path = board.file_path(row["file_sha256"])
        ref = board.benchmark_ref()
        log(f"benchmark {ref.sha256[:12]} ({len(ref.object_ids)} objects); file {path.name}")
        evaluators = submission_evaluators(
            names,
            ref,
            workers=options.workers,
            backend=options.backend,
            address=options.address,
            seed=options.seed,
        )
        for name, evaluator in evaluators.items():
            log(f"{name} v{evaluator.version}: scoring")
            started = time.perf_counter()
            result = evaluator.evaluate(path)
            results[name] = result
            headline = format_rate(result.metrics.get(result.headline))
            log(f"{name}: {result.headline} {headline} in {time.perf_counter() - started:.1f} s")
            if result.failures:
                log(f"{name}: {len(result.failures)} objects could not be scored (counted as 0)")
    except Dg16mError as exc:
        error = (str(exc) or type(exc).__name__)[:ERROR_CHARS]
        log(f"error: {exc}")
    except Exception as exc:  # a bug or a broken environment: recorded, shown, not hidden
        error = f"internal error while scoring: {type(exc).__name__}: {exc}"
        log(traceback.format_exc())
        print(f"worker {claim.worker}, submission #{claim.submission_id}:", file=sys.stderr)
        traceback.print_exc()
    finally:
        heartbeat.stopped.set()
        heartbeat.join()
    if error is None:
        log("scored")
        stored = board.finish(claim, results, log.text)
    else:
        stored = board.fail(claim, error, log.text)
    if not stored:
        return "lost"
    return "scored" if error is None else "failed"


def run_worker(
    board: Board,
    options: WorkerOptions = WorkerOptions(),
    *,
    name: str | None = None,
    stop: threading.Event | None = None,
    report: Callable[[str], None] = print,
) -> int:
    """Claim and score jobs until ``stop`` is set, ``max_jobs`` were done or the queue stayed
    empty ``idle_exit_s``; returns the number of jobs taken."""
    name = name or worker_name()
    stop = stop or threading.Event()
    done = 0
    idle_since = time.monotonic()
    while not stop.is_set():
        claim = board.claim(name, options.lease_s)
        if claim is None:
            idle = time.monotonic() - idle_since
            if options.idle_exit_s is not None and idle >= options.idle_exit_s:
                break
            stop.wait(options.poll_s)
            continue
        report(f"#{claim.submission_id}: claimed (attempt {claim.attempt})")
        outcome = score_claim(board, claim, options)
        report(f"#{claim.submission_id}: {outcome}")
        done += 1
        idle_since = time.monotonic()
        if options.max_jobs is not None and done >= options.max_jobs:
            break
    return done
