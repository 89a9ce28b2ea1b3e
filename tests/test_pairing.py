"""Pairing of single-arm grasps: candidates, gripper-gripper collision, ablations, selection."""

from __future__ import annotations

import fcl
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dataset_gen.force_closure import evaluate
from dataset_gen.grasps.gripper import PANDA
from dataset_gen.grasps.pairing import (
    STRATEGIES,
    PairingError,
    candidate_pairs,
    dual_contacts,
    dual_poses,
    farthest_pairs,
    grippers_collide,
    make_pairs,
    obb_overlap,
    proven_loss_lower,
    random_pairs,
    score_pairs,
    select_pairs,
    strategy_pass_rates,
)
from dataset_gen.grasps.sampling import SingleArmGrasps, sample_antipodal_grasps
from dataset_gen.sources.procedural import make_procedural_object

# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------


def _synthetic_grasps(m: int, seed: int = 0, spread: float = 0.3) -> SingleArmGrasps:
    """M Panda grasps at random poses; contacts where a centred grasp of width w puts them."""
    rng = np.random.default_rng(seed)
    poses = np.tile(np.eye(4), (m, 1, 1))
    poses[:, :3, :3] = Rotation.random(m, random_state=seed).as_matrix()
    poses[:, :3, 3] = rng.uniform(-spread, spread, (m, 3))
    widths = rng.uniform(0.01, 0.07, m)
    local = np.zeros((m, 2, 3))
    local[:, 0, 0], local[:, 1, 0] = widths / 2, -widths / 2
    local[:, :, 1] = PANDA.contact_depth
    R, t = poses[:, :3, :3], poses[:, :3, 3]
    points = np.einsum("mij,mfj->mfi", R, local) + t[:, None]
    normals = np.stack([R[:, :, 0], -R[:, :, 0]], axis=1)  # outward: towards each finger
    return SingleArmGrasps(
        poses=poses,
        contact_points=points,
        contact_normals=normals,
        face_ids=np.zeros((m, 2), dtype=np.int64),
        widths=widths,
        gripper="panda",
    )


def _empty_grasps(m: int) -> SingleArmGrasps:
    """A set of ``m`` (0 or 1) grasps."""
    if m:
        return _synthetic_grasps(m)
    return SingleArmGrasps(
        poses=np.zeros((0, 4, 4)),
        contact_points=np.zeros((0, 2, 3)),
        contact_normals=np.zeros((0, 2, 3)),
        face_ids=np.zeros((0, 2), dtype=np.int64),
        widths=np.zeros(0),
        gripper="panda",
    )


@pytest.fixture(scope="module")
def table_grasps() -> SingleArmGrasps:
    """60 collision-free Panda grasps on a procedural table from the antipodal sampler."""
    obj = make_procedural_object("table", 0)
    grasps = sample_antipodal_grasps(obj, n_grasps=60, rng=np.random.default_rng(0))
    assert grasps.n == 60
    return grasps


def _fcl_boxes_collide(ca, Ra, ha, cb, Rb, hb) -> bool:
    a = fcl.CollisionObject(fcl.Box(*(2.0 * ha)), fcl.Transform(Ra, ca))
    b = fcl.CollisionObject(fcl.Box(*(2.0 * hb)), fcl.Transform(Rb, cb))
    return fcl.collide(a, b, fcl.CollisionRequest(), fcl.CollisionResult()) > 0


# --------------------------------------------------------------------------------------------
# Separating-axis test and gripper-gripper collision
# --------------------------------------------------------------------------------------------


