"""What the one-step grasp environments share (``DualGraspPose-v0``, ``DualGraspSelect-v0``).

:class:`OneStepGraspEnv` is their base: it draws a benchmark object on ``reset``, builds the
observation (the object's point cloud, or what seeded depth cameras see of it), checks actions,
runs ONE trial of the benchmark's protocol per episode (:func:`simulate_once`), assembles the
``info`` dict (:func:`trial_info`) and renders the scene offscreen (:class:`SceneRenderer`).
A subclass only says what its action means (:meth:`OneStepGraspEnv._act`) and what it adds to the
observation.

Observation layout
------------------
Every entry is a flat float32 vector (stable-baselines3 warns about any other Box shape, and the
environments pass its ``check_env`` with warnings as errors); :func:`structured_observation`
gives the arrays their natural shapes (a copy-free reshape):

======================  ===========  =========  ===============================================
key                     flat shape   shaped     meaning
======================  ===========  =========  ===============================================
``points``              (3 P,)       (P, 3)     surface points, object frame (m)
``normals``             (3 P,)       (P, 3)     unit outward normals at ``points``
``bounds``              (6,)         (2, 3)     the object's box: min corner, max corner (m)
``mask``                (P,)         (P,)       partial mode only: 1 = real point, 0 = padding
``candidates``          (18 K,)      (K, 2, 9)  Select only: pose encodings (:mod:`~dg16m_env.envs.spaces`)
``candidate_contacts``  (24 K,)      (K, 4, 6)  Select only: contact points (m), outward normals
``candidate_mask``      (K,)         (K,)       Select only: 1 = a candidate, 0 = an empty slot
======================  ===========  =========  ===============================================

Coordinates lie within ``±OBSERVATION_LIMIT`` m (an object beyond it is refused on reset).

Vector environments
-------------------
A one-step episode ends at every step. With Gymnasium's default ``NEXT_STEP`` autoreset a vector
environment would spend every other ``step`` call on resetting the finished sub-environments
(reward 0, the action ignored). ``gym.make_vec`` takes the vector environment's arguments from
the registered spec's ``kwargs["vector_kwargs"]`` (it pops them before making each
sub-environment), so the ids register with ``kwargs={"vector_kwargs": VECTOR_KWARGS}``
(``autoreset_mode`` ``SAME_STEP``): every vector step is a real trial, the reset comes in the
same call and the last observation and info are in ``infos["final_obs"]`` /
``infos["final_info"]``. A spec's ``vector_kwargs`` win over ``make_vec``'s own argument; for
another mode build ``gymnasium.vector.SyncVectorEnv`` / ``AsyncVectorEnv`` directly. The
constructors accept ``vector_kwargs`` (what ``gym.make`` passes on from the spec) and ignore it;
``metadata["autoreset_mode"]`` names the intended mode.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode

from dataset_gen.objects.grasp_object import GraspObject
from dg16m_core.checks import check_integer
from dg16m_core.errors import Dg16mError
from dg16m_env.benchmark.ref import BenchmarkRef
from dg16m_env.evaluators.fce import REASONS, fce_verdicts
from dg16m_env.physics.cameras import CameraPose, DepthCameras, RendererSlot, offscreen_renderer
from dg16m_env.physics.labels import GRAVITY_PHASE, LEVELS, PerturbationSpec, perturb_poses
from dg16m_env.physics.replay import DISTANCE_FACTOR, check_size, default_camera
from dg16m_env.physics.replay import render_model as restyled_model
from dg16m_env.physics.scene import Scene, quat_from_matrix
from dg16m_env.physics.trial import run_trials
from dg16m_env.physics.trial_measures import grasp_centres
from dg16m_env.physics.trial_protocol import (
    STATE_SPEC,
    InvalidReason,
    TrialProtocol,
    TrialResults,
    TrialStatus,
    initial_state,
)

from .objects import BenchmarkObjects
from .spaces import POSE_SIZE

DEFAULT_POINTS = 1024
"""Points in an observation's cloud unless asked otherwise."""

OBSERVATION_LIMIT = 10.0
"""Largest absolute coordinate (m) of an observation's points, box and candidate positions."""

OBS_MODES = ("full", "partial")
"""``"full"``: points drawn on the whole surface; ``"partial"``: what depth cameras see."""

