"""The one-step Gymnasium environments DualGraspPose-v0 and DualGraspSelect-v0: both checkers,
seeded determinism, agreement with the stored trials and labels, clear action errors, vector
forms without wasted steps, offscreen rendering and the partial (depth camera) observation."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import trimesh
from gymnasium.utils.env_checker import check_env as gym_check_env
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import dg16m_env
from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.model import Benchmark
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.envs import ENVIRONMENTS, NAMESPACE, env_ids
from dg16m_env.envs.common import (
    OBSERVATION_LIMIT,
    VECTOR_KWARGS,
    structured_observation,
)
from dg16m_env.envs.dual_grasp_pose import DualGraspPoseEnv
from dg16m_env.envs.dual_grasp_select import DualGraspSelectEnv
from dg16m_env.envs.objects import BenchmarkObjects
from dg16m_env.envs.spaces import action_from_poses
from dg16m_env.physics.cameras import DepthCameras
from dg16m_env.physics.labels import GRAVITY_PHASE
from dg16m_env.physics.trial_protocol import PHASES, TrialStatus

OBJECTS = ["table-1000000", "frame-1000000", "crate-1000000"]
POSE = f"{NAMESPACE}/DualGraspPose-v0"
SELECT = f"{NAMESPACE}/DualGraspSelect-v0"
ONE_STEP = ("DualGraspPose-v0", "DualGraspSelect-v0")


@pytest.fixture(scope="module")
def bench_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A three-object benchmark cut from the embedded one."""
    path = tmp_path_factory.mktemp("env") / "small.h5"
    write_benchmark(path, read_benchmark(EMBEDDED_BENCHMARK).select_objects(OBJECTS))
    return path


@pytest.fixture(scope="module")
def bench(bench_path: Path) -> Benchmark:
    return read_benchmark(bench_path)


@pytest.fixture
def strict() -> Iterator[None]:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def _one_step_ids() -> list[str]:
    """Every registered id of the one-step environments (namespaced and bare aliases); the
    closed-loop DualGraspLift is another module's, tested there."""
    ids = [i for i in env_ids(aliases=True) if i.split("/")[-1] in ONE_STEP]
    assert len(ids) == 4
    return ids


def _importable(env_id: str) -> bool:
    module = gym.spec(env_id).entry_point.split(":")[0]  # type: ignore[union-attr]
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True


