"""The dataset tutorial (``docs/tutorials/dataset.md``) as written: its small build command
(with ``--objects 4`` for speed), its card commands and its 20-line training example, run on the
folder it built."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

pytest.importorskip("torch")

from dg16m_core.cli import main

TUTORIAL = Path(__file__).resolve().parents[1] / "docs" / "tutorials" / "dataset.md"


def _commands() -> list[list[str]]:
    text = TUTORIAL.read_text(encoding="utf-8")
    lines = []
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        joined = block.replace("\\\n", " ")
        lines += [shlex.split(line, comments=True) for line in joined.splitlines()]
    return [line for line in lines if line]


def _example() -> str:
    text = TUTORIAL.read_text(encoding="utf-8")
    match = re.search(r"<!-- training-example -->\n```python\n(.*?)```", text, re.S)
    assert match, f"{TUTORIAL}: expected the training example"
    return match.group(1)


def test_the_tutorial_builds_a_dataset_and_trains_on_it(tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(tmp_path)
    commands = [c for c in _commands() if "runs/small" in " ".join(c)]
    assert commands[0][:3] == ["dg16m", "dataset", "build"]
    build = [*commands[0][1:], "--no-progress"]
    build[build.index("--objects") + 1] = "4"  # speed: 4 objects, not 40
    assert main(build) == 0
    for command in commands[1:]:
        assert main(command[1:]) == 0, command
    out = capsys.readouterr().out
    assert "4 objects" in out
    assert "sha256 as built" in out
    code = _example()
    assert len([line for line in code.splitlines() if line.strip()]) <= 20  # "in 20 lines"
    namespace: dict[str, object] = {}
    exec(compile(code, str(TUTORIAL), "exec"), namespace)
    printed = capsys.readouterr().out
    assert re.search(r"epoch 1: loss \d+\.\d{3}", printed), printed
