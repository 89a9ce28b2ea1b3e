"""Run one object's work in a child process with a time budget per stage.

Some real meshes take CoACD or the trials far longer than others (one wardrobe: 18 minutes of
CoACD; one thin vase: more than 33 minutes of a benchmark build). A build over hundreds of
objects must not wait for them: :func:`run_with_budget` runs ``fn(*args, on_stage=...)`` in a
fresh (spawned) child process; ``fn`` calls ``on_stage(name)`` when it enters a stage, and the
parent kills the child when a stage runs past its budget. Compiled code (CoACD, MuJoCo) cannot
be interrupted from inside its own process; a child can always be killed.

Errors the work raises on purpose (:class:`~dg16m_core.errors.Dg16mError`) come back as
themselves, with the seconds spent in each stage as their ``stage_times``; anything else (a
bug) comes back as a :class:`RuntimeError` with the child's traceback, never hidden.
"""

from __future__ import annotations

import multiprocessing
import os
import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dg16m_core.errors import Dg16mError
from dg16m_core.stopping import die_with_parent

StageCallback = Callable[[str], None]

WALL_FACTOR = 1.5
"""A stage is also stopped after this many times its budget of wall time (a child that waits
or hangs spends no CPU; on a loaded machine a stage gets at most this much more wall time than
its CPU budget). Was 4 until 2026-12-05: a loaded machine then let one object run past half an
hour."""


class StageTimeoutError(Dg16mError, RuntimeError):
    """A stage ran past its budget; the child was killed.

    Attributes:
        stage: the stage that ran out of time.
        budget: its budget (s).
        stage_times: wall seconds spent in each stage entered, in order (the name every error
            from :func:`run_with_budget` carries them under).
        whole: the object's total wall bound ran out (``budget`` is that bound), not the
            stage's own budget.
    """

    def __init__(
        self,
        stage: str,
        budget: float,
        stage_times: Mapping[str, float],
        whole: bool = False,
    ) -> None:
        what = "the object's" if whole else "its"
        super().__init__(
            f"expected stage {stage!r} to finish within {what} budget of {budget:g} s, found it "
            "still running (stopped)"
        )
        self.stage = stage
        self.budget = budget
        self.stage_times = dict(stage_times)
        self.whole = whole

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.stage, self.budget, self.stage_times, self.whole))


@dataclass
class BudgetedResult:
    """What :func:`run_with_budget` returns: the work's value and the seconds of each stage."""

    value: Any
    times: dict[str, float] = field(default_factory=dict)


class _ParentGoneError(Exception):
    """The parent closed its end (it was stopped): the child has no one to answer."""


def _child(conn: Any, fn: Callable[..., Any], args: tuple[Any, ...], parent_pid: int) -> None:
    die_with_parent(parent_pid)

    def send(message: tuple[str, Any]) -> None:
        try:
            conn.send(message)
        except (BrokenPipeError, ConnectionResetError):
            raise _ParentGoneError from None

    try:
        try:
            value = fn(*args, on_stage=lambda name: send(("stage", name)))
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


def _cpu_seconds(pid: int) -> float | None:
    """User + system CPU seconds of a live process (Linux ``/proc``), or None elsewhere."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


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
    first ``on_stage`` call is stage ``"start"``). CPU time, read from ``/proc`` (wall time where
    there is none), so that a loaded machine does not stop work a quiet one finishes; and at
    :data:`WALL_FACTOR` times the budget in wall time, whatever the CPU. The budget is checked
    every ``poll_s`` and again when the stage ends, so a stage that finishes past its budget
    between two polls is stopped all the same (the verdict does not depend on ``poll_s`` or on
    how fast the machine is). The seconds reported per stage are wall seconds. ``total_wall_s``
    bounds the whole run's wall time (all stages together; the stage running then is the one
    stopped, with ``budget`` the total).

    Stopping: the child dies with its parent (:func:`die_with_parent`), and a ``KeyboardInterrupt``
    (Ctrl-C, or SIGTERM made one by
    :func:`~dg16m_core.stopping.sigterm_interrupts`) in the parent kills it at once;
    the parent checks for one at least every ``poll_s``.

    Args:
        fn: a module-level function (it is pickled to the child) taking ``on_stage``.
        args: its positional arguments (picklable).
        budgets: seconds per stage name.
        total_wall_s: wall seconds for all stages together (None: no such bound).
        poll_s: how often the parent checks the child (s).

    Raises:
        StageTimeoutError: a stage ran past its budget (the child is killed).
        Dg16mError: what ``fn`` raised of that kind.
        RuntimeError: ``fn`` raised anything else (with the child's traceback), or the child
            died without an answer (e.g. killed for memory).
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
    process = context.Process(target=_child, args=(sender, fn, args, os.getpid()), daemon=True)
    process.start()
    sender.close()
    stage, started = "start", time.monotonic()
    began = started
    times: dict[str, float] = {}

    def spent() -> float:  # the child's CPU seconds in this stage (wall seconds without /proc)
        cpu = _cpu_seconds(process.pid) if process.pid is not None else None
        return time.monotonic() - started if cpu is None or cpu_start is None else cpu - cpu_start

    def over_budget(budget: float, now: float) -> bool:  # CPU past it, or WALL_FACTOR x wall
        return spent() > budget or now - started >= WALL_FACTOR * budget

    cpu_start = _cpu_seconds(process.pid) if process.pid is not None else None
    try:
        while True:
            budget = budgets.get(stage)
            if receiver.poll(poll_s):
                try:
                    kind, value = receiver.recv()
                except EOFError:
                    process.join()
                    raise RuntimeError(
                        f"expected an answer from the worker process, found it ended with exit "
                        f"code {process.exitcode} in stage {stage!r}"
                    ) from None
                now = time.monotonic()
                if budget is not None and over_budget(budget, now):
                    # a stage that ended past its budget between two polls is past it all the
                    # same: the verdict must not depend on poll_s or on how fast the machine is
                    times[stage] = times.get(stage, 0.0) + now - started
                    raise StageTimeoutError(stage, budget, times)
                if kind == "stage":
                    times[stage] = times.get(stage, 0.0) + now - started
                    stage, started = value, now
                    cpu_start = _cpu_seconds(process.pid) if process.pid is not None else None
                    continue
                times[stage] = times.get(stage, 0.0) + now - started
                process.join()
                if kind == "result":
                    return BudgetedResult(value, times)
                if kind == "error":
                    value.stage_times = dict(times)  # where the time went, for the caller
                    raise value
                raise RuntimeError(f"the worker process failed in stage {stage!r}:\n{value}")
            now = time.monotonic()
            if budget is not None and over_budget(budget, now):
                times[stage] = times.get(stage, 0.0) + now - started
                raise StageTimeoutError(stage, budget, times)
            if total_wall_s is not None and now - began >= total_wall_s:
                times[stage] = times.get(stage, 0.0) + now - started
                raise StageTimeoutError(stage, total_wall_s, times, whole=True)
            if not process.is_alive() and not receiver.poll():
                raise RuntimeError(
                    f"expected an answer from the worker process, found it ended with exit code "
                    f"{process.exitcode} in stage {stage!r}"
                )
    finally:
        if process.is_alive():
            process.kill()
        process.join()
        receiver.close()
