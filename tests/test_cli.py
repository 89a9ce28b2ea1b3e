"""The ``dg16m`` command line: help texts, the objects workflow, pictures and errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from dataset_gen import io
from dataset_gen.cli import build_parser, main
from dataset_gen.library import load_library

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
]


def _image_is_a_picture(path: Path) -> None:
    image = matplotlib.image.imread(path)
    assert image.ndim == 3
    assert min(image.shape[:2]) > 300
    assert image[..., :3].std() > 0.05  # not blank


def test_console_script_help_lists_every_subcommand() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "dataset_gen.cli", "--help"],
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
    assert "watertight True" in out
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


def test_parser_is_built_from_command_modules() -> None:
    parser = build_parser()
    args = parser.parse_args(["grippers"])
    assert callable(args.handler)


@pytest.mark.real_data
def test_show_renders_the_real_release_file(real_data: Path, tmp_path: Path) -> None:
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
    from dataset_gen.render import select_pairs

    passed = np.array([True] * 3 + [False] * 30)
    p, f = select_pairs(passed, 10, seed=1)
    assert (len(p), len(f)) == (3, 7)  # failing pairs fill the missing passing slots
    p2, f2 = select_pairs(passed, 10, seed=1)
    assert (p.tolist(), f.tolist()) == (p2.tolist(), f2.tolist())
