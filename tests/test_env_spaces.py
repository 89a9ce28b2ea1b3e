"""Hand-pose actions (6D rotations), the environment registry and the object pool."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest

import dg16m_env
from dg16m_env.envs import ENVIRONMENTS, env_ids
from dg16m_env.envs.objects import BenchmarkObjects
from dg16m_env.envs.spaces import (
    POSITION_LIMIT,
    action_from_poses,
    pose_action_bounds,
    poses_from_action,
    rotation_from_6d,
    rotation_to_6d,
)


def _random_rotations(n: int, seed: int = 0) -> np.ndarray:
    q = np.random.default_rng(seed).standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def test_6d_round_trip_is_exact_up_to_rounding():
    R = _random_rotations(500)
    back, valid = rotation_from_6d(rotation_to_6d(R))
    assert valid.all()
    np.testing.assert_allclose(back, R, atol=1e-12)


def test_any_nondegenerate_6d_decodes_to_a_rotation():
    six = np.random.default_rng(1).uniform(-1, 1, (1000, 6))
    R, valid = rotation_from_6d(six)
    assert valid.mean() > 0.99
    np.testing.assert_allclose(
        np.swapaxes(R, 1, 2) @ R, np.broadcast_to(np.eye(3), R.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    # the closing axis keeps the direction of a
    a = six[:, :3] / np.linalg.norm(six[:, :3], axis=1, keepdims=True)
    np.testing.assert_allclose(R[valid][:, :, 0], a[valid], atol=1e-12)


@pytest.mark.parametrize(
    "six",
    [
        [0, 0, 0, 0, 1, 0],  # a = 0
        [1, 0, 0, 2, 0, 0],  # b parallel to a
        [1, 0, 0, 0, 0, 0],  # b = 0
        [np.nan, 0, 0, 0, 1, 0],
    ],
)
def test_degenerate_6d_is_flagged_not_raised(six):
    R, valid = rotation_from_6d(np.array(six, dtype=float))
    assert not valid
    np.testing.assert_array_equal(R, np.eye(3))


def test_pose_actions_round_trip_and_bounds():
    poses = np.tile(np.eye(4), (3, 2, 1, 1))
    poses[..., :3, :3] = _random_rotations(6, seed=2).reshape(3, 2, 3, 3)
    poses[..., :3, 3] = np.random.default_rng(3).uniform(-0.5, 0.5, (3, 2, 3))
    action = action_from_poses(poses)
    assert action.shape == (3, 2, 9)
    back, valid = poses_from_action(action)
    assert valid.all()
    np.testing.assert_allclose(back, poses, atol=1e-12)
    low, high = pose_action_bounds()
    assert low.shape == high.shape == (2, 9)
    assert low.dtype == np.float32
    far = action.copy()
    far[0, 1, 2] = POSITION_LIMIT + 0.01
    _, valid = poses_from_action(far)
    assert valid.tolist() == [[True, False], [True, True], [True, True]]


def test_every_environment_is_registered_with_its_alias():
    assert dg16m_env.envs is not None
    for name in ENVIRONMENTS:
        assert f"dg16m_env/{name}" in gymnasium.registry
        assert name in gymnasium.registry
        assert (
            gymnasium.registry[name].entry_point
            == gymnasium.registry[f"dg16m_env/{name}"].entry_point
        )
    assert len(env_ids(aliases=True)) == 2 * len(env_ids())


def test_objects_are_drawn_with_the_generator_and_checked():
    pool = BenchmarkObjects()
    draws = [pool.choose(np.random.default_rng(7)) for _ in range(2)]
    assert draws[0] == draws[1]
    assert pool.choose(np.random.default_rng(0), "table-1000000") == "table-1000000"
    with pytest.raises(ValueError, match="expected an id of the benchmark"):
        pool.choose(np.random.default_rng(0), "no-such-object")
    with pytest.raises(ValueError, match="object_ids: expected ids"):
        BenchmarkObjects(object_ids=["no-such-object"])
    small = BenchmarkObjects(object_ids=["table-1000000"])
    assert small.choose(np.random.default_rng(5)) == "table-1000000"
    scene = small.scene("table-1000000")
    assert small.scene("table-1000000") is scene  # cached
    assert scene.object_id == "table-1000000"
