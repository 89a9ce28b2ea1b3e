"""Replaying a trial (dg16m_env.physics.replay) and ``dg16m sim``: stepped trials agree with the C rollout,
frames are pictures of the requested size, strips and GIFs are written, the CLI reports errors."""

from __future__ import annotations

import argparse
import json
import re
import shutil
from pathlib import Path

import h5py
import mujoco
import numpy as np
import pytest
from PIL import Image

import dg16m_core.cli
from dg16m_core.errors import Dg16mError
from dg16m_env.benchmark.build import build_benchmark
from dg16m_env.benchmark.file import read_benchmark
from dg16m_env.benchmark.model import Benchmark, BenchmarkParameters
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.benchmark.sources import procedural_benchmark_sources
from dg16m_env.cli.sim import register
from dg16m_env.physics import replay as replay_module
from dg16m_env.physics.labels import PerturbationSpec
from dg16m_env.physics.replay import (
    RenderError,
    ReplayError,
    frame_steps,
    make_renderer,
    render_model,
    step_trial,
    trial_frames,
    write_gif,
    write_strip,
)
from dg16m_env.physics.scene import Scene, compile_scene
from dg16m_env.physics.trial import run_trials
from dg16m_env.physics.trial_protocol import TrialStatus, simulate


@pytest.fixture(scope="module")
def bench_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("bench")
    params = BenchmarkParameters(
        n_grasps=40,
        n_passing=3,
        n_failing=2,
        n_random=2,
        n_farthest=2,
        perturbation=PerturbationSpec(n_perturbations=1),
    )
    return build_benchmark(procedural_benchmark_sources(1), out, params, progress=False)


@pytest.fixture(scope="module")
def bench(bench_path: Path) -> Benchmark:
    return read_benchmark(bench_path)


@pytest.fixture(scope="module")
def scene(bench: Benchmark) -> Scene:
    item = bench.objects[0]
    return compile_scene(item.load(), params=bench.parameters().scene, parts=item.parts)


@pytest.fixture(scope="module")
def can_render(scene: Scene) -> None:
    try:
        make_renderer(render_model(scene, 64, 48), 48, 64).close()
    except RenderError as exc:
        pytest.skip(f"no offscreen OpenGL here: {exc}")


def _ran_row(bench: Benchmark, failed: bool | None = None) -> int:
    status = bench.trials.status
    rows = np.flatnonzero(status != TrialStatus.INVALID)
    if failed is not None:
        rows = rows[(status[rows] == TrialStatus.FAILED) == failed]
    if rows.size == 0:
        pytest.skip("the tiny benchmark has no such row")
    return int(rows[0])


# --------------------------------------------------------------------------------------------
# Stepping (no rendering)
# --------------------------------------------------------------------------------------------


def test_stepped_trials_match_run_trials(scene: Scene, bench: Benchmark) -> None:
    protocol = bench.trials.protocol
    rerun = run_trials(scene, bench.poses, protocol)
    for row in range(bench.n):
        stepped = step_trial(scene, bench.poses[row], protocol)
        assert stepped.results.status[0] == rerun.status[row] == bench.trials.status[row]
        assert stepped.results.failing_phase[0] == rerun.failing_phase[row]
        assert stepped.results.invalid_reason[0] == rerun.invalid_reason[row]
        # run_trials restarts the rollout between segments (warm start dropped): close, not equal
        np.testing.assert_allclose(
            stepped.results.max_displacement[0], rerun.max_displacement[row], atol=1e-5
        )


def test_stepping_equals_one_continuous_rollout(scene: Scene, bench: Benchmark) -> None:
    row = _ran_row(bench)
    stepped = step_trial(scene, bench.poses[row], bench.trials.protocol)
    states, _, plan = simulate(scene, bench.poses[row : row + 1], bench.trials.protocol)
    assert stepped.states.shape == (plan.nstep + 1, states.shape[2])
    np.testing.assert_array_equal(stepped.states[1:], states[0])
    assert stepped.slip[0] == 0.0
    assert np.nanmax(stepped.slip[: stepped.end + 1]) == pytest.approx(
        stepped.results.max_displacement[0]
    )


