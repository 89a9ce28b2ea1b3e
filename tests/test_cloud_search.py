"""The cloud sampler's neighbour searches give the answers of a search of everything
(``baselines.cloud_inputs._neighbours``, ``cloud_grasps.partner_ball``,
``cloud_hand.hand_balls``, ``cloud_enclosing.enclose``): each is checked against the plain
search it replaced, on a small object whose whole cloud lies within reach of every hand (where
the narrower searches matter) and on random hands about it."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import baselines.cloud_enclosing as cloud_enclosing
import baselines.cloud_grasps as cloud_grasps
import baselines.cloud_hand as cloud_hand
from baselines.cloud_enclosing import _grouped_extremes, enclose, enclosing_poses
from baselines.cloud_grasps import (
    CloudSamplerConfig,
    check_cloud,
    cloud_contact_pairs,
    hand_hits_cloud,
    partner_ball,
)
from baselines.cloud_inputs import _neighbours, _search
from dataset_gen.grasps.gripper import PANDA
from dg16m_core.parameters import PAPER
from dg16m_env.subjects.observation import surface_points


@pytest.fixture(scope="module")
def bottle_cloud():
    """A dense cloud of a small capsule (3 cm radius, 12 cm long): every point lies within a
    hand's reach of every other, as on the real benchmark's bottles and intercoms."""
    capsule = trimesh.creation.capsule(height=0.06, radius=0.03)
    points, normals = surface_points(
        capsule.vertices, capsule.faces, 3000, np.random.default_rng(0)
    )
    return check_cloud(points, normals)


def random_hands(cloud, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 4, 4) hands of random rotation whose grasp centres lie within 4 cm of cloud points."""
    poses = np.zeros((n, 4, 4))
    for i in range(n):
        poses[i] = trimesh.transformations.random_rotation_matrix(rng.random(3))
    centres = cloud.points[rng.integers(0, cloud.n, n)] + rng.normal(0.0, 0.02, (n, 3))
    poses[:, :3, 3] = centres - PANDA.contact_depth * poses[:, :3, 1]
    return poses


def test_repeated_queries_are_searched_once_with_the_same_answer(bottle_cloud):
    rng = np.random.default_rng(1)
    queries = bottle_cloud.points[rng.integers(0, bottle_cloud.n, 40)]
    queries = np.repeat(queries, rng.integers(1, 4, 40), axis=0)[rng.permutation(80)[:60] % 60]
    rows, points = _neighbours(bottle_cloud.tree, queries, 0.03)
    once_rows, once_points = _search(bottle_cloud.tree, queries, 0.03)
    assert len(np.unique(queries, axis=0)) < len(queries)
    np.testing.assert_array_equal(rows, once_rows)
    np.testing.assert_array_equal(points, once_points)


def test_the_partner_ball_holds_the_friction_cone_within_the_opening():
    rng = np.random.default_rng(2)
    width = 0.079
    cos_cone = math.cos(math.atan(PAPER.mu))
    normal = np.array([[0.0, 0.0, 1.0]])
    centre, radius = partner_ball(np.zeros((1, 3)), normal, cos_cone, width)
    assert radius < 0.55 * width
    # partners on the cone's surface and inside it, at every length up to the opening
    angle = math.acos(cos_cone) * np.sqrt(rng.random(20000))
    turn = rng.random(20000) * 2.0 * math.pi
    length = width * rng.random(20000) ** (1.0 / 3.0)
    length[:2000] = width
    angle[2000:4000] = math.acos(cos_cone)
    d = length[:, None] * np.stack(
        [np.sin(angle) * np.cos(turn), np.sin(angle) * np.sin(turn), -np.cos(angle)], axis=1
    )
    assert (np.linalg.norm(d - centre, axis=1) <= radius).all()
    # and it is the smallest such ball: the apex and the rim lie on it
    assert math.isclose(np.linalg.norm(centre), radius, abs_tol=2e-6)
    wide, wide_radius = partner_ball(np.zeros((1, 3)), normal, 0.4, width)
    assert np.array_equal(wide, np.zeros((1, 3)))
    assert wide_radius >= width


@pytest.mark.parametrize("mu", [PAPER.mu, 1.0, 2.0])
def test_contact_pairs_are_those_of_the_whole_ball(bottle_cloud, monkeypatch, mu):
    seeds = np.random.default_rng(3).choice(bottle_cloud.n, 1500, replace=False)
    narrow = cloud_contact_pairs(bottle_cloud, seeds, mu=mu)
    monkeypatch.setattr(
        cloud_grasps, "partner_ball", lambda points, normals, cos_cone, width: (points, width)
    )
    whole = cloud_contact_pairs(bottle_cloud, seeds, mu=mu)
    assert whole.n > 100
    np.testing.assert_array_equal(narrow.index, whole.index)
    np.testing.assert_array_equal(narrow.cosine, whole.cosine)


def every_entry(tree, poses, model, clearance):
    """(pose, point) for every pose and every point: the search that tests everything."""
    n, p = len(poses), tree.n
    return np.repeat(np.arange(n), p), np.tile(np.arange(p), n)


