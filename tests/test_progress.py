"""Progress bars (``dg16m_core.progress``): a tqdm bar on a terminal; in a log (stderr not a
terminal) one plain line at most every few seconds and one at the end, never a carriage return."""

from __future__ import annotations

import io
import subprocess
import sys
import types

import pytest

import dg16m_core.progress as progress
from dg16m_core.progress import LineProgress, format_seconds, progress_bar


class FakeClock:
    """A ``time`` module whose ``monotonic`` is advanced by hand."""

    def __init__(self) -> None:
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> FakeClock:
    fake = FakeClock()
    monkeypatch.setattr(progress, "time", types.SimpleNamespace(monotonic=fake.monotonic))
    return fake


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_log_gets_one_line_per_interval_and_one_at_the_end(clock: FakeClock) -> None:
    """1,000 updates over 12 s with a 5 s interval: lines at 5 s and 10 s, then the last one."""
    log = io.StringIO()
    bar = progress_bar(total=1000, desc="pairs", unit="pair", stream=log, interval=5.0)
    assert isinstance(bar, LineProgress)
    for _ in range(1000):
        clock.now += 0.012
        bar.update(1)
    bar.set_postfix(failed=2)
    bar.close()
    bar.close()  # a second close writes nothing
    text = log.getvalue()
    assert "\r" not in text
    lines = text.splitlines()
    assert len(lines) == 3, lines
    assert lines[0].startswith("pairs: 417/1000 pair (42%), 0:05 elapsed, 83.3 pair/s, ~0:07 left")
    assert lines[-1] == "pairs: 1000/1000 pair (100%), 0:12 elapsed, 83.3 pair/s, done, failed=2"


def test_iterating_counts_and_closes(clock: FakeClock) -> None:
    """Iteration advances by one per item and writes the last line when the items run out;
    a bar left early says so; ``leave=False`` writes no last line."""
    log = io.StringIO()
    seen = []
    for item in progress_bar(range(4), desc="objects", unit="obj", stream=log):
        clock.now += 1.0
        seen.append(item)
    assert seen == [0, 1, 2, 3]
    assert log.getvalue() == "objects: 4/4 obj (100%), 0:04 elapsed, 1 obj/s, done\n"

    log = io.StringIO()
    with progress_bar(total=10, desc="repair", unit="mesh", initial=6, stream=log) as bar:
        bar.update(2)
    assert log.getvalue() == "repair: 8/10 mesh (80%), 0:00 elapsed, stopped\n"

    log = io.StringIO()
    with progress_bar(total=3, stream=log, leave=False) as bar:
        bar.update(3)
    assert log.getvalue() == ""

    log = io.StringIO()  # stopped before any progress (an error): the error says it all
    with pytest.raises(OSError, match="disk full"), progress_bar(total=3, stream=log):
        raise OSError("disk full")
    assert log.getvalue() == ""
    with progress_bar(total=2, initial=2, desc="objects", stream=log):
        pass  # all kept from an earlier run: still reported
    assert log.getvalue() == "objects: 2/2 it (100%), 0:00 elapsed, done\n"


def test_disabled_and_terminal_bars() -> None:
    """``enabled=False`` shows nothing; on a terminal the bar is tqdm's (carriage returns)."""
    from tqdm import tqdm

    log = io.StringIO()
    with progress_bar(total=5, stream=log, enabled=False) as bar:
        bar.update(5)
    assert log.getvalue() == ""

    terminal = Terminal()
    with progress_bar(total=5, desc="gsr", stream=terminal, mininterval=0) as bar:
        assert isinstance(bar, tqdm)
        for _ in range(5):
            bar.update(1)
    assert "\r" in terminal.getvalue()
    assert "5/5" in terminal.getvalue()


def test_format_seconds() -> None:
    assert [format_seconds(s) for s in (0, 59.6, 61, 3600 * 2 + 5)] == [
        "0:00",
        "1:00",
        "1:01",
        "2:00:05",
    ]
    assert format_seconds(float("inf")) == "?"


def test_a_command_logs_plain_lines(tmp_path) -> None:
    """``dg16m generate`` with stderr to a pipe (a log): no carriage return, one last line per
    bar (before, tqdm wrote one ``\\r`` update per object)."""
    out = tmp_path / "data"
    sizes = ["--grasps", "40", "--max-passing", "10", "--max-failing", "10", "--out", str(out)]
    done = subprocess.run(
        [sys.executable, "-m", "dg16m_core.cli", "generate", "--procedural", "2", *sizes],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr.count("\r") == 0, repr(done.stderr[:500])
    lines = [line for line in done.stderr.splitlines() if line.startswith("generate: ")]
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith("generate: 2/2 object (100%)"), lines
    assert lines[0].split(", ")[-1] == "done", lines


def test_slow_work_reads_in_seconds_per_unit(clock: FakeClock) -> None:
    """Under one unit a second the rate reads as seconds per unit; reaching the total writes
    no line of its own (the last line follows on close)."""
    log = io.StringIO()
    bar = progress_bar(total=4, desc="benchmark", unit="object", stream=log, interval=5.0)
    clock.now += 16.0
    bar.update(1)
    clock.now += 16.0
    bar.update(3)
    bar.close()
    assert log.getvalue().splitlines() == [
        "benchmark: 1/4 object (25%), 0:16 elapsed, 16 s/object, ~0:48 left",
        "benchmark: 4/4 object (100%), 0:32 elapsed, 8 s/object, done",
    ]
