"""``dg16m_env/DualGraspLift-v1``: the Lift task as a robot-learning benchmark.

The physics, the action space, the randomisations, success (lift ``lift_height`` and hold
``hold_time`` without slip) and the failure causes are those of ``DualGraspLift-v0``
(:mod:`dg16m_env.envs.dual_grasp_lift`, whose docstring is the reference for them). v1 changes
what a learner sees and earns:

* **Reward modes** in which success is always the best return (*Rewards*).
* **Observation modes**, with the relative features a policy needs (*Observation modes*).
* ``info["success"]`` and ``info["fail"]`` on every step; the episode ends itself at
  ``episode_steps`` (``truncated``); ``step()`` after the episode ended raises
  ``RuntimeError`` until ``reset()``.
* :meth:`DualGraspLiftV1Env.get_state` / :meth:`~DualGraspLiftV1Env.set_state` restore a
  simulation exactly (same machine): the steps after a restore give the same bytes.
* A target grasp by default (``target_grasp="benchmark"``): the task is to carry out the
  benchmark's dual grasp and lift.

Observations are taken after the control step's last physics step (v0 read positions and
contacts as they were at the start of that physics step, 2 ms earlier); the physics is the same.
``render()`` draws the lights' shadows into 1024 x 1024 maps (v0: 4096 x 4096, 93% of a frame
with Mesa's software OpenGL): a frame after the first takes 10-25 ms (procedural objects) and
40-50 ms (real furniture) instead of 0.09 and 0.15 s; the shadows' edges are softer.

Rewards
-------
``reward_mode`` (default ``"dense"``); the reward is the sum of ``info["reward_terms"]``.

* ``"dense"``: on a step that does not succeed, all terms are >= 0 and sum to at most
  ``R = MAX_STEP_REWARD`` = 5 (:func:`~dg16m_env.envs.lift_reward.dense_terms`):
  ``reach = 1 - tanh(5 d)`` (``d`` the mean distance, m, from each hand's grasp centre to its
  target's; to the object's box without a target), ``align = 1 - theta / pi`` (mean jaw angle to
  the target, rad; 0 without one), ``grasp = 0.5`` per hand grasping with both fingers,
  ``lift = clip(lift / lift_height, 0, 1)`` while both hands grasp, ``hold = 1`` while a hold is
  under way. The **success step pays** ``R * (T - t + 1)`` (``success``, the other terms 0),
  where ``t`` is the step's number (1 for the first step) and ``T`` = ``episode_steps`` (200). An
  unstable step and a failed episode's last step pay 0; a failure ends the episode, so it
  forfeits what the steps left could have paid.
* ``"normalized_dense"``: the dense terms divided by ``R`` (a step pays at most 1; the success
  step ``T - t + 1``).
* ``"sparse"``: 1 on the success step, else 0.

**Bound** (every mode): from any step ``t`` of any episode, what the steps ``t .. T`` can earn
without succeeding is at most ``R * (T - t + 1)`` (dense; ``T - t + 1`` normalised, 0 sparse),
which is exactly what succeeding at step ``t`` pays (sparse: 1). So of two episodes that agree
up to step ``t - 1``, the one that succeeds at step ``t`` has the higher or equal return: a
policy that hovers with the object lifted never out-earns one that completes the hold
(``tests/test_lift_v1.py`` checks it seed for seed against a policy that lifts only 5 cm).

Observation modes
-----------------
``obs_mode`` (default ``"state"``; spaces by
:func:`~dg16m_env.envs.lift_observations.observation_space`):

* ``"state"``: ``Box((117,), float32)``, world frame, the parts of
  :data:`~dg16m_env.envs.lift_observations.STATE_LAYOUT` in order:

  ============================  ==  ============================================================
  part                          n   content (units)
  ============================  ==  ============================================================
  ``centre_errors``             6   per hand: its grasp centre minus its target's (m; 0 without)
  ``rotation_errors``           6   per hand: rotation vector (rad, world) turning it onto the
                                    nearer of its target and the target turned by pi about the
                                    approach axis (the same parallel grasp); 0 without a target
  ``grasp_centres``             6   per hand: grasp centre minus the object's position (m)
  ``hand_poses``                18  per hand: flange position (m) + 6D rotation
  ``commanded_poses``           18  per hand: commanded grasp centre (m) + 6D rotation (where
                                    the arm is told to be; the hand follows within ~1 mm)
  ``finger_openings``           2   distance between each hand's finger faces (m, 0-0.08)
  ``finger_contacts``           4   1 where finger i of hand k touches the object (h0f0, h0f1,
                                    h1f0, h1f1)
  ``object_position``           3   object frame origin (m)
  ``object_rotation``           6   object rotation, 6D
  ``object_linear_velocity``    3   m/s
  ``object_angular_velocity``   3   rad/s, world frame
  ``object_size``               3   bounding box side lengths, object frame (m)
  ``object_box_centre``         3   its centre, object frame (m)
  ``lift``                      1   centre-of-mass height above its resting height (m)
  ``target_poses``              18  target dual grasp at the object's pose: flange position (m)
                                    + 6D rotation per hand; 0 without a target
  ``target_flag``               1   1 with a target grasp, else 0
  ``previous_action``           14  the last action (0 after reset)
  ``elapsed``                   1   steps taken / ``episode_steps``
  ``hold``                      1   the current hold's length / ``hold_time`` (0-1)
  ============================  ==  ============================================================

  A 6D rotation is ``[R[:, 0], R[:, 1]]``. Values are clipped to the space's bounds.
* ``"state_dict"``: a ``Dict`` space of the same parts, one ``Box`` each.
* ``"pointcloud"``: ``Dict(state, points, normals, mask)``: the ``"state"`` vector, and a
  fixed-size cloud of ``n_points`` points of the object (world frame, m), their outward normals
  and a mask (1 = a point, 0 = padding): what ``n_cameras`` seeded depth cameras (those of
  ``DualGraspPose-v0``, :mod:`dg16m_env.physics.cameras`, drawn with the env's generator at
  reset) saw of the object, carried with the object's pose as it moves (an object tracker).

Arguments
---------
v0's (``benchmark``, ``object_ids``, ``mesh_root``, ``lift_height``, ``hold_time``,
``render_mode``, ``width``, ``height``), and:

* ``target_grasp``: ``"benchmark"`` (default) or ``None`` (v0's default was ``None``).
* ``reward_mode``: ``"dense"`` (default), ``"normalized_dense"`` or ``"sparse"``.
* ``obs_mode``: ``"state"`` (default), ``"state_dict"`` or ``"pointcloud"``.
* ``n_points`` (512), ``n_cameras`` (1 or 2), ``camera_resolution`` (128 pixels): the
  ``"pointcloud"`` mode's cloud.

* ``episode_steps``: ``T``, the steps after which the env truncates the episode itself
  (:data:`EPISODE_STEPS` = 200 = 10 s at 20 Hz, the registered ``max_episode_steps``). It sets
  the reward bound and the ``elapsed`` fraction; for a longer episode give
  ``gym.make(..., episode_steps=N, max_episode_steps=N)`` (Gymnasium's ``TimeLimit`` wrapper
  would cut it at 200, and the env cannot see that wrapper). A shorter ``max_episode_steps``
  alone keeps ``T`` = 200: a success still pays at least what the steps left could.

Info
----
v0's keys, plus ``fail`` (the episode ended in failure on this step: ``termination`` is
``"off_table"``, ``"out_of_bounds"`` or ``"unstable"``) and ``elapsed_steps``; at reset
``fail`` is False and ``elapsed_steps`` 0.

Version history
---------------
* v2 (2026-12-05): v1's task on 5 ms physics steps with compiled step arithmetic, about three
  times the steps per second (:mod:`dg16m_env.envs.dual_grasp_lift_v2`).
* v1 (2026-12-05): reward and observation modes, success-dominant rewards, ``fail``, step
  after the end refused, state save and restore, a target grasp by default, 1024-pixel shadow
  maps when rendering.
* v0: see :mod:`dg16m_env.envs.dual_grasp_lift` (unchanged, still registered).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np

from dataset_gen.checks import check_integer
from dg16m_env.benchmark.ref import BenchmarkRef
from dg16m_env.envs.dual_grasp_lift import DualGraspLiftEnv
from dg16m_env.envs.lift_observations import (
    OBS_MODES,
    POINTCLOUD_SIZE,
    STATE_HIGH,
    STATE_LAYOUT,
    STATE_LOW,
    STATE_SLICES,
    observation_space,
    rotation_errors,
)
from dg16m_env.envs.lift_reward import REWARD_MODES, dense_terms, mode_terms
from dg16m_env.envs.lift_spaces import ACTION_SIZE
from dg16m_env.envs.spaces import rotation_to_6d

EPISODE_STEPS = 200
"""``T`` by default (``episode_steps``; the registered ``max_episode_steps``)."""

FAILURES = ("off_table", "out_of_bounds", "unstable")
"""The terminations that are failures (``info["fail"]``)."""

STATE_VERSION = 1
"""Version of the :meth:`DualGraspLiftV1Env.get_state` dictionary."""

_STATE_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION
_STATE_KEYS = (
    "version",
    "object_id",
    "physics",
    "commanded_centres",
    "commanded_rotations",
    "commanded_quaternions",
    "target_grasp",
    "target_row",
    "rest_height",
    "hold_anchor",
    "hold_count",
    "elapsed_steps",
    "episode_steps",
    "previous_action",
    "ended",
    "cloud",
)


class DualGraspLiftV1Env(DualGraspLiftEnv):
    """Two floating Panda hands lift a benchmark object (v1: reward and observation modes,
    success-dominant rewards, state save and restore; see the module docstring)."""

    render_shadow_size = 1024
    """Side of the lights' shadow maps when rendering (pixels; v0: the model's 4096)."""

    def __init__(
        self,
        benchmark: str | os.PathLike[str] | BenchmarkRef | None = None,
        object_ids: Sequence[str] | None = None,
        mesh_root: str | os.PathLike[str] | None = None,
        target_grasp: str | None = "benchmark",
        reward_mode: str = "dense",
        obs_mode: str = "state",
        lift_height: float = 0.10,
        hold_time: float = 1.0,
        n_points: int = POINTCLOUD_SIZE,
        n_cameras: int = 1,
        camera_resolution: int = 128,
        episode_steps: int = EPISODE_STEPS,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 360,
    ) -> None:
        if reward_mode not in REWARD_MODES:
            raise ValueError(f"reward_mode: expected one of {REWARD_MODES}, found {reward_mode!r}")
        if obs_mode not in OBS_MODES:
            raise ValueError(f"obs_mode: expected one of {OBS_MODES}, found {obs_mode!r}")
        self.n_points = check_integer("n_points", n_points, minimum=1, error=ValueError)
        self.n_cameras = check_integer("n_cameras", n_cameras, minimum=1, error=ValueError)
        if self.n_cameras > 2:
            raise ValueError(f"n_cameras: expected 1 or 2, found {n_cameras}")
        self.episode_steps = check_integer(
            "episode_steps", episode_steps, minimum=1, error=ValueError
        )
        self.camera_resolution = check_integer(
            "camera_resolution", camera_resolution, minimum=16, error=ValueError
        )
        super().__init__(
            benchmark=benchmark,
            object_ids=object_ids,
            mesh_root=mesh_root,
            target_grasp=target_grasp,
            lift_height=lift_height,
            hold_time=hold_time,
            render_mode=render_mode,
            width=width,
            height=height,
        )
        self.reward_mode = reward_mode
        self.obs_mode = obs_mode
        self.observation_space = observation_space(obs_mode, self.n_points)
        self._cameras: Any = None
        self._new_episode()

    def _new_episode(self) -> None:
        self._elapsed = 0
        self._ended = ""
        self._previous_action = np.zeros(ACTION_SIZE)
        self._cloud: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # object frame

    # ----------------------------------------------------------------------------------------
    # Gymnasium API
    # ----------------------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        self._new_episode()
        self._steps_total = self.episode_steps
        _, info = super().reset(seed=seed, options=options)
        assert self._current is not None  # observe the settled state itself (module docstring)
        mujoco.mj_forward(self._current.scene.model, self._current.data)
        info["fail"] = False
        info["elapsed_steps"] = 0
        return self._observation(), info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        if self._current is not None and self._ended:
            raise RuntimeError(
                f"step: expected reset() after the episode ended ({self._ended}), found another "
                "step()"
            )
        return super().step(action)

    def _transition(
        self, values: np.ndarray, unstable: bool
    ) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        assert self._current is not None
        if not unstable:  # observe the state the step ended in (module docstring)
            mujoco.mj_forward(self._current.scene.model, self._current.data)
        self._elapsed += 1
        m = self._measure(unstable)
        dense = dense_terms(
            reach_distance=m.reach_distance,
            jaw_angle=m.jaw_angle,
            hands_grasping=int(m.grasping.sum()),
            both_grasping=bool(m.grasping.all()),
            lift=m.lift,
            lift_height=self.lift_height,
            holding=m.holding,
            success=m.success,
            steps_left=self._steps_total - self._elapsed,
            unstable=unstable,
        )
        if m.termination in FAILURES:
            dense = dict.fromkeys(dense, 0.0)
        terms = mode_terms(self.reward_mode, dense, m.success)
        reward = float(sum(terms.values()))
        self._previous_action = values.copy()
        terminated = m.termination != ""
        truncated = not terminated and self._elapsed >= self._steps_total
        if terminated:
            self._ended = f"terminated by {m.termination!r} at step {self._elapsed}"
        elif truncated:
            self._ended = f"truncated at step {self._elapsed} of {self._steps_total}"
        info = self._step_info(m, terms)
        info["fail"] = m.termination in FAILURES
        info["elapsed_steps"] = self._elapsed
        return self._observation(), reward, terminated, truncated, info

    # ----------------------------------------------------------------------------------------
    # Observation
    # ----------------------------------------------------------------------------------------

    def state_parts(self) -> dict[str, np.ndarray]:
        """The named parts of the ``"state"`` observation (float64, unclipped; module
        docstring, *Observation modes*)."""
        assert self._current is not None
        scene, data = self._current.scene, self._current.data
        body = scene.object_body
        obj_pos, obj_rot = data.xpos[body], data.xmat[body].reshape(3, 3)
        velocity = data.qvel[scene.object_qvel]
        hands = data.xmat[scene.hand_bodies].reshape(2, 3, 3)
        hand_pos = data.xpos[scene.hand_bodies]
        depth = scene.gripper.contact_depth
        centres = hand_pos + depth * hands[:, :, 1]
        parts = {name: np.zeros(size) for name, size, _, _ in STATE_LAYOUT}
        if self._grasp is not None:
            goal = self._target_world(obj_pos, obj_rot)
            goal_centres = goal[:, :3, 3] + depth * goal[:, :3, 1]
            parts["centre_errors"] = (centres - goal_centres).ravel()
            parts["rotation_errors"] = rotation_errors(hands, goal[:, :3, :3]).ravel()
            parts["target_poses"] = np.concatenate(
                [goal[:, :3, 3], rotation_to_6d(goal[:, :3, :3])], axis=1
            ).ravel()
            parts["target_flag"][0] = 1.0
        parts["grasp_centres"] = (centres - obj_pos).ravel()
        parts["hand_poses"] = np.concatenate([hand_pos, rotation_to_6d(hands)], axis=1).ravel()
        parts["commanded_poses"] = np.concatenate(
            [self._target_pos, rotation_to_6d(self._target_rot)], axis=1
        ).ravel()
        travel = data.qpos[scene.finger_qpos].sum(axis=1)
        parts["finger_openings"] = scene.gripper.max_opening - travel
        parts["finger_contacts"] = (data.sensordata[scene.finger_contacts] > 0).ravel() * 1.0
        parts["object_position"] = obj_pos.copy()
        parts["object_rotation"] = rotation_to_6d(obj_rot)
        parts["object_linear_velocity"] = velocity[:3].copy()
        parts["object_angular_velocity"] = obj_rot @ velocity[3:]
        parts["object_size"] = self._current.box_high - self._current.box_low
        parts["object_box_centre"] = 0.5 * (self._current.box_high + self._current.box_low)
        parts["lift"][0] = data.xipos[body, 2] - self._rest_com_z
        parts["previous_action"] = self._previous_action.copy()
        parts["elapsed"][0] = min(self._elapsed / self._steps_total, 1.0)
        parts["hold"][0] = min(self._hold_count / max(self.hold_steps, 1), 1.0)
        return parts

    def _state_values(self) -> np.ndarray:
        """The flat state (float64, unclipped; :data:`~dg16m_env.envs.lift_observations.STATE_LAYOUT`)."""
        parts = self.state_parts()
        return np.concatenate([parts[name] for name, _, _, _ in STATE_LAYOUT])

    def _observation(self) -> Any:
        state = np.clip(self._state_values().astype(np.float32), STATE_LOW, STATE_HIGH)
        if self.obs_mode == "state":
            return state
        if self.obs_mode == "state_dict":
            return {name: state[STATE_SLICES[name]] for name, _, _, _ in STATE_LAYOUT}
        points, normals, mask = self._object_cloud()
        assert self._current is not None
        data, body = self._current.data, self._current.scene.object_body
        rot, pos = data.xmat[body].reshape(3, 3), data.xpos[body]
        world = (points @ rot.T + pos) * mask[:, None]
        return {
            "state": state,
            "points": np.clip(world, -5.0, 5.0).astype(np.float32),
            "normals": (normals @ rot.T).astype(np.float32),
            "mask": mask.astype(np.float32),
        }

    def _object_cloud(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The episode's object-frame cloud, taken at reset with the env's generator."""
        if self._cloud is None:
            from dg16m_env.physics.cameras import DepthCameras

            assert self.object_id is not None
            if self._cameras is None:
                self._cameras = DepthCameras(self.camera_resolution)
            scene = self.objects.scene(self.object_id)
            points, normals, mask, _ = self._cameras.observe(
                scene, self.np_random, self.n_points, self.n_cameras
            )
            self._cloud = (points.astype(np.float64), normals.astype(np.float64), mask)
        return self._cloud

    # ----------------------------------------------------------------------------------------
    # State save and restore
    # ----------------------------------------------------------------------------------------

    def get_state(self) -> dict[str, Any]:
        """Everything the next steps depend on, as plain values (numpy arrays, numbers, str):
        MuJoCo's integration state (``mjSTATE_INTEGRATION``: positions, velocities, controls,
        mocap targets, warm start, time), the commanded hand poses, the target grasp, the hold,
        the step count and the previous action. :meth:`set_state` restores it exactly on the
        same machine and build (the same later steps, bit for bit)."""
        if self._current is None:
            raise RuntimeError("get_state: expected reset() before get_state(), found no episode")
        model, data = self._current.scene.model, self._current.data
        physics = np.empty(mujoco.mj_stateSize(model, _STATE_SPEC))
        mujoco.mj_getState(model, data, physics, _STATE_SPEC)
        return {
            "version": STATE_VERSION,
            "object_id": self.object_id,
            "physics": physics,
            "commanded_centres": self._target_pos.copy(),
            "commanded_rotations": self._target_rot.copy(),
            "commanded_quaternions": self._target_quat.copy(),
            "target_grasp": None if self._grasp is None else self._grasp.copy(),
            "target_row": int(self._target_row),
            "rest_height": float(self._rest_com_z),
            "hold_anchor": None if self._hold_anchor is None else self._hold_anchor.copy(),
            "hold_count": int(self._hold_count),
            "elapsed_steps": int(self._elapsed),
            "episode_steps": int(self._steps_total),
            "previous_action": self._previous_action.copy(),
            "ended": self._ended,
            "cloud": None if self._cloud is None else tuple(a.copy() for a in self._cloud),
        }

    @staticmethod
    def get_state_keys() -> tuple[str, ...]:
        """The keys of a :meth:`get_state` dictionary."""
        return _STATE_KEYS

    def set_state(self, state: dict[str, Any]) -> Any:
        """Restore a :meth:`get_state` dictionary; returns the observation at that state.

        Raises:
            ValueError: not such a dictionary (a missing key, another object, wrong shapes).
        """
        if not isinstance(state, dict) or state.get("version") != STATE_VERSION:
            found = state.get("version") if isinstance(state, dict) else type(state).__name__
            raise ValueError(
                f"state: expected a get_state() dictionary of version {STATE_VERSION}, found "
                f"{found!r}"
            )
        missing = sorted(set(self.get_state_keys()) - set(state))
        if missing:
            raise ValueError(
                f"state: expected the keys of a get_state() dictionary, found {missing} missing"
            )
        object_id = state.get("object_id")
        if object_id not in self.objects.ref.object_ids:
            raise ValueError(
                f"state['object_id']: expected an object of this env's benchmark, found "
                f"{object_id!r}"
            )
        item = self._object(object_id)
        model, data = item.scene.model, item.data
        physics = np.asarray(state["physics"], dtype=np.float64)
        size = mujoco.mj_stateSize(model, _STATE_SPEC)
        if physics.shape != (size,):
            raise ValueError(
                f"state['physics']: expected shape ({size},) for object {object_id!r}, found "
                f"{physics.shape}"
            )
        self._reset_state()
        self.object_id, self._current = object_id, item
        mujoco.mj_setState(model, data, physics, _STATE_SPEC)
        mujoco.mj_forward(model, data)
        self._target_pos = np.array(state["commanded_centres"], dtype=np.float64)
        self._target_rot = np.array(state["commanded_rotations"], dtype=np.float64)
        self._target_quat = np.array(state["commanded_quaternions"], dtype=np.float64)
        grasp = state["target_grasp"]
        self._grasp = None if grasp is None else np.array(grasp, dtype=np.float64)
        self._target_row = int(state["target_row"])
        self._rest_com_z = float(state["rest_height"])
        anchor = state["hold_anchor"]
        self._hold_anchor = None if anchor is None else np.array(anchor, dtype=np.float64)
        self._hold_count = int(state["hold_count"])
        self._elapsed = int(state["elapsed_steps"])
        self._steps_total = int(state["episode_steps"])
        self._previous_action = np.array(state["previous_action"], dtype=np.float64)
        self._ended = str(state["ended"])
        cloud = state["cloud"]
        self._cloud = None if cloud is None else tuple(np.array(a) for a in cloud)  # type: ignore[assignment]
        if self.render_mode == "rgb_array":
            self._camera = None
        return self._observation()

    def close(self) -> None:
        if self._cameras is not None:
            self._cameras.close()
            self._cameras = None
        super().close()
