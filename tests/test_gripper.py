"""Gripper models, the grasp frame convention, and closing the jaws (contacts_from_pose)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from dataset_gen.grasps.gripper import (
    GRIPPERS,
    PANDA,
    ROBOTIQ_2F85,
    ContactStatus,
    contacts_from_pose,
    get_gripper,
    transform_points,
)
from dataset_gen.objects.grasp_object import make_object
from dg16m_core.errors import GripperError


def _plank(thickness: float = 0.03, x_offset: float = 0.0):
    """A 0.2 x 0.2 m plank of the given thickness along x, centred at (x_offset, 0, 0)."""
    box = trimesh.creation.box(extents=(thickness, 0.2, 0.2))
    box.apply_translation([x_offset, 0.0, 0.0])
    return make_object(box, object_id="plank", center=False)


def _edge_grasp(depth_into_edge: float, gripper=PANDA) -> np.ndarray:
    """Approach along +y onto the plank's edge at y = -0.1, contacts ``depth_into_edge`` deep."""
    y = -0.1 + depth_into_edge
    return gripper.pose_from_contacts([0.015, y, 0.0], [-0.015, y, 0.0], approach=[0, 1, 0])


def test_plank_edge_grasp_gives_two_opposite_contacts() -> None:
    result = contacts_from_pose(_plank(), _edge_grasp(0.02))
    assert result.status.tolist() == [ContactStatus.OK]
    points, normals = result.points[0], result.normals[0]
    np.testing.assert_allclose(points[:, 0], [0.015, -0.015], atol=1e-9)
    np.testing.assert_allclose(points[:, 2], 0.0, atol=1e-9)  # patch centre across the pad
    # the plank's edge is at y = -0.1; the pad reaches from it to the fingertip
    fingertip_y = -0.08 + (PANDA.finger_tip - PANDA.contact_depth)
    assert points[0, 1] == pytest.approx((-0.1 + fingertip_y) / 2, abs=5e-3)
    np.testing.assert_allclose(normals, [[1, 0, 0], [-1, 0, 0]], atol=1e-9)
    assert result.width[0] == pytest.approx(0.03, abs=1e-9)
    assert result.reason(0) == "both jaws touch the object"


def test_off_centre_object_is_pushed_to_the_middle() -> None:
    result = contacts_from_pose(_plank(x_offset=0.02), _edge_grasp(0.02))
    assert result.ok.all()
    np.testing.assert_allclose(result.points[0, :, 0], [0.035, 0.005], atol=1e-9)


def test_pose_far_from_the_object_misses() -> None:
    T = _edge_grasp(0.02)
    T[:3, 3] += [0.0, 0.0, 1.0]
    result = contacts_from_pose(_plank(), T)
    assert result.status.tolist() == [ContactStatus.MISS]
    assert np.isnan(result.points).all()
    assert result.face_ids.tolist() == [[-1, -1]]


def test_palm_pushed_into_the_object_collides() -> None:
    result = contacts_from_pose(_plank(), _edge_grasp(0.09))
    assert result.status.tolist() == [ContactStatus.COLLISION]
    assert "intersects" in result.reason(0)


def test_finger_landing_on_the_object_collides() -> None:
    T = _edge_grasp(0.02)
    T[:3, 3] += [0.04, 0.0, 0.0]  # finger 1 now sits inside the plank, finger 0 is clear
    assert contacts_from_pose(_plank(), T).status.tolist() == [ContactStatus.COLLISION]


def test_object_wider_than_the_opening() -> None:
    result = contacts_from_pose(_plank(thickness=0.1), _edge_grasp(0.02))
    assert result.status.tolist() == [ContactStatus.TOO_WIDE]
    # without the collision check the pads start inside the plank: nothing to close on
    unchecked = contacts_from_pose(_plank(thickness=0.1), _edge_grasp(0.02), check_collision=False)
    assert unchecked.status.tolist() == [ContactStatus.MISS]


def test_batch_mixes_outcomes_and_flags_invalid_poses() -> None:
    good = _edge_grasp(0.02)
    scaled = good.copy()
    scaled[:3, :3] *= 1.1
    nan = good.copy()
    nan[0, 3] = np.nan
    far = good.copy()
    far[2, 3] += 1.0
    result = contacts_from_pose(_plank(), np.stack([good, scaled, nan, far, _edge_grasp(0.09)]))
    assert result.status.tolist() == [
        ContactStatus.OK,
        ContactStatus.INVALID_POSE,
        ContactStatus.INVALID_POSE,
        ContactStatus.MISS,
        ContactStatus.COLLISION,
    ]


@pytest.mark.parametrize("shape", [(3, 4), (2, 4, 3), (4,)])
def test_wrong_pose_shapes_raise(shape: tuple[int, ...]) -> None:
    with pytest.raises(GripperError, match=r"expected shape \(4, 4\) or \(N, 4, 4\)"):
        contacts_from_pose(_plank(), np.zeros(shape))


