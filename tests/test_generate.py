"""Generator end to end: small objects, determinism across workers, resume, broken meshes."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dataset_gen.force_closure import evaluate
from dataset_gen.io import read_dg16m, read_manifest
from dataset_gen.pipeline.generate import (
    GenerationError,
    GenerationParameters,
    generate_dataset,
    generate_object,
)
from dataset_gen.sources.object_source import mesh_sources, object_seed, procedural_sources
from dataset_gen.sources.procedural import make_procedural_object
from dg16m_core.cli import main
from dg16m_core.parameters import PAPER

SMALL = GenerationParameters(n_grasps=60, max_passing=50, max_failing=50)
SPECS = [("table", 0), ("ladder", 1), ("crate", 2)]


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((folder / "grasps").glob("*.h5"))}


def test_generate_object_writes_a_consistent_release_schema_set() -> None:
    obj = make_procedural_object("table", 0)
    data = generate_object(obj, SMALL, object_file="meshes/table-0000000.obj")
    assert 0 < data.passing_indices.size <= 50
    assert 0 < data.failed_indices.size <= 50
    assert data.grasps.shape == (data.n, 2, 4, 4)
    # Stored verdicts and losses are reproduced by an independent Clarabel check.
    check = evaluate(data.contact_points, data.extras["contact_normals"], method="clarabel")
    assert check.passed[data.passing_indices].all()
    assert not check.passed[data.failed_indices].any()
    failing = data.failed_indices
    assert np.all(data.loss_values[failing] > 0.5)
    assert np.allclose(data.loss_values[failing], check.loss[failing], rtol=2e-3)
    # Forces push (physical convention) and carry the weight on passing pairs.
    forces = data.contact_forces[data.passing_indices]
    assert np.allclose(forces.sum(axis=1), [0, 0, 60.0], atol=1e-4)
    normals = data.extras["contact_normals"][data.passing_indices]
    assert np.all(np.einsum("nkj,nkj->nk", forces, normals) <= 1e-6)
    counts = data.metadata["counts"]
    assert counts["sampled"] == 60
    assert counts["pairs_pairs"] == 60 * 59 // 2
    assert data.metadata["object_seed"] == object_seed(0, "table-0000000")


def test_same_bytes_for_one_and_two_workers(tmp_path: Path) -> None:
    sources = procedural_sources(SPECS)
    generate_dataset(sources, tmp_path / "one", SMALL, workers=1, progress=False)
    generate_dataset(sources, tmp_path / "two", SMALL, workers=2, progress=False)
    one, two = _files(tmp_path / "one"), _files(tmp_path / "two")
    assert len(one) == 3
    assert one == two
    assert (tmp_path / "one/manifest.json").read_bytes() == (
        tmp_path / "two/manifest.json"
    ).read_bytes()


def test_rerun_skips_finished_objects_and_rejects_other_parameters(tmp_path: Path) -> None:
    sources = procedural_sources(SPECS[:2])
    generate_dataset(sources, tmp_path, SMALL, progress=False)
    seen: list[str] = []
    generate_dataset(
        sources, tmp_path, SMALL, progress=False, on_object=lambda i, e: seen.append(i)
    )
    assert seen == []
    with pytest.raises(GenerationError, match="same parameters"):
        generate_dataset(sources, tmp_path, GenerationParameters(n_grasps=61), progress=False)


def test_meshes_are_not_merged_into_a_procedural_dataset(tmp_path: Path) -> None:
    """One dataset holds one kind of object: adding the other kind is refused, with nothing in
    the folder changed; the entries say which kind made them (older ones are inferred)."""
    out = tmp_path / "ds"
    manifest = generate_dataset(procedural_sources(SPECS[:1]), out, SMALL, progress=False)
    assert manifest["entries"]["table-0000000"]["source"] == "procedural"
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    make_procedural_object("ladder", 1).mesh.export(meshes / "ladder.obj")
    before = {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
    with pytest.raises(GenerationError, match=r"expected a dataset of mesh objects.*1 procedural"):
        generate_dataset(mesh_sources(meshes), out, SMALL, progress=False)
    assert {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()} == before
    # a manifest written before entries named their kind: inferred from the stored mesh
    import json

    path = out / "manifest.json"
    old = json.loads(path.read_text())
    del old["entries"]["table-0000000"]["source"]
    path.write_text(json.dumps(old))
    with pytest.raises(GenerationError, match="1 procedural"):
        generate_dataset(mesh_sources(meshes), out, SMALL, progress=False)
    mine = generate_dataset(mesh_sources(meshes), tmp_path / "m", SMALL, progress=False)
    assert mine["entries"]["ladder"]["source"] == "mesh"


def test_ids_select_a_subset_of_a_mesh_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--ids takes a file of ids, a JSON file's list (split.json:train) or a,b,c; unknown ids
    and --ids without --meshes are refused before anything runs."""
    import json

    from dataset_gen.sources.object_source import read_ids, select_sources
    from dg16m_core.errors import MeshError

    meshes = tmp_path / "meshes"
    meshes.mkdir()
    for family, seed in SPECS:
        make_procedural_object(family, seed).mesh.export(meshes / f"{family}.obj")
    (tmp_path / "ids.txt").write_text("# two of them\nladder\ncrate  # boxy\n")
    (tmp_path / "split.json").write_text(json.dumps({"train": ["crate"], "bad": 3}))
    assert read_ids(str(tmp_path / "ids.txt")) == ["ladder", "crate"]
    assert read_ids(f"{tmp_path / 'split.json'}:train") == ["crate"]
    assert read_ids("table, crate") == ["table", "crate"]
    with pytest.raises(MeshError, match="expected key 'bad' to hold a list of ids, found int"):
        read_ids(f"{tmp_path / 'split.json'}:bad")
    with pytest.raises(MeshError, match="found 1 unknown: chair"):
        select_sources(mesh_sources(meshes), ["table", "chair"])
    with pytest.raises(MeshError, match="expected each id once"):
        select_sources(mesh_sources(meshes), ["table", "table"])
    out = tmp_path / "out"
    argv = ["generate", "--meshes", str(meshes), "--ids", f"{tmp_path / 'split.json'}:train"]
    assert main([*argv, "--out", str(out), "--grasps", "60", "--no-progress"]) == 0
    assert sorted(read_manifest(out)["entries"]) == ["crate"]
    assert main(["generate", "--procedural", "1", "--ids", "a", "--out", str(tmp_path / "p")]) == 2
    assert "--ids: expected --meshes" in capsys.readouterr().err


