"""``dg16m`` starts at once (issue 45): building the parser, ``dg16m --help`` and
``dg16m --version`` import none of the heavy libraries.

Each check runs a fresh interpreter (this test process has imported everything already) and
reads which modules it imported. No timing here (``bench/cli_startup.py`` times it): the imports
are what make the time, and they do not depend on the machine's load.
"""

from __future__ import annotations

import argparse
import ast
import os
import subprocess
import sys

import pytest

from dg16m_core.cli import add_command, build_parser

HEAVY = (
    "torch",
    "mujoco",
    "ray",
    "trimesh",
    "scipy",
    "h5py",
    "matplotlib",
    "dm_control",
    "numba",
    "sklearn",
    "stable_baselines3",
    "cvxpy",
    "clarabel",
    "coacd",
)
"""Top-level packages that building the ``dg16m`` parser must not import. Gymnasium (with
numpy, about 0.09 s) is not among them: ``import dg16m_env``, which the ``dg16m_env`` command
modules cannot avoid, registers the environments (DESIGN.md), and that imports Gymnasium."""

BUILD_PARSER = "import sys; from dg16m_core.cli import build_parser; build_parser(); print(sorted(sys.modules))"

#: Deferred parsers (their defaults live in modules that import trimesh or MuJoCo), each with a
#: text its help shows once its arguments are added.
DEFERRED = {
    ("objects", "decompose"): "CoACD concavity threshold in (0, 1] (default: 0.01)",
    ("objects", "import-sweethome3d"): "--pitch-fraction",
    ("benchmark", "split-real"): "share of the 300 benchmark objects",
    ("benchmark", "build-real"): "--simulator {mujoco,warp}",
    ("sim", "replay"): "--coacd-threshold T",
    ("sim", "run"): "--coacd-threshold T",
}


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *args],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
        env={**os.environ, "COLUMNS": "100"},
    )


def _heavy(modules: list[str]) -> list[str]:
    """The packages of :data:`HEAVY` that ``modules`` (or their submodules) are in."""
    return sorted({m.split(".", 1)[0] for m in modules} & set(HEAVY))


def test_building_the_whole_parser_imports_no_heavy_library() -> None:
    modules = ast.literal_eval(_run("-c", BUILD_PARSER).stdout)  # that process's sys.modules
    assert "dataset_gen.cli.objects" in modules
    assert "leaderboard.commands" in modules
    assert _heavy(modules) == [], f"expected no heavy import, found {_heavy(modules)}"


#: What the ``dg16m`` console script runs (``sys.exit(main())``), reporting the imported modules
#: on stderr when the interpreter exits (after argparse's ``SystemExit`` for --help/--version).
CONSOLE_SCRIPT = (
    "import atexit, sys; "
    "atexit.register(lambda: sys.stderr.write(repr(sorted(sys.modules)))); "
    "from dg16m_core.cli import main; sys.argv[0] = 'dg16m'; sys.exit(main())"
)


@pytest.mark.parametrize("option", ["--help", "--version"])
def test_help_and_version_import_no_heavy_library(option: str) -> None:
    result = _run("-c", CONSOLE_SCRIPT, option)
    assert result.stdout.startswith("usage: dg16m" if option == "--help" else "dg16m ")
    modules = ast.literal_eval(result.stderr)
    assert "dg16m_env.cli.benchmark" in modules  # every plugin registered
    assert _heavy(modules) == [], f"expected no heavy import, found {_heavy(modules)}"


def test_python_m_help_lists_the_commands_and_imports_no_heavy_library() -> None:
    """``python -m dg16m_core.cli --help``, read with ``-X importtime`` (which reports the
    modules imported by ``import`` statements: every heavy library comes in through one)."""
    result = _run("-X", "importtime", "-m", "dg16m_core.cli", "--help")
    assert "benchmark" in result.stdout
    assert "leaderboard" in result.stdout
    modules = [
        line.rsplit("|", 1)[1].strip()
        for line in result.stderr.splitlines()
        if line.startswith("import time:") and line.count("|") == 2
    ]
    assert "dg16m_env.physics.simulator" in modules  # the report is read right
    assert _heavy(modules) == [], f"expected no heavy import, found {_heavy(modules)}"


def test_the_version_is_the_installed_distributions() -> None:
    from importlib import metadata

    from dg16m_core.distribution import DISTRIBUTION

    assert _run("-m", "dg16m_core.cli", "--version").stdout.split() == [
        "dg16m",
        metadata.version(DISTRIBUTION),
    ]


def test_deferred_commands_show_their_arguments_and_parse() -> None:
    """A command whose arguments are added on use shows them in its help and parses them."""
    parser = build_parser()
    for (command, action), text in DEFERRED.items():
        sub = parser._subparsers._group_actions[0].choices[command]  # type: ignore[union-attr]
        leaf = sub._subparsers._group_actions[0].choices[action]  # type: ignore[union-attr]
        assert text in leaf.format_help(), (command, action)
    args = build_parser().parse_args(["objects", "decompose", "a.obj"])
    assert args.threshold == 0.01
    assert callable(args.handler)
    args = build_parser().parse_args(["benchmark", "split-real", "--meshes", "m", "--out", "s"])
    assert args.size == 300
    assert callable(args.handler)


def test_add_command_adds_deferred_arguments_once_on_first_use(
    capsys: pytest.CaptureFixture[str],
) -> None:
    calls: list[str] = []

    def arguments(parser: argparse.ArgumentParser) -> None:
        calls.append("arguments")
        parser.add_argument("--size", type=int, default=3, help="how many (default 3)")

    def description() -> str:
        calls.append("description")
        return "A long description, 95%% of it made on use."

    root = argparse.ArgumentParser(prog="dg16m")
    sub = root.add_subparsers(dest="command")
    add_command(
        sub, "late", "One line.", "  dg16m late\n", description=description, arguments=arguments
    )
    assert calls == []
    assert "late" in root.format_help()
    assert calls == []
    assert root.parse_args(["late", "--size", "5"]).size == 5
    assert calls == ["description", "arguments"]
    with pytest.raises(SystemExit):
        root.parse_args(["late", "--help"])
    out = capsys.readouterr().out
    assert "A long description, 95% of it made on use." in out
    assert "how many (default 3)" in out
    assert calls == ["description", "arguments"]  # once
    with pytest.raises(TypeError):
        add_command(sub, "bad", "One line.", "  dg16m bad\n", description=description)


def test_importing_the_package_registers_the_environments() -> None:
    """``import dg16m_env`` registers every environment id (and its bare alias) in a fresh
    interpreter, without importing any environment's module (they load on ``gym.make``)."""
    code = (
        "import sys, gymnasium, dg16m_env; from dg16m_env.envs import env_ids; "
        "print(all(i in gymnasium.registry for i in env_ids(aliases=True)), "
        "'dg16m_env.envs.lift.task' in sys.modules, 'mujoco' in sys.modules)"
    )
    assert _run("-c", code).stdout.split() == ["True", "False", "False"]
