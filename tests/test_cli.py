"""The ``dg16m`` command line: help texts, the objects workflow, pictures and errors."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import h5py
import matplotlib.image
import numpy as np
import pytest

from dataset_gen import io
from dataset_gen.sources.library import load_library
from dg16m_core.cli import COMMAND_GROUP, CommandPlugin, build_parser, command_plugins, main

SUBCOMMANDS = [
    "objects",
    "show",
    "inspect",
    "grippers",
    "verify",
    "generate",
    "stats",
    "benchmark",
    "sim",
    "evaluate",
    "submission",
    "baselines",
    "demo",
    "dataset",
]


def _image_is_a_picture(path: Path) -> None:
    image = matplotlib.image.imread(path)
    assert image.ndim == 3
    assert min(image.shape[:2]) > 300
    assert image[..., :3].std() > 0.05  # not blank


def test_console_script_help_lists_every_subcommand() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "dg16m_core.cli", "--help"],
        capture_output=True,
        text=True,
        check=True,
    )
    for name in SUBCOMMANDS:
        assert name in result.stdout


@pytest.mark.parametrize(
    "argv",
    [
        ["objects"],
        ["objects", "make"],
        ["objects", "show"],
        ["objects", "check"],
        ["show"],
        ["inspect"],
        ["grippers"],
        ["benchmark", "build"],
        ["benchmark", "info"],
        ["sim", "replay"],
        ["sim", "run"],
        ["verify"],
        ["generate"],
        ["stats"],
        ["evaluate"],
        ["submission", "validate"],
        ["submission", "make"],
        ["baselines", "submissions"],
        ["demo"],
    ],
)
def test_each_subcommand_has_help_with_examples(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as info:
        main([*argv, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out
    assert "dg16m " + argv[0] in out


def test_objects_make_writes_loadable_objects_and_reruns_keep_them(tmp_path: Path) -> None:
    out = tmp_path / "objects"
    assert main(["objects", "make", "--count", "20", "--seed", "0", "--out", str(out)]) == 0
    manifest = io.read_manifest(out)
    assert manifest["kind"] == "objects"
    assert len(manifest["entries"]) == 20
    objects = load_library(out)
    assert len(objects) == 20
    assert len({o.metadata["family"] for o in objects}) >= 8
    for obj in objects:
        assert obj.is_watertight
        assert 0.3 <= obj.extents.max() <= 1.2
        assert obj.parts
    before = {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
    mtimes = {p: p.stat().st_mtime_ns for p in before if p.suffix == ".obj"}
    assert main(["objects", "make", "--count", "20", "--seed", "0", "--out", str(out)]) == 0
    assert {p: p.read_bytes() for p in before} == before
    assert {p: p.stat().st_mtime_ns for p in mtimes} == mtimes  # not rewritten

    again = tmp_path / "again"
    assert main(["objects", "make", "--count", "20", "--seed", "0", "--out", str(again)]) == 0
    for path, data in before.items():
        assert (again / path.relative_to(out)).read_bytes() == data  # same seed, same bytes

    png = tmp_path / "sheet.png"
    assert main(["objects", "show", str(out), "--out", str(png), "--limit", "10"]) == 0
    _image_is_a_picture(png)


def test_objects_check_reports_good_and_broken_meshes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import trimesh

    good = tmp_path / "good.obj"
    trimesh.creation.box(extents=(0.5, 0.3, 0.04)).export(good)
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\n")
    assert main(["objects", "check", str(good), str(bad)]) == 1
    out = capsys.readouterr().out
    assert "ok   " in out
    assert "; watertight, solid mass model" in out
    assert f"FAIL {bad}: expected a triangle mesh, found PointCloud" in out


def test_input_errors_exit_2_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    missing = tmp_path / "nope.h5"
    assert main(["inspect", str(missing)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dg16m inspect: error:")
    assert "nope.h5" in err
    assert (
        main(
            [
                "objects",
                "make",
                "--count",
                "3",
                "--split",
                "benchmark",
                "--seed",
                "4",
                "--out",
                str(tmp_path / "b"),
            ]
        )
        == 2
    )
    assert "dg16m objects: error:" in capsys.readouterr().err
    assert main(["objects", "make", "--count", "0", "--out", str(tmp_path / "z")]) == 2


@pytest.mark.parametrize(
    "argv",
    [
        ["generate", "--procedural", "1", "--out", "{file}"],
        ["objects", "make", "--count", "1", "--out", "{file}"],
        ["objects", "make", "--count", "1", "--out", "{file}/inside"],
    ],
)
def test_an_output_path_that_is_a_file_is_bad_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str]
) -> None:
    """No traceback: one line saying a folder was expected, exit 2, the file left as it was."""
    file = tmp_path / "readme.txt"
    file.write_text("mine")
    assert main([a.replace("{file}", str(file)) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "expected a folder" in err
    assert "Traceback" not in err
    assert file.read_text() == "mine"


def test_input_that_cannot_be_read_exits_2_for_every_command(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    truncated = tmp_path / "truncated.h5"
    with h5py.File(tmp_path / "whole.h5", "w") as f:
        f.create_dataset("x", data=np.zeros(10_000))
    truncated.write_bytes((tmp_path / "whole.h5").read_bytes()[:1000])
    for argv in (
        ["objects", "check", str(tmp_path / "missing.obj")],
        ["inspect", str(tmp_path / "missing.h5")],
        ["inspect", str(truncated)],
        ["submission", "validate", str(tmp_path / "missing.h5")],
        ["submission", "validate", str(truncated)],
        ["submission", "validate", str(tmp_path)],
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith(f"dg16m {argv[0]}: error:"), err
        assert "expected" in err


def test_no_doubled_percent_signs_in_any_help(capsys: pytest.CaptureFixture[str]) -> None:
    """argparse formats a help string ("95%%" -> "95%") but not a description: both read right."""
    parser = build_parser()
    seen = 0
    stack = [parser]
    while stack:
        current = stack.pop()
        text = current.format_help()
        assert "%%" not in text, current.prog
        seen += "95%" in text
        for action in current._actions:
            if isinstance(action, argparse._SubParsersAction):
                stack.extend(action.choices.values())
    assert seen >= 2  # reproduce and leaderboard show speak of 95% intervals


def test_parser_is_built_from_command_modules() -> None:
    parser = build_parser()
    args = parser.parse_args(["grippers"])
    assert callable(args.handler)


@pytest.mark.real_data
def test_show_renders_the_real_release_file(
    real_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    png = tmp_path / "airplane.png"
    code = main(
        [
            "show",
            str(real_data / "dg16m_airplane.h5"),
            "--mesh",
            str(real_data / "dg16m_airplane.obj"),
            "--out",
            str(png),
            "--n",
            "12",
        ]
    )
    assert code == 0
    assert "6 passing + 6 failing of 4000 dual grasps" in capsys.readouterr().out  # --n 12 in all
    _image_is_a_picture(png)
    assert not list(tmp_path.glob(".*tmp*"))  # atomic write left nothing behind


@pytest.mark.real_data
def test_inspect_real_files(real_data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(real_data / "dg16m_airplane.h5")]) == 0
    out = capsys.readouterr().out
    assert "4000 (2000 passing, 2000 failing)" in out
    assert main(["inspect", str(real_data / "acronym_table_99cf659a.h5")]) == 0
    assert "ACRONYM" in capsys.readouterr().out


def test_select_pairs_balances_and_is_seeded() -> None:
    from dataset_gen.pipeline.render import select_pairs

    passed = np.array([True] * 3 + [False] * 30)
    p, f = select_pairs(passed, 10, seed=1)
    assert (len(p), len(f)) == (3, 7)  # failing pairs fill the missing passing slots
    p2, f2 = select_pairs(passed, 10, seed=1)
    assert (p.tolist(), f.tolist()) == (p2.tolist(), f2.tolist())


# --------------------------------------------------------------------------------------------
# Commands by package: entry points, broken plugins, no arguments, closed pipes
# --------------------------------------------------------------------------------------------

CLI = [sys.executable, "-m", "dg16m_core.cli"]


def test_commands_come_from_the_entry_point_group_in_a_stable_order() -> None:
    plugins = command_plugins()
    assert [p.value for p in plugins] == [
        "dataset_gen.cli:register",
        "baselines.baseline_commands:register",
        "baselines.demo:register",
        "dg16m_env.cli.benchmark:register",
        "dg16m_env.cli.dataset:register",
        "dg16m_env.cli.demos:register",
        "dg16m_env.cli.evaluate:register",
        "dg16m_env.cli.sim:register",
        "leaderboard.commands:register",
    ]
    parser = build_parser()
    names = list(parser._subparsers._group_actions[0].choices)  # help order
    assert names == [
        *SUBCOMMANDS[:4],
        *("generate", "stats", "verify", "baselines", "reproduce", "demo", "benchmark"),
        "dataset",
        "demos",
        "evaluate",
        *("submission", "sim"),
        "leaderboard",
    ]


def test_dataset_gen_names_no_package_above_it() -> None:
    root = Path(__file__).resolve().parents[1] / "dataset_gen"
    offenders = [
        f"{path.relative_to(root.parent)}: {word}"
        for path in sorted(root.rglob("*.py"))
        for word in ("dg16m_env", "baselines", "leaderboard")
        if word in path.read_text(encoding="utf-8")
    ]
    assert offenders == []


def _plugins_with(*extra: CommandPlugin) -> list[CommandPlugin]:
    return [p for p in command_plugins() if p.is_base] + list(extra)


def test_a_broken_plugin_is_named_and_the_other_commands_work(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    missing = CommandPlugin("missing.commands", "no_such_module_xyz.commands:register")
    monkeypatch.setattr("dg16m_core.cli.command_plugins", lambda: _plugins_with(missing))
    assert main(["grippers"]) == 0
    captured = capsys.readouterr()
    assert "panda" in captured.out
    assert "command plugin 'missing.commands'" in captured.err
    assert "no_such_module_xyz.commands:register" in captured.err
    assert "ModuleNotFoundError" in captured.err
    assert COMMAND_GROUP in captured.err


def test_a_plugin_failing_halfway_leaves_no_half_registered_command(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def half(subparsers: object) -> None:
        subparsers.add_parser("half", help="registered before the failure")  # type: ignore[attr-defined]
        raise RuntimeError("register broke")

    plugin = CommandPlugin("half.commands", "half.commands:register")
    real = CommandPlugin.load
    monkeypatch.setattr(CommandPlugin, "load", lambda self: half if self is plugin else real(self))
    problems: list[tuple[str, str]] = []
    parser = build_parser(
        _plugins_with(plugin), on_broken=lambda p, exc: problems.append((p.name, str(exc)))
    )
    assert problems == [("half.commands", "register broke")]
    choices = parser._subparsers._group_actions[0].choices
    assert "half" not in choices
    assert "grippers" in choices
    assert "half" not in parser.format_help()


def test_a_duplicate_command_name_is_reported_against_its_plugin() -> None:
    twice = CommandPlugin("again.commands", "dataset_gen.cli.objects:register")
    problems: list[str] = []
    build_parser(_plugins_with(twice), on_broken=lambda p, exc: problems.append(p.name))
    assert problems == ["again.commands"]


def test_no_plugins_at_all_is_a_clear_error(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr("dg16m_core.cli.command_plugins", lambda: [])
    assert main(["grippers"]) == 2
    err = capsys.readouterr().err
    assert f"expected subcommands registered in the entry-point group {COMMAND_GROUP!r}" in err
    assert "pip install -e ." in err


def test_no_arguments_prints_the_help_and_exits_0() -> None:
    result = subprocess.run(CLI, capture_output=True, text=True, check=False)
    assert result.returncode == 0
    assert result.stdout.startswith("usage: dg16m")
    for name in SUBCOMMANDS:
        assert name in result.stdout
    assert result.stderr == ""


@pytest.mark.parametrize("argv", [["--help"], ["grippers"], ["objects", "make", "--help"]])
def test_a_closed_pipe_ends_quietly(argv: list[str]) -> None:
    """`dg16m ... | head -1`: the reader is gone before dg16m writes; no BrokenPipeError trace."""
    process = subprocess.Popen(
        [*CLI, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert process.stdout is not None
    process.stdout.close()  # the reader leaves before the interpreter has even started
    _, err = process.communicate(timeout=60)
    assert err == ""
    # 141 (as killed by SIGPIPE) when dg16m's own output hits the closed pipe; argparse's
    # --help swallows the error itself and exits 0.
    assert process.returncode == (0 if "--help" in argv else 141)


def test_head_of_the_help_through_a_shell_pipe() -> None:
    result = subprocess.run(
        f"{sys.executable} -m dg16m_core.cli --help | head -1",
        shell=True,
        capture_output=True,
        text=True,
        check=True,
    )
    assert result.stdout.startswith("usage: dg16m")
    assert result.stderr == ""


# --------------------------------------------------------------------------------------------
# What a new user tripped on
# --------------------------------------------------------------------------------------------


def test_inspect_a_file_with_no_grasps(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    empty = io.DualGraspSet(
        grasps=np.zeros((0, 2, 4, 4)),
        contact_points=np.zeros((0, 4, 3)),
        contact_forces=np.zeros((0, 4, 3)),
        loss_values=np.zeros(0),
        passing_indices=np.zeros(0, dtype=np.int64),
        failed_indices=np.zeros(0, dtype=np.int64),
        object_file="box.obj",
        object_scale=1.0,
    )
    path = tmp_path / "empty.h5"
    io.write_dg16m(path, empty)
    assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    assert "0 (0 passing, 0 failing)" in out
    assert "the file stores no dual grasps" in out


def test_objects_make_with_a_bad_mass_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "objects"
    assert main(["objects", "make", "--mass", "-6", "--out", str(out)]) == 2
    assert "--mass: expected a positive finite number, found -6.0" in capsys.readouterr().err
    assert not out.exists()


def test_library_validates_before_writing(tmp_path: Path) -> None:
    from dataset_gen.sources.library import write_procedural_library
    from dataset_gen.sources.procedural import ProceduralError
    from dg16m_core.errors import MeshError

    with pytest.raises(MeshError, match="mass: expected a positive finite number"):
        write_procedural_library(tmp_path / "a", [("table", 0)], mass=0.0)
    with pytest.raises(ProceduralError):
        write_procedural_library(tmp_path / "b", [("table", 0), ("no_such_family", 0)])
    assert not (tmp_path / "a").exists()
    assert not (tmp_path / "b").exists()


def test_objects_show_limit_0_names_the_option(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(
        ["objects", "show", str(tmp_path), "--out", str(tmp_path / "x.png"), "--limit", "0"]
    )
    assert code == 2
    err = capsys.readouterr().err
    assert "--limit: expected an integer >= 1, found 0" in err
    assert "manifest" not in err


def test_show_help_says_how_n_is_split(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["show", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "dual grasps drawn in all: N/2 passing (left) and N/2 failing (right)" in out
    assert "10 + 10" in out


def test_verify_help_examples_name_files_that_generate_writes(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from dataset_gen.pipeline.generate import GRASPS_FOLDER
    from dataset_gen.sources.object_source import procedural_sources
    from dataset_gen.sources.procedural import object_id, object_specs

    with pytest.raises(SystemExit):
        main(["verify", "--help"])
    out = capsys.readouterr().out
    assert "dg16m generate --procedural 20 --out runs/dataset" in out
    source = procedural_sources(object_specs(20, seed=0))[0]
    assert source.object_id == object_id("table", 0)
    assert f"runs/dataset/{GRASPS_FOLDER}/{source.object_id}.h5" in out
    assert f"runs/dataset/{source.object_file}" in out


def test_objects_check_output_is_for_people(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import re

    import trimesh

    good = tmp_path / "good.obj"
    trimesh.creation.box(extents=(0.5, 0.3, 0.04)).export(good)
    assert main(["objects", "check", str(good)]) == 0
    out = capsys.readouterr().out
    assert not re.search(r"\d\.\d{7,}", out)  # no 17-digit floats
    assert "{" not in out
    assert "[" not in out
    assert "centre of mass (0.0000, 0.0000, 0.0000) m" in out
    assert "cleaning: nothing to clean" in out


def test_objects_check_suggests_scales(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import trimesh

    millimetres = tmp_path / "box_mm.obj"
    trimesh.creation.box(extents=(80.0, 50.0, 30.0)).export(millimetres)
    metres = tmp_path / "box_m.obj"
    trimesh.creation.box(extents=(0.8, 0.5, 0.3)).export(metres)
    assert main(["objects", "check", str(millimetres)]) == 1  # 80 units: the one units rule
    assert "needs --scale 0.01 (0.8 m" in capsys.readouterr().out
    assert main(["objects", "check", str(millimetres), "--scale", "0.001"]) == 0
    assert "0.080 x 0.050 x 0.030 m (scale 0.001)" in capsys.readouterr().out
    assert main(["objects", "check", str(millimetres), "--allow-any-size"]) == 0
    capsys.readouterr()
    assert main(["objects", "check", str(metres), "--scale", "0.001"]) == 1
    assert "--scale 0.001 looks wrong" in capsys.readouterr().out


def test_pyproject_uses_an_spdx_license_and_registers_every_command_module() -> None:
    import tomllib

    root = Path(__file__).resolve().parents[1]
    project = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))
    assert project["project"]["license"] == "MIT"
    entries = project["project"]["entry-points"][COMMAND_GROUP]
    assert {p.value for p in command_plugins()} == set(entries.values())
    for name, value in entries.items():
        assert value == f"{name}:register"
        module = root / name.replace(".", "/")
        assert module.with_suffix(".py").is_file() or (module / "__init__.py").is_file(), name


def test_library_code_never_switches_the_matplotlib_backend() -> None:
    root = Path(__file__).resolve().parents[1]
    for path in sorted(
        [*(root / "dataset_gen").rglob("*.py"), *(root / "dg16m_core").rglob("*.py")]
    ):
        text = path.read_text(encoding="utf-8")
        assert "matplotlib.use(" not in text, path
        assert "import matplotlib.pyplot" not in text, path
        assert "from matplotlib import pyplot" not in text, path