MAX_CAMERAS = 2
"""Most depth cameras of the partial observation."""

MAX_CAMERA_RESOLUTION = 960
"""Largest depth image side (pixels; the scene's offscreen buffer is 1280 x 960)."""

RENDER_FPS = 4
"""Frames per second of ``render_mode="rgb_array"`` videos (one frame per episode's action)."""

HAND_CLEARANCE = 0.12
"""Before a step, :meth:`OneStepGraspEnv.render` shows open hands this far (m) beyond the
object's bounding sphere, facing it."""

VECTOR_KWARGS: dict[str, Any] = {"autoreset_mode": AutoresetMode.SAME_STEP.value}
"""What the one-step ids register as ``kwargs["vector_kwargs"]`` (see the module docstring)."""

STATUS_NOT_RUN = "not_run"
"""``info["status"]`` when no trial ran (degenerate rotation, empty slot)."""

STATUS_LABEL = "label"
"""``info["status"]`` when the reward was drawn from the stored label (Select, label mode)."""


class EnvArgumentError(Dg16mError, ValueError):
    """A bad environment argument, reset option or action."""


# --------------------------------------------------------------------------------------------
# Spaces and observations
# --------------------------------------------------------------------------------------------


def _box(low: np.ndarray | float, high: np.ndarray | float, size: int) -> spaces.Box:
    return spaces.Box(
        low=np.broadcast_to(np.float32(low), (size,)).copy(),
        high=np.broadcast_to(np.float32(high), (size,)).copy(),
        dtype=np.float32,
    )


def cloud_spaces(n_points: int, partial: bool) -> dict[str, spaces.Box]:
    """The point-cloud entries of the observation space (see the module docstring)."""
    out = {
        "points": _box(-OBSERVATION_LIMIT, OBSERVATION_LIMIT, 3 * n_points),
        "normals": _box(-1.0, 1.0, 3 * n_points),
        "bounds": _box(-OBSERVATION_LIMIT, OBSERVATION_LIMIT, 6),
    }
    if partial:
        out["mask"] = _box(0.0, 1.0, n_points)
    return out


def candidate_spaces(n_candidates: int) -> dict[str, spaces.Box]:
    """The candidate entries of the Select observation space (see the module docstring)."""
    rotation = np.ones(POSE_SIZE - 3)
    pose_high = np.concatenate([np.full(3, OBSERVATION_LIMIT), rotation])  # p, a, b
    contact_high = np.concatenate([np.full(3, OBSERVATION_LIMIT), np.ones(3)])  # point, normal
    pose_high = np.tile(pose_high, 2 * n_candidates)
    contact_high = np.tile(contact_high, 4 * n_candidates)
    return {
        "candidates": _box(-pose_high, pose_high, pose_high.size),
        "candidate_contacts": _box(-contact_high, contact_high, contact_high.size),
        "candidate_mask": _box(0.0, 1.0, n_candidates),
    }


_SHAPES = {
    "points": (-1, 3),
    "normals": (-1, 3),
    "bounds": (2, 3),
    "candidates": (-1, 2, POSE_SIZE),
    "candidate_contacts": (-1, 4, 6),
}