def _equal(a: Any, b: Any) -> bool:
    """Exact equality of observations / infos (arrays by bytes, dtypes and shapes)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray):
        return (
            isinstance(b, np.ndarray)
            and a.dtype == b.dtype
            and a.shape == b.shape
            and a.tobytes() == b.tobytes()
        )
    return type(a) is type(b) and a == b


def _robust_rows(bench: Benchmark, arm: int = 0) -> np.ndarray:
    """Rows of one arm whose every stored trial agrees (p in {0, 1}): their verdict does not
    hang on the last bits of a pose."""
    p = bench.p("full")
    return np.flatnonzero((bench.source == arm) & ((p == 0.0) | (p == 1.0)))


# --------------------------------------------------------------------------------------------
# Registration and both checkers
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("env_id", _one_step_ids())
def test_check_env_every_id(env_id: str, strict: None) -> None:
    if not _importable(env_id):
        pytest.skip(f"{env_id}: its module does not import yet")
    env = gym.make(env_id)  # the registered default: the embedded 300-object benchmark
    try:
        gym_check_env(env.unwrapped)
        sb3_check_env(env.unwrapped)
    finally:
        env.close()


@pytest.mark.parametrize(
    ("env_id", "kwargs"),
    [
        (POSE, {"obs_mode": "partial", "n_cameras": 2, "camera_resolution": 64}),
        (SELECT, {"reward_mode": "label", "level": "gravity", "n_candidates": 128}),
        (SELECT, {"obs_mode": "partial", "perturb": False, "fc_info": False}),
    ],
)
def test_check_env_options(env_id: str, kwargs: dict, bench_path: Path, strict: None) -> None:
    env = gym.make(env_id, benchmark=bench_path, **kwargs)
    try:
        gym_check_env(env.unwrapped)
        sb3_check_env(env.unwrapped)
    finally:
        env.close()


def test_fresh_interpreter_make() -> None:
    code = (
        "import gymnasium as gym\n"
        "env = gym.make('dg16m_env:DualGraspSelect-v0')\n"
        "obs, info = env.reset(seed=0)\n"
        "obs, reward, terminated, truncated, info = env.step(0)\n"
        "assert terminated and not truncated and info['status'], info\n"
        "print(type(env.unwrapped).__name__, info['object_id'])\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("DualGraspSelectEnv ")


def test_ids_point_at_these_classes() -> None:
    assert ENVIRONMENTS["DualGraspPose-v0"][1] is None  # one-step: no TimeLimit
    assert ENVIRONMENTS["DualGraspSelect-v0"][1] is None
    for env_id in _one_step_ids():
        entry = gym.spec(env_id).entry_point
        assert entry in (
            "dg16m_env.envs.dual_grasp_pose:DualGraspPoseEnv",
            "dg16m_env.envs.dual_grasp_select:DualGraspSelectEnv",
        )
    for cls in (DualGraspPoseEnv, DualGraspSelectEnv):
        doc = cls.__doc__ or ""
        for section in ("## Action Space", "## Observation Space", "## Rewards", "## Arguments"):
            assert section in doc
        assert "v0: initial" in doc
        assert cls.METADATA["render_modes"] == ["rgb_array"]
        assert cls.METADATA["render_fps"] > 0
    assert dg16m_env.envs is not None


# --------------------------------------------------------------------------------------------
# Observations, determinism
# --------------------------------------------------------------------------------------------


def _rollout(env_id: str, bench_path: Path, seed: int, action: Any, **kwargs: Any) -> tuple:
    env = gym.make(env_id, benchmark=bench_path, **kwargs)
    try:
        obs, info = env.reset(seed=seed)
        step = env.step(action)
    finally:
        env.close()
    return obs, info, step


@pytest.mark.parametrize(
    ("env_id", "kwargs"),
    [(POSE, {}), (SELECT, {}), (SELECT, {"reward_mode": "label"}), (POSE, {"obs_mode": "partial"})],
)
def test_seeded_determinism(env_id: str, kwargs: dict, bench_path: Path) -> None:
    env = gym.make(env_id, benchmark=bench_path, **kwargs)
    env.action_space.seed(5)
    action = env.action_space.sample()
    env.close()
    first = _rollout(env_id, bench_path, 11, action, **kwargs)
    second = _rollout(env_id, bench_path, 11, action, **kwargs)
    assert _equal(first[0], second[0])  # reset observation bytes
    assert _equal(first[1], second[1])
    for a, b in zip(first[2], second[2], strict=True):  # obs, reward, terminated, truncated, info
        assert _equal(a, b)


def test_observation_layout(bench_path: Path, bench: Benchmark) -> None:
    env = DualGraspSelectEnv(benchmark=bench_path, n_points=256, n_candidates=8)
    obs, info = env.reset(seed=3, options={"object_id": "crate-1000000"})
    assert info["object_id"] == "crate-1000000"
    assert obs in env.observation_space
    assert all(v.ndim == 1 and v.dtype == np.float32 for v in obs.values())
    shaped = structured_observation(obs)
    assert shaped["points"].shape == (256, 3)
    assert shaped["normals"].shape == (256, 3)
    assert shaped["candidates"].shape == (8, 2, 9)
    assert shaped["candidate_contacts"].shape == (8, 4, 6)
    np.testing.assert_allclose(np.linalg.norm(shaped["normals"], axis=1), 1.0, atol=1e-5)
    lo, hi = shaped["bounds"]
    assert np.all(shaped["points"] >= lo - 1e-6)
    assert np.all(shaped["points"] <= hi + 1e-6)
    # the candidates: the object's stored rows in a random order, encoded exactly
    rows = info["rows"]
    own = bench.object_rows("crate-1000000")
    assert set(rows.tolist()) <= set(own.tolist())
    assert len(set(rows.tolist())) == 8
    assert not np.all(np.diff(rows) > 0)  # stored rows are grouped by arm: order never shows
    np.testing.assert_allclose(
        shaped["candidates"], action_from_poses(bench.poses[rows]), atol=1e-6
    )
    np.testing.assert_allclose(
        shaped["candidate_contacts"][..., :3], bench.contact_points[rows], atol=1e-6
    )
    np.testing.assert_array_equal(obs["candidate_mask"], np.ones(8, dtype=np.float32))
    # the same observation comes back with the step, as new arrays
    step_obs = env.step(0)[0]
    assert _equal(step_obs, obs)
    assert not np.shares_memory(step_obs["points"], obs["points"])
    env.close()


def test_empty_slots(bench_path: Path) -> None:
    env = DualGraspSelectEnv(benchmark=bench_path, n_candidates=128, fc_info=False)
    obs, info = env.reset(seed=0)
    n_rows = int(obs["candidate_mask"].sum())
    assert 0 < n_rows < 128
    assert np.all(info["rows"][n_rows:] == -1)
    shaped = structured_observation(obs)
    assert not shaped["candidates"][n_rows:].any()
    assert not shaped["candidate_contacts"][n_rows:].any()
    _, reward, terminated, truncated, step_info = env.step(127)
    assert reward == 0.0
    assert terminated
    assert not truncated
    assert step_info["invalid_reason"] == "empty_slot"
    assert step_info["row"] is None
    assert step_info["status"] == "not_run"
    env.close()


# --------------------------------------------------------------------------------------------
# Rewards against the stored benchmark
# --------------------------------------------------------------------------------------------


def test_pose_at_stored_rows_gives_stored_verdict(bench_path: Path, bench: Benchmark) -> None:
    """A Pose action equal to a stored fc_pass row's poses, unperturbed, gives the stored
    nominal trial's verdict (rows whose stored trials all agree, so the float32 encoding of
    the action cannot tip it)."""
    env = DualGraspPoseEnv(benchmark=bench_path, perturb=False)
    gravity = DualGraspPoseEnv(benchmark=bench_path, perturb=False, level="gravity")
    ids = [o.object_id for o in bench.objects]
    rows = _robust_rows(bench)
    rows = np.concatenate([rows[bench.p()[rows] == 1.0][:3], rows[bench.p()[rows] == 0.0][:2]])
    assert rows.size >= 3
    for row in rows:
        object_id = ids[bench.object_index[row]]
        action = action_from_poses(bench.poses[row]).astype(np.float32)
        for e in (env, gravity):
            e.reset(seed=0, options={"object_id": object_id})
        _, reward, _, _, info = env.step(action)
        assert info["success"] == bool(bench.trials.success[row])
        assert reward == float(bench.trials.success[row])
        assert info["status"] == TrialStatus(int(bench.trials.status[row])).name.lower()
        assert info["is_success"] is info["success"]
        assert info["fc_passed"] is True  # an fc_pass row: its jaws close in force closure
        assert info["fc_reason"] == "pass"
        phase = int(bench.labels.failing_phase[row, 0])
        held_gravity = bench.trials.valid[row] and (phase < 0 or phase > GRAVITY_PHASE)
        assert gravity.step(action)[1] == float(held_gravity)
        if not info["success"]:
            assert info["failing_phase"] in PHASES
    env.close()
    gravity.close()


def test_select_simulate_unperturbed_is_stored_trial(bench_path: Path, bench: Benchmark) -> None:
    env = DualGraspSelectEnv(benchmark=bench_path, perturb=False, fc_info=False)
    for seed in range(4):
        _, info = env.reset(seed=seed)
        slot = seed % env.n_candidates
        _, reward, _, _, step_info = env.step(slot)
        row = int(info["rows"][slot])
        assert step_info["row"] == row
        assert step_info["p"] == float(bench.p()[row])
        assert reward == float(bench.trials.success[row])  # float64 stored poses: bit for bit
        assert step_info["slip_m"] == pytest.approx(float(bench.trials.max_displacement[row]))
    env.close()


def test_select_label_vs_simulate(bench_path: Path, bench: Benchmark) -> None:
    label = DualGraspSelectEnv(benchmark=bench_path, reward_mode="label", fc_info=False)
    simulate = DualGraspSelectEnv(benchmark=bench_path, fc_info=False)
    rewards, ps = [], []
    for seed in range(300):
        label.reset(seed=seed)
        _, reward, _, _, info = label.step(seed % 16)
        assert info["status"] == "label"
        assert info["slip_m"] is None
        assert info["failing_phase"] is None
        if info["p"] in (0.0, 1.0):
            assert reward == info["p"]  # a certain label is drawn as itself
        rewards.append(reward)
        ps.append(info["p"])
    # Bernoulli(p): the mean reward matches the mean stored p (4 standard errors)
    se = np.sqrt(np.sum(np.multiply(ps, 1.0 - np.asarray(ps)))) / len(ps)
    assert abs(np.mean(rewards) - np.mean(ps)) <= 4.0 * se + 1e-9
    # the same seed and slot pick the same row in both modes; simulate runs a real trial
    for seed in range(3):
        label.reset(seed=seed)
        simulate.reset(seed=seed)
        info_label = label.step(1)[4]
        info_sim = simulate.step(1)[4]
        assert info_label["row"] == info_sim["row"]
        assert info_label["p"] == info_sim["p"]
        assert info_label.keys() == info_sim.keys()
        assert info_sim["status"] in {s.name.lower() for s in TrialStatus}
        assert simulate.last_trial_poses is not None
    label.close()
    simulate.close()


def test_perturbation_moves_the_hands(bench_path: Path, bench: Benchmark) -> None:
    env = DualGraspSelectEnv(benchmark=bench_path, fc_info=False)
    _, info = env.reset(seed=2)
    env.step(0)
    row = int(info["rows"][0])
    ran = env.last_trial_poses
    assert ran is not None
    spec = env.perturbation
    shift = np.linalg.norm(ran[:, :3, 3] - bench.poses[row][:, :3, 3], axis=1)
    assert np.all(shift > 0.0)
    assert np.all(shift < spec.translation + 0.2 * np.radians(spec.rotation_deg) + 1e-9)
    turn = np.einsum("hij,hij->h", ran[:, :3, :3], bench.poses[row][:, :3, :3])
    np.testing.assert_allclose(
        np.degrees(np.arccos(np.clip((turn - 1) / 2, -1, 1))), spec.rotation_deg, atol=1e-6
    )
    env.close()


# --------------------------------------------------------------------------------------------
# Actions
# --------------------------------------------------------------------------------------------


def test_pose_bad_actions_name_the_space(bench_path: Path) -> None:
    env = DualGraspPoseEnv(benchmark=bench_path, fc_info=False)
    good = np.zeros((2, 9), dtype=np.float32)
    good[:, 3] = 1.0  # a = x
    good[:, 7] = 1.0  # b = y
    nan = good.copy()
    nan[1, 4] = np.nan
    far = good.copy()
    far[0, 0] = 1.5
    bad = {
        "nan": nan,
        "out of bounds": far,
        "wrong shape": good[:, :8],
        "flat": good.reshape(-1),
        "strings": np.full((2, 9), "a"),
        "objects": np.array([[object()] * 9] * 2, dtype=object),
        "booleans": np.ones((2, 9), dtype=bool),
        "ragged": [[0.0] * 9, [0.0] * 8],
        "none": None,
    }
    for name, action in bad.items():
        env.reset(seed=0)
        with pytest.raises(ValueError, match=r"action: expected an element of Box\(") as err:
            env.step(action)
        assert "(2, 9)" in str(err.value), name
    # accepted: float64 arrays and lists of numbers within the bounds (cast to float32)
    for action in (good.astype(np.float64), good.tolist(), good.astype(np.int64)):
        env.reset(seed=0)
        _, reward, terminated, _, info = env.step(action)
        assert terminated
        assert reward in (0.0, 1.0)
        assert info["status"] != "not_run"
    env.close()


def test_select_bad_actions_name_the_space(bench_path: Path) -> None:
    env = DualGraspSelectEnv(benchmark=bench_path, fc_info=False, reward_mode="label")
    for action in (1.5, "0", -1, 16, True, np.array([1, 2]), np.float32(2.0), None):
        env.reset(seed=0)
        with pytest.raises(ValueError, match=r"action: expected an element of Discrete\(16\)"):
            env.step(action)
    for action in (3, np.int64(3), np.array(3)):
        env.reset(seed=0)
        assert env.step(action)[4]["row"] is not None
    env.close()


def test_degenerate_rotation_is_not_an_error(bench_path: Path) -> None:
    env = DualGraspPoseEnv(benchmark=bench_path)
    env.reset(seed=0)
    action = np.zeros((2, 9), dtype=np.float32)  # a = b = 0: no rotation
    action[1, 3] = action[1, 7] = 1.0
    _, reward, terminated, truncated, info = env.step(action)
    assert reward == 0.0
    assert terminated
    assert not truncated
    assert info["invalid_reason"] == "degenerate_rotation"
    assert info["status"] == "not_run"
    assert info["success"] is False
    assert info["is_success"] is False
    assert info["fc_passed"] is False
    assert env.last_trial_poses is None
    parallel = action.copy()
    parallel[0, 3:6] = parallel[0, 6:9] = [0.0, 0.6, 0.8]  # a parallel to b
    env.reset(seed=0)
    assert env.step(parallel)[4]["invalid_reason"] == "degenerate_rotation"
    env.close()


def test_episode_order_errors(bench_path: Path) -> None:
    env = DualGraspSelectEnv(benchmark=bench_path, reward_mode="label", fc_info=False)
    with pytest.raises(gym.error.ResetNeeded, match="before the first step"):
        env.step(0)
    env.reset(seed=0)
    env.step(0)
    with pytest.raises(gym.error.ResetNeeded, match="terminated"):
        env.step(0)
    with pytest.raises(ValueError, match="options: expected only 'object_id'"):
        env.reset(options={"objekt": "x"})
    with pytest.raises(ValueError, match="object_id"):
        env.reset(options={"object_id": "no-such-object"})
    env.close()
    env.close()  # idempotent


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"obs_mode": "depth"}, "obs_mode: expected one of"),
        ({"level": "half"}, "level: expected one of"),
        ({"n_points": 0}, "n_points: expected an integer >= 1"),
        ({"n_cameras": 3}, "n_cameras: expected 1 or 2"),
        ({"render_mode": "human"}, "render_mode: expected None or 'rgb_array', found 'human'"),
        ({"reward_mode": "guess"}, "reward_mode: expected one of"),
        ({"n_candidates": 0}, "n_candidates: expected an integer >= 1"),
        ({"perturb": "yes"}, "perturb: expected True or False"),
    ],
)
def test_bad_arguments(kwargs: dict, message: str, bench_path: Path) -> None:
    with pytest.raises(ValueError, match=message):
        DualGraspSelectEnv(benchmark=bench_path, **kwargs)


# --------------------------------------------------------------------------------------------
# Vector environments
# --------------------------------------------------------------------------------------------


def _check_vector_steps(env: gym.vector.VectorEnv, action: Any) -> None:
    assert env.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    env.reset(seed=0)
    for _ in range(3):  # every call is a real trial: no step spent on a reset
        _, reward, terminated, truncated, infos = env.step(action)
        assert terminated.all()
        assert not truncated.any()
        final = infos["final_info"]
        assert np.all(final["status"] != "not_run")
        assert np.all(final["status"] != None)  # noqa: E711 (elementwise over an object array)
        np.testing.assert_array_equal(reward, final["success"].astype(np.float64))
        assert "object_id" in infos  # the new episodes' reset info
    env.close()


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_vector_same_step_registration(mode: str, bench_path: Path) -> None:
    """The registration the one-step ids use: ``kwargs={"vector_kwargs": VECTOR_KWARGS}`` makes
    ``gym.make_vec`` default to SAME_STEP, and ``gym.make`` still works."""
    env_id = f"{NAMESPACE}/TestSelectSameStep-v0"
    gym.register(
        id=env_id,
        entry_point="dg16m_env.envs.dual_grasp_select:DualGraspSelectEnv",
        kwargs={"vector_kwargs": VECTOR_KWARGS, "benchmark": str(bench_path)},
    )
    try:
        single = gym.make(env_id, reward_mode="label")
        single.reset(seed=0)
        assert single.step(0)[2]
        single.close()
        env = gym.make_vec(env_id, num_envs=2, vectorization_mode=mode, fc_info=False)
        _check_vector_steps(env, np.array([0, 1]))
    finally:
        del gym.registry[env_id]


@pytest.mark.parametrize("mode", ["sync", "async"])
@pytest.mark.parametrize("env_id", [POSE, SELECT])
def test_vector_registered_ids(env_id: str, mode: str, bench_path: Path) -> None:
    spec_kwargs = gym.spec(env_id).kwargs
    vector_kwargs = {"autoreset_mode": AutoresetMode.SAME_STEP}
    if spec_kwargs.get("vector_kwargs") is None:  # registration not updated (see common.py)
        env = gym.make_vec(
            env_id,
            num_envs=2,
            vectorization_mode=mode,
            vector_kwargs=vector_kwargs,
            benchmark=bench_path,
            fc_info=False,
        )
    else:
        env = gym.make_vec(
            env_id, num_envs=2, vectorization_mode=mode, benchmark=bench_path, fc_info=False
        )
    sample = env.single_action_space
    sample.seed(0)
    _check_vector_steps(env, np.stack([sample.sample(), sample.sample()]))


def test_registered_ids_default_to_same_step() -> None:
    for env_id in _one_step_ids():
        if gym.spec(env_id).kwargs.get("vector_kwargs") is None:
            pytest.skip(
                "the registration in dg16m_env/envs/__init__.py does not pass "
                "kwargs={'vector_kwargs': VECTOR_KWARGS} yet"
            )
        mode = gym.spec(env_id).kwargs["vector_kwargs"]["autoreset_mode"]
        assert AutoresetMode(mode) == AutoresetMode(VECTOR_KWARGS["autoreset_mode"])
        assert AutoresetMode(mode) == AutoresetMode.SAME_STEP


# --------------------------------------------------------------------------------------------
# Rendering and the partial observation
# --------------------------------------------------------------------------------------------


def test_render_rgb_array_offscreen(bench_path: Path, bench: Benchmark) -> None:
    env = gym.make(POSE, benchmark=bench_path, render_mode="rgb_array", fc_info=False)
    env.reset(seed=0, options={"object_id": "table-1000000"})
    before = env.render()
    assert isinstance(before, np.ndarray)
    assert before.shape == (360, 480, 3)
    assert before.dtype == np.uint8
    assert before.std() > 5.0  # not blank
    row = int(bench.object_rows("table-1000000")[0])
    env.step(action_from_poses(bench.poses[row]).astype(np.float32))
    after = env.render()
    assert after.shape == (360, 480, 3)
    assert after.std() > 5.0
    assert not np.array_equal(before, after)  # the hands moved to the action
    env.close()
    plain = DualGraspPoseEnv(benchmark=bench_path, render_width=64, render_height=48)
    assert plain.render() is None  # render_mode None
    small = DualGraspSelectEnv(
        benchmark=bench_path, render_mode="rgb_array", render_width=64, render_height=48
    )
    small.reset(seed=1)
    assert small.render().shape == (48, 64, 3)
    small.close()


def test_partial_observation_sees_one_side(bench_path: Path, bench: Benchmark) -> None:
    env = DualGraspPoseEnv(
        benchmark=bench_path, obs_mode="partial", n_points=2048, camera_resolution=48
    )
    objects = BenchmarkObjects(bench_path)
    for seed, object_id in enumerate(OBJECTS):
        obs, _ = env.reset(seed=seed, options={"object_id": object_id})
        assert obs in env.observation_space
        mask = obs["mask"].astype(bool)
        shaped = structured_observation(obs)
        points, normals = shaped["points"][mask], shaped["normals"][mask]
        assert 50 < mask.sum() < 2048  # few pixels: padded, and a mask says so
        assert np.all(mask[: mask.sum()])  # real points first
        assert not shaped["points"][~mask].any()
        lo, hi = shaped["bounds"]
        assert np.all(points >= lo - 1e-3)
        assert np.all(points <= hi + 1e-3)
        # on the surface, and every normal faces the camera that saw its point
        mesh = objects.load(object_id).mesh
        _, distance, _ = trimesh.proximity.closest_point(mesh, points.astype(np.float64))
        assert np.quantile(distance, 0.99) < 1e-3
        (camera,) = env.camera_poses
        towards = camera.position - points
        facing = np.sum(normals * towards, axis=1) > 0.0
        assert facing.mean() > 0.99
    env.close()


def test_partial_two_cameras_fill_n_points(bench_path: Path) -> None:
    env = DualGraspSelectEnv(
        benchmark=bench_path, obs_mode="partial", n_cameras=2, n_points=512, fc_info=False
    )
    obs, _ = env.reset(seed=4, options={"object_id": "crate-1000000"})
    assert obs["mask"].sum() == 512  # 128 x 128 pixels each: more than enough points
    assert len(env.camera_poses) == 2
    first, second = env.camera_poses
    gap = abs((first.azimuth - second.azimuth + 180.0) % 360.0 - 180.0)
    assert gap > 90.0  # two cameras look from roughly opposite sides
    assert np.all(np.abs(obs["points"]) <= OBSERVATION_LIMIT)
    env.close()


def test_depth_cameras_back_project_onto_the_surface(bench_path: Path) -> None:
    objects = BenchmarkObjects(bench_path)
    cameras = DepthCameras(96)
    for object_id in OBJECTS:
        scene = objects.scene(object_id)
        points, normals, poses = cameras.look(scene, np.random.default_rng(0), 2)
        mesh = objects.load(object_id).mesh
        _, distance, faces = trimesh.proximity.closest_point(mesh, points)
        assert np.median(distance) < 1e-4  # the mesh tessellates cylinders; MuJoCo does not
        assert distance.max() < 2e-3  # exact for these primitive parts up to depth precision
        agree = np.sum(mesh.face_normals[faces] * normals, axis=1) > 0.99
        assert agree.mean() > 0.97  # the face under the pixel (edges may pick a neighbour)
        assert len(poses) == 2
    cameras.close()
    cameras.close()


def test_render_falls_back_to_osmesa(bench_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """No EGL context: the renderer is made with osmesa (when it is installed) instead."""
    from dg16m_env.physics import cameras
    from dg16m_env.physics.replay import RenderError

    real = cameras.make_renderer
    tried: list[str] = []

    def egl_broken(model: Any, height: int, width: int) -> Any:
        backend = os.environ["MUJOCO_GL"]
        tried.append(backend)
        if backend == "egl":
            raise RenderError("expected an offscreen OpenGL context (MUJOCO_GL='egl'), found none")
        return real(model, height, width)

    monkeypatch.setenv("MUJOCO_GL", "egl")
    monkeypatch.setattr(cameras, "make_renderer", egl_broken)
    env = DualGraspPoseEnv(
        benchmark=bench_path, render_mode="rgb_array", render_width=64, render_height=48
    )
    env.reset(seed=0)
    failure = ""
    try:
        image = env.render()
    except RenderError as exc:  # no libOSMesa here: both reasons are given
        failure = str(exc)
    if failure:
        assert "osmesa fallback failed too" in failure
        assert os.environ["MUJOCO_GL"] == "egl"
    else:
        assert image.shape == (48, 64, 3)
        assert os.environ["MUJOCO_GL"] == "osmesa"
    assert tried[:2] == ["egl", "osmesa"]
    env.close()
