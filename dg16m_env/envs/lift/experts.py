"""The Lift task's experts, each a policy from the observation alone (so it works through
wrappers; the task is :mod:`dg16m_env.envs.lift.task`, of which they read only the observation
layout and the action scaling):

* :class:`ScriptedLiftPolicy`, for ``dg16m_env/DualGraspLift-v0``: grasps the target dual grasp
  and lifts, on waypoints planned once per episode (a function of the episode).
* :class:`FeedbackLiftExpert`, for ``dg16m_env/DualGraspLift-v1`` and ``-v2``: decides its
  action from the current observation alone (it replans every step and keeps no memory), so
  observation -> action is a function, which imitation learning and DAgger need.
* :class:`~dg16m_env.envs.lift.recovering_expert.RecoveringLiftExpert` (its own module): the
  feedback expert's phases, followed so that it recovers from pushes.

:func:`dg16m_env.envs.lift.expert_registry.make_lift_expert` makes the feedback experts by name.

Measured (2026-12-05, ``gym.make("dg16m_env/DualGraspLift-v1")``, procedural benchmark with its
target grasp, seeds 0-119): :class:`FeedbackLiftExpert` succeeds in 92/120 = 0.77 (Wilson 95 %
0.68-0.83), where ``ScriptedLiftPolicy`` on ``DualGraspLift-v0`` with
``target_grasp="benchmark"`` (the same episodes) succeeds in 89/120 = 0.74 (0.66-0.81), never on
a seed the feedback expert fails; after 30 uniform random actions, 89/120 = 0.74 (0.66-0.81).
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from dataset_gen.grasps.gripper import PANDA
from dg16m_env.envs.lift.observations import STATE_SLICES, goal_frames, state_vector
from dg16m_env.envs.lift.scenes import HAND_REACH, TABLE_MARGIN
from dg16m_env.envs.lift.spaces import (
    ACTION_SIZE,
    MAX_ROTATION,
    MAX_TRANSLATION,
    OBS_SLICES,
    rotation_vector,
)
from dg16m_env.envs.spaces import rotation_from_6d
from dg16m_env.physics.lift_scene import hand_points

# --------------------------------------------------------------------------------------------
# The scripted expert (v0)
# --------------------------------------------------------------------------------------------

PREGRASP_DISTANCE = 0.09
"""Pre-grasp distance of :class:`ScriptedLiftPolicy` back along the approach axis (m)."""


class ScriptedLiftPolicy:
    """A scripted grasp-and-lift policy for ``DualGraspLift-v0``
    (:class:`~dg16m_env.envs.lift.v0.DualGraspLiftEnv`) with a target grasp, from the observation
    alone (so it works through wrappers): the reference solution the tests and
    ``bench/env_lift.py`` run, and a demonstration that the task is solvable.

    Each hand's grasp centre follows waypoints at full speed (the action bounds): up to a safe
    height above the object (its top bound plus the hand's reach), over to a point
    ``FAR_DISTANCE`` back along the target's approach axis while turning to the target rotation,
    down to it, in to the pre-grasp (``PREGRASP_DISTANCE`` back), in to the grasp (waypoints
    are raised to where the env lets a hand go above the table). When both hands are there the
    fingers close (``close_steps`` steps), then both hands rise together by ``lift`` m over
    ``lift_steps`` steps and hold still with the fingers closed.

    The path is not planned against the object's shape: a hand can run into a part of the object
    on its way (about one episode in ten on the shipped benchmark knocks the object over or away),
    and some grasps slip or swing out while lifted. With ``target_grasp="benchmark"`` it succeeds
    in about 80 % of episodes of the shipped benchmark.

    Args:
        lift: how far the hands rise (m; default 0.2: an object hanging from two grasps swings
            about the line joining the hands and its centre of mass settles below where it was
            lifted, so the hands rise more than ``lift_height``).
        close_steps: control steps to close the fingers before lifting.
        lift_steps: control steps of the rise (a half-cosine profile: smooth start and stop).
    """

    FAR_DISTANCE = 0.25
    CLEARANCE = 0.05
    POSITION_TOLERANCE = 0.003
    ANGLE_TOLERANCE = 0.03

    def __init__(self, lift: float = 0.2, close_steps: int = 12, lift_steps: int = 20) -> None:
        self.lift = lift
        self.close_steps = close_steps
        self.lift_steps = lift_steps
        self.depth = PANDA.contact_depth
        self._hand_points = hand_points(PANDA)
        self.reset()

    def reset(self) -> None:
        """Forget the episode (call at every env reset)."""
        self.phase = "approach"
        self.waypoints: list[list[tuple[np.ndarray, np.ndarray | None]]] | None = None
        self.progress = [0, 0]
        self.count = 0
        self.lift_goal: np.ndarray | None = None
        self.lift_rot: np.ndarray | None = None

    @staticmethod
    def _poses(flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rows = flat.reshape(-1, 9).astype(np.float64)
        a = rows[:, 3:6] / np.linalg.norm(rows[:, 3:6], axis=1, keepdims=True)
        b = rows[:, 6:9] - np.sum(rows[:, 6:9] * a, axis=1, keepdims=True) * a
        b /= np.linalg.norm(b, axis=1, keepdims=True)
        rot = np.stack([a, b, np.cross(a, b)], axis=-1)
        return rows[:, :3], rot

    def _plan(self, obs: np.ndarray) -> None:
        s = OBS_SLICES
        hand_pos, hand_rot = self._poses(obs[s["hand_poses"]])
        goal_pos, goal_rot = self._poses(obs[s["target_poses"]])
        centres = hand_pos + self.depth * hand_rot[:, :, 1]
        goal = goal_pos + self.depth * goal_rot[:, :, 1]
        # The object's top: its bounding box (object frame) at the object's pose.
        obj_pos, obj_rot = self._poses(
            np.concatenate([obs[s["object_position"]], obs[s["object_rotation"]]])
        )
        half = 0.5 * obs[s["object_size"]].astype(np.float64)
        centre = obs[s["object_box_centre"]].astype(np.float64)
        up = obj_rot[0][2]  # world z in the object frame
        top = float(obj_pos[0, 2] + up @ centre + np.abs(up) @ half)
        safe = top + HAND_REACH + self.CLEARANCE
        self.waypoints = []
        for k in range(2):
            approach = goal_rot[k][:, 1]
            far = goal[k] - self.FAR_DISTANCE * approach
            high = max(safe, float(far[2]))
            # The env keeps hands above the table: so do the waypoints (an approach from below
            # ends on the table's margin instead of under it).
            lowest = float((goal_rot[k][2] @ (self._hand_points - [0.0, self.depth, 0.0]).T).min())
            floor = TABLE_MARGIN + 1e-3 - lowest
            pregrasp = goal[k] - PREGRASP_DISTANCE * approach
            self.waypoints.append(
                [
                    (np.array([centres[k, 0], centres[k, 1], max(high, centres[k, 2])]), None),
                    (np.array([far[0], far[1], high]), goal_rot[k]),
                    (np.array([far[0], far[1], max(far[2], floor)]), goal_rot[k]),
                    (np.array([*pregrasp[:2], max(pregrasp[2], floor)]), goal_rot[k]),
                    (goal[k], goal_rot[k]),
                ]
            )

    @staticmethod
    def _delta(
        centre: np.ndarray, rot: np.ndarray, goal: np.ndarray, goal_rot: np.ndarray | None
    ) -> tuple[np.ndarray, bool]:
        move = goal - centre
        reached = float(np.linalg.norm(move)) < ScriptedLiftPolicy.POSITION_TOLERANCE
        largest = float(np.abs(move).max())
        if largest > MAX_TRANSLATION:
            move *= MAX_TRANSLATION / largest
        turn = np.zeros(3)
        if goal_rot is not None:
            turn = rotation_vector(goal_rot @ rot.T)
            reached &= float(np.linalg.norm(turn)) < ScriptedLiftPolicy.ANGLE_TOLERANCE
            largest = float(np.abs(turn).max())
            if largest > MAX_ROTATION:
                turn *= MAX_ROTATION / largest
        return np.concatenate([move / MAX_TRANSLATION, turn / MAX_ROTATION]), reached

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """The action (float32, (14,)) for observation ``obs``."""
        s = OBS_SLICES
        if obs[s["target_flag"]][0] < 0.5:
            raise ValueError("ScriptedLiftPolicy: expected an observation with a target grasp")
        if self.waypoints is None:
            self._plan(obs)
        assert self.waypoints is not None
        hand_pos, hand_rot = self._poses(obs[s["hand_poses"]])
        centres = hand_pos + self.depth * hand_rot[:, :, 1]
        action = np.zeros(ACTION_SIZE)
        if self.phase == "approach":
            done = []
            for k in range(2):
                path = self.waypoints[k]
                while self.progress[k] < len(path):
                    goal, goal_rot = path[self.progress[k]]
                    motion, reached = self._delta(centres[k], hand_rot[k], goal, goal_rot)
                    if not reached:
                        action[7 * k : 7 * k + 6] = motion
                        break
                    self.progress[k] += 1
                done.append(self.progress[k] >= len(path))
                action[7 * k + 6] = -1.0
            if all(done):
                self.phase, self.count = "close", 0
        if self.phase == "close":
            for k in range(2):  # keep the hands at the grasp
                goal, goal_rot = self.waypoints[k][-1]
                action[7 * k : 7 * k + 6] = self._delta(centres[k], hand_rot[k], goal, goal_rot)[0]
            self.count += 1
            if self.count > self.close_steps:
                self.phase = "lift"
                self.lift_goal = np.array([p[-1][0] for p in self.waypoints])
                self.lift_goal[:, 2] += self.lift
                self.lift_rot = np.array([p[-1][1] for p in self.waypoints])
                self.count = 0
        if self.phase == "lift":
            assert self.lift_goal is not None
            assert self.lift_rot is not None
            phase = min(self.count / self.lift_steps, 1.0)  # smooth start and stop
            rise = self.lift * 0.5 * (1.0 - math.cos(math.pi * phase))
            self.count += 1
            for k in range(2):
                goal = self.lift_goal[k] - np.array([0.0, 0.0, self.lift - rise])
                action[7 * k : 7 * k + 6] = self._delta(
                    centres[k], hand_rot[k], goal, self.lift_rot[k]
                )[0]
        action[[6, 13]] = -1.0 if self.phase == "approach" else 1.0
        return np.clip(action, -1.0, 1.0).astype(np.float32)


# --------------------------------------------------------------------------------------------
# The feedback expert (v1, v2)
# --------------------------------------------------------------------------------------------


def _motion(
    centre: np.ndarray, rotation: np.ndarray, goal: np.ndarray, goal_rotation: np.ndarray | None
) -> np.ndarray:
    """The 6 motion components (action units) taking a commanded pose towards a goal at full
    speed (each part scaled as a whole so no component leaves [-1, 1])."""
    move = (goal - centre) / MAX_TRANSLATION
    move /= max(1.0, float(np.abs(move).max()))
    turn = np.zeros(3)
    if goal_rotation is not None:
        turn = rotation_vector(goal_rotation @ rotation.T) / MAX_ROTATION
        turn /= max(1.0, float(np.abs(turn).max()))
    return np.concatenate([move, turn])


def _along(path: list[np.ndarray], point: np.ndarray) -> tuple[float, float, float]:
    """Arc length of the point of polyline ``path`` nearest ``point``, the distance to it, and
    the polyline's length (m); of equally near points the later one."""
    best, distance, start = 0.0, np.inf, 0.0
    for a, b in itertools.pairwise(path):
        segment = b - a
        size = float(np.linalg.norm(segment))
        t = 0.0 if size < 1e-12 else float(np.clip((point - a) @ segment / size**2, 0.0, 1.0))
        gap = float(np.linalg.norm(a + t * segment - point))
        if gap <= distance + 1e-9:
            best, distance = start + t * size, gap
        start += size
    return best, distance, start


def _point(path: list[np.ndarray], arc: float) -> np.ndarray:
    """The point of polyline ``path`` at arc length ``arc`` (clipped to its ends)."""
    for a, b in itertools.pairwise(path):
        size = float(np.linalg.norm(b - a))
        if arc <= size:
            return a + (b - a) * (max(arc, 0.0) / size if size > 1e-12 else 0.0)
        arc -= size
    return path[-1].copy()


class FeedbackLiftExpert:
    """Grasp the target dual grasp and lift, deciding everything from the current observation.

    ``expert(obs)`` returns the action (float32, (14,), in [-1, 1]) for a ``DualGraspLift-v1``
    observation with a target grasp: the flat ``"state"`` vector, a ``"state_dict"`` dictionary
    or a ``"pointcloud"`` dictionary (its ``"state"`` entry; the cloud is not used). It is a
    pure function of the observation: nothing is kept between calls (``reset()`` does nothing;
    it is there for evaluators that call it). The observation's ``previous_action`` is the one
    memory it reads: its finger values say "the fingers were closing", its ``z`` values "the
    hands were rising".

    Units: m, rad, world frame; an action moves a commanded grasp centre by up to
    ``MAX_TRANSLATION`` (0.02 m) per axis and turns it by up to ``MAX_ROTATION`` (0.1 rad) per
    axis. Motions are planned from the *commanded* poses (``commanded_poses``: where the hands
    are told to be, so waypoints are reached exactly) towards goals taken from the target grasp
    at the object's current pose (``target_poses``: it moves with the object, so a knocked
    object simply gives new goals). A hand's goal rotation is the nearer of its target and the
    target turned by pi about the approach axis ``+y`` (the same parallel grasp); its goal
    centre is the target flange + ``contact_depth`` (0.1034 m) along that axis.

    Phase rules, in order, each step (:meth:`phase` names the one that applies):

    1. ``"lift"`` when the previous action closed both hands' fingers and either all four
       fingers touch the object, or the object is up (``lift`` > ``LIFTED``) and each hand still
       touches it or its fingers stay open on it (> ``OPEN_ON_OBJECT``). Both hands rise
       together, fingers closed, nothing else moving: ``RISE_MIN`` per step at first, faster as
       ``lift`` grows (``RISE_GAIN`` per m of lift, at most ``RISE_MAX``), slowing down to stop
       at ``lift_height + lift_margin``; then they hold still. Holding hands rise again only if
       ``lift`` falls below ``lift_height + RESUME_MARGIN``.
    2. ``"close"`` when both hands are at their goals (commanded and actual grasp centre within
       ``POSITION_TOLERANCE``, rotation within ``ANGLE_TOLERANCE``), or the previous action
       closed the fingers and each hand touches the object or is within ``NEAR_GOAL`` of its
       goal: the hands keep to their goals, the fingers close.
    3. ``"approach"`` otherwise, fingers open; each hand by where its commanded pose is:

       * in the *corridor* (within ``CORRIDOR_RADIUS`` of the path far point -> pre-grasp ->
         grasp centre, rotation within ``CORRIDOR_ANGLE``): on along the path, ``IN_STEP`` per
         step, slower in the last ``SLOW_DISTANCE``; at the goal it waits for the other hand.
         The far point is ``FAR_DISTANCE`` and the pre-grasp ``PREGRASP_DISTANCE`` back along
         the approach axis, both raised so that the hand stays above the table's margin;
       * in the far point's *column* (within ``COLUMN_RADIUS`` horizontally): turn to the goal
         rotation, then go to the far point;
       * elsewhere: straight up to the safe height (the object's bounding-box top +
         ``HAND_REACH`` (0.16 m) + ``CLEARANCE``, or the far point if higher), then across at
         that height to above the far point, turning to the goal rotation on the way.

    The path is not planned against the object's shape (the state holds its bounding box
    only): a target whose approach runs into the object, or a grasp the object turns in as it
    is lifted, fails as it does for ``ScriptedLiftPolicy``.

    Args:
        lift_height: the env's ``lift_height`` (m; not in the observation).
        lift_margin: how far above ``lift_height`` the object is lifted (m; an object hanging
            from two grasps swings and its centre of mass sits lower than where it was
            lifted).
    """

    OBS_MODE = "state"
    """The observation mode the expert needs (it reads only the state: any mode serves)."""
    FAR_DISTANCE = 0.25
    """Distance of the far point back along the approach axis from the grasp centre (m)."""
    PREGRASP_DISTANCE = 0.09
    """Distance of the pre-grasp point back along the approach axis (m): the approach path is
    far point -> pre-grasp -> grasp centre, each raised above the table (then a straight line
    unless the table is in the way)."""
    CLEARANCE = 0.05
    """Safe height above the object's box top beyond the hand's reach (m)."""
    POSITION_TOLERANCE = 0.004
    """A hand is at its goal within this distance (m) ..."""
    ANGLE_TOLERANCE = 0.05
    """... and this angle (rad)."""
    NEAR_GOAL = 0.03
    """While the fingers close, a hand without contacts must stay this near its goal (m)."""
    CORRIDOR_RADIUS = 0.01
    """Largest distance from the approach line to stay in the corridor (m)."""
    CORRIDOR_ANGLE = 0.1
    """Largest rotation error to stay in the corridor (rad)."""
    IN_STEP = 0.02
    """Step along the approach line (m)."""
    SLOW_DISTANCE = 0.04
    """Within this distance of the goal the step shrinks (m)."""
    COLUMN_RADIUS = 0.005
    """Horizontal distance from the far point that counts as above or below it (m)."""
    HEIGHT_TOLERANCE = 0.005
    """A hand this near the safe height is at it (m)."""
    OPEN_ON_OBJECT = 0.004
    """Fingers of a hand without contacts that stay this open (m) are still on the object."""
    LIFTED = 0.01
    """``lift`` (m) above which a closed grasp keeps lifting even if contacts flicker."""
    RESUME_MARGIN = 0.02
    """Holding hands rise again when ``lift`` falls below ``lift_height`` + this (m)."""
    RISE_MIN = 0.003
    """Rise per step at the start of the lift (m)."""
    RISE_MAX = 0.012
    """Largest rise per step (m)."""
    RISE_GAIN = 0.3
    """Rise per step per metre of ``lift`` (ramp up) and per metre left (slow down)."""

    def __init__(self, lift_height: float = 0.10, lift_margin: float = 0.03) -> None:
        self.lift_height = float(lift_height)
        self.lift_margin = float(lift_margin)
        self.depth = float(PANDA.contact_depth)
        self._below_centre = hand_points(PANDA) - np.array([0.0, self.depth, 0.0])

    def reset(self) -> None:
        """Nothing to forget (the expert has no memory); for evaluators that call it."""

    # ----------------------------------------------------------------------------------------
    # Observation
    # ----------------------------------------------------------------------------------------

    @staticmethod
    def state_vector(obs: Any) -> np.ndarray:
        """The flat ``"state"`` vector (float64, (117,)) of a state, state_dict or pointcloud
        observation (:func:`~dg16m_env.envs.lift.observations.state_vector`); ``ValueError`` for
        anything else or an observation without a target."""
        state = state_vector(obs, "FeedbackLiftExpert")
        flag = float(state[STATE_SLICES["target_flag"]][0])
        if flag < 0.5:
            raise ValueError(
                "FeedbackLiftExpert: expected an observation with a target grasp (target_flag "
                f"1), found target_flag {flag}"
            )
        return state

    # ----------------------------------------------------------------------------------------
    # Policy
    # ----------------------------------------------------------------------------------------

    def __call__(self, obs: Any) -> np.ndarray:
        """The action (float32, (14,)) for observation ``obs`` (see the class docstring)."""
        return self.decide(obs)[1]

    def phase(self, obs: Any) -> str:
        """The rule that decides the action for ``obs``: ``"lift"``, ``"close"`` or
        ``"approach"`` (class docstring)."""
        return self.decide(obs)[0]

    def decide(self, obs: Any) -> tuple[str, np.ndarray]:
        """The phase (:meth:`phase`) and the action (``expert(obs)``) for ``obs``."""
        s = self.state_vector(obs)
        part = {name: s[sl] for name, sl in STATE_SLICES.items()}
        previous = part["previous_action"]
        contacts = part["finger_contacts"].reshape(2, 2) > 0.5
        lift = float(part["lift"][0])
        closing = bool(previous[6] > 0.0 and previous[13] > 0.0)
        action = np.zeros(ACTION_SIZE)

        openings = part["finger_openings"]
        gripping = contacts.any(axis=1) | (openings > self.OPEN_ON_OBJECT)
        if closing and (contacts.all() or (lift > self.LIFTED and gripping.all())):
            rise = self._rise(lift, bool(previous[2] > 0.0 and previous[9] > 0.0))
            action[[2, 9]] = rise / MAX_TRANSLATION
            action[[6, 13]] = 1.0
            return "lift", np.clip(action, -1.0, 1.0).astype(np.float32)

        target_rot, goals, centres, rotations = (frame[0] for frame in goal_frames(s[None]))
        errors = np.linalg.norm(centres - goals, axis=1)
        actual = np.linalg.norm(part["centre_errors"].reshape(2, 3), axis=1)
        errors = np.maximum(errors, actual)
        angles = np.linalg.norm(rotation_vector(target_rot @ np.swapaxes(rotations, 1, 2)), axis=1)
        at_goal = (errors < self.POSITION_TOLERANCE) & (angles < self.ANGLE_TOLERANCE)
        holding = closing and bool(np.all(contacts.any(axis=1) | (errors < self.NEAR_GOAL)))
        if at_goal.all() or holding:
            return "close", self._close_action(centres, rotations, goals, target_rot)
        return "approach", self._approach_action(part, centres, rotations, goals, target_rot)

    @staticmethod
    def _close_action(
        centres: np.ndarray, rotations: np.ndarray, goals: np.ndarray, goal_rots: np.ndarray
    ) -> np.ndarray:
        """The ``"close"`` action: each hand keeps to its goal, the fingers close."""
        action = np.zeros(ACTION_SIZE)
        for k in range(2):
            action[7 * k : 7 * k + 6] = _motion(centres[k], rotations[k], goals[k], goal_rots[k])
        action[[6, 13]] = 1.0
        return np.clip(action, -1.0, 1.0).astype(np.float32)

    def _approach_action(
        self,
        part: dict[str, np.ndarray],
        centres: np.ndarray,
        rotations: np.ndarray,
        goals: np.ndarray,
        goal_rots: np.ndarray,
        paths: list[list[np.ndarray]] | None = None,
    ) -> np.ndarray:
        """The ``"approach"`` action: each hand on its way (:meth:`_approach`) along its path
        (``paths``: far point -> pre-grasp -> grasp centre per hand; :meth:`_path` of the goals
        when ``None``), fingers open."""
        if paths is None:
            paths = [self._path(goals[k], goal_rots[k]) for k in range(2)]
        action = np.zeros(ACTION_SIZE)
        corners = self._box_corners(part)
        for k in range(2):
            action[7 * k : 7 * k + 6] = self._approach(
                centres[k], rotations[k], goals[k], goal_rots[k], corners, paths[k]
            )
        action[[6, 13]] = -1.0
        return np.clip(action, -1.0, 1.0).astype(np.float32)

    def _rise(self, lift: float, rising: bool) -> float:
        """Rise of both hands this step (m)."""
        goal = self.lift_height + self.lift_margin
        if lift >= goal or (not rising and lift >= self.lift_height + self.RESUME_MARGIN):
            return 0.0
        up = self.RISE_MIN + self.RISE_GAIN * max(lift, 0.0)
        down = self.RISE_MIN + self.RISE_GAIN * (goal - lift)
        return min(up, down, self.RISE_MAX)

    @staticmethod
    def _box_corners(part: dict[str, np.ndarray]) -> np.ndarray:
        """(8, 3) corners of the object's bounding box at its pose (world, m)."""
        rotation = rotation_from_6d(part["object_rotation"])[0]
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
        local = part["object_box_centre"] + 0.5 * signs * part["object_size"]
        return local @ rotation.T + part["object_position"]

    def _floor(self, rotation: np.ndarray) -> float:
        """Lowest grasp-centre height (m) keeping the hand at ``rotation`` above the table."""
        lowest = float((rotation[2] @ self._below_centre.T).min())
        return TABLE_MARGIN + 1e-3 - lowest

    def _path(self, goal: np.ndarray, goal_rot: np.ndarray) -> list[np.ndarray]:
        """The approach path far point -> pre-grasp -> grasp centre (3 points, world, m), the
        first two raised so that the hand at ``goal_rot`` stays above the table."""
        axis = goal_rot[:, 1]
        floor = self._floor(goal_rot)
        path = [goal - back * axis for back in (self.FAR_DISTANCE, self.PREGRASP_DISTANCE, 0.0)]
        for point in path[:2]:
            point[2] = max(point[2], floor)
        return path

    def _safe_height(self, corners: np.ndarray) -> float:
        """Grasp-centre height (m) at which a hand crosses over the object: the top of its
        (8, 3) box ``corners`` + the hand's reach + ``CLEARANCE``."""
        return float(corners[:, 2].max()) + HAND_REACH + self.CLEARANCE

    def _over_the_object(
        self,
        centre: np.ndarray,
        rotation: np.ndarray,
        start: np.ndarray,
        goal_rot: np.ndarray,
        corners: np.ndarray,
    ) -> np.ndarray:
        """Motion of a hand far from its path: up to the safe height (the box top + the hand's
        reach + ``CLEARANCE``, or the far point ``start`` if higher), then across at that height
        to above the far point, turning to ``goal_rot`` on the way."""
        high = max(self._safe_height(corners), float(start[2]))
        if centre[2] < high - self.HEIGHT_TOLERANCE:
            return _motion(centre, rotation, np.array([centre[0], centre[1], high]), None)
        return _motion(centre, rotation, np.array([start[0], start[1], centre[2]]), goal_rot)

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
        along, lateral, length = _along(path, centre)
        angle = float(np.linalg.norm(rotation_vector(goal_rot @ rotation.T)))
        if lateral <= self.CORRIDOR_RADIUS and angle <= self.CORRIDOR_ANGLE:
            left = length - along
            step = self.IN_STEP * min(1.0, left / self.SLOW_DISTANCE + 0.25)
            return _motion(centre, rotation, _point(path, along + step), goal_rot)
        start = path[0]
        if float(np.linalg.norm(centre[:2] - start[:2])) <= self.COLUMN_RADIUS:
            if angle > self.ANGLE_TOLERANCE:  # turn in place first
                return _motion(centre, rotation, centre, goal_rot)
            return _motion(centre, rotation, start, goal_rot)
        return self._over_the_object(centre, rotation, start, goal_rot, corners)
