"""Antipodal dual-grasp candidates from a point cloud (``baselines.cloud_grasps``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from baselines.cloud_grasps import (
    CloudError,
    CloudSamplerConfig,
    check_cloud,
    cloud_dual_candidates,
    hand_hits_cloud,
    sample_enclosing_grasps,
)
from dataset_gen.grasps.gripper import PANDA
from dataset_gen.grasps.pairing import grippers_collide
from dg16m_core.parameters import PAPER
from dg16m_env.subjects.observation import surface_points

HALF = np.array([0.25, 0.03, 0.15])
"""Half extents of the test box (m): a 6 cm slab the Panda can span across its thickness."""


@pytest.fixture(scope="module")
def box_cloud():
    box = trimesh.creation.box(extents=2.0 * HALF)
    points, normals = surface_points(box.vertices, box.faces, 2048, np.random.default_rng(0))
    return check_cloud(points, normals)


@pytest.fixture(scope="module")
def candidates(box_cloud):
    return cloud_dual_candidates(box_cloud, rng=np.random.default_rng(1))


def box_distance(points: np.ndarray) -> np.ndarray:
    """Unsigned distance (m) of points (N, 3) on or inside the box to its surface."""
    return np.abs((np.abs(points) - HALF).max(axis=-1))


def test_candidates_lie_on_the_box_and_face_each_other(box_cloud, candidates):
    assert candidates.n > 50
    contacts = candidates.contact_points.reshape(-1, 3)
    assert box_distance(contacts).max() <= box_cloud.spacing
    cos_cone = math.cos(math.atan(PAPER.mu))
    for first in (0, 2):  # each hand's two contacts
        p0, p1 = candidates.contact_points[:, first], candidates.contact_points[:, first + 1]
        n0, n1 = candidates.contact_normals[:, first], candidates.contact_normals[:, first + 1]
        line = (p1 - p0) / np.linalg.norm(p1 - p0, axis=1, keepdims=True)
        assert (np.einsum("ij,ij->i", line, -n0) >= cos_cone - 1e-9).all()
        assert (np.einsum("ij,ij->i", line, n1) >= cos_cone - 1e-9).all()
        assert (np.einsum("ij,ij->i", n0, n1) <= -math.cos(2.0 * math.atan(PAPER.mu))).all()


def test_no_candidate_hand_intersects_the_cloud(box_cloud, candidates):
    """Checked independently with the gripper's own boxes: palm and open fingers, and the
    fingers closed at each grasp's width, each shrunk by the tolerance."""
    tol = CloudSamplerConfig().tolerance
    grasps = candidates.grasps
    for pose, width in zip(grasps.poses, grasps.widths, strict=True):
        local = (box_cloud.points - pose[:3, 3]) @ pose[:3, :3]
        boxes = (*PANDA.collision_boxes(None), *PANDA.finger_boxes(float(width)))
        for box in boxes:
            lo = np.asarray(box.center) - np.asarray(box.half_extents) + tol
            hi = np.asarray(box.center) + np.asarray(box.half_extents) - tol
            assert not ((local > lo) & (local < hi)).all(axis=1).any()


def test_dual_candidates_follow_the_centre_rule_and_hands_do_not_collide(candidates):
    grasps = candidates.grasps
    centres = grasps.centers[candidates.pairs]
    assert (np.linalg.norm(centres[:, 0] - centres[:, 1], axis=1) >= 0.1).all()
    assert not grippers_collide(grasps, candidates.pairs).any()
    assert candidates.poses.shape == (candidates.n, 2, 4, 4)
    assert candidates.n <= CloudSamplerConfig().max_pairs


def test_same_generator_same_arrays(box_cloud, candidates):
    again = cloud_dual_candidates(box_cloud, rng=np.random.default_rng(1))
    assert np.array_equal(again.poses, candidates.poses)
    assert again.counts == candidates.counts
    other = cloud_dual_candidates(box_cloud, rng=np.random.default_rng(2))
    assert not np.array_equal(other.poses[:5], candidates.poses[:5])