def test_kill_9_then_resume_gives_the_same_bytes(tmp_path: Path) -> None:
    reference = tmp_path / "reference"
    generate_dataset(procedural_sources(SPECS), reference, SMALL, progress=False)
    out = tmp_path / "killed"
    script = (
        "from dataset_gen.pipeline.generate import *\n"
        "from dataset_gen.sources.object_source import procedural_sources\n"
        f"p = GenerationParameters(n_grasps=60, max_passing=50, max_failing=50)\n"
        f"generate_dataset(procedural_sources({SPECS!r}), {str(out)!r}, p, progress=False)\n"
    )
    process = subprocess.Popen([sys.executable, "-c", script])
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list((out / "grasps").glob("*.h5")):
        time.sleep(0.02)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    finished_before = len(list((out / "grasps").glob("*.h5")))
    assert finished_before < 3  # it was interrupted mid-run
    generate_dataset(procedural_sources(SPECS), out, SMALL, progress=False)
    assert _files(out) == _files(reference)
    assert not list((out / "grasps").glob(".*tmp*"))
    assert (out / "manifest.json").read_bytes() == (reference / "manifest.json").read_bytes()


def test_a_broken_mesh_fails_only_its_own_object(tmp_path: Path) -> None:
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    make_procedural_object("ladder", 1).mesh.export(meshes / "ladder.obj")
    (meshes / "broken.obj").write_text("v 0 0 0\nv 1 0 0\nf 1 2 7\nthis is not a mesh\n")
    manifest = generate_dataset(mesh_sources(meshes), tmp_path / "out", SMALL, progress=False)
    assert manifest["entries"]["ladder"]["status"] == "ok"
    broken = manifest["entries"]["broken"]
    assert broken["status"] == "failed"
    assert "broken.obj" in broken["error"]
    assert read_dg16m(tmp_path / "out/grasps/ladder.h5").n > 0
    assert read_manifest(tmp_path / "out") == manifest


def test_cli_generate_and_stats(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "data"
    code = main(
        [
            "generate",
            "--procedural",
            "2",
            "--out",
            str(out),
            "--grasps",
            "60",
            "--max-passing",
            "40",
            "--max-failing",
            "40",
            "--no-progress",
        ]
    )
    assert code == 0
    assert "2 objects ok, 0 failed" in capsys.readouterr().out
    mesh = next((out / "meshes").glob("*.obj"))
    grasps = out / "grasps" / f"{mesh.stem}.h5"
    assert main(["verify", str(grasps), "--mesh", str(mesh), "--strict"]) == 0
    assert "100.00% of verdicts" in capsys.readouterr().out
    code = main(["stats", str(out), "--out", str(tmp_path / "stats")])
    assert code == 0
    text = capsys.readouterr().out
    assert "passing_pairs" in text
    assert not re.search(r"\d\.\d{7,}", text)  # rates printed for people, not 17 digits
    for name in ("quality_hist.png", "passes_per_object.png", "loss_hist.png", "stats.json"):
        assert (tmp_path / "stats" / name).stat().st_size > 0


def test_cli_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["generate", "--meshes", str(tmp_path / "none"), "--out", str(tmp_path)]) == 2
    assert "expected a folder of mesh files" in capsys.readouterr().err
    assert main(["generate", "--procedural", "2", "--out", str(tmp_path), "--workers", "0"]) == 2


