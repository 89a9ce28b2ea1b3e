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

<<rewards>>

<<state_modes>>
<<pointcloud_tracked>>

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

from dg16m_env.envs.lift.manual import fill
from dg16m_env.envs.lift.task import LiftEnv
from dg16m_env.envs.lift.versions import V1

__doc__ = fill(__doc__)  # the sections shared with the other versions' pages


class DualGraspLiftV1Env(LiftEnv):
    """``dg16m_env/DualGraspLift-v1``: :class:`~dg16m_env.envs.lift.task.LiftEnv` with the
    :data:`~dg16m_env.envs.lift.versions.V1` record (see the module docstring)."""

    version = V1
