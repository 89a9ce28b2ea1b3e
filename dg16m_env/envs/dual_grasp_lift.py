"""``dg16m_env/DualGraspLift-v0``: two floating Panda hands lift a benchmark object from a table.

Description
-----------
A closed-loop task. At reset an object of the benchmark rests on a table in one of its stable
poses; two floating Franka Panda hands start open, above the table, on roughly opposite sides of
it and clear of it. Each control step moves each hand by a bounded translation and rotation and
opens or closes its fingers. The episode succeeds when the object's centre of mass has been
lifted at least ``lift_height`` above its resting height and held there for ``hold_time`` while
both hands grasp it without slipping. Physics (the MJCF model) is in
:mod:`dg16m_env.physics.lift_scene`; this module is the task.

Optionally a *target dual grasp* of the benchmark (two hand poses in the object frame) is put in
the observation, which is what a grasp-conditioned policy needs: ``target_grasp="benchmark"`` or
``options={"target_grasp": ...}`` at reset (see *Target grasp*).

Frames and units
----------------
SI units (m, s, rad, N). World = table frame: ``z`` up, the table top is the plane ``z = 0``,
the table spans ``[-1, 1] x [-1, 1]`` m (:data:`~dg16m_env.physics.lift_scene.TABLE_HALF_SIZE`).
Hand frames are dg16m grasp frames (:mod:`dataset_gen.gripper`): ``+x`` closing axis, ``+y``
approach axis, origin at the flange; the *grasp centre* of a hand is the point between its pads,
``contact_depth`` (0.1034 m) along ``+y``. A 6D rotation is the first two columns of the rotation
matrix, ``[R[:, 0], R[:, 1]]`` (:func:`dg16m_env.envs.spaces.rotation_to_6d`).

Control
-------
Control rate :data:`CONTROL_HZ` = 20 Hz: each step runs ``0.05 s / timestep`` physics steps at
the benchmark's timestep (2 ms: 25 substeps). The hands are commanded through mocap targets
(standing for arms) to which they are welded (see :mod:`~dg16m_env.physics.lift_scene`); within a
step the targets move linearly (grasp centre) and at a constant angular rate (rotation) from
their pose to the new one.

Action space
------------
``Box(-1, 1, (14,), float32)``; indices ``7 k .. 7 k + 6`` belong to hand ``k`` (0, 1):

====================  ========================================================================
index (hand k)        meaning after scaling
====================  ========================================================================
``7k + 0 .. 7k + 2``  translation of the hand's grasp centre, world frame:
                      ``MAX_TRANSLATION * a`` = up to 0.02 m per axis per step
``7k + 3 .. 7k + 5``  rotation vector (axis-angle, world frame) applied about the grasp centre:
                      ``MAX_ROTATION * a`` = up to 0.1 rad per axis per step
``7k + 6``            finger force: ``a * squeeze_force`` N per finger (the benchmark's 70 N at
                      ``a = 1``); ``a > 0`` closes, ``a < 0`` opens, 0 leaves the fingers free
====================  ========================================================================

After each step's delta the commanded grasp centre is clipped to the workspace
``|x|, |y| <= HAND_WORKSPACE_XY`` (1.2 m), ``z <= HAND_WORKSPACE_TOP`` (1.5 m); then the
commanded pose is raised if needed so that no point of the hand (its collision boxes at any
finger opening) lies below ``z = TABLE_MARGIN`` (0.01 m above the table top). Hands never touch
the table nor each other (they are not simulated as colliding); they do collide with the object.
Actions must be real arrays of shape (14,) with finite values within the bounds (float32 or
float64); anything else raises ``ValueError`` naming the space.

Observation space
-----------------
``Box(low, high, (71,), float32)``, world frame unless noted (slices in :data:`OBS_SLICES`):

=======  ==========================  ============================================================
slice    name                        content (units)
=======  ==========================  ============================================================
0:3      ``object_position``         origin of the object frame (m)
3:9      ``object_rotation``         object frame rotation, 6D
9:12     ``object_linear_velocity``  velocity of the object frame origin (m/s)
12:15    ``object_angular_velocity`` angular velocity (rad/s)
15:33    ``hand_poses``              hand 0 then hand 1: flange position (m, 3) + 6D rotation (6)
33:35    ``finger_openings``         distance between each hand's inner finger faces (m, 0-0.08)
35:41    ``grasp_centres``           each hand's grasp centre minus ``object_position`` (m)
41:45    ``finger_contacts``         1 where finger i of hand k touches the object, else 0
                                     (order: h0 f0, h0 f1, h1 f0, h1 f1)
45:48    ``object_size``             side lengths of the object's bounding box, object frame (m)
48:51    ``object_box_centre``       centre of that box in the object frame (m)
51:52    ``lift``                    centre-of-mass height above its resting height (m)
52:70    ``target_poses``            target dual grasp, hand 0 then hand 1: flange position (m)
                                     + 6D rotation, at the object's current pose; zeros if none
70:71    ``target_flag``             1 if a target grasp is given, else 0
=======  ==========================  ============================================================

Observations are clipped to the space's finite bounds (positions +-5 m, velocities +-50).

Rewards
-------
The reward is the sum of the terms in ``info["reward_terms"]`` (a dict, always all keys, summed
in this order, so ``sum(info["reward_terms"].values()) == reward`` exactly):

* ``reach`` = ``-1.0 * mean_k d_k``: with a target, ``d_k`` is the distance (m) from hand k's
  grasp centre to the target's grasp centre k; without one, to the object's bounding box (object
  frame).
* ``align`` = ``-0.1 * mean_k theta_k`` with a target (0 without): ``theta_k`` is the angle (rad)
  between hand k's rotation and target k's, the smaller of the two jaw-symmetric targets (a
  parallel jaw turned by pi about its approach axis is the same grasp).
* ``grasp`` = ``+0.25`` per hand grasping the object (both its fingers touch the object).
* ``lift`` = ``+1.0 * clip(lift / lift_height, 0, 1)`` while both hands grasp, else 0.
* ``hold`` = ``+1.0`` while a hold (see *Success*) is under way.
* ``success`` = ``+10.0`` on the step the episode succeeds.
* ``failure`` = ``-10.0`` on the step the episode ends in failure.
* ``action`` = ``-0.01 * mean(a[motion]**2)`` over the 12 motion components (not the fingers).

Success and termination
-----------------------
A *hold* begins after a step where the object's centre of mass is at least ``lift_height``
(default 0.10 m) above its resting height and both hands grasp it (both fingers of each hand
touch it). It continues, step after step, while the object stays lifted and does not slip: the
displacement of the object's material points that sat at the hands' grasp centres when the hold
began, relative to those grasp centres now, stays below the benchmark protocol's
``max_displacement`` (0.02 m) at both hands (finger contacts may flicker meanwhile; slip is
measured at control steps). When a hold has lasted ``hold_time`` (default 1.0 s = 20 control
steps), ``info["success"]`` and ``info["is_success"]`` are True and the episode **terminates**. A
step that breaks the hold ends it; a new one may begin at once. The episode also terminates, as
a failure, when the object's centre of mass leaves the table's footprint (``|x|`` or ``|y|``
over 1 m: it fell off), rises above
:data:`~dg16m_env.envs.lift_measures.OBJECT_MAX_HEIGHT` or moves faster than
:data:`~dg16m_env.envs.lift_measures.OBJECT_MAX_SPEED` (thrown), or the
simulation becomes unstable; ``info["termination"]`` names the cause (``"success"``,
``"off_table"``, ``"out_of_bounds"``, ``"unstable"``, or ``""`` while running). Episodes are
truncated by the registered ``TimeLimit`` (200 steps = 10 s).

Target grasp
------------
A target is two hand poses in the object frame; the observation shows them at the object's
current pose (they move with the object). The dual grasp is unordered: at reset its hands are
listed so that target hand k is the one nearer hand k's start (smaller sum of grasp-centre
distances).

* ``target_grasp="benchmark"`` (env argument or reset option): each reset draws one of the
  object's benchmark rows that passed force closure with success probability ``p("full") >=
  0.5`` and whose open hands stay above the table in the resting pose (no hand point below
  ``TABLE_MARGIN``). The resting pose is drawn first, among the poses that have such a row
  (see *Randomisations*; if none of the most probable ones has, the most probable other pose
  that has), then the row, uniformly. An object with no such row in any stable pose (e.g. one
  without a force-closure pass of ``p >= 0.5``) is skipped when drawing, and naming it in
  ``options["object_id"]`` raises ``ValueError``.
* ``options={"target_grasp": row}``: a global row index of the benchmark; without
  ``options["object_id"]`` the object is that row's object.
* ``options={"target_grasp": poses}``: (2, 4, 4) rigid hand poses (gripper -> object frame, m).
* ``options={"target_grasp": None}`` or ``target_grasp=None`` (default): no target; the slot is
  zeros and the flag 0.

With a given target the resting pose is drawn among those where the target's hands stay above
the table; if there is none, the most probable drawn pose is used and
``info["target_above_table"]`` is False.

Randomisations (all from ``self.np_random``)
--------------------------------------------
The object (uniform over ``object_ids`` unless ``options["object_id"]``); its resting pose among
the :data:`STABLE_POSE_CHOICES` most probable stable poses of the convex hull of its simulated
parts (``trimesh``'s quasi-static probabilities, renormalised over the poses allowed), then a
yaw uniform in ``[-pi, pi)`` and an ``x, y`` offset uniform in ``+-OBJECT_OFFSET`` m; the hands:
hand 0 at a uniform azimuth around the object, hand 1 opposite it within +-45 degrees, each at a
horizontal distance from the centre of mass of the object's bounding radius plus
:data:`HAND_REACH` plus a clearance uniform in ``START_CLEARANCE`` (so no hand touches it), its
grasp centre at a height of ``u * top + v`` (``u`` uniform in ``[0.5, 1]``, ``top`` the
object's top, ``v`` uniform in ``START_HEIGHT``), its approach axis towards the object pitched
down by up to 45 degrees and rolled by up to 90 degrees either way, then raised if needed to
clear the table like a commanded pose; the benchmark target row when drawn. The object is then
settled for :data:`SETTLE_TIME` with the hands open (``info["settle_speed"]``, m/s).

Info
----
Reset: ``object_id``, ``stable_pose`` (index into the object's stable poses, most probable
first), ``target_row`` (benchmark row of the target, -1 if none or given as poses),
``target_above_table``, ``rest_height`` (resting centre-of-mass height, m), ``settle_speed``
(m/s), ``hands_clear`` (no hand touches the object), ``success`` / ``is_success`` (False).
Step: ``object_id``, ``success``, ``is_success``, ``termination``, ``reward_terms``, ``lift``
(m), ``hold_time`` (s of the current hold), ``slip`` ((2,) m, since the hold began),
``grasping`` ((2,) bool), ``target_row``.

Arguments
---------
* ``benchmark``: benchmark file or reference (default: the one shipped with dg16m).
* ``object_ids``: draw only among these objects (default: all).
* ``mesh_root``: folder of a mesh benchmark's meshes.
* ``target_grasp``: ``None`` (default) or ``"benchmark"`` (see *Target grasp*).
* ``lift_height``: required lift of the centre of mass (m, default 0.10).
* ``hold_time``: how long the lift must be held (s, default 1.0; 0 succeeds at once).
* ``render_mode``: ``None`` or ``"rgb_array"`` (an offscreen (height, width, 3) uint8 image).
* ``width``, ``height``: image size (pixels, default 480 x 360).

Reset options: ``object_id`` (str), ``target_grasp`` (see above).

Version history
---------------
* v0: initial. Later (same id, same default): `benchmark` also takes a shipped benchmark's
  short name (`"procedural"`, the default, or `"real"`: 300 furniture models, shipped since
  2026-12-03), and mesh benchmarks that carry their meshes need no `mesh_root`.
* v1 (2026-12-05, :mod:`dg16m_env.envs.dual_grasp_lift_v1`, ``dg16m_env/DualGraspLift-v1``):
  reward modes in which success is the best return (v0's dense reward pays a policy that lifts
  5 cm and hovers more than one that succeeds), observation modes with relative features,
  ``info["fail"]``, ``step()`` after the end refused, state save and restore, a target grasp by
  default. v0 stays registered unchanged (``gym.make`` notes that a newer version exists).
* v2 (2026-12-05, :mod:`dg16m_env.envs.dual_grasp_lift_v2`): v1's task on 5 ms physics steps,
  with compiled step arithmetic: about three times v0's steps per second.
"""

