"""``dg16m_env/DualGraspLift-v2``: the Lift task of v1 on 5 ms physics steps, about three times
as many steps per second.

Everything a learner sees and earns is v1's (:mod:`dg16m_env.envs.dual_grasp_lift_v1`, whose
docstring is the reference): the action space, the reward modes and their bound, the
observation modes and their 117-number state, ``info``, ``get_state``/``set_state``, the
target grasp by default, 20 Hz control and the 200-step episode. v2 changes how a step is
computed:

* **Physics**: MuJoCo steps of :data:`PHYSICS_TIMESTEP` = 5 ms, 10 per control step (v0, v1:
  the benchmark's 2 ms, 25 per step). Contacts keep their time constant of two physics steps
  (``solref = [2 * timestep, 1]``: 10 ms instead of 4 ms), so they are a little softer. On the
  same seeded episodes of the held-out objects the feedback expert succeeds as on v1 (74.5%
  against 73.5% of 200 procedural episodes, 72 against 77% of 100 real ones, within the
  intervals; BENCHMARKS.md), no episode ended unstable, and the physics costs 0.45 of v1's.
* **Speed**: 2,589-3,081 random-action steps per second on one quiet core, against v0's
  1,119-1,132 and v1's 931-1,010 in the same runs (``bench/env_lift.py --versions 6``).
* **Arithmetic**: a step's hand targets and its observation are computed by two compiled
  functions (:mod:`dg16m_env.envs.lift_kernels`) instead of a few hundred numpy operations;
  they agree with v1's formulas to rounding (within 1e-9, ``tests/test_lift_v2.py``), not bit
  for bit.

``gym.make_vec("dg16m_env/DualGraspLift-v2", num_envs=N)`` gives a
:class:`~dg16m_env.envs.lift_vector.LiftVectorEnv`: the N environments in blocks stepped by
``workers`` processes, the calling one included, one message per worker per step (Gymnasium's
``AsyncVectorEnv``, one message per environment, spent as long on the messages as on v2's
steps); ``vectorization_mode="sync"`` or ``"async"`` give Gymnasium's own.

A v1 policy runs on v2 unchanged (same spaces); its success rate can differ a little, since
the hands and object move slightly differently. Demonstrations and replays are per version:
``dg16m demos collect --env-id dg16m_env/DualGraspLift-v2``.

Version history
---------------
* v2 (2026-12-05): 5 ms physics steps (10 per control step), compiled step arithmetic,
  :class:`~dg16m_env.envs.lift_vector.LiftVectorEnv` as ``gym.make_vec``'s default.
* v1, v0: see :mod:`dg16m_env.envs.dual_grasp_lift_v1` and
  :mod:`dg16m_env.envs.dual_grasp_lift` (unchanged, still registered).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dg16m_env.envs.dual_grasp_lift import (
    HAND_WORKSPACE_TOP,
    HAND_WORKSPACE_XY,
    TABLE_MARGIN,
    use_timestep,
)
from dg16m_env.envs.dual_grasp_lift_v1 import DualGraspLiftV1Env
from dg16m_env.envs.lift_measures import Hold, LiftStepMeasures, measure_step
from dg16m_env.envs.lift_observations import STATE_LAYOUT, STATE_SIZE, STATE_SLICES
from dg16m_env.envs.lift_spaces import MAX_ROTATION, MAX_TRANSLATION

PHYSICS_TIMESTEP = 0.005
"""MuJoCo's timestep in v2 (s; 10 physics steps per 50 ms control step)."""

_PREVIOUS = STATE_SLICES["previous_action"]
_ELAPSED = STATE_SLICES["elapsed"].start
_HOLD = STATE_SLICES["hold"].start
_kernels: Any = None  # dg16m_env.envs.lift_kernels, imported at the first reset (numba: 0.4 s)


def lift_kernels() -> Any:
    """:mod:`dg16m_env.envs.lift_kernels`, imported on first use (so that ``gym.make`` does
    not wait for numba)."""
    global _kernels
    if _kernels is None:
        from dg16m_env.envs import lift_kernels as module

        _kernels = module
    return _kernels


