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
Hand frames are dg16m grasp frames (:mod:`dataset_gen.grasps.gripper`): ``+x`` closing axis, ``+y``
approach axis, origin at the flange; the *grasp centre* of a hand is the point between its pads,
``contact_depth`` (0.1034 m) along ``+y``. A 6D rotation is the first two columns of the rotation
matrix, ``[R[:, 0], R[:, 1]]`` (:func:`dg16m_env.envs.spaces.rotation_to_6d`).

Control
-------
Control rate :data:`~.scenes.CONTROL_HZ` = 20 Hz: each step runs ``0.05 s / timestep`` physics steps
at the benchmark's timestep (2 ms: 25 substeps). The hands are commanded through mocap targets
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
``Box(low, high, (71,), float32)``, world frame unless noted (slices in
:data:`~.spaces.OBS_SLICES`):

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
:data:`~dg16m_env.envs.lift.measures.OBJECT_MAX_HEIGHT` or moves faster than
:data:`~dg16m_env.envs.lift.measures.OBJECT_MAX_SPEED` (thrown), or the
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
the :data:`~.scenes.STABLE_POSE_CHOICES` most probable stable poses of the convex hull of its
simulated parts (``trimesh``'s quasi-static probabilities, renormalised over the poses allowed),
then a yaw uniform in ``[-pi, pi)`` and an ``x, y`` offset uniform in ``+-OBJECT_OFFSET`` m; the
hands: hand 0 at a uniform azimuth around the object, hand 1 opposite it within +-45 degrees, each
at a horizontal distance from the centre of mass of the object's bounding radius plus
:data:`~.scenes.HAND_REACH` plus a clearance uniform in ``START_CLEARANCE`` (so no hand touches it),
its grasp centre at a height of ``u * top + v`` (``u`` uniform in ``[0.5, 1]``, ``top`` the
object's top, ``v`` uniform in ``START_HEIGHT``), its approach axis towards the object pitched
down by up to 45 degrees and rolled by up to 90 degrees either way, then raised if needed to
clear the table like a commanded pose; the benchmark target row when drawn. The object is then
settled for :data:`~.scenes.SETTLE_TIME` with the hands open (``info["settle_speed"]``, m/s).

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
  2026-12-03), and mesh benchmarks that carry their meshes need no `mesh_root`. Deprecated
  (0.2.0): ``gym.make`` raises a ``DeprecationWarning`` that names the reward's flaw (a policy
  that lifts 5 cm and hovers out-earns one that succeeds); the id is removed in 0.3.0. The
  task's code moved to :mod:`dg16m_env.envs.lift` (one class for every version, this one its
  :data:`~dg16m_env.envs.lift.versions.V0` record; same episodes, bit for bit).
* v1 (2026-12-05, :mod:`dg16m_env.envs.lift.v1`, ``dg16m_env/DualGraspLift-v1``):
  reward modes in which success is the best return (v0's dense reward pays a policy that lifts
  5 cm and hovers more than one that succeeds), observation modes with relative features,
  ``info["fail"]``, ``step()`` after the end refused, state save and restore, a target grasp by
  default. v0 stays registered unchanged (``gym.make`` notes that a newer version exists).
* v2 (2026-12-05, :mod:`dg16m_env.envs.lift.v2`): v1's task on 5 ms physics steps,
  with compiled step arithmetic: about three times v0's steps per second.
"""

from __future__ import annotations

from dg16m_env.envs.lift.task import LiftEnv
from dg16m_env.envs.lift.versions import V0


class DualGraspLiftEnv(LiftEnv):
    """``dg16m_env/DualGraspLift-v0``: :class:`~dg16m_env.envs.lift.task.LiftEnv` with the
    :data:`~dg16m_env.envs.lift.versions.V0` record (deprecated; see the module docstring)."""

    version = V0