from __future__ import annotations

import math
import os
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import gymnasium
import mujoco
import numpy as np
from gymnasium import spaces

from dataset_gen.checks import check_number
from dg16m_env._compat import moved_names
from dg16m_env.benchmark.ref import BenchmarkRef
from dg16m_env.envs.common import RENDER_MODES, RenderModes, check_render_mode
from dg16m_env.envs.lift_measures import (  # the three constants: their old import path
    OBJECT_MAX_HEIGHT,  # noqa: F401
    OBJECT_MAX_SPEED,  # noqa: F401
    TERMINATIONS,  # noqa: F401
    Hold,
    LiftStepMeasures,
    measure_step,
)
from dg16m_env.envs.lift_reward import jaw_angle, reward_terms
from dg16m_env.envs.lift_spaces import (
    ACTION_SIZE,
    MAX_ROTATION,
    MAX_TRANSLATION,
    MOTION_COMPONENTS,
    OBS_LAYOUT,
    OBS_SIZE,
    OBS_SLICES,
    _right_matrix,
    check_lift_action,
)
from dg16m_env.envs.lift_targets import check_reset_options, parse_target_option
from dg16m_env.envs.objects import CACHE_SIZE, BenchmarkObjects
from dg16m_env.envs.spaces import rotation_to_6d
from dg16m_env.physics.lift_scene import (
    LiftScene,
    compile_lift_scene,
    hand_points,
    lowest_hand_z,
    part_points,
    stable_rest_poses,
    step_hand_targets,
)
from dg16m_env.physics.scene import quat_from_matrix, quat_to_matrix