def structured_observation(observation: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The observation's arrays in their natural shapes (views; see the module docstring):
    ``points`` (P, 3), ``normals`` (P, 3), ``bounds`` (2, 3), ``candidates`` (K, 2, 9),
    ``candidate_contacts`` (K, 4, 6); masks unchanged. Works on batched (vector) observations
    too: leading axes are kept."""
    out = {}
    for key, value in observation.items():
        value = np.asarray(value)
        shape = _SHAPES.get(key)
        out[key] = value if shape is None else value.reshape(*value.shape[:-1], *shape)
    return out


def check_in_limit(object_id: str, what: str, values: np.ndarray) -> None:
    """Refuse an object whose observation would leave the space (coordinates in m)."""
    worst = float(np.max(np.abs(values))) if values.size else 0.0
    if not worst <= OBSERVATION_LIMIT:
        raise EnvArgumentError(
            f"{object_id}: expected {what} within ±{OBSERVATION_LIMIT} m of the object's "
            f"centre, found {worst:.3g} m"
        )


# --------------------------------------------------------------------------------------------
# Actions
# --------------------------------------------------------------------------------------------


def _found(value: Any) -> str:
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} and dtype {value.dtype}"
    return f"{type(value).__name__} {value!r}"[:200]


def check_box_action(action: Any, space: spaces.Box) -> np.ndarray:
    """``action`` as an array of ``space``'s dtype, or :class:`EnvArgumentError` naming the space.

    Real numbers of any float or integer dtype are cast (a float64 array is fine); strings,
    objects, booleans and complex numbers, a wrong shape, NaN / inf and values outside the
    bounds (after the cast) are refused.
    """
    expected = f"action: expected an element of {space}"
    try:
        arr = np.asarray(action)
    except (ValueError, TypeError):  # ragged nested sequences and the like
        raise EnvArgumentError(f"{expected}, found {_found(action)}") from None
    if arr.dtype.kind not in "fiu":
        raise EnvArgumentError(f"{expected}, found {_found(arr)} (expected real numbers)")
    if arr.shape != space.shape:
        raise EnvArgumentError(f"{expected}, found an array of shape {arr.shape}")
    cast = arr.astype(space.dtype)
    finite = np.isfinite(cast)
    if not finite.all():
        where = tuple(int(i) for i in np.argwhere(~finite)[0])
        raise EnvArgumentError(f"{expected}, found {arr[where]} at index {where}")
    outside = (cast < space.low) | (cast > space.high)
    if outside.any():
        where = tuple(int(i) for i in np.argwhere(outside)[0])
        raise EnvArgumentError(
            f"{expected}, found {arr[where]} at index {where}, outside "
            f"[{space.low[where]}, {space.high[where]}]"
        )
    return cast


def check_discrete_action(action: Any, space: spaces.Discrete) -> int:
    """``action`` as an int in ``space``, or :class:`EnvArgumentError` naming the space.

    Python and numpy integers and 0-d integer arrays are accepted; booleans, floats, strings
    and arrays of another shape are refused.
    """
    expected = f"action: expected an element of {space}"
    value = action
    if isinstance(value, np.ndarray) and value.shape == () and value.dtype.kind in "iu":
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise EnvArgumentError(f"{expected}, found {_found(action)}")
    start, n = int(space.start), int(space.n)
    if not start <= int(value) < start + n:
        raise EnvArgumentError(f"{expected}, found {int(value)} (outside {start}..{start + n - 1})")
    return int(value)


# --------------------------------------------------------------------------------------------
# One trial
# --------------------------------------------------------------------------------------------


def perturbed_poses(
    scene: Scene, poses: np.ndarray, spec: PerturbationSpec, rng: np.random.Generator
) -> np.ndarray:
    """(2, 4, 4) ``poses`` with the benchmark's pose noise: each hand turned by exactly
    ``spec.rotation_deg`` about a random axis through its grasp centre and moved by exactly
    ``spec.translation`` in a random direction (:func:`dg16m_env.physics.labels.perturb_poses`, one
    perturbation, its seed drawn from ``rng``)."""
    seed = np.array([rng.integers(0, np.iinfo(np.int64).max)], dtype=np.int64)
    one = PerturbationSpec(
        n_perturbations=1, translation=spec.translation, rotation_deg=spec.rotation_deg
    )
    nominal = poses[None]
    return perturb_poses(nominal, grasp_centres(scene, nominal), seed, one)[0, 0]


def held(results: TrialResults, level: str, row: int = 0) -> bool:
    """Whether trial ``row`` held at ``level`` (``"full"``: through every disturbance;
    ``"gravity"``: it ran and nothing broke before the end of *gravity*), as the benchmark's
    labels count it (:class:`dg16m_env.physics.labels.GraspLabels`)."""
    status = int(results.status[row])
    if level == "full":
        return status == TrialStatus.SUCCESS
    phase = int(results.failing_phase[row])
    return status != TrialStatus.INVALID and (phase < 0 or phase > GRAVITY_PHASE)


def simulate_once(
    scene: Scene,
    poses: np.ndarray,
    protocol: TrialProtocol,
    perturbation: PerturbationSpec | None,
    rng: np.random.Generator,
) -> tuple[TrialResults, np.ndarray]:
    """ONE trial of ``protocol`` with the hands at ``poses`` (2, 4, 4), perturbed first when
    ``perturbation`` is given (:func:`perturbed_poses`; no draw from ``rng`` otherwise).

    Returns:
        The trial's results (one row) and the poses it ran at.
    """
    if perturbation is not None:
        poses = perturbed_poses(scene, poses, perturbation, rng)
    return run_trials(scene, poses[None], protocol), poses


def fc_verdict(obj: GraspObject, poses: np.ndarray, kwargs: dict[str, float]) -> tuple[bool, str]:
    """``(fc_passed, fc_reason)`` of the jaws closed at ``poses`` (2, 4, 4)
    (:func:`dg16m_env.evaluators.fce.fce_verdicts`; reasons in its ``REASONS``)."""
    codes, _ = fce_verdicts(obj, poses[None], kwargs)
    reason = REASONS[int(codes[0])]
    return reason == "pass", reason


def _finite_or_none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


@dataclass
class Outcome:
    """What one step did (turned into ``info`` by :func:`trial_info`).

    Attributes:
        success: the reward is 1.
        status: the trial's :class:`~dg16m_env.physics.trial.TrialStatus` name (lower case),
            :data:`STATUS_NOT_RUN` or :data:`STATUS_LABEL`.
        results: the trial's results (None when none ran).
        invalid_reason: why no trial (or an invalid one) ran, or None.
        fc_passed, fc_reason: the force-closure verdict (None when not computed).
        poses: the nominal hand poses (2, 4, 4) the action stands for, or None.
        extra: further info entries (Select: ``row``, ``p``).
    """

    success: bool
    status: str
    results: TrialResults | None = None
    invalid_reason: str | None = None
    fc_passed: bool | None = None
    fc_reason: str | None = None
    poses: np.ndarray | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_trial(
        cls, results: TrialResults, level: str, fc: tuple[bool | None, str | None]
    ) -> Outcome:
        status = TrialStatus(int(results.status[0]))
        reason = InvalidReason(int(results.invalid_reason[0]))
        return cls(
            success=held(results, level),
            status=status.name.lower(),
            results=results,
            invalid_reason=None if reason == InvalidReason.NONE else reason.name.lower(),
            fc_passed=fc[0],
            fc_reason=fc[1],
        )


def trial_info(object_id: str, outcome: Outcome) -> dict[str, Any]:
    """The ``info`` of a step: ``success`` and ``is_success`` (bool), ``object_id``,
    ``fc_passed``, ``fc_reason``, ``slip_m`` (largest slip at the hands' grasp centres, m),
    ``rotation_deg``, ``failing_phase`` (a :data:`~dg16m_env.physics.trial.PHASES` name),
    ``invalid_reason``, ``status``; entries that do not apply are None (never NaN, so equal
    steps give equal infos)."""
    results = outcome.results
    slip = rotation = None
    phase = None
    if results is not None:
        slip = _finite_or_none(float(results.max_displacement[0]))
        rotation = _finite_or_none(float(results.max_rotation_deg[0]))
        phase = results.phase_name(0) or None
    info: dict[str, Any] = {
        "success": bool(outcome.success),
        "is_success": bool(outcome.success),
        "object_id": object_id,
        "fc_passed": outcome.fc_passed,
        "fc_reason": outcome.fc_reason,
        "slip_m": slip,
        "rotation_deg": rotation,
        "failing_phase": phase,
        "invalid_reason": outcome.invalid_reason,
        "status": outcome.status,
    }
    info.update(outcome.extra)
    return info


# --------------------------------------------------------------------------------------------
# Rendering
# --------------------------------------------------------------------------------------------


def hands_away(centre: np.ndarray, radius: float) -> np.ndarray:
    """(2, 4, 4) open hands on either side of the object (along x, :data:`HAND_CLEARANCE`
    beyond its bounding sphere), approach axis towards it, closing axis vertical."""
    poses = np.tile(np.eye(4), (2, 1, 1))
    for hand, sign in enumerate((1.0, -1.0)):
        direction = np.array([sign, 0.0, 0.0])
        x = np.array([0.0, 0.0, 1.0])
        y = -direction
        poses[hand, :3, :3] = np.stack([x, y, np.cross(x, y)], axis=1)
        poses[hand, :3, 3] = centre + (radius + HAND_CLEARANCE) * direction
    return poses


class SceneRenderer:
    """Offscreen RGB pictures of a scene: the object at rest, the open hands at given poses
    (the restyled model of :func:`dg16m_env.physics.replay.render_model`, the free camera of
    :func:`dg16m_env.physics.replay.default_camera`, moved back to keep the hands in view). The renderer
    of the last scene is kept.

    Raises:
        RenderError: no offscreen OpenGL context, EGL or osmesa
            (:func:`~dg16m_env.physics.cameras.offscreen_renderer`).
    """

    def __init__(self, width: int = 480, height: int = 360) -> None:
        self.width, self.height = check_size(width, height)
        self._object_id: str | None = None
        self._slot = RendererSlot()
        self._model: mujoco.MjModel | None = None
        self._data: mujoco.MjData | None = None

    def render(self, scene: Scene, poses: np.ndarray | None) -> np.ndarray:
        """(H, W, 3) uint8 RGB: the hands at ``poses`` (2, 4, 4), or away (:func:`hands_away`)."""
        renderer = self._slot.renderer
        if renderer is None or self._object_id != scene.object_id:
            self.close()
            self._model = restyled_model(scene, self.width, self.height)
            self._data = mujoco.MjData(self._model)
            renderer = self._slot.hold(offscreen_renderer(self._model, self.height, self.width))
            self._object_id = scene.object_id
        model, data = self._model, self._data
        assert model is not None
        assert data is not None
        mujoco.mj_setState(model, data, initial_state(scene), STATE_SPEC)
        mujoco.mj_kinematics(model, data)
        camera = default_camera(scene, data)
        centre = np.array(camera.lookat)
        radius = float(camera.distance) / DISTANCE_FACTOR
        if poses is None:
            poses = hands_away(centre, radius)
        data.mocap_pos[scene.hand_mocap] = poses[:, :3, 3]
        data.mocap_quat[scene.hand_mocap] = quat_from_matrix(poses[:, :3, :3])
        mujoco.mj_forward(model, data)
        reach = np.linalg.norm(poses[:, :3, 3] - centre, axis=1).max() + 0.1
        camera.distance = DISTANCE_FACTOR * max(radius, float(reach))
        option = mujoco.MjvOption()
        option.flags[mujoco.mjtVisFlag.mjVIS_CONTACTPOINT] = False
        renderer.update_scene(data, camera=camera, scene_option=option)
        return np.array(renderer.render(), dtype=np.uint8)

    def close(self) -> None:
        """Free the renderer (idempotent)."""
        self._slot.close()
        self._model = self._data = None
        self._object_id = None


# --------------------------------------------------------------------------------------------
# The base environment
# --------------------------------------------------------------------------------------------


def _choice(name: str, value: Any, allowed: Sequence[str]) -> str:
    if not isinstance(value, str) or value not in allowed:
        raise EnvArgumentError(f"{name}: expected one of {tuple(allowed)}, found {value!r}")
    return value


RENDER_MODES: tuple[str, ...] = ("rgb_array",)
"""The render modes the environments implement. Not ``"human"``: a window needs pygame, which is
no dependency of this package (render ``"rgb_array"`` frames and show them yourself)."""


def check_render_mode(render_mode: object) -> str | None:
    """``render_mode`` if it is ``None`` or one of :data:`RENDER_MODES`.

    Raises:
        EnvArgumentError: any other value, ``"human"`` included.
    """
    if render_mode is None or render_mode in RENDER_MODES:
        return render_mode  # type: ignore[return-value]
    modes = " or ".join(repr(mode) for mode in RENDER_MODES)
    raise EnvArgumentError(f"render_mode: expected None or {modes}, found {render_mode!r}")


class RenderModes:
    """Mixin (listed before :class:`gymnasium.Env`): the class's :attr:`METADATA` served as the
    instance property ``metadata``, whose ``render_modes`` are :data:`RENDER_MODES`.

    ``gym.make(..., render_mode="human")`` wraps an environment whose *class* metadata lacks
    ``"human"`` in ``HumanRendering``, which then fails at the first reset without pygame; for
    an environment whose metadata is a property it passes the mode to the constructor instead,
    so :func:`check_render_mode` refuses it at construction, by name.
    """

    METADATA: ClassVar[dict[str, Any]]

    @property
    def metadata(self) -> dict[str, Any]:
        return self.METADATA


class OneStepGraspEnv(RenderModes, gym.Env[dict[str, np.ndarray], Any]):
    """Base of the one-step grasp environments (see the module docstring and the subclasses'
    docstrings for spaces, rewards and arguments)."""

    METADATA: ClassVar[dict[str, Any]] = {
        "render_modes": list(RENDER_MODES),
        "render_fps": RENDER_FPS,
        "autoreset_mode": AutoresetMode.SAME_STEP,
    }

    def __init__(
        self,
        *,
        benchmark: str | os.PathLike[str] | BenchmarkRef | None = None,
        object_ids: Sequence[str] | None = None,
        mesh_root: str | os.PathLike[str] | None = None,
        n_points: int = DEFAULT_POINTS,
        obs_mode: str = "full",
        n_cameras: int = 1,
        camera_resolution: int = 128,
        level: str = "full",
        perturb: bool = True,
        fc_info: bool = True,
        render_mode: str | None = None,
        render_width: int = 480,
        render_height: int = 360,
        vector_kwargs: Mapping[str, Any] | None = None,
    ) -> None:
        del vector_kwargs  # gym.make_vec's business (see the module docstring)
        self.n_points = check_integer("n_points", n_points, minimum=1, error=EnvArgumentError)
        self.obs_mode = _choice("obs_mode", obs_mode, OBS_MODES)
        self.n_cameras = check_integer("n_cameras", n_cameras, minimum=1, error=EnvArgumentError)
        if self.n_cameras > MAX_CAMERAS:
            raise EnvArgumentError(f"n_cameras: expected 1 or {MAX_CAMERAS}, found {n_cameras}")
        self.camera_resolution = check_integer(
            "camera_resolution", camera_resolution, minimum=16, error=EnvArgumentError
        )
        if self.camera_resolution > MAX_CAMERA_RESOLUTION:
            raise EnvArgumentError(
                f"camera_resolution: expected 16 to {MAX_CAMERA_RESOLUTION} pixels, found "
                f"{camera_resolution}"
            )
        self.level = _choice("level", level, LEVELS)
        for name, flag in (("perturb", perturb), ("fc_info", fc_info)):
            if not isinstance(flag, (bool, np.bool_)):
                raise EnvArgumentError(f"{name}: expected True or False, found {flag!r}")
        self.perturb = bool(perturb)
        self.fc_info = bool(fc_info)
        self.render_mode = check_render_mode(render_mode)
        self._scene_renderer = SceneRenderer(render_width, render_height)
        self._cameras = DepthCameras(self.camera_resolution)

        self.objects = BenchmarkObjects(benchmark, object_ids, mesh_root)
        self.benchmark = self.objects.ref.benchmark
        self.protocol: TrialProtocol = self.objects.parameters.protocol
        self.perturbation: PerturbationSpec = self.objects.parameters.perturbation
        self._fc_kwargs = self.objects.parameters.force_closure_kwargs()

        self.object_id: str | None = None
        self._observation: dict[str, np.ndarray] | None = None
        self._terminated = False
        self._poses: np.ndarray | None = None  # nominal poses of the last action (rendering)
        self.last_trial_poses: np.ndarray | None = None
        """The (2, 4, 4) poses the last trial ran at (perturbed), None when none ran."""
        self.camera_poses: list[CameraPose] = []
        """Partial mode: the depth cameras of the current episode."""

    # -- hooks for subclasses ----------------------------------------------------------------

    def _reset_extra(self, object_id: str) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Observation entries and reset-info entries beyond the point cloud (draws from
        ``self.np_random`` after the cloud)."""
        return {}, {}

    def _act(self, action: Any) -> Outcome:
        """Check ``action`` and carry it out (one trial, or none)."""
        raise NotImplementedError

    # -- shared steps --------------------------------------------------------------------------

    def _cloud(self, object_id: str) -> dict[str, np.ndarray]:
        obj_obs = self.objects.observation(object_id, self.n_points, 0)
        bounds = np.asarray(obj_obs["bounds"])
        check_in_limit(object_id, "its box", bounds)
        if self.obs_mode == "full":
            points, normals = obj_obs["points"], obj_obs["normals"]
            out = {}
        else:
            scene = self.objects.scene(object_id)
            points, normals, mask, cameras = self._cameras.observe(
                scene, self.np_random, self.n_points, self.n_cameras
            )
            self.camera_poses = cameras
            out = {"mask": mask}
        out["points"] = np.asarray(points, dtype=np.float32).reshape(-1)
        out["normals"] = np.asarray(normals, dtype=np.float32).reshape(-1)
        out["bounds"] = bounds.astype(np.float32).reshape(-1)
        return out

    def trial(self, poses: np.ndarray) -> Outcome:
        """One trial of the benchmark's protocol on the current object with the hands at
        ``poses`` (2, 4, 4), perturbed unless ``perturb=False``, with the force-closure
        verdict at ``poses`` (when ``fc_info``)."""
        assert self.object_id is not None
        fc: tuple[bool | None, str | None] = (None, None)
        if self.fc_info:
            fc = fc_verdict(self.objects.load(self.object_id), poses, self._fc_kwargs)
        return self._run(poses, fc)

    def _run(self, poses: np.ndarray, fc: tuple[bool | None, str | None]) -> Outcome:
        assert self.object_id is not None
        scene = self.objects.scene(self.object_id)
        spec = self.perturbation if self.perturb else None
        results, ran_at = simulate_once(scene, poses, self.protocol, spec, self.np_random)
        self.last_trial_poses = ran_at
        outcome = Outcome.from_trial(results, self.level, fc)
        outcome.poses = poses
        return outcome

    def _copy_observation(self) -> dict[str, np.ndarray]:
        assert self._observation is not None
        return {key: value.copy() for key, value in self._observation.items()}

    # -- Gymnasium API -------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Start an episode on a benchmark object: ``options={"object_id": id}`` picks it,
        else it is drawn uniformly with ``self.np_random``. Returns the observation and
        ``info = {"object_id": ...}`` (plus the subclass's entries)."""
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - {"object_id"})
        if unknown:
            raise EnvArgumentError(f"options: expected only 'object_id', found {unknown}")
        object_id = self.objects.choose(self.np_random, options.get("object_id"))
        observation = self._cloud(object_id)
        self.object_id = object_id
        extra, info = self._reset_extra(object_id)
        observation.update(extra)
        self._observation = observation
        self._terminated = False
        self._poses = None
        self.last_trial_poses = None
        return self._copy_observation(), {"object_id": object_id, **info}

    def step(self, action: Any) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Carry out ``action`` (one trial): the observation (unchanged), reward 1.0 or 0.0,
        ``terminated=True``, ``truncated=False`` and the info (:func:`trial_info`).

        Raises:
            EnvArgumentError: an action outside the action space (the message names it).
            gymnasium.error.ResetNeeded: no episode in progress (before ``reset`` or after the
                episode's one step).
        """
        if self._observation is None or self.object_id is None:
            raise gym.error.ResetNeeded(
                "step: expected reset() before the first step, found no episode in progress"
            )
        if self._terminated:
            raise gym.error.ResetNeeded(
                "step: expected reset() after the episode's one step, found a terminated episode"
            )
        outcome = self._act(action)
        self._terminated = True
        self._poses = outcome.poses
        info = trial_info(self.object_id, outcome)
        reward = 1.0 if outcome.success else 0.0
        return self._copy_observation(), reward, True, False, info

    def render(self) -> np.ndarray | None:  # type: ignore[override]
        """``render_mode="rgb_array"``: an (H, W, 3) uint8 picture of the object with the open
        hands at the last action's poses (before a step: open hands on either side, facing
        it). ``render_mode=None``: nothing (None)."""
        if self.render_mode is None:
            return None
        object_id = self.object_id or self.objects.object_ids[0]
        return self._scene_renderer.render(self.objects.scene(object_id), self._poses)

    def close(self) -> None:
        """Free the renderers (idempotent)."""
        self._scene_renderer.close()
        self._cameras.close()
        super().close()


__all__ = [
    "DEFAULT_POINTS",
    "OBSERVATION_LIMIT",
    "OBS_MODES",
    "VECTOR_KWARGS",
    "EnvArgumentError",
    "OneStepGraspEnv",
    "Outcome",
    "SceneRenderer",
    "candidate_spaces",
    "check_box_action",
    "check_discrete_action",
    "cloud_spaces",
    "held",
    "simulate_once",
    "structured_observation",
    "trial_info",
]