def test_robotiq_geometry_and_opening_limits() -> None:
    result = contacts_from_pose(_plank(), _edge_grasp(0.02, ROBOTIQ_2F85), gripper="robotiq_2f85")
    assert result.ok.all()
    with pytest.raises(GripperError, match=r"opening in \[0, 0.085\]"):
        contacts_from_pose(_plank(), _edge_grasp(0.02), gripper="robotiq_2f85", opening=0.1)
    with pytest.raises(GripperError, match="expected one of"):
        get_gripper("shadow_hand")


def test_pose_from_contacts_puts_contacts_at_the_contact_depth() -> None:
    rng = np.random.default_rng(0)
    for model in GRIPPERS.values():
        p0, p1 = rng.normal(size=3), rng.normal(size=3)
        T = model.pose_from_contacts(p0, p1, approach=rng.normal(size=3))
        local = transform_points(np.linalg.inv(T), [p0, p1])
        half = np.linalg.norm(p0 - p1) / 2
        np.testing.assert_allclose(
            local, [[half, model.contact_depth, 0], [-half, model.contact_depth, 0]], atol=1e-12
        )
    with pytest.raises(GripperError, match="distinct"):
        PANDA.pose_from_contacts(np.zeros(3), np.zeros(3), approach=[0, 1, 0])


def test_templates_and_collision_geometry() -> None:
    points = PANDA.control_points()
    assert points.shape == (6, 3)
    np.testing.assert_allclose(points[3], [0.04, PANDA.finger_tip, 0.0])
    a = PANDA.surface_points(256, seed=3)
    np.testing.assert_array_equal(a, PANDA.surface_points(256, seed=3))
    assert not np.array_equal(a, PANDA.surface_points(256, seed=4))
    mesh = PANDA.collision_mesh()
    # fitted to the ACRONYM Panda collision mesh: fingers from 0.0584 to 0.1122 m along approach
    assert mesh.bounds[1, 1] == pytest.approx(0.1122)
    assert mesh.bounds[1, 0] == pytest.approx(0.1025)
    closed = PANDA.finger_boxes(opening=0.0)
    assert closed[0].center[0] == pytest.approx(PANDA.finger_thickness / 2)


@pytest.mark.real_data
def test_release_contacts_lie_between_the_robotiq_fingers(real_data: Path) -> None:
    import h5py

    with h5py.File(real_data / "dg16m_airplane.h5", "r") as handle:
        T = handle["grasps/grasps"][:].reshape(-1, 4, 4)
        contacts = handle["grasps/contact_points"][:].reshape(-1, 2, 3)
    local = np.einsum("nji,nkj->nki", T[:, :3, :3], contacts - T[:, None, :3, 3])
    model = ROBOTIQ_2F85
    assert np.all(np.abs(local[:, :, 0]) <= model.max_opening / 2)
    assert np.all(local[:, 0, 0] > 0)  # finger 0 at +x
    np.testing.assert_allclose(local[:, :, 1], model.contact_depth, atol=1e-9)
    np.testing.assert_allclose(local[:, :, 2], 0.0, atol=1e-9)


@pytest.mark.real_data
def test_acronym_panda_grasps_close_on_the_mug(real_data: Path) -> None:
    from dataset_gen.io import read_acronym
    from dataset_gen.objects.grasp_object import load_object

    acr = read_acronym(real_data / "acronym_mug_10f6e090.h5")
    mug = load_object(real_data / "acronym_mug_10f6e090.obj", scale=acr.object_scale, center=False)
    picks = np.flatnonzero(acr.success)[:60]
    result = contacts_from_pose(mug, acr.transforms[picks], gripper=PANDA)
    # ACRONYM's successful grasps put the mug between the Panda's fingers
    assert result.ok.mean() >= 0.8, {s.name: int((result.status == s).sum()) for s in ContactStatus}
    assert np.nanmax(result.width) <= PANDA.max_opening


def test_the_collision_checker_is_built_once_per_mesh_and_dropped_when_it_changes():
    from dataset_gen.grasps.gripper import _collision_checker

    mesh = trimesh.creation.box(extents=(0.04, 0.03, 0.03))
    first = _collision_checker(mesh, PANDA, PANDA.max_opening)
    assert _collision_checker(mesh, PANDA, PANDA.max_opening) is first
    assert _collision_checker(mesh, PANDA, 0.05) is not first  # another opening
    T = np.eye(4)
    T[1, 3] = -PANDA.contact_depth  # the box between the open fingers
    before = contacts_from_pose(mesh, T)
    mesh.vertices = mesh.vertices * np.array([3.0, 1.0, 1.0])  # now wider than the opening
    assert _collision_checker(mesh, PANDA, PANDA.max_opening) is not first
    after = contacts_from_pose(mesh, T)
    assert before.ok[0]
    assert not after.ok[0]