CONTROL_HZ = 20
"""Control steps per second (each runs ``1 / (CONTROL_HZ * timestep)`` physics steps)."""

TABLE_MARGIN = 0.01
"""No point of a hand is commanded below this height above the table top (m)."""

HAND_WORKSPACE_XY = 1.2
"""Commanded grasp centres stay within ``|x|, |y| <=`` this (m)."""

HAND_WORKSPACE_TOP = 1.5
"""Commanded grasp centres stay below this height (m)."""

STABLE_POSE_CHOICES = 3
"""The resting pose is drawn among this many most probable stable poses."""

OBJECT_OFFSET = 0.05
"""Largest ``x`` / ``y`` offset of the resting object from the table centre (m)."""

START_CLEARANCE = (0.05, 0.15)
"""Range of the hands' start clearance beyond the object's bounding radius plus reach (m)."""

START_HEIGHT = (0.05, 0.15)
"""Range of the height added to the start grasp centres (m; see *Randomisations*)."""

HAND_REACH = 0.16
"""Radius about the grasp centre holding the whole Panda hand (m)."""

SETTLE_TIME = 0.2
"""Simulated time the object settles at reset, hands open and away (s)."""

TARGET_MIN_P = 0.5
"""Benchmark target rows need ``p("full") >=`` this (and a force-closure pass)."""