def test_obb_overlap_matches_fcl_including_near_contact() -> None:
    n = 400
    rng = np.random.default_rng(0)
    Ra = Rotation.random(n, random_state=1).as_matrix()
    Rb = Rotation.random(n, random_state=2).as_matrix()
    Ra[:60], Rb[:60] = np.eye(3), np.eye(3)  # axis-aligned: parallel faces and edges
    Rb[60:120] = Ra[60:120]  # parallel, rotated
    ha = rng.uniform(0.005, 0.1, (n, 3))
    hb = rng.uniform(0.005, 0.1, (n, 3))
    ca = rng.uniform(-0.1, 0.1, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    # Contact distance along d by bisection with fcl (independent of the code under test).
    lo, hi = np.zeros(n), np.full(n, 0.6)
    for _ in range(32):
        mid = 0.5 * (lo + hi)
        hit = np.array(
            [
                _fcl_boxes_collide(ca[k], Ra[k], ha[k], ca[k] + mid[k] * d[k], Rb[k], hb[k])
                for k in range(n)
            ]
        )
        lo, hi = np.where(hit, mid, lo), np.where(hit, hi, mid)
    boundary = 0.5 * (lo + hi)
    checked = 0
    for offset in (-0.2, -1e-3, -1e-6, 1e-6, 1e-3, 0.2):
        cb = ca + np.maximum(boundary + offset, 0.0)[:, None] * d
        mine = obb_overlap(ca, Ra, ha, cb, Rb, hb)
        ref = np.array(
            [_fcl_boxes_collide(ca[k], Ra[k], ha[k], cb[k], Rb[k], hb[k]) for k in range(n)]
        )
        np.testing.assert_array_equal(mine, ref, err_msg=f"offset {offset}")
        if abs(offset) < 0.01:
            assert mine.all() if offset < 0 else not mine.any()
        checked += n
    assert checked >= 2000
    # Broadcasting: one box against many.
    many = obb_overlap(ca[0], Ra[0], ha[0], ca, Rb, hb)
    assert many.shape == (n,)


def test_obb_overlap_rejects_bad_shapes() -> None:
    with pytest.raises(PairingError, match="expected shape"):
        obb_overlap(np.zeros(2), np.eye(3), np.ones(3), np.zeros(3), np.eye(3), np.ones(3))


@pytest.mark.parametrize("opening", [None, "grasp", 0.03])
def test_grippers_collide_matches_fcl(opening) -> None:
    m = 120
    grasps = _synthetic_grasps(m, seed=4, spread=0.12)
    i, j = np.triu_indices(m, k=1)
    pairs = np.stack([i, j], axis=1)[::3]
    mine = grippers_collide(grasps, pairs, opening=opening)
    widths = (
        grasps.widths
        if opening == "grasp"
        else np.full(m, opening if opening else PANDA.max_opening)
    )
    objects = []
    for g in range(m):
        T = grasps.poses[g]
        boxes = PANDA.collision_boxes(widths[g])
        objects.append(
            [
                fcl.CollisionObject(
                    fcl.Box(*(2.0 * np.asarray(b.half_extents))),
                    fcl.Transform(T[:3, :3], T[:3, :3] @ np.asarray(b.center) + T[:3, 3]),
                )
                for b in boxes
            ]
        )
    ref = np.array(
        [
            any(
                fcl.collide(a, b, fcl.CollisionRequest(), fcl.CollisionResult()) > 0
                for a in objects[p]
                for b in objects[q]
            )
            for p, q in pairs
        ]
    )
    assert 0.05 < ref.mean() < 0.95  # both outcomes well represented
    np.testing.assert_array_equal(mine, ref)


# --------------------------------------------------------------------------------------------
# Candidates, contacts, poses
# --------------------------------------------------------------------------------------------


def test_candidate_pairs_counts_and_exact_pruning() -> None:
    m = 45
    grasps = _synthetic_grasps(m, seed=1)
    everything = candidate_pairs(grasps, min_center_distance=0.0, check_gripper_collision=False)
    assert everything.counts["pairs"] == m * (m - 1) // 2 == everything.n
    assert (everything.pairs[:, 0] < everything.pairs[:, 1]).all()
    assert len(np.unique(everything.pairs, axis=0)) == everything.n

    c = grasps.centers
    distance = np.linalg.norm(c[:, None] - c[None], axis=-1)
    threshold = float(np.median(distance[np.triu_indices(m, 1)]))  # exactly a pair's distance
    pruned = candidate_pairs(grasps, min_center_distance=threshold, check_gripper_collision=False)
    expected = {(a, b) for a in range(m) for b in range(a + 1, m) if distance[a, b] >= threshold}
    assert {tuple(p) for p in pruned.pairs.tolist()} == expected
    assert pruned.counts["pruned_distance"] == m * (m - 1) // 2 - len(expected)
    np.testing.assert_allclose(
        pruned.center_distance, distance[pruned.pairs[:, 0], pruned.pairs[:, 1]]
    )

    checked = candidate_pairs(grasps, min_center_distance=threshold)
    collide = grippers_collide(grasps, pruned.pairs)
    np.testing.assert_array_equal(checked.pairs, pruned.pairs[~collide])
    assert checked.counts["gripper_collision"] == int(collide.sum())
    assert checked.counts["remaining"] == checked.n == len(expected) - int(collide.sum())


def test_dual_contacts_and_poses_order() -> None:
    grasps = _synthetic_grasps(6, seed=2)
    pairs = np.array([[0, 3], [5, 1], [2, 4]])
    points, normals = dual_contacts(grasps, pairs)
    assert points.shape == normals.shape == (3, 4, 3)
    for row, (i, j) in enumerate(pairs):
        np.testing.assert_array_equal(points[row, 0], grasps.contact_points[i, 0])
        np.testing.assert_array_equal(points[row, 1], grasps.contact_points[i, 1])
        np.testing.assert_array_equal(points[row, 2], grasps.contact_points[j, 0])
        np.testing.assert_array_equal(points[row, 3], grasps.contact_points[j, 1])
        np.testing.assert_array_equal(normals[row, 2:], grasps.contact_normals[j])
    poses = dual_poses(grasps, pairs)
    assert poses.shape == (3, 2, 4, 4)
    np.testing.assert_array_equal(poses[1, 0], grasps.poses[5])
    np.testing.assert_array_equal(poses[1, 1], grasps.poses[1])


def test_bad_inputs_say_what_was_expected() -> None:
    grasps = _synthetic_grasps(4)
    with pytest.raises(PairingError, match=r"expected grasp indices in \[0, 4\), found \[0, 4\]"):
        dual_contacts(grasps, np.array([[0, 4]]))
    with pytest.raises(PairingError, match="expected two different grasps"):
        dual_poses(grasps, np.array([[2, 2]]))
    with pytest.raises(PairingError, match=r"expected shape \(P, 2\)"):
        dual_contacts(grasps, np.array([0, 1, 2]))
    with pytest.raises(
        PairingError, match=r"expected a dataset_gen\.grasps\.sampling\.SingleArmGrasps"
    ):
        candidate_pairs(np.zeros((4, 4, 4)))  # type: ignore[arg-type]
    with pytest.raises(PairingError, match="min_center_distance: expected a finite number >= 0"):
        candidate_pairs(grasps, min_center_distance=-1.0)
    with pytest.raises(PairingError, match="strategy: expected one of"):
        make_pairs(grasps, "nearest", rng=np.random.default_rng(0))  # type: ignore[arg-type]
    with pytest.raises(PairingError, match=r"rng: expected a numpy\.random\.Generator"):
        make_pairs(grasps, "random", n_pairs=2)
    with pytest.raises(PairingError, match="opening: expected None"):
        grippers_collide(grasps, np.array([[0, 1]]), opening="closed")  # type: ignore[arg-type]


@pytest.mark.parametrize("m", [0, 1])
def test_empty_grasp_sets_give_empty_outputs(m: int) -> None:
    grasps = _empty_grasps(m)
    cands = candidate_pairs(grasps)
    assert cands.pairs.shape == (0, 2)
    assert cands.counts == {
        "pairs": 0,
        "pruned_distance": 0,
        "gripper_collision": 0,
        "remaining": 0,
    }
    points, normals = dual_contacts(grasps, cands.pairs)
    assert points.shape == normals.shape == (0, 4, 3)
    assert dual_poses(grasps, cands.pairs).shape == (0, 2, 4, 4)
    fc = score_pairs(grasps, cands.pairs)
    assert fc.n == 0
    sel = select_pairs(fc, points, normals, rng=np.random.default_rng(0))
    assert sel.n == 0
    assert sel.contact_forces.shape == (0, 4, 3)
    assert sel.counts["selected_passing"] == sel.counts["selected_failing"] == 0
    for strategy in STRATEGIES:
        result = make_pairs(grasps, strategy, rng=np.random.default_rng(0))  # type: ignore[arg-type]
        assert result.pairs.shape == (0, 2)
        assert np.isnan(result.pass_rate)


# --------------------------------------------------------------------------------------------
# Ablation strategies
# --------------------------------------------------------------------------------------------


def test_farthest_pairs_each_grasp_with_its_farthest() -> None:
    m = 30
    grasps = _synthetic_grasps(m, seed=3)
    pairs = farthest_pairs(grasps)
    c = grasps.centers
    distance = np.linalg.norm(c[:, None] - c[None], axis=-1)
    assert (pairs[:, 0] < pairs[:, 1]).all()
    assert len(np.unique(pairs, axis=0)) == len(pairs) <= m
    as_set = {tuple(p) for p in pairs.tolist()}
    for i in range(m):
        j = int(np.argmax(distance[i]))
        assert distance[i, j] == distance[i].max()
        assert (min(i, j), max(i, j)) in as_set
    # Every pair is some grasp's farthest.
    for a, b in pairs:
        assert distance[a, b] in (distance[a].max(), distance[b].max())
    result = make_pairs(grasps, "farthest")
    np.testing.assert_array_equal(result.pairs, pairs)


def test_random_pairs_deterministic_and_unique() -> None:
    grasps = _synthetic_grasps(40, seed=5)
    a = make_pairs(grasps, "random", rng=np.random.default_rng(11), n_pairs=100)
    b = make_pairs(grasps, "random", rng=np.random.default_rng(11), n_pairs=100)
    c = make_pairs(grasps, "random", rng=np.random.default_rng(12), n_pairs=100)
    np.testing.assert_array_equal(a.pairs, b.pairs)
    np.testing.assert_array_equal(a.fc.passed, b.fc.passed)
    assert not np.array_equal(a.pairs, c.pairs)
    assert a.pairs.shape == (100, 2)
    assert (a.pairs[:, 0] < a.pairs[:, 1]).all()
    assert len(np.unique(a.pairs, axis=0)) == 100
    # Default count: as many as the force-closure strategy evaluates.
    default = make_pairs(grasps, "random", rng=np.random.default_rng(0))
    assert default.counts["pairs"] == candidate_pairs(grasps).n
    # Capped at the number of pairs available.
    assert random_pairs(5, 100, np.random.default_rng(0)).shape == (10, 2)


# --------------------------------------------------------------------------------------------
# Selection
# --------------------------------------------------------------------------------------------


def test_selection_caps_proof_and_determinism(table_grasps: SingleArmGrasps) -> None:
    cands = candidate_pairs(table_grasps)
    fc = score_pairs(table_grasps, cands.pairs)
    points, normals = dual_contacts(table_grasps, cands.pairs)
    assert fc.passed.sum() > 10
    kwargs = {"max_passing": 10, "max_failing": 15}
    sel = select_pairs(fc, points, normals, rng=np.random.default_rng(5), **kwargs)
    again = select_pairs(fc, points, normals, rng=np.random.default_rng(5), **kwargs)
    other = select_pairs(fc, points, normals, rng=np.random.default_rng(6), **kwargs)
    exact = select_pairs(
        fc, points, normals, rng=np.random.default_rng(5), exact_counts=True, **kwargs
    )
    np.testing.assert_array_equal(sel.indices, again.indices)
    np.testing.assert_array_equal(sel.loss, again.loss)
    np.testing.assert_array_equal(sel.indices, exact.indices)
    assert not np.array_equal(sel.indices, other.indices)

    assert sel.counts["selected_passing"] == 10
    assert sel.counts["selected_failing"] == 15
    pass_rows, fail_rows = sel.passing_indices, sel.failing_indices
    assert (np.diff(pass_rows) > 0).all()
    assert (np.diff(fail_rows) > 0).all()
    np.testing.assert_array_equal(sel.indices, np.concatenate([pass_rows, fail_rows]))
    assert fc.passed[pass_rows].all()
    assert not fc.passed[fail_rows].any()
    assert (sel.loss[: len(pass_rows)] <= 1e-5).all()
    # The failing pairs' losses are proven above 0.5 by an independent reference solve.
    ref = evaluate(points[fail_rows], normals[fail_rows], method="clarabel")
    assert (ref.loss > 0.5).all()
    np.testing.assert_allclose(sel.loss[~sel.passed], ref.loss, rtol=1e-3)
    np.testing.assert_allclose(sel.quality, fc.quality[sel.indices])
    assert sel.contact_forces.shape == (25, 4, 3)

    # Counts: failing pool bounds, exact count within them.
    lower = proven_loss_lower(fc)
    failing = fc.rank_ok & ~fc.passed
    assert sel.counts["failing_over_min_loss"] == int((failing & (lower > 0.5)).sum())
    assert exact.counts["failing_maybe_over_min_loss"] == 0
    assert (
        sel.counts["failing_over_min_loss"]
        <= exact.counts["failing_over_min_loss"]
        <= sel.counts["failing_over_min_loss"] + sel.counts["failing_maybe_over_min_loss"]
    )
    # Caps larger than what is available keep everything eligible.
    everything = select_pairs(
        fc,
        points,
        normals,
        rng=np.random.default_rng(0),
        max_passing=10**6,
        max_failing=10**6,
        exact_counts=True,
    )
    assert everything.counts["selected_passing"] == int(fc.passed.sum())
    assert everything.counts["selected_failing"] == exact.counts["failing_over_min_loss"]


def test_selection_parameters_are_checked(table_grasps: SingleArmGrasps) -> None:
    pairs = np.array([[0, 1], [0, 2]])
    fc = score_pairs(table_grasps, pairs)
    points, normals = dual_contacts(table_grasps, pairs)
    rng = np.random.default_rng(0)
    for kwargs, message in (
        ({"max_passing": -1}, "max_passing: expected an integer >= 0, found -1"),
        ({"max_failing": True}, "max_failing: expected an integer >= 0, found True"),
        ({"max_failing": 2.0}, "max_failing: expected an integer >= 0, found 2.0"),
        ({"failing_min_loss": float("inf")}, "failing_min_loss: expected a finite number >= 0"),
        ({"failing_min_loss": True}, "failing_min_loss: expected a finite number >= 0"),
        ({"loss_rtol": "1e-4"}, "loss_rtol: expected a finite number >= 0, found '1e-4'"),
    ):
        with pytest.raises(PairingError, match=message):
            select_pairs(fc, points, normals, rng=rng, **kwargs)  # type: ignore[arg-type]
    # numpy scalars are numbers like any other
    sel = select_pairs(
        fc,
        points,
        normals,
        rng=rng,
        max_passing=np.int64(1),
        max_failing=np.int32(1),
        failing_min_loss=np.float32(0.5),
    )
    assert sel.counts["selected_passing"] <= 1
    assert sel.counts["selected_failing"] <= 1


def test_defaults_are_the_papers() -> None:
    import inspect

    from dataset_gen.grasps import pairing
    from dg16m_core.parameters import PAPER

    assert pairing.DEFAULT_MIN_CENTER_DISTANCE == PAPER.min_center_distance == 0.1
    assert pairing.DEFAULT_MAX_PASSING == PAPER.max_passing == 2000
    assert pairing.DEFAULT_MAX_FAILING == PAPER.max_failing == 2000
    assert pairing.DEFAULT_FAILING_MIN_LOSS == PAPER.failing_min_loss == 0.5
    selection = inspect.signature(select_pairs).parameters
    assert selection["max_passing"].default == PAPER.max_passing
    assert selection["failing_min_loss"].default == PAPER.failing_min_loss
    assert (
        inspect.signature(candidate_pairs).parameters["min_center_distance"].default
        == PAPER.min_center_distance
    )


def test_selection_rejects_mismatched_contacts(table_grasps: SingleArmGrasps) -> None:
    pairs = np.array([[0, 1], [0, 2]])
    fc = score_pairs(table_grasps, pairs)
    points, normals = dual_contacts(table_grasps, pairs)
    with pytest.raises(PairingError, match=r"expected shape \(2, 4, 3\)"):
        select_pairs(fc, points[:1], normals, rng=np.random.default_rng(0))


def test_end_to_end_on_a_procedural_object(table_grasps: SingleArmGrasps) -> None:
    rng = np.random.default_rng(0)
    result = make_pairs(table_grasps, "force_closure", rng=rng)
    m = table_grasps.n
    assert result.counts["all_pairs"] == m * (m - 1) // 2
    assert result.counts["pairs"] == (
        result.counts["all_pairs"]
        - result.counts["pruned_distance"]
        - result.counts["gripper_collision"]
    )
    assert result.counts["pruned_distance"] > 0
    assert 0.0 < result.pass_rate < 1.0  # both passing and failing pairs
    points, normals = dual_contacts(table_grasps, result.pairs)
    sel = select_pairs(result.fc, points, normals, rng=rng)
    assert sel.counts["selected_passing"] == result.counts["passing"] > 0
    assert sel.counts["selected_failing"] > 0
    chosen = result.pairs[sel.indices]
    assert chosen.shape == (sel.n, 2)
    # Stored grasps and contacts line up: contact rows equal the chosen pairs' contacts.
    np.testing.assert_array_equal(points[sel.indices], dual_contacts(table_grasps, chosen)[0])
    # The selected passing pairs are exactly the passing candidates.
    np.testing.assert_array_equal(result.passing_pairs, chosen[sel.passed])

    rates = strategy_pass_rates(table_grasps, rng=np.random.default_rng(1))
    assert set(rates) == set(STRATEGIES)
    assert all(0.0 <= r <= 1.0 for r in rates.values())
    assert rates["force_closure"] == pytest.approx(result.pass_rate)
