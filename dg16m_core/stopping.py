"""Stopping long work promptly: Ctrl-C and SIGTERM end a command and every process it started.

Compiled code (CoACD, MuJoCo) cannot be interrupted from inside its own process, so long stages
run in child processes (:mod:`dg16m_core.budget`, :mod:`dataset_gen.pipeline.parallel`) that the parent
stops. Two pieces make that hold whatever signal arrives and wherever:

* :func:`sigterm_interrupts` (every resumable run of objects,
  :func:`dataset_gen.pipeline.parallel.run_resumable`, is inside it): SIGTERM raises
  ``KeyboardInterrupt`` as Ctrl-C does, so the parent unwinds and stops its children; Python's
  default would end the parent at once and leave them running.
* :func:`die_with_parent` (run first in every child): the kernel kills the child when its parent
  ends, however the parent ended (even SIGKILL), and the child leaves Ctrl-C to the parent.

Stdlib only.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

_PR_SET_PDEATHSIG = 1


def die_with_parent(parent_pid: int | None = None) -> None:
    """Have the kernel kill this process (SIGKILL) when the thread that started it ends (Linux
    ``prctl(PR_SET_PDEATHSIG)``; nothing elsewhere), so that compiled work (CoACD, MuJoCo) never
    outlives a parent that was stopped by a signal; and ignore SIGINT here: a Ctrl-C reaches the
    whole process group, and the parent, which hears it too, decides (it stops this process);
    SIGTERM, the parent's way of stopping it, ends it at once.
    ``parent_pid`` (the parent's ``os.getpid()``): exit at once if the parent is already gone
    (it ended before the kernel was told)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # not a forked parent's handler: just end
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL))
    except (OSError, AttributeError):  # no libc prctl: the parent's finally still kills us
        return
    if parent_pid is not None and os.getppid() != parent_pid:  # it ended before prctl
        os._exit(1)


@contextmanager
def sigterm_interrupts() -> Iterator[None]:
    """While inside, SIGTERM raises ``KeyboardInterrupt`` in the main thread as Ctrl-C does, so
    that a stopped run unwinds: its pool and budget children are stopped, its temporary files
    removed, and what was finished stays recorded (Python's default for SIGTERM ends the process
    at once and leaves its children running). Only in the main thread; elsewhere nothing
    changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGTERM)

    def handler(signum: int, frame: Any) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second one must not cut the unwinding
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
