"""The open-hand clearance rule: the generator's test agrees with the simulator's invalid check."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

pytest.importorskip("mujoco")
pytest.importorskip("coacd")

from shipped_meshes import FAST, MESHES

from dataset_gen.grasps.clearance import OpenHandClearance, collision_parts
from dataset_gen.grasps.gripper import get_gripper
from dataset_gen.grasps.sampling import sample_antipodal_grasps
from dataset_gen.objects.decomposition import convex_decomposition
from dataset_gen.objects.grasp_object import ConvexPart, make_object
from dataset_gen.sources.object_source import ObjectSource
from dg16m_core.parameters import PAPER, PROTOCOL
from dg16m_env.physics.scene import compile_scene
from dg16m_env.physics.trial_protocol import (
    InvalidReason,
    TrialProtocol,
    check_initial_poses,
    open_hand_penetration,
)


def _box_part(center: tuple[float, float, float], half: tuple[float, float, float]) -> ConvexPart:
    pose = np.eye(4)
    pose[:3, 3] = center
    return ConvexPart(kind="box", pose=pose, size=half)


@pytest.fixture(scope="module")
def l_object():
    """An L of two 4 cm square bars (0.4 m long each) meeting at the origin corner; its exact
    convex parts are the two boxes, its coarse one the L's convex hull (which fills the notch)."""
    exact = (
        _box_part((0.18, 0.0, 0.0), (0.2, 0.02, 0.02)),
        _box_part((0.0, 0.0, 0.18), (0.02, 0.02, 0.2)),
    )
    boxes = []
    for part in exact:
        box = trimesh.creation.box(extents=2 * np.asarray(part.size))
        box.apply_transform(part.pose)
        boxes.append(box)
    mesh = trimesh.boolean.union(boxes, engine="manifold")
    obj = make_object(mesh, object_id="l_bars", center=False, parts=exact, mass=PAPER.mass)
    coarse = (
        ConvexPart(kind="mesh", pose=np.eye(4), vertices=np.asarray(mesh.convex_hull.vertices)),
    )
    return obj, exact, coarse


def _top_pinch(x: float) -> np.ndarray:
    """A Panda pose pinching the horizontal bar from above at ``x`` (closing along world y)."""
    gripper = get_gripper("panda")
    pose = np.eye(4)
    pose[:3, 0] = (0.0, 1.0, 0.0)  # closing axis
    pose[:3, 1] = (0.0, 0.0, -1.0)  # approach: down
    pose[:3, 2] = np.cross(pose[:3, 0], pose[:3, 1])
    pose[:3, 3] = (x, 0.0, gripper.contact_depth)  # contacts on the bar's centre line
    return pose


def test_pair_invalid_against_coarse_hull_is_valid_against_faithful_parts(l_object) -> None:
    obj, exact, coarse = l_object
    grasp = np.stack([_top_pinch(0.12), _top_pinch(0.3)])[None]
    protocol = TrialProtocol()
    # The simulator's verdicts.
    reason_exact, depth_exact = check_initial_poses(
        compile_scene(obj, parts=exact), grasp, protocol
    )
    reason_coarse, depth_coarse = check_initial_poses(
        compile_scene(obj, parts=coarse), grasp, protocol
    )
    assert reason_exact[0] == InvalidReason.NONE
    assert depth_exact[0] <= PROTOCOL.invalid_penetration
    assert reason_coarse[0] == InvalidReason.HAND0_PENETRATES
    assert depth_coarse[0] > 0.05  # the palm sits centimetres inside the hull over the notch
    # The generator's rule says the same, hand by hand.
    assert OpenHandClearance(exact).clear(grasp[0]).all()
    assert not OpenHandClearance(coarse).clear(grasp[0]).any()


