"""DualGraspLift-v3 (:mod:`dg16m_env.envs.lift.v3`): v2 whose success needs both hands grasping
on the step it is credited. v2 credits a hold that reached its time on the step the hands let
go (issue 56, item 7): driven into it here, and v3 refuses it; v3's ordinary successes are v2's.
Also v3's flat point cloud (stable-baselines3's checker without a warning) and the versions'
errors for a keyword they do not take. v1 and v2 semantics shared with v3 (reward bound, modes,
state restore) are tested in ``tests/test_lift_v1.py``."""

from __future__ import annotations

import dataclasses
import warnings

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import dg16m_env  # noqa: F401  registers the environments
from dg16m_env.envs.lift.experts import FeedbackLiftExpert
from dg16m_env.envs.lift.measures import Hold, measure_step
from dg16m_env.envs.lift.reward import MAX_STEP_REWARD
from dg16m_env.envs.lift.vector import LiftVectorEnv
from dg16m_env.envs.lift.versions import V0, V1, V2, V3, VERSIONS

LIFT_V2 = "dg16m_env/DualGraspLift-v2"
LIFT_V3 = "dg16m_env/DualGraspLift-v3"
LOOPHOLE_SEED = 0
"""The procedural episode (of 17 seeds, 0-16) in which v2 credits success after the expert held
for 0.9 s and then opened both hands (the only one; found by running all 17)."""
RELEASE_HOLD = 0.9
"""The hold (s) after which the loophole policy opens both hands."""


def release_episode(env_id: str, seed: int, actions: list[np.ndarray] | None = None):
    """The expert until the hold reaches ``RELEASE_HOLD``, then both hands open (fingers -1,
    no motion), to the episode's end; or the given ``actions``. Returns the actions, the
    observations (after each step) and the infos."""
    env = gym.make(env_id)
    expert = FeedbackLiftExpert()
    obs, _ = env.reset(seed=seed)
    taken, observations, infos = [], [], []
    released = False
    for t in range(200):
        if actions is not None:
            action = actions[t]
        elif released:
            action = np.zeros(14, np.float32)
            action[6] = action[13] = -1.0
        else:
            action = expert(obs)
        obs, _, terminated, truncated, info = env.step(action)
        taken.append(action)
        observations.append(obs)
        infos.append(info)
        released = released or info["hold_time"] >= RELEASE_HOLD - 1e-9
        if terminated or truncated or (actions is not None and t + 1 == len(actions)):
            break
    env.close()
    return taken, observations, infos


def test_v3_is_v2_with_the_grasp_needed_at_success_and_a_flat_cloud() -> None:
    assert dataclasses.replace(V2, name="v3", success_needs_grasp=True, flat_cloud=True) == V3
    assert not any(v.success_needs_grasp or v.flat_cloud for v in (V0, V1, V2))
    assert VERSIONS["v3"] is V3
    assert gym.spec(LIFT_V3).max_episode_steps == 200


def test_success_needs_the_grasp_only_where_the_version_says() -> None:
    """The rule on its own: a hold at its time with both hands open succeeds in v0-v2's rule,
    not in v3's, whose hold goes on and succeeds on the next step with the grasp."""
    rot, pos = np.eye(3), np.array([0.0, 0.0, 0.2])
    centres = np.array([[0.05, 0.0, 0.2], [-0.05, 0.0, 0.2]])
    hold = Hold((centres - pos) @ rot, 19)  # a hold of 19 steps: the next one is the 20th
    common = {
        "unstable": False,
        "lift": 0.15,
        "lift_height": 0.10,
        "hold_steps": 20,
        "max_slip": 0.02,
        "centres": centres,
        "obj_pos": pos,
        "obj_rot": rot,
        "com": pos,
        "speed": 0.0,
        "reach_distance": 0.0,
        "jaw_angle": None,
    }
    open_hands = np.array([False, False])
    _, old = measure_step(hold, grasping=open_hands, **common)
    assert old.success
    assert old.termination == "success"
    later, new = measure_step(hold, grasping=open_hands, success_needs_grasp=True, **common)
    assert new.holding
    assert not new.success
    assert new.termination == ""
    assert later.count == 20
    _, regrasped = measure_step(
        later, grasping=np.array([True, True]), success_needs_grasp=True, **common
    )
    assert regrasped.success
    assert regrasped.termination == "success"
    _, one_hand = measure_step(
        later, grasping=np.array([True, False]), success_needs_grasp=True, **common
    )
    assert not one_hand.success


