"""Benchmarks of real meshes: a mesh folder end to end, DG16M files and ``dg16m generate``
folders, re-seating of hands that start inside the object, and the per-pair diagnostics
(hand-line distance, centres of mass) with files that predate them."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest

pytest.importorskip("mujoco")

from planks import DOWN, THICKNESS, dual, hand, plank
from shipped_meshes import MESHES

from dataset_gen.grasps.gripper import PANDA
from dataset_gen.io import DualGraspSet, read_manifest, write_dg16m
from dataset_gen.objects.decomposition import DecompositionParameters
from dg16m_core.cli import main as cli_main
from dg16m_env.benchmark.build import benchmark_object, build_benchmark
from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.model import (
    ARMS,
    SOURCES,
    BenchmarkError,
    BenchmarkParameters,
    hand_line_distance,
)
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.benchmark.report import HAND_LINE_BINS, benchmark_report, hand_line
from dg16m_env.benchmark.report_plot import plot_summary
from dg16m_env.benchmark.report_text import format_summary
from dg16m_env.benchmark.sources import file_benchmark_sources, mesh_benchmark_sources, split_id
from dg16m_env.physics.labels import PerturbationSpec
from dg16m_env.physics.reseat import DEFAULT_RESEAT_MAX, reseat_poses
from dg16m_env.physics.scene import compile_scene
from dg16m_env.physics.trial_measures import grasp_centres
from dg16m_env.physics.trial_protocol import InvalidReason, TrialProtocol, check_initial_poses

TINY = BenchmarkParameters(
    n_grasps=40,
    n_passing=4,
    n_failing=2,
    n_random=2,
    n_farthest=2,
    perturbation=PerturbationSpec(n_perturbations=1),
)
LIMIT = TrialProtocol().invalid_penetration


@pytest.fixture(scope="module", autouse=True)
def coacd_cache(tmp_path_factory: pytest.TempPathFactory):
    """Every decomposition of this module in one temporary cache (the dining table's is shared
    by the tests; nothing is written to the user's cache)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("DG16M_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
        yield


@pytest.fixture(scope="module")
def mesh_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("meshes")
    shutil.copy(MESHES / "dining_table.obj", folder / "dining_table.obj")
    return folder


@pytest.fixture(scope="module")
def mesh_build(mesh_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``dg16m benchmark build --meshes DIR --mesh-settings plain`` (no grasp files): the
    default pair counts, the nominal trial only (the real-object settings, the default for
    meshes, are run by tests/test_tutorial_own_meshes.py)."""
    out = tmp_path_factory.mktemp("mesh_bench")
    args = ["benchmark", "build", "--meshes", str(mesh_dir), "--out", str(out)]
    args += ["--mesh-settings", "plain"]
    assert cli_main([*args, "--perturbations", "0", "--no-progress"]) == 0
    return out


@pytest.fixture(scope="module")
def generated(mesh_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder written by ``dg16m generate`` from the mesh folder (grasps/, manifest.json)."""
    out = tmp_path_factory.mktemp("generated")
    args = ["generate", "--meshes", str(mesh_dir), "--out", str(out), "--grasps", "40"]
    assert cli_main([*args, "--max-passing", "4", "--max-failing", "4", "--no-progress"]) == 0
    return out


# --------------------------------------------------------------------------------------------
# A mesh folder, end to end
# --------------------------------------------------------------------------------------------


def test_cli_builds_a_benchmark_from_a_mesh_folder(
    mesh_build: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bench = read_benchmark(mesh_build / "benchmark.h5")
    obj = bench.objects[0]
    assert [o.object_id for o in bench.objects] == ["dining_table"]
    assert (obj.family, obj.seed, obj.file, obj.scale) == ("", -1, "dining_table.obj", 1.0)
    assert obj.parts, "the mesh is simulated through its convex parts"
    assert set(bench.source.tolist()) == {SOURCES.index(arm) for arm in ARMS}
    assert bench.labels.spec.trials == 1
    # The diagnostics are stored: the centre of mass, and each pair's hand-line distance
    # recomputed from its poses with the simulator's grasp centres.
    assert obj.center_of_mass is not None
    assert obj.center_of_mass.shape == (3,)
    assert obj.reseat_max == 0.0
    np.testing.assert_array_equal(bench.reseat_shift, np.zeros((bench.n, 2)))
    centres = bench.poses[:, :, :3, 3] + PANDA.contact_depth * bench.poses[:, :, :3, 1]
    np.testing.assert_allclose(
        bench.hand_line_distance, hand_line_distance(centres, obj.center_of_mass), atol=1e-12
    )
    # The manifest entry names invalid trials by reason.
    entry = read_manifest(mesh_build)["entries"]["dining_table"]
    assert entry["status"] == "ok"
    assert sum(entry["invalid_reasons"].values()) == entry["invalid"]
    assert "reseat" not in entry
    # benchmark info: the new sections, as text and JSON.
    assert cli_main(["benchmark", "info", str(mesh_build / "benchmark.h5")]) == 0
    out = capsys.readouterr().out
    for heading in (
        "re-seating: off",
        "hand-line distance",
        "GSR (mean p, full level) by distance bin",
        "a hand without contact at the end of close (< 1 contact)",
    ):
        assert heading in out, heading
    assert "nan" not in out.lower()
    assert cli_main(["benchmark", "info", str(mesh_build / "benchmark.h5"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    line = report["hand_line"]
    assert line["bins"] == list(HAND_LINE_BINS)
    for arm in ARMS:
        rows = bench.arm_rows(arm)
        assert sum(line["by_arm"][arm]["counts"]) == int(rows.sum())
        assert line["by_arm"][arm]["median_m"] == pytest.approx(
            float(np.median(bench.hand_line_distance[rows]))
        )
    contacts = report["contacts_after_close"]
    assert contacts["pooled"]["valid"] == int(bench.trials.valid.sum())


def test_split_ids_are_stems_or_file_names(mesh_dir: Path, tmp_path: Path) -> None:
    assert split_id("couch") == "couch"
    assert split_id("couch.obj") == split_id("couch.h5") == split_id("couch.STL") == "couch"
    assert split_id("table-1.5") == "table-1.5"
    shutil.copy(MESHES / "dining_table.obj", tmp_path / "other.obj")
    shutil.copy(MESHES / "dining_table.obj", tmp_path / "dining_table.obj")
    for split in (["dining_table"], ["dining_table.obj"], ["dining_table.h5"]):
        items = mesh_benchmark_sources(tmp_path, split)
        assert [i.object_id for i in items] == ["dining_table"]
    assert [i.object_id for i in mesh_benchmark_sources(tmp_path)] == ["dining_table", "other"]
    with pytest.raises(BenchmarkError, match="repeated"):
        mesh_benchmark_sources(tmp_path, ["other", "other.obj"])


def test_mesh_folder_errors_say_what_was_expected(
    mesh_dir: Path, generated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    out = str(tmp_path / "out")
    cases = [
        (["--meshes", str(empty)], "expected mesh files"),
        (["--meshes", str(tmp_path / "nope")], "found no folder"),
        (["--meshes", str(mesh_dir), "--split", "couch"], "found none for ['couch']"),
        (["--grasps", str(generated)], "expected --meshes"),
        (["--grasps", str(empty)], "expected DG16M files"),
        (["--meshes", str(mesh_dir), "--reseat"], "--reseat: expected only with --grasps"),
        (["--reseat", "10"], "--reseat: expected only with --grasps"),
        (["--grasps", str(generated), "--meshes", str(mesh_dir), "--reseat", "0"], "positive"),
        (["--grasps", str(generated), "--meshes", str(mesh_dir), "--scale", "2"], "--scale"),
        (["--split", "a"], "expected only with --meshes or --grasps"),
        (["--meshes", str(mesh_dir), "--limit", "0"], "--limit"),
        (["--meshes", str(mesh_dir), "--robust", "-1"], "--robust: expected an integer >= 0"),
    ]
    for extra, message in cases:
        assert cli_main(["benchmark", "build", "--out", out, *extra]) == 2, extra
        assert message in capsys.readouterr().err, extra


# --------------------------------------------------------------------------------------------
# DG16M files: a `dg16m generate` folder
# --------------------------------------------------------------------------------------------


def test_grasps_accepts_a_generate_folder(
    mesh_dir: Path, generated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert (generated / "grasps" / "dining_table.h5").is_file()
    for folder in (generated, generated / "grasps"):
        for split in (None, ["dining_table"], ["dining_table.h5"], ["dining_table.obj"]):
            items = file_benchmark_sources(mesh_dir, folder, split)
            assert [i.object_id for i in items] == ["dining_table"]
            assert items[0].grasp_file == generated / "grasps" / "dining_table.h5"
    # A generate folder that holds meshes/ (procedural objects) needs no --meshes.
    copy = tmp_path / "copy"
    (copy / "grasps").mkdir(parents=True)
    (copy / "meshes").mkdir()
    shutil.copy(generated / "grasps" / "dining_table.h5", copy / "grasps")
    shutil.copy(mesh_dir / "dining_table.obj", copy / "meshes")
    items = file_benchmark_sources(None, copy, ["dining_table.h5"], reseat_max=0.01)
    assert items[0].source.mesh == copy / "meshes" / "dining_table.obj"
    assert items[0].reseat_max == 0.01
    # The CLI end to end, split ids as file names, re-seating on (nothing to move: the file's
    # poses are the Panda's, made clear of the object's parts).
    out = tmp_path / "bench"
    args = ["benchmark", "build", "--grasps", str(generated), "--meshes", str(mesh_dir)]
    args += ["--split", "dining_table.h5", "--out", str(out), "--perturbations", "0"]
    assert cli_main([*args, "--reseat", "--no-progress"]) == 0
    capsys.readouterr()
    bench = read_benchmark(out / "benchmark.h5")
    assert set(bench.source.tolist()) <= {SOURCES.index("file_pass"), SOURCES.index("file_fail")}
    assert bench.objects[0].reseat_max == DEFAULT_RESEAT_MAX
    entry = read_manifest(out)["entries"]["dining_table"]
    assert entry["reseat"]["max_shift_m"] == DEFAULT_RESEAT_MAX
    assert entry["reseat"]["hands"] == 2 * bench.n
    assert entry["reseat"]["moved"] == int((bench.reseat_shift > 0).sum())
    assert read_manifest(out)["parameters"]["reseat_max"] == DEFAULT_RESEAT_MAX
    assert bench.metadata["reseat"]["dining_table"] == entry["reseat"]


# --------------------------------------------------------------------------------------------
# The new datasets: round trip, and files without them
# --------------------------------------------------------------------------------------------


def test_new_datasets_round_trip(mesh_build: Path, tmp_path: Path) -> None:
    bench = read_benchmark(mesh_build / "benchmark.h5")
    bench.reseat_shift[0] = (0.004, 0.0)  # as if re-seated
    bench.objects[0] = replace(bench.objects[0], reseat_max=0.01)
    path = tmp_path / "again.h5"
    write_benchmark(path, bench)
    again = read_benchmark(path)
    np.testing.assert_array_equal(again.reseat_shift, bench.reseat_shift)
    np.testing.assert_array_equal(again.hand_line_distance, bench.hand_line_distance)
    np.testing.assert_array_equal(again.objects[0].center_of_mass, bench.objects[0].center_of_mass)
    assert again.objects[0].reseat_max == 0.01
    with h5py.File(path) as f:
        assert f["grasps/reseat_shift"].dtype == np.float64
        assert f["grasps/reseat_shift"].shape == (bench.n, 2)
        assert f["grasps/hand_line_distance"].shape == (bench.n,)
        assert f["objects/centers_of_mass"].shape == (1, 3)
    report = benchmark_report(again)
    assert report["reseat"]["moved"] == 1
    assert report["reseat"]["median_m"] == pytest.approx(0.004)
    assert f"1 of {2 * bench.n} hands moved, median 4.0 mm, max 4.0 mm" in format_summary(again)
    # Subsets keep the new fields row by row.
    part = again.select_objects(["dining_table"])
    np.testing.assert_array_equal(part.hand_line_distance, again.hand_line_distance)
    # Bad values are refused.
    with h5py.File(path, "r+") as f:
        f["grasps/reseat_shift"][0, 0] = -1.0
    with pytest.raises(BenchmarkError, match="grasps/reseat_shift"):
        read_benchmark(path)


def test_files_without_the_new_datasets_still_read(mesh_build: Path, tmp_path: Path) -> None:
    old = tmp_path / "old.h5"
    shutil.copy(mesh_build / "benchmark.h5", old)
    with h5py.File(old, "r+") as f:
        for key in (
            "grasps/reseat_shift",
            "grasps/hand_line_distance",
            "objects/centers_of_mass",
            "objects/reseat_max",
        ):
            del f[key]
    bench = read_benchmark(old)
    assert bench.hand_line_distance is None
    assert bench.objects[0].center_of_mass is None
    assert bench.objects[0].reseat_max == 0.0
    np.testing.assert_array_equal(bench.reseat_shift, np.zeros((bench.n, 2)))
    assert hand_line(bench) is None
    text = format_summary(bench)
    assert "not stored (older file" in text
    plot_summary(bench, tmp_path / "old.png")
    assert (tmp_path / "old.png").stat().st_size > 10_000
    # Written again, it stays without the unknown fields (and reads the same).
    write_benchmark(tmp_path / "again.h5", bench)
    again = read_benchmark(tmp_path / "again.h5")
    assert again.hand_line_distance is None
    assert again.objects[0].center_of_mass is None


@pytest.mark.skipif(not EMBEDDED_BENCHMARK.is_file(), reason="no shipped benchmark file")
def test_the_shipped_file_carries_what_the_code_writes() -> None:
    """The shipped file was rebuilt with the current code (issue 29): it stores every dataset a
    build writes now, and its hand-line distances are those of its own poses and objects."""
    with h5py.File(EMBEDDED_BENCHMARK, "r") as f:
        for key in ("grasps/reseat_shift", "grasps/hand_line_distance"):
            assert key in f, key
    bench = read_benchmark(EMBEDDED_BENCHMARK)
    assert bench.hand_line_distance is not None
    assert bench.hand_line_distance.shape == (bench.n,)
    assert np.all(np.isfinite(bench.hand_line_distance))
    assert not bench.reseat_shift.any()  # the procedural benchmark is built without re-seating
    # the stored distances of one object's rows, recomputed from its scene and poses
    first = bench.objects[0]
    rows = bench.object_rows(first.object_id)
    loaded = first.load()
    centres = grasp_centres(compile_scene(loaded), bench.poses[rows])
    expected = hand_line_distance(centres, loaded.mass_properties.center_of_mass)
    np.testing.assert_allclose(bench.hand_line_distance[rows], expected, rtol=1e-6, atol=1e-9)
    report = benchmark_report(bench, n_resamples=50)
    assert report["hand_line"] is not None
    assert set(report["hand_line"]["by_arm"]) == {"fc_pass", "fc_fail", "random", "farthest"}
    assert report["reseat"]["objects"] == 0
    assert sum(sum(v.values()) for v in report["invalid_by_object"].values()) == int(
        (~bench.trials.valid).sum()
    )
    assert report["contacts_after_close"]["pooled"]["valid"] == int(bench.trials.valid.sum())
    assert "not stored (older file" not in format_summary(bench)


# --------------------------------------------------------------------------------------------
# Hand-line distance and re-seating on hand-made cases
# --------------------------------------------------------------------------------------------


def test_hand_line_distance_on_a_known_case() -> None:
    com = np.array([0.01, -0.02, 0.03])
    # Grasp centres on the line {z = com_z + 0.1, y = com_y}: 0.1 m from the centre of mass.
    centres = np.array([[[-0.3, -0.02, 0.13], [0.2, -0.02, 0.13]]])
    np.testing.assert_allclose(hand_line_distance(centres, com), [0.1])
    # A line through the centre of mass; coinciding centres give the distance to the point.
    through = np.array([[[-0.3, -0.02, 0.03], [0.2, -0.02, 0.03]], [[0.01, 0.0, 0.03]] * 2])
    np.testing.assert_allclose(hand_line_distance(through, com), [0.0, 0.02], atol=1e-15)
    # From hand poses: the simulator's grasp centres (the pads' centre, contact_depth along
    # the approach axis) of two hands squeezing a plank 0.04 m thick.
    obj = plank(0.6, 6.0)
    poses = dual(hand(-0.2, "y", DOWN), hand(0.2, "y", DOWN))[None]
    poses[:, :, 2, 3] += 0.05  # both pad centres 5 cm above the plank's axis
    scene = compile_scene(obj)
    centres = grasp_centres(scene, poses)
    np.testing.assert_allclose(centres[0, :, 2], [0.05, 0.05])
    distance = hand_line_distance(centres, obj.mass_properties.center_of_mass)
    np.testing.assert_allclose(distance, [0.05], atol=1e-9)


def _pushed(depth: float) -> np.ndarray:
    """(4, 4) a Panda hand over the plank (approach down) pushed so that its palm face sits
    ``depth`` m below the plank's top face."""
    pose = hand(-0.2, "y", DOWN)
    gap = PANDA.contact_depth - PANDA.palm_depth - THICKNESS / 2.0  # palm face above the top
    pose[:3, 3] += (gap + depth) * pose[:3, 1]
    return pose


def test_reseat_moves_a_pushed_hand_back_until_it_clears() -> None:
    obj = plank(0.6, 6.0)
    scene = compile_scene(obj)
    protocol = TrialProtocol()
    other = hand(0.2, "y", DOWN)
    poses = np.stack([dual(_pushed(0.005), other), dual(_pushed(0.02), other)])
    reason, _ = check_initial_poses(scene, poses, protocol)
    assert reason.tolist() == [InvalidReason.HAND0_PENETRATES] * 2
    result = reseat_poses(scene, poses, max_shift=0.01, limit=LIMIT)
    # 5 mm in, moved back 5 mm (1 mm steps: the first step with depth <= 0.5 mm) and valid.
    assert result.shift[0, 0] == pytest.approx(0.005, abs=1e-9)
    expected = poses[0, 0].copy()
    expected[:3, 3] -= 0.005 * expected[:3, 1]
    np.testing.assert_allclose(result.poses[0, 0], expected, atol=1e-12)
    # 20 mm in cannot clear within 10 mm: it stays where it was, its trial stays invalid.
    assert result.shift[1, 0] == 0.0
    np.testing.assert_array_equal(result.poses[1], poses[1])
    # The clear hands never move.
    assert (result.shift[:, 1] == 0).all()
    np.testing.assert_array_equal(result.poses[:, 1], poses[:, 1])
    reason, _ = check_initial_poses(scene, result.poses, protocol)
    assert reason.tolist() == [InvalidReason.NONE, InvalidReason.HAND0_PENETRATES]
    summary = result.summary()
    assert (summary["penetrating"], summary["moved"], summary["not_cleared"]) == (2, 1, 1)
    assert summary["median_m"] == pytest.approx(0.005)
    # Off: nothing moves.
    assert not reseat_poses(scene, poses, max_shift=0.0, limit=LIMIT).shift.any()


def test_reseat_through_a_dg16m_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--reseat on a DG16M file whose first pair starts 5 mm inside the object."""
    import trimesh

    meshes = tmp_path / "meshes"
    meshes.mkdir()
    length = 0.6
    trimesh.creation.box(extents=(length, THICKNESS, THICKNESS)).export(meshes / "plank.obj")
    other = hand(0.2, "y", DOWN)
    grasps = np.stack([dual(_pushed(0.005), other), dual(_pushed(0.02), other)])
    data = DualGraspSet(
        grasps=grasps,
        contact_points=np.zeros((2, 4, 3)),
        contact_forces=np.zeros((2, 4, 3)),
        loss_values=np.array([0.0, 1.0]),
        passing_indices=np.array([0]),
        failed_indices=np.array([1]),
        object_file="plank.obj",
        object_scale=1.0,
        metadata={"gripper": "panda"},
    )
    write_dg16m(tmp_path / "grasps" / "plank.h5", data)
    out = tmp_path / "bench"
    args = ["benchmark", "build", "--meshes", str(meshes), "--grasps", str(tmp_path / "grasps")]
    args += ["--out", str(out), "--perturbations", "1", "--reseat", "10", "--no-progress"]
    assert cli_main(args) == 0
    capsys.readouterr()
    bench = read_benchmark(out / "benchmark.h5")
    assert bench.n == 2
    assert bench.reseat_shift[0, 0] == pytest.approx(0.005, abs=1e-9)
    assert bench.reseat_shift[1].tolist() == [0.0, 0.0]
    assert bench.reseat_shift[0, 1] == 0.0
    np.testing.assert_array_equal(bench.poses[1], grasps[1])
    assert bench.trials.valid.tolist() == [True, False], "the hand that cannot clear stays"
    assert bench.trials.invalid_reasons() == {"hand0_penetrates": 1}
    entry = read_manifest(out)["entries"]["plank"]
    assert entry["invalid_reasons"] == {"hand0_penetrates": 1}
    assert (entry["reseat"]["moved"], entry["reseat"]["not_cleared"]) == (1, 1)
    assert cli_main(["benchmark", "info", str(out / "benchmark.h5")]) == 0
    text = capsys.readouterr().out
    assert "1 of 4 hands moved, median 5.0 mm, max 5.0 mm" in text
    assert "plank: hand0_penetrates 1" in text


# --------------------------------------------------------------------------------------------
# The real release file
# --------------------------------------------------------------------------------------------


@pytest.mark.real_data
def test_release_airplane_with_reseat(
    real_data: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The DG16M release's Robotiq 2F-85 poses on the airplane: most open Panda hands start
    inside a convex part; re-seating moves them back and reports how far."""
    # The open airplane needs CoACD's voxel repair: about 80 s on one core at the default
    # threshold, 30 s at 0.05. The coarser hulls test the same path. (A parameter, not a
    # monkeypatch: a mesh object is built in a child process, which sees no monkeypatch.)
    (tmp_path / "meshes").mkdir()
    (tmp_path / "grasps").mkdir()
    (tmp_path / "meshes" / "dg16m_airplane.obj").symlink_to(real_data / "dg16m_airplane.obj")
    (tmp_path / "grasps" / "dg16m_airplane.h5").symlink_to(real_data / "dg16m_airplane.h5")
    params = BenchmarkParameters(
        n_passing=10,
        n_failing=10,
        perturbation=PerturbationSpec(n_perturbations=0),
        decomposition=DecompositionParameters(threshold=0.05),
    )
    plain, moved = (
        file_benchmark_sources(tmp_path / "meshes", tmp_path / "grasps", reseat_max=reseat)[0]
        for reseat in (0.0, DEFAULT_RESEAT_MAX)
    )
    before = benchmark_object(plain, params)
    out = tmp_path / "bench"
    build_benchmark([moved], out, params, progress=False)
    after = read_benchmark(out / "benchmark.h5")
    np.testing.assert_array_equal(after.contact_points, before.contact_points)
    invalid_before = int((~before.trials.valid).sum())
    invalid_after = int((~after.trials.valid).sum())
    assert invalid_before > before.n // 2, "the release's poses mostly start inside the airplane"
    assert invalid_after < invalid_before
    shift = after.reseat_shift
    assert shift.max() <= DEFAULT_RESEAT_MAX + 1e-12
    moved_hands = shift > 0
    assert moved_hands.any()
    np.testing.assert_array_equal(after.poses[~moved_hands], before.poses[~moved_hands])
    entry = read_manifest(out)["entries"]["dg16m_airplane"]
    assert entry["reseat"]["moved"] == int(moved_hands.sum())
    assert entry["reseat"]["median_m"] == pytest.approx(float(np.median(shift[moved_hands])))
    assert sum(entry["invalid_reasons"].values()) == invalid_after
    assert cli_main(["benchmark", "info", str(out / "benchmark.h5")]) == 0
    text = capsys.readouterr().out
    assert f"{int(moved_hands.sum())} of {2 * after.n} hands moved" in text
    if invalid_after:
        assert "dg16m_airplane: hand" in text
