"""Test helpers shared by the evaluation-resume tests (importable from tests/ as
``checkpoint_stops``): stop a run right after its k-th checkpointed object, by Ctrl-C or by a
real SIGTERM."""

from __future__ import annotations

import os
import signal
from collections.abc import Callable

import pytest

from dg16m_env.evaluators.checkpoint import ObjectCheckpoint


def stop_after(patch: pytest.MonkeyPatch, k: int, stop: Callable[[], None]) -> None:
    """Stop the run (``stop()``) right after the k-th object (or episode) was checkpointed."""
    original = ObjectCheckpoint.save
    saved = []

    def save(self, *args, **kwargs):
        original(self, *args, **kwargs)
        saved.append(args)
        if len(saved) == k:
            stop()

    patch.setattr(ObjectCheckpoint, "save", save)


def ctrl_c() -> None:
    """What Ctrl-C does to the run."""
    raise KeyboardInterrupt


def sigterm() -> None:
    """A real SIGTERM to this process."""
    os.kill(os.getpid(), signal.SIGTERM)
