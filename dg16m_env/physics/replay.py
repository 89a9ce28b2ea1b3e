"""Seeing a trial: replay one dual grasp step by step and render it offscreen.

:func:`step_trial` runs one trial of :mod:`dg16m_env.physics.trial` in a Python loop (``mj_step`` with the
controls of the C rollout: the same :func:`~dg16m_env.physics.trial.schedule`,
:func:`~dg16m_env.physics.trial.trial_controls` and :func:`~dg16m_env.physics.trial.initial_state`) and judges it
with :func:`~dg16m_env.physics.trial.analyse`, so its verdict is the verdict of
:func:`~dg16m_env.physics.trial.run_trials`, and its trajectory is the same bit for bit: ``run_trials``
restarts ``mujoco.rollout`` at every phase (:func:`~dg16m_env.physics.trial.trial_segments`), which starts
the solver without a warm start, and the replay clears ``qacc_warmstart`` at the same steps.

:func:`trial_frames` renders frames of a replayed trial with ``mujoco.Renderer`` (a free camera
looking across the line between the two hands, :func:`hands_view`, so both are in view; both
hands fixed in the world), each with a caption
``"t=1.20 s  force+y  slip 3.1 mm"``: time, phase and the object's displacement at the hands' grasp
centres (the slip measured by the protocol: from the start during *close*, from the end of
*close* after it). :func:`write_strip` writes frames side by side (a grid for more than four) to
one PNG, with the slip over time under them (:func:`slip_curve`), :func:`write_gif` an animated
GIF (both in :mod:`dg16m_env.physics.replay_files`, re-exported here).

Rendering needs an offscreen OpenGL: ``MUJOCO_GL=egl`` (GPU, or Mesa's software EGL) or
``MUJOCO_GL=osmesa`` (software), with the system libraries ``libegl1`` / ``libosmesa6``.
:mod:`dg16m_env` sets ``MUJOCO_GL=egl`` unless it is already set, before MuJoCo is imported.

Units: SI (m, s); frames are (H, W, 3) uint8 RGB arrays.
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from dg16m_core.errors import Dg16mError
from dg16m_env.physics.replay_files import ReplayError as ReplayError
from dg16m_env.physics.replay_files import write_gif as write_gif
from dg16m_env.physics.replay_files import write_strip as write_strip
from dg16m_env.physics.scene import Scene
from dg16m_env.physics.trial_measures import analyse, grasp_centres, object_motion, object_states
from dg16m_env.physics.trial_protocol import (
    CONTROL_SPEC,
    PHASES,
    STATE_SPEC,
    InvalidReason,
    Schedule,
    TrialProtocol,
    TrialResults,
    TrialStatus,
    check_dual_grasps,
    check_initial_poses,
    initial_state,
    schedule,
    trial_controls,
    trial_segments,
)

DEFAULT_AZIMUTH = 135.0
"""Camera azimuth (degrees) of the default free camera."""

DEFAULT_ELEVATION = -25.0
"""Camera elevation (degrees; negative looks down) of the default free camera."""

DISTANCE_FACTOR = 2.2
"""Default camera distance as a multiple of the object's bounding radius."""

MAX_IMAGE_SIDE = 4096
"""Largest frame width or height (pixels)."""

OBJECT_ALPHA = 0.5
"""Opacity of the object in renderings (hands behind or under it stay visible)."""

HAND_COLORS = ((0.95, 0.55, 0.15), (0.75, 0.15, 0.75))
"""Finger colours of hand 0 (orange) and hand 1 (magenta: the object is light blue, a blue hand
was lost against it) in renderings; palms are lighter."""

HAND_COLOR_NAMES = ("orange", "magenta")
"""Names of :data:`HAND_COLORS`, for titles and legends."""

BACKGROUND = (0.93, 0.94, 0.96)
"""Colour (RGB in [0, 1]) of the backdrop behind a replayed trial (MuJoCo clears to black)."""

REPLAY_DISTANCE_FACTOR = 1.6
"""Camera distance of :func:`hands_view` as a multiple of the extent it frames (tighter than
:data:`DISTANCE_FACTOR`, which the environments' cameras keep), so the hands are larger."""

