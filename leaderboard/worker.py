"""Workers: claim queued submissions, score them with the registered evaluators, store results.

Run any number of them on one board (``dg16m leaderboard worker``). Each claim is a lease that a
background thread renews every third of its length while the evaluators run; a worker killed
mid-scoring (SIGKILL, a crash, a lost machine) stops renewing, its lease expires, and the next
claim by any worker re-queues the job (after ``max_attempts`` claims it is failed with a
message saying so). A worker that lost its lease (it was paused past the deadline) has its
results refused, so every submission is scored once.

The evaluators run in a scoring process (:class:`Scorer`: forked, kept from job to job, in its
own process group with the evaluators' pool, and killed by the kernel if the worker dies). When
a renewal finds the lease lost, the worker kills that group at once and moves on ("lost"),
rather than scoring to the end for a result that would be refused; the next job gets a fresh
scoring process. One that dies (out of memory, a crash in native code) fails the submission
with its exit status.

What the team sees of a scoring run is its log: when it started, each evaluator's headline and
time, and the error with its traceback when scoring failed.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import multiprocessing
import multiprocessing.connection
import multiprocessing.process
import os
import signal
import socket
import sys
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any, Literal

from dataset_gen.pipeline.parallel import Backend
from dg16m_core.errors import Dg16mError

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
        progress: the evaluators' progress bars (on the scoring process's stderr).
    """

    lease_s: float = 60.0
    poll_s: float = 1.0
    workers: int = 1
    backend: Backend = "local"
    address: str | None = None
    seed: int = 0
    max_jobs: int | None = None
    idle_exit_s: float | None = None
    progress: bool = False

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
    """Renews a claim's lease every ``lease_s / 3`` until stopped; sets :attr:`lost` when a
    renewal finds the claim gone."""

    def __init__(self, board: Board, claim: Claim, lease_s: float):
        super().__init__(name=f"lease-{claim.submission_id}", daemon=True)
        self.board, self.claim, self.lease_s = board, claim, lease_s
        self.stopped = threading.Event()
        self.lost = threading.Event()

    def run(self) -> None:
        while not self.stopped.wait(self.lease_s / 3):
            if not self.board.renew(self.claim, self.lease_s):
                self.lost.set()
                return


class _Log:
    """The scoring log: timestamped lines."""

    def __init__(
        self, clock: Callable[[], float], echo: Callable[[str], None] | None = None
    ) -> None:
        self.clock = clock
        self.echo = echo
        self.lines: list[str] = []

    def __call__(self, message: str) -> None:
        for line in message.rstrip("\n").splitlines() or [""]:
            self.lines.append(f"{iso_time(self.clock())} {line}")
            if self.echo is not None:
                self.echo(self.lines[-1])

    @property
    def text(self) -> str:
        return "\n".join(self.lines) + "\n"


def _die_with_parent(parent: int) -> None:
    """Have the kernel SIGKILL this process when its parent dies (Linux), and stop now if the
    parent is already gone."""
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        pr_set_pdeathsig = 1
        libc.prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0)
    if os.getppid() != parent:
        os._exit(1)


def _scorer_main(
    conn: multiprocessing.connection.Connection,
    workers_end: multiprocessing.connection.Connection,
    ref: Any,
    options: WorkerOptions,
    parent: int,
) -> None:
    """The scoring process: for each job ``(names, path)`` received on ``conn``, score ``path``
    with each evaluator, reporting as it goes: ``("log", line)``, ``("result", name,
    result)``, then ``("error", message, log)`` or ``("done",)``. Ends when the worker closes
    its end of the pipe (``workers_end``, inherited by the fork and closed here first, or the
    end would never be seen)."""
    workers_end.close()
    os.setpgid(0, 0)  # the evaluators' pool joins this group, so one killpg stops them all
    _die_with_parent(parent)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the worker decides when to stop
    from dg16m_env.evaluators import submission_evaluators
    from dg16m_env.evaluators.result import format_rate

    while True:
        try:
            names, path = conn.recv()
        except EOFError:
            return
        try:
            evaluators = submission_evaluators(
                names,
                ref,
                workers=options.workers,
                backend=options.backend,
                address=options.address,
                seed=options.seed,
                progress=options.progress,
            )
            for name, evaluator in evaluators.items():
                conn.send(("log", f"{name} v{evaluator.version}: scoring"))
                started = time.perf_counter()
                result = evaluator.evaluate(path)
                headline = format_rate(result.metrics.get(result.headline))
                took = time.perf_counter() - started
                conn.send(("log", f"{name}: {result.headline} {headline} in {took:.1f} s"))
                if result.failures:
                    count = len(result.failures)
                    conn.send(
                        ("log", f"{name}: {count} objects could not be scored (counted as 0)")
                    )
                conn.send(("result", name, result))
        except Dg16mError as exc:
            conn.send(("error", (str(exc) or type(exc).__name__)[:ERROR_CHARS], f"error: {exc}"))
        except Exception as exc:  # a bug or a broken environment: recorded, shown, not hidden
            text = traceback.format_exc()
            print(f"scoring process {os.getpid()}: {text}", file=sys.stderr)
            message = f"internal error while scoring: {type(exc).__name__}: {exc}"
            conn.send(("error", message[:ERROR_CHARS], text))
        else:
            conn.send(("done",))