def test_parameters_default_to_the_paper_and_are_checked() -> None:
    params = GenerationParameters()
    for name in (
        "n_grasps",
        "mu",
        "mass",
        "gravity",
        "f_high",
        "threshold",
        "min_center_distance",
        "max_passing",
        "max_failing",
        "failing_min_loss",
    ):
        assert getattr(params, name) == getattr(PAPER, name), name
    for kwargs, message in [
        ({"n_grasps": 1}, "n_grasps: expected an integer >= 2, found 1"),
        ({"max_passing": -1}, "max_passing: expected an integer >= 0, found -1"),
        ({"seed": 1.5}, "seed: expected an integer >= 0, found 1.5"),
        ({"mass": -6.0}, "mass: expected a positive finite number, found -6.0"),
        ({"mu": float("nan")}, "mu: expected a positive finite number, found nan"),
        ({"min_center_distance": -0.1}, "min_center_distance: expected a finite number >= 0"),
        ({"convention": "outward"}, "convention: expected one of ('physical', 'release')"),
        ({"check_gripper_collision": 1}, "check_gripper_collision: expected True or False"),
    ]:
        with pytest.raises(GenerationError, match=re.escape(message)):
            GenerationParameters(**kwargs)
    assert GenerationParameters(min_center_distance=0.0, failing_min_loss=0.0).n_grasps == 500


def test_generate_help_defaults_come_from_the_paper(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["generate", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert f"single-arm grasps per object (default: {PAPER.n_grasps})" in out
    assert f"passing pairs kept per object (default: {PAPER.max_passing})" in out
    assert f"keep up to {PAPER.max_passing} passing and {PAPER.max_failing} failing pairs" in out


def test_generate_exits_1_and_names_every_failed_object(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A broken mesh, a box 80 units long (80 m: refused with the scale to use)
    and an object too small for two hands (no pairs) each fail; the run goes on and exits 1."""
    import trimesh

    meshes = tmp_path / "meshes"
    meshes.mkdir()
    make_procedural_object("ladder", 1).mesh.export(meshes / "ladder.obj")
    (meshes / "broken.obj").write_text("v 0 0 0\nv 1 0 0\nf 1 2 7\n")
    trimesh.creation.box(extents=(80.0, 50.0, 30.0)).export(meshes / "box_mm.obj")
    out = tmp_path / "out"
    argv = ["generate", "--meshes", str(meshes), "--out", str(out), "--no-progress"]
    small = ["--grasps", "60", "--max-passing", "50", "--max-failing", "50"]
    assert main(argv + small) == 1
    text = capsys.readouterr().out
    assert "1 objects ok, 2 failed" in text
    assert "failed box_mm: " in text
    assert "longest side 80 m: expected 0.05-5 m for a dual-arm object" in text
    # one units rule everywhere (issue 55): 80 units read as centimetres give a typical 0.8 m
    assert "a file in centimetres needs --scale 0.01" in text
    assert "failed broken: " in text
    entries = read_manifest(out)["entries"]
    assert entries["box_mm"]["status"] == "failed"

    # The same box at its true size is accepted with the override but holds no dual grasp.
    tiny = tmp_path / "tiny"
    tiny.mkdir()
    trimesh.creation.box(extents=(0.08, 0.05, 0.03)).export(tiny / "box.obj")
    out = tmp_path / "tiny_out"
    argv = ["generate", "--meshes", str(tiny), "--out", str(out), "--no-progress"]
    assert main([*argv, *small, "--allow-any-size"]) == 1
    text = capsys.readouterr().out
    assert "0 objects ok, 1 failed" in text
    assert "failed box: no dual grasps:" in text
    entry = read_manifest(out)["entries"]["box"]
    assert entry["status"] == "failed"
    assert entry["error"].startswith("no dual grasps:")
    assert entry["counts"]["pairs_remaining"] == 0
    assert not (out / "grasps" / "box.h5").exists()


@pytest.mark.slow
def test_ray_backend_gives_the_same_bytes(tmp_path: Path) -> None:
    pytest.importorskip("ray")
    sources = procedural_sources(SPECS[:2])
    generate_dataset(sources, tmp_path / "local", SMALL, progress=False)
    generate_dataset(sources, tmp_path / "ray", SMALL, backend="ray", progress=False)
    assert _files(tmp_path / "local") == _files(tmp_path / "ray")