def test_generator_rule_rejects_exactly_what_the_simulator_calls_invalid(tmp_path: Path) -> None:
    """Real-mesh hulls (the shipped dining table, CoACD), 600 seeded open hands around it."""
    obj = ObjectSource("dining_table", mesh=MESHES / "dining_table.obj").load(PAPER.mass)
    parts = convex_decomposition(obj.mesh, params=FAST, cache_dir=tmp_path)
    rng = np.random.default_rng(7)
    n = 300
    rotations = np.linalg.qr(rng.normal(size=(2 * n, 3, 3)))[0]
    rotations *= np.sign(np.linalg.det(rotations))[:, None, None]
    poses = np.tile(np.eye(4), (2 * n, 1, 1))
    poses[:, :3, :3] = rotations
    # Hand origins near the surface: a surface point pushed out along its normal by 0-15 cm.
    points, faces = trimesh.sample.sample_surface(obj.mesh, 2 * n, seed=3)
    offsets = rng.uniform(0.0, 0.15, 2 * n)[:, None]
    poses[:, :3, 3] = points + offsets * obj.mesh.face_normals[faces]
    grasps = poses.reshape(n, 2, 4, 4)

    simulator = open_hand_penetration(compile_scene(obj, parts=parts), grasps).reshape(2 * n, 3)
    generator = OpenHandClearance(parts).depths(poses)
    tolerance = PROTOCOL.invalid_penetration
    sim_invalid = simulator.max(axis=1) > tolerance
    gen_invalid = generator.max(axis=1) > tolerance
    # Both are exact convex penetration depths; only a hand within solver precision of the
    # threshold could be judged differently, and there is none here.
    near = (np.abs(simulator - tolerance) < 1e-6).any(axis=1) | (
        np.abs(generator - tolerance) < 1e-6
    ).any(axis=1)
    assert not near.any()
    assert 0.1 < sim_invalid.mean() < 0.9  # the sample has both kinds
    np.testing.assert_array_equal(gen_invalid, sim_invalid)
    # Depths near the threshold (what the rule is about) agree closely too; deeper ones can
    # differ by millimetres (MuJoCo reports its deepest contact point, FCL the minimum
    # translation), which never changes a verdict.
    shallow = (simulator < 0.001) & (generator < 0.001)
    print("max |depth difference| below 1 mm:", np.abs(generator - simulator)[shallow].max())
    np.testing.assert_allclose(generator[shallow], simulator[shallow], atol=1e-5)


def test_sampler_keeps_only_hands_clear_of_the_collision_parts(l_object) -> None:
    obj, _, coarse = l_object
    mesh_only = sample_antipodal_grasps(obj, n_grasps=60, rng=np.random.default_rng(0))
    with_parts = sample_antipodal_grasps(
        obj, n_grasps=60, rng=np.random.default_rng(0), collision_parts=coarse
    )
    coarse_rule = OpenHandClearance(coarse)
    # Without the rule, grasps over the notch are kept although the coarse hull covers them ...
    assert not coarse_rule.clear(mesh_only.poses).all()
    assert mesh_only.counts["poses_blocked_by_parts"] == 0
    # ... with it, every kept open hand is clear, and the sampler says how many it turned away.
    assert with_parts.n > 0
    assert coarse_rule.clear(with_parts.poses).all()
    assert with_parts.counts["poses_blocked_by_parts"] > 0


def test_collision_parts_are_the_decomposition_for_meshes_only(
    l_object, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    obj, _, _ = l_object
    assert collision_parts(obj) is None  # exact parts: the mesh test covers them
    monkeypatch.setenv("DG16M_CACHE_DIR", str(tmp_path))
    mesh_obj = ObjectSource("dining_table", mesh=MESHES / "dining_table.obj").load(PAPER.mass)
    parts = collision_parts(mesh_obj)
    assert parts
    assert all(p.kind == "mesh" for p in parts)
    assert any(tmp_path.rglob("*.json"))  # cached under DG16M_CACHE_DIR


def test_depths_of_an_empty_part_list_and_shapes(l_object) -> None:
    _, exact, _ = l_object
    rule = OpenHandClearance(exact)
    assert rule.depths(np.eye(4)).shape == (1, 3)
    assert rule.depths(np.zeros((0, 4, 4))).shape == (0, 3)
    assert OpenHandClearance(()).clear(np.tile(np.eye(4), (3, 1, 1))).all()