_INSTALL_HINT = (
    "offscreen rendering needs OpenGL: install libegl1 (GPU or Mesa EGL) or libosmesa6 "
    "(software) and set MUJOCO_GL=egl or MUJOCO_GL=osmesa before starting Python"
)


class RenderError(Dg16mError, RuntimeError):
    """No offscreen OpenGL context could be created (missing libraries or a bad ``MUJOCO_GL``)."""


# --------------------------------------------------------------------------------------------
# Stepping one trial
# --------------------------------------------------------------------------------------------


@dataclass
class SteppedTrial:
    """One trial simulated step by step (see the module docstring).

    Attributes:
        results: the verdict (one row), judged like :func:`~dg16m_env.physics.trial.run_trials`.
        plan: the trial's schedule (T steps).
        controls: (T, C) controls applied before each step (``mjSTATE_CTRL | XFRC_APPLIED |
            MOCAP_POS | MOCAP_QUAT``).
        states: (K + 1, S) full physics states at the start and after each simulated step
            (``mjSTATE_FULLPHYSICS``); K = T for a trial that ran, 0 for an invalid one.
        slip: (K + 1,) displacement of the object at the hands' grasp centres (m; the larger
            of the two), measured like the protocol.
        rotation_deg: (K + 1,) rotation of the object (degrees), measured like the protocol.
    """

    results: TrialResults
    plan: Schedule
    controls: np.ndarray
    states: np.ndarray
    slip: np.ndarray
    rotation_deg: np.ndarray

    @property
    def status(self) -> TrialStatus:
        return TrialStatus(int(self.results.status[0]))

    @property
    def failing_phase(self) -> str:
        """Name of the phase that broke the bounds ('' when none)."""
        return self.results.phase_name(0)

    @property
    def end(self) -> int:
        """Number of steps that decide the verdict: up to the end of the failing phase, the whole
        trial when it held, 0 for an invalid trial."""
        if self.status == TrialStatus.INVALID:
            return 0
        phase = int(self.results.failing_phase[0])
        if phase < 0:
            return self.plan.nstep
        return int(np.searchsorted(self.plan.phase, phase, side="right"))

    @property
    def first_out(self) -> int | None:
        """State after the first step outside the bounds (slip or rotation), ``None`` when the
        trial held or was not run."""
        if self.status in (TrialStatus.SUCCESS, TrialStatus.INVALID):
            return None
        out = self.results.protocol.out_of_bounds(self.slip, self.rotation_deg)
        out |= ~np.isfinite(self.slip)
        hits = np.flatnonzero(out[1 : self.end + 1])
        return int(hits[0]) + 1 if hits.size else None

    def phase_at(self, k: int) -> str:
        """Phase of state ``k`` (0 = the start, ``k`` = after step ``k``)."""
        if k <= 0:
            return PHASES[0]
        return PHASES[int(self.plan.phase[k - 1])]

    def describe(self) -> str:
        """One line: the verdict with its measurements."""
        return describe_result(self.results, 0)

    def __repr__(self) -> str:  # states are (T + 1, S): describe the trial instead
        return f"SteppedTrial({len(self.states) - 1} steps: {self.describe()})"


def describe_result(results: TrialResults, row: int) -> str:
    """One line for trial ``row`` of ``results``: status, failing phase, slip and rotation."""
    status = TrialStatus(int(results.status[row]))
    if status == TrialStatus.INVALID:
        reason = InvalidReason(int(results.invalid_reason[row])).name.lower().replace("_", " ")
        depth = float(results.max_penetration[row]) * 1e3
        return f"invalid ({reason}, open-hand penetration {depth:.1f} mm; not run)"
    text = status.name.lower()
    if status != TrialStatus.SUCCESS and results.failing_phase[row] >= 0:
        text += f" in {results.phase_name(row)}"
    slip = float(results.max_displacement[row]) * 1e3
    rotation = float(results.max_rotation_deg[row])
    return f"{text} (max slip {slip:.1f} mm, max rotation {rotation:.1f} deg)"


