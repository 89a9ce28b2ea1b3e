"""DualGraspLift-v2 (:mod:`dg16m_env.envs.lift.v2`): 5 ms physics steps, and compiled
step arithmetic (:mod:`dg16m_env.envs.lift.kernels`) that agrees with v1's numpy formulas
(:mod:`dg16m_env.envs.lift.arithmetic`) on the same states: the observation, the step's measures
and the hands' substep targets. The task semantics (reward bound, modes, step after the end,
state restore) are tested for v1 and v2 together in ``tests/test_lift_v1.py``; the versions'
records here."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import dg16m_env  # noqa: F401  registers the environments
from dg16m_env.envs.lift import arithmetic
from dg16m_env.envs.lift.experts import FeedbackLiftExpert
from dg16m_env.envs.lift.kernels import STATE_OFFSETS, STATE_PARTS
from dg16m_env.envs.lift.observations import STATE_LAYOUT, STATE_SLICES
from dg16m_env.envs.lift.v2 import PHYSICS_TIMESTEP, DualGraspLiftV2Env
from dg16m_env.envs.lift.versions import V1, V2
from dg16m_env.physics.lift_scene import step_hand_targets

# v1 is made on purpose: Gymnasium's note that a newer version (v2) is registered is expected.
pytestmark = pytest.mark.filterwarnings(
    "ignore:.*DualGraspLift-v1 is out of date.*:DeprecationWarning"
)

LIFT_V2 = "dg16m_env/DualGraspLift-v2"
TOLERANCE = 1e-9
"""Largest difference allowed between the compiled arithmetic and v1's formulas (m, rad)."""


def numpy_state(env: DualGraspLiftV2Env) -> dict[str, np.ndarray]:
    """v1's ``state_parts`` (numpy formulas) on the env's current state."""
    return arithmetic.state_parts(env)


def test_v1_and_v2_differ_only_where_their_records_say() -> None:
    """One task class; the versions are frozen records, and v2's is v1's with 5 ms physics and
    the compiled arithmetic."""
    assert V2.physics_timestep == PHYSICS_TIMESTEP
    differ = {f for f in V1.__dataclass_fields__ if getattr(V1, f) != getattr(V2, f)}
    assert differ == {"name", "physics_timestep", "compiled_arithmetic"}
    with pytest.raises(AttributeError):
        V2.physics_timestep = 0.002  # type: ignore[misc]


def test_v2_steps_the_physics_at_5_ms() -> None:
    env = gym.make(LIFT_V2)
    inner = env.unwrapped
    assert isinstance(inner, DualGraspLiftV2Env)
    env.reset(seed=0)
    assert inner.timestep == PHYSICS_TIMESTEP == 0.005
    assert inner.substeps == 10
    assert inner.control_dt == pytest.approx(0.05)
    assert inner._current.scene.model.opt.timestep == PHYSICS_TIMESTEP
    data = inner._current.data
    before = data.time
    env.step(np.zeros(14, dtype=np.float32))
    assert data.time - before == pytest.approx(0.05, abs=1e-12)
    v1 = gym.make("dg16m_env/DualGraspLift-v1").unwrapped
    v1.reset(seed=0)
    assert v1._current.scene.model.opt.timestep == 0.002  # v1 keeps the benchmark's
    env.close()
    v1.close()


def test_the_kernel_layout_is_the_state_layout() -> None:
    names = [name for name, _, _, _ in STATE_LAYOUT]
    assert set(STATE_PARTS) | {"previous_action", "elapsed", "hold"} == set(names)
    for name, offset in zip(STATE_PARTS, STATE_OFFSETS, strict=True):
        assert STATE_SLICES[name].start == offset


@pytest.mark.parametrize("target_grasp", ["benchmark", None])
def test_observation_and_measures_agree_with_the_numpy_formulas(target_grasp) -> None:
    """Over an expert episode and a random one (hands and object moving, contacts coming and
    going, a hold): every state part and every measure within ``TOLERANCE`` of v1's."""
    env = DualGraspLiftV2Env(target_grasp=target_grasp)
    expert = FeedbackLiftExpert()
    rng = np.random.default_rng(1)
    checked = 0
    for seed, policy in ((3, "expert"), (4, "random")):
        obs, _ = env.reset(seed=seed)
        for _ in range(200):
            if policy == "expert" and target_grasp is not None:
                action = expert(obs)
            else:
                action = rng.uniform(-1, 1, 14).astype(np.float32)
            state = env.get_state()
            obs, _, terminated, truncated, info = env.step(action)
            compiled = env.state_parts()
            formulas = numpy_state(env)
            for name, _, _, _ in STATE_LAYOUT:
                assert np.abs(compiled[name] - formulas[name]).max() <= TOLERANCE, name
            # The step's measures from the state the step ended in and the hold before it:
            # v2's compiled ones and v0's numpy ones.
            env._hold_anchor, env._hold_count = state["hold_anchor"], state["hold_count"]
            numpy_measures = arithmetic.measure(env, False)
            env._hold_anchor, env._hold_count = state["hold_anchor"], state["hold_count"]
            compiled_measures = env._measure(False)
            for field in ("lift", "reach_distance", "slip"):
                assert np.allclose(
                    getattr(compiled_measures, field),
                    getattr(numpy_measures, field),
                    rtol=0.0,
                    atol=TOLERANCE,
                ), field
            if target_grasp is None:
                assert compiled_measures.jaw_angle is None is numpy_measures.jaw_angle
            else:
                assert abs(compiled_measures.jaw_angle - numpy_measures.jaw_angle) <= 1e-7
            for field in ("grasping", "holding", "success", "termination", "unstable"):
                assert np.array_equal(
                    getattr(compiled_measures, field), getattr(numpy_measures, field)
                ), field
            checked += 1
            if terminated or truncated:
                break
        if policy == "expert" and target_grasp is not None:
            assert info["success"]  # the episode went through grasp, lift and hold
    assert checked > 150
    env.close()


def test_substep_targets_agree_with_the_numpy_formulas() -> None:
    """The hands' targets of a step, from the same state: v2's compiled path against v0's numpy
    formulas (both at 10 substeps): the same substep rows and commanded poses, and the same
    physics after the step, within rounding."""
    env = DualGraspLiftV2Env()
    env.reset(seed=5)
    rng = np.random.default_rng(2)
    for _ in range(40):
        action = rng.uniform(-1, 1, 14).astype(np.float32)
        values = env._check_action(action)
        state = env.get_state()
        formulas = [a.copy() for a in arithmetic.hand_targets(env, values)]
        compiled = [a.copy() for a in env._hand_targets(values)]
        for a, b in zip(compiled, formulas, strict=True):  # rows, centres, rotations, quats
            assert a.shape == b.shape
            assert np.abs(a - b).max() <= TOLERANCE
        env.step(action)
        compiled_qpos = env._current.data.qpos.copy()
        env.set_state(state)
        scene, data = env._current.scene, env._current.data
        data.ctrl[scene.squeeze_actuators] = values[6::7] * scene.params.squeeze_force
        step_hand_targets(scene.model, data, formulas[0])
        assert np.abs(compiled_qpos - data.qpos).max() <= 1e-6
        env.set_state(state)
        env.step(action)
    env.close()