@pytest.mark.parametrize(("tolerance", "clearance"), [(2e-3, 0.0), (3e-3, 0.004), (1e-3, 0.01)])
def test_hand_balls_hold_every_point_a_hand_can_hit(
    bottle_cloud, monkeypatch, tolerance, clearance
):
    rng = np.random.default_rng(4)
    poses = random_hands(bottle_cloud, 300, rng)
    # and points at the corners of the grown palm and beside the open fingers' outer faces
    grow = clearance - tolerance
    palm = PANDA.palm_box()
    corners = np.array(palm.center) + np.array(palm.half_extents) * np.array(
        [[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    )
    corners += np.sign(corners - np.array(palm.center)) * (grow - 1e-5)
    outer = PANDA.max_opening / 2.0 + PANDA.finger_thickness + clearance - 1e-5
    fingers = np.array(
        [
            [
                sx * outer,
                PANDA.finger_tip + clearance - 1e-5,
                sz * (PANDA.finger_width / 2.0 + clearance - 1e-5),
            ]
            for sx in (-1, 1)
            for sz in (-1, 1)
        ]
    )
    local = np.concatenate([corners, fingers])
    pose = random_hands(bottle_cloud, 1, rng)[0]
    extra = local @ pose[:3, :3].T + pose[:3, 3]
    cloud = check_cloud(
        np.concatenate([bottle_cloud.points, extra]),
        np.concatenate([bottle_cloud.normals, np.tile([0.0, 0.0, 1.0], (len(extra), 1))]),
    )
    poses = np.concatenate([poses, pose[None]])
    contact_x = np.tile([0.03, -0.03], (len(poses), 1))
    monkeypatch.setattr(cloud_hand, "COARSE_POINTS", ())
    narrow = hand_hits_cloud(cloud, poses, contact_x, PANDA, tolerance, clearance)
    # each of the corner points alone is a hit, so the balls reach it
    for point in extra:
        assert hand_hits_cloud(point[None], pose[None], contact_x[:1], PANDA, tolerance, clearance)[
            0
        ]
    monkeypatch.setattr(cloud_hand, "_hand_entries", every_entry)
    everything = hand_hits_cloud(cloud, poses, contact_x, PANDA, tolerance, clearance)
    assert 0.2 < everything.mean() < 0.99
    np.testing.assert_array_equal(narrow, everything)


def enclose_everything(cloud, poses, model, pad_margin=0.0):
    """:func:`enclose` by its definition, every point tested against every pose."""
    half_z = model.finger_width / 2.0 - pad_margin
    index = np.full((len(poses), 2), -1, dtype=np.int64)
    local_x = np.zeros((len(poses), 2))
    for k, pose in enumerate(poses):
        local = np.einsum("ki,ek->ei", pose[:3, :3], cloud.points - pose[:3, 3])
        held = np.flatnonzero(
            (local[:, 1] >= model.palm_depth)
            & (local[:, 1] <= model.finger_tip)
            & (np.abs(local[:, 2]) <= half_z)
            & (np.abs(local[:, 0]) <= model.max_opening / 2.0)
        )
        if len(held) >= 2:
            x = local[held, 0]
            top = held[np.flatnonzero(x == x.max())[-1]]
            bottom = held[np.flatnonzero(x == x.min())[0]]
            index[k] = top, bottom
            local_x[k] = local[top, 0], local[bottom, 0]
    return index, local_x


@pytest.mark.parametrize("pad_margin", [0.0, 0.002])
def test_enclose_finds_what_testing_every_point_finds(bottle_cloud, pad_margin):
    rng = np.random.default_rng(5)
    seeds = rng.choice(bottle_cloud.n, 60, replace=False)
    angles = rng.random(60)[:, None] * math.pi / 6 + math.pi / 6 * np.arange(6)
    shared = enclosing_poses(
        bottle_cloud.points[seeds], bottle_cloud.normals[seeds], angles, 0.02, PANDA
    ).reshape(-1, 4, 4)
    poses = np.concatenate([shared, random_hands(bottle_cloud, 100, rng)])
    index, local_x = enclose(bottle_cloud, poses, PANDA, pad_margin=pad_margin)
    want_index, want_x = enclose_everything(bottle_cloud, poses, PANDA, pad_margin)
    assert (index[:, 0] >= 0).mean() > 0.5
    np.testing.assert_array_equal(index, want_index)
    np.testing.assert_allclose(local_x, want_x, rtol=0.0, atol=1e-15)


def test_grouped_extremes_of_runs_take_ties_as_a_stable_sort_does():
    rng = np.random.default_rng(6)
    for _ in range(300):
        n = int(rng.integers(1, 12))
        group = np.sort(rng.integers(0, n, int(rng.integers(0, 40))))
        value = rng.integers(0, 3, len(group)) * 0.5  # many ties
        top, bottom, size = _grouped_extremes(group, value, n)
        order = np.lexsort((value, group))
        for g in range(n):
            members = order[group[order] == g]
            assert size[g] == len(members)
            assert top[g] == (members[-1] if len(members) else -1)
            assert bottom[g] == (members[0] if len(members) else -1)
    # groups out of order take the sorting path with the same answer
    group, value = np.array([2, 0, 2, 1, 0]), np.array([1.0, 3.0, 1.0, 0.0, 3.0])
    top, bottom, size = _grouped_extremes(group, value, 3)
    assert top.tolist() == [4, 3, 2]
    assert bottom.tolist() == [1, 3, 0]
    assert size.tolist() == [2, 1, 2]


def test_the_enclosing_sampler_is_unchanged_by_its_narrow_search(bottle_cloud, monkeypatch):
    config = CloudSamplerConfig(enclosing=True)
    fast = cloud_enclosing.sample_enclosing_grasps(bottle_cloud, config, np.random.default_rng(7))
    monkeypatch.setattr(cloud_enclosing, "enclose", enclose_everything)
    slow = cloud_enclosing.sample_enclosing_grasps(bottle_cloud, config, np.random.default_rng(7))
    assert fast.n > 10
    np.testing.assert_array_equal(fast.face_ids, slow.face_ids)
    np.testing.assert_allclose(fast.poses, slow.poses, rtol=0.0, atol=1e-15)
