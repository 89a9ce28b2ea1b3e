"""A Lift expert that plans its approach on the observation's point cloud:
:class:`PlanningLiftExpert`.

:class:`~dg16m_env.envs.lift.recovering_expert.RecoveringLiftExpert` approaches each grasp along
one fixed path, ``FAR_DISTANCE`` (0.25 m) straight back along the grasp's approach axis to the
grasp centre; the state holds only the object's bounding box, so where that path runs through
another part of the object (a chair's seat over the rail it grasps, a frame's far side) the
palm pushes the object away, often far enough that the episode ends in the approach (the clean
failures of ``baselines/RESULTS.md``). With ``obs_mode="pointcloud"`` the observation also holds
the object's cloud as the env's cameras saw it at reset (world frame, moving with the object);
this expert checks each hand's path against it and takes the first free one of:

1. the recovering expert's path (so a free path changes nothing);
2. the same final straight segment (``PREGRASP_DISTANCE`` along the approach axis), reached
   from a far point ``FAR_DISTANCE - PREGRASP_DISTANCE`` from the pre-grasp in a direction
   turned ``TURNS`` (rad) from straight back towards up, either way along the fingers' closing
   axis, or either way along the hand's third axis (:func:`approach_candidates`);
3. the same with a shorter final segment (``SHORT_PREGRASP_DISTANCE``), for a part that blocks
   the palm within ``PREGRASP_DISTANCE`` of the grasp.

A path is free when no cloud point falls in the open hand's collision boxes (:func:`hand_hits`),
grown by ``PATH_MARGIN`` (the cloud is sparse: about 512 points), at poses ``PATH_SPACING``
apart along far point -> pre-grasp, ungrown along pre-grasp -> grasp centre (the fingers end
around points of the part they grasp), and grown along the column above the far point up to the
height at which the recovering expert crosses over the object (where a hand far off its path
comes down). A path whose far point or pre-grasp is below the table's margin is skipped. When no
candidate is free, or the observation has no cloud (``"state"``, ``"state_dict"``), it is the
recovering expert exactly.

Still a function of the observation: the paths are recomputed from the cloud on every call, so
DAgger can label any state (of a pointcloud env).

Measured (2026-12-07, ``dg16m_env/DualGraspLift-v2`` with ``obs_mode="pointcloud"``, held-out
objects, reset seeds 100000 + i, ``baselines.lift_expert_robustness --experts planning``; Wilson
95 % intervals): ``baselines/RESULTS.md``.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from dataset_gen.grasps.gripper import PANDA, GripperModel, get_gripper
from dg16m_env.envs.lift.recovering_expert import RecoveringLiftExpert


def open_hand_boxes(gripper: str | GripperModel = PANDA) -> np.ndarray:
    """(B, 2, 3) lower and upper corners of the fully open hand's collision boxes (palm, two
    fingers; gripper frame, m)."""
    model = get_gripper(gripper)
    return np.array(
        [
            [np.subtract(box.center, box.half_extents), np.add(box.center, box.half_extents)]
            for box in model.collision_boxes(model.max_opening)
        ]
    )


def hand_hits(
    points: np.ndarray,
    centres: np.ndarray,
    rotation: np.ndarray,
    *,
    boxes: np.ndarray,
    depth: float,
    margin: float,
) -> np.ndarray:
    """(n,) bool: whether any of ``points`` lies in the open hand's boxes at each pose.

    Args:
        points: (P, 3) cloud points (world, m).
        centres: (n, 3) grasp centres of the hand (world, m); the gripper frame's origin is
            ``depth`` back along the approach axis ``rotation[:, 1]``.
        rotation: (3, 3) the hand's rotation (gripper -> world), the same at every pose.
        boxes: (B, 2, 3) from :func:`open_hand_boxes`.
        depth: the gripper's contact depth (m).
        margin: each box grown by this on every side (m).
    """
    flanges = centres - depth * rotation[:, 1]
    local = (points[None, :, :] - flanges[:, None, :]) @ rotation  # (n, P, 3) gripper frame
    inside = np.zeros(local.shape[:2], dtype=bool)
    for low, high in boxes:
        inside |= np.all((local >= low - margin) & (local <= high + margin), axis=2)
    return inside.any(axis=1)


def segment_hits(
    points: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    rotation: np.ndarray,
    *,
    boxes: np.ndarray,
    depth: float,
    margin: float,
    spacing: float,
) -> bool:
    """Whether the open hand at ``rotation``, its grasp centre moved from ``start`` to ``end``
    ((3,) world, m) at poses at most ``spacing`` apart (both ends included), meets a cloud point
    (:func:`hand_hits`). Only points within the hand's reach of the segment are tested."""
    reach = float(np.linalg.norm(boxes.reshape(-1, 3) - [0.0, depth, 0.0], axis=1).max())
    segment = end - start
    squared = max(float(segment @ segment), 1e-12)
    t = np.clip((points - start) @ segment / squared, 0.0, 1.0)
    near = np.linalg.norm(points - (start + t[:, None] * segment), axis=1) < reach + margin
    if not near.any():
        return False
    count = max(2, int(np.ceil(np.sqrt(squared) / spacing)) + 1)
    centres = start + np.linspace(0.0, 1.0, count)[:, None] * segment
    return bool(
        hand_hits(points[near], centres, rotation, boxes=boxes, depth=depth, margin=margin).any()
    )


