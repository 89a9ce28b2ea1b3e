"""``dg16m_env/DualGraspLift-v1``: the Lift task as a robot-learning benchmark.

The physics, the action space, the randomisations, success (lift ``lift_height`` and hold
``hold_time`` without slip) and the failure causes are those of ``DualGraspLift-v0``
(:mod:`dg16m_env.envs.lift.v0`, whose docstring is the reference for them). v1 changes
what a learner sees and earns:

* **Reward modes** in which success is always the best return (*Rewards*).
* **Observation modes**, with the relative features a policy needs (*Observation modes*).
* ``info["success"]`` and ``info["fail"]`` on every step; the episode ends itself at
  ``episode_steps`` (``truncated``); ``step()`` after the episode ended raises
  ``RuntimeError`` until ``reset()``.
* :meth:`~dg16m_env.envs.lift.task.LiftEnv.get_state` /
  :meth:`~dg16m_env.envs.lift.task.LiftEnv.set_state` restore a
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
v0's (``benchmark``, ``object_ids``, ``mesh_root``, ``lift_height``, ``hold_time``,
``render_mode``, ``width``, ``height``), and:

* ``target_grasp``: ``"benchmark"`` (default) or ``None`` (v0's default was ``None``).
* ``reward_mode``: ``"dense"`` (default), ``"normalized_dense"`` or ``"sparse"``.
* ``obs_mode``: ``"state"`` (default), ``"state_dict"`` or ``"pointcloud"``.
* ``n_points`` (512), ``n_cameras`` (1 or 2), ``camera_resolution`` (128 pixels): the
  ``"pointcloud"`` mode's cloud.

* ``episode_steps``: ``T``, the steps after which the env truncates the episode itself
  (:data:`~.task.EPISODE_STEPS` = 200 = 10 s at 20 Hz, the registered ``max_episode_steps``). It
  sets the reward bound and the ``elapsed`` fraction; for a longer episode give
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
  times the steps per second (:mod:`dg16m_env.envs.lift.v2`).
* v1 (2026-12-05): reward and observation modes, success-dominant rewards, ``fail``, step
  after the end refused, state save and restore, a target grasp by default, 1024-pixel shadow
  maps when rendering. Later (0.2.0, same id, same episodes bit for bit): the task's code is
  one class for every version (:mod:`dg16m_env.envs.lift.task`; this version its
  :data:`~dg16m_env.envs.lift.versions.V1` record).
* v0: see :mod:`dg16m_env.envs.lift.v0` (unchanged, still registered).
"""

from __future__ import annotations

from dg16m_env.envs.lift.task import LiftEnv
from dg16m_env.envs.lift.versions import V1


class DualGraspLiftV1Env(LiftEnv):
    """``dg16m_env/DualGraspLift-v1``: :class:`~dg16m_env.envs.lift.task.LiftEnv` with the
    :data:`~dg16m_env.envs.lift.versions.V1` record (see the module docstring)."""

    version = V1