def _motion(
    scene: Scene, states: np.ndarray, anchors: np.ndarray, close: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per-state slip (m) and rotation (deg) of the object, measured by the protocol's own
    :func:`~dg16m_env.physics.trial.object_motion` (``states[0]`` is the start, ``states[k]`` the state
    after step ``k``, so the close phase holds ``close + 1`` states)."""
    pos, quat, _ = object_states(scene, states[None])
    slip, rotation = object_motion(pos, quat, anchors[None], close + 1)
    return slip[0], rotation[0]


def step_trial(
    scene: Scene, dual_grasp: np.ndarray, protocol: TrialProtocol | None = None
) -> SteppedTrial:
    """Simulate one trial step by step in Python and judge it (see the module docstring).

    Args:
        scene: the object's compiled scene (:func:`dg16m_env.physics.scene.compile_scene`).
        dual_grasp: (2, 4, 4) hand poses, gripper frame -> object frame (m).
        protocol: timing, loads and thresholds (default :class:`TrialProtocol`).

    Returns:
        The :class:`SteppedTrial`; an invalid grasp (open hand in the object, hands overlapping)
        is not simulated, as in :func:`~dg16m_env.physics.trial.run_trials`.

    Raises:
        TrialError: malformed poses.
    """
    protocol = protocol or TrialProtocol()
    grasps = check_dual_grasps(dual_grasp)
    if len(grasps) != 1:
        raise ReplayError(f"dual_grasp: expected one (2, 4, 4) dual grasp, found {len(grasps)}")
    model = scene.model
    plan = schedule(scene, protocol)
    controls = trial_controls(scene, grasps, plan)[0]
    start = initial_state(scene)
    anchors = grasp_centres(scene, grasps)[0]
    reason, penetration = check_initial_poses(scene, grasps, protocol)
    if reason[0] != InvalidReason.NONE:
        results = TrialResults.empty(1, protocol)
        results.invalid_reason[:] = reason
        results.max_penetration[:] = penetration
        zero = np.zeros(1)
        return SteppedTrial(results, plan, controls, start[None], zero, zero.copy())

    data = mujoco.MjData(model)
    mujoco.mj_resetData(model, data)
    mujoco.mj_setState(model, data, start, STATE_SPEC)
    states = np.empty((plan.nstep + 1, start.size))
    sensors = np.empty((plan.nstep, model.nsensordata))
    states[0] = start
    restarts = {seg.start for seg in trial_segments(plan)}
    for t in range(plan.nstep):
        if t in restarts:  # as mujoco.rollout at the start of each segment
            data.qacc_warmstart[:] = 0.0
        mujoco.mj_setState(model, data, controls[t], CONTROL_SPEC)
        mujoco.mj_step(model, data)
        mujoco.mj_getState(model, data, states[t + 1], STATE_SPEC)
        sensors[t] = data.sensordata
    results = analyse(scene, states[None, 1:], sensors[None], plan, protocol, anchors[None])
    slip, rotation = _motion(scene, states, anchors, plan.close_end)
    return SteppedTrial(results, plan, controls, states, slip, rotation)


# --------------------------------------------------------------------------------------------
# Rendering
# --------------------------------------------------------------------------------------------


def _object_bounds(scene: Scene, data: mujoco.MjData) -> tuple[np.ndarray, float]:
    """Centre and radius (m) of a sphere around the object's geoms (their bounding spheres)."""
    geoms = scene.object_geoms
    centres = data.geom_xpos[geoms]
    radii = scene.model.geom_rbound[geoms]
    lo = (centres - radii[:, None]).min(axis=0)
    hi = (centres + radii[:, None]).max(axis=0)
    centre = (lo + hi) / 2.0
    radius = float(np.max(np.linalg.norm(centres - centre, axis=1) + radii))
    return centre, max(radius, 1e-3)


def _start_data(scene: Scene) -> mujoco.MjData:
    """The scene's data at the start of a trial (positions computed)."""
    data = mujoco.MjData(scene.model)
    mujoco.mj_setState(scene.model, data, initial_state(scene), STATE_SPEC)
    mujoco.mj_kinematics(scene.model, data)
    return data


def default_camera(scene: Scene, data: mujoco.MjData | None = None) -> mujoco.MjvCamera:
    """A free camera at :data:`DEFAULT_AZIMUTH` / :data:`DEFAULT_ELEVATION`, looking at the
    object's centre (at the start of a trial) from :data:`DISTANCE_FACTOR` times its bounding
    radius."""
    centre, radius = _object_bounds(scene, _start_data(scene) if data is None else data)
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.lookat[:] = centre
    camera.distance = DISTANCE_FACTOR * radius
    camera.azimuth = DEFAULT_AZIMUTH
    camera.elevation = DEFAULT_ELEVATION
    return camera


HAND_REACH = 0.12
"""How far (m) a Panda hand extends from its grasp centre, for framing both hands."""


def hands_view(scene: Scene, dual_grasp: np.ndarray) -> dict[str, Any]:
    """Camera overrides of :func:`default_camera` that show both hands of one dual grasp.

    The camera looks across the horizontal line between the two hands' grasp centres (so
    neither hand stands behind the other), from the side of the object the hands are on
    (their mean offset from the object's centre; the default azimuth's side when they are
    balanced), at :data:`DEFAULT_ELEVATION`; it looks at the middle of the two hands and
    stands back far enough to hold both (:data:`HAND_REACH` around each centre;
    :data:`REPLAY_DISTANCE_FACTOR` times that extent, and both centres inside the vertical
    field of view): the view is
    cropped on the hands and the part of the object they hold, not the whole object (on a
    large object the hands were a few pixels wide).

    Args:
        dual_grasp: (2, 4, 4) hand poses, gripper -> object frame (m); the object starts at the
            world origin.

    Returns:
        ``lookat`` (3,) m, ``distance`` m, ``azimuth`` degrees.
    """
    grasp = check_dual_grasps(np.asarray(dual_grasp)[None])
    centres = grasp_centres(scene, grasp)[0]
    centre, _ = _object_bounds(scene, _start_data(scene))
    across = centres[1, :2] - centres[0, :2]
    default = math.radians(DEFAULT_AZIMUTH)
    forward = np.array([math.cos(default), math.sin(default)])  # camera -> scene, horizontal
    if np.linalg.norm(across) > 1e-6:
        normal = np.array([-across[1], across[0]]) / np.linalg.norm(across)
        side = float(np.dot(centres[:, :2].mean(axis=0) - centre[:2], normal))
        # the camera stands on the hands' side: it looks towards -side along the normal
        sign = -np.sign(side) if abs(side) > 1e-6 else np.sign(np.dot(forward, normal)) or 1.0
        forward = sign * normal
    lookat = (centres.min(axis=0) + centres.max(axis=0)) / 2.0
    half = float(np.linalg.norm(centres - lookat, axis=1).max())
    # both grasp centres within the vertical field of view (the narrower one), with a margin
    inside = 1.15 * half / math.tan(math.radians(float(scene.model.vis.global_.fovy)) / 2.0)
    return {
        "lookat": lookat,
        "distance": max(REPLAY_DISTANCE_FACTOR * (half + HAND_REACH), inside),
        "azimuth": math.degrees(math.atan2(forward[1], forward[0])),
    }


def _camera(scene: Scene, camera: mujoco.MjvCamera | Mapping[str, Any] | None) -> mujoco.MjvCamera:
    if isinstance(camera, mujoco.MjvCamera):
        return camera
    out = default_camera(scene)
    for key, value in dict(camera or {}).items():
        if key not in ("lookat", "distance", "azimuth", "elevation"):
            raise ReplayError(
                f"camera: expected keys lookat, distance, azimuth, elevation, found {key!r}"
            )
        if key == "lookat":
            out.lookat[:] = np.asarray(value, dtype=np.float64).reshape(3)
        else:
            setattr(out, key, float(value))
    return out


def check_size(width: int, height: int) -> tuple[int, int]:
    """Validate a frame size in pixels."""
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ReplayError(f"{name}: expected an integer number of pixels, found {value!r}")
        if not 16 <= value <= MAX_IMAGE_SIDE:
            raise ReplayError(f"{name}: expected 16 to {MAX_IMAGE_SIDE} pixels, found {value}")
    return int(width), int(height)


def render_model(scene: Scene, width: int = 480, height: int = 360) -> mujoco.MjModel:
    """A copy of the scene's model restyled for pictures (physics unchanged): translucent
    object (:data:`OBJECT_ALPHA`), coloured hands (:data:`HAND_COLORS`), small red contact
    points, brighter head light, and an offscreen buffer of at least ``width`` x ``height``."""
    model = copy.copy(scene.model)
    visual = model.vis.global_
    visual.offwidth = max(int(visual.offwidth), width)
    visual.offheight = max(int(visual.offheight), height)
    model.geom_rgba[scene.object_geoms, 3] = OBJECT_ALPHA
    for geoms, color in zip(scene.hand_geoms, HAND_COLORS, strict=True):
        palm = 0.5 + 0.5 * np.asarray(color)
        model.geom_rgba[geoms[0], :3] = palm
        model.geom_rgba[geoms[1:], :3] = color
    size = max(float(model.stat.meansize), 1e-6)
    model.vis.scale.contactwidth = 0.012 / size
    model.vis.scale.contactheight = 0.004 / size
    model.vis.rgba.contactpoint[:] = (0.9, 0.1, 0.1, 1.0)
    model.vis.headlight.ambient[:] = 0.35
    model.vis.headlight.diffuse[:] = 0.55
    return model


def _match_gl_backend() -> None:
    """Make MuJoCo's renderer use the backend ``MUJOCO_GL`` names now.

    MuJoCo picks its OpenGL backend once, when it is imported; a program that imported ``mujoco``
    before :mod:`dg16m_env` set ``MUJOCO_GL=egl`` got GLFW, which needs a display. For
    ``egl`` / ``osmesa`` the choice is redone here (a no-op when it already matches)."""
    from mujoco.rendering.classic import gl_context

    wanted = os.environ.get("MUJOCO_GL", "").lower().strip()
    chosen = getattr(gl_context, "_MUJOCO_GL", wanted)
    if wanted == chosen or wanted not in ("egl", "osmesa"):
        return
    if wanted == "egl":
        from mujoco.egl import GLContext
    else:
        from mujoco.osmesa import GLContext
    gl_context.GLContext = GLContext
    gl_context._MUJOCO_GL = wanted


def make_renderer(
    model: mujoco.MjModel, height: int, width: int, shadow_size: int | None = None
) -> mujoco.Renderer:
    """An offscreen ``mujoco.Renderer`` (``model``'s offscreen buffer must hold the size; see
    :func:`render_model`), its lights' shadow maps ``shadow_size`` pixels a side (None: the
    model's ``visual/quality/shadowsize``; ``model`` keeps its own value: the size is read
    when the OpenGL context is made).

    Raises:
        RenderError: no OpenGL context (see the module docstring).
    """
    shipped = int(model.vis.quality.shadowsize)
    try:
        _match_gl_backend()
        if shadow_size is not None:
            model.vis.quality.shadowsize = shadow_size
        return mujoco.Renderer(model, height, width)
    except Exception as exc:  # ImportError, RuntimeError, mujoco.FatalError, OSError, ...
        backend = os.environ.get("MUJOCO_GL", "")
        raise RenderError(
            f"expected an offscreen OpenGL context (MUJOCO_GL={backend!r}), found: "
            f"{type(exc).__name__}: {str(exc).strip()}; {_INSTALL_HINT}"
        ) from exc
    finally:
        model.vis.quality.shadowsize = shipped


def phase_ends(stepped: SteppedTrial) -> list[int]:
    """The start (0) and the last state of each phase among the steps that decide the verdict."""
    ends = np.flatnonzero(np.diff(stepped.plan.phase)) + 1  # the last step of each phase
    ends = [int(k) for k in ends if k <= stepped.end] + [stepped.end]
    return sorted({0, *ends})


def largest_slip_step(stepped: SteppedTrial) -> int | None:
    """The state with the largest slip among the steps that decide the verdict (None for an
    invalid trial)."""
    if stepped.end == 0:
        return None
    slip = stepped.slip[1 : stepped.end + 1]
    slip = np.where(np.isfinite(slip), slip, np.inf)
    return int(np.argmax(slip)) + 1


def frame_steps(stepped: SteppedTrial, n_frames: int) -> list[int]:
    """States to render: ``n_frames`` over the steps that decide the verdict, always with the
    start, the end of *close* and, for a failed trial, the first step out of bounds and the end
    of its failing phase.

    Exactly ``n_frames`` (more only when the key frames above need them). Up to as many
    frames as there are phase ends (:func:`phase_ends`: a strip of pictures): the key frames,
    then the end of *gravity* and the state of the largest slip, then ends of the other phases
    spread evenly; no phase shows twice after the start (the object moves by millimetres:
    frames evenly spread in time looked alike). More frames (an animation, or a trial that
    failed early): every phase end, then states spread evenly in time."""
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or n_frames < 1:
        raise ReplayError(f"n_frames: expected an integer >= 1, found {n_frames!r}")
    end = stepped.end
    if end == 0:
        return [0]
    ends = phase_ends(stepped)
    close_end = stepped.plan.close_end if stepped.plan.close_end <= end else None
    if n_frames == 1:
        return sorted({k for k in (close_end, stepped.first_out, end) if k is not None})
    if n_frames > len(ends):  # every phase end, the key frames, then states evenly in time
        steps = {*ends, *(k for k in (close_end, stepped.first_out) if k is not None)}
        grid = np.round(np.linspace(0, end, int(n_frames) + len(steps))).astype(int).tolist()
        grid = [k for k in dict.fromkeys(grid) if k not in steps]
        need = int(n_frames) - len(steps)
        if need > 0 and grid:
            picks = np.round(np.linspace(0, len(grid) - 1, min(need, len(grid)))).astype(int)
            steps |= {grid[i] for i in picks.tolist()}
        return sorted(steps)
    chosen: list[int] = []
    covered: set[str] = set()  # phases with a frame (the start's does not count)

    def add(k: int | None, *, required: bool = False) -> None:
        if k is None or k in chosen:
            return
        phase = stepped.phase_at(k) if k > 0 else None
        if not required and (len(chosen) >= n_frames or phase in covered):
            return
        chosen.append(k)
        if phase is not None:
            covered.add(phase)

    for k in (0, end, stepped.first_out, close_end):
        add(k, required=True)
    gravity_end = int(np.searchsorted(stepped.plan.phase, 1, side="right"))
    add(gravity_end if 0 < gravity_end <= end else None)
    add(largest_slip_step(stepped))
    rest = [k for k in ends if k not in chosen and stepped.phase_at(k) not in covered]
    need = n_frames - len(chosen)
    if need > 0 and rest:
        picks = np.round(np.linspace(0, len(rest) - 1, min(need, len(rest)))).astype(int)
        for i in sorted(set(picks.tolist())):
            add(rest[i])
    return sorted(chosen)


def caption(stepped: SteppedTrial, k: int) -> str:
    """``"t=1.20 s  force+y  slip 3.1 mm"`` for state ``k`` (``" (max)"`` at the largest slip,
    ``"  rot 4 deg"`` once the object has turned by a degree or more)."""
    if stepped.status == TrialStatus.INVALID:
        reason = InvalidReason(int(stepped.results.invalid_reason[0])).name.lower()
        return f"t=0.00 s  invalid: {reason.replace('_', ' ')}"
    t = float(stepped.states[k, 0])
    text = f"t={t:.2f} s  {stepped.phase_at(k)}  slip {stepped.slip[k] * 1e3:.1f} mm"
    if k == largest_slip_step(stepped) and stepped.slip[k] > 0:
        text += " (max)"
    if stepped.rotation_deg[k] >= 1.0:
        text += f"  rot {stepped.rotation_deg[k]:.1f} deg"
    return text


def _add_backdrop(scene: mujoco.MjvScene, camera: mujoco.MjvCamera) -> None:
    """Add a light screen (:data:`BACKGROUND`) behind everything the free ``camera`` sees: a
    large flat box facing it, twice its distance beyond the point it looks at (decoration:
    only in the picture, never in the simulated model)."""
    if scene.ngeom >= scene.maxgeom:
        return
    azimuth, elevation = math.radians(camera.azimuth), math.radians(camera.elevation)
    forward = np.array(
        [
            math.cos(elevation) * math.cos(azimuth),
            math.cos(elevation) * math.sin(azimuth),
            math.sin(elevation),
        ]
    )
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= max(float(np.linalg.norm(right)), 1e-9)
    up = np.cross(right, forward)
    distance = float(camera.distance)
    centre = np.asarray(camera.lookat, dtype=np.float64) + 2.0 * distance * forward
    rotation = np.column_stack([right, up, forward])  # the box's z axis points away
    size = np.array([6.0 * distance, 6.0 * distance, 1e-3 * distance])
    geom = scene.geoms[scene.ngeom]
    mujoco.mjv_initGeom(
        geom,
        mujoco.mjtGeom.mjGEOM_BOX,
        size,
        centre,
        rotation.reshape(9),
        np.array([*BACKGROUND, 1.0], dtype=np.float32),
    )
    geom.emission = 1.0  # its own colour, whatever the light
    geom.specular = 0.0
    geom.shininess = 0.0
    geom.reflectance = 0.0
    scene.ngeom += 1


def render_states(
    scene: Scene,
    stepped: SteppedTrial,
    steps: Sequence[int],
    *,
    width: int = 480,
    height: int = 360,
    camera: mujoco.MjvCamera | Mapping[str, Any] | None = None,
    contacts: bool = True,
) -> list[np.ndarray]:
    """Render states ``steps`` of a stepped trial ((H, W, 3) uint8 each).

    Args:
        camera: a ``mujoco.MjvCamera``, or overrides of :func:`default_camera` (``lookat``,
            ``distance``, ``azimuth``, ``elevation``).
        contacts: draw contact points.

    The object and hands stand in front of a light backdrop (:data:`BACKGROUND`).
    """
    width, height = check_size(width, height)
    model = render_model(scene, width, height)
    view = _camera(scene, camera)
    option = mujoco.MjvOption()
    option.flags[mujoco.mjtVisFlag.mjVIS_CONTACTPOINT] = contacts
    data = mujoco.MjData(model)
    renderer = make_renderer(model, height, width)
    frames = []
    try:
        for k in steps:
            mujoco.mj_setState(model, data, stepped.states[k], STATE_SPEC)
            control = stepped.controls[max(k - 1, 0)]
            mujoco.mj_setState(model, data, control, CONTROL_SPEC)
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera=view, scene_option=option)
            _add_backdrop(renderer.scene, view)
            frames.append(np.array(renderer.render(), dtype=np.uint8))
    finally:
        renderer.close()
    return frames


