"""The cloud sampler's compiled loops (``baselines.cloud_kernels``) give what the numpy code
they replaced gave: each is checked against that code (written out here, every (hand or seed,
point) pair at once) on a small object whose whole cloud lies within reach of every hand, and on
random hands about it. Choices (which points, which hands) are compared exactly, values within
:data:`ROUNDING`: numpy's ``einsum`` sums a three-term dot product in an order that depends on
the CPU's vector instructions (on the 2-core development machine ``(a0 b0 + a2 b2) + a1 b1``
for ``"ek,ek->e"``), the loops in index order."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import baselines.cloud_enclosing as cloud_enclosing
from baselines.cloud_enclosing import enclose, enclosing_poses
from baselines.cloud_grasps import CloudSamplerConfig, check_cloud, cloud_contact_pairs
from baselines.cloud_hand import hand_hits_cloud
from dataset_gen.grasps.gripper import PANDA
from dg16m_core.parameters import PAPER
from dg16m_env.subjects.observation import surface_points

ROUNDING = 1e-15
"""Largest difference (m, or a cosine) allowed between a loop's value and numpy's: a few units
in the last place of values below 1."""


@pytest.fixture(scope="module")
def bottle_cloud():
    """A dense cloud of a small capsule (3 cm radius, 12 cm long; every point within a hand's
    reach of every other, as on the real benchmark's bottles and intercoms), with 40 points
    repeated (ties of every kind)."""
    capsule = trimesh.creation.capsule(height=0.06, radius=0.03)
    points, normals = surface_points(
        capsule.vertices, capsule.faces, 3000, np.random.default_rng(0)
    )
    again = np.random.default_rng(1).integers(0, 3000, 40)
    return check_cloud(
        np.concatenate([points, points[again]]), np.concatenate([normals, normals[again]])
    )


def random_hands(cloud, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 4, 4) hands of random rotation whose grasp centres lie within about 4 cm of cloud
    points."""
    poses = np.zeros((n, 4, 4))
    for i in range(n):
        poses[i] = trimesh.transformations.random_rotation_matrix(rng.random(3))
    centres = cloud.points[rng.integers(0, cloud.n, n)] + rng.normal(0.0, 0.02, (n, 3))
    poses[:, :3, 3] = centres - PANDA.contact_depth * poses[:, :3, 1]
    return poses


def every_pair(n: int, p: int) -> tuple[np.ndarray, np.ndarray]:
    """(row, point) for every row and every point, grouped by row, points ascending."""
    return np.repeat(np.arange(n), p), np.tile(np.arange(p), n)


def contact_pairs_in_numpy(cloud, seeds, mu, min_width=1e-3, max_width=0.079):
    """The contact pairs as the numpy code computed them, over every (seed, point) pair."""
    cos_cone = math.cos(math.atan(mu)) - 1e-12
    pts, nrm = cloud.points, cloud.normals
    row, j = every_pair(len(seeds), cloud.n)
    i = seeds[row]
    d = pts[j] - pts[i]
    dist = np.linalg.norm(d, axis=1)
    ok = (dist > min_width) & (dist <= max_width)
    row, i, j, d, dist = row[ok], i[ok], j[ok], d[ok], dist[ok]
    both = np.minimum(
        -np.einsum("ek,ek->e", d, nrm[i]) / dist, np.einsum("ek,ek->e", d, nrm[j]) / dist
    )
    ok = both >= cos_cone
    row, j, both = row[ok], j[ok], both[ok]
    order = np.lexsort((-j, both, row))
    last = np.flatnonzero(np.r_[row[order][1:] != row[order][:-1], len(order) > 0])
    pick = order[last]
    index = np.stack([seeds[row[pick]], j[pick]], axis=1)
    cosine = both[pick]
    key = np.sort(index, axis=1)
    _, first = np.unique(key[:, 0] * cloud.n + key[:, 1], return_index=True)
    first = np.sort(first)
    return index[first], cosine[first]


@pytest.mark.parametrize("mu", [PAPER.mu, 1.0])
def test_contact_pairs_are_those_of_the_numpy_search(bottle_cloud, mu):
    seeds = np.random.default_rng(3).choice(bottle_cloud.n, 1200, replace=False)
    pairs = cloud_contact_pairs(bottle_cloud, seeds, mu=mu)
    index, cosine = contact_pairs_in_numpy(bottle_cloud, seeds, mu)
    assert len(index) > 100
    np.testing.assert_array_equal(pairs.index, index)
    np.testing.assert_allclose(pairs.cosine, cosine, rtol=0.0, atol=ROUNDING)


def hits_in_numpy(points, poses, contact_x, model, tolerance, clearance):
    """The hand's collision test as the numpy code computed it, over every (hand, point)."""
    palm = model.palm_box()
    grow = clearance - tolerance
    palm_lo = np.asarray(palm.center) - np.asarray(palm.half_extents) - grow
    palm_hi = np.asarray(palm.center) + np.asarray(palm.half_extents) + grow
    outer = model.max_opening / 2.0 + model.finger_thickness + clearance
    half_z = model.finger_width / 2.0 + clearance
    pose, point = every_pair(len(poses), len(points))
    local = np.einsum("eki,ek->ei", poses[pose, :3, :3], points[point] - poses[pose, :3, 3])
    gx, gy, gz = local[:, 0], local[:, 1], local[:, 2]
    in_palm = ((local > palm_lo) & (local < palm_hi)).all(axis=1)
    foot = (gy >= model.palm_depth - clearance) & (gy <= model.finger_tip + clearance)
    foot &= np.abs(gz) <= half_z
    finger0 = (gx > contact_x[pose, 0] + tolerance) & (gx <= outer)
    finger1 = (gx < contact_x[pose, 1] - tolerance) & (gx >= -outer)
    hit = in_palm | (foot & (finger0 | finger1))
    return np.bincount(pose[hit], minlength=len(poses)) > 0


@pytest.mark.parametrize(("tolerance", "clearance"), [(2e-3, 0.0), (3e-3, 0.004), (1e-3, 0.01)])
def test_hand_hits_are_those_of_the_numpy_test(bottle_cloud, tolerance, clearance):
    rng = np.random.default_rng(4)
    poses = random_hands(bottle_cloud, 300, rng)
    contact_x = np.stack([rng.uniform(0.0, 0.04, 300), -rng.uniform(0.0, 0.04, 300)], axis=1)
    hits = hand_hits_cloud(bottle_cloud, poses, contact_x, PANDA, tolerance, clearance)
    want = hits_in_numpy(bottle_cloud.points, poses, contact_x, PANDA, tolerance, clearance)
    assert 0.2 < want.mean() < 0.99
    np.testing.assert_array_equal(hits, want)
    # a point just inside each corner of the grown palm, and beside each open finger's outer
    # face and tip, is a hit alone; just outside, it is not
    palm = PANDA.palm_box()
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    corner = np.asarray(palm.center) + signs * (
        np.asarray(palm.half_extents) + clearance - tolerance
    )
    outer = PANDA.max_opening / 2.0 + PANDA.finger_thickness + clearance
    tip = PANDA.finger_tip + clearance
    side = PANDA.finger_width / 2.0 + clearance
    finger = np.array([[sx * outer, tip, sz * side] for sx in (-1, 1) for sz in (-1, 1)])
    eye = np.eye(4)[None]
    no_contact = np.array([[0.0, 0.0]])
    for point in corner:
        inside = point - np.sign(point - np.asarray(palm.center)) * 1e-6
        outside = point + np.sign(point - np.asarray(palm.center)) * 1e-6
        assert hand_hits_cloud(inside[None], eye, no_contact, PANDA, tolerance, clearance)[0]
        assert not hand_hits_cloud(outside[None], eye, no_contact, PANDA, tolerance, clearance)[0]
    for point in finger:
        inside = point - np.array([np.sign(point[0]), 1.0, np.sign(point[2])]) * 1e-6
        outside = point + np.array([np.sign(point[0]), 1.0, np.sign(point[2])]) * 1e-6
        assert hand_hits_cloud(inside[None], eye, no_contact, PANDA, tolerance, clearance)[0]
        assert not hand_hits_cloud(outside[None], eye, no_contact, PANDA, tolerance, clearance)[0]


def enclose_in_numpy(cloud, poses, model, pad_margin=0.0):
    """What each hand holds as the numpy code found it, over every (hand, point)."""
    n = len(poses)
    half_x = model.max_opening / 2.0
    half_z = model.finger_width / 2.0 - pad_margin
    pose, point = every_pair(n, cloud.n)
    local = np.einsum("eki,ek->ei", poses[pose, :3, :3], cloud.points[point] - poses[pose, :3, 3])
    held = (
        (local[:, 1] >= model.palm_depth)
        & (local[:, 1] <= model.finger_tip)
        & (np.abs(local[:, 2]) <= half_z)
        & (np.abs(local[:, 0]) <= half_x)
    )
    pose, point, gx = pose[held], point[held], local[held, 0]
    size = np.bincount(pose, minlength=n)
    order = np.lexsort((gx, pose))  # by hand, then x ascending, ties in cloud order
    g = pose[order]
    first = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
    last = np.r_[first[1:] - 1, len(g) - 1]
    top, bottom = np.full(n, -1), np.full(n, -1)
    bottom[g[first]], top[g[last]] = order[first], order[last]
    index = np.full((n, 2), -1, dtype=np.int64)
    local_x = np.zeros((n, 2))
    ok = size >= 2
    index[ok, 0], index[ok, 1] = point[top[ok]], point[bottom[ok]]
    local_x[ok, 0], local_x[ok, 1] = gx[top[ok]], gx[bottom[ok]]
    return index, local_x


def hands_at_cloud_points(cloud, rng, n_seeds: int = 60) -> np.ndarray:
    """Enclosing hands (six closing axes about each approach, as the sampler makes them) and
    random hands."""
    seeds = rng.choice(cloud.n, n_seeds, replace=False)
    angles = rng.random(n_seeds)[:, None] * math.pi / 6 + math.pi / 6 * np.arange(6)
    shared = enclosing_poses(cloud.points[seeds], cloud.normals[seeds], angles, 0.02, PANDA)
    return np.concatenate([shared.reshape(-1, 4, 4), random_hands(cloud, 100, rng)])


@pytest.mark.parametrize("pad_margin", [0.0, 0.002])
def test_enclose_finds_what_the_numpy_search_found(bottle_cloud, pad_margin):
    poses = hands_at_cloud_points(bottle_cloud, np.random.default_rng(5))
    index, local_x = enclose(bottle_cloud, poses, PANDA, pad_margin=pad_margin)
    want_index, want_x = enclose_in_numpy(bottle_cloud, poses, PANDA, pad_margin)
    assert (index[:, 0] >= 0).mean() > 0.5
    np.testing.assert_array_equal(index, want_index)
    np.testing.assert_allclose(local_x, want_x, rtol=0.0, atol=ROUNDING)


def test_ties_go_to_the_last_point_at_the_top_and_the_first_at_the_bottom():
    """Four points held at two x values, each twice: finger 0 takes the later of the two at the
    largest x, finger 1 the earlier of the two at the smallest."""
    y = PANDA.contact_depth
    points = np.array([[0.01, y, 0.0], [-0.01, y, 0.0], [0.01, y, 0.0], [-0.01, y, 0.0]])
    cloud = check_cloud(
        np.concatenate([points, [[1.0, 1.0, 1.0]] * 12]), np.tile([0.0, 0.0, 1.0], (16, 1))
    )
    index, local_x = enclose(cloud, np.eye(4)[None], PANDA)
    assert index.tolist() == [[2, 1]]
    assert local_x.tolist() == [[0.01, -0.01]]


def test_the_enclosing_sampler_matches_the_numpy_search(bottle_cloud, monkeypatch):
    config = CloudSamplerConfig(enclosing=True)
    fast = cloud_enclosing.sample_enclosing_grasps(bottle_cloud, config, np.random.default_rng(7))
    monkeypatch.setattr(cloud_enclosing, "enclose", enclose_in_numpy)
    slow = cloud_enclosing.sample_enclosing_grasps(bottle_cloud, config, np.random.default_rng(7))
    assert fast.n > 10
    np.testing.assert_array_equal(fast.face_ids, slow.face_ids)
    np.testing.assert_allclose(fast.poses, slow.poses, rtol=0.0, atol=ROUNDING)
