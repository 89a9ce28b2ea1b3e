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

<<rewards>>

<<state_modes>>
* ``"pointcloud"``: ``Dict(state, points, normals, mask)``: the ``"state"`` vector and a
  fixed-size cloud of ``n_points`` points of the object (world frame, m), their outward
  normals and a mask ((``n_points``,): 1 = a point, 0 = padding), seen by ``n_cameras`` seeded
  depth cameras at reset and carried with the object's pose. New in v3: ``points`` and
  ``normals`` are flat ``Box((3 n_points,))`` vectors, ``x0, y0, z0, x1, ...``
  (``obs["points"].reshape(-1, 3)`` gives v2's ``(n_points, 3)`` array, the same numbers), as
  in the one-step environments, so stable-baselines3's ``check_env`` passes without a warning.

<<arguments_and_info>>

State save and restore
----------------------
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

from dg16m_env.envs.lift.manual import fill
from dg16m_env.envs.lift.task import LiftEnv
from dg16m_env.envs.lift.versions import V3

__doc__ = fill(__doc__)  # the sections shared with the other versions' pages


class DualGraspLiftV3Env(LiftEnv):
    """``dg16m_env/DualGraspLift-v3``: :class:`~dg16m_env.envs.lift.task.LiftEnv` with the
    :data:`~dg16m_env.envs.lift.versions.V3` record (see the module docstring)."""

    version = V3
