"""What one ``DualGraspLift`` control step did, as pure functions of the simulated state: the
hold (:func:`update_hold`) and the episode's end (:func:`termination_of`), gathered in
:class:`LiftStepMeasures`. The rules are stated in :mod:`dg16m_env.envs.lift.v0`
(*Success* and *Termination*); the env calls these once per step."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dg16m_env.physics.lift_scene import TABLE_HALF_SIZE

OBJECT_MAX_HEIGHT = 2.0
"""An object whose centre of mass rises above this (m) ends the episode (failure)."""

OBJECT_MAX_SPEED = 10.0
"""An object faster than this (m/s) ends the episode (failure)."""

TERMINATIONS = ("success", "off_table", "out_of_bounds", "unstable")
"""The values of ``info["termination"]`` when an episode terminates (``""`` while it runs)."""


@dataclass(frozen=True)
class LiftStepMeasures:
    """What one control step did: centre-of-mass ``lift`` (m), ``grasping`` ((2,) bool),
    ``holding``, ``success``, ``termination`` (``""`` while running), ``unstable``, ``slip``
    ((2,) m), mean ``reach_distance`` (m), mean ``jaw_angle`` (rad, None without a target)."""

    lift: float
    grasping: np.ndarray
    holding: bool
    success: bool
    termination: str
    unstable: bool
    slip: np.ndarray
    reach_distance: float
    jaw_angle: float | None


@dataclass(frozen=True)
class Hold:
    """The hold carried from step to step: ``anchor`` ((2, 3) the hands' grasp centres in the
    object frame when the hold began, m; None = no hold) and ``count`` (steps held since)."""

    anchor: np.ndarray | None = None
    count: int = 0


def update_hold(
    hold: Hold,
    *,
    lifted: bool,
    both_grasping: bool,
    centres: np.ndarray,
    obj_pos: np.ndarray,
    obj_rot: np.ndarray,
    max_slip: float,
) -> tuple[Hold, bool, np.ndarray]:
    """One step of the hold: it begins lifted with both hands grasping and continues while
    lifted without slip at the hands' grasp centres (contacts may flicker meanwhile).

    Args:
        hold: the hold before this step.
        lifted: the object is at least ``lift_height`` up and the step was stable.
        both_grasping: both hands touch the object with both fingers.
        centres: (2, 3) the hands' grasp centres, world (m).
        obj_pos, obj_rot: (3,) the object's position (m) and (3, 3) rotation, world.
        max_slip: the largest motion of a grasp centre against the object that still holds (m).

    Returns:
        The hold after the step, whether the object is held now, and the (2,) slip (m; zero
        when the hold (re)starts or is dropped).
    """
    if lifted and hold.anchor is not None:
        moved = hold.anchor @ obj_rot.T + obj_pos
        slip = np.linalg.norm(moved - centres, axis=1)
        if bool(np.all(slip < max_slip)):
            return Hold(hold.anchor, hold.count + 1), True, slip
    if lifted and both_grasping:  # (re)start the hold here
        return Hold((centres - obj_pos) @ obj_rot, 0), True, np.zeros(2)
    return Hold(), False, np.zeros(2)


def termination_of(*, com: np.ndarray, speed: float, unstable: bool, success: bool) -> str:
    """Why the episode ends after this step (one of :data:`TERMINATIONS`), or ``""``.

    Args:
        com: (3,) the object's centre of mass, world (m).
        speed: the object's linear speed (m/s; ignored when ``unstable``).
        unstable: the physics diverged this step.
        success: the hold lasted its time this step.
    """
    if unstable:
        return "unstable"
    if success:
        return "success"
    if abs(com[0]) > TABLE_HALF_SIZE or abs(com[1]) > TABLE_HALF_SIZE:
        return "off_table"
    if com[2] > OBJECT_MAX_HEIGHT or speed > OBJECT_MAX_SPEED:
        return "out_of_bounds"
    return ""


def measure_step(
    hold: Hold,
    *,
    unstable: bool,
    lift: float,
    lift_height: float,
    hold_steps: int,
    max_slip: float,
    grasping: np.ndarray,
    centres: np.ndarray,
    obj_pos: np.ndarray,
    obj_rot: np.ndarray,
    com: np.ndarray,
    speed: float,
    reach_distance: float,
    jaw_angle: float | None,
    success_needs_grasp: bool = False,
) -> tuple[Hold, LiftStepMeasures]:
    """One step's hold (:func:`update_hold`), success (a hold of ``hold_steps`` steps) and
    termination (:func:`termination_of`) from what the step measured.

    Args:
        hold: the hold before this step.
        unstable: the physics diverged this step.
        lift: centre-of-mass height above its resting height (m); lift_height: the success
            height (m); hold_steps: the steps a hold must last; max_slip: as :func:`update_hold`.
        grasping: (2,) bool, each hand touches the object with both fingers.
        centres: (2, 3) the hands' grasp centres, world (m).
        obj_pos, obj_rot, com: the object's (3,) position, (3, 3) rotation and (3,) centre of
            mass, world (m).
        speed: the object's linear speed (m/s; ignored when ``unstable``).
        reach_distance, jaw_angle: passed through to the measures.
        success_needs_grasp: success also needs both hands grasping on this step
            (:attr:`~.versions.LiftVersion.success_needs_grasp`: v3); otherwise a hold that
            has lasted its time succeeds even on the step the hands let go. A hold that reaches
            its time without the grasp goes on, and succeeds on the first step that has both.

    Returns:
        The hold after the step and the step's :class:`LiftStepMeasures`.
    """
    new, holding, slip = update_hold(
        hold,
        lifted=lift >= lift_height and not unstable,
        both_grasping=bool(grasping.all()),
        centres=centres,
        obj_pos=obj_pos,
        obj_rot=obj_rot,
        max_slip=max_slip,
    )
    success = holding and new.count >= hold_steps
    if success_needs_grasp:
        success = success and bool(grasping.all())
    termination = termination_of(com=com, speed=speed, unstable=unstable, success=success)
    return new, LiftStepMeasures(
        lift=lift,
        grasping=grasping,
        holding=holding,
        success=bool(success),
        termination=termination,
        unstable=unstable,
        slip=slip,
        reach_distance=reach_distance,
        jaw_angle=jaw_angle,
    )
