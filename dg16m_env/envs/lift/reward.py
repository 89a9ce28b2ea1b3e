"""The reward of ``dg16m_env/DualGraspLift-v0``: its terms, their weights, and the one function that
computes them from what the task measured on a step (:func:`reward_terms`). The terms and their
signs are documented in :mod:`dg16m_env.envs.lift.v0` (*Rewards*); the reward is their
sum, in the order of :data:`REWARD_WEIGHTS`.
"""

from __future__ import annotations

import numpy as np

from dg16m_env.envs.lift.measures import LiftStepMeasures

REWARD_WEIGHTS: dict[str, float] = {
    "reach": 1.0,
    "align": 0.1,
    "grasp": 0.25,
    "lift": 1.0,
    "hold": 1.0,
    "success": 10.0,
    "failure": 10.0,
    "action": 0.01,
}
"""Weights of the reward terms (see the module docstring for their signs)."""


def jaw_angle(rotations: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(...) angle (rad) between hand rotations and target rotations (..., 3, 3), the smaller of
    the target and the target turned by pi about its approach axis (the same parallel grasp)."""
    relative = np.einsum("...ji,...jk->...ik", targets, rotations)  # R_t^T R
    trace = relative[..., 0, 0] + relative[..., 1, 1] + relative[..., 2, 2]
    flipped = -relative[..., 0, 0] + relative[..., 1, 1] - relative[..., 2, 2]
    best = np.maximum(trace, flipped)
    return np.arccos(np.clip((best - 1.0) / 2.0, -1.0, 1.0))


def reward_terms(
    m: LiftStepMeasures, *, lift_height: float, failure: bool, motion: np.ndarray
) -> dict[str, float]:
    """The reward terms of one step, in the order of :data:`REWARD_WEIGHTS` (their sum is the
    reward).

    Args:
        m: what the step measured: ``reach_distance`` (mean over the hands of the distance, m,
            from each grasp centre to its target grasp centre, with a target, or to the
            object's bounding box, without), ``jaw_angle`` (mean over the hands of the angle,
            rad, to the target rotation, :func:`jaw_angle`; ``None`` without a target: the
            ``align`` term is then 0), ``grasping`` (which hands touch the object with both
            fingers), ``lift`` (centre-of-mass height above its resting height, m), ``holding``,
            ``success`` and ``unstable`` (every term is then 0 but ``failure``).
        lift_height: the lift that succeeds (m, > 0).
        failure: whether the episode ends in failure on this step.
        motion: (12,) the action's motion components (not the finger forces).
    """
    reach_distance, jaw_angle, lift = m.reach_distance, m.jaw_angle, m.lift
    hands_grasping, both_grasping = int(m.grasping.sum()), bool(m.grasping.all())
    holding, success, unstable = m.holding, m.success, m.unstable
    weights = REWARD_WEIGHTS
    align = -weights["align"] * jaw_angle if jaw_angle is not None else 0.0
    terms = {
        "reach": -weights["reach"] * reach_distance,
        "align": align,
        "grasp": weights["grasp"] * float(hands_grasping),
        "lift": weights["lift"] * min(max(lift / lift_height, 0.0), 1.0) if both_grasping else 0.0,
        "hold": weights["hold"] if holding else 0.0,
        "success": weights["success"] if success else 0.0,
        "failure": -weights["failure"] if failure else 0.0,
        "action": -weights["action"] * float(np.mean(motion**2)),
    }
    if unstable:  # MuJoCo reset the state: the observation is the reset state's, finite
        terms = dict.fromkeys(terms, 0.0) | {"failure": -weights["failure"]}
    return terms


# --------------------------------------------------------------------------------------------
# DualGraspLift-v1: reward modes in which success is always the best return
# --------------------------------------------------------------------------------------------

REWARD_MODES = ("dense", "normalized_dense", "sparse")
"""The ``reward_mode`` values of ``dg16m_env/DualGraspLift-v1``."""

DENSE_WEIGHTS: dict[str, float] = {
    "reach": 1.0,
    "align": 1.0,
    "grasp": 1.0,
    "lift": 1.0,
    "hold": 1.0,
}
"""Largest value of each v1 dense term on a step that does not succeed (all terms are >= 0)."""

MAX_STEP_REWARD = sum(DENSE_WEIGHTS.values())
"""Largest dense reward of a step that does not succeed (5.0): the ``R`` of the success bound."""


def dense_terms(m: LiftStepMeasures, *, lift_height: float, steps_left: int) -> dict[str, float]:
    """The v1 dense reward terms of one step (their sum is the dense reward), all >= 0.

    On a step that does not succeed: ``reach = 1 - tanh(5 d)`` (``d`` the mean distance, m, from
    each hand's grasp centre to its target's, or to the object's box without a target),
    ``align = 1 - theta / pi`` (mean jaw angle, rad; 0 without a target), ``grasp = 0.5`` per
    hand grasping, ``lift = clip(lift / lift_height, 0, 1)`` while both hands grasp, ``hold = 1``
    while a hold is under way: at most :data:`MAX_STEP_REWARD`. The success step pays
    ``MAX_STEP_REWARD * (steps_left + 1)`` in ``success`` and 0 in the other terms: at least what
    the step and every step left could earn without success. An unstable step pays nothing.

    Args:
        m: what the step measured (as for :func:`reward_terms`).
        lift_height: the lift that succeeds (m, > 0).
        steps_left: steps the episode could still run after this one (>= 0).
    """
    reach_distance, jaw_angle, lift = m.reach_distance, m.jaw_angle, m.lift
    hands_grasping, both_grasping = int(m.grasping.sum()), bool(m.grasping.all())
    holding, success, unstable = m.holding, m.success, m.unstable
    terms = dict.fromkeys((*DENSE_WEIGHTS, "success"), 0.0)
    if unstable:
        return terms
    if success:
        terms["success"] = MAX_STEP_REWARD * float(max(steps_left, 0) + 1)
        return terms
    w = DENSE_WEIGHTS
    terms["reach"] = w["reach"] * (1.0 - float(np.tanh(5.0 * reach_distance)))
    if jaw_angle is not None:
        terms["align"] = w["align"] * (1.0 - min(max(jaw_angle / np.pi, 0.0), 1.0))
    terms["grasp"] = w["grasp"] * 0.5 * float(hands_grasping)
    if both_grasping:
        terms["lift"] = w["lift"] * min(max(lift / lift_height, 0.0), 1.0)
    terms["hold"] = w["hold"] if holding else 0.0
    return terms


def mode_terms(mode: str, dense: dict[str, float], success: bool) -> dict[str, float]:
    """The reward terms of ``mode`` from the step's :func:`dense_terms` (sum = the reward):
    ``"dense"`` as they are, ``"normalized_dense"`` each divided by :data:`MAX_STEP_REWARD`,
    ``"sparse"`` only ``success`` (1.0 on the success step, else 0.0)."""
    if mode == "dense":
        return dense
    if mode == "normalized_dense":
        return {name: value / MAX_STEP_REWARD for name, value in dense.items()}
    if mode == "sparse":
        return {"success": 1.0 if success else 0.0}
    raise ValueError(f"reward_mode: expected one of {REWARD_MODES}, found {mode!r}")
