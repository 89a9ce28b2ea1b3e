"""The MuJoCo Warp simulator (optional extra ``warp``) against the C MuJoCo path.

The first group needs no extra: settings, errors and the commands' options. The second runs a few
trials on Warp's CPU device (or ``DG16M_WARP_DEVICE``) and compares them with C MuJoCo; it is
marked ``warp`` and skipped, with the reason, when the extra is not installed (CI never installs
it). Warp compiles its CPU kernels on first use (one to two minutes, then cached in
``~/.cache/warp``).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
from dataclasses import replace

import numpy as np
import pytest
from planks import (
    FAIL_HORIZONTAL,
    HOLD_FROM_ABOVE,
    HOLD_FROM_SIDE,
    SHORT_PLANK,
    dual,
    finger_inside,
    plank,
)

from dg16m_core.cli import main
from dg16m_env.physics import simulator as simulator_module
from dg16m_env.physics.scene import Scene, compile_scene
from dg16m_env.physics.simulator import (
    Simulator,
    SimulatorError,
    add_simulator_arguments,
    check_simulator,
    simulator_from_args,
)
from dg16m_env.physics.trial import run_trials
from dg16m_env.physics.trial_measures import body_points, grasp_centres, object_states
from dg16m_env.physics.trial_protocol import (
    STATE_SPEC,
    InvalidReason,
    TrialProtocol,
    TrialResults,
    TrialStatus,
    trial_control_vectors,
)

WARP = importlib.util.find_spec("mujoco_warp") is not None and (
    importlib.util.find_spec("warp") is not None
)
requires_warp = pytest.mark.skipif(
    not WARP, reason="MuJoCo Warp is an optional extra: pip install 'dg16m[warp]'"
)

# --------------------------------------------------------------------------------------------
# Settings and errors (no extra needed)
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"name": "physx"}, "expected one of mujoco, warp, found 'physx'"),
        ({"device": "cuda:0"}, "expected none for the 'mujoco' simulator"),
        ({"name": "warp", "device": ""}, "expected a Warp device name"),
        ({"name": "warp", "worlds": 0}, "worlds: expected an integer >= 1, found 0"),
        ({"name": "warp", "nconmax": 2.5}, "nconmax: expected an integer >= 1"),
        ({"name": "warp", "deterministic": "yes"}, "deterministic: expected true or false"),
    ],
)
def test_bad_simulator_settings_say_what_was_expected(kwargs: dict, message: str) -> None:
    with pytest.raises(SimulatorError, match=message):
        Simulator(**kwargs)


def test_simulator_settings_round_trip() -> None:
    warp = Simulator(name="warp", device="cpu", worlds=16, deterministic=True)
    assert Simulator.from_dict(warp.to_dict()) == warp
    assert Simulator().to_dict() == {"name": "mujoco"}
    assert Simulator.from_dict({"name": "mujoco"}) == Simulator()
    assert Simulator(name="warp").to_dict()["device"] == "cuda:0"
    assert check_simulator(None) == Simulator()
    assert check_simulator("warp") == Simulator(name="warp")
    with pytest.raises(SimulatorError, match="unknown"):
        Simulator.from_dict({"name": "warp", "gpus": 2})
    with pytest.raises(SimulatorError, match="expected a Simulator"):
        check_simulator(3)


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_simulator_arguments(parser)
    return parser.parse_args(list(argv))


def test_command_options_make_the_simulator() -> None:
    assert simulator_from_args(_args()) == Simulator()
    made = simulator_from_args(_args("--simulator", "warp", "--device", "cpu", "--worlds", "8"))
    assert made == Simulator(name="warp", device="cpu", worlds=8)
    with pytest.raises(SimulatorError, match="--device, --worlds: expected --simulator warp"):
        simulator_from_args(_args("--device", "cpu", "--worlds", "3"))


def test_a_missing_extra_is_reported_with_the_install_command(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(simulator_module, "warp_installed", lambda: False)
    scene = compile_scene(plank(*SHORT_PLANK))
    with pytest.raises(SimulatorError, match=r"install them with pip install 'dg16m\[warp\]'"):
        run_trials(scene, HOLD_FROM_ABOVE[None], simulator="warp")


def test_commands_refuse_warp_without_the_extra_before_any_work(
    monkeypatch: pytest.MonkeyPatch, tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(simulator_module, "warp_installed", lambda: False)
    argv = ["benchmark", "build", "--out", str(tmp_path / "b"), "--limit", "1"]
    assert main([*argv, "--simulator", "warp"]) == 2
    assert "dg16m[warp]" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()  # nothing started, nothing written
    assert main([*argv, "--device", "cpu"]) == 2
    assert "expected --simulator warp" in capsys.readouterr().err


def test_a_result_computed_on_warp_says_so_and_the_reference_stays_silent() -> None:
    from dg16m_env.evaluators.result import EvaluationResult

    def result(parameters: dict) -> str:
        return EvaluationResult(
            evaluator="gsr",
            evaluator_version="1",
            package_version="0",
            benchmark={},
            subject={},
            parameters=parameters,
            seeds={},
            headline="gsr",
            metrics={"gsr": 0.5},
        ).format()

    warp = Simulator(name="warp", device="cuda:1")
    assert "trials on MuJoCo Warp, device cuda:1" in result({"simulator": warp.to_dict()})
    assert "Warp" not in result({})


# --------------------------------------------------------------------------------------------
# Trials on Warp's CPU device against C MuJoCo (extra needed)
# --------------------------------------------------------------------------------------------

WARP_DEVICE = os.environ.get("DG16M_WARP_DEVICE", "cpu")
"""Where the comparisons run: Warp's CPU device, or a GPU (``DG16M_WARP_DEVICE=cuda:0``, what
``scripts/gpu_check.sh`` sets)."""
WARP_SIM = Simulator(name="warp", device=WARP_DEVICE, worlds=8)


@pytest.fixture(scope="module")
def mixed(short_scene: Scene, long_scene: Scene) -> dict[str, tuple[np.ndarray, TrialResults]]:
    """Holds, an invalid pair, and failures, on C MuJoCo (the reference)."""
    short = np.stack(
        [
            HOLD_FROM_ABOVE,
            HOLD_FROM_SIDE,
            dual(finger_inside(HOLD_FROM_ABOVE[0]), HOLD_FROM_ABOVE[1]),
        ]
    )
    long = np.stack([FAIL_HORIZONTAL, HOLD_FROM_ABOVE, FAIL_HORIZONTAL])
    return {
        "short": (short, run_trials(short_scene, short)),
        "long": (long, run_trials(long_scene, long)),
    }


@pytest.mark.parametrize("which", ["short", "long"])
@pytest.mark.warp
@requires_warp
def test_warp_verdicts_match_c_mujoco(
    which: str, mixed: dict, short_scene: Scene, long_scene: Scene
) -> None:
    scene = short_scene if which == "short" else long_scene
    grasps, reference = mixed[which]
    results = run_trials(scene, grasps, simulator=WARP_SIM)
    assert results.status.tolist() == reference.status.tolist()
    assert results.failing_phase.tolist() == reference.failing_phase.tolist()
    assert results.invalid_reason.tolist() == reference.invalid_reason.tolist()
    held = results.success
    # float32 against float64: the held object's slip and turn agree to a fraction of a bound.
    np.testing.assert_allclose(
        results.max_displacement[held], reference.max_displacement[held], atol=1e-3
    )
    np.testing.assert_allclose(
        results.max_rotation_deg[held], reference.max_rotation_deg[held], atol=0.5
    )
    assert (results.contacts_after_close[held] > 0).all()
    if which == "short":
        assert results.invalid_reason[2] == InvalidReason.HAND0_PENETRATES
    else:  # two of three fell under gravity: the survivor moved to a smaller Data
        assert results.status.tolist() == [
            TrialStatus.FAILED,
            TrialStatus.SUCCESS,
            TrialStatus.FAILED,
        ]


@pytest.mark.warp
@requires_warp
def test_warp_is_repeatable_and_early_exit_keeps_the_verdicts(long_scene: Scene) -> None:
    """Deterministic mode gives the same bytes twice (on a GPU too); the default mode and a
    run without early exit give the same verdicts."""
    grasps = np.stack([FAIL_HORIZONTAL, HOLD_FROM_ABOVE, FAIL_HORIZONTAL])
    deterministic = replace(WARP_SIM, deterministic=True)
    first = run_trials(long_scene, grasps, simulator=deterministic)
    again = run_trials(long_scene, grasps, simulator=deterministic)
    for name in TrialResults.ARRAY_FIELDS:
        assert np.array_equal(getattr(first, name), getattr(again, name), equal_nan=True), name
    for early_exit in (True, False):
        other = run_trials(long_scene, grasps, simulator=WARP_SIM, early_exit=early_exit)
        assert other.status.tolist() == first.status.tolist()
        assert other.failing_phase.tolist() == first.failing_phase.tolist()


@pytest.mark.warp
@requires_warp
def test_a_world_that_overflows_its_contacts_is_unstable_not_dropped(short_scene: Scene) -> None:
    tiny = Simulator(name="warp", device=WARP_DEVICE, worlds=8, nconmax=1)
    results = run_trials(short_scene, np.stack([HOLD_FROM_ABOVE, HOLD_FROM_SIDE]), simulator=tiny)
    assert results.status.tolist() == [TrialStatus.UNSTABLE] * 2
    assert results.summary()["unstable"] == 2


@pytest.mark.warp
@requires_warp
def test_device_measures_match_measure_steps_on_the_same_states(short_scene: Scene) -> None:
    """The float32 kernel and the float64 reference measure the same states alike: C MuJoCo's
    trajectory of a hold, every 40th step after close, measured from the end of close."""
    from dg16m_env.physics.trial_measures import measure_steps
    from dg16m_env.physics.trial_protocol import simulate
    from dg16m_env.physics.warp_trials import MEASURE_COLUMN, WarpRunner

    protocol = TrialProtocol()
    grasps = np.stack([HOLD_FROM_ABOVE, HOLD_FROM_SIDE])
    states, sensors, plan = simulate(short_scene, grasps, protocol)
    close = plan.close_end
    steps = np.arange(close, plan.nstep, 40)
    anchors = grasp_centres(short_scene, grasps)
    reference = states[:, close - 1]
    expected = measure_steps(
        short_scene, states[:, steps], sensors[:, steps], 0, protocol, anchors, reference
    )
    # One world per (trial, step): its state and sensors set directly, measured once.
    runner = WarpRunner(short_scene, plan, WARP_SIM)
    trial = np.repeat(np.arange(2), steps.size)
    world_states = states[:, steps].reshape(-1, states.shape[-1])
    world_sensors = sensors[:, steps].reshape(-1, sensors.shape[-1])
    controls = trial_control_vectors(short_scene, grasps)
    worlds = runner._worlds(trial, controls, anchors)
    wp = runner.wp
    with wp.ScopedDevice(runner.device):
        runner.mjw.set_state(
            runner.model,
            worlds.data,
            wp.array(world_states.astype(np.float32), dtype=float),
            int(STATE_SPEC),
        )
        worlds.data.sensordata.assign(world_sensors.astype(np.float32))
        ref_pos, ref_quat, _ = object_states(short_scene, reference[trial])
        body = body_points(anchors[trial], ref_pos, ref_quat)
        worlds.body_points.assign(body.astype(np.float32))
        worlds.reference.assign(ref_quat[:, [1, 2, 3, 0]].astype(np.float32))
        wp.launch(
            runner.kernels.measure,
            dim=worlds.n,
            inputs=[
                worlds.counter,
                worlds.data.time,
                worlds.data.qpos,
                worlds.data.qvel,
                worlds.data.act,
                worlds.data.sensordata,
                int(short_scene.object_qpos.start),
                int(short_scene.object_qvel.start),
                runner.sensor_adr,
                worlds.anchors,
                worlds.body_points,
                worlds.reference,
            ],
            outputs=[worlds.measures],
        )
        got = worlds.measures.numpy()[0].reshape(2, steps.size, -1).astype(np.float64)
    column = MEASURE_COLUMN
    np.testing.assert_allclose(got[..., column["displacement"]], expected.displacement, atol=2e-6)
    np.testing.assert_allclose(got[..., column["rotation"]], expected.rotation, atol=2e-3)
    assert expected.rotation.max() > 1e-3  # the rotations compared are not all zero
    np.testing.assert_allclose(got[..., column["depth"]], expected.depth, atol=1e-7)
    hands = got[..., [column["hand0"], column["hand1"]]]
    assert np.array_equal(hands, expected.hand_contacts)
    assert (got[..., column["finite"]] == 1.0).all()
    assert expected.finite.all()
    _, _, vel = object_states(short_scene, states[:, steps])
    np.testing.assert_allclose(got[..., column["speed"]], np.linalg.norm(vel, axis=-1), atol=1e-6)


@pytest.mark.warp
@requires_warp
def test_a_warp_build_names_its_engine_and_cannot_resume_on_another(tmp_path) -> None:
    from dg16m_env.benchmark.build import build_benchmark
    from dg16m_env.benchmark.file import read_benchmark
    from dg16m_env.benchmark.model import BenchmarkError, BenchmarkParameters
    from dg16m_env.benchmark.sources import procedural_benchmark_sources
    from dg16m_env.physics.labels import PerturbationSpec

    small = BenchmarkParameters(
        n_grasps=40,
        n_passing=3,
        n_failing=2,
        n_random=2,
        n_farthest=2,
        perturbation=PerturbationSpec(n_perturbations=1),
    )
    sources = procedural_benchmark_sources(1)
    path = build_benchmark(sources, tmp_path, small, progress=False, simulator=WARP_SIM)
    bench = read_benchmark(path)
    engine = bench.metadata["simulator"]
    assert engine["name"] == "warp"
    assert engine["device"] == WARP_DEVICE
    assert {"mujoco", "mujoco_warp", "warp"} <= set(engine)
    assert bench.labels.status.shape == (bench.n, 2)
    assert (bench.labels.status != TrialStatus.UNSTABLE).all()
    with pytest.raises(BenchmarkError, match="same parameters"):
        build_benchmark(sources, tmp_path, small, progress=False)  # C MuJoCo into a Warp build
