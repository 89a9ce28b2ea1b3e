"""``dg16m_env/DualGraspLift-v3``: v2's Lift task whose success needs the grasp held on the step
it is credited. The newest version, and the one to use for new work.

Physics, action space and randomisations are v0's (:mod:`dg16m_env.envs.lift.v0`); the 5 ms
physics steps, compiled arithmetic and vector env are v2's (:mod:`dg16m_env.envs.lift.v2`).
What a learner sees and earns is stated here in full.

Action space
------------
``Box(-1, 1, (14,), float32)``, indices ``7 k .. 7 k + 6`` for hand ``k``: a
translation of the commanded grasp centre (3, up to 0.02 m per axis per step), a rotation vector
about it (3, up to 0.1 rad per axis per step), and the finger force (1: ``a * squeeze_force``,
70 N at 1; > 0 closes, < 0 opens, 0 leaves the fingers free); v0's docstring (*Action space*)
gives the workspace clipping.

Success
-------
An episode succeeds (``info["success"]``, ``terminated``, ``info["termination"] ==
"success"``) on the first step on which

* a **hold** has lasted ``hold_time`` (1 s = 20 steps by default): the hold begins on a step
  on which the object's centre of mass is at least ``lift_height`` (0.10 m) above where it
  rested and both hands grasp it (each touches it with both fingers), and goes on while the
  object stays that high and neither hand's grasp centre moves more than the benchmark's slip
  limit (``max_displacement``) against the object (contacts may flicker meanwhile), and
* **both hands grasp the object on that step** (``info["grasping"] == [True, True]``).

The second condition is new in v3. In v0-v2 the hold alone decided: a policy that held for
0.9 s and then opened both hands (fingers commanded -1) could still be credited with success
and paid its success reward two steps later, fingers 5.3 cm open and the object falling,
because the slip is measured at the grasp centres, which a falling object has not left yet
(``tests/test_lift_v3.py`` drives v2 into it and shows v3 refusing it). In v3 a hold that
reaches its time on a step without the grasp goes on, and succeeds on the next step that has
it; a dropped object ends the hold (it is no longer lifted).

The episode fails (``info["fail"]``, ``terminated``) when the object leaves the table
(``"off_table"``), rises above 2 m or moves faster than 10 m/s (``"out_of_bounds"``), or the
physics diverges (``"unstable"``); it is truncated after ``episode_steps`` (200 = 10 s at
20 Hz).

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
  unstable step and a failed episode's last step pay 0.
* ``"normalized_dense"``: the dense terms divided by ``R`` (a step pays at most 1; the success
  step ``T - t + 1``).
* ``"sparse"``: 1 on the success step, else 0.

**Bound** (every mode): from any step ``t``, what the steps ``t .. T`` can earn without
succeeding is at most what succeeding at step ``t`` pays, so a policy that hovers with the
object lifted never out-earns one that completes the hold.

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
* ``"pointcloud"``: ``Dict(state, points, normals, mask)``: the ``"state"`` vector and a
  fixed-size cloud of ``n_points`` points of the object (world frame, m), their outward
  normals and a mask ((``n_points``,): 1 = a point, 0 = padding), seen by ``n_cameras`` seeded
  depth cameras at reset and carried with the object's pose. New in v3: ``points`` and
  ``normals`` are flat ``Box((3 n_points,))`` vectors, ``x0, y0, z0, x1, ...``
  (``obs["points"].reshape(-1, 3)`` gives v2's ``(n_points, 3)`` array, the same numbers), as
  in the one-step environments, so stable-baselines3's ``check_env`` passes without a warning.

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

:meth:`~dg16m_env.envs.lift.task.LiftEnv.get_state` /
:meth:`~dg16m_env.envs.lift.task.LiftEnv.set_state` restore a simulation exactly (same machine
and build), as in v1 and v2.

``gym.make_vec("dg16m_env/DualGraspLift-v3", num_envs=N)`` gives a
:class:`~dg16m_env.envs.lift.vector.LiftVectorEnv`, as v2. A v2 policy of the ``"state"`` or
``"state_dict"`` modes runs on v3 unchanged (same spaces, same physics, the same steps until a
hold reaches its time; the feedback expert's 200 seeded procedural episodes are the same
episodes on both, 150 successes); a ``"pointcloud"`` one reshapes the cloud.

Version history
---------------
* v3 (2026-12-06): success needs both hands grasping on the step it is credited
  (:attr:`~dg16m_env.envs.lift.versions.LiftVersion.success_needs_grasp`); the point cloud's
  ``points`` and ``normals`` flat (:attr:`~dg16m_env.envs.lift.versions.LiftVersion.flat_cloud`);
  otherwise v2.
* v2 (2026-12-05): v1's task on 5 ms physics steps with compiled step arithmetic
  (:mod:`dg16m_env.envs.lift.v2`).
* v1 (2026-12-05): reward and observation modes, success-dominant rewards
  (:mod:`dg16m_env.envs.lift.v1`).
* v0: the first closed-loop task (:mod:`dg16m_env.envs.lift.v0`; deprecated).
"""

from __future__ import annotations

from dg16m_env.envs.lift.task import LiftEnv
from dg16m_env.envs.lift.versions import V3


class DualGraspLiftV3Env(LiftEnv):
    """``dg16m_env/DualGraspLift-v3``: :class:`~dg16m_env.envs.lift.task.LiftEnv` with the
    :data:`~dg16m_env.envs.lift.versions.V3` record (see the module docstring)."""

    version = V3
