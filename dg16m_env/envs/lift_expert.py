"""The scripted expert of ``dg16m_env/DualGraspLift-v0``: :class:`ScriptedLiftPolicy` grasps the
target dual grasp and lifts, from the observation alone. The task is
:mod:`dg16m_env.envs.dual_grasp_lift`; this module reads only its observation layout and its
action scaling.
"""

from __future__ import annotations

import math

import numpy as np

from dataset_gen.gripper import PANDA
from dg16m_env.envs.dual_grasp_lift import HAND_REACH, TABLE_MARGIN
from dg16m_env.envs.lift_spaces import (
    ACTION_SIZE,
    MAX_ROTATION,
    MAX_TRANSLATION,
    OBS_SLICES,
    rotation_vector,
)
from dg16m_env.physics.lift_scene import hand_points

PREGRASP_DISTANCE = 0.09
"""Pre-grasp distance of :class:`ScriptedLiftPolicy` back along the approach axis (m)."""


class ScriptedLiftPolicy:
    """A scripted grasp-and-lift policy for :class:`DualGraspLiftEnv` with a target grasp, from
    the observation alone (so it works through wrappers): the reference solution the tests and
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
