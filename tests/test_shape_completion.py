"""Completing a two-camera cloud with the best-fitting training shape (baselines.shape_completion)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from baselines.cloud_grasps import CloudError, hand_volume_in_object
from baselines.cloud_predictor import (
    CloudPredictor,
    random_completed_predictor,
    random_partial_predictor,
)
from baselines.shape_completion import (
    CompletionConfig,
    ShapeLibrary,
    complete_cloud,
    procedural_library,
    yaw_matrix,
)
from dataset_gen.grasps.gripper import PANDA
from dg16m_core.cli import main
from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.evaluators import load_benchmark_ref
from dg16m_env.subjects.observation import object_observation, surface_points
from dg16m_env.subjects.submission_reader import read_submission

TOLERANCE = 0.015  # m: a point "on" the true surface


@pytest.fixture(scope="module")
def objects():
    ref = load_benchmark_ref(None)
    by_id = {o.object_id: o for o in ref.benchmark.objects}
    return {i: by_id[i].load(None) for i in ("bench-1000000", "table-1000000")}


def seen(obs: dict, seed: int = 0):
    """The two-camera cloud and views of the partial predictors, for ``obs``."""
    rng = np.random.default_rng(seed)
    return random_partial_predictor.observe(obs, rng)


def true_surface(obs: dict) -> np.ndarray:
    points, _ = surface_points(
        obs["mesh_vertices"], obs["mesh_faces"], 20000, np.random.default_rng(1)
    )
    return points


def coverage(points: np.ndarray, truth: np.ndarray) -> float:
    return float(np.mean(cKDTree(points).query(truth)[0] < TOLERANCE))


def test_a_library_holding_the_object_turned_puts_the_unseen_points_on_its_surface(objects):
    obj = objects["table-1000000"]
    obs = object_observation(obj)
    turned = obj.mesh.copy()
    turned.apply_transform(np.block([[yaw_matrix(90.0), np.zeros((3, 1))], [np.zeros(3), 1.0]]))
    decoy = trimesh.creation.box(extents=np.sort(obj.mesh.extents)[::-1] * [1.0, 0.9, 1.1])
    library = ShapeLibrary.from_meshes([("decoy", decoy), ("table-turned", turned)])
    cloud, views = seen(obs)
    completion = complete_cloud(cloud, views, library)
    assert completion.fit is not None
    assert completion.fit.shape_id == "table-turned"
    assert completion.n_observed == cloud.n
    assert np.array_equal(completion.cloud.points[: cloud.n], cloud.points)
    assert completion.added > 200
    truth = true_surface(obs)
    placed, normals = completion.fit.place(library)
    _, to_mesh, _ = trimesh.proximity.closest_point(obj.mesh, placed)
    # within a few mm: the height is fitted to what the cameras saw of the legs
    assert np.median(to_mesh) < 0.003, to_mesh
    assert np.quantile(to_mesh, 0.9) < 0.01, to_mesh
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
    assert coverage(completion.cloud.points, truth) > coverage(cloud.points, truth) + 0.1


def test_the_procedural_library_completes_a_benchmark_bench(objects):
    obs = object_observation(objects["bench-1000000"])
    cloud, views = seen(obs)
    library = procedural_library()
    assert library.n == 200
    assert all("-0" in i for i in library.ids)
    completion = complete_cloud(cloud, views, library)
    assert completion.fit is not None
    assert completion.fit.shape_id.startswith("bench-")
    truth = true_surface(obs)
    added = completion.cloud.points[completion.n_observed :]
    on_surface = np.mean(cKDTree(truth).query(added)[0] < TOLERANCE)
    assert on_surface > 0.7, on_surface
    assert coverage(completion.cloud.points, truth) > coverage(cloud.points, truth) + 0.1
    again = complete_cloud(cloud, views, library)
    assert np.array_equal(again.cloud.points, completion.cloud.points)  # nothing drawn


def test_no_shape_within_the_scale_limits_leaves_the_cloud_as_seen(objects):
    obs = object_observation(objects["bench-1000000"])
    cloud, views = seen(obs)
    tiny = ShapeLibrary.from_meshes([("cube", trimesh.creation.box(extents=(0.01,) * 3))])
    completion = complete_cloud(cloud, views, tiny)
    assert completion.fit is None
    assert completion.added == 0
    assert completion.cloud is cloud
    strict = complete_cloud(cloud, views, procedural_library(), CompletionConfig(max_score=1e-6))
    assert strict.fit is None
    assert strict.added == 0


def test_a_library_survives_its_file_and_bad_libraries_are_refused(tmp_path: Path):
    box = trimesh.creation.box(extents=(0.3, 0.2, 0.1))
    library = ShapeLibrary.from_meshes([("box", box)], n_points=64)
    path = library.save(tmp_path / "lib.npz")
    back = ShapeLibrary.load(path)
    assert back.ids == ("box",)
    assert np.allclose(back.points, library.points, atol=1e-6)
    np.savez(tmp_path / "other.npz", points=np.zeros((1, 64, 3)))
    with pytest.raises(CloudError, match=r"expected a shape library .* found no format entry"):
        ShapeLibrary.load(tmp_path / "other.npz")
    with pytest.raises(CloudError, match="expected a readable shape library"):
        ShapeLibrary.load(tmp_path / "missing.npz")
    with pytest.raises(CloudError, match=r"expected shape \(1, S, 3\)"):
        ShapeLibrary(("a",), np.zeros((2, 64, 3)), np.zeros((2, 64, 3)))
    bad = library.points.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(CloudError, match="expected finite points"):
        ShapeLibrary(("box",), bad, library.normals)
    with pytest.raises(CloudError, match="xy_scale: expected 0 < low <= high"):
        CompletionConfig(xy_scale=(1.2, 0.8))


def test_the_completed_predictor_keeps_hands_on_seen_points_and_refuses_bad_settings(objects):
    obs = object_observation(objects["bench-1000000"])
    cloud, cands, _ = random_completed_predictor.candidates(obs)
    assert cands.counts["completion_added"] > 0
    n_observed = cloud.n - cands.counts["completion_added"]
    seen_contact = np.asarray(cands.grasps.face_ids) < n_observed
    assert seen_contact[cands.pairs[:, 0]].any(axis=1).all()
    assert seen_contact[cands.pairs[:, 1]].any(axis=1).all()
    assert cands.counts["seen_contacts"] == cands.n
    first, again = random_completed_predictor(obs), random_completed_predictor(obs)
    assert np.array_equal(first[0], again[0])
    # hands that come near guessed points are ranked after the others
    clear = random_completed_predictor.clear_of_guessed_points(cloud, cands)
    assert 10 <= clear.sum() < cands.n
    returned = {p.tobytes() for p in first[0]}
    assert returned <= {p.tobytes() for p in cands.poses[clear]}
    volume = hand_volume_in_object(cands.poses[~clear].reshape(-1, 4, 4), PANDA)
    guessed = cloud.points[n_observed:]
    nearest = cKDTree(guessed).query(volume.reshape(-1, 3))[0].reshape((~clear).sum(), -1)
    assert (nearest.min(axis=1) < random_completed_predictor.guessed_clearance).all()
    off = dataclasses.replace(random_completed_predictor, guessed_clearance=0.0)
    assert off.clear_of_guessed_points(cloud, cands).all()
    with pytest.raises(CloudError, match="guessed_clearance: expected a finite number >= 0"):
        dataclasses.replace(random_completed_predictor, guessed_clearance=-0.01)
    with pytest.raises(CloudError, match="completion: expected None with view='full'"):
        CloudPredictor("random", completion="procedural")
    with pytest.raises(CloudError, match="collision: expected None with completion"):
        dataclasses.replace(random_completed_predictor, collision="shipped")
    broken = dataclasses.replace(random_completed_predictor, completion="/nonexistent/lib.npz")
    with pytest.raises(CloudError, match="expected a readable shape library"):
        broken(obs)


@pytest.mark.parametrize(
    ("predictor", "object_id"),
    [("cgdf_completed_predictor", "table-1000000"), ("cgdf_robust_predictor", "chair-1000000")],
)
def test_the_completed_predictors_pass_the_runners_checks(
    tmp_path: Path, capsys, predictor: str, object_id: str
):
    small = tmp_path / "small.h5"
    write_benchmark(small, read_benchmark(EMBEDDED_BENCHMARK).select_objects([object_id]))
    kept = tmp_path / "completed.h5"
    argv = ["evaluate", "--predictor", f"baselines.cloud_predictor:{predictor}"]
    argv += ["--benchmark", str(small), "--evaluators", "fce", "--save-submission", str(kept)]
    assert main([*argv, "--no-progress"]) == 0  # the default time and memory limits
    assert "failed on" not in capsys.readouterr().out
    sub = read_submission(kept, object_ids=[object_id])
    assert sub.metadata["failed_objects"] == {}
    assert sub.poses[object_id].shape == (10, 2, 4, 4)


def test_the_library_command_reads_a_mesh_folder(tmp_path: Path, capsys):
    from baselines.shape_completion import main as library_main

    for name, extents in (("a", (0.3, 0.2, 0.1)), ("b", (0.5, 0.4, 0.3))):
        trimesh.creation.box(extents=extents).export(tmp_path / f"{name}.obj")
    out = tmp_path / "lib.npz"
    assert library_main(["--meshes", str(tmp_path), "--out", str(out), "--points", "64"]) == 0
    library = ShapeLibrary.load(out)
    assert library.ids == ("a", "b")
    assert library.points.shape == (2, 64, 3)
    assert np.allclose(library.extents[1], (0.5, 0.4, 0.3), atol=0.02)
    with pytest.raises(SystemExit):
        library_main(["--meshes", str(tmp_path / "none"), "--out", str(out)])
    assert "expected some .obj files" in capsys.readouterr().err
