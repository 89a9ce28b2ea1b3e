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

<<rewards>>

<<state_modes>>
<<pointcloud_tracked>>

<<arguments_and_info>>

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

from dg16m_env.envs.lift.manual import fill
from dg16m_env.envs.lift.task import LiftEnv
from dg16m_env.envs.lift.versions import V2

__doc__ = fill(__doc__)  # the sections shared with the other versions' pages

PHYSICS_TIMESTEP = V2.physics_timestep
"""MuJoCo's timestep in v2 (s; 10 physics steps per 50 ms control step)."""


class DualGraspLiftV2Env(LiftEnv):
    """``dg16m_env/DualGraspLift-v2``: :class:`~dg16m_env.envs.lift.task.LiftEnv` with the
    :data:`~dg16m_env.envs.lift.versions.V2` record (see the module docstring)."""

    version = V2
