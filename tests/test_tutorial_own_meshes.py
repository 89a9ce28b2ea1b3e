"""The "your own meshes" tutorial's quick path, run end to end (issue 41, part 5): its commands,
read from ``docs/tutorials/own_meshes.md`` and run as written, on two small non-watertight
meshes from another application, y up as OBJ files are by convention, one in metres and one in
centimetres (units guessed): they come out z up, standing on their legs (issue 55, item 4).

Two flags are added for speed only: ``--pitch-fraction 0.05`` (a coarser repair voxel) and
``--perturbations 0`` (the nominal trial alone); the paths are moved into ``tmp_path``.
"""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import numpy as np
import pytest
import trimesh

pytest.importorskip("mujoco")

from dg16m_core.cli import main as cli_main
from dg16m_env.benchmark.file import read_benchmark

TUTORIAL = Path(__file__).resolve().parents[1] / "docs" / "tutorials" / "own_meshes.md"
SPEED = {
    ("objects", "repair"): ["--pitch-fraction", "0.05", "--no-progress"],
    ("benchmark", "build"): ["--perturbations", "0", "--no-progress"],
}


def quick_path() -> list[list[str]]:
    """The commands of the tutorial's quick-path block, split as a shell would (comments off)."""
    text = TUTORIAL.read_text(encoding="utf-8")
    block = re.search(r"<!-- quick-path.*?```bash\n(.*?)```\n<!-- /quick-path -->", text, re.S)
    assert block, f"{TUTORIAL}: expected the quick-path block"
    return [shlex.split(line, comments=True) for line in block.group(1).splitlines() if line]


def bench_stool(scale: float) -> trimesh.Trimesh:
    """A 0.6 x 0.35 x 0.45 m bench: a 3 cm seat board on four 4 cm legs, five overlapping
    pieces, the seat missing two faces (open: a shell), times ``scale``."""
    seat = trimesh.creation.box(extents=(0.6, 0.35, 0.03)).apply_translation((0, 0, 0.435))
    seat = trimesh.Trimesh(seat.vertices, seat.faces[2:], process=False)
    legs = [
        trimesh.creation.box(extents=(0.04, 0.04, 0.43)).apply_translation((x, y, 0.215))
        for x in (-0.26, 0.26)
        for y in (-0.14, 0.14)
    ]
    return trimesh.util.concatenate([seat, *legs]).apply_scale(scale)


Z_UP_TO_Y_UP = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, -1.0, 0, 0], [0, 0, 0, 1.0]])
"""-90 degrees about x: how a y-up application writes a z-up model ((x, y, z) -> (x, z, -y))."""


def test_the_quick_path_runs_as_written_on_two_shells_one_in_centimetres(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("DG16M_CACHE_DIR", str(tmp_path / "cache"))
    raw = tmp_path / "raw_meshes"
    raw.mkdir()
    for name, scale in (("bench_m", 1.0), ("bench_cm", 100.0)):
        mesh = bench_stool(scale).apply_transform(Z_UP_TO_Y_UP)
        assert not mesh.is_watertight
        assert np.argmax(mesh.extents) == 0
        assert mesh.extents[1] > mesh.extents[2]  # 0.45 m tall along y
        mesh.export(raw / f"{name}.obj")

    commands = quick_path()
    assert [c[:3] for c in commands] == [
        ["dg16m", "objects", "repair"],
        ["dg16m", "objects", "check"],
        ["dg16m", "benchmark", "build"],
        ["dg16m", "benchmark", "info"],
    ]
    for command in commands:
        args = command[1:]
        args += SPEED.get((args[0], args[1]), [])
        code = cli_main(args)
        out = capsys.readouterr().out
        assert code == 0, f"{shlex.join(command)} -> {code}\n{out}"
        if args[:2] == ["objects", "repair"]:
            # the units guess says what it assumed, per mesh
            assert "units guessed: centimetres (60 units -> 0.6 m" in out
            assert "units guessed: metres (0.6 units -> 0.6 m" in out
            assert out.count("up axis y (assumed: OBJ files are y up by convention") == 2
        if args[:2] == ["objects", "check"]:
            assert "found 2 mesh files in my_meshes (skipped 1 other files)" in out
            assert "2 meshes: 2 solid, 0 shell, 0 failed" in out
            assert out.count("up axis z (detected: a folder written by dg16m") == 2
        if args[:2] == ["benchmark", "build"]:
            assert "(--stage-budget STAGE=SECONDS), the same at any machine load" in out

    # The repaired meshes are in metres: the centimetre file came out the same size.
    repaired = json.loads((tmp_path / "my_meshes" / "manifest.json").read_text())
    assert set(repaired["entries"]) == {"bench_m", "bench_cm"}
    sizes = [
        trimesh.load(tmp_path / "my_meshes" / f"{i}.obj", force="mesh").extents.max()
        for i in ("bench_m", "bench_cm")
    ]
    assert sizes[0] == pytest.approx(0.6, abs=0.02)
    assert sizes[1] == pytest.approx(sizes[0], abs=1e-3)
    # ... and stand upright: 0.45 m tall along z, the seat on top (more area high than low)
    for object_id in ("bench_m", "bench_cm"):
        mesh = trimesh.load(tmp_path / "my_meshes" / f"{object_id}.obj", force="mesh")
        assert mesh.extents[2] == pytest.approx(0.45, abs=0.03)
        assert mesh.extents[0] == pytest.approx(0.6, abs=0.03)
        top = mesh.bounds[1, 2] - 0.05
        assert mesh.area_faces[mesh.triangles_center[:, 2] > top].sum() > 0.3  # the seat board
    # Both benches admitted with the real-object settings.
    bench = read_benchmark(tmp_path / "runs" / "mine_bench" / "benchmark.h5")
    assert sorted(o.object_id for o in bench.objects) == ["bench_cm", "bench_m"]
    assert bench.arm_rows("fc_robust").any(), "the real settings draw fc_robust pairs"
    built = json.loads((tmp_path / "runs" / "mine_bench" / "manifest.json").read_text())
    assert "object_wall_s" not in built["parameters"]["limits"]  # CPU budgets only
    for entry in built["entries"].values():
        assert entry["status"] == "ok"
        assert set(entry["stage_seconds"]) >= {"screen", "decompose", "sample", "label"}
