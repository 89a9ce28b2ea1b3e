"""The Lift task: two floating Panda hands lift a benchmark object from a table, as one class,
:class:`LiftEnv`, whose registered versions differ only by the frozen record it reads at
construction (:class:`~dg16m_env.envs.lift.versions.LiftVersion`: physics step, reward, observation,
episode bookkeeping, arithmetic, success rule).

Each version's environment class is this class bound to its record (``DualGraspLiftEnv`` in
:mod:`.v0`, ``DualGraspLiftV1Env`` in :mod:`.v1`, ``DualGraspLiftV2Env`` in :mod:`.v2`,
``DualGraspLiftV3Env`` in :mod:`.v3`, which document the task: v0's docstring is the reference
for the physics, actions and randomisations; v2's and v3's each state the whole interface). Its signature is this class's,
less the arguments the version does not take (:attr:`~.versions.LiftVersion.arguments`), with
the version's default target grasp.

Physics (the MJCF model) is in :mod:`dg16m_env.physics.lift_scene`; the per-object data and
reset draws in :mod:`.scenes`; a step's arithmetic in :mod:`.arithmetic`; the hold and the
episode's end in :mod:`.measures`; the reward in :mod:`.reward`; spaces in :mod:`~dg16m_env.envs.lift.spaces` and
:mod:`.observations`; state save and restore in :mod:`.state`.
"""

from __future__ import annotations

import difflib
import functools
import inspect
import os
import sys
import warnings
from collections import OrderedDict
from collections.abc import Callable, Sequence
from typing import Any, ClassVar

import gymnasium
import mujoco
import numpy as np
from gymnasium import spaces

from dg16m_core.checks import check_integer, check_number
from dg16m_env.benchmark.ref import BenchmarkRef
from dg16m_env.envs.common import RENDER_MODES, RenderModes, check_render_mode
from dg16m_env.envs.lift import arithmetic, scenes
from dg16m_env.envs.lift import state as saved
from dg16m_env.envs.lift.measures import LiftStepMeasures
from dg16m_env.envs.lift.observations import (
    OBS_MODES,
    POINTCLOUD_SIZE,
    STATE_HIGH,
    STATE_LAYOUT,
    STATE_LOW,
    STATE_SIZE,
    STATE_SLICES,
    observation_space,
)
from dg16m_env.envs.lift.reward import REWARD_MODES, dense_terms, mode_terms, reward_terms
from dg16m_env.envs.lift.scenes import CONTROL_HZ, SETTLE_TIME, LiftObject, use_timestep
from dg16m_env.envs.lift.spaces import ACTION_SIZE, MOTION_COMPONENTS, OBS_LAYOUT, check_lift_action
from dg16m_env.envs.lift.targets import check_reset_options, parse_target_option
from dg16m_env.envs.lift.versions import V2, LiftVersion
from dg16m_env.envs.objects import CACHE_SIZE, BenchmarkObjects
from dg16m_env.physics.lift_scene import LiftScene, hand_points, step_hand_targets
from dg16m_env.physics.scene import quat_from_matrix, quat_to_matrix

EPISODE_STEPS = 200
"""``T`` by default (``episode_steps``; the registered ``max_episode_steps``)."""

FAILURES = ("off_table", "out_of_bounds", "unstable")
"""The terminations that are failures (``info["fail"]``)."""


def _caller_level() -> int:
    """The ``stacklevel`` (for a warning raised by the caller of this function) of the first
    frame outside this package and Gymnasium: the code that called ``gym.make`` or the
    constructor, so that Python's default filters show it the warning."""
    inner = (os.path.dirname(__file__), os.path.dirname(gymnasium.__file__))
    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_code.co_filename.startswith(inner):
        frame, level = frame.f_back, level + 1
    return level