# --------------------------------------------------------------------------------------------
# Per-object data (cached)
# --------------------------------------------------------------------------------------------


@dataclass
class _LiftObject:
    """What a reset needs of one object: compiled scene, reusable data, resting poses, bounds."""

    scene: LiftScene
    data: mujoco.MjData
    rest_poses: np.ndarray  # (n, 4, 4), most probable first
    rest_probabilities: np.ndarray  # (n,)
    points: np.ndarray  # (P, 3) hull points of the parts, object frame
    box_low: np.ndarray  # (3,) bounding box of the parts, object frame
    box_high: np.ndarray
    target_rows: np.ndarray  # benchmark rows eligible as targets (before the table rule)
    feasible: dict[int, np.ndarray] = field(default_factory=dict)  # pose -> rows above table


def use_timestep(env: DualGraspLiftEnv, timestep: float) -> None:
    """Make ``env`` (before its first reset: scenes are compiled then) step MuJoCo at
    ``timestep`` (s): the control rate stays :data:`CONTROL_HZ`, the physics steps per control
    step and the hold's length in steps follow."""
    env.scene_parameters = replace(env.scene_parameters, timestep=timestep)
    env.timestep = timestep
    env.substeps = max(1, round(1.0 / (CONTROL_HZ * timestep)))
    env.control_dt = env.substeps * timestep
    env._fractions = np.arange(1, env.substeps + 1, dtype=np.float64) / env.substeps
    env._fraction_column = env._fractions[:, None, None]  # (n, 1, 1), for the substeps
    env.hold_steps = math.ceil(env.hold_time / env.control_dt - 1e-9)


