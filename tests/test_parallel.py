"""Ctrl-C on a run (dataset_gen.pipeline.parallel): the pool stops without finishing its tasks, and an
interrupt Python swallowed during a task still stops the run after it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from dataset_gen.io import read_manifest
from dataset_gen.pipeline.parallel import run_resumable
from dg16m_core.errors import Dg16mError


@dataclass(frozen=True)
class Item:
    object_id: str


def _swallowing_task(item: Item) -> dict[str, object]:
    """Receives Ctrl-C where Python ignores it (as in a weakref callback), then returns."""
    try:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    return {"status": "ok", "files": {}}


def test_an_interrupt_swallowed_during_a_task_stops_the_run_after_it(tmp_path: Path) -> None:
    # Python's own handler, as in a terminal (a shell's background job, e.g. under nohup,
    # starts with SIGINT ignored, and the tests may run in one)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        items = [Item(f"o{i}") for i in range(4)]
        with pytest.raises(KeyboardInterrupt):
            run_resumable(
                _swallowing_task,
                items,
                (),
                root=tmp_path,
                kind="grasps",
                parameters={},
                folders=(),
                error=Dg16mError,
            )
        assert list(read_manifest(tmp_path)["entries"]) == ["o0"]  # recorded, then stopped
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back
    finally:
        signal.signal(signal.SIGINT, previous)


POOL_SCRIPT = """
import signal, sys, time
# Python's own handler, as in a terminal: a shell's background job (nohup, &) starts with
# SIGINT ignored, and so would this script when the tests run in one
signal.signal(signal.SIGINT, signal.default_int_handler)
from dataclasses import dataclass
from pathlib import Path
from dg16m_core.errors import Dg16mError
from dataset_gen.pipeline.parallel import run_resumable

@dataclass(frozen=True)
class Item:
    object_id: str

def task(item, root):
    (Path(root) / f"started-{item.object_id}").touch()
    time.sleep(600)  # a long object: Ctrl-C must not wait for it
    return {"status": "ok", "files": {}}

root = sys.argv[1]
run_resumable(task, [Item(f"o{i}") for i in range(4)], (root,), root=Path(root), kind="grasps",
              parameters={}, folders=(), error=Dg16mError, workers=2)
"""


def test_ctrl_c_stops_a_pool_without_waiting_for_its_tasks(tmp_path: Path) -> None:
    script = tmp_path / "run.py"
    script.write_text(textwrap.dedent(POOL_SCRIPT))
    root = tmp_path / "out"
    root.mkdir()
    process = subprocess.Popen(
        [sys.executable, str(script), str(root)], stderr=subprocess.PIPE, text=True
    )
    try:
        for _ in range(600):  # both workers have started a task (bounded: 60 s)
            if len(list(root.glob("started-*"))) >= 2:
                break
            time.sleep(0.1)
        assert len(list(root.glob("started-*"))) >= 2
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=60)  # before the fix: the tasks' 600 s
    finally:
        if process.poll() is None:
            process.kill()
    assert "KeyboardInterrupt" in err
    assert len(list(root.glob("started-*"))) == 2  # nothing else started after the signal
    assert not (root / "manifest.json").exists()  # no object was recorded as done


def test_a_ray_address_where_nothing_answers_is_refused_at_once() -> None:
    import socket

    from dataset_gen.pipeline.parallel import ParallelError, check_ray_address

    check_ray_address("auto")  # left to Ray
    with socket.socket() as server:  # something answering on loopback
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        check_ray_address(f"127.0.0.1:{port}")
    with pytest.raises(ParallelError, match="found none within"):
        check_ray_address(f"127.0.0.1:{port}", timeout_s=2.0)  # closed now
    with pytest.raises(ParallelError, match="found none within"):
        check_ray_address("nowhere.invalid:6379", timeout_s=2.0)
    with pytest.raises(ParallelError, match="expected 'auto' or host:port"):
        check_ray_address("nowhere")