def test_hand_hits_a_point_in_the_palm_and_not_one_between_the_fingers():
    pose = np.eye(4)[None]
    contact_x = np.array([[0.02, -0.02]])
    between = np.array([[0.0, PANDA.contact_depth, 0.0]])
    palm = np.array([[0.0, PANDA.palm_depth - 0.01, 0.0]])
    beyond_contact = np.array([[0.03, PANDA.contact_depth, 0.0]])
    assert not hand_hits_cloud(between, pose, contact_x, PANDA, 2e-3)[0]
    assert hand_hits_cloud(palm, pose, contact_x, PANDA, 2e-3)[0]
    assert hand_hits_cloud(beyond_contact, pose, contact_x, PANDA, 2e-3)[0]
    near_tip = np.array([[0.03, PANDA.finger_tip + 0.004, 0.0]])  # past the tip, within clearance
    assert not hand_hits_cloud(near_tip, pose, contact_x, PANDA, 2e-3)[0]
    assert hand_hits_cloud(near_tip, pose, contact_x, PANDA, 2e-3, clearance=0.005)[0]


def test_a_cloud_without_antipodal_points_gives_no_candidates_not_an_error():
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(-0.3, 0.3, (200, 2)), np.zeros(200)])
    normals = np.tile([0.0, 0.0, 1.0], (200, 1))
    cands = cloud_dual_candidates(check_cloud(points, normals), rng=rng)
    assert cands.n == 0
    assert cands.counts["contact_pairs"] == 0


@pytest.mark.parametrize(
    ("points", "normals", "message"),
    [
        (np.zeros((20, 2)), np.zeros((20, 2)), r"points: expected shape \(P, 3\), found \(20, 2\)"),
        (np.zeros((20, 3)), np.zeros((19, 3)), "normals: expected the shape of points"),
        (
            np.zeros((5, 3)),
            np.tile([0.0, 0.0, 1.0], (5, 1)),
            "expected at least 16 points, found 5",
        ),
        (np.full((20, 3), np.nan), np.tile([0.0, 0.0, 1.0], (20, 1)), "points: expected finite"),
        (np.zeros((20, 3)), np.zeros((20, 3)), "normals: expected unit vectors"),
        (np.zeros((20, 3), dtype=object), np.zeros((20, 3)), "expected a float array"),
    ],
)
def test_malformed_clouds_are_refused(points, normals, message):
    with pytest.raises(CloudError, match=message):
        check_cloud(points, normals)


def test_the_mask_drops_padding():
    points = np.zeros((40, 3))
    points[:, 0] = np.arange(40)
    normals = np.tile([0.0, 0.0, 1.0], (40, 1))
    mask = np.r_[np.ones(30), np.zeros(10)]
    assert check_cloud(points, normals, mask).n == 30
    with pytest.raises(CloudError, match=r"mask: expected shape \(40,\), found \(3,\)"):
        check_cloud(points, normals, np.ones(3))


def test_bad_sampler_arguments():
    with pytest.raises(CloudError, match="n_seeds"):
        CloudSamplerConfig(n_seeds=0)
    with pytest.raises(CloudError, match="opening_margin"):
        CloudSamplerConfig(opening_margin=0.08)


BOARD = np.array([0.2, 0.15, 0.01])
"""Half extents of a board (m) whose underside the cameras never see."""


@pytest.fixture(scope="module")
def board_clouds():
    """(the board seen from above and from its edges: no underside, the whole board)."""
    board = trimesh.creation.box(extents=2.0 * BOARD)
    points, normals = surface_points(board.vertices, board.faces, 4096, np.random.default_rng(3))
    seen = normals[:, 2] > -0.5
    return check_cloud(points[seen], normals[seen]), check_cloud(points, normals)