class DualGraspLiftEnv(RenderModes, gymnasium.Env[np.ndarray, np.ndarray]):
    """Two floating Panda hands lift a benchmark object from a table (see the module docstring:
    spaces, rewards, success, randomisations, arguments)."""

    METADATA: ClassVar[dict[str, Any]] = {
        "render_modes": list(RENDER_MODES),
        "render_fps": CONTROL_HZ,
    }

    def __init__(
        self,
        benchmark: str | os.PathLike[str] | BenchmarkRef | None = None,
        object_ids: Sequence[str] | None = None,
        mesh_root: str | os.PathLike[str] | None = None,
        target_grasp: str | None = None,
        lift_height: float = 0.10,
        hold_time: float = 1.0,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 360,
    ) -> None:
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
        self.objects = BenchmarkObjects(benchmark, object_ids, mesh_root)
        parameters = self.objects.parameters
        self.scene_parameters = parameters.scene
        self.gravity = float(parameters.protocol.gravity)
        self.max_slip = float(parameters.protocol.max_displacement)
        use_timestep(self, float(parameters.scene.timestep))
        self._hand_points = hand_points()
        self._clip_points: tuple[float, np.ndarray] | None = None  # depth, hand points - depth y
        self._bench = self.objects.ref.benchmark
        self._p_full = self._bench.p("full")

        low = np.concatenate([np.full(size, lo) for _, size, lo, _ in OBS_LAYOUT])
        high = np.concatenate([np.full(size, hi) for _, size, _, hi in OBS_LAYOUT])
        self.observation_space = spaces.Box(low.astype(np.float32), high.astype(np.float32))
        self.action_space = spaces.Box(-1.0, 1.0, (ACTION_SIZE,), dtype=np.float32)
        self._obs_low, self._obs_high = self.observation_space.low, self.observation_space.high

        self._cache: OrderedDict[str, _LiftObject] = OrderedDict()
        self._current: _LiftObject | None = None
        self._renderer: Any = None
        self._renderer_model: mujoco.MjModel | None = None
        self._camera: mujoco.MjvCamera | None = None
        self._reset_state()

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

    def _object(self, object_id: str) -> _LiftObject:
        if object_id in self._cache:
            self._cache.move_to_end(object_id)
            return self._cache[object_id]
        obj = self.objects.load(object_id)
        stored = self.objects.benchmark_object(object_id)
        scene = compile_lift_scene(
            obj, params=self.scene_parameters, parts=stored.parts, gravity=self.gravity
        )
        poses, probabilities = stable_rest_poses(obj, stored.parts)
        points = part_points(stored.parts)
        rows = self.objects.rows(object_id)
        eligible = rows[self._bench.fc_passed[rows] & (self._p_full[rows] >= TARGET_MIN_P)]
        item = _LiftObject(
            scene=scene,
            data=mujoco.MjData(scene.model),
            rest_poses=poses,
            rest_probabilities=probabilities,
            points=points,
            box_low=points.min(axis=0),
            box_high=points.max(axis=0),
            target_rows=eligible,
        )
        self._cache[object_id] = item
        while len(self._cache) > CACHE_SIZE:
            self._cache.popitem(last=False)
        return item

    def _above_table(self, rest_pose: np.ndarray, grasps: np.ndarray) -> np.ndarray:
        """(N,) whether both hands of (N, 2, 4, 4) object-frame grasps stay above the table
        (``TABLE_MARGIN``) with the object at ``rest_pose``."""
        world = rest_pose @ grasps
        return (lowest_hand_z(world, self._hand_points) >= TABLE_MARGIN).all(axis=-1)

    def _feasible_rows(self, item: _LiftObject, pose: int) -> np.ndarray:
        if pose not in item.feasible:
            rows = item.target_rows
            ok = self._above_table(item.rest_poses[pose], self._bench.poses[rows])
            item.feasible[pose] = rows[ok]
        return item.feasible[pose]

    def _pose_order(self, item: _LiftObject) -> list[int]:
        """Stable-pose indices: the top choices in a drawn order, then the rest by probability."""
        top = min(STABLE_POSE_CHOICES, len(item.rest_poses))
        weights = item.rest_probabilities[:top]
        weights = weights / weights.sum() if weights.sum() > 0 else np.full(top, 1.0 / top)
        drawn = self.np_random.choice(top, size=top, replace=False, p=weights)
        return [int(i) for i in drawn] + list(range(top, len(item.rest_poses)))

    # ----------------------------------------------------------------------------------------
    # Target grasps
    # ----------------------------------------------------------------------------------------

    def _choose(
        self, kind: Any, object_id: str | None
    ) -> tuple[str, _LiftObject, int, np.ndarray | None, int, bool]:
        """Object, its data, resting pose index, target grasp (object frame) or None, target
        row (-1 if none) and whether the target stays above the table."""
        if not isinstance(kind, str):  # None, a row or poses
            object_id = self.objects.choose(self.np_random, object_id)
            item = self._object(object_id)
            order = self._pose_order(item)
            if kind is None:
                return object_id, item, order[0], None, -1, True
            row = kind if isinstance(kind, int) else -1
            grasp = self._bench.poses[row].copy() if row >= 0 else kind
            for pose in order:
                if self._above_table(item.rest_poses[pose], grasp[None])[0]:
                    return object_id, item, pose, grasp, row, True
            return object_id, item, order[0], grasp, row, False
        given = object_id is not None
        tried: set[str] = set()
        while True:
            object_id = self.objects.choose(self.np_random, object_id if given else None)
            item = self._object(object_id)
            for pose in self._pose_order(item):
                rows = self._feasible_rows(item, pose)
                if rows.size:
                    row = int(rows[self.np_random.integers(rows.size)])
                    return object_id, item, pose, self._bench.poses[row].copy(), row, True
            tried.add(object_id)
            if given or tried >= set(self.objects.object_ids):
                raise ValueError(
                    f"target_grasp='benchmark': expected an object with a benchmark dual grasp "
                    f"(force-closure pass, p >= {TARGET_MIN_P}) whose hands stay above the table "
                    f"in a stable pose, found none for {sorted(tried)[:5]}"
                )

    # ----------------------------------------------------------------------------------------
    # Gymnasium API
    # ----------------------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        opts = check_reset_options(options)
        requested = opts.get("object_id")
        if requested is not None and not isinstance(requested, str):
            raise ValueError(f"options['object_id']: expected a string, found {requested!r}")
        target = opts.get("target_grasp", self.target_mode)
        kind, requested = parse_target_option(target, requested, self._bench)
        self._reset_state()
        object_id, item, pose_index, grasp, row, above = self._choose(kind, requested)
        self.object_id, self._current = object_id, item
        scene, data = item.scene, item.data
        rng = self.np_random

        # The object at rest: stable pose, then a yaw and an offset on the table.
        yaw = rng.uniform(-math.pi, math.pi)
        offset = rng.uniform(-OBJECT_OFFSET, OBJECT_OFFSET, size=2)
        turn = np.eye(4)
        turn[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
        turn[:2, 3] = offset
        rest = turn @ item.rest_poses[pose_index]
        world_points = item.points @ rest[:3, :3].T + rest[:3, 3]
        com = rest[:3, :3] @ self.objects.load(object_id).mass_properties.center_of_mass
        com = com + rest[:3, 3]
        radius = float(np.linalg.norm(world_points[:, :2] - com[:2], axis=1).max())
        top = float(world_points[:, 2].max())

        # The hands: opposite sides, clear of the object's bounding cylinder.
        azimuth = rng.uniform(0.0, 2.0 * math.pi)
        azimuths = (azimuth, azimuth + math.pi + rng.uniform(-math.pi / 4, math.pi / 4))
        centres, rotations = np.zeros((2, 3)), np.zeros((2, 3, 3))
        for k, phi in enumerate(azimuths):
            distance = radius + HAND_REACH + rng.uniform(*START_CLEARANCE)
            height = top * rng.uniform(0.5, 1.0) + rng.uniform(*START_HEIGHT)
            direction = np.array([math.cos(phi), math.sin(phi), 0.0])
            centres[k] = com + distance * direction
            centres[k, 2] = height
            pitch = rng.uniform(0.0, math.pi / 4)
            roll = rng.uniform(-math.pi / 2, math.pi / 2)
            approach = -direction * math.cos(pitch) + np.array([0.0, 0.0, -math.sin(pitch)])
            side = np.cross(approach, [0.0, 0.0, 1.0])
            side /= np.linalg.norm(side)
            normal = np.cross(side, approach)
            closing = math.cos(roll) * side + math.sin(roll) * normal
            rotations[k] = np.column_stack([closing, approach, np.cross(closing, approach)])
        self._set_command(centres, rotations)

        if grasp is not None:  # list the target's hands so hand k goes to the nearer one
            depth = scene.gripper.contact_depth
            goal = (rest @ grasp)[:, :3, 3] + depth * (rest @ grasp)[:, :3, 1]
            straight = np.linalg.norm(goal - self._target_pos, axis=1).sum()
            swapped = np.linalg.norm(goal[::-1] - self._target_pos, axis=1).sum()
            if swapped < straight:
                grasp = grasp[::-1].copy()
        self._grasp, self._target_row = grasp, row

        mujoco.mj_resetData(scene.model, data)
        data.qpos[scene.object_qpos] = np.concatenate([rest[:3, 3], quat_from_matrix(rest[:3, :3])])
        self._place_hands(data, scene)
        data.ctrl[scene.squeeze_actuators] = -scene.params.squeeze_force  # open
        mujoco.mj_forward(scene.model, data)
        mujoco.mj_step(scene.model, data, nstep=max(1, round(SETTLE_TIME / self.timestep)))
        data.time = 0.0
        self._rest_com_z = float(data.xipos[scene.object_body, 2])
        settle_speed = float(np.linalg.norm(data.qvel[scene.object_qvel][:3]))
        observation = self._observation()
        info = {
            "object_id": object_id,
            "stable_pose": pose_index,
            "target_row": row,
            "target_above_table": bool(above),
            "rest_height": self._rest_com_z,
            "settle_speed": settle_speed,
            "hands_clear": bool(np.all(data.sensordata[scene.hand_contacts] == 0)),
            "success": False,
            "is_success": False,
        }
        if self.render_mode == "rgb_array":
            self._camera = None  # re-aim at the new object
        return observation, info

    def _set_command(self, centres: np.ndarray, rotations: np.ndarray) -> None:
        self._target_quat = quat_from_matrix(rotations)
        self._target_rot = quat_to_matrix(self._target_quat)
        self._target_pos = self._clip_command(np.asarray(centres, np.float64), self._target_rot)

    def _flanges(self, centres: np.ndarray, rotations: np.ndarray) -> np.ndarray:
        """Flange positions (..., 3) of hands whose grasp centres and rotations are given."""
        assert self._current is not None
        return centres - self._current.scene.gripper.contact_depth * rotations[..., :, 1]

    def _place_hands(self, data: mujoco.MjData, scene: LiftScene) -> None:
        """Targets and hands at the commanded poses, at rest, fingers open."""
        flanges = self._flanges(self._target_pos, self._target_rot)
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

    def _clip_command(self, centres: np.ndarray, rotations: np.ndarray) -> np.ndarray:
        """Grasp centres inside the workspace and hands above the table (module docstring)."""
        centres = centres.copy()
        centres[:, :2] = np.clip(centres[:, :2], -HAND_WORKSPACE_XY, HAND_WORKSPACE_XY)
        centres[:, 2] = np.minimum(centres[:, 2], HAND_WORKSPACE_TOP)
        assert self._current is not None
        local = self._clip_local_points()
        lowest = (rotations[:, 2, :] @ local.T).min(axis=1)
        centres[:, 2] = np.maximum(centres[:, 2], TABLE_MARGIN - lowest)
        return centres

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._current is None:
            raise RuntimeError("step: expected reset() before step(), found no episode")
        values = self._check_action(action)
        scene, data = self._current.scene, self._current.data
        targets, centres, rotations, final = self._hand_targets(values)
        data.ctrl[scene.squeeze_actuators] = values[6::7] * scene.params.squeeze_force
        unstable = step_hand_targets(scene.model, data, targets)
        self._target_pos, self._target_rot, self._target_quat = centres, rotations, final
        return self._transition(values, unstable)

    def _hand_targets(
        self, values: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One control step's hand targets (module docstring, *Actions*): ``(n, 14)`` substep
        rows for :func:`~dg16m_env.physics.lift_scene.step_hand_targets`, and the commanded
        grasp centres (2, 3), rotations (2, 3, 3) and unit quaternions (2, 4) after the step."""
        assert self._current is not None
        scene = self._current.scene

        # The same operations as the plain formulas in the comments, on views and reused
        # arrays (bit for bit the same; bench/env_lift.py measures the difference).
        pairs = values.reshape(2, 7)  # one row per hand
        moves = pairs[:, 0:3] * MAX_TRANSLATION  # values[[0, 1, 2, 7, 8, 9]].reshape(2, 3) * ..
        turns = pairs[:, 3:6] * MAX_ROTATION  # values[[3, 4, 5, 10, 11, 12]].reshape(2, 3) * ..
        start_centres, start_quat = self._target_pos, self._target_quat

        # Substep targets: rotations at a constant rate (the quaternion is the commanded
        # rotation's one source), grasp centres linear in time.
        n, fraction = self.substeps, self._fractions
        angle = np.sqrt(np.sum(turns * turns, axis=1))  # (2,)
        axis = turns / np.maximum(angle, 1e-300)[:, None]
        half = np.multiply.outer(fraction, 0.5 * angle)  # (n, 2)
        delta = np.empty((n, 2, 4))
        delta[..., 0] = np.cos(half)
        delta[..., 1:] = np.sin(half)[..., None] * axis
        quats = np.empty((n, 2, 4))
        for k in range(2):  # delta ⊗ q0, with q0's right-multiplication matrix
            quats[:, k] = delta[:, k] @ _right_matrix(start_quat[k]).T
        final = quats[-1] / np.sqrt(np.sum(quats[-1] * quats[-1], axis=1))[:, None]
        rotations = np.empty((2, 9))
        for k in range(2):
            mujoco.mju_quat2Mat(rotations[k], final[k])
        rotations = rotations.reshape(2, 3, 3)
        centres = self._clip_command(start_centres + moves, rotations)
        path = start_centres + self._fraction_column * (centres - start_centres)  # (n, 2, 3)
        # Approach axis R[:, 1] of each substep quaternion (w, x, y, z); MuJoCo normalises
        # mocap quaternions itself. Each substep's hand targets (mocap ids 0, 1 = hands) are
        # one row of ``targets``: both flanges, then both quaternions (mjSTATE_MOCAP_POS, _QUAT).
        w, x, y, z = quats[..., 0], quats[..., 1], quats[..., 2], quats[..., 3]
        approach = np.empty((n, 2, 3))
        approach[..., 0] = 2.0 * (x * y - w * z)
        approach[..., 1] = 1.0 - 2.0 * (x * x + z * z)
        approach[..., 2] = 2.0 * (y * z + w * x)
        flanges = path - scene.gripper.contact_depth * approach
        targets = np.concatenate([flanges.reshape(n, 6), quats.reshape(n, 8)], axis=1)
        return targets, centres, rotations, final

    def _measure(self, unstable: bool) -> LiftStepMeasures:
        """What the step did: lift, grasps, hold (updated here), termination, reach and angle."""
        assert self._current is not None
        scene, data = self._current.scene, self._current.data
        body = scene.object_body
        com = data.xipos[body]
        lift = float(com[2] - self._rest_com_z)
        grasping = (data.sensordata[scene.finger_contacts] > 0).all(axis=1)  # (2,)
        centres = self._hand_centres(data, scene)
        obj_pos, obj_rot = data.xpos[body], data.xmat[body].reshape(3, 3)
        speed = float(np.linalg.norm(data.qvel[scene.object_qvel][:3])) if not unstable else 0.0
        if self._grasp is not None:
            goal = self._target_world(obj_pos, obj_rot)
            depth = scene.gripper.contact_depth
            goal_centres = goal[:, :3, 3] + depth * goal[:, :3, 1]
            distance = np.linalg.norm(centres - goal_centres, axis=1)
            hands = data.xmat[scene.hand_bodies].reshape(2, 3, 3)
            angle: float | None = float(jaw_angle(hands, goal[:, :3, :3]).mean())
        else:
            local = (centres - obj_pos) @ obj_rot
            nearest = np.clip(local, self._current.box_low, self._current.box_high)
            distance = np.linalg.norm(local - nearest, axis=1)
            angle = None
        hold, measures = measure_step(  # module docstring, *Success* and *Termination*
            Hold(self._hold_anchor, self._hold_count),
            unstable=unstable,
            lift=lift,
            lift_height=self.lift_height,
            hold_steps=self.hold_steps,
            max_slip=self.max_slip,
            grasping=grasping,
            centres=centres,
            obj_pos=obj_pos,
            obj_rot=obj_rot,
            com=com,
            speed=speed,
            reach_distance=float(distance.mean()),
            jaw_angle=angle,
        )
        self._hold_anchor, self._hold_count = hold.anchor, hold.count
        return measures

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

    def _transition(
        self, values: np.ndarray, unstable: bool
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        m = self._measure(unstable)
        terms = reward_terms(  # module docstring, :mod:`dg16m_env.envs.lift_reward`
            reach_distance=m.reach_distance,
            jaw_angle=m.jaw_angle,
            hands_grasping=int(m.grasping.sum()),
            both_grasping=bool(m.grasping.all()),
            lift=m.lift,
            lift_height=self.lift_height,
            holding=m.holding,
            success=m.success,
            failure=m.termination not in ("", "success"),
            motion=values[MOTION_COMPONENTS],
            unstable=unstable,
        )
        reward = float(sum(terms.values()))
        return self._observation(), reward, m.termination != "", False, self._step_info(m, terms)

    # ----------------------------------------------------------------------------------------
    # Observation
    # ----------------------------------------------------------------------------------------

    def _hand_centres(self, data: mujoco.MjData, scene: LiftScene) -> np.ndarray:
        rotations = data.xmat[scene.hand_bodies].reshape(2, 3, 3)
        return data.xpos[scene.hand_bodies] + scene.gripper.contact_depth * rotations[:, :, 1]

    def _target_world(self, obj_pos: np.ndarray, obj_rot: np.ndarray) -> np.ndarray:
        """(2, 4, 4) the target grasp at the object's current pose."""
        assert self._grasp is not None
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = obj_rot, obj_pos
        return pose @ self._grasp

    def _observation(self) -> np.ndarray:
        assert self._current is not None
        scene, data = self._current.scene, self._current.data
        body = scene.object_body
        obj_pos, obj_rot = data.xpos[body], data.xmat[body].reshape(3, 3)
        velocity = data.qvel[scene.object_qvel]
        hands = data.xmat[scene.hand_bodies].reshape(2, 3, 3)
        hand_pos = data.xpos[scene.hand_bodies]
        centres = hand_pos + scene.gripper.contact_depth * hands[:, :, 1]
        travel = data.qpos[scene.finger_qpos].sum(axis=1)
        obs = np.zeros(OBS_SIZE)
        s = OBS_SLICES
        obs[s["object_position"]] = obj_pos
        obs[s["object_rotation"]] = rotation_to_6d(obj_rot)
        obs[s["object_linear_velocity"]] = velocity[:3]
        obs[s["object_angular_velocity"]] = obj_rot @ velocity[3:]
        obs[s["hand_poses"]] = np.concatenate([hand_pos, rotation_to_6d(hands)], axis=1).ravel()
        obs[s["finger_openings"]] = scene.gripper.max_opening - travel
        obs[s["grasp_centres"]] = (centres - obj_pos).ravel()
        obs[s["finger_contacts"]] = (data.sensordata[scene.finger_contacts] > 0).ravel()
        obs[s["object_size"]] = self._current.box_high - self._current.box_low
        obs[s["object_box_centre"]] = 0.5 * (self._current.box_high + self._current.box_low)
        obs[s["lift"]] = data.xipos[body, 2] - self._rest_com_z
        if self._grasp is not None:
            goal = self._target_world(obj_pos, obj_rot)
            obs[s["target_poses"]] = np.concatenate(
                [goal[:, :3, 3], rotation_to_6d(goal[:, :3, :3])], axis=1
            ).ravel()
            obs[s["target_flag"]] = 1.0
        return np.clip(obs.astype(np.float32), self._obs_low, self._obs_high)

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

    render_shadow_size: int | None = None
    """Side of the lights' shadow maps when rendering (pixels); None: the model's (4096)."""

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
            self._renderer_model = None
        super().close()


# ScriptedLiftPolicy and PREGRASP_DISTANCE moved to lift_expert, REWARD_WEIGHTS to lift_reward
# (0.2.0): the old names still work here for one release, with a DeprecationWarning.
__getattr__ = moved_names(__name__)
