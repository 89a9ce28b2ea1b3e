"""The robust criterion on a cloud's dual candidates (baselines.cloud_robust) and the robust
cloud predictors."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from baselines.cloud_grasps import CloudError, check_cloud, cloud_dual_candidates
from baselines.cloud_predictor import (
    CLEAR_BONUS,
    FC_BONUS,
    ROBUST_BONUS,
    CloudPredictor,
    cloud_force_closure,
    random_completed_predictor,
    random_robust_predictor,
)
from baselines.cloud_robust import MIN_SIDE, MOTION_RATIO_LEVELS, cloud_inertia, robust_first
from dataset_gen.grasps.robust import disturbance_motion
from dg16m_core.parameters import PAPER
from dg16m_env.evaluators import load_benchmark_ref
from dg16m_env.subjects.observation import object_observation

PLATE = (0.5, 0.3, 0.06)  # m: thinner than the Panda's opening


def plate_cloud(n: int = 3000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    box = trimesh.creation.box(extents=PLATE)
    points, faces = trimesh.sample.sample_surface(box, n, seed=seed)
    return np.asarray(points), np.asarray(box.face_normals[faces])


def squeeze(c0: tuple[float, float], c1: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """(1, 4, 3) contacts and normals of two hands squeezing the plate top to bottom at the
    (x, y) points ``c0`` and ``c1``."""
    top = PLATE[2] / 2
    points = np.array([[*c0, top], [*c0, -top], [*c1, top], [*c1, -top]])
    normals = np.array([[0, 0, 1], [0, 0, -1], [0, 0, 1], [0, 0, -1.0]])
    return points[None], normals[None]


def test_the_inertia_of_a_cloud_is_its_solids():
    points, _ = plate_cloud()
    box = trimesh.creation.box(extents=PLATE)
    expected = box.moment_inertia * (PAPER.mass / box.mass)
    assert np.allclose(cloud_inertia(points), expected, rtol=0.02, atol=1e-4)
    assert np.allclose(cloud_inertia(points, 3.0), expected / 2.0, rtol=0.02, atol=1e-4)
    # a flat cloud has no solid hull: the box of its bounds, at least MIN_SIDE thick
    flat = points.copy()
    flat[:, 2] = 0.0
    sides = np.array([PLATE[0], PLATE[1], MIN_SIDE])
    box_inertia = PAPER.mass / 12.0 * (np.sum(sides**2) - sides**2)
    assert np.allclose(np.diag(cloud_inertia(flat)), box_inertia, rtol=0.02)
    assert np.allclose(cloud_inertia(flat[:1]), np.diag([2 * MIN_SIDE**2 * PAPER.mass / 12] * 3))
    with pytest.raises(CloudError, match=r"points: expected shape \(P, 3\) with P >= 1"):
        cloud_inertia(points[:, :2])
    with pytest.raises(CloudError, match=r"points: expected shape \(P, 3\) with P >= 1"):
        cloud_inertia(np.zeros((0, 3)))
    bad = points.copy()
    bad[3, 1] = np.nan
    with pytest.raises(CloudError, match="points: expected finite values"):
        cloud_inertia(bad)
    for mass in (0.0, -1.0, float("nan")):
        with pytest.raises(CloudError, match="mass: expected a positive finite number"):
            cloud_inertia(points, mass)


def test_a_hand_line_through_the_centre_is_robust_and_one_beside_it_is_not():
    points, _ = plate_cloud()
    inertia = cloud_inertia(points)
    through = squeeze((-0.2, 0.0), (0.2, 0.0))
    beside = squeeze((-0.2, 0.02), (0.2, 0.02))  # the same hands 2 cm to the side
    contacts = np.concatenate([through[0], beside[0]])
    normals = np.concatenate([through[1], beside[1]])
    motion = disturbance_motion(contacts, normals, center_of_mass=np.zeros(3), inertia=inertia)
    assert (motion.losses[:, 0] <= PAPER.threshold).all()  # both pass the paper's check

    def rank(passed: list[bool], **kwargs):
        scores = np.array([0.0, 1.0])
        return robust_first(scores, np.array(passed), contacts, normals, k=1, **kwargs)

    ranking = rank([True, True], bonus=ROBUST_BONUS, inertia=inertia)
    assert ranking.robust.tolist() == [True, False]
    assert ranking.ratio[0] <= 1.0 < ranking.ratio[1] <= 4.0
    # the robust one gains the whole bonus, the other the share of the levels it is within
    assert np.allclose(ranking.scores, [ROBUST_BONUS, 1.0 + ROBUST_BONUS / 3])
    only = rank([True, True], bonus=ROBUST_BONUS, inertia=inertia, max_ratios=[1.0])
    assert only.scores.tolist() == [ROBUST_BONUS, 1.0]
    # a candidate that fails force closure is never evaluated nor made robust
    ranking = rank([False, True], bonus=ROBUST_BONUS, inertia=inertia)
    assert ranking.robust.tolist() == [False, False]
    assert np.isnan(ranking.ratio[0])
    assert ranking.evaluated == 1


@pytest.fixture(scope="module")
def plate_candidates():
    points, normals = plate_cloud(4000, seed=1)
    cloud = check_cloud(points, normals)
    candidates = cloud_dual_candidates(cloud, rng=np.random.default_rng(0))
    assert candidates.n >= 500
    return cloud, candidates


@pytest.mark.parametrize("k", [1, 10, 40])
@pytest.mark.parametrize("chunk_size", [8, 64])
def test_the_lazy_ranking_is_the_full_one(plate_candidates, k: int, chunk_size: int):
    cloud, cands = plate_candidates
    passed = cloud_force_closure(cands)
    scores = np.random.default_rng(k).normal(size=cands.n) + FC_BONUS * passed
    inertia = cloud_inertia(cloud.points)
    kw = dict(k=k, bonus=ROBUST_BONUS, inertia=inertia)
    lazy = robust_first(scores, passed, cands.contact_points, cands.contact_normals, **kw,
                        chunk_size=chunk_size)  # fmt: skip
    full = robust_first(scores, passed, cands.contact_points, cands.contact_normals, **kw,
                        chunk_size=cands.n)  # fmt: skip
    assert full.evaluated == passed.sum()
    assert lazy.evaluated < passed.sum()  # it stopped early
    assert 0 < full.robust.sum() < passed.sum()
    top = np.argsort(-full.scores, kind="stable")[:k]
    assert np.array_equal(np.argsort(-lazy.scores, kind="stable")[:k], top)
    assert full.robust[top].all()  # enough robust candidates: the top k are all robust
    done = ~np.isnan(lazy.ratio)
    assert np.array_equal(lazy.ratio[done], full.ratio[done])


def test_robust_first_refuses_bad_arguments(plate_candidates):
    cloud, cands = plate_candidates
    passed = cloud_force_closure(cands)
    scores = np.zeros(cands.n)
    inertia = cloud_inertia(cloud.points)
    args = (scores, passed, cands.contact_points, cands.contact_normals)
    with pytest.raises(CloudError, match=r"scores, passed: expected shapes \(N,\) and \(N,\)"):
        robust_first(scores, passed[:-1], *args[2:], k=1, bonus=1.0, inertia=inertia)
    with pytest.raises(CloudError, match=r"contacts: expected points and normals of shape"):
        robust_first(*args[:2], cands.contact_points[:, :2], args[3], k=1, bonus=1, inertia=inertia)
    with pytest.raises(CloudError, match="k: expected an integer >= 1"):
        robust_first(*args, k=0, bonus=1.0, inertia=inertia)
    with pytest.raises(CloudError, match="bonus: expected a positive finite number"):
        robust_first(*args, k=1, bonus=0.0, inertia=inertia)
    with pytest.raises(CloudError, match="max_ratios: expected an ascending sequence"):
        robust_first(*args, k=1, bonus=1.0, inertia=inertia, max_ratios=[1.0, float("nan")])


@pytest.fixture(scope="module")
def bench_observation():
    ref = load_benchmark_ref(None)
    by_id = {o.object_id: o for o in ref.benchmark.objects}
    return object_observation(by_id["bench-1000000"].load(None))


def test_the_robust_predictor_ranks_robust_candidates_first_in_their_group(bench_observation):
    obs = bench_observation
    poses, scores = random_robust_predictor(obs)
    again = random_robust_predictor(obs)
    assert np.array_equal(poses, again[0])
    assert np.array_equal(scores, again[1])
    # the same candidates as the completed predictor, re-ordered
    cloud, cands, _ = random_robust_predictor.candidates(obs)
    plain_poses, _ = random_completed_predictor(obs)
    passed = cloud_force_closure(cands)
    clear = random_completed_predictor.clear_of_guessed_points(cloud, cands)
    motion = disturbance_motion(
        cands.contact_points,
        cands.contact_normals,
        center_of_mass=np.zeros(3),
        inertia=cloud_inertia(cloud.points),
    )
    robust = passed & (motion.ratio <= 1.0)
    group = CLEAR_BONUS * clear + FC_BONUS * passed
    levels = (motion.ratio[:, None] <= np.array(MOTION_RATIO_LEVELS)).sum(axis=1) * passed
    tier = group + ROBUST_BONUS / len(MOTION_RATIO_LEVELS) * levels
    assert 0 < (robust & (group == group.max())).sum() < 10  # the top group has too few
    index = {p.tobytes(): i for i, p in enumerate(cands.poses)}
    chosen = np.array([index[p.tobytes()] for p in poses])
    # the returned grasps are those of the best tiers, in tier order
    assert np.array_equal(tier[chosen], np.sort(tier)[::-1][:10])
    assert np.all(np.diff(scores) <= 0)
    plain = np.array([index[p.tobytes()] for p in plain_poses])
    assert robust[plain].sum() < robust[chosen].sum()  # the criterion changed the choice
    with pytest.raises(CloudError, match="robust: expected force_closure=True"):
        dataclasses.replace(random_robust_predictor, force_closure=False)
    with pytest.raises(CloudError, match="robust: expected a bool"):
        dataclasses.replace(random_robust_predictor, robust=1)
    for bad in ((), (0.0, 1.0), (2.0, 1.0), (1.0, 1.0), (1.0, float("inf")), "12", 1.0):
        with pytest.raises(CloudError, match="max_ratios: expected an ascending sequence"):
            dataclasses.replace(random_robust_predictor, motion_ratio_levels=bad)
    assert CloudPredictor("random", robust=True).robust  # any view may use it
