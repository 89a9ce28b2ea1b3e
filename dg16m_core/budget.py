"""Run one object's work in a child process with a budget of CPU time per stage.

Some real meshes take CoACD or the trials far longer than others (one wardrobe: 18 minutes of
CoACD; one thin vase: more than 33 minutes of a benchmark build), and some crash CoACD outright
(a thin vase: SIGSEGV in its triangulation). A build over hundreds of objects must not wait for
them nor stop because of them: :func:`run_with_budget` runs ``fn(*args, on_stage=...)`` in a
fresh (spawned) child process; ``fn`` calls ``on_stage(name)`` when it enters a stage, and the
parent kills the child when a stage uses more CPU time than its budget. Compiled code (CoACD,
MuJoCo) cannot be interrupted from inside its own process; a child can always be killed, and its
crash does not take the parent with it.

What comes back:

* the work's value (:class:`BudgetedResult`, with the wall seconds of each stage);
* :class:`StageTimeoutError`: a stage used its budget of CPU seconds (``limit == "cpu"``, the
  verdict that does not depend on machine load), or ran into the wall-time safety net of
  :data:`WALL_FACTOR` times its budget (``limit == "wall"``: a child that waits or a heavily
  loaded machine), or the whole run's wall bound (``limit == "object"``); each with the CPU
  seconds the stage had used;
* :class:`StageCrashError`: the child died without an answer (a signal: SIGSEGV, SIGABRT,
  SIGKILL from the out-of-memory killer; or an exit status), with the stage, the signal or
  exit status and the CPU seconds used;
* errors the work raises on purpose (:class:`~dg16m_core.errors.Dg16mError`) as themselves,
  with the seconds spent in each stage as their ``stage_times``; anything else (a bug in
  Python) as a :class:`RuntimeError` with the child's traceback, never hidden.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import signal
import sys
import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dg16m_core.errors import Dg16mError
from dg16m_core.stopping import die_with_parent

StageCallback = Callable[[str], None]

WALL_FACTOR = 10.0
"""The wall-time safety net: a stage is also stopped after this many times its CPU budget in
wall seconds, whatever CPU it used (a child that waits or hangs spends none). Far above what
load does to a CPU budget (at load 8 on 2 cores a stage gets about a quarter of a core: 4 to 5
times its CPU seconds in wall time), so that the verdict is the CPU budget's on any machine the
build runs on, and a verdict of the safety net says so. Was 1.5 from 2026-12-05 (a chair was
rejected at 270 s of wall time after 113 of its 180 CPU s on a loaded machine), 4 before."""

RLIMIT_MARGIN_S = 2.0
"""The child's hard backstop: entering a stage with a budget of B CPU s sets its ``RLIMIT_CPU``
(soft) to the CPU seconds it has used plus B plus this margin, so the kernel stops it with
SIGXCPU (reported as the CPU budget, not as a crash) should the parent fail to read its CPU
time; the parent, which checks every ``poll_s``, normally stops it first."""


class StageTimeoutError(Dg16mError, RuntimeError):
    """A stage ran past its budget; the child was killed.

    Attributes:
        stage: the stage that ran out of time.
        budget: its budget (CPU s; with ``whole``, the run's wall bound in s).
        stage_times: wall seconds spent in each stage entered, in order (the name every error
            from :func:`run_with_budget` carries them under).
        whole: the object's total wall bound ran out (``budget`` is that bound), not the
            stage's own budget.
        cpu_seconds: CPU seconds the stage had used when it was stopped (None where they
            cannot be read).
        wall_s: set when the wall-time safety net (:data:`WALL_FACTOR` x ``budget``, s) stopped
            the stage rather than its CPU budget.
    """

    def __init__(
        self,
        stage: str,
        budget: float,
        stage_times: Mapping[str, float],
        whole: bool = False,
        cpu_seconds: float | None = None,
        wall_s: float | None = None,
    ) -> None:
        used = "" if cpu_seconds is None else f" after {cpu_seconds:.1f} CPU s"
        if whole:
            message = (
                f"expected stage {stage!r} to finish within the object's bound of {budget:g} s "
                f"of wall time, found it still running{used} (stopped)"
            )
        elif wall_s is not None:
            message = (
                f"expected stage {stage!r} to finish within the wall-time safety net of "
                f"{wall_s:g} s ({WALL_FACTOR:g} x its budget of {budget:g} CPU s), found it "
                f"still running{' after only' + used[6:] if used else ''} (stopped)"
            )
        else:
            message = (
                f"expected stage {stage!r} to finish within its budget of {budget:g} CPU s, "
                f"found it still running{used} (stopped)"
            )
        super().__init__(message)
        self.stage = stage
        self.budget = budget
        self.stage_times = dict(stage_times)
        self.whole = whole
        self.cpu_seconds = cpu_seconds
        self.wall_s = wall_s

    @property
    def limit(self) -> str:
        """Which limit ended the stage: ``"cpu"`` (its budget), ``"wall"`` (the safety net) or
        ``"object"`` (the run's wall bound)."""
        return "object" if self.whole else "wall" if self.wall_s is not None else "cpu"

    def __reduce__(self) -> tuple[Any, ...]:
        return (
            type(self),
            (self.stage, self.budget, self.stage_times, self.whole, self.cpu_seconds, self.wall_s),
        )


def signal_words(signum: int) -> str:
    """A signal in words, e.g. ``"signal 11 (SIGSEGV, segmentation fault)"``; SIGKILL names
    the out-of-memory killer, its most common sender."""
    try:
        name = signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"
    if signum == getattr(signal, "SIGKILL", None):
        return f"signal {signum} ({name}, most often the out-of-memory killer)"
    described = (signal.strsignal(signum) or "").lower()
    return f"signal {signum} ({name}" + (f", {described})" if described else ")")


class StageCrashError(Dg16mError, RuntimeError):
    """The child died in a stage without an answer: killed by a signal (a segmentation fault or
    an abort in compiled code, the out-of-memory killer) or ended with an exit status. Not a
    bug in Python (that comes back as a :class:`RuntimeError` with its traceback).

    Attributes:
        stage: the stage it died in.
        signal: the signal that killed it, or None.
        exit_code: its exit status when no signal killed it, or None.
        cpu_seconds: CPU seconds the stage had used (None where they cannot be read).
        stage_times: wall seconds spent in each stage entered, in order.
    """

    def __init__(
        self,
        stage: str,
        signal: int | None,
        exit_code: int | None,
        cpu_seconds: float | None,
        stage_times: Mapping[str, float],
    ) -> None:
        how = (
            f"killed by {signal_words(signal)}"
            if signal is not None
            else f"ended with exit status {exit_code} and no answer"
        )
        used = "" if cpu_seconds is None else f" after {cpu_seconds:.1f} CPU s"
        super().__init__(
            f"expected stage {stage!r} to end with an answer from its worker process, found it "
            f"{how}{used}"
        )
        self.stage = stage
        self.signal = signal
        self.exit_code = exit_code
        self.cpu_seconds = cpu_seconds
        self.stage_times = dict(stage_times)

    def __reduce__(self) -> tuple[Any, ...]:
        return (
            type(self),
            (self.stage, self.signal, self.exit_code, self.cpu_seconds, self.stage_times),
        )


@dataclass
class BudgetedResult:
    """What :func:`run_with_budget` returns: the work's value and the seconds of each stage."""

    value: Any
    times: dict[str, float] = field(default_factory=dict)


class _ParentGoneError(Exception):
    """The parent closed its end (it was stopped): the child has no one to answer."""


def _own_cpu_seconds() -> float:
    """User + system CPU seconds of this process, all its threads."""
    times = os.times()
    return times.user + times.system


def _limit_cpu(budget: float | None) -> None:
    """Set this process's ``RLIMIT_CPU`` soft limit for a stage of ``budget`` CPU s (None:
    unlimited again); the hard limit is left as it is, so a later stage can raise it."""
    try:
        import resource
    except ImportError:  # not POSIX: the parent's checks alone
        return
    hard = resource.getrlimit(resource.RLIMIT_CPU)[1]
    soft = (
        resource.RLIM_INFINITY
        if budget is None
        else math.ceil(_own_cpu_seconds() + budget + RLIMIT_MARGIN_S)
    )
    if hard != resource.RLIM_INFINITY:
        soft = hard if soft == resource.RLIM_INFINITY else min(soft, hard)
    resource.setrlimit(resource.RLIMIT_CPU, (soft, hard))


def _quiet_child() -> None:
    """What a budget child sets first: no core file when compiled code crashes it (the crash is
    reported to the parent), and semaphores that are unlinked as soon as made (the default of
    a forked process) instead of named and registered with the parent's resource tracker: a
    child killed at its budget or by Ctrl-C cannot unregister them (e.g. tqdm's lock), and the
    tracker then warns of "leaked semaphore objects" when the command ends."""
    try:
        import resource

        resource.setrlimit(resource.RLIMIT_CORE, (0, resource.getrlimit(resource.RLIMIT_CORE)[1]))
    except (ImportError, ValueError, OSError):
        pass
    if sys.platform.startswith("linux"):
        multiprocessing.set_start_method("fork", force=True)


def _child(
    conn: Any,
    fn: Callable[..., Any],
    args: tuple[Any, ...],
    parent_pid: int,
    budgets: Mapping[str, float] | None = None,
) -> None:
    die_with_parent(parent_pid)
    _quiet_child()
    budgets = budgets or {}

    def send(message: tuple[str, Any]) -> None:
        try:
            conn.send(message)
        except (BrokenPipeError, ConnectionResetError):
            raise _ParentGoneError from None

    def on_stage(name: str) -> None:
        send(("stage", name))
        _limit_cpu(budgets.get(name))

    try:
        _limit_cpu(budgets.get("start"))
        try:
            value = fn(*args, on_stage=on_stage)
        except _ParentGoneError:
            return
        except Dg16mError as exc:
            send(("error", exc))
        except BaseException:  # a bug: its traceback goes to the parent, which raises it
            send(("crash", traceback.format_exc()))
        else:
            send(("result", value))
    except _ParentGoneError:
        return
    finally:
        conn.close()


def process_cpu_seconds(pid: int) -> float | None:
    """User + system CPU seconds of a live process (Linux ``/proc``), or None elsewhere."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _children_cpu_seconds() -> float | None:
    """User + system CPU seconds of this process's ended and reaped children (None where
    ``resource`` is missing)."""
    try:
        import resource
    except ImportError:
        return None
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_with_budget(
    fn: Callable[..., Any],
    args: tuple[Any, ...],
    budgets: Mapping[str, float],
    *,
    total_wall_s: float | None = None,
    poll_s: float = 0.5,
) -> BudgetedResult:
    """``fn(*args, on_stage=callback)`` in a spawned child, each stage within ``budgets[stage]``
    seconds of the child's CPU time (stages without a budget are unlimited; the time before the
    first ``on_stage`` call is stage ``"start"``).

    Limits, and which one a verdict names (:attr:`StageTimeoutError.limit`):

    * the CPU budget (``"cpu"``): the child's user + system CPU seconds in the stage, read from
      ``/proc`` every ``poll_s`` and again when the stage ends (a stage that finishes past its
      budget between two polls is stopped all the same: the verdict depends neither on
      ``poll_s`` nor on machine load); the child's own ``RLIMIT_CPU`` (budget +
      :data:`RLIMIT_MARGIN_S`) is the kernel's backstop, its SIGXCPU reported as this limit;
    * the wall-time safety net (``"wall"``): :data:`WALL_FACTOR` times the budget in wall
      seconds, whatever the CPU (a child that waits or hangs, or a machine so loaded that the
      stage got a tenth of a core);
    * ``total_wall_s`` (``"object"``): the whole run's wall time, all stages together (the
      stage running then is the one stopped, with ``budget`` the total).

    The seconds reported per stage are wall seconds; each limit's error carries the CPU seconds
    the stage had used.

    Stopping: the child dies with its parent (:func:`die_with_parent`), and a ``KeyboardInterrupt``
    (Ctrl-C, or SIGTERM made one by :func:`~dg16m_core.stopping.sigterm_interrupts`) in the
    parent kills it at once; the parent checks for one at least every ``poll_s``.

    Args:
        fn: a module-level function (it is pickled to the child) taking ``on_stage``.
        args: its positional arguments (picklable).
        budgets: CPU seconds per stage name.
        total_wall_s: wall seconds for all stages together (None: no such bound).
        poll_s: how often the parent checks the child (s).

    Raises:
        StageTimeoutError: a stage ran past a limit (the child is killed).
        StageCrashError: the child died without an answer (a signal such as SIGSEGV, SIGABRT or
            SIGKILL, or an exit status).
        Dg16mError: what ``fn`` raised of that kind.
        RuntimeError: ``fn`` raised anything else (with the child's traceback).
    """
    for name, seconds in budgets.items():
        if not (isinstance(seconds, (int, float)) and seconds > 0):
            raise ValueError(f"budgets[{name!r}]: expected seconds > 0, found {seconds!r}")
    if total_wall_s is not None and not (
        isinstance(total_wall_s, (int, float)) and total_wall_s > 0
    ):
        raise ValueError(f"total_wall_s: expected seconds > 0, found {total_wall_s!r}")
    context = multiprocessing.get_context("spawn")
    receiver, sender = context.Pipe(duplex=False)
    reaped_before = _children_cpu_seconds()
    process = context.Process(
        target=_child, args=(sender, fn, args, os.getpid(), dict(budgets)), daemon=True
    )
    try:
        process.start()
    finally:
        sender.close()
    watch = _Watch(process, budgets, total_wall_s, reaped_before)
    try:
        while True:
            if receiver.poll(poll_s):
                try:
                    kind, value = receiver.recv()
                except EOFError:
                    raise watch.ended() from None
                now = time.monotonic()
                # a stage that ended past its budget between two polls is past it all the
                # same: the verdict must not depend on poll_s or on how fast the machine is
                stopped = watch.past_limit(now)
                if stopped is not None:
                    raise stopped
                if kind == "stage":
                    watch.enter(value, now)
                    continue
                watch.close_stage(now)
                process.join()
                if kind == "result":
                    return BudgetedResult(value, watch.times)
                if kind == "error":
                    value.stage_times = dict(watch.times)  # where the time went, for the caller
                    raise value
                raise RuntimeError(f"the worker process failed in stage {watch.stage!r}:\n{value}")
            stopped = watch.past_limit(time.monotonic())
            if stopped is not None:
                raise stopped
            if not process.is_alive() and not receiver.poll():
                raise watch.ended()
    finally:
        if process.is_alive():
            process.kill()
        process.join()
        receiver.close()
        process.close()


class _Watch:
    """The parent's view of a budget child: its stage, the wall and CPU seconds spent, and the
    verdict when a limit is passed or the child died (:func:`run_with_budget`)."""

    def __init__(
        self,
        process: Any,
        budgets: Mapping[str, float],
        total_wall_s: float | None,
        reaped_before: float | None,
    ) -> None:
        self.process = process
        self.budgets = budgets
        self.total_wall_s = total_wall_s
        self.reaped_before = reaped_before  # CPU s of this process's reaped children before it
        self.stage = "start"
        self.began = self.started = time.monotonic()
        self.times: dict[str, float] = {}
        self.last_cpu: float | None = None  # the latest reading of the child's CPU seconds
        self.cpu_start = self.cpu_now() or 0.0  # the child's CPU seconds when its stage began

    def cpu_now(self) -> float | None:
        pid = self.process.pid
        cpu = process_cpu_seconds(pid) if pid is not None else None
        if cpu is not None:
            self.last_cpu = cpu
        return cpu

    def close_stage(self, now: float) -> None:
        self.times[self.stage] = self.times.get(self.stage, 0.0) + now - self.started

    def enter(self, stage: str, now: float) -> None:
        self.close_stage(now)
        self.stage, self.started = stage, now
        self.cpu_start = self.cpu_now() or 0.0

    def past_limit(self, now: float) -> StageTimeoutError | None:
        """The verdict when the stage is past a limit at ``now``, else None."""
        stage, budget, total = self.stage, self.budgets.get(self.stage), self.total_wall_s
        cpu = self.cpu_now()
        used = None if cpu is None else cpu - self.cpu_start
        over_cpu = budget is not None and used is not None and used > budget
        over_wall = budget is not None and now - self.started >= WALL_FACTOR * budget
        whole = total is not None and now - self.began >= total
        if not (over_cpu or over_wall or whole):
            return None
        self.close_stage(now)
        if budget is not None and (over_cpu or over_wall):
            wall = None if over_cpu else WALL_FACTOR * budget
            return StageTimeoutError(stage, budget, self.times, cpu_seconds=used, wall_s=wall)
        assert total is not None
        return StageTimeoutError(stage, total, self.times, whole=True, cpu_seconds=used)

    def ended(self) -> Dg16mError:
        """The verdict of a child that died without an answer: its CPU budget when the kernel's
        RLIMIT_CPU stopped it (SIGXCPU), else a crash (its CPU seconds from the rusage of the
        reaped child, or the last reading)."""
        self.process.join()
        self.close_stage(time.monotonic())
        reaped = _children_cpu_seconds()
        total = (
            reaped - self.reaped_before
            if reaped is not None and self.reaped_before is not None
            else self.last_cpu
        )
        used = None if total is None else round(max(0.0, total - self.cpu_start), 2)
        code = self.process.exitcode if self.process.exitcode is not None else 0
        budget = self.budgets.get(self.stage)
        if code == -getattr(signal, "SIGXCPU", -1) and budget is not None:  # RLIMIT_CPU
            return StageTimeoutError(self.stage, budget, self.times, cpu_seconds=used)
        signum, status = (-code, None) if code < 0 else (None, code)
        return StageCrashError(self.stage, signum, status, used, self.times)
