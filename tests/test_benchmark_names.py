"""A benchmark named by a misspelled short name gets one clear error everywhere a benchmark is
taken (issue 43): ``benchmark_file``, the command line and ``gym.make``."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import pytest

import dg16m_env  # noqa: F401  registers the environments
from dg16m_core.cli import main as cli_main
from dg16m_env.benchmark.model import BenchmarkError
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK, benchmark_file

EXPECTED = r"benchmark: expected a file or one of: procedural, real, found 'reall' \(no such file\)"


@pytest.mark.parametrize(
    ("name", "hint"),
    [("reall", "did you mean 'real'"), ("Real", "did you mean 'real'"), ("xyz", None)],
)
def test_a_misspelled_name_says_what_names_there_are(name: str, hint: str | None) -> None:
    with pytest.raises(BenchmarkError, match="expected a file or one of: procedural, real") as err:
        benchmark_file(name)
    assert f"found {name!r} (no such file)" in str(err.value)
    assert (hint in str(err.value)) if hint else "did you mean" not in str(err.value)


def test_names_paths_and_files_still_resolve(tmp_path: Path) -> None:
    assert benchmark_file("procedural") == EMBEDDED_BENCHMARK
    assert benchmark_file(str(tmp_path / "x.h5")) == tmp_path / "x.h5"  # read_benchmark says
    word = tmp_path / "mybench"
    word.write_bytes(b"")
    assert benchmark_file(str(word)) == word


def test_the_command_line_and_gym_make_say_the_same(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        cli_main(["benchmark", "info", "reall"])
    assert exit_info.value.code == 2
    assert "did you mean 'real'" in capsys.readouterr().err
    with pytest.raises(BenchmarkError, match=EXPECTED):
        gym.make("dg16m_env/DualGraspPose-v0", benchmark="reall")
