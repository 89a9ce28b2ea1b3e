"""One answer for the same mistake (issue 43, items 6, 7 and 9): a misspelled benchmark name, a
mesh folder in millimetres, an empty HDF5 file, a mesh file where a folder must go and
``render_mode="human"`` get the same message (and exit status) wherever they are made."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import pytest

import dg16m_env  # noqa: F401  registers the environments
from dg16m_core.cli import main
from dg16m_env.envs import env_ids
from dg16m_env.envs.common import EnvArgumentError

MILLIMETRES = "longest side 900 m: expected 0.05-5 m for a dual-arm object"
SCALE_HINT = (
    "a file in millimetres needs --scale 0.001 (0.9 m, the only unit giving a typical size)"
)


@pytest.fixture
def chair_mm(tmp_path: Path) -> Path:
    """A folder holding one 900 x 450 x 450 box: a chair written in millimetres."""
    import trimesh

    folder = tmp_path / "meshes"
    folder.mkdir()
    trimesh.creation.box(extents=(900.0, 450.0, 450.0)).export(folder / "chair.obj")
    return folder


def test_a_misspelled_benchmark_name_on_evaluate_is_bad_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["evaluate", str(tmp_path / "s.h5"), "--benchmark", "Real"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "expected a file or one of: procedural, real, found 'Real' (no such file)" in err
    assert "did you mean 'real'?" in err


def test_a_folder_in_millimetres_fails_its_object_in_generate_and_benchmark_build(
    chair_mm: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Both commands read the folder, fail the object with the scale hint and exit 1."""
    lines = {}
    for command in (["generate"], ["benchmark", "build"]):
        out = tmp_path / "-".join(command)
        argv = [*command, "--meshes", str(chair_mm), "--out", str(out), "--no-progress"]
        assert main(argv) == 1, command
        text = capsys.readouterr().out
        assert "0 objects ok, 1 failed" in text, command
        lines[command[-1]] = next(x for x in text.splitlines() if x.startswith("  failed chair:"))
    assert lines["generate"] == lines["build"]
    assert MILLIMETRES in lines["build"]
    assert SCALE_HINT in lines["build"]
    assert not (tmp_path / "benchmark-build" / "benchmark.h5").exists()


def test_a_mesh_file_where_a_folder_must_go(
    chair_mm: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    chair = chair_mm / "chair.obj"
    for command in (["generate"], ["benchmark", "build"]):
        argv = [*command, "--meshes", str(chair), "--out", str(tmp_path / "out")]
        assert main(argv) == 2, command
        err = capsys.readouterr().err
        assert f"--meshes: expected a folder of mesh files, found a file: {chair}" in err


def test_an_empty_hdf5_file_reads_the_same_in_inspect_validate_evaluate_and_info(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    empty = tmp_path / "empty.h5"
    empty.write_bytes(b"")
    for argv in (["inspect"], ["submission", "validate"], ["evaluate"], ["benchmark", "info"]):
        assert main([*argv, str(empty)]) == 2, argv
        err = capsys.readouterr().err
        assert "expected an HDF5 file, found an empty file (0 bytes)" in err, argv
        assert "signature" not in err, argv


@pytest.mark.parametrize("env_id", env_ids())
@pytest.mark.filterwarnings("ignore:dg16m_env/DualGraspLift-v0 is deprecated:DeprecationWarning")
def test_render_mode_human_is_refused_at_construction(env_id: str) -> None:
    """Not wrapped in HumanRendering by gym.make (that fails at reset without pygame)."""
    with pytest.raises(EnvArgumentError) as err:
        gym.make(env_id, render_mode="human")
    assert str(err.value) == "render_mode: expected None or 'rgb_array', found 'human'"
    cls = gym.spec(env_id).entry_point
    assert isinstance(cls, str)
    module, _, name = cls.partition(":")
    env_class = getattr(__import__(module, fromlist=[name]), name)
    assert env_class.METADATA["render_modes"] == ["rgb_array"]
