"""The registered versions of the Lift task, each a frozen record (:class:`LiftVersion`) that the
one task class (:class:`~dg16m_env.envs.lift.task.LiftEnv`) reads at construction: what differs
between ``dg16m_env/DualGraspLift-v0``, ``-v1``, ``-v2`` and ``-v3`` is written here, side by
side, and nowhere else. A registered version never changes: a change is a new record (and a new id).

Each version is documented in its own module (:mod:`.v0`, :mod:`.v1`, :mod:`.v2`, :mod:`.v3`),
which also names its environment class (``DualGraspLiftEnv``, ``DualGraspLiftV1Env``,
``DualGraspLiftV2Env``, ``DualGraspLiftV3Env``: the task class bound to its record). Standard
library only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

V0_ARGUMENTS = (
    "benchmark",
    "object_ids",
    "mesh_root",
    "target_grasp",
    "lift_height",
    "hold_time",
    "render_mode",
    "width",
    "height",
)
"""The constructor arguments of v0 (every version takes them)."""

V1_ARGUMENTS = (
    *V0_ARGUMENTS,
    "reward_mode",
    "obs_mode",
    "n_points",
    "n_cameras",
    "camera_resolution",
    "episode_steps",
)
"""The constructor arguments of v1, v2 and v3."""

V0_REWARD_FLAW = (
    "dg16m_env/DualGraspLift-v0 is deprecated and will be removed in dg16m 0.3.0: its dense "
    "reward pays per step over a 200-step horizon, so a policy that lifts the object 5 cm and "
    "hovers earns more than one that completes the lift and hold (success); use "
    "dg16m_env/DualGraspLift-v3 (or -v2, -v1), whose rewards make success the best return"
)
"""The :class:`DeprecationWarning` that making v0 raises (DESIGN.md, *The closed-loop task as a
learning benchmark*)."""


@dataclass(frozen=True)
class LiftVersion:
    """What one registered version of the Lift task is (read once, at construction).

    Attributes:
        name: ``"v0"``, ``"v1"``, ``"v2"``, ``"v3"`` (the id's suffix).
        arguments: the constructor keywords the version takes (others raise ``TypeError``).
        target_grasp: the default of ``target_grasp`` (None or ``"benchmark"``).
        physics_timestep: MuJoCo's timestep (s); None: the benchmark's (2 ms).
        reward: ``"terms"`` (v0's weighted terms, :func:`~.reward.reward_terms`) or
            ``"modes"`` (v1's success-dominant ``reward_mode``\\ s, :func:`~.reward.dense_terms`).
        observation: ``"vector"`` (v0's 71 numbers, :data:`~.spaces.OBS_LAYOUT`) or ``"modes"``
            (v1's ``obs_mode``\\ s over the 117-number state, :data:`~.observations.STATE_LAYOUT`).
        observe_settled: observe the state a step (and the reset) ended in (``mj_forward`` after
            the physics); v0 reads positions and contacts from the start of the last physics
            step.
        episode_bookkeeping: the env counts its steps and ends the episode itself
            (``episode_steps``; ``info["fail"]``, ``info["elapsed_steps"]``), refuses ``step()``
            after the end and saves and restores its state (``get_state``, ``set_state``).
        compiled_arithmetic: a step's hand targets and observation by the compiled functions of
            :mod:`~.kernels` (numba) instead of numpy: they agree to rounding, not bit for bit,
            so each version keeps the one it was registered with.
        render_shadow_size: side of the lights' shadow maps when rendering (pixels); None: the
            model's (4096).
        deprecation: the :class:`DeprecationWarning` raised at construction (None: none).
        success_needs_grasp: success is credited only on a step on which both hands grasp the
            object (both fingers each, ``info["grasping"]``); v0-v2 credit a hold that has
            lasted ``hold_time`` without slip even if the hands have just let go (the slip is
            measured at the grasp centres, which an object falling out of open fingers has not
            yet left).
        flat_cloud: the ``"pointcloud"`` observation's ``points`` and ``normals`` are flat
            ``(3 n_points,)`` vectors (the same numbers row by row) instead of ``(n_points, 3)``
            arrays, so stable-baselines3's ``check_env`` has no warning about their shape (as
            the one-step environments' clouds).
    """

    name: str
    arguments: tuple[str, ...]
    target_grasp: str | None
    physics_timestep: float | None
    reward: Literal["terms", "modes"]
    observation: Literal["vector", "modes"]
    observe_settled: bool
    episode_bookkeeping: bool
    compiled_arithmetic: bool
    render_shadow_size: int | None
    deprecation: str | None = None
    success_needs_grasp: bool = False
    flat_cloud: bool = False


V0 = LiftVersion(
    name="v0",
    arguments=V0_ARGUMENTS,
    target_grasp=None,
    physics_timestep=None,
    reward="terms",
    observation="vector",
    observe_settled=False,
    episode_bookkeeping=False,
    compiled_arithmetic=False,
    render_shadow_size=None,
    deprecation=V0_REWARD_FLAW,
)
"""``dg16m_env/DualGraspLift-v0`` (:mod:`.v0`)."""

V1 = LiftVersion(
    name="v1",
    arguments=V1_ARGUMENTS,
    target_grasp="benchmark",
    physics_timestep=None,
    reward="modes",
    observation="modes",
    observe_settled=True,
    episode_bookkeeping=True,
    compiled_arithmetic=False,
    render_shadow_size=1024,
)
"""``dg16m_env/DualGraspLift-v1`` (:mod:`.v1`)."""

V2 = replace(V1, name="v2", physics_timestep=0.005, compiled_arithmetic=True)
"""``dg16m_env/DualGraspLift-v2`` (:mod:`.v2`): v1 on 5 ms physics steps with the compiled
arithmetic."""

V3 = replace(V2, name="v3", success_needs_grasp=True, flat_cloud=True)
"""``dg16m_env/DualGraspLift-v3`` (:mod:`.v3`): v2 whose success needs both hands grasping on
the step it is credited, with flat point-cloud arrays."""

VERSIONS: dict[str, LiftVersion] = {version.name: version for version in (V0, V1, V2, V3)}
"""Name -> record of every registered version."""
