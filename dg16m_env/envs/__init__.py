"""Gymnasium environments over the simulation benchmark; registered when :mod:`dg16m_env` is
imported (Gymnasium 1.x has no plugin entry points).

Ids (each documented in its module, with a version history):

* ``dg16m_env/DualGraspPose-v0`` (:mod:`.dual_grasp_pose`): one step: two hand poses -> one
  trial of the benchmark protocol;
* ``dg16m_env/DualGraspSelect-v0`` (:mod:`.dual_grasp_select`): one step: pick one of K
  candidate dual grasps of the benchmark;
* ``dg16m_env/DualGraspLift-v0`` (:mod:`.lift.v0`): closed loop: two floating Panda hands lift
  an object from a table (deprecated: its reward pays a hover more than a success; removed in
  0.3.0);
* ``dg16m_env/DualGraspLift-v1`` (:mod:`.lift.v1`): the same task as a learning benchmark:
  reward modes where success pays best, observation modes, state save and restore;
* ``dg16m_env/DualGraspLift-v2`` (:mod:`.lift.v2`): v1's task on 5 ms physics steps with
  compiled step arithmetic, about three times v1's steps per second; ``gym.make_vec`` gives it
  :class:`.lift.vector.LiftVectorEnv` (blocks of environments stepped by this process and
  worker processes, one message per worker per step);
* ``dg16m_env/DualGraspLift-v3`` (:mod:`.lift.v3`): v2 whose success needs both hands grasping
  on the step it is credited (v2 could credit a hold whose hands had just opened); the newest
  Lift version, recommended for new work (``gym.make_vec`` as v2).

The Lift task is one package, :mod:`.lift`: one task class (:mod:`.lift.task`) whose versions
differ by a frozen record (:mod:`.lift.versions`), its reward, experts, demonstrations and
vector env; :mod:`.common`, :mod:`.objects` and :mod:`.spaces` serve the tasks. Layer rule:
modules here import the evaluators, subjects, benchmark and physics layers below them, never
:mod:`dg16m_env.cli`.

``gym.make("dg16m_env/DualGraspSelect-v0")`` after ``import dg16m_env``; from a fresh
interpreter ``gym.make("dg16m_env:DualGraspSelect-v0")`` imports the package first. Gymnasium
looks that form up without the namespace, so every id is also registered under its bare name
(``DualGraspSelect-v0``), an alias of the same environment.
"""

from __future__ import annotations

import gymnasium

NAMESPACE = "dg16m_env"

#: name -> (entry point, max_episode_steps or None for one-step environments)
ENVIRONMENTS: dict[str, tuple[str, int | None]] = {
    "DualGraspPose-v0": ("dg16m_env.envs.dual_grasp_pose:DualGraspPoseEnv", None),
    "DualGraspSelect-v0": ("dg16m_env.envs.dual_grasp_select:DualGraspSelectEnv", None),
    "DualGraspLift-v0": ("dg16m_env.envs.lift.v0:DualGraspLiftEnv", 200),
    "DualGraspLift-v1": ("dg16m_env.envs.lift.v1:DualGraspLiftV1Env", 200),
    "DualGraspLift-v2": ("dg16m_env.envs.lift.v2:DualGraspLiftV2Env", 200),
    "DualGraspLift-v3": ("dg16m_env.envs.lift.v3:DualGraspLiftV3Env", 200),
}


#: name -> ``vector_entry_point`` (``gym.make_vec``'s default for that id)
VECTOR_ENTRY_POINTS: dict[str, str] = {
    "DualGraspLift-v2": "dg16m_env.envs.lift.vector:lift_v2_vector_env",
    "DualGraspLift-v3": "dg16m_env.envs.lift.vector:lift_v3_vector_env",
}


def env_ids(*, aliases: bool = False) -> list[str]:
    """The registered ids (``dg16m_env/<Name>-v0``; with ``aliases`` also the bare names)."""
    ids = [f"{NAMESPACE}/{name}" for name in ENVIRONMENTS]
    return ids + list(ENVIRONMENTS) if aliases else ids


def register_envs() -> None:
    """Register every environment (idempotent: ids already registered are left alone).

    One-step environments (no step limit) register ``vector_kwargs={"autoreset_mode":
    "SameStep"}``: ``gym.make_vec`` then resets a finished sub-environment within the same
    step, instead of spending every other step on a reset (Gymnasium's default, NextStep).
    """
    for name, (entry_point, max_steps) in ENVIRONMENTS.items():
        for env_id in (f"{NAMESPACE}/{name}", name):
            if env_id in gymnasium.registry:
                continue
            kwargs = {} if max_steps else {"vector_kwargs": {"autoreset_mode": "SameStep"}}
            gymnasium.register(
                id=env_id,
                entry_point=entry_point,
                vector_entry_point=VECTOR_ENTRY_POINTS.get(name),
                max_episode_steps=max_steps,
                kwargs=kwargs,
            )


register_envs()