def observed_cloud(obs: Any) -> np.ndarray | None:
    """(P, 3) float64: the valid points (``mask`` 1) of a ``"pointcloud"`` observation (world,
    m; the ``(n, 3)`` cloud of v1/v2 or the flat ``(3 n,)`` one of v3); ``None`` for an
    observation without a cloud. ``ValueError`` for a cloud of the wrong shape or with
    non-finite points."""
    if not isinstance(obs, Mapping) or "points" not in obs:
        return None
    points = np.asarray(obs["points"], dtype=np.float64)
    mask = np.asarray(obs.get("mask", np.ones(points.size // 3)), dtype=np.float64).reshape(-1)
    if points.size != 3 * mask.size:
        raise ValueError(
            f"PlanningLiftExpert: expected a cloud of 3 x {mask.size} values (one point per mask "
            f"entry), found points of shape {points.shape}"
        )
    points = points.reshape(-1, 3)[mask > 0.5]
    if not np.all(np.isfinite(points)):
        raise ValueError("PlanningLiftExpert: expected finite cloud points, found NaN or inf")
    return points


def approach_candidates(
    goal_rot: np.ndarray, turns: tuple[float, ...]
) -> Iterator[tuple[np.ndarray, float]]:
    """The unit directions (world) from the pre-grasp to the far point, other than straight back,
    in the order they are tried for one pre-grasp distance: for each angle of ``turns`` (rad),
    straight back (``-approach``) turned by it towards up (its part orthogonal to the approach
    axis, when it has one), then towards either side of the closing axis and of the hand's third
    axis. Yields ``(direction, angle)``."""
    approach, closing, third = goal_rot[:, 1], goal_rot[:, 0], goal_rot[:, 2]
    up = np.array([0.0, 0.0, 1.0])
    up = up - (up @ approach) * approach
    sides = ([up / np.linalg.norm(up)] if np.linalg.norm(up) > 0.2 else []) + [
        closing,
        -closing,
        third,
        -third,
    ]
    for angle in turns:
        for side in sides:
            yield np.cos(angle) * -approach + np.sin(angle) * side, angle


class PlanningLiftExpert(RecoveringLiftExpert):
    """:class:`~dg16m_env.envs.lift.recovering_expert.RecoveringLiftExpert` whose approach paths
    avoid the parts of the object in the observation's cloud (module docstring); the same call,
    phases and units. Needs ``obs_mode="pointcloud"`` to differ from the recovering expert."""

    OBS_MODE = "pointcloud"
    """The observation mode it plans on (``baselines.lift_expert_robustness`` makes its env so)."""
    TURNS = (0.5, 1.0, float(np.pi / 2))
    """Angles (rad) from straight back of the far points tried (:func:`approach_candidates`)."""
    SHORT_PREGRASP_DISTANCE = 0.06
    """The shorter final straight segment tried after the others (m)."""
    PATH_MARGIN = 0.01
    """The hand's boxes grown by this (m) along far point -> pre-grasp and the column above."""
    PATH_SPACING = 0.01
    """Largest distance between the hand poses checked along a path (m)."""
    COLUMN_SPACING = 0.03
    """... and along the column above the far point (m)."""

    def __init__(self, lift_height: float = 0.10, lift_margin: float = 0.03) -> None:
        super().__init__(lift_height=lift_height, lift_margin=lift_margin)
        self.boxes = open_hand_boxes(PANDA)

    def approach_paths(
        self,
        obs: Any,
        part: dict[str, np.ndarray],
        goals: np.ndarray,
        goal_rots: np.ndarray,
    ) -> list[list[np.ndarray]]:
        """Each hand's approach path (far point -> pre-grasp -> grasp centre, world, m): the
        first free one of the module docstring's list, or the recovering expert's."""
        default = super().approach_paths(obs, part, goals, goal_rots)
        cloud = observed_cloud(obs)
        if cloud is None or len(cloud) == 0:
            return default
        crossing = self._safe_height(self._box_corners(part))
        return [
            self._free_path(cloud, goals[k], goal_rots[k], default[k], crossing) for k in range(2)
        ]

    def _free_path(
        self,
        cloud: np.ndarray,
        goal: np.ndarray,
        goal_rot: np.ndarray,
        default: list[np.ndarray],
        crossing: float,
    ) -> list[np.ndarray]:
        """One hand's path: ``default`` when free, else the first free candidate (up to 30), else
        ``default``."""
        floor = self._floor(goal_rot)
        approach = goal_rot[:, 1]
        if self._is_free(cloud, default, goal_rot, crossing):
            return default
        length = self.FAR_DISTANCE - self.PREGRASP_DISTANCE
        for pregrasp_distance in (self.PREGRASP_DISTANCE, self.SHORT_PREGRASP_DISTANCE):
            pregrasp = goal - pregrasp_distance * approach
            if pregrasp[2] < floor:
                continue
            for direction, _ in approach_candidates(goal_rot, self.TURNS):
                far = pregrasp + length * direction
                if far[2] < floor:
                    continue
                path = [far, pregrasp.copy(), goal.copy()]
                if self._is_free(cloud, path, goal_rot, crossing):
                    return path
        return default

    def _is_free(
        self, cloud: np.ndarray, path: list[np.ndarray], goal_rot: np.ndarray, crossing: float
    ) -> bool:
        """Whether the open hand at ``goal_rot`` meets no cloud point along ``path`` and the column
        above its far point up to ``crossing`` (m; module docstring)."""
        far, pregrasp, goal = path
        top = np.array([far[0], far[1], max(crossing, float(far[2]))])
        checks = (
            (far, pregrasp, self.PATH_MARGIN, self.PATH_SPACING),
            (pregrasp, goal, 0.0, self.PATH_SPACING),
            (top, far, self.PATH_MARGIN, self.COLUMN_SPACING),
        )
        return not any(
            segment_hits(
                cloud,
                start,
                end,
                goal_rot,
                boxes=self.boxes,
                depth=self.depth,
                margin=margin,
                spacing=spacing,
            )
            for start, end, margin, spacing in checks
        )


__all__ = [
    "PlanningLiftExpert",
    "approach_candidates",
    "hand_hits",
    "observed_cloud",
    "open_hand_boxes",
    "segment_hits",
]