class Scorer:
    """A scoring process (forked from this one; its own process group with the evaluators'
    pool), kept for job after job so that what the evaluators load and cache is loaded once,
    and killed with its group when a job must stop (its lease was lost). Use it from one
    thread: the kernel kills the process when the thread that forked it ends
    (``PR_SET_PDEATHSIG``), as it does when the worker dies.

    Args:
        board: the board (its benchmark is loaded when the first job starts).
        options: how to score (workers, backend, seed).
    """

    def __init__(self, board: Board, options: WorkerOptions) -> None:
        self.board, self.options = board, options
        self._proc: multiprocessing.process.BaseProcess | None = None
        self._conn: multiprocessing.connection.Connection | None = None

    def _start(self) -> multiprocessing.connection.Connection:
        if self._proc is not None and self._proc.is_alive() and self._conn is not None:
            return self._conn
        self.close()
        context = multiprocessing.get_context("fork")
        ours, theirs = context.Pipe(duplex=True)
        proc = context.Process(
            target=_scorer_main,
            args=(theirs, ours, self.board.benchmark_ref(), self.options, os.getpid()),
            name="dg16m-scorer",
            daemon=False,
        )
        proc.start()
        with contextlib.suppress(ProcessLookupError, PermissionError):  # the child does it too
            os.setpgid(proc.pid, proc.pid)
        theirs.close()
        self._proc, self._conn = proc, ours
        return ours

    def score(
        self, names: list[str], path: str, log: Callable[[str], None], lost: threading.Event
    ) -> tuple[dict[str, Any], str | None] | None:
        """Score ``path``: (results, error or None), or None when ``lost`` was set meanwhile
        (the process was killed at once)."""
        conn = self._start()
        conn.send((list(names), path))
        results: dict[str, Any] = {}
        while True:
            if lost.is_set():
                self.kill()
                return None
            if not conn.poll(0.2):
                continue
            try:
                message = conn.recv()
            except EOFError:  # the process died without a word
                code = self.kill()
                error = (
                    f"scoring process died with exit status {code} (killed, out of memory or "
                    "a crash in native code)"
                )
                log(f"error: {error}")
                return results, error
            if message[0] == "log":
                log(message[1])
            elif message[0] == "result":
                results[message[1]] = message[2]
            elif message[0] == "error":
                log(message[2])
                return results, message[1]
            else:
                return results, None

    def _release(self) -> multiprocessing.process.BaseProcess | None:
        """Forget the process and close its pipe; the process (None when none was running)."""
        proc, self._proc = self._proc, None
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        return proc

    def kill(self) -> int | None:
        """Kill the process with its group (the evaluators' pool); its exit status."""
        proc = self._release()
        if proc is None:
            return None
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):  # no group (yet): the process alone
            proc.kill()
        proc.join()
        return proc.exitcode

    def close(self) -> int | None:
        """Let the process end (it sees the end of its jobs), or kill it after 30 s; its exit
        status (0: it ended by itself), None when none was running."""
        proc = self._release()
        if proc is None:
            return None
        proc.join(30)
        if proc.is_alive():
            self._proc = proc
            return self.kill()
        return proc.exitcode

    def __enter__(self) -> Scorer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def score_claim(
    board: Board,
    claim: Claim,
    options: WorkerOptions,
    scorer: Scorer | None = None,
    *,
    on_log: Callable[[str], None] | None = None,
) -> Outcome:
    """Score a claimed submission (in a :class:`Scorer` process) and store the outcome.

    Input problems (a :class:`~dg16m_core.errors.Dg16mError`, e.g. a file that no longer
    validates) fail the submission with their message; any other exception is a bug or a
    broken environment: it fails the submission with its traceback in the log, and is printed
    on stderr for the board's operator. A lost lease stops the scoring at once.

    Args:
        board, claim, options: the board, the worker's claim and how to score.
        scorer: the worker's scoring process (default: one for this job alone).
        on_log: called with each line of the scoring log as it is written (a local
            ``dg16m leaderboard submit`` prints them).

    Returns:
        ``"scored"``, ``"failed"``, or ``"lost"`` when the lease was lost meanwhile (nothing
        stored; another worker scores it).
    """
    log = _Log(board.clock, on_log)
    log(f"claimed by {claim.worker} (attempt {claim.attempt})")
    try:
        row = board.submission_row(claim.submission_id)
        names = json.loads(row["evaluators"])
        path = board.file_path(row["file_sha256"])
        ref = board.benchmark_ref()
    except Dg16mError as exc:
        log(f"error: {exc}")
        error = (str(exc) or type(exc).__name__)[:ERROR_CHARS]
        return "failed" if board.fail(claim, error, log.text) else "lost"
    log(f"benchmark {ref.sha256[:12]} ({len(ref.object_ids)} objects); file {path.name}")
    heartbeat = _Heartbeat(board, claim, options.lease_s)
    with contextlib.ExitStack() as stack:
        if scorer is None:
            scorer = stack.enter_context(Scorer(board, options))
        heartbeat.start()
        try:
            outcome = scorer.score(names, str(path), log, heartbeat.lost)
        finally:
            heartbeat.stopped.set()
            heartbeat.join()
    if outcome is None or heartbeat.lost.is_set():
        return "lost"
    results, error = outcome
    if error is None:
        log("scored")
        try:
            stored = board.finish(claim, results, log.text)
        except BoardError as exc:  # e.g. a partial result: never ranked
            log(f"error: {exc}")
            error = (str(exc) or type(exc).__name__)[:ERROR_CHARS]
            stored = board.fail(claim, error, log.text)
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
    with Scorer(board, options) as scorer:
        while not stop.is_set():
            claim = board.claim(name, options.lease_s)
            if claim is None:
                idle = time.monotonic() - idle_since
                if options.idle_exit_s is not None and idle >= options.idle_exit_s:
                    break
                stop.wait(options.poll_s)
                continue
            report(f"#{claim.submission_id}: claimed (attempt {claim.attempt})")
            outcome = score_claim(board, claim, options, scorer)
            report(f"#{claim.submission_id}: {outcome}")
            done += 1
            idle_since = time.monotonic()
            if options.max_jobs is not None and done >= options.max_jobs:
                break
    return done
