"""PlanningLiftExpert (:mod:`dg16m_env.envs.lift.planning_expert`, issue 57): the open hand's
collision test on cloud points, the cloud read from a pointcloud observation (and its errors),
the recovering expert exactly where there is no cloud or the path is free, a detour where the
cloud blocks the straight path, and a held-out episode the recovering expert loses (its palm
pushes the chair away) that the planning expert completes."""

from __future__ import annotations

import copy

import gymnasium as gym
import numpy as np
import pytest

import dg16m_env  # noqa: F401  registers the environments
from dataset_gen.grasps.gripper import PANDA, get_gripper
from dg16m_env.envs.lift.expert_registry import make_lift_expert
from dg16m_env.envs.lift.observations import STATE_SLICES, goal_frames
from dg16m_env.envs.lift.planning_expert import (
    PlanningLiftExpert,
    approach_candidates,
    hand_hits,
    observed_cloud,
    open_hand_boxes,
    segment_hits,
)
from dg16m_env.envs.lift.recovering_expert import RecoveringLiftExpert

LIFT_V2 = "dg16m_env/DualGraspLift-v2"
DEPTH = get_gripper(PANDA).contact_depth
BOXES = open_hand_boxes(PANDA)
DETOUR_SEED = 100152
"""A held-out procedural episode (a chair) the recovering expert loses in its approach and the
planning expert completes (`baselines.lift_expert_robustness`, 2026-12-07)."""


def held_out_env(**kwargs) -> gym.Env:
    from dg16m_env.envs.objects import split_objects
    from dg16m_env.evaluators import load_benchmark_ref

    ref = load_benchmark_ref(None)
    return gym.make(
        LIFT_V2, benchmark=ref, object_ids=split_objects(list(ref.object_ids))[1], **kwargs
    )


def test_hand_hits_the_palm_not_the_gap_between_the_fingers() -> None:
    rotation = np.eye(3)  # gripper frame = world: approach +y, closing x
    centre = np.array([[0.0, DEPTH, 0.0]])
    between_fingers = centre.copy()
    palm = np.array([[0.0, 0.0, 0.0]])  # the gripper frame's origin, in the palm box
    far = np.array([[0.5, 0.5, 0.5]])
    kw = {"boxes": BOXES, "depth": DEPTH, "margin": 0.0}
    assert not hand_hits(between_fingers, centre, rotation, **kw)[0]
    assert hand_hits(palm, centre, rotation, **kw)[0]
    assert not hand_hits(far, centre, rotation, **kw)[0]
    # just outside the palm box's back face: clear, but not with a margin
    behind = np.array([[0.0, BOXES[0, 0, 1] - 0.005, 0.0]])
    assert not hand_hits(behind, centre, rotation, **kw)[0]
    assert hand_hits(behind, centre, rotation, boxes=BOXES, depth=DEPTH, margin=0.01)[0]
    # several poses at once: only the one whose palm holds the point
    centres = np.array([[0.0, DEPTH, 0.0], [0.3, DEPTH, 0.0]])
    assert hand_hits(palm, centres, rotation, **kw).tolist() == [True, False]


def test_segment_hits_what_the_sweep_meets() -> None:
    rotation = np.eye(3)
    obstacle = np.array([[0.0, 0.0, 0.0]])
    kw = {"boxes": BOXES, "depth": DEPTH, "margin": 0.0, "spacing": 0.01}
    # the hand comes in along +y: its palm passes the obstacle on the way to this goal
    start, goal = np.array([0.0, -0.3, 0.0]), np.array([0.0, DEPTH, 0.0])
    assert segment_hits(obstacle, start, goal, rotation, **kw)
    # ... but not on a path that stops 10 cm before the palm gets there
    assert not segment_hits(obstacle, start, np.array([0.0, DEPTH - 0.2, 0.0]), rotation, **kw)
    # nor one that passes 30 cm to the side
    side = np.array([0.3, 0.0, 0.0])
    assert not segment_hits(obstacle, start + side, goal + side, rotation, **kw)


def test_approach_candidates_turn_away_from_straight_back() -> None:
    rotation = np.eye(3)
    directions = list(approach_candidates(rotation, (0.5, 1.0)))
    # approach +y, up (+z) is orthogonal to it: up, +-x (closing), +-z (third axis) per angle
    assert len(directions) == 10
    for direction, angle in directions:
        assert np.linalg.norm(direction) == pytest.approx(1.0)
        assert np.arccos(np.clip(direction @ [0.0, -1.0, 0.0], -1, 1)) == pytest.approx(angle)
    assert directions[0][0][2] > 0.0  # turned towards up first
    # a vertical approach has no "up" side
    down = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    assert len(list(approach_candidates(down, (0.5,)))) == 4


