"""Sample-and-rank predictors on a point cloud (``baselines.cloud_predictor``)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import trimesh

from baselines.cloud_grasps import (
    CloudError,
    check_cloud,
    cloud_dual_candidates,
    hands_in_seen_free_space,
)
from baselines.cloud_predictor import (
    CloudPredictor,
    camera_cloud,
    camera_views,
    cgdf_predictor,
    random_partial_predictor,
)
from dataset_gen.grasps.gripper import PANDA
from dg16m_core.cli import main
from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.evaluators import load_benchmark_ref
from dg16m_env.evaluators.fce import REASONS, fce_verdicts
from dg16m_env.subjects.observation import object_observation
from dg16m_env.subjects.submission_reader import read_submission

OBJECTS = ["bench-1000000"]
RANKED = ["table-1000000", "bench-1000000", "chair-1000000"]


@pytest.fixture(scope="module")
def ref():
    return load_benchmark_ref(None)


@pytest.fixture(scope="module")
def observations(ref):
    by_id = {o.object_id: o for o in ref.benchmark.objects}
    return {i: (by_id[i].load(None), object_observation(by_id[i].load(None))) for i in RANKED}


def test_the_predictor_passes_the_runners_checks_on_a_tiny_benchmark(tmp_path: Path, capsys):
    small = tmp_path / "small.h5"
    write_benchmark(small, read_benchmark(EMBEDDED_BENCHMARK).select_objects(OBJECTS))
    kept = tmp_path / "cgdf.h5"
    argv = ["evaluate", "--predictor", "baselines.cloud_predictor:cgdf_predictor"]
    argv += ["--benchmark", str(small), "--evaluators", "fce", "--save-submission", str(kept)]
    assert main([*argv, "--no-progress"]) == 0  # the default time and memory limits
    out = capsys.readouterr().out
    assert "failed on" not in out
    sub = read_submission(kept, object_ids=OBJECTS)
    assert sub.metadata["failed_objects"] == {}
    for object_id in OBJECTS:
        assert sub.poses[object_id].shape == (10, 2, 4, 4)
        scores = sub.scores[object_id]
        assert (np.diff(scores) <= 0).all()


def fce(obj, poses: np.ndarray, ref) -> float:
    codes, _ = fce_verdicts(obj, poses, ref.benchmark.parameters().force_closure_kwargs())
    return float((codes == REASONS.index("pass")).mean())


def test_the_ranking_uses_the_classifier(observations, ref):
    """On the same seeded candidates, without the cloud force-closure check, CGDF's top-10
    close in force closure on the mesh more often than the reversed ranking's."""
    ranked = CloudPredictor("cgdf", force_closure=False)
    reverse = CloudPredictor("reversed", force_closure=False)
    ours, theirs = [], []
    for obj, obs in observations.values():
        ours.append(fce(obj, ranked(obs)[0], ref))
        theirs.append(fce(obj, reverse(obs)[0], ref))
    assert np.mean(ours) > np.mean(theirs) + 0.2, (ours, theirs)


def test_rankers_share_the_candidates_and_the_random_control_is_seeded(observations):
    _, obs = observations["bench-1000000"]
    _, ours, _ = cgdf_predictor.candidates(obs)
    _, theirs, _ = CloudPredictor("random").candidates(obs)
    assert np.array_equal(ours.poses, theirs.poses)
    control = CloudPredictor("random")
    first, again = control(obs), control(obs)
    assert np.array_equal(first[0], again[0])
    assert np.array_equal(first[1], again[1])
    other = CloudPredictor("random", seed=1)(obs)
    assert not np.array_equal(first[0], other[0])


def test_camera_cloud_shapes_and_one_camera_sees_no_antipodal_pair_on_a_box():
    box = trimesh.creation.box(extents=(0.4, 0.06, 0.3))
    obs = {
        "mesh_vertices": np.asarray(box.vertices),
        "mesh_faces": np.asarray(box.faces),
        "bounds": np.asarray(box.bounds),
    }
    rng = np.random.default_rng(0)
    points, normals, mask = camera_cloud(obs, rng, n_cameras=1, resolution=64, n_points=512)
    assert points.shape == normals.shape == (512, 3)
    assert mask.shape == (512,)
    one = check_cloud(points, normals, mask)
    assert np.abs((np.abs(one.points) - [0.2, 0.03, 0.15]).max(axis=1)).max() < 1e-6
    assert cloud_dual_candidates(one, rng=rng).counts["contact_pairs"] == 0
    two = check_cloud(*camera_cloud(obs, rng, n_cameras=2, resolution=64, n_points=2048))
    assert cloud_dual_candidates(two, rng=rng).counts["contact_pairs"] > 0


def test_the_partial_predictor_runs_and_bad_arguments_are_refused(observations):
    _, obs = observations["bench-1000000"]
    poses, scores = random_partial_predictor(obs)
    assert 1 <= len(poses) <= 10
    assert poses.shape[1:] == (2, 4, 4)
    assert scores.shape == (len(poses),)
    _, cands, _ = random_partial_predictor.candidates(obs)
    assert cands.counts["enclosing_grasps"] > 0
    assert "unseen_space" not in cands.counts  # free_space is off by default
    seen_free = dataclasses.replace(random_partial_predictor, free_space=True)
    _, fewer, _ = seen_free.candidates(obs)
    assert fewer.counts["unseen_space"] + fewer.counts["enclosing_unseen_space"] > 0
    assert fewer.grasps.n < cands.grasps.n
    with pytest.raises(CloudError, match="ranker: expected one of"):
        CloudPredictor("best")  # type: ignore[arg-type]
    with pytest.raises(CloudError, match="object_id: expected a non-empty str"):
        cgdf_predictor({"points": obs["points"]})


def test_depth_views_tell_space_seen_empty_from_space_behind_a_surface():
    """One camera above a board: above it is seen empty, just under it is not (the board hides
    it), nor is a point outside the picture; a hand under the board is refused, one above is
    not."""
    board = trimesh.creation.box(extents=(0.4, 0.3, 0.02))
    obs = {
        "mesh_vertices": np.asarray(board.vertices),
        "mesh_faces": np.asarray(board.faces),
        "bounds": np.asarray(board.bounds),
    }
    points, normals, views = camera_views(obs, np.random.default_rng(0), n_cameras=1)
    assert views.distance.shape == (1, 128, 128)
    assert np.isfinite(views.distance).sum() == len(points) == len(normals)
    above, under, away = [0.0, 0.0, 0.06], [0.0, 0.0, -0.03], [10.0, 10.0, 10.0]
    assert views.seen_free(np.array([above, under, away]), 0.005).tolist() == [True, False, False]
    depth = views.occlusion_depth(np.array([above, under, away]))
    # 5 cm in front of the board's top (the ray is slanted: longer), 4 cm behind it, no image
    assert depth[0] < -0.05
    assert 0.04 <= depth[1] < 0.2
    assert depth[2] == np.inf
    down = np.eye(4)
    down[:3, :3] = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]  # y (approach) = -z
    high, low = down.copy(), down.copy()
    high[2, 3] = 0.01 + 0.02 + PANDA.finger_tip  # fingertips 2 cm above the board
    low[2, 3] = -0.012  # the palm's top 2 mm under the board, the rest below
    assert hands_in_seen_free_space(views, np.stack([high, low]), PANDA, 0.01).tolist() == [
        True,
        False,
    ]
    skip = np.ones((2, 2), dtype=bool)  # leaving out the fingers keeps the palm's test
    assert hands_in_seen_free_space(views, np.stack([high, low]), PANDA, 0.01, skip).tolist() == [
        True,
        False,
    ]