class DualGraspLiftV2Env(DualGraspLiftV1Env):
    """Two floating Panda hands lift a benchmark object (v2: v1's task on 5 ms physics steps
    with compiled step arithmetic; see the module docstring). Arguments: v1's."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        use_timestep(self, PHYSICS_TIMESTEP)
        self._targets = np.empty((self.substeps, 14))
        self._state = np.zeros(STATE_SIZE)  # the last observe() (float64, unclipped)
        self._state_fresh = False  # _measure's observe() is the state the step ended in
        self._centres = np.zeros((2, 3))

    def _hand_targets(
        self, values: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """v0's hand targets (:meth:`DualGraspLiftEnv._hand_targets`), by
        :func:`~dg16m_env.envs.lift_kernels.substep_targets`."""
        assert self._current is not None
        centres, rotations, final = np.empty((2, 3)), np.empty((2, 3, 3)), np.empty((2, 4))
        lift_kernels().substep_targets(
            values,
            self._target_pos,
            self._target_quat,
            self._fractions,
            MAX_TRANSLATION,
            MAX_ROTATION,
            self._current.scene.gripper.contact_depth,
            HAND_WORKSPACE_XY,
            HAND_WORKSPACE_TOP,
            TABLE_MARGIN,
            self._clip_local_points(),
            self._targets,
            centres,
            rotations,
            final,
        )
        return self._targets, centres, rotations, final

    def _observe(self) -> tuple[float, bool, bool, float, float, float]:
        """:func:`~dg16m_env.envs.lift_kernels.observe` on the current state."""
        assert self._current is not None
        scene, data, item = self._current.scene, self._current.data, self._current
        grasp = self._grasp
        kernels = lift_kernels()
        return kernels.observe(  # type: ignore[no-any-return]
            data.xpos,
            data.xmat,
            data.xipos,
            data.qpos,
            data.qvel,
            data.sensordata,
            scene.object_body,
            scene.hand_bodies,
            scene.object_qvel.start,
            scene.finger_qpos,
            scene.finger_contacts,
            self._no_grasp if grasp is None else grasp,
            grasp is not None,
            self._target_pos,
            self._target_rot,
            item.box_low,
            item.box_high,
            self._rest_com_z,
            scene.gripper.contact_depth,
            scene.gripper.max_opening,
            kernels.STATE_OFFSETS,
            self._state,
            self._centres,
        )

    _no_grasp = np.zeros((2, 4, 4))

    def _measure(self, unstable: bool) -> LiftStepMeasures:
        """v0's measures (lift, grasps, hold, termination, reach and angle) from one
        :meth:`_observe`, which also leaves the step's state for :meth:`_state_values`."""
        lift, grasp0, grasp1, reach, angle, speed = self._observe()
        self._state_fresh = True
        assert self._current is not None
        data, body = self._current.data, self._current.scene.object_body
        hold, measures = measure_step(  # v0's module docstring, *Success* and *Termination*
            Hold(self._hold_anchor, self._hold_count),
            unstable=unstable,
            lift=lift,
            lift_height=self.lift_height,
            hold_steps=self.hold_steps,
            max_slip=self.max_slip,
            grasping=np.array([grasp0, grasp1]),
            centres=self._centres.copy(),
            obj_pos=data.xpos[body],
            obj_rot=data.xmat[body].reshape(3, 3),
            com=data.xipos[body],
            speed=speed,
            reach_distance=reach,
            jaw_angle=angle if self._grasp is not None else None,
        )
        self._hold_anchor, self._hold_count = hold.anchor, hold.count
        return measures

    def _state_values(self) -> np.ndarray:
        if not self._state_fresh:
            self._observe()
        self._state_fresh = False
        state = self._state
        state[_PREVIOUS] = self._previous_action
        state[_ELAPSED] = min(self._elapsed / self._steps_total, 1.0)
        state[_HOLD] = min(self._hold_count / max(self.hold_steps, 1), 1.0)
        return state.copy()

    def state_parts(self) -> dict[str, np.ndarray]:
        """The named parts of the ``"state"`` observation (float64, unclipped; v1's)."""
        self._state_fresh = False  # a caller between steps sees the current state
        state = self._state_values()
        return {name: state[STATE_SLICES[name]].copy() for name, _, _, _ in STATE_LAYOUT}