def test_observed_cloud_reads_the_pointcloud_observation_and_refuses_bad_clouds() -> None:
    assert observed_cloud(np.zeros(117)) is None
    assert observed_cloud({"state": np.zeros(117)}) is None
    points = np.arange(12, dtype=np.float32).reshape(4, 3)
    mask = np.array([1, 0, 1, 1], dtype=np.float32)
    cloud = observed_cloud({"points": points, "mask": mask})
    assert cloud.dtype == np.float64
    np.testing.assert_array_equal(cloud, points[[0, 2, 3]])
    flat = observed_cloud({"points": points.reshape(-1), "mask": mask})  # v3's flat cloud
    np.testing.assert_array_equal(flat, cloud)
    with pytest.raises(ValueError, match=r"expected a cloud of 3 x 4 values .* found points of"):
        observed_cloud({"points": points[:3], "mask": mask})
    bad = points.copy()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match="expected finite cloud points, found NaN"):
        observed_cloud({"points": bad, "mask": mask})
    bad[2, 1] = 0.0
    bad[1, 0] = np.nan  # a masked-out point may be anything
    assert len(observed_cloud({"points": bad, "mask": mask})) == 3


def test_is_the_recovering_expert_without_a_cloud() -> None:
    env = gym.make(LIFT_V2)
    planning, recovering = PlanningLiftExpert(), RecoveringLiftExpert()
    try:
        obs, _ = env.reset(seed=3)
        for _ in range(60):
            phase, action = planning.decide(obs)
            assert (phase, action.tobytes()) == (
                recovering.phase(obs),
                recovering(obs).tobytes(),
            )
            obs, *_ = env.step(action)
    finally:
        env.close()
    assert make_lift_expert("planning").OBS_MODE == "pointcloud"
    assert make_lift_expert("recovering").OBS_MODE == "state"


def approach_setup(obs, expert):
    s = expert.state_vector(obs)
    part = {name: s[sl] for name, sl in STATE_SLICES.items()}
    target_rot, goals, _, _ = (frame[0] for frame in goal_frames(s[None]))
    return part, goals, target_rot


def test_detours_where_the_cloud_blocks_the_straight_path() -> None:
    env = held_out_env(obs_mode="pointcloud")
    planning, recovering = PlanningLiftExpert(), RecoveringLiftExpert()
    try:
        obs, _ = env.reset(seed=DETOUR_SEED)
    finally:
        env.close()
    part, goals, target_rot = approach_setup(obs, planning)
    planned = planning.approach_paths(obs, part, goals, target_rot)
    straight = recovering.approach_paths(obs, part, goals, target_rot)
    cloud = observed_cloud(obs)
    crossing = planning._safe_height(planning._box_corners(part))
    changed = [k for k in range(2) if not np.allclose(np.stack(planned[k]), np.stack(straight[k]))]
    assert changed, "expected a hand whose straight path the cloud blocks"
    for k in changed:
        assert not planning._is_free(cloud, straight[k], target_rot[k], crossing)
        assert planning._is_free(cloud, planned[k], target_rot[k], crossing)
        np.testing.assert_allclose(planned[k][2], goals[k])  # it still ends at the grasp
    # the state alone (no cloud) gives the straight paths
    state = obs["state"]
    assert all(
        np.allclose(np.stack(a), np.stack(b))
        for a, b in zip(
            planning.approach_paths(state, part, goals, target_rot), straight, strict=True
        )
    )


@pytest.mark.parametrize("expert_cls", [RecoveringLiftExpert, PlanningLiftExpert])
def test_a_blocked_approach_is_lost_by_the_recovering_expert_only(expert_cls) -> None:
    env = held_out_env(obs_mode="pointcloud")
    expert = expert_cls()
    attributes = copy.deepcopy(vars(expert))
    try:
        obs, _ = env.reset(seed=DETOUR_SEED)
        while True:
            obs, _, terminated, truncated, info = env.step(expert(obs))
            if terminated or truncated:
                break
    finally:
        env.close()
    assert info["success"] == (expert_cls is PlanningLiftExpert)
    assert vars(expert).keys() == attributes.keys()  # no memory kept between calls


def test_robustness_script_runs_the_planning_expert_on_the_cloud(tmp_path) -> None:
    import json

    from baselines.lift_expert_robustness import Args, main

    out = tmp_path / "robustness.json"
    main(Args(experts="planning", episodes=1, clean=False, out=out))
    saved = json.loads(out.read_text())
    assert [(r["expert"], r["obs_mode"], r["setting"]) for r in saved["rates"]] == [
        ("planning", "pointcloud", "perturbed")
    ]