def test_stepped_trial_and_replay_print_short(scene: Scene, bench: Benchmark) -> None:
    row = _ran_row(bench)
    stepped = step_trial(scene, bench.poses[row], bench.trials.protocol)
    text = repr(stepped)
    assert text.startswith(f"SteppedTrial({stepped.plan.nstep} steps: ")
    assert len(text) < 200
    assert repr(scene).startswith(f"Scene({scene.object_id!r}, mass ")
    assert len(repr(scene)) < 200


def test_frame_steps_include_key_steps(scene: Scene, bench: Benchmark) -> None:
    row = _ran_row(bench, failed=True)
    stepped = step_trial(scene, bench.poses[row], bench.trials.protocol)
    steps = frame_steps(stepped, 5)
    assert steps[0] == 0
    assert steps[-1] == stepped.end < stepped.plan.nstep
    assert stepped.first_out in steps
    if stepped.plan.close_end <= stepped.end:
        assert stepped.plan.close_end in steps
    with pytest.raises(ReplayError):
        frame_steps(stepped, 0)


def test_renderer_failure_is_a_render_error(scene: Scene, monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(*args, **kwargs):
        raise mujoco.FatalError("an OpenGL platform library has not been loaded")

    monkeypatch.setattr(replay_module.mujoco, "Renderer", broken)
    with pytest.raises(RenderError, match="MUJOCO_GL=egl or MUJOCO_GL=osmesa") as info:
        make_renderer(scene.model, 48, 64)
    assert isinstance(info.value, Dg16mError)


def test_write_strip_rejects_mismatched_captions(tmp_path: Path) -> None:
    with pytest.raises(ReplayError, match="one per frame"):
        write_strip([np.zeros((20, 30, 3), np.uint8)], ["a", "b"], tmp_path / "s.png")
    assert not (tmp_path / "s.png").exists()


# --------------------------------------------------------------------------------------------
# Rendering and files
# --------------------------------------------------------------------------------------------


def test_frames_have_the_size_and_are_pictures(
    can_render: None, scene: Scene, bench: Benchmark
) -> None:
    row = _ran_row(bench, failed=True)
    frames, captions = trial_frames(
        scene, bench.poses[row], bench.trials.protocol, n_frames=4, width=160, height=120
    )
    assert len(frames) == len(captions) >= 4
    for frame in frames:
        assert frame.shape == (120, 160, 3)
        assert frame.dtype == np.uint8
        assert frame.std() > 0
    assert captions[0].startswith("t=0.00 s  close  slip 0.0 mm")
    assert "slip" in captions[-1]
    assert " mm" in captions[-1]
    assert not np.array_equal(frames[0], frames[-1])  # the object moved


def test_invalid_grasp_gives_one_frame(can_render: None, scene: Scene, bench: Benchmark) -> None:
    rows = np.flatnonzero(bench.trials.status == TrialStatus.INVALID)
    if rows.size == 0:
        pytest.skip("the tiny benchmark has no invalid row")
    frames, captions = trial_frames(scene, bench.poses[rows[0]], width=64, height=48)
    assert len(frames) == 1
    assert "invalid" in captions[0]


def test_strip_and_gif_are_written(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import matplotlib

    def refuse(*args, **kwargs):
        raise AssertionError("library code called matplotlib.use")

    monkeypatch.setattr(matplotlib, "use", refuse)  # figures are built on Figure, no pyplot
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 255, (48, 64, 3), dtype=np.uint8) for _ in range(6)]
    captions = [f"t={i / 10:.2f} s  close  slip 0.0 mm" for i in range(6)]
    strip = write_strip(frames, captions, tmp_path / "strip.png", title="row 0")
    with Image.open(strip) as image:  # 6 frames: 3 columns x 2 rows, no empty cell
        assert image.format == "PNG"
        assert 3 * 64 <= image.width < 4 * 64
        assert image.height >= 2 * 48
    eight = write_strip(frames + frames[:2], captions + captions[:2], tmp_path / "eight.png")
    with Image.open(eight) as image:  # 8 frames: 4 x 2
        assert 4 * 64 <= image.width < 5 * 64
        assert 2 * 48 <= image.height < 3 * 48 + 100
    eight.unlink()
    gif = write_gif(frames, tmp_path / "anim.gif", fps=5, captions=captions)
    with Image.open(gif) as image:
        assert image.format == "GIF"
        assert image.n_frames == 6
        assert image.size[0] == 64
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim.gif", "strip.png"]


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------


