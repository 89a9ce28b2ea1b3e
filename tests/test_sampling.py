"""Antipodal single-arm grasp sampling (dataset_gen.grasps.sampling)."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

from dataset_gen.grasps.gripper import PANDA, ROBOTIQ_2F85, GripperModel, contacts_from_pose
from dataset_gen.grasps.sampling import (
    STAGES,
    SamplingError,
    SingleArmGrasps,
    sample_antipodal_grasps,
)
from dataset_gen.objects.grasp_object import GraspObject, is_rigid, load_object
from dataset_gen.sources.procedural import FAMILIES, make_procedural_object
from dg16m_core.errors import Dg16mError, GripperError

MU = 0.4
ARRAYS = ("poses", "contact_points", "contact_normals", "face_ids", "widths")


@pytest.fixture(scope="module")
def ladder() -> GraspObject:
    return make_procedural_object("ladder", 0)


@pytest.fixture(scope="module")
def ladder_grasps(ladder: GraspObject) -> SingleArmGrasps:
    return sample_antipodal_grasps(
        ladder, n_grasps=60, max_candidates=4096, rng=np.random.default_rng(0)
    )


@pytest.fixture(scope="module")
def airplane(real_data: Path) -> GraspObject:
    return load_object(real_data / "dg16m_airplane.obj")


@pytest.fixture(scope="module")
def airplane_grasps(airplane: GraspObject) -> SingleArmGrasps:
    return sample_antipodal_grasps(airplane, n_grasps=80, rng=np.random.default_rng(1))


def _same(a: SingleArmGrasps, b: SingleArmGrasps) -> bool:
    return all(getattr(a, k).tobytes() == getattr(b, k).tobytes() for k in ARRAYS)


def _check_grasps(
    obj: GraspObject, grasps: SingleArmGrasps, gripper: GripperModel = PANDA, mu: float = MU
) -> None:
    """Every property a returned grasp must have, on any mesh."""
    mesh = obj.mesh
    m = grasps.n
    assert m > 0
    assert grasps.gripper == gripper.name
    assert grasps.poses.dtype == np.float64
    assert grasps.face_ids.dtype == np.int64
    assert np.all(is_rigid(grasps.poses, atol=1e-9))

    # contacts lie on the mesh surface, on their own faces
    points = grasps.contact_points.reshape(-1, 3)
    _, distance, _ = trimesh.proximity.closest_point(mesh, points)
    assert distance.max() < 1e-6
    on_face = trimesh.triangles.closest_point(mesh.triangles[grasps.face_ids.reshape(-1)], points)
    assert np.abs(on_face - points).max() < 1e-6

    # unit normals equal to the hit faces' normals (up to orientation on open meshes)
    normals = grasps.contact_normals
    assert np.allclose(np.linalg.norm(normals, axis=-1), 1.0, atol=1e-12)
    face_normals = mesh.face_normals[grasps.face_ids]
    dots = np.einsum("mki,mki->mk", normals, face_normals)
    if mesh.is_volume:
        assert np.allclose(dots, 1.0, atol=1e-12)
    else:
        assert np.allclose(np.abs(dots), 1.0, atol=1e-12)
        assert int((dots < 0).sum()) == grasps.counts["normals_flipped"]
    # normals face their finger: finger 0 at +x, finger 1 at -x
    x = grasps.poses[:, :3, 0]
    assert (np.einsum("mi,mi->m", normals[:, 0], x) > 0).all()
    assert (np.einsum("mi,mi->m", normals[:, 1], x) < 0).all()

    # antipodal: the contact line lies in both friction cones
    line = grasps.contact_points[:, 1] - grasps.contact_points[:, 0]
    line /= np.linalg.norm(line, axis=1, keepdims=True)
    cos_cone = math.cos(math.atan(mu))
    assert (np.einsum("mi,mi->m", line, -normals[:, 0]) >= cos_cone - 1e-9).all()
    assert (np.einsum("mi,mi->m", line, normals[:, 1]) >= cos_cone - 1e-9).all()

    # widths: positive and spannable
    assert (grasps.widths > 1e-3).all()
    assert (grasps.widths <= gripper.max_opening).all()

    # contacts sit between the fingers, in the grasp frame
    R, t = grasps.poses[:, :3, :3], grasps.poses[:, :3, 3]
    local = np.einsum("mji,mkj->mki", R, grasps.contact_points - t[:, None, :])
    assert (np.abs(local[..., 0]) <= gripper.max_opening / 2 + 1e-9).all()
    assert (local[:, 0, 0] > local[:, 1, 0]).all()  # finger 0 on the +x side
    assert (local[..., 1] >= gripper.palm_depth - 1e-9).all()
    assert (local[..., 1] <= gripper.finger_tip + 1e-9).all()
    assert (np.abs(local[..., 2]) <= gripper.finger_width / 2 + 1e-9).all()

    # no returned pose collides: closing the jaws again gives the same grasps
    jaws = contacts_from_pose(obj, grasps.poses, gripper=gripper, check_collision=True)
    assert jaws.ok.all(), [jaws.reason(i) for i in np.flatnonzero(~jaws.ok)[:3]]
    assert np.abs(jaws.points - grasps.contact_points).max() < 1e-4
    assert np.allclose(jaws.width, grasps.widths)

    # counts: stage counts never grow, kept is what came back
    counts = grasps.counts
    stages = [counts[s] for s in STAGES]
    assert all(a >= b for a, b in itertools.pairwise(stages)), counts
    assert counts["kept"] == m
    assert counts["poses_tried"] >= counts["poses_collision_free"] >= counts["poses_closed"]
    assert counts["poses_closed"] >= counts["closed"]


# --------------------------------------------------------------------------------------------
# Procedural objects (closed volumes)
# --------------------------------------------------------------------------------------------


def test_grasps_are_valid(ladder: GraspObject, ladder_grasps: SingleArmGrasps) -> None:
    assert ladder_grasps.n == 60
    _check_grasps(ladder, ladder_grasps)
    # one grasp per contact pair: no two grasps share their contacts
    keys = np.round(ladder_grasps.contact_points.reshape(-1, 6), 9)
    assert len(np.unique(keys, axis=0)) == ladder_grasps.n


def test_deterministic(ladder: GraspObject, ladder_grasps: SingleArmGrasps) -> None:
    again = sample_antipodal_grasps(
        ladder, n_grasps=60, max_candidates=4096, rng=np.random.default_rng(0)
    )
    assert _same(again, ladder_grasps)
    assert again.counts == ladder_grasps.counts
    other = sample_antipodal_grasps(ladder, n_grasps=60, rng=np.random.default_rng(1))
    assert not np.array_equal(other.contact_points, ladder_grasps.contact_points)


def test_fewer_grasps_are_a_prefix(ladder: GraspObject, ladder_grasps: SingleArmGrasps) -> None:
    few = sample_antipodal_grasps(
        ladder, n_grasps=7, max_candidates=4096, rng=np.random.default_rng(0)
    )
    assert few.n == 7
    assert few.counts["kept"] == 7
    for name in ARRAYS:
        assert np.array_equal(getattr(few, name), getattr(ladder_grasps, name)[:7])


def test_prefilter_does_not_change_the_result(ladder: GraspObject) -> None:
    kwargs = {"n_grasps": 25, "batch_size": 256}
    fast = sample_antipodal_grasps(ladder, rng=np.random.default_rng(3), prefilter=True, **kwargs)
    slow = sample_antipodal_grasps(ladder, rng=np.random.default_rng(3), prefilter=False, **kwargs)
    assert _same(fast, slow)
    assert fast.counts["poses_prefiltered"] > 0
    assert slow.counts["poses_prefiltered"] == 0
    assert {k: v for k, v in fast.counts.items() if k != "poses_prefiltered"} == {
        k: v for k, v in slow.counts.items() if k != "poses_prefiltered"
    }


def test_candidates_run_out(ladder: GraspObject) -> None:
    grasps = sample_antipodal_grasps(
        ladder, n_grasps=500, max_candidates=40, batch_size=16, rng=np.random.default_rng(0)
    )
    assert grasps.counts["surface_points"] == 40
    assert grasps.counts["batches"] == 3
    assert 0 < grasps.n < 40
    assert grasps.counts["kept"] == grasps.n


def test_nothing_graspable_returns_empty() -> None:
    cube = trimesh.creation.box(extents=(0.5, 0.5, 0.5))  # wider than any opening
    grasps = sample_antipodal_grasps(
        cube, n_grasps=5, max_candidates=200, rng=np.random.default_rng(0)
    )
    assert grasps.n == 0
    assert grasps.poses.shape == (0, 4, 4)
    assert grasps.contact_points.shape == (0, 2, 3)
    assert grasps.counts["surface_points"] == 200
    assert grasps.counts["within_opening"] == 0


def test_small_box_and_friction() -> None:
    box = trimesh.creation.box(extents=(0.03, 0.2, 0.2))  # graspable across x only
    grasps = sample_antipodal_grasps(box, n_grasps=20, mu=0.0, rng=np.random.default_rng(0))
    assert grasps.n == 20
    # frictionless: only exactly opposite faces qualify; the axis is the box's x axis
    assert np.allclose(np.abs(grasps.poses[:, 0, 0]), 1.0)
    assert np.allclose(grasps.widths, 0.03)
    assert np.allclose(np.abs(grasps.contact_points[..., 0]), 0.015)


def test_other_gripper(ladder: GraspObject) -> None:
    grasps = sample_antipodal_grasps(
        ladder, gripper="robotiq_2f85", n_grasps=15, rng=np.random.default_rng(0)
    )
    assert grasps.n == 15
    _check_grasps(ladder, grasps, gripper=ROBOTIQ_2F85)


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"n_grasps": 0}, SamplingError, "n_grasps: expected an integer >= 1, found 0"),
        ({"n_grasps": 2.5}, SamplingError, "n_grasps: expected an integer >= 1"),
        ({"n_grasps": True}, SamplingError, "n_grasps: expected an integer >= 1, found True"),
        ({"batch_size": np.int64(0)}, SamplingError, "batch_size: expected an integer >= 1"),
        ({"n_approach": 0}, SamplingError, "n_approach: expected"),
        ({"mu": -0.1}, SamplingError, "mu: expected a finite friction coefficient >= 0"),
        ({"mu": float("nan")}, SamplingError, "mu: expected"),
        ({"gripper": "hand"}, GripperError, "gripper: expected one of"),
        ({"rng": 0}, SamplingError, "rng: expected a numpy.random.Generator, found int"),
        ({"max_candidates": 0}, SamplingError, "max_candidates: expected"),
        ({"opening_margin": 0.1}, SamplingError, "opening_margin: expected"),
        ({"min_width": -1.0}, SamplingError, "min_width: expected a finite length"),
        ({"axis": "z"}, SamplingError, "axis: expected 'normals' or 'contacts'"),
        ({"rays_per_finger": (0, 5)}, SamplingError, "rays_per_finger: expected"),
    ],
)
def test_bad_input(
    ladder: GraspObject, kwargs: dict[str, object], error: type[Exception], message: str
) -> None:
    args: dict[str, object] = {"rng": np.random.default_rng(0), "n_grasps": 5, **kwargs}
    with pytest.raises(error, match=message) as info:
        sample_antipodal_grasps(ladder, **args)  # type: ignore[arg-type]
    assert isinstance(info.value, Dg16mError)


def test_defaults_are_the_papers() -> None:
    import inspect

    from dg16m_core.parameters import PAPER

    defaults = inspect.signature(sample_antipodal_grasps).parameters
    assert defaults["n_grasps"].default == PAPER.n_grasps == 500
    assert defaults["mu"].default == PAPER.mu


def test_numpy_counts_are_accepted(ladder: GraspObject) -> None:
    grasps = sample_antipodal_grasps(
        ladder, n_grasps=np.int64(3), batch_size=np.int32(256), rng=np.random.default_rng(0)
    )
    assert grasps.n <= 3


def test_bad_object() -> None:
    with pytest.raises(SamplingError, match=r"obj: expected a GraspObject or trimesh\.Trimesh"):
        sample_antipodal_grasps("mesh.obj", rng=np.random.default_rng(0))  # type: ignore[arg-type]
    with pytest.raises(SamplingError, match="obj: expected a mesh with surface area, found 0"):
        sample_antipodal_grasps(trimesh.Trimesh(), rng=np.random.default_rng(0))


# --------------------------------------------------------------------------------------------
# The real airplane: open, 27 bodies, inconsistently wound
# --------------------------------------------------------------------------------------------


@pytest.mark.real_data
def test_airplane_grasps_are_valid(airplane: GraspObject, airplane_grasps: SingleArmGrasps) -> None:
    assert not airplane.mesh.is_volume
    assert airplane_grasps.n == 80
    _check_grasps(airplane, airplane_grasps)


@pytest.mark.real_data
def test_airplane_deterministic(airplane: GraspObject, airplane_grasps: SingleArmGrasps) -> None:
    again = sample_antipodal_grasps(airplane, n_grasps=80, rng=np.random.default_rng(1))
    assert _same(again, airplane_grasps)


# --------------------------------------------------------------------------------------------
# Heavier: the release's 500 grasps on the airplane and on every family
# --------------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.real_data
def test_airplane_500(airplane: GraspObject) -> None:
    grasps = sample_antipodal_grasps(airplane, rng=np.random.default_rng(0))
    assert grasps.n == 500
    _check_grasps(airplane, grasps)


@pytest.mark.slow
@pytest.mark.parametrize("family", FAMILIES)
def test_every_family_500(family: str) -> None:
    obj = make_procedural_object(family, 0)
    grasps = sample_antipodal_grasps(obj, rng=np.random.default_rng(0))
    assert grasps.n == 500, grasps.counts
    _check_grasps(obj, grasps)