def _argument_error(cls: type, version: LiftVersion, kwargs: dict[str, Any], exc: TypeError) -> str:
    """The message for arguments a version's class does not take: the class and the id it is
    (not the shared ``LiftEnv.__init__``), the keyword(s) it does not know with the nearest
    known one, and the keywords it takes."""
    where = f"{cls.__name__}(), dg16m_env/DualGraspLift-{version.name}"
    unknown = [name for name in kwargs if name not in version.arguments]
    if not unknown:
        return f"{where}: {exc}"
    hints = []
    for name in unknown:
        near = difflib.get_close_matches(name, version.arguments, n=1)
        hints.append(f"{name!r}" + (f" (did you mean {near[0]!r}?)" if near else ""))
    return (
        f"{where}: expected keyword arguments among {', '.join(version.arguments)}, found "
        f"{', '.join(hints)}"
    )


def _version_init(version: LiftVersion) -> Callable[..., None]:
    """The ``__init__`` of a version's class: :class:`LiftEnv`'s signature less the arguments
    ``version`` does not take, with its default target grasp (so ``inspect.signature``, the
    docs and a wrong keyword's ``TypeError`` show the version's own arguments)."""
    full = inspect.signature(LiftEnv.__init__)
    parameters = [
        p.replace(default=version.target_grasp) if p.name == "target_grasp" else p
        for p in full.parameters.values()
        if p.name == "self" or p.name in version.arguments
    ]
    signature = full.replace(parameters=parameters)

    @functools.wraps(LiftEnv.__init__)
    def __init__(self: LiftEnv, *args: Any, **kwargs: Any) -> None:  # noqa: N807
        try:
            bound = signature.bind(self, *args, **kwargs)
        except TypeError as exc:
            raise TypeError(_argument_error(type(self), version, kwargs, exc)) from None
        bound.apply_defaults()
        arguments = dict(bound.arguments)
        del arguments["self"]
        LiftEnv.__init__(self, **arguments)

    __init__.__signature__ = signature  # type: ignore[attr-defined]
    return __init__


