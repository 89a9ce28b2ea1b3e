"""A Lift expert that recovers from perturbations: :class:`RecoveringLiftExpert`.

:class:`~dg16m_env.envs.lift.experts.FeedbackLiftExpert` decides from the observation alone, but
it is brittle: a hand knocked more than 1 cm off its approach line, or a far point that moves
with a pushed object, sends it back up to its safe height to start the whole path again, and
while lifting it only rises, so whatever moves the hands apart is never corrected. With
N(0, 0.3) added to the action on 30 % of the steps it succeeds in a few per cent of held-out
episodes. This expert keeps the same phases and goals and changes how each is followed:

* approach: each hand resumes from where its commanded pose is. Near its approach path it
  follows a *funnel* (a tolerance that grows with the distance still to go) towards the point a
  step further along the path, correcting its lateral and rotation error on the way; a hand a
  little outside the funnel backs off along the path (towards the far point) while converging,
  instead of climbing back to the safe height; only a hand far from the path goes round over the
  object, and then it tracks the far point (which moves with the object) instead of waiting in a
  fixed column above it;
* close: a hand whose fingers shut on nothing (open less than ``EMPTY_OPENING`` without a
  contact), or a grasp whose actual centre settled more than ``REGRASP_ERROR`` from its goal
  before the object is up, opens again and re-approaches (a regrasp), where the other expert
  kept closing or lifted a poor grasp;
* lift: the hands rise faster (fewer steps in which a push can loosen the grasp) and hold
  their relative pose: each step each commanded pose is moved towards its actual hand by its
  offset less the two hands' mean offset (``HOLD_GAIN``) beyond a dead band, so a push that
  strains the object between the hands is relieved instead of left standing, while the weight
  both hands carry (a common offset) and the small steady strain of a load carried unevenly
  stay.

It is still a function of the observation (DAgger labels states it did not visit): the only
memory is the observation's ``previous_action`` (were the fingers closing, were the hands
rising), as for the feedback expert.

Measured (2026-12-07, ``dg16m_env/DualGraspLift-v2``, held-out objects, reset seeds
100000 + i, ``baselines.lift_expert_robustness``; Wilson 95 % intervals): procedural, 200
episodes, clean 79.0 % [72.8, 84.1] (feedback expert 74.5 %), with N(0, 0.3) added to the
action on 30 % of the steps 34.5 % [28.3, 41.3] (feedback expert 3.0 %); real furniture, 100
episodes, clean 70.0 % [60.4, 78.1] (72.0 %), perturbed 21.0 % [14.2, 30.0] (1.0 %). Perturbed
episodes fail in the lift: a perturbed step moves the two stiff hands about 1.4 cm relative to
each other and the object slips in the fingers; clean ones fail where the approach path runs
into another part of the object (the state holds only its bounding box;
:class:`~dg16m_env.envs.lift.planning_expert.PlanningLiftExpert` plans the path on the
``"pointcloud"`` observation's cloud instead).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from dg16m_env.envs.lift.experts import FeedbackLiftExpert, _along, _motion, _point
from dg16m_env.envs.lift.observations import STATE_SLICES, goal_frames
from dg16m_env.envs.lift.spaces import ACTION_SIZE, MAX_ROTATION, MAX_TRANSLATION, rotation_vector
from dg16m_env.envs.spaces import rotation_from_6d


class _PathPlace(NamedTuple):
    """Where a hand's commanded pose is against its approach path
    (:meth:`RecoveringLiftExpert._path_place`)."""

    rule: str
    """``"inside"`` (the funnel), ``"back"`` (backing off) or ``"off"`` (the rest)."""
    path: list[np.ndarray]
    """The path far point -> pre-grasp -> grasp centre (3 points, world, m)."""
    along: float
    """Arc length of the nearest path point (m)."""
    radii: float
    """Distance to the path in funnel radii."""
    left: float
    """Path length still to go (m)."""
    angle: float
    """Rotation error against the goal rotation (rad)."""


def _shrink(vectors: np.ndarray, deadband: float) -> np.ndarray:
    """(n, 3) vectors shortened by ``deadband`` (those shorter become zero)."""
    length = np.linalg.norm(vectors, axis=1, keepdims=True)
    return vectors * np.clip(1.0 - deadband / np.maximum(length, 1e-12), 0.0, None)


class RecoveringLiftExpert(FeedbackLiftExpert):
    """Grasp the target dual grasp and lift, from the current observation, recovering from
    pushes (module docstring). Same call, observation modes and units as
    :class:`~dg16m_env.envs.lift.experts.FeedbackLiftExpert`; its class constants are shared
    where not restated here.

    Phase rules, in order, each step (:meth:`phase` names the one that applies):

    1. ``"lift"``: as the feedback expert's (the previous action closed both hands, all four
       fingers touch, or the object is up and each hand still grips), unless the object is not
       up yet and a hand's actual grasp centre is more than ``REGRASP_ERROR`` from its goal.
       Both hands rise (``RISE_MIN`` .. ``RISE_MAX`` per step) and each commanded pose moves
       ``HOLD_GAIN`` of the way to its actual hand, less the two hands' mean offset and less
       the dead band (``HOLD_DEADBAND``, ``HOLD_DEADBAND_ANGLE``).
    2. ``"close"``: both hands at their goals, or the previous action closed the fingers and
       each hand touches the object or is within ``NEAR_GOAL`` of its goal, unless a hand's
       fingers shut on nothing (open less than ``EMPTY_OPENING``, no contact) or the grasp is
       misplaced (rule 1): the hands keep to their goals and close. Otherwise the fingers open
       and the hands re-approach (rule 3) and close again at their goals.
    3. ``"approach"`` otherwise, fingers open; each hand by where its commanded pose is, on the
       path far point -> pre-grasp -> grasp centre (raised above the table's margin):

       * inside the funnel (distance to the path at most ``funnel`` of the path length still to
         go, rotation error at most ``FUNNEL_ANGLE``): on along the path, a step of ``IN_STEP``
         (smaller near the goal and when far off the line) towards the path point ahead;
       * within ``BACK_OFF_FACTOR`` funnels: towards the path point ``BACK_STEP`` behind,
         turning to the goal rotation (the funnel is wider there);
       * within ``TRACK_RADIUS`` (+ ``TRACK_SLOPE`` per metre above it) horizontally of the
         far point: turn, then straight to the far point (tracking it as the object moves);
       * elsewhere: up to the safe height, across to above the far point, turning on the way.
    """

    FUNNEL_NEAR = 0.012
    """Funnel radius at the grasp centre (m)."""
    FUNNEL_SLOPE = 0.25
    """Funnel radius growth per metre of path still to go."""
    FUNNEL_FAR = 0.05
    """Largest funnel radius (m)."""
    FUNNEL_ANGLE = 0.35
    """Largest rotation error inside the funnel (rad)."""
    BACK_OFF_FACTOR = 2.5
    """A hand within this many funnel radii of the path backs off along it (more: goes round)."""
    BACK_STEP = 0.02
    """Step back along the path when backing off (m)."""
    TRACK_RADIUS = 0.03
    """Horizontal distance from the far point within which a hand goes straight to it (m)."""
    TRACK_SLOPE = 0.15
    """Growth of the tracking radius per metre above the far point."""
    EMPTY_OPENING = 0.002
    """Fingers open less than this (m) without a contact have closed on nothing."""
    HOLD_GAIN = 1.0
    """Share of the strain between the hands undone per step while lifting."""
    HOLD_DEADBAND = 0.003
    """Strain between the hands below this (m) is left (a load carried unevenly makes some:
    following it would tilt the object further every step)."""
    HOLD_DEADBAND_ANGLE = 0.02
    """... and below this (rad)."""
    REGRASP_ERROR = 0.01
    """Before the lift, a closed hand whose actual grasp centre is this far from its goal (m)
    opens and re-approaches."""
    RISE_MIN = 0.01
    """Rise per step at the start of the lift (m; the feedback expert's 0.003: a short lift
    leaves fewer steps for a push to loosen the grasp)."""
    RISE_MAX = 0.02
    """Largest rise per step (m; the action bound)."""
    RISE_GAIN = 1.0
    """Rise per step per metre of ``lift`` (ramp up) and per metre left (slow down)."""

    def funnel(self, left: float) -> float:
        """Funnel radius (m) with ``left`` m of path still to go."""
        return min(self.FUNNEL_NEAR + self.FUNNEL_SLOPE * max(left, 0.0), self.FUNNEL_FAR)

    def decide(self, obs: Any) -> tuple[str, np.ndarray]:
        """The phase (:meth:`phase`) and the action (``expert(obs)``) for ``obs``."""
        s = self.state_vector(obs)
        part = {name: s[sl] for name, sl in STATE_SLICES.items()}
        previous = part["previous_action"]
        contacts = part["finger_contacts"].reshape(2, 2) > 0.5
        lift = float(part["lift"][0])
        closing = bool(previous[6] > 0.0 and previous[13] > 0.0)
        openings = part["finger_openings"]
        target_rot, goals, centres, rotations = (frame[0] for frame in goal_frames(s[None]))
        action = np.zeros(ACTION_SIZE)

        gripping = contacts.any(axis=1) | (openings > self.OPEN_ON_OBJECT)
        actual = np.linalg.norm(part["centre_errors"].reshape(2, 3), axis=1)
        misplaced = lift <= self.LIFTED and float(actual.max()) > self.REGRASP_ERROR
        if (
            closing
            and not misplaced
            and (contacts.all() or (lift > self.LIFTED and gripping.all()))
        ):
            rise = self._rise(lift, bool(previous[2] > 0.0 and previous[9] > 0.0))
            action[:] = self._hold(part, centres, rotations)
            action[[2, 9]] += rise / MAX_TRANSLATION
            action[[6, 13]] = 1.0
            return "lift", np.clip(action, -1.0, 1.0).astype(np.float32)

        errors = np.maximum(np.linalg.norm(centres - goals, axis=1), actual)
        angles = np.linalg.norm(rotation_vector(target_rot @ np.swapaxes(rotations, 1, 2)), axis=1)
        at_goal = (errors < self.POSITION_TOLERANCE) & (angles < self.ANGLE_TOLERANCE)
        empty = ~contacts.any(axis=1) & (openings < self.EMPTY_OPENING)
        holding = closing and bool(np.all(contacts.any(axis=1) | (errors < self.NEAR_GOAL)))
        if (at_goal.all() or holding) and not (
            closing and (empty.any() or (misplaced and contacts.all()))
        ):
            return "close", self._close_action(centres, rotations, goals, target_rot)
        paths = self.approach_paths(obs, part, goals, target_rot)
        return "approach", self._approach_action(part, centres, rotations, goals, target_rot, paths)

    def approach_paths(
        self,
        obs: Any,
        part: dict[str, np.ndarray],
        goals: np.ndarray,
        goal_rots: np.ndarray,
    ) -> list[list[np.ndarray]]:
        """Each hand's approach path, far point -> pre-grasp -> grasp centre (2 lists of 3 points,
        world, m): ``FAR_DISTANCE`` and ``PREGRASP_DISTANCE`` back along the goal's approach axis,
        raised above the table (the state holds the object's bounding box only, so the path does
        not depend on ``obs`` beyond the goals; a subclass may plan it on the observation)."""
        return [self._path(goals[k], goal_rots[k]) for k in range(2)]

    def _hold(
        self, part: dict[str, np.ndarray], centres: np.ndarray, rotations: np.ndarray
    ) -> np.ndarray:
        """The 14 action values (fingers 0) that undo ``HOLD_GAIN`` of the strain between the two
        hands: each commanded pose's offset from the actual hand, less the two hands' mean offset
        (the weight the hands carry is common to both and stays)."""
        actual = part["hand_poses"].reshape(2, 9)
        actual_rot = rotation_from_6d(actual[:, 3:])[0]
        actual_centres = actual[:, :3] + self.depth * actual_rot[:, :, 1]
        moves = actual_centres - centres
        turns = rotation_vector(actual_rot @ np.swapaxes(rotations, 1, 2))
        moves = _shrink(moves - moves.mean(axis=0), self.HOLD_DEADBAND)
        turns = _shrink(turns - turns.mean(axis=0), self.HOLD_DEADBAND_ANGLE)
        moves = self.HOLD_GAIN * moves / MAX_TRANSLATION
        turns = self.HOLD_GAIN * turns / MAX_ROTATION
        action = np.zeros(ACTION_SIZE)
        for k in range(2):
            action[7 * k : 7 * k + 3] = moves[k] / max(1.0, float(np.abs(moves[k]).max()))
            action[7 * k + 3 : 7 * k + 6] = turns[k] / max(1.0, float(np.abs(turns[k]).max()))
        return action

    def following_path(self, obs: Any) -> np.ndarray:
        """(2,) bool: whether each hand's commanded pose is on its approach path, inside the
        funnel or within the back-off distance of it (the first two approach rules of the class
        docstring), rather than far off it (turning at the far point or going round over the
        object). Read in the ``"approach"`` phase; ``baselines.bc_lift --dagger-on-path true`` keeps
        the DAgger labels of approach states where both hands follow their paths."""
        s = self.state_vector(obs)
        part = {name: s[sl] for name, sl in STATE_SLICES.items()}
        target_rot, goals, centres, rotations = (frame[0] for frame in goal_frames(s[None]))
        paths = self.approach_paths(obs, part, goals, target_rot)
        return np.array(
            [
                self._path_place(
                    centres[k], rotations[k], goal_rot=target_rot[k], path=paths[k]
                ).rule
                != "off"
                for k in range(2)
            ]
        )

    def _path_place(
        self,
        centre: np.ndarray,
        rotation: np.ndarray,
        *,
        goal_rot: np.ndarray,
        path: list[np.ndarray],
    ) -> _PathPlace:
        """Which approach rule a hand's commanded pose falls under, and where it is on ``path``
        (far point -> pre-grasp -> grasp centre)."""
        along, lateral, length = _along(path, centre)
        left = length - along
        angle = float(np.linalg.norm(rotation_vector(goal_rot @ rotation.T)))
        radius = self.funnel(left)
        rule = "off"
        if lateral <= radius and angle <= self.FUNNEL_ANGLE:
            rule = "inside"
        elif lateral <= self.BACK_OFF_FACTOR * radius and along > 0.0:
            rule = "back"
        return _PathPlace(rule, path, along, lateral / radius, left, angle)

    def _approach(
        self,
        centre: np.ndarray,
        rotation: np.ndarray,
        goal: np.ndarray,
        goal_rot: np.ndarray,
        corners: np.ndarray,
        path: list[np.ndarray],
    ) -> np.ndarray:
        """Motion (6 action components) of one hand on its way to its goal along ``path`` (class
        docstring)."""
        place = self._path_place(centre, rotation, goal_rot=goal_rot, path=path)
        path, along, angle = place.path, place.along, place.angle
        if place.rule == "inside":
            share = 1.0 - place.radii
            step = self.IN_STEP * min(1.0, place.left / self.SLOW_DISTANCE + 0.25) * share
            return _motion(centre, rotation, _point(path, along + step), goal_rot)
        if place.rule == "back":
            return _motion(centre, rotation, _point(path, along - self.BACK_STEP), goal_rot)
        start = path[0]
        track = self.TRACK_RADIUS + self.TRACK_SLOPE * max(float(centre[2] - start[2]), 0.0)
        if float(np.linalg.norm(centre[:2] - start[:2])) <= track:
            if angle > self.FUNNEL_ANGLE:  # turn in place first
                return _motion(centre, rotation, centre, goal_rot)
            return _motion(centre, rotation, start, goal_rot)
        return self._over_the_object(centre, rotation, start, goal_rot, corners)