def test_v2_credits_a_hold_whose_hands_let_go_and_v3_refuses_it() -> None:
    actions, v2_obs, v2_infos = release_episode(LIFT_V2, LOOPHOLE_SEED)
    last = v2_infos[-1]
    # v2: success with both hands open, and the success payment
    assert last["success"]
    assert last["termination"] == "success"
    assert last["grasping"].tolist() == [False, False]
    opened = next(t for t, info in enumerate(v2_infos) if info["hold_time"] >= RELEASE_HOLD - 1e-9)
    assert len(v2_infos) - 1 > opened  # credited after the hands were told to open
    t = len(v2_infos)
    assert last["reward_terms"]["success"] == MAX_STEP_REWARD * (200 - t + 1)

    # v3, the same actions: the same steps up to there, but no success without the grasp
    _, v3_obs, v3_infos = release_episode(LIFT_V3, LOOPHOLE_SEED, actions)
    assert len(v3_infos) == t
    for a, b in zip(v2_obs[:-1], v3_obs[:-1], strict=True):
        assert a.tobytes() == b.tobytes()
    assert not v3_infos[-1]["success"]
    assert v3_infos[-1]["termination"] == ""
    assert v3_infos[-1]["reward_terms"].get("success", 0.0) == 0.0

    # v3 with the hands kept open to the end: never a success, the object is dropped
    _, _, infos = release_episode(LIFT_V3, LOOPHOLE_SEED)
    assert not any(info["success"] for info in infos)
    assert infos[-1]["hold_time"] == 0.0


def test_v3_succeeds_where_v2_does_with_the_expert() -> None:
    """The feedback expert keeps its grasp: on seed 1 both versions succeed on the same step,
    with both hands grasping (200 seeded procedural episodes gave the same outcomes: v3.py)."""
    steps = {}
    for env_id in (LIFT_V2, LIFT_V3):
        env = gym.make(env_id)
        expert = FeedbackLiftExpert()
        obs, _ = env.reset(seed=1)
        while True:
            obs, _, terminated, truncated, info = env.step(expert(obs))
            if terminated or truncated:
                break
        env.close()
        assert info["success"], env_id
        assert info["grasping"].tolist() == [True, True]
        steps[env_id] = info["elapsed_steps"]
    assert steps[LIFT_V2] == steps[LIFT_V3]


def test_v3_point_cloud_is_flat_and_passes_sb3_checker_without_warnings() -> None:
    """v3's ``points`` and ``normals`` are v2's rows, flattened; SB3's checker warns about
    v2's (n, 3) arrays and not about v3's."""
    v2 = gym.make(LIFT_V2, obs_mode="pointcloud", n_points=64)
    v3 = gym.make(LIFT_V3, obs_mode="pointcloud", n_points=64)
    assert v3.observation_space["points"].shape == (192,)
    assert v3.observation_space["normals"].shape == (192,)
    a, _ = v2.reset(seed=7)
    b, _ = v3.reset(seed=7)
    for key in ("points", "normals"):
        assert a[key].shape == (64, 3)
        assert b[key].tobytes() == a[key].tobytes()
        assert np.array_equal(b[key].reshape(-1, 3), a[key])
    assert b["mask"].tobytes() == a["mask"].tobytes()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_check_env(v3.unwrapped)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(v2.unwrapped)
    shapes = {str(w.message).split()[2] for w in caught if "unconventional shape" in str(w.message)}
    assert shapes == {"points", "normals"}
    v2.close()
    v3.close()


@pytest.mark.parametrize(
    ("env_id", "name"),
    [
        ("dg16m_env/DualGraspLift-v1", "DualGraspLiftV1Env"),
        (LIFT_V2, "DualGraspLiftV2Env"),
        (LIFT_V3, "DualGraspLiftV3Env"),
    ],
)
def test_an_unknown_keyword_names_the_version_and_the_nearest_keyword(
    env_id: str, name: str
) -> None:
    with pytest.raises(TypeError) as err:
        gym.make(env_id, obsmode="state")
    text = str(err.value)
    assert f"{name}(), {env_id}: expected keyword arguments among benchmark" in text
    assert "found 'obsmode' (did you mean 'obs_mode'?)" in text
    assert "LiftEnv.__init__" not in text


def test_make_vec_gives_the_lift_vector_env_of_v3() -> None:
    envs = gym.make_vec(LIFT_V3, num_envs=2)
    try:
        assert isinstance(envs, LiftVectorEnv)
        assert [v.name for v in envs.get_attr("version")] == ["v3", "v3"]
    finally:
        envs.close()
