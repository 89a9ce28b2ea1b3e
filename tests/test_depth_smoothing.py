"""Depth smoothing before the cloud is used (baselines.depth_smoothing, issue 59)."""

from __future__ import annotations

import numpy as np
import pytest

from baselines.cloud_grasps import CloudError
from baselines.depth_smoothing import DepthSmoothing, smooth_depth, smoothed_observation
from dg16m_env.subjects.cloud_observation import (
    CloudTrack,
    back_project,
    cloud_observation,
    intrinsics_matrix,
)

K = intrinsics_matrix(64)


def plane_depth(distance: float, tilt: float = 0.3) -> np.ndarray:
    """(64, 64) ideal depth of the plane ``z = distance + tilt * y`` seen by ``K``."""
    y = (np.arange(64) + 0.5 - K[1, 2]) / K[1, 1]
    z = distance / (1.0 - tilt * y)  # a ray (x, y, 1) z meets z = distance + tilt * y z
    return np.repeat(z[:, None], 64, axis=1)


def test_a_noisy_plane_comes_closer_to_the_plane_and_missing_pixels_stay_missing() -> None:
    rng = np.random.default_rng(0)
    ideal = plane_depth(1.0)
    config = DepthSmoothing()
    noisy = ideal + config.sigma(ideal) * rng.standard_normal(ideal.shape)
    noisy[rng.random(ideal.shape) < 0.2] = 0.0
    smoothed = smooth_depth(noisy, K, config)
    seen = noisy > 0.0
    assert np.array_equal(smoothed > 0.0, seen)
    before = np.sqrt(np.mean((noisy - ideal)[seen] ** 2))
    after = np.sqrt(np.mean((smoothed - ideal)[seen] ** 2))
    assert after < 0.5 * before  # a 5 x 5 fit averages about 20 pixels' noise


def test_a_depth_step_is_not_averaged_across() -> None:
    # 8 mm: more than the gate (4 noise levels, 6 mm at 0.8 m), less than a move a plane fitted
    # across the step would be allowed (3 noise levels, 4.5 mm) at the pixels beside it.
    near, far = plane_depth(0.8, 0.0), plane_depth(0.808, 0.0)
    depth = np.where(np.arange(64)[None, :] < 32, near, far)
    smoothed = smooth_depth(depth, K)
    # Without noise every pixel already lies on its plane: the step stays a step.
    np.testing.assert_allclose(smoothed, depth, atol=1e-9)


def test_the_observation_keeps_its_pixels_and_gets_unit_normals() -> None:
    from dg16m_env.evaluators import load_benchmark_ref

    obj = load_benchmark_ref("procedural").benchmark.objects[0].load(None)
    observation = cloud_observation(obj, CloudTrack(resolution=64))
    out = smoothed_observation(observation)
    assert set(out) == set(observation)
    for key in ("points", "normals"):
        assert out[key].shape == observation[key].shape
        assert out[key].dtype == np.float32
    np.testing.assert_array_equal(out["pixels"], observation["pixels"])
    np.testing.assert_allclose(np.linalg.norm(out["normals"], axis=1), 1.0, atol=1e-5)
    moved = np.linalg.norm(out["points"] - observation["points"], axis=1)
    assert 0.0 < np.median(moved) < 0.005  # within the sensor's noise, and not a no-op
    again = smoothed_observation(observation)
    for key in ("points", "normals", "depth"):
        np.testing.assert_array_equal(again[key], out[key])
    # the point of each pixel lies on its camera's ray through the smoothed depth
    c, row, col = out["pixels"][0]
    pose = observation["camera_poses"][c]
    local = back_project(out["depth"][c].astype(np.float64), observation["intrinsics"])[row, col]
    np.testing.assert_allclose(local @ pose[:3, :3].T + pose[:3, 3], out["points"][0], atol=1e-5)


def test_malformed_observations_and_settings_get_clear_errors() -> None:
    from dg16m_env.evaluators import load_benchmark_ref

    obj = load_benchmark_ref("procedural").benchmark.objects[0].load(None)
    observation = cloud_observation(obj, CloudTrack(resolution=32))
    with pytest.raises(CloudError, match=r"expected keys \['depth'\]"):
        smoothed_observation({k: v for k, v in observation.items() if k != "depth"})
    with pytest.raises(CloudError, match=r"expected \(C, H, W\)"):
        smoothed_observation({**observation, "depth": observation["depth"][0]})
    bad = observation["depth"].copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(CloudError, match="expected finite depths"):
        smoothed_observation({**observation, "depth": bad})
    with pytest.raises(CloudError, match=r"expected .* integers"):
        smoothed_observation({**observation, "pixels": observation["pixels"][1:]})
    moved = observation["pixels"].copy()
    moved[0] = (0, *np.argwhere(observation["depth"][0] == 0)[0])  # a pixel that saw nothing
    with pytest.raises(CloudError, match="on missing pixels"):
        smoothed_observation({**observation, "pixels": moved})
    with pytest.raises(CloudError, match="radius: expected an integer in"):
        DepthSmoothing(radius=0)
    with pytest.raises(CloudError, match="gate_sigmas: expected a positive number"):
        DepthSmoothing(gate_sigmas=float("nan"))