def test_enclosing_grasps_hold_a_board_seen_from_one_side(board_clouds):
    """The antipodal sampler finds nothing on a board without its underside; the enclosing
    grasps close across its thickness, on the cloud, without touching the whole board."""
    seen, whole = board_clouds
    assert cloud_dual_candidates(seen, rng=np.random.default_rng(4)).n == 0
    config = CloudSamplerConfig(enclosing=True)
    cands = cloud_dual_candidates(seen, config, rng=np.random.default_rng(4))
    assert cands.n > 20
    grasps = cands.grasps
    assert grasps.counts["enclosing_grasps"] == grasps.n
    spacing = seen.spacing
    across = np.abs(grasps.poses[:, 2, 0]) > 0.9  # closing axis within 26 degrees of vertical
    assert across.mean() > 0.9
    # the lowest edge point seen is up to a cloud spacing or two above the underside
    assert (np.abs(grasps.widths[across] - 2.0 * BOARD[2]) <= 2.0 * spacing).all()
    on_board = np.abs((np.abs(grasps.contact_points) - BOARD).max(axis=-1))
    assert on_board.max() <= spacing
    # the unseen underside's contact normal is assumed to face its finger
    lower = np.argmin(grasps.contact_points[..., 2], axis=1)
    assumed = grasps.contact_normals[np.arange(grasps.n), lower]
    finger_side = np.where(lower == 0, 1.0, -1.0)[:, None] * grasps.poses[:, :3, 0]
    assert np.allclose(assumed, finger_side)
    # ... and the other contact is on a face seen to face its finger (the board's top)
    upper = 1 - lower
    seen_normal = seen.normals[grasps.face_ids[np.arange(grasps.n), upper]]
    facing = np.where(upper == 0, 1.0, -1.0) * np.einsum(
        "nk,nk->n", seen_normal, grasps.poses[:, :3, 0]
    )
    assert (facing >= math.cos(math.atan(PAPER.mu))).all()
    assert np.allclose(seen_normal[:, 2], 1.0)
    # The closed fingers miss what was seen; the open hand misses the whole board too (the
    # planned width is what was seen: the fingers close on until they meet the underside).
    tol = CloudSamplerConfig().tolerance
    for pose, width in zip(grasps.poses, grasps.widths, strict=True):
        for cloud, boxes in (
            (seen, (*PANDA.collision_boxes(None), *PANDA.finger_boxes(float(width)))),
            (whole, PANDA.collision_boxes(None)),
        ):
            local = (cloud.points - pose[:3, 3]) @ pose[:3, :3]
            for box in boxes:
                lo = np.asarray(box.center) - np.asarray(box.half_extents) + tol
                hi = np.asarray(box.center) + np.asarray(box.half_extents) - tol
                assert not ((local > lo) & (local < hi)).all(axis=1).any()


def test_enclosing_grasps_refuse_a_face_wider_than_the_hand():
    """A flat face alone (a wall seen from the front) holds nothing the jaws can close on away
    from its border (at the border a finger can reach round it)."""
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(-0.3, 0.3, (2000, 2)), np.zeros(2000)])
    normals = np.tile([0.0, 0.0, 1.0], (2000, 1))
    config = CloudSamplerConfig(enclosing=True)
    grasps = sample_enclosing_grasps(check_cloud(points, normals), config, rng)
    assert grasps.counts["enclosing_poses"] > 0
    to_border = 0.3 - np.abs(grasps.contact_points[..., :2]).max(axis=-1)
    assert (to_border < PANDA.max_opening).all()
    assert grasps.n < 10


def test_bad_enclosing_arguments():
    with pytest.raises(CloudError, match="enclosing_reach: expected at most the pad length"):
        CloudSamplerConfig(enclosing_reach=0.06)
    with pytest.raises(CloudError, match="enclosing: expected a bool, found int"):
        CloudSamplerConfig(enclosing=1)
    with pytest.raises(CloudError, match="n_closing"):
        CloudSamplerConfig(n_closing=0)
