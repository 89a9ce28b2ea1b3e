"""``dg16m_env/DualGraspLift-v2``: the Lift task of v1 on 5 ms physics steps, about three times
as many steps per second.

Everything a learner sees and earns is v1's (:mod:`dg16m_env.envs.lift.v1`, whose
docstring is the reference): the action space, the reward modes and their bound, the
observation modes and their 117-number state, ``info``, ``get_state``/``set_state``, the
target grasp by default, 20 Hz control and the 200-step episode. v2 changes how a step is
computed:

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

Version history
---------------
* v2 (2026-12-05): 5 ms physics steps (10 per control step), compiled step arithmetic,
  :class:`~dg16m_env.envs.lift.vector.LiftVectorEnv` as ``gym.make_vec``'s default. Later
  (0.2.0, same id, same episodes bit for bit): the task's code is one class for every version
  (:mod:`dg16m_env.envs.lift.task`; this version its :data:`~dg16m_env.envs.lift.versions.V2`
  record).
* v1, v0: see :mod:`dg16m_env.envs.lift.v1` and
  :mod:`dg16m_env.envs.lift.v0` (unchanged, still registered).
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