@pytest.fixture
def with_sim() -> None:
    """``dg16m sim`` comes from dg16m_env's entry point (the package must be installed)."""
    values = [plugin.value for plugin in dg16m_core.cli.command_plugins()]
    assert "dg16m_env.cli.sim:register" in values, values


@pytest.mark.parametrize("argv", [["sim"], ["sim", "replay"], ["sim", "run"]])
def test_help_has_examples(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser(prog="dg16m")
    register(parser.add_subparsers(dest="command"))
    with pytest.raises(SystemExit) as info:
        parser.parse_args([*argv, "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out
    assert "dg16m " + " ".join(argv) in out


def test_replay_help_says_how_frames_are_chosen(capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 43: the help said frames are spread evenly; a strip shows ends of distinct phases
    (:func:`frame_steps`), an animation frames spread in time, key frames on top."""
    from dg16m_env.physics.trial_protocol import PHASES

    parser = argparse.ArgumentParser(prog="dg16m")
    register(parser.add_subparsers(dest="command"))
    with pytest.raises(SystemExit):
        parser.parse_args(["sim", "replay", "--help"])
    out = " ".join(capsys.readouterr().out.split())  # argparse's line breaks undone
    assert f"Its {len(PHASES)} phases" in out
    assert "at most one frame per phase" in out
    assert "more frames (a GIF) are spread evenly in time" in out
    assert "a few frames more than N" in out
    assert "frames spread evenly over the part" not in out
    assert "evenly spread frames" not in out


def test_cli_replay_writes_a_strip(
    with_sim: None,
    can_render: None,
    bench_path: Path,
    bench: Benchmark,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    row = _ran_row(bench)
    out = tmp_path / "strip.png"
    argv = ["sim", "replay", str(bench_path), "--row", str(row), "--out", str(out)]
    assert dg16m_core.cli.main([*argv, "--frames", "3", "--size", "96x72"]) == 0
    printed = capsys.readouterr().out
    assert "stored nominal trial:" in printed
    assert "success probability:" in printed
    assert "replayed:" in printed
    assert "note:" not in printed
    with Image.open(out) as image:
        assert image.format == "PNG"
        assert image.width >= 3 * 96
    # A perturbed trial, rebuilt from the stored seed, replays to its stored verdict.
    last = bench.labels.spec.trials - 1
    assert dg16m_core.cli.main([*argv, "--trial", str(last), "--frames", "2"]) == 0
    printed = capsys.readouterr().out
    assert f"stored perturbed trial {last}:" in printed
    assert "note:" not in printed
    assert dg16m_core.cli.main([*argv, "--trial", str(last + 1)]) == 2
    assert (
        "--trial: expected a trial (0 nominal, 1..K perturbed) in [0, " in capsys.readouterr().err
    )


@pytest.mark.skipif(not EMBEDDED_BENCHMARK.is_file(), reason="no shipped benchmark file")
def test_cli_replay_defaults_to_the_shipped_benchmark(
    with_sim: None, can_render: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "row1.png"
    assert (
        dg16m_core.cli.main(
            ["sim", "replay", "--row", "1", "--out", str(out), "--frames", "2", "--size", "96x72"]
        )
        == 0
    )
    assert str(EMBEDDED_BENCHMARK) in capsys.readouterr().out
    assert out.stat().st_size > 1000


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--row", "999"], "expected a row in [0, 7), found 999"),
        (["--row", "-1"], "expected a row in [0, 7), found -1"),
        (["--row", "0", "--size", "5x5"], "--size 5x5"),
        (["--row", "0", "--index", "1"], "--index: expected only with --grasps"),
        (["--row", "0", "--frames", "0"], "--frames: expected an integer >= 1"),
    ],
)
def test_cli_replay_bad_input_exits_2(
    with_sim: None,
    bench_path: Path,
    bench: Benchmark,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    message: str,
) -> None:
    message = message.replace("[0, 7)", f"[0, {bench.n})")
    argv = ["sim", "replay", str(bench_path), "--out", str(tmp_path / "x.png"), *extra]
    assert dg16m_core.cli.main(argv) == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.count("\n") == 1
    assert not (tmp_path / "x.png").exists()


def test_cli_replay_rejects_other_suffixes(
    with_sim: None, bench_path: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["sim", "replay", str(bench_path), "--row", "0", "--out", str(tmp_path / "x.jpg")]
    assert dg16m_core.cli.main(argv) == 2
    assert "expected a .png or .gif path" in capsys.readouterr().err


@pytest.fixture(scope="module")
def grasp_file(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    from dataset_gen.pipeline.generate import GenerationParameters, generate_dataset
    from dataset_gen.sources.object_source import procedural_sources
    from dataset_gen.sources.procedural import benchmark_specs

    out = tmp_path_factory.mktemp("dataset")
    sources = procedural_sources(benchmark_specs()[:1])
    generate_dataset(sources, out, GenerationParameters(n_grasps=40), progress=False)
    object_id = sources[0].object_id
    return out / "grasps" / f"{object_id}.h5", object_id


def test_cli_replay_a_grasp_file_pair(
    with_sim: None,
    can_render: None,
    grasp_file: tuple[Path, str],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    path, object_id = grasp_file
    out = tmp_path / "pair.gif"
    argv = ["sim", "replay", "--grasps", str(path), "--index", "0", "--procedural", object_id]
    assert dg16m_core.cli.main([*argv, "--out", str(out), "--frames", "3", "--size", "64x48"]) == 0
    assert "replayed:" in capsys.readouterr().out
    with Image.open(out) as image:
        assert image.format == "GIF"
        assert image.n_frames >= 3
    bad = ["sim", "replay", "--grasps", str(path), "--index", "99999", "--procedural", object_id]
    assert dg16m_core.cli.main([*bad, "--out", str(out)]) == 2
    assert "expected a pair index in [0, " in capsys.readouterr().err


def test_cli_run_reports_passing_and_failing(
    with_sim: None, grasp_file: tuple[Path, str], capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    path, object_id = grasp_file
    argv = ["sim", "run", str(path), "--procedural", object_id, "--limit", "3", "--json"]
    assert dg16m_core.cli.main(argv) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["object"] == object_id
    assert payload["summary"]["trials"] == sum(
        v["pairs"] for v in payload["force_closure"].values()
    )
    assert set(payload["force_closure"]) == {"passing", "failing"}
    assert payload["perturbation"]["n_perturbations"] == PerturbationSpec().n_perturbations
    assert len(payload["p_success"]) == payload["summary"]["trials"]
    assert all(g >= f for g, f in zip(payload["p_gravity"], payload["p_success"], strict=True))
    assert dg16m_core.cli.main([*argv[:5], "--limit", "0"]) == 2
    # --perturbations 0: the nominal trial alone, so every p is 0 or 1.
    assert dg16m_core.cli.main([*argv, "--perturbations", "0"]) == 0
    alone = json.loads(capsys.readouterr().out)
    assert set(alone["p_success"]) <= {0.0, 1.0}


@pytest.fixture(scope="module")
def penetrating_file(
    grasp_file: tuple[Path, str], tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, str]:
    """The generated file with hand 0 of every passing pair moved 4 cm along its closing axis:
    one open finger then lies inside the object."""
    path, object_id = grasp_file
    out = tmp_path_factory.mktemp("penetrating") / path.name
    shutil.copyfile(path, out)
    with h5py.File(out, "r+") as f:
        poses = f["grasps/grasps"][()]
        passing = np.sort(f["grasps/fc_passing_indices"][()])
        poses[passing, 0, :3, 3] += 0.04 * poses[passing, 0, :3, 0]
        f["grasps/grasps"][...] = poses
    return out, object_id


def test_cli_run_says_why_trials_are_invalid_and_what_to_do(
    with_sim: None, penetrating_file: tuple[Path, str], capsys: pytest.CaptureFixture[str]
) -> None:
    path, object_id = penetrating_file
    argv = ["sim", "run", str(path), "--procedural", object_id, "--limit", "3"]
    assert dg16m_core.cli.main(argv) == 0
    out = capsys.readouterr().out
    match = re.search(r"invalid trials \((\d+) of (\d+); not run\), by reason:", out)
    assert match, out
    invalid = int(match.group(1))
    assert invalid >= 1  # moved passing pairs
    counts = [int(m) for m in re.findall(r"^ +(\d+)  hand[01] penetrates: ", out, re.MULTILINE)]
    assert sum(counts) == invalid, out
    assert "inside the object: the open hand's palm in " in out
    assert "what to do" in out
    assert "dg16m sim replay --grasps" in out
    assert "--coacd-threshold" not in out  # a procedural object has exact parts
    # Numbers for people: no raw dicts, no 17-digit floats.
    assert "{" not in out
    assert not re.search(r"\d\.\d{5,}", out), out

    assert dg16m_core.cli.main([*argv, "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert sum(payload["invalid_reasons"].values()) == payload["summary"]["invalid"] == invalid
    assert payload["invalid_reasons"]["hand0_penetrates"] >= 1
    assert payload["open_hand_inside"]["fingers"] >= 1


def test_cli_run_coacd_threshold_is_for_meshes_only(
    with_sim: None, grasp_file: tuple[Path, str], capsys: pytest.CaptureFixture[str]
) -> None:
    path, object_id = grasp_file
    argv = ["sim", "run", str(path), "--procedural", object_id, "--coacd-threshold", "0.02"]
    assert dg16m_core.cli.main(argv) == 2
    assert "--coacd-threshold: expected only with --mesh" in capsys.readouterr().err


REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


@pytest.mark.slow
@pytest.mark.real_data
@pytest.mark.skipif(not (REAL / "dg16m_airplane.h5").is_file(), reason="no ../shared/data/real")
def test_cli_run_on_the_release_airplane_explains_the_invalid_trials(
    with_sim: None, capsys: pytest.CaptureFixture[str]
) -> None:
    """The new user's case: the release's airplane (CoACD parts: ~50 s the first time, then
    cached) marks most trials invalid; the report says why (the open Panda hand, mostly its
    palm, sits inside the object: the poses were made for the Robotiq 2F-85)."""
    argv = ["sim", "run", str(REAL / "dg16m_airplane.h5"), "--mesh"]
    argv += [str(REAL / "dg16m_airplane.obj"), "--limit", "50"]
    assert dg16m_core.cli.main(argv) == 0
    out = capsys.readouterr().out
    match = re.search(r"invalid trials \((\d+) of 100; not run\)", out)
    assert match, out
    assert int(match.group(1)) > 50, out
    assert "hand0 penetrates" in out
    assert "poses are for the robotiq_2f85 hand" in out
    assert "--coacd-threshold" in out


def test_the_default_view_shows_both_hands(scene: Scene, bench: Benchmark) -> None:
    """The camera looks across the line between the hands (neither behind the other), from the
    hands' side, with both grasp centres inside its field of view."""
    from dg16m_env.physics.replay import DEFAULT_ELEVATION, hands_view
    from dg16m_env.physics.trial_measures import grasp_centres

    fovy = float(scene.model.vis.global_.fovy)
    for row in range(bench.n):
        view = hands_view(scene, bench.poses[row])
        az, el = np.radians(view["azimuth"]), np.radians(DEFAULT_ELEVATION)
        forward = np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
        position = view["lookat"] - view["distance"] * forward
        centres = grasp_centres(scene, bench.poses[row][None])[0]
        across = centres[1, :2] - centres[0, :2]
        assert abs(np.dot(forward[:2], across)) <= 1e-9 + 1e-9 * np.linalg.norm(across)
        for centre in centres:
            ray = centre - position
            angle = np.degrees(np.arccos(np.dot(ray, forward) / np.linalg.norm(ray)))
            assert angle < fovy / 2, (row, angle)
        side = np.dot(centres[:, :2].mean(axis=0), [-across[1], across[0]])
        camera_side = np.dot(position[:2], [-across[1], across[0]])
        if abs(side) > 1e-3:
            assert np.sign(side) == np.sign(camera_side)


def test_strip_frames_show_distinct_phases(scene: Scene, bench: Benchmark) -> None:
    """Issue 43: a strip's frames (fewer than the phases) are ends of distinct phases; an
    animation's many frames are still spread in time."""
    row = _ran_row(bench, failed=False)
    stepped = step_trial(scene, bench.poses[row], bench.trials.protocol)
    steps = frame_steps(stepped, 8)
    phases = [stepped.phase_at(k) for k in steps[1:]]
    assert len(set(phases)) == len(phases)  # no phase twice after the start
    assert steps[0] == 0
    assert steps[-1] == stepped.end
    assert len(frame_steps(stepped, 40)) >= 40


def test_frames_have_a_light_background(can_render: None, scene: Scene, bench: Benchmark) -> None:
    """Issue 43: the replay was drawn on black; the corners are now the light backdrop."""
    from dg16m_env.physics.replay import BACKGROUND

    row = _ran_row(bench)
    frames, _ = trial_frames(
        scene, bench.poses[row], bench.trials.protocol, n_frames=2, width=160, height=120
    )
    corners = frames[0][[0, 0, -1, -1], [0, -1, 0, -1]].astype(float) / 255.0
    assert corners.min() > min(BACKGROUND) - 0.1, corners  # the view of both hands
    for frame in frames:  # close-ups of hands far apart may be filled by the object
        assert (frame.max(axis=2) < 40).mean() < 0.02  # not drawn on black
        assert frame.std() > 5  # the object and hands are drawn over it


def test_strip_frames_are_as_many_as_asked_and_show_the_largest_slip(
    scene: Scene, bench: Benchmark
) -> None:
    """Issue 56: a strip of 8 holds 8 frames (a 4 x 2 grid, no empty cell): the start, the
    ends of close and gravity, the largest slip (its caption says so) unless its phase already
    has a frame, then ends of other phases; the slip curve under it marks every frame."""
    from dg16m_env.physics.replay import Replay, caption, largest_slip_step, slip_curve

    for row in np.flatnonzero(bench.trials.status != TrialStatus.INVALID)[:3]:
        stepped = step_trial(scene, bench.poses[row], bench.trials.protocol)
        steps = frame_steps(stepped, 8)
        assert len(steps) == 8, steps
        assert stepped.plan.close_end in steps
        gravity_end = int(np.searchsorted(stepped.plan.phase, 1, side="right"))
        if gravity_end <= stepped.end and stepped.first_out is None:
            assert gravity_end in steps
        largest = largest_slip_step(stepped)
        assert largest is not None
        shown = {stepped.phase_at(k) for k in steps[1:]}
        assert stepped.phase_at(largest) in shown
        captions = [caption(stepped, k) for k in steps]
        assert sum("(max)" in c for c in captions) == (largest in steps), captions
        curve = slip_curve(Replay(stepped, [], captions, steps))
        assert curve is not None
        assert len(curve["frames_t"]) == len(steps)
        assert curve["slip_mm"].max() == pytest.approx(1e3 * stepped.slip[: stepped.end + 1].max())


def test_hands_far_apart_get_close_ups(scene: Scene, bench: Benchmark) -> None:
    """Issue 56: hands more than CLOSE_UP_SPLIT apart get one close-up camera each, on its
    grasp centre; hands close together keep one view."""
    from dg16m_env.physics.replay import CLOSE_UP_DISTANCE, CLOSE_UP_SPLIT, hand_close_ups
    from dg16m_env.physics.trial_measures import grasp_centres

    for row in range(bench.n):
        centres = grasp_centres(scene, bench.poses[row][None])[0]
        cameras = hand_close_ups(scene, bench.poses[row])
        if np.linalg.norm(centres[1] - centres[0]) <= CLOSE_UP_SPLIT:
            assert cameras is None
            continue
        assert cameras is not None
        for camera, centre in zip(cameras, centres, strict=True):
            np.testing.assert_allclose(camera["lookat"], centre)
            assert camera["distance"] == CLOSE_UP_DISTANCE
