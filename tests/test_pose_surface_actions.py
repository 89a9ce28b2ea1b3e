"""DualGraspPose-v0's surface actions (``action_mode="surface"``): the mapping from ``[point,
roll, depth]`` to hand poses, the environment in that mode (both checkers, determinism, errors,
degenerate normals) and the default pose mode left as it was."""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import dg16m_env  # noqa: F401  registers the environments
from dataset_gen.grasps.gripper import PANDA
from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.envs.common import (
    EnvArgumentError,
    check_box_action,
    structured_observation,
    trial_info,
)
from dg16m_env.envs.dual_grasp_pose import DualGraspPoseEnv
from dg16m_env.envs.pose_surface_actions import (
    INVALID_NO_POINT,
    INVALID_NORMAL,
    STANDOFF_MAX,
    STANDOFF_MIN,
    approach_rotations,
    height_order,
    point_indices,
    poses_from_surface_action,
    roll_angles,
    standoffs,
    surface_poses,
)
from dg16m_env.envs.spaces import pose_action_bounds, poses_from_action

OBJECTS = ["table-1000000", "frame-1000000", "crate-1000000"]
POSE = "dg16m_env/DualGraspPose-v0"


@pytest.fixture(scope="module")
def bench_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A three-object benchmark cut from the embedded one."""
    path = tmp_path_factory.mktemp("surface") / "small.h5"
    write_benchmark(path, read_benchmark(EMBEDDED_BENCHMARK).select_objects(OBJECTS))
    return path


@pytest.fixture
def strict() -> Iterator[None]:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# --------------------------------------------------------------------------------------------
# The mapping
# --------------------------------------------------------------------------------------------


def test_point_indices_cover_every_rank() -> None:
    n = 7
    assert point_indices(np.array(-1.0), n) == 0
    assert point_indices(np.array(1.0), n) == n - 1
    grid = np.linspace(-1.0, 1.0, 1001)
    ranks = point_indices(grid, n)
    assert set(ranks.tolist()) == set(range(n))
    assert np.all(np.diff(ranks) >= 0)
    np.testing.assert_array_equal(ranks, np.clip(np.floor((grid + 1) / 2 * n), 0, n - 1))
    assert point_indices(np.zeros((2,)), 0).tolist() == [-1, -1]


def test_height_order_sorts_valid_points_stably() -> None:
    points = np.array([[0, 0, 0.3], [1, 0, -0.2], [2, 0, 0.3], [3, 0, 0.1], [4, 0, -1.0]])
    np.testing.assert_array_equal(height_order(points), [4, 1, 3, 0, 2])
    mask = np.array([1, 1, 1, 1, 0], dtype=np.float32)
    np.testing.assert_array_equal(height_order(points, mask), [1, 3, 0, 2])
    assert height_order(points, np.zeros(5)).size == 0


def test_approach_axis_is_the_inward_normal_and_frames_are_rotations() -> None:
    rng = np.random.default_rng(0)
    normals = _unit(rng.normal(size=(500, 3))) * rng.uniform(0.5, 3.0, size=(500, 1))  # any length
    angles = rng.uniform(-np.pi, np.pi, 500)
    rotations, valid = approach_rotations(normals, angles)
    assert valid.all()
    np.testing.assert_allclose(rotations[:, :, 1], -_unit(normals), atol=1e-12)
    eye = np.einsum("nji,njk->nik", rotations, rotations)
    np.testing.assert_allclose(eye, np.broadcast_to(np.eye(3), eye.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rotations), 1.0, atol=1e-12)


def test_roll_zero_closes_vertically_and_roll_turns_the_closing_axis() -> None:
    side = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.2], [-0.6, 0.8, 0.0]])
    rotations, _ = approach_rotations(side, np.zeros(3))
    x0 = rotations[:, :, 0]
    # roll 0: the object's up axis projected perpendicular to the approach (here: +z itself
    # for horizontal normals)
    up = np.array([0.0, 0.0, 1.0])
    expected = _unit(up - (rotations[:, :, 1] @ up)[:, None] * rotations[:, :, 1])
    np.testing.assert_allclose(x0, expected, atol=1e-12)
    # a near-vertical approach takes the object's x axis instead
    top, _ = approach_rotations(np.array([[0.0, 0.1, 1.0]]), np.zeros(1))
    assert abs(top[0, 0, 0]) > 0.99
    # roll r turns x by pi * r about the approach axis (right-handed, Rodrigues' formula)
    y = rotations[:, :, 1]
    for roll in (-1.0, -0.5, 0.25, 0.5, 1.0):
        turned, _ = approach_rotations(side, roll_angles(np.full(3, roll)))
        x = turned[:, :, 0]
        np.testing.assert_allclose(turned[:, :, 1], y, atol=1e-12)
        theta = np.pi * roll
        np.testing.assert_allclose(x, x0 * np.cos(theta) + np.cross(y, x0) * np.sin(theta))
        signed = np.arctan2(np.sum(np.cross(x0, x) * y, axis=1), np.sum(x * x0, axis=1))
        np.testing.assert_allclose(np.abs(signed), abs(theta), atol=1e-9)
        if abs(roll) < 1.0:
            np.testing.assert_allclose(signed, theta, atol=1e-9)


def test_depth_moves_the_flange_along_the_normal() -> None:
    point = np.array([[0.1, -0.2, 0.3]])
    normal = np.array([[0.0, 0.6, 0.8]])
    assert standoffs(np.array(-1.0)) == pytest.approx(PANDA.palm_depth)
    assert standoffs(np.array(1.0)) == pytest.approx(PANDA.finger_tip)
    assert PANDA.palm_depth == STANDOFF_MIN
    assert PANDA.finger_tip == STANDOFF_MAX
    depths = np.linspace(-1.0, 1.0, 5)
    flanges = []
    for depth in depths:
        s = standoffs(np.array([depth]))
        poses, valid = surface_poses(point, normal, np.array([0.3]), s)
        assert valid.all()
        np.testing.assert_allclose(poses[0, :3, 3], point[0] + s[0] * normal[0], atol=1e-12)
        centre = poses[0, :3, 3] + PANDA.contact_depth * poses[0, :3, 1]
        np.testing.assert_allclose(centre, point[0] + (s[0] - PANDA.contact_depth) * normal[0])
        flanges.append(poses[0, :3, 3])
    steps = np.diff(np.array(flanges), axis=0)
    np.testing.assert_allclose(_unit(steps), np.tile(normal, (4, 1)), atol=1e-12)
    np.testing.assert_allclose(
        np.linalg.norm(steps, axis=1), (PANDA.finger_tip - PANDA.palm_depth) / 4
    )
    # the grasp centre lands on the point at s = contact_depth
    depth = 2 * (PANDA.contact_depth - STANDOFF_MIN) / (STANDOFF_MAX - STANDOFF_MIN) - 1
    poses, _ = surface_poses(point, normal, np.zeros(1), standoffs(np.array([depth])))
    centre = poses[0, :3, 3] + PANDA.contact_depth * poses[0, :3, 1]
    np.testing.assert_allclose(centre, point[0], atol=1e-12)


def test_action_rows_pick_points_by_height_rank() -> None:
    rng = np.random.default_rng(1)
    points = rng.uniform(-0.5, 0.5, size=(10, 3))
    normals = _unit(rng.normal(size=(10, 3)))
    mask = np.ones(10)
    mask[[2, 7]] = 0.0
    order = height_order(points, mask)
    action = np.array([[-1.0, 0.0, 0.0], [1.0, 0.5, -1.0]])
    poses, valid, indices, reasons = poses_from_surface_action(action, points, normals, mask)
    assert valid.all()
    assert reasons == [None, None]
    assert indices.tolist() == [order[0], order[-1]]
    assert indices[0] == np.flatnonzero(mask)[np.argmin(points[mask > 0, 2])]
    expected, _ = surface_poses(
        points[indices], normals[indices], roll_angles(action[:, 1]), standoffs(action[:, 2])
    )
    np.testing.assert_array_equal(poses, expected)
    assert 2 not in indices.tolist()
    assert 7 not in indices.tolist()


def test_degenerate_normals_and_empty_clouds_are_masked() -> None:
    points = np.zeros((3, 3))
    normals = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [np.nan, 0.0, 1.0]])
    points[:, 2] = [0.0, 1.0, 2.0]  # height ranks 0, 1, 2
    action = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    poses, valid, indices, reasons = poses_from_surface_action(action, points, normals)
    assert valid.tolist() == [True, False]
    assert indices.tolist() == [0, 1]
    assert reasons == [None, INVALID_NORMAL]
    np.testing.assert_array_equal(poses[1], np.eye(4))
    action = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    _, valid, _, reasons = poses_from_surface_action(action, points, normals)
    assert reasons == [INVALID_NORMAL, INVALID_NORMAL]
    _, valid, indices, reasons = poses_from_surface_action(action, points, normals, np.zeros(3))
    assert not valid.any()
    assert indices.tolist() == [-1, -1]
    assert reasons == [INVALID_NO_POINT, INVALID_NO_POINT]
    short = approach_rotations(np.array([[0.0, 0.0, 0.49]]), np.zeros(1))[1]
    assert not short.any()


# --------------------------------------------------------------------------------------------
# The environment in surface mode
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs",
    [{}, {"obs_mode": "partial", "camera_resolution": 64, "perturb": False, "fc_info": False}],
)
def test_check_env_surface(kwargs: dict, bench_path: Path, strict: None) -> None:
    env = gym.make(POSE, benchmark=bench_path, action_mode="surface", **kwargs)
    try:
        assert env.action_space == gym.spaces.Box(-1.0, 1.0, (2, 3), np.float32)
        gym_check_env(env.unwrapped)
        sb3_check_env(env.unwrapped)
    finally:
        env.close()


def test_surface_step_runs_the_mapped_poses(bench_path: Path) -> None:
    env = DualGraspPoseEnv(benchmark=bench_path, action_mode="surface", perturb=False)
    for seed, action in enumerate(
        [[[-0.9, 0.5, -0.2], [0.9, 0.5, -0.2]], [[0.0, 0.0, -0.5], [0.4, 0.0, -0.5]]]
    ):
        obs, _ = env.reset(seed=seed)
        action = np.asarray(action, dtype=np.float32)
        cloud = structured_observation(obs)
        expected, valid, indices, _ = poses_from_surface_action(
            action, cloud["points"], cloud["normals"]
        )
        assert valid.all()
        _, reward, terminated, truncated, info = env.step(action)
        assert terminated
        assert not truncated
        assert info["point_index"] == tuple(indices.tolist())
        assert env.last_trial_poses is not None
        np.testing.assert_array_equal(env.last_trial_poses, expected)  # unperturbed
        assert reward == float(info["success"])
        assert info["fc_reason"] is not None
    env.close()


def test_surface_partial_mode_picks_real_points(bench_path: Path) -> None:
    env = DualGraspPoseEnv(
        benchmark=bench_path,
        action_mode="surface",
        obs_mode="partial",
        camera_resolution=32,  # fewer pixels on the object than points: padding
        fc_info=False,
    )
    obs, _ = env.reset(seed=4)
    assert 0 < obs["mask"].sum() < obs["mask"].size
    real = set(np.flatnonzero(obs["mask"] > 0.5).tolist())
    for point in np.linspace(-1.0, 1.0, 9):
        env.reset(seed=4)
        action = np.array([[point, 0.0, 1.0], [-point, 0.5, 1.0]], dtype=np.float32)
        info = env.step(action)[4]
        assert set(info["point_index"]) <= real
    env.close()


def test_surface_seeded_determinism(bench_path: Path) -> None:
    runs = []
    for _ in range(2):
        env = gym.make(POSE, benchmark=bench_path, action_mode="surface")
        env.action_space.seed(3)
        steps = []
        for seed in range(3):
            obs, _ = env.reset(seed=seed)
            _, reward, _, _, info = env.step(env.action_space.sample())
            steps.append((obs["points"].tobytes(), reward, sorted(info.items(), key=str)))
        runs.append(steps)
        env.close()
    assert repr(runs[0]) == repr(runs[1])


def test_degenerate_normal_fails_the_episode(bench_path: Path) -> None:
    env = DualGraspPoseEnv(benchmark=bench_path, action_mode="surface")
    env.reset(seed=0)
    assert env._observation is not None
    env._observation["normals"][:] = 0.0  # as if the observed cloud had no usable normal
    _, reward, terminated, truncated, info = env.step(np.zeros((2, 3), dtype=np.float32))
    assert reward == 0.0
    assert terminated
    assert not truncated
    assert info["success"] is False
    assert info["invalid_reason"] == INVALID_NORMAL
    assert info["status"] == "not_run"
    assert info["fc_passed"] is False
    assert len(info["point_index"]) == 2
    assert env.last_trial_poses is None
    env.close()


@pytest.mark.parametrize(
    ("action", "found"),
    [
        (np.zeros((2, 9), dtype=np.float32), "found an array of shape (2, 9)"),
        (np.zeros(6, dtype=np.float32), "found an array of shape (6,)"),
        (np.array([[np.nan, 0, 0], [0, 0, 0]]), "found nan at index (0, 0)"),
        (np.array([[0, 0, 0], [0, 1.5, 0]]), "found 1.5 at index (1, 1), outside [-1.0, 1.0]"),
        ("left", "dtype <U4 (expected real numbers)"),
    ],
)
def test_surface_bad_actions_name_the_space(action: object, found: str, bench_path: Path) -> None:
    env = DualGraspPoseEnv(benchmark=bench_path, action_mode="surface", fc_info=False)
    env.reset(seed=0)
    with pytest.raises(EnvArgumentError) as excinfo:  # a ValueError
        env.step(action)
    message = str(excinfo.value)
    assert isinstance(excinfo.value, ValueError)
    assert message.startswith("action: expected an element of Box(-1.0, 1.0, (2, 3), float32)")
    assert found in message
    env.close()


@pytest.mark.parametrize("mode", ["Surface", "points", 3, None])
def test_bad_action_mode(mode: object, bench_path: Path) -> None:
    with pytest.raises(EnvArgumentError, match=r"action_mode: expected one of \('pose', "):
        DualGraspPoseEnv(benchmark=bench_path, action_mode=mode)  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------------
# The default mode is what it was
# --------------------------------------------------------------------------------------------


def test_default_mode_is_the_pose_mode_unchanged(bench_path: Path) -> None:
    """The default env, ``action_mode="pose"`` and the pre-option code path (check the action,
    decode the 6D rotation, one trial) give the same bytes, seed for seed."""
    default = gym.make(POSE, benchmark=bench_path)
    explicit = gym.make(POSE, benchmark=bench_path, action_mode="pose")
    before = DualGraspPoseEnv(benchmark=bench_path)
    low, high = pose_action_bounds(2)
    for env in (default, explicit):
        assert env.action_space == gym.spaces.Box(low, high, dtype=np.float32)
    default.action_space.seed(7)
    actions = [default.action_space.sample() for _ in range(3)]
    actions.append(np.zeros((2, 9), dtype=np.float32))  # degenerate rotation
    for seed, action in enumerate(actions):
        outs = []
        for env in (default, explicit):
            obs, _ = env.reset(seed=seed)
            outs.append((obs, *env.step(action)))
        obs, _ = before.reset(seed=seed)
        poses, valid = poses_from_action(check_box_action(action, before.action_space))
        if valid.all():
            info = trial_info(before.object_id, before.trial(poses))
        else:
            info = before.step(action)[4]
        assert "point_index" not in outs[0][-1]
        assert repr(outs[0]) == repr(outs[1])
        assert repr(sorted(outs[0][-1].items())) == repr(sorted(info.items()))
        assert outs[0][0]["points"].tobytes() == obs["points"].tobytes()
    for env in (default, explicit, before):
        env.close()
