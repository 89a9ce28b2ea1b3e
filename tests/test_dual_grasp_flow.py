"""The learned dual-grasp generator (issue 59): its pose representation, sampling determinism,
the training command on a 5-object dataset (runs, resumes to the same weights, refuses another
run's state), the shipped weights on a procedural and a real object through the cloud track, the
snap onto a cloud, and clear errors for a malformed cloud."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import baselines.train_dual_grasp_flow as training  # noqa: E402
from baselines.cloud_grasps import CloudError, check_cloud  # noqa: E402
from baselines.dual_grasp_flow import (  # noqa: E402
    AnchoredGraspFlow,
    AnchoredGraspFlowConfig,
    hands_to_vectors,
    vectors_to_hands,
)
from baselines.flow_predictor import (  # noqa: E402
    GENERATOR_CHECKPOINT,
    RANKER_CHECKPOINT,
    FlowPredictor,
    flow_predictor,
    snap_hands,
)
from baselines.grasp_geometry import load_checkpoint  # noqa: E402
from dataset_gen.collection.build import build_dataset  # noqa: E402
from dataset_gen.collection.recipe import DatasetRecipe  # noqa: E402
from dataset_gen.collection.splits import Exclusion  # noqa: E402
from dataset_gen.grasps.gripper import get_gripper  # noqa: E402
from dg16m_env.benchmark.names import REAL_BENCHMARK  # noqa: E402
from dg16m_env.evaluators import load_benchmark_ref  # noqa: E402
from dg16m_env.subjects.cloud_observation import cloud_observation  # noqa: E402


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("flow") / "ds"
    recipe = DatasetRecipe(objects=5, sources=("procedural",), validation_fraction=0.3)
    build_dataset(out, recipe, Exclusion(), progress=False, card=False, log=lambda _: None)
    return out


def tiny_args(dataset: Path, out: Path) -> training.Args:
    return training.Args(
        dataset=dataset,
        out=out,
        n_points=128,
        grasps_per_object=8,
        objects_per_batch=2,
        grasps_per_batch=4,
        generator_steps=2,
        ranker_objects=3,
        ranker_samples=16,
        ranker_steps=2,
        ranker_batch_objects=2,
        ranker_grasps=4,
        eval_every=1,
        init_generator=str(GENERATOR_CHECKPOINT),  # a 2-step model from scratch pairs nothing
    )


def weights(path: Path) -> dict[str, torch.Tensor]:
    model, _ = load_checkpoint(path)
    return model.state_dict()


def test_vectors_round_trip_and_any_vector_is_a_rigid_pose() -> None:
    rng = np.random.default_rng(0)
    q, _ = np.linalg.qr(rng.normal(size=(6, 3, 3)))
    q *= np.sign(np.linalg.det(q))[:, None, None]
    poses = np.tile(np.eye(4), (6, 1, 1))
    poses[:, :3, :3], poses[:, :3, 3] = q, rng.normal(size=(6, 3)) * 0.2
    poses = torch.as_tensor(poses)
    anchors = torch.as_tensor(rng.normal(size=(6, 3)) * 0.2)
    vectors = hands_to_vectors(poses, anchors, 0.1034, 0.05)
    assert vectors.shape == (6, 9)
    assert torch.allclose(vectors_to_hands(vectors, anchors, 0.1034, 0.05), poses, atol=1e-12)
    anything = vectors_to_hands(torch.randn(5, 9, dtype=torch.float64), anchors[:5], 0.1, 0.05)
    rotation = anything[..., :3, :3]
    eye = torch.eye(3, dtype=torch.float64).expand_as(rotation)
    assert torch.allclose(rotation @ rotation.transpose(-1, -2), eye, atol=1e-12)
    assert torch.allclose(torch.linalg.det(rotation), torch.ones(5, dtype=torch.float64))


def small_model() -> AnchoredGraspFlow:
    return AnchoredGraspFlow(
        AnchoredGraspFlowConfig(
            point_widths=(16,), patch_widths=(8,), condition_width=8, hidden_widths=(16,), steps=4
        )
    )


def test_sampling_is_deterministic_for_a_seed_and_refuses_a_bad_cloud() -> None:
    model = small_model()
    points = np.random.default_rng(1).normal(size=(100, 3)) * 0.2
    anchors = np.arange(7)
    a = model.sample(points, anchors, torch.Generator().manual_seed(3))
    b = model.sample(points, anchors, torch.Generator().manual_seed(3))
    c = model.sample(points, anchors, torch.Generator().manual_seed(4))
    assert a.shape == (7, 4, 4)
    assert a.dtype == torch.float32
    assert torch.equal(a, b)
    assert not torch.equal(a, c)
    chance = model.anchor_probabilities(points)
    assert chance.shape == (100,)
    assert bool(((chance > 0) & (chance < 1)).all())
    with pytest.raises(ValueError, match=r"expected shape \(P, 3\)"):
        model.sample(points[:, :2], anchors, torch.Generator())
    with pytest.raises(ValueError, match=r"anchors: expected \(M,\) indices in \[0, 100\)"):
        model.sample(points, np.array([0, 100]), torch.Generator())
    bad = points.copy()
    bad[5, 1] = np.nan
    with pytest.raises(ValueError, match="expected finite values"):
        model.sample(bad, anchors, torch.Generator())


def test_sources_keep_only_the_named_collections_and_refuse_an_absent_one(
    dataset: Path, tmp_path: Path
) -> None:
    args = replace(tiny_args(dataset, tmp_path / "run"), sources="procedural")
    every = training.open_dataset(replace(args, sources=""), "train")
    kept = training.open_dataset(args, "train")
    assert {r.source for r in every.records} == {"procedural"}
    assert kept.object_ids == every.object_ids == [r.object_id for r in kept.records]
    with pytest.raises(training.TrainingArgumentsError, match=r"expected some of \['procedural'\]"):
        training.open_dataset(replace(args, sources="sweethome3d"), "train")


def test_training_runs_resumes_to_the_same_weights_and_refuses_another_runs_state(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    whole = tiny_args(dataset, tmp_path / "whole")
    state = training.main(whole)
    assert state["stage"] == "done"
    for name in ("grasp-flow.pt", "grasp-flow-ranker.pt", "history.json", "curves.png"):
        assert (whole.out / name).is_file()
    samples = sorted((whole.out / "samples").glob("*.npz"))
    assert len(samples) == 3
    sizes = []
    for file in samples:
        with np.load(file) as data:
            assert data["poses"].shape[1:] == (2, 4, 4)
            assert data["label"].dtype == bool
            sizes.append(len(data["label"]))
    assert sum(sizes) >= 1  # an object without a dual candidate on its cloud has none
    assert all(0 <= size <= 16 for size in sizes)  # at most ranker_samples

    # Stop after the first generator step, then rerun: the same weights as without the stop.
    parted = tiny_args(dataset, tmp_path / "parted")
    batch, calls = training.generator_batch, []

    def stop_at_step_one(args, ds, data, step, split):
        if split == "train" and step == 1 and not calls:
            calls.append(step)
            raise training._StopRequestedError("SIGTERM")
        return batch(args, ds, data, step, split)

    monkeypatch.setattr(training, "generator_batch", stop_at_step_one)
    with pytest.raises(SystemExit) as stopped:
        training.main(parted)
    assert stopped.value.code == 130
    assert training.load_state(parted)["step"] == 1
    training.main(parted)
    for name in ("grasp-flow.pt", "grasp-flow-ranker.pt"):
        ours, theirs = weights(parted.out / name), weights(whole.out / name)
        assert all(torch.equal(ours[k], theirs[k]) for k in theirs)

    with pytest.raises(training.TrainingArgumentsError, match=r"differs in \['generator_steps'\]"):
        training.main(replace(parted, generator_steps=3))


def test_ranker_samples_drawn_from_the_cloud_force_closure_group_all_pass_on_the_cloud(
    dataset: Path, tmp_path: Path
) -> None:
    args = tiny_args(dataset, tmp_path / "run")
    args.out.mkdir(parents=True)
    (args.out / "grasp-flow.pt").symlink_to(GENERATOR_CHECKPOINT.resolve())
    record, _ = training.sample_objects(args)[0]
    every = training.object_samples(replace(args, ranker_samples=1024), record)
    passing = training.object_samples(
        replace(args, ranker_samples=1024, ranker_pairs="cloud_force_closure"), record
    )
    assert every["cloud_force_closure"].sum() >= 1  # the group is not empty on this object
    assert passing["cloud_force_closure"].all()
    assert len(passing["label"]) == every["cloud_force_closure"].sum()  # all of the group
    with pytest.raises(training.TrainingArgumentsError, match="--ranker-pairs: expected one of"):
        training.main(replace(args, ranker_pairs="passing"))


@pytest.fixture(scope="module")
def procedural_object():
    ref = load_benchmark_ref(None)
    return next(o for o in ref.benchmark.objects if o.object_id == "chair-1000000").load(None)


def test_the_shipped_weights_give_valid_poses_on_a_procedural_object(procedural_object) -> None:
    assert GENERATOR_CHECKPOINT.stat().st_size + RANKER_CHECKPOINT.stat().st_size < 20e6
    observation = cloud_observation(procedural_object)
    poses, scores = flow_predictor(observation)
    assert poses.shape == (10, 2, 4, 4)
    assert poses.dtype == np.float64
    assert scores.shape == (10,)
    assert np.all(np.diff(scores) <= 0)
    rotation = poses[..., :3, :3]
    np.testing.assert_allclose(
        rotation @ np.swapaxes(rotation, -1, -2),
        np.broadcast_to(np.eye(3), rotation.shape),
        atol=1e-9,
    )
    again, _ = flow_predictor(observation)
    np.testing.assert_array_equal(poses, again)
    other, _ = FlowPredictor(seed=1)(observation)
    assert not np.array_equal(poses, other)


@pytest.mark.skipif(
    not REAL_BENCHMARK.is_file(), reason=f"the real benchmark is not shipped ({REAL_BENCHMARK})"
)
def test_the_shipped_weights_give_valid_poses_on_a_real_object() -> None:
    obj = load_benchmark_ref("real").benchmark.objects[0].load(None)
    poses, scores = flow_predictor(cloud_observation(obj))
    assert poses.shape == (10, 2, 4, 4)
    assert np.all(np.isfinite(poses))
    assert np.all(np.isfinite(scores))


def test_a_malformed_cloud_gets_the_clouds_error(procedural_object) -> None:
    observation = cloud_observation(procedural_object)
    bad = dict(observation, points=observation["points"].copy())
    bad["points"][3, 0] = np.nan
    with pytest.raises(CloudError, match="NaN"):
        flow_predictor(bad)
    with pytest.raises(CloudError, match=r"expected two \(P, 3\) arrays"):
        flow_predictor(dict(observation, points=observation["points"][:, :2]))
    with pytest.raises(CloudError, match="expected keys"):
        flow_predictor({"depth": observation["depth"]})


def test_a_hand_around_a_bar_snaps_onto_it_and_one_through_it_is_dropped() -> None:
    # A 3 cm x 3 cm bar along z, sampled on its four sides, with outward normals.
    t = np.linspace(-0.015, 0.015, 7)
    z = np.linspace(-0.2, 0.2, 81)
    points, normals = [], []
    for axis, sign in ((0, 1), (0, -1), (1, 1), (1, -1)):
        a, b = np.meshgrid(t, z)
        p = np.zeros((a.size, 3))
        p[:, axis], p[:, 1 - axis], p[:, 2] = 0.015 * sign, a.ravel(), b.ravel()
        n = np.zeros_like(p)
        n[:, axis] = sign
        points.append(p)
        normals.append(n)
    cloud = check_cloud(np.concatenate(points), np.concatenate(normals))
    around = np.eye(4)  # closing along x, approach along y, grasp centre 1 cm off the bar's axis
    around[:3, 3] = (0.01, -get_gripper("panda").contact_depth, 0.1)
    through = np.eye(4)
    through[:3, 3] = (0.0, -0.033, -0.1)  # the bar runs through the palm (y in [0, 0.066])
    far = np.eye(4)
    far[:3, 3] = (0.5, 0.0, 0.0)  # holds nothing
    kept, singles = snap_hands(cloud, np.stack([around, through, far]))
    assert kept.tolist() == [True, False, False]
    assert singles.n == 1
    np.testing.assert_allclose(singles.widths, [0.03], atol=1e-9)
    np.testing.assert_allclose(singles.poses[0, 0, 3], 0.0, atol=1e-9)  # centred on the bar
    np.testing.assert_allclose(np.abs(singles.contact_points[0, :, 0]), 0.015, atol=1e-9)


@pytest.mark.parametrize(
    "name",
    ["flow_predictor", "flow_random_predictor", "flow_smoothed_predictor", "flow_robust_predictor"],
)
def test_the_registered_predictors_run_on_the_cloud_track(tmp_path: Path, name: str) -> None:
    from dg16m_env.subjects.predictor import submission_from_predictor
    from dg16m_env.subjects.predictor_process import PredictorSpec
    from dg16m_env.subjects.submission_reader import read_submission

    objects = ["tub-1000000", "chair-1000000"]
    path, run = submission_from_predictor(
        PredictorSpec(f"baselines.flow_predictor:{name}"),
        tmp_path / f"{name}.h5",
        benchmark=load_benchmark_ref(None).subset(objects),
        track="cloud",
        progress=False,
    )
    assert run.errors == {}
    submission = read_submission(path, object_ids=objects)
    assert submission.metadata["track"]["name"] == "cloud"


def test_depth_smoothing_moves_the_same_points_a_little_and_keeps_the_stream(
    procedural_object,
) -> None:
    from baselines.depth_smoothing import DepthSmoothing

    observation = cloud_observation(procedural_object)
    raw, *_ = FlowPredictor().candidates(observation)
    smooth, *_ = FlowPredictor(smoothing=DepthSmoothing()).candidates(observation)
    # the same pixels drawn (the stream is named by the observation as given), each moved
    # along its ray by less than the sensor's noise
    moved = np.linalg.norm(smooth.points - raw.points, axis=1)
    assert 0.0 < np.median(moved) < 0.005
    again, *_ = FlowPredictor(smoothing=DepthSmoothing()).candidates(observation)
    np.testing.assert_array_equal(again.points, smooth.points)


def test_the_ablations_share_the_samplers_draws_and_refuse_bad_settings(procedural_object) -> None:
    observation = cloud_observation(procedural_object)
    _, both, _, _ = FlowPredictor(proposals="generator+sampler").candidates(observation)
    _, sampler, _, _ = FlowPredictor(proposals="sampler").candidates(observation)
    _, generator, _, _ = FlowPredictor(proposals="generator").candidates(observation)
    assert both.counts["kept_hands"] == generator.counts["kept_hands"]
    assert sampler.counts["kept_hands"] == 0
    assert both.counts["sampler_hands"] == sampler.counts["sampler_hands"]
    for bad in ({"proposals": "mesh"}, {"anchors": "top"}, {"ranker": "cgdf"}, {"k": 0}):
        with pytest.raises(CloudError, match="expected"):
            FlowPredictor(**bad)


def test_lift_with_generated_grasps_runs_both_settings(tmp_path: Path) -> None:
    from baselines.lift_generated_grasps import Args, main

    results = main(Args(episodes=1, out=tmp_path / "lift.json"))
    assert results["episodes"] == 1
    for setting in ("benchmark_grasp", "generated_grasp"):
        assert results[setting]["episodes"] == 1
    assert (tmp_path / "lift.json").is_file()


def test_the_robust_variant_ranks_pairs_by_their_level_then_by_the_ranker() -> None:
    from baselines.cloud_robust import MOTION_RATIO_LEVELS, cloud_inertia
    from dataset_gen.grasps.robust import disturbance_motion

    ref = load_benchmark_ref(None)
    shelf = next(o for o in ref.benchmark.objects if o.object_id == "shelf-1000000")
    observation = cloud_observation(shelf.load(None))  # passing pairs on all four levels
    predictor = FlowPredictor(robust=True)
    cloud, candidates, passed, _ = predictor.candidates(observation)
    assert passed.sum() > predictor.k  # enough passing pairs for the levels to decide the top
    motion = disturbance_motion(
        candidates.contact_points[passed],
        candidates.contact_normals[passed],
        center_of_mass=np.zeros(3),
        inertia=cloud_inertia(cloud.points),
    )
    level = np.full(candidates.n, -1)  # -1: fails force closure on the cloud
    level[passed] = (motion.ratio[:, None] <= np.asarray(MOTION_RATIO_LEVELS)).sum(axis=1)
    poses, scores = predictor(observation)
    flat = candidates.poses.reshape(candidates.n, -1)
    chosen = [int(np.flatnonzero((flat == p.ravel()).all(axis=1))[0]) for p in poses]
    got = level[chosen]
    assert np.all(np.diff(got) <= 0)  # best level first, the ranker within a level
    left_out = np.setdiff1d(np.arange(candidates.n), chosen)
    assert got.min() >= level[left_out].max()  # none left out is on a better level
    assert np.all(np.diff(scores) <= 0)
    plain, _ = FlowPredictor()(observation)
    assert not np.array_equal(plain, poses)  # the levels changed the top here
    assert len(np.unique(level[passed])) == 4
    with pytest.raises(CloudError, match="robust: expected a bool"):
        FlowPredictor(robust=1)
    with pytest.raises(CloudError, match="expected"):
        FlowPredictor(motion_ratio_levels=(2.0, 1.0))