class LiftEnv(RenderModes, gymnasium.Env[Any, np.ndarray]):
    """Two floating Panda hands lift a benchmark object from a table; the registered version
    :attr:`version` (v2 unless a subclass binds another; see the module docstring)."""

    METADATA: ClassVar[dict[str, Any]] = {
        "render_modes": list(RENDER_MODES),
        "render_fps": CONTROL_HZ,
    }

    version: ClassVar[LiftVersion] = V2
    """The registered version this class is (read at construction)."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "version" in cls.__dict__ and "__init__" not in cls.__dict__:
            cls.__init__ = _version_init(cls.version)  # type: ignore[method-assign]

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
        version = self.version
        if version.deprecation:
            warnings.warn(version.deprecation, DeprecationWarning, stacklevel=_caller_level())
        if version.observation == "modes":
            self._check_modes(reward_mode, obs_mode, n_points, n_cameras, camera_resolution)
        self.episode_steps = check_integer(
            "episode_steps", episode_steps, minimum=1, error=ValueError
        )
        if target_grasp not in (None, "benchmark"):
            raise ValueError(f"target_grasp: expected None or 'benchmark', found {target_grasp!r}")
        check_render_mode(render_mode)
        from dg16m_env.physics.replay import ReplayError, check_size

        try:
            self.width, self.height = check_size(width, height)
        except ReplayError as exc:
            raise ValueError(str(exc)) from None
        self.lift_height = check_number("lift_height", lift_height, error=ValueError)
        self.hold_time = check_number("hold_time", hold_time, allow_zero=True, error=ValueError)
        self.target_mode = target_grasp
        self.render_mode = render_mode
        self.render_shadow_size = version.render_shadow_size
        self.objects = BenchmarkObjects(benchmark, object_ids, mesh_root)
        parameters = self.objects.parameters
        self.scene_parameters = parameters.scene
        self.gravity = float(parameters.protocol.gravity)
        self.max_slip = float(parameters.protocol.max_displacement)
        use_timestep(self, version.physics_timestep or float(parameters.scene.timestep))
        self._hand_points = hand_points()
        self._clip_points: tuple[float, np.ndarray] | None = None  # depth, hand points - depth y
        self._bench = self.objects.ref.benchmark
        self._p_full = self._bench.p("full")

        self.observation_space: spaces.Space[Any]
        if version.observation == "modes":
            self.observation_space = observation_space(
                self.obs_mode, self.n_points, version.flat_cloud
            )
        else:
            low = np.concatenate([np.full(size, lo) for _, size, lo, _ in OBS_LAYOUT])
            high = np.concatenate([np.full(size, hi) for _, size, _, hi in OBS_LAYOUT])
            self.observation_space = spaces.Box(low.astype(np.float32), high.astype(np.float32))
            self._obs_low, self._obs_high = self.observation_space.low, self.observation_space.high
        self.action_space = spaces.Box(-1.0, 1.0, (ACTION_SIZE,), dtype=np.float32)

        self._cache: OrderedDict[str, LiftObject] = OrderedDict()
        self._current: LiftObject | None = None
        self._renderer: Any = None
        self._renderer_model: mujoco.MjModel | None = None
        self._camera: mujoco.MjvCamera | None = None
        self._cameras: Any = None
        self._reset_state()
        self._new_episode()
        self._targets = np.empty((self.substeps, 14))  # compiled_hand_targets' rows
        self._state = np.zeros(STATE_SIZE)  # the last arithmetic.observe() (float64, unclipped)
        self._state_fresh = False  # the step's observe() is the state the step ended in
        self._centres = np.zeros((2, 3))

    def _check_modes(
        self, reward_mode: str, obs_mode: str, n_points: int, n_cameras: int, resolution: int
    ) -> None:
        """Check and keep v1's arguments (reward and observation modes, the point cloud's)."""
        if reward_mode not in REWARD_MODES:
            raise ValueError(f"reward_mode: expected one of {REWARD_MODES}, found {reward_mode!r}")
        if obs_mode not in OBS_MODES:
            raise ValueError(f"obs_mode: expected one of {OBS_MODES}, found {obs_mode!r}")
        self.n_points = check_integer("n_points", n_points, minimum=1, error=ValueError)
        self.n_cameras = check_integer("n_cameras", n_cameras, minimum=1, error=ValueError)
        if self.n_cameras > 2:
            raise ValueError(f"n_cameras: expected 1 or 2, found {n_cameras}")
        self.camera_resolution = check_integer(
            "camera_resolution", resolution, minimum=16, error=ValueError
        )
        self.reward_mode, self.obs_mode = reward_mode, obs_mode

    # ----------------------------------------------------------------------------------------
    # State
    # ----------------------------------------------------------------------------------------

    def _reset_state(self) -> None:
        self.object_id: str | None = None
        self._target_pos = np.zeros((2, 3))  # commanded grasp centres (world, m)
        self._target_rot = np.tile(np.eye(3), (2, 1, 1))  # commanded hand rotations
        self._target_quat = np.tile([1.0, 0.0, 0.0, 0.0], (2, 1))
        self._grasp: np.ndarray | None = None  # (2, 4, 4) target grasp, object frame
        self._target_row = -1
        self._rest_com_z = 0.0
        self._hold_anchor: np.ndarray | None = None  # (2, 3) object-frame anchors of the hold
        self._hold_count = 0
        self._done = False

    def _new_episode(self) -> None:
        """v1's episode bookkeeping: steps taken, why it ended, the last action, the cloud."""
        self._elapsed = 0
        self._steps_total = self.episode_steps
        self._ended = ""
        self._previous_action = np.zeros(ACTION_SIZE)
        self._cloud: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # object frame

    def _object(self, object_id: str) -> LiftObject:
        if object_id in self._cache:
            self._cache.move_to_end(object_id)
            return self._cache[object_id]
        item = scenes.load_lift_object(
            self.objects, object_id, self.scene_parameters, self.gravity, self._p_full
        )
        self._cache[object_id] = item
        while len(self._cache) > CACHE_SIZE:
            self._cache.popitem(last=False)
        return item

    # ----------------------------------------------------------------------------------------
    # Gymnasium API
    # ----------------------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        self._new_episode()
        opts = check_reset_options(options)
        requested = opts.get("object_id")
        if requested is not None and not isinstance(requested, str):
            raise ValueError(f"options['object_id']: expected a string, found {requested!r}")
        target = opts.get("target_grasp", self.target_mode)
        kind, requested = parse_target_option(target, requested, self._bench)
        self._reset_state()
        object_id, item, pose_index, grasp, row, above = scenes.choose_target(
            kind,
            requested,
            objects=self.objects,
            rng=self.np_random,
            load=self._object,
            hand_points=self._hand_points,
        )
        self.object_id, self._current = object_id, item
        scene, data = item.scene, item.data
        centre_of_mass = self.objects.load(object_id).mass_properties.center_of_mass
        rest, centres, rotations = scenes.draw_placement(
            item, pose_index, centre_of_mass, self.np_random
        )
        self._set_command(centres, rotations)
        if grasp is not None:  # list the target's hands so hand k goes to the nearer one
            grasp = scenes.order_target(grasp, rest, scene.gripper.contact_depth, self._target_pos)
        self._grasp, self._target_row = grasp, row

        mujoco.mj_resetData(scene.model, data)
        data.qpos[scene.object_qpos] = np.concatenate([rest[:3, 3], quat_from_matrix(rest[:3, :3])])
        self._place_hands(data, scene)
        data.ctrl[scene.squeeze_actuators] = -scene.params.squeeze_force  # open
        mujoco.mj_forward(scene.model, data)
        mujoco.mj_step(scene.model, data, nstep=max(1, round(SETTLE_TIME / self.timestep)))
        data.time = 0.0
        self._rest_com_z = float(data.xipos[scene.object_body, 2])
        info = {
            "object_id": object_id,
            "stable_pose": pose_index,
            "target_row": row,
            "target_above_table": bool(above),
            "rest_height": self._rest_com_z,
            "settle_speed": float(np.linalg.norm(data.qvel[scene.object_qvel][:3])),
            "hands_clear": bool(np.all(data.sensordata[scene.hand_contacts] == 0)),
            "success": False,
            "is_success": False,
        }
        if self.render_mode == "rgb_array":
            self._camera = None  # re-aim at the new object
        if self.version.observe_settled:  # observe the settled state itself (v1's docstring)
            mujoco.mj_forward(scene.model, data)
        if self.version.episode_bookkeeping:
            info["fail"] = False
            info["elapsed_steps"] = 0
        return self._observation(), info

    def _set_command(self, centres: np.ndarray, rotations: np.ndarray) -> None:
        self._target_quat = quat_from_matrix(rotations)
        self._target_rot = quat_to_matrix(self._target_quat)
        self._target_pos = arithmetic.clip_command(
            self, np.asarray(centres, np.float64), self._target_rot
        )

    def _place_hands(self, data: mujoco.MjData, scene: LiftScene) -> None:
        """Targets and hands at the commanded poses, at rest, fingers open."""
        depth = scene.gripper.contact_depth
        flanges = self._target_pos - depth * self._target_rot[..., :, 1]
        data.mocap_pos[scene.target_mocap] = flanges
        data.mocap_quat[scene.target_mocap] = self._target_quat
        for k in range(2):
            address = scene.hand_qpos[k]
            data.qpos[address : address + 3] = flanges[k]
            data.qpos[address + 3 : address + 7] = self._target_quat[k]

    def _check_action(self, action: Any) -> np.ndarray:
        return check_lift_action(action, self.action_space)

    def _clip_local_points(self) -> np.ndarray:
        """(m, 3) the hand points relative to the grasp centre, hand frame (``p - depth * y``):
        the lowest hand point of rotation ``R`` is the least ``R[2] @`` of them."""
        assert self._current is not None
        depth = self._current.scene.gripper.contact_depth
        if self._clip_points is None or self._clip_points[0] != depth:
            self._clip_points = (depth, self._hand_points - np.array([0.0, depth, 0.0]))
        return self._clip_points[1]

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        if self._current is None:
            raise RuntimeError("step: expected reset() before step(), found no episode")
        if self._ended:
            raise RuntimeError(
                f"step: expected reset() after the episode ended ({self._ended}), found another "
                "step()"
            )
        values = self._check_action(action)
        scene, data = self._current.scene, self._current.data
        targets, centres, rotations, final = self._hand_targets(values)
        data.ctrl[scene.squeeze_actuators] = values[6::7] * scene.params.squeeze_force
        unstable = step_hand_targets(scene.model, data, targets)
        self._target_pos, self._target_rot, self._target_quat = centres, rotations, final
        if self.version.episode_bookkeeping:
            return self._transition(values, unstable)
        return self._transition_v0(values, unstable)

    def _hand_targets(
        self, values: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One control step's hand targets (:func:`.arithmetic.hand_targets`, or its compiled
        form for a version with compiled arithmetic)."""
        if self.version.compiled_arithmetic:
            return arithmetic.compiled_hand_targets(self, values)
        return arithmetic.hand_targets(self, values)

    def _measure(self, unstable: bool) -> LiftStepMeasures:
        """What the step did (:func:`.arithmetic.measure`, or its compiled form)."""
        if self.version.compiled_arithmetic:
            return arithmetic.compiled_measure(self, unstable)
        return arithmetic.measure(self, unstable)

    def _step_info(self, m: LiftStepMeasures, terms: dict[str, float]) -> dict[str, Any]:
        return {
            "object_id": self.object_id,
            "success": m.success,
            "is_success": m.success,
            "termination": m.termination,
            "reward_terms": terms,
            "lift": m.lift,
            "hold_time": self._hold_count * self.control_dt if m.holding else 0.0,
            "slip": m.slip,
            "grasping": m.grasping.copy(),
            "target_row": self._target_row,
        }

    def _transition_v0(
        self, values: np.ndarray, unstable: bool
    ) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """v0's end of a step: its weighted reward terms, no episode bookkeeping."""
        m = self._measure(unstable)
        terms = reward_terms(  # v0's docstring, :mod:`dg16m_env.envs.lift.reward`
            m,
            lift_height=self.lift_height,
            failure=m.termination not in ("", "success"),
            motion=values[MOTION_COMPONENTS],
        )
        reward = float(sum(terms.values()))
        return self._observation(), reward, m.termination != "", False, self._step_info(m, terms)

    def _transition(
        self, values: np.ndarray, unstable: bool
    ) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """v1's end of a step: the state it ended in, the reward mode, the episode's end."""
        assert self._current is not None
        if not unstable and self.version.observe_settled:  # the state the step ended in
            mujoco.mj_forward(self._current.scene.model, self._current.data)
        self._elapsed += 1
        m = self._measure(unstable)
        dense = dense_terms(
            m, lift_height=self.lift_height, steps_left=self._steps_total - self._elapsed
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

    def _needs_modes(self, name: str) -> None:
        if self.version.observation != "modes":
            raise AttributeError(
                f"{name}: expected DualGraspLift-v1 or later, found {self.version.name}"
            )

    def state_parts(self) -> dict[str, np.ndarray]:
        """The named parts of the ``"state"`` observation (float64, unclipped; v1's docstring,
        *Observation modes*)."""
        self._needs_modes("state_parts")
        if not self.version.compiled_arithmetic:
            return arithmetic.state_parts(self)
        self._state_fresh = False  # a caller between steps sees the current state
        state = self._state_values()
        return {name: state[STATE_SLICES[name]].copy() for name, _, _, _ in STATE_LAYOUT}

    def _state_values(self) -> np.ndarray:
        """The flat state (float64, unclipped; :data:`~.observations.STATE_LAYOUT`)."""
        if self.version.compiled_arithmetic:
            return arithmetic.compiled_state_values(self)
        parts = arithmetic.state_parts(self)
        return np.concatenate([parts[name] for name, _, _, _ in STATE_LAYOUT])

    def _observation(self) -> Any:
        if self.version.observation == "vector":
            return arithmetic.vector_observation(self)
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
        cloud = {
            "state": state,
            "points": np.clip(world, -5.0, 5.0).astype(np.float32),
            "normals": (normals @ rot.T).astype(np.float32),
            "mask": mask.astype(np.float32),
        }
        if self.version.flat_cloud:  # (3 n,) vectors, the same numbers row by row
            cloud["points"] = cloud["points"].reshape(-1)
            cloud["normals"] = cloud["normals"].reshape(-1)
        return cloud

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
    # State save and restore (v1 and later)
    # ----------------------------------------------------------------------------------------

    def get_state(self) -> dict[str, Any]:
        """Everything the next steps depend on, as plain values (numpy arrays, numbers, str):
        MuJoCo's integration state (``mjSTATE_INTEGRATION``: positions, velocities, controls,
        mocap targets, warm start, time), the commanded hand poses, the target grasp, the hold,
        the step count and the previous action. :meth:`set_state` restores it exactly on the
        same machine and build (the same later steps, bit for bit)."""
        self._needs_modes("get_state")
        return saved.get_state(self)

    @staticmethod
    def get_state_keys() -> tuple[str, ...]:
        """The keys of a :meth:`get_state` dictionary."""
        return saved.STATE_KEYS

    def set_state(self, state: dict[str, Any]) -> Any:
        """Restore a :meth:`get_state` dictionary; returns the observation at that state.

        Raises:
            ValueError: not such a dictionary (a missing key, another object, wrong shapes).
        """
        self._needs_modes("set_state")
        saved.set_state(self, state)
        return self._observation()

    # ----------------------------------------------------------------------------------------
    # Rendering
    # ----------------------------------------------------------------------------------------

    def render(self) -> np.ndarray | None:
        """An (height, width, 3) uint8 image of table, object and hands (``"rgb_array"``), or
        None when the environment has no render mode."""
        if self.render_mode is None:
            gymnasium.logger.warn(
                "render: expected render_mode='rgb_array' at construction, found None"
            )
            return None
        if self._current is None:
            raise RuntimeError("render: expected reset() before render(), found no episode")
        from dg16m_env.physics.replay import make_renderer

        scene, data = self._current.scene, self._current.data
        if self._renderer is None or self._renderer_model is not scene.model:
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = make_renderer(
                scene.model, self.height, self.width, self.render_shadow_size
            )
            self._renderer_model = scene.model
            self._camera = None
        if self._camera is None:
            camera = mujoco.MjvCamera()
            camera.type = mujoco.mjtCamera.mjCAMERA_FREE
            size = float(np.linalg.norm(self._current.box_high - self._current.box_low))
            camera.lookat[:] = (
                data.xipos[scene.object_body, 0],
                data.xipos[scene.object_body, 1],
                self._rest_com_z + 0.5 * self.lift_height,
            )
            camera.distance = 1.3 * size + 0.6
            camera.azimuth, camera.elevation = 135.0, -25.0
            self._camera = camera
        self._renderer.update_scene(data, camera=self._camera)
        return np.array(self._renderer.render(), dtype=np.uint8, copy=True)

    def close(self) -> None:
        if self._cameras is not None:
            self._cameras.close()
            self._cameras = None
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
            self._renderer_model = None
        super().close()