@dataclass
class Replay:
    """A replayed and rendered trial: the stepped trial, its frames, their captions and the
    states they show (indices into ``trial.states``)."""

    trial: SteppedTrial
    frames: list[np.ndarray]
    captions: list[str]
    steps: list[int]
    layout: str = ""
    """How the frames are laid out, for a title ('' for one view of both hands)."""

    def __repr__(self) -> str:  # frames are images: give their count and size
        size = "x".join(str(v) for v in self.frames[0].shape[1::-1]) if self.frames else "-"
        return f"Replay({len(self.frames)} frames of {size}: {self.trial.describe()})"


def replay_trial(
    scene: Scene,
    dual_grasp: np.ndarray,
    protocol: TrialProtocol | None = None,
    *,
    n_frames: int = 8,
    width: int = 480,
    height: int = 360,
    camera: mujoco.MjvCamera | Mapping[str, Any] | None = None,
) -> Replay:
    """:func:`step_trial` then render it (frames as :func:`trial_frames` describes).

    Hands more than :data:`CLOSE_UP_SPLIT` apart (a view of both left them a few pixels wide)
    are shown, after a first frame of both, as two close-ups side by side in each frame
    (:func:`hand_close_ups`; hand 0 left, hand 1 right), unless ``camera`` places the camera
    (a ``mujoco.MjvCamera``, or ``lookat`` / ``distance`` given)."""
    check_size(width, height)
    stepped = step_trial(scene, dual_grasp, protocol)
    overrides = {} if isinstance(camera, mujoco.MjvCamera) else dict(camera or {})
    if not isinstance(camera, mujoco.MjvCamera):  # both hands in view unless told otherwise
        camera = {**hands_view(scene, dual_grasp), **overrides}
    steps = frame_steps(stepped, n_frames)
    captions = [caption(stepped, k) for k in steps]
    close_ups = hand_close_ups(scene, dual_grasp)
    split = (
        not isinstance(camera, mujoco.MjvCamera)
        and not {"lookat", "distance"} & set(overrides)
        and close_ups is not None
        and len(steps) > 1
        and width >= 32
    )
    if not split:
        frames = render_states(scene, stepped, steps, width=width, height=height, camera=camera)
        return Replay(stepped, frames, captions, steps)
    assert close_ups is not None
    frames = render_states(scene, stepped, steps[:1], width=width, height=height, camera=camera)
    halves = [
        render_states(scene, stepped, steps[1:], width=w, height=height, camera={**c, **overrides})
        for w, c in zip((width // 2, width - width // 2), close_ups, strict=True)
    ]
    for left, right in zip(*halves, strict=True):
        frame = np.concatenate([left, right], axis=1)
        frame[:, width // 2 - 1 : width // 2 + 1] = 255  # a white seam between the close-ups
        frames.append(frame)
    layout = "first frame: both hands; then close-ups of each hand (hand 0 left, hand 1 right)"
    return Replay(stepped, frames, captions, steps, layout)


CLOSE_UP_SPLIT = 0.3
"""Grasp centres farther apart than this (m) are shown as two close-ups (:func:`replay_trial`)."""

CLOSE_UP_DISTANCE = 0.4
"""Camera distance (m) of a close-up of one hand."""


def hand_close_ups(scene: Scene, dual_grasp: np.ndarray) -> list[dict[str, Any]] | None:
    """Cameras on each hand's grasp centre, from :func:`hands_view`'s direction, at
    :data:`CLOSE_UP_DISTANCE`; None when the grasp centres are within :data:`CLOSE_UP_SPLIT`
    of each other (one view shows both large enough)."""
    grasp = check_dual_grasps(np.asarray(dual_grasp)[None])
    centres = grasp_centres(scene, grasp)[0]
    if float(np.linalg.norm(centres[1] - centres[0])) <= CLOSE_UP_SPLIT:
        return None
    azimuth = hands_view(scene, dual_grasp)["azimuth"]
    return [{"lookat": c, "distance": CLOSE_UP_DISTANCE, "azimuth": azimuth} for c in centres]


def slip_curve(replay: Replay) -> dict[str, Any] | None:
    """What :func:`write_strip` draws under the frames: the slip (mm) over the steps that decide
    the verdict, the protocol's bound, the phases' start times and the frames' times (None for
    an invalid trial, which was not run)."""
    stepped = replay.trial
    if stepped.end == 0:
        return None
    states = range(stepped.end + 1)
    starts = [0, *(int(k) for k in np.flatnonzero(np.diff(stepped.plan.phase)) + 1)]
    return {
        "t": stepped.states[: stepped.end + 1, 0].copy(),
        "slip_mm": 1e3 * stepped.slip[: stepped.end + 1],
        "limit_mm": 1e3 * float(stepped.results.protocol.max_displacement),
        "phases": [
            (float(stepped.states[k, 0]), stepped.phase_at(k + 1)) for k in starts if k in states
        ],
        "frames_t": [float(stepped.states[k, 0]) for k in replay.steps],
    }


def trial_frames(
    scene: Scene, dual_grasp: np.ndarray, protocol: TrialProtocol | None = None, **options: Any
) -> tuple[list[np.ndarray], list[str]]:
    """Simulate one trial step by step and render it: :func:`replay_trial`'s frames and captions.

    Frames cover the part of the trial that decides the verdict (the whole trial when the grasp
    held, up to the end of the failing phase when it failed), as :func:`frame_steps` picks them:
    up to as many frames as phase ends, ends of distinct phases (one frame per phase); more,
    spread evenly in time; always with the end of *close* and, for a failed trial, the first
    step out of bounds and the end of the failing phase. An invalid grasp (not simulated) gives
    one frame of the open hands.

    Args:
        scene: the object's compiled scene.
        dual_grasp: (2, 4, 4) hand poses, gripper frame -> object frame (m).
        protocol: the trial protocol (default :class:`TrialProtocol`).
        options: :func:`replay_trial`'s keywords: ``n_frames`` (frames as above; the key
            frames come on top when not among them), ``width``, ``height`` (pixels) and
            ``camera`` (a ``mujoco.MjvCamera``, or a mapping overriding
            :func:`default_camera`'s ``lookat`` (m), ``distance`` (m), ``azimuth`` and
            ``elevation`` (degrees)).

    Returns:
        ``(frames, captions)``: (H, W, 3) uint8 RGB frames and ``"t=1.20 s  force+y  slip 3.1 mm"``
        captions.

    Raises:
        RenderError: no offscreen OpenGL context.
        ReplayError: bad frame count or size.
        TrialError: malformed poses.
    """
    replay = replay_trial(scene, dual_grasp, protocol, **options)
    return replay.frames, replay.captions
