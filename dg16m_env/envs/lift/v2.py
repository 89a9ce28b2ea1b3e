"""``dg16m_env/DualGraspLift-v2``: the Lift task of v1 on 5 ms physics steps, about three times
as many steps per second.

The task: two floating Franka Panda hands, standing for arms, lift a benchmark object from a
table and hold it. At reset the object rests on the table in one of its stable poses and the
hands start open, on roughly opposite sides of it; each 50 ms control step (20 Hz) moves each
hand by a bounded translation and rotation and opens or closes its fingers. By default each
episode also draws a *target dual grasp* of the benchmark (``target_grasp="benchmark"``), shown
in the observation at the object's current pose: the task is to carry it out and lift. This
page states the whole interface (action, success, reward, observation, arguments, info); the
task's geometry, the target grasp's draw and the randomisations are v0's
(:mod:`dg16m_env.envs.lift.v0`, unchanged since). v2 is v1's task (same spaces, rewards and
success rule) computed differently:

* **Physics**: MuJoCo steps of :data:`PHYSICS_TIMESTEP` = 5 ms, 10 per control step (v0, v1:
  the benchmark's 2 ms, 25 per step). Contacts keep their time constant of two physics steps
  (``solref = [2 * timestep, 1]``: 10 ms instead of 4 ms), so they are a little softer. On the
  same seeded episodes of the held-out objects the feedback expert succeeds as on v1 (74.5%
  against 73.5% of 200 procedural episodes, 72 against 77% of 100 real ones, within the
  intervals; BENCHMARKS.md), no episode ended unstable, and the physics costs 0.45 of v1's.
* **Speed**: 2,589-3,081 random-action steps per second on one quiet core, against v0's
  1,119-1,132 and v1's 931-1,010 in the same runs (``bench/env_lift.py --versions 6``).
* **Arithmetic**: a step's hand targets and its observation are computed by two compiled
  functions (:mod:`dg16m_env.envs.lift.kernels`) instead of a few hundred numpy operations;
  they agree with v1's formulas to rounding (within 1e-9, ``tests/test_lift_v2.py``), not bit
  for bit.

``gym.make_vec("dg16m_env/DualGraspLift-v2", num_envs=N)`` gives a
:class:`~dg16m_env.envs.lift.vector.LiftVectorEnv`: the N environments in blocks stepped by
``workers`` processes, the calling one included, one message per worker per step (Gymnasium's
``AsyncVectorEnv``, one message per environment, spent as long on the messages as on v2's
steps); ``vectorization_mode="sync"`` or ``"async"`` give Gymnasium's own.

A v1 policy runs on v2 unchanged (same spaces); its success rate can differ a little, since
the hands and object move slightly differently. Demonstrations and replays are per version:
``dg16m demos collect --env-id dg16m_env/DualGraspLift-v2``.

Action space
------------
``Box(-1, 1, (14,), float32)``; indices ``7 k .. 7 k + 6`` belong to hand ``k`` (0, 1):
``7k + 0 .. 7k + 2`` translate the hand's grasp centre (world frame, up to 0.02 m per axis per
step), ``7k + 3 .. 7k + 5`` rotate it about the grasp centre (a rotation vector, up to 0.1 rad
per axis per step), ``7k + 6`` is the finger force (``a * squeeze_force``, the benchmark's
70 N at ``a = 1``; ``a > 0`` closes, ``a < 0`` opens, 0 leaves the fingers free). The commanded
pose is kept in the workspace and above the table (v0's *Action space*). Actions outside the
space raise ``ValueError``.

Success and termination
-----------------------
A *hold* begins on a step on which the object's centre of mass is at least ``lift_height``
(0.10 m) above its resting height and both hands grasp it (both fingers of each touch it). It
goes on while the object stays lifted and neither hand's grasp centre moves more than the
benchmark's ``max_displacement`` (0.02 m) against the object (contacts may flicker). When a
hold has lasted ``hold_time`` (1 s = 20 steps) the episode succeeds (``info["success"]``) and
terminates, even if the hands have just let go (v3, :mod:`dg16m_env.envs.lift.v3`, also needs
both hands grasping on that step). It terminates as a failure (``info["fail"]``) when the
object leaves the table (``"off_table"``), rises above 2 m or moves faster than 10 m/s
(``"out_of_bounds"``), or the physics diverges (``"unstable"``); ``info["termination"]`` names
the cause. The env truncates the episode after ``episode_steps`` (200) steps; ``step()`` after
the end raises ``RuntimeError`` until ``reset()``.

Rewards
-------
``reward_mode`` (default ``"dense"``); the reward is the sum of ``info["reward_terms"]``.

* ``"dense"``: on a step that does not succeed, all terms are >= 0 and sum to at most
  ``R = MAX_STEP_REWARD`` = 5 (:func:`~dg16m_env.envs.lift.reward.dense_terms`):
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
:func:`~dg16m_env.envs.lift.observations.observation_space`):

* ``"state"``: ``Box((117,), float32)``, world frame, the parts of
  :data:`~dg16m_env.envs.lift.observations.STATE_LAYOUT` in order:

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
* ``benchmark``: benchmark file or reference (default: the one shipped with dg16m);
  ``object_ids``: draw only among these objects (default: all); ``mesh_root``: folder of a mesh
  benchmark's meshes.
* ``target_grasp``: ``"benchmark"`` (default: each reset draws a benchmark dual grasp of the
  object that passed force closure with ``p("full") >= 0.5``) or ``None`` (no target; its
  observation slots are 0). Reset options: ``object_id``, and ``target_grasp`` (a benchmark
  row, (2, 4, 4) hand poses in the object frame, or None).
* ``reward_mode``: ``"dense"`` (default), ``"normalized_dense"`` or ``"sparse"``;
  ``obs_mode``: ``"state"`` (default), ``"state_dict"`` or ``"pointcloud"``; ``n_points``
  (512), ``n_cameras`` (1 or 2), ``camera_resolution`` (128 pixels): the cloud's.
* ``lift_height`` (0.10 m) and ``hold_time`` (1.0 s): the success rule's.
* ``episode_steps``: ``T``, the steps after which the env truncates the episode itself (200 =
  10 s at 20 Hz, the registered ``max_episode_steps``); it sets the reward bound and the
  ``elapsed`` fraction. For a longer episode give ``gym.make(..., episode_steps=N,
  max_episode_steps=N)`` (Gymnasium's ``TimeLimit`` would cut it at 200).
* ``render_mode``: ``None`` or ``"rgb_array"``; ``width``, ``height``: image size (480 x 360).

A keyword the version does not take raises ``TypeError`` naming the class, the id and the
nearest keyword.

Info
----
Reset: ``object_id``, ``stable_pose`` (index into the object's stable poses, most probable
first), ``target_row`` (benchmark row of the target, -1 if none or given as poses),
``target_above_table``, ``rest_height`` (resting centre-of-mass height, m), ``settle_speed``
(m/s), ``hands_clear`` (no hand touches the object), ``success`` / ``is_success`` (False),
``fail`` (False), ``elapsed_steps`` (0). Step: ``object_id``, ``success``, ``is_success``,
``termination``, ``reward_terms``, ``lift`` (m), ``hold_time`` (s of the current hold),
``slip`` ((2,) m, since the hold began), ``grasping`` ((2,) bool: each hand touches the object
with both fingers), ``target_row``, ``fail`` (the episode ended in failure on this step) and
``elapsed_steps``.

State save and restore
----------------------
:meth:`~dg16m_env.envs.lift.task.LiftEnv.get_state` /
:meth:`~dg16m_env.envs.lift.task.LiftEnv.set_state` restore a simulation exactly (same machine
and build): the steps after a restore give the same bytes.

Version history
---------------
* v3 (2026-12-06): success also needs both hands grasping on the step it is credited (in v2 a
  hold could be credited two steps after both hands opened); the point cloud's ``points`` and
  ``normals`` flat (:mod:`dg16m_env.envs.lift.v3`). v2 is unchanged and still registered.
* v2 (2026-12-05): 5 ms physics steps (10 per control step), compiled step arithmetic,
  :class:`~dg16m_env.envs.lift.vector.LiftVectorEnv` as ``gym.make_vec``'s default. Later
  (0.2.0, same id, same episodes bit for bit): the task's code is one class for every version
  (:mod:`dg16m_env.envs.lift.task`; this version its :data:`~dg16m_env.envs.lift.versions.V2`
  record); a keyword it does not take raises a ``TypeError`` that names this class, the id and
  the nearest keyword (2026-12-06; it named ``LiftEnv``'s ``__init__``).
* v1 (2026-12-05): reward and observation modes, success-dominant rewards, state save and
  restore, a target grasp by default (:mod:`dg16m_env.envs.lift.v1`).
* v0: the first closed-loop task (:mod:`dg16m_env.envs.lift.v0`; deprecated).
"""

from __future__ import annotations

from dg16m_env.envs.lift.task import LiftEnv
from dg16m_env.envs.lift.versions import V2

PHYSICS_TIMESTEP = V2.physics_timestep
"""MuJoCo's timestep in v2 (s; 10 physics steps per 50 ms control step)."""


class DualGraspLiftV2Env(LiftEnv):
    """``dg16m_env/DualGraspLift-v2``: :class:`~dg16m_env.envs.lift.task.LiftEnv` with the
    :data:`~dg16m_env.envs.lift.versions.V2` record (see the module docstring)."""

    version = V2
