"""``dg16m demo``: the main job end to end, as a newcomer runs it (:mod:`baselines.demo`)."""

from __future__ import annotations

import io
import json
from collections.abc import Sequence
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytest.importorskip("starlette")

from baselines.demo import MARKER, DemoError, demo_steps, prepare_folder, run_demo
from dg16m_core.cli import main as cli_main


def test_the_demo_runs_end_to_end(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    stream = io.StringIO()
    record = run_demo(out, objects=1, workers=1, stream=stream)
    assert record["complete"]
    assert [s["exit"] for s in record["steps"]] == [0] * len(demo_steps(out))
    for relative in record["outputs"]:
        assert (out / relative).exists(), relative
    assert json.loads((out / MARKER).read_text())["complete"]
    scores = json.loads((out / "scores" / "force_closure.json").read_text())
    # force-closure pairing keeps only pairs that pass the force-closure check: fce is 1
    assert scores["results"]["fce"]["metrics"]["fce"]["rate"] == 1.0
    assert 0.0 <= scores["results"]["gsr"]["metrics"]["gsr"]["rate"] <= 1.0
    page = (out / "leaderboard" / "site" / "index.html").read_text()
    assert "force-closure pairing" in page
    assert "random pairing" in page
    text = stream.getvalue()
    assert "$ dg16m benchmark build --limit 1" in text  # each step's command is shown
    assert "force-closure pairing on the demo benchmark: fce 100.0%" in text
    assert "What to run next" in text


def test_a_folder_the_demo_did_not_write_is_refused(tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("precious")
    with pytest.raises(DemoError, match="expected a missing or empty folder"):
        prepare_folder(mine)
    assert (mine / "thesis.tex").read_text() == "precious"
    with pytest.raises(DemoError, match="expected a folder, found a file"):
        prepare_folder(mine / "thesis.tex")
    previous = tmp_path / "previous"
    previous.mkdir()
    (previous / MARKER).write_text("{}")
    (previous / "old.png").write_text("x")
    prepare_folder(previous)  # a previous demo's folder is replaced
    assert previous.is_dir()
    assert not any(previous.iterdir())


def test_a_failed_step_is_named_with_its_command(tmp_path: Path) -> None:
    calls: list[list[str]] = []

    def run(argv: Sequence[str]) -> int:
        calls.append(list(argv))
        return 0 if len(calls) < 3 else 2

    with pytest.raises(DemoError, match=r"step 3 \(dual grasps.*exit status 2.*dg16m generate"):
        run_demo(tmp_path / "d", objects=2, workers=1, run=run, stream=io.StringIO())
    assert len(calls) == 3
    record = json.loads((tmp_path / "d" / MARKER).read_text())
    assert not record["complete"]
    assert [s["exit"] for s in record["steps"]] == [0, 0, 2]


def test_bad_arguments_are_refused_on_the_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli_main(["demo", "--out", str(tmp_path / "d"), "--objects", "0"]) == 2
    assert "--objects: expected an integer >= 1, found 0" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


def test_the_benchmark_report_is_printed_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 43: ``benchmark build`` and ``benchmark info`` print the same ~70-line report; the
    demo showed it twice. The info step (run for its plot) now shows only its ``wrote`` line."""
    report = "failure phase of failed trials (a long report)"

    def run(argv: Sequence[str]) -> int:
        if argv[:2] in (["benchmark", "build"], ["benchmark", "info"]):
            print(report)
            print(f"wrote {argv[-1]}")
        return 2 if argv[:2] == ["sim", "replay"] else 0  # stop after the info step

    stream = io.StringIO()
    with pytest.raises(DemoError, match="step 7"):
        run_demo(tmp_path / "d", objects=1, workers=1, run=run, stream=stream)
    shown = capsys.readouterr().out + stream.getvalue()
    assert shown.count(report) == 1
    assert f"wrote {tmp_path / 'd' / 'benchmark.png'}" in stream.getvalue()
    assert "$ dg16m benchmark info" in stream.getvalue()  # the command is still shown
