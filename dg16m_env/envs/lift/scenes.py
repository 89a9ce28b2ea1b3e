"""The Lift task's per-object data and what a reset draws: the task's geometry constants, the
physics rate (:func:`use_timestep`), one object's compiled scene and resting poses
(:class:`LiftObject`, :func:`load_lift_object`), the target grasp and resting pose
(:func:`choose_target`) and the start of an episode (:func:`draw_placement`). The rules are
documented in :mod:`dg16m_env.envs.lift.v0` (*Randomisations*, *Target grasp*).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import mujoco
import numpy as np

from dg16m_env.benchmark.model import Benchmark
from dg16m_env.envs.objects import BenchmarkObjects
from dg16m_env.physics.lift_scene import (
    LiftScene,
    compile_lift_scene,
    lowest_hand_z,
    part_points,
    stable_rest_poses,
)
from dg16m_env.physics.scene import SceneParameters

CONTROL_HZ = 20
"""Control steps per second (each runs ``1 / (CONTROL_HZ * timestep)`` physics steps)."""

TABLE_MARGIN = 0.01
"""No point of a hand is commanded below this height above the table top (m)."""

HAND_WORKSPACE_XY = 1.2
"""Commanded grasp centres stay within ``|x|, |y| <=`` this (m)."""

HAND_WORKSPACE_TOP = 1.5
"""Commanded grasp centres stay below this height (m)."""

STABLE_POSE_CHOICES = 3
"""The resting pose is drawn among this many most probable stable poses."""

OBJECT_OFFSET = 0.05
"""Largest ``x`` / ``y`` offset of the resting object from the table centre (m)."""

START_CLEARANCE = (0.05, 0.15)
"""Range of the hands' start clearance beyond the object's bounding radius plus reach (m)."""

START_HEIGHT = (0.05, 0.15)
"""Range of the height added to the start grasp centres (m; see *Randomisations*)."""

HAND_REACH = 0.16
"""Radius about the grasp centre holding the whole Panda hand (m)."""

SETTLE_TIME = 0.2
"""Simulated time the object settles at reset, hands open and away (s)."""

TARGET_MIN_P = 0.5
"""Benchmark target rows need ``p("full") >=`` this (and a force-closure pass)."""


def use_timestep(env: Any, timestep: float) -> None:
    """Make ``env`` (a Lift env, before its first reset: scenes are compiled then) step MuJoCo
    at ``timestep`` (s): the control rate stays :data:`CONTROL_HZ`, the physics steps per
    control step and the hold's length in steps follow."""
    env.scene_parameters = replace(env.scene_parameters, timestep=timestep)
    env.timestep = timestep
    env.substeps = max(1, round(1.0 / (CONTROL_HZ * timestep)))
    env.control_dt = env.substeps * timestep
    env._fractions = np.arange(1, env.substeps + 1, dtype=np.float64) / env.substeps
    env._fraction_column = env._fractions[:, None, None]  # (n, 1, 1), for the substeps
    env.hold_steps = math.ceil(env.hold_time / env.control_dt - 1e-9)


@dataclass
class LiftObject:
    """What a reset needs of one object: compiled scene, reusable data, resting poses, bounds."""

    scene: LiftScene
    data: mujoco.MjData
    rest_poses: np.ndarray  # (n, 4, 4), most probable first
    rest_probabilities: np.ndarray  # (n,)
    points: np.ndarray  # (P, 3) hull points of the parts, object frame
    box_low: np.ndarray  # (3,) bounding box of the parts, object frame
    box_high: np.ndarray
    target_rows: np.ndarray  # benchmark rows eligible as targets (before the table rule)
    feasible: dict[int, np.ndarray] = field(default_factory=dict)  # pose -> rows above table


def load_lift_object(
    objects: BenchmarkObjects,
    object_id: str,
    scene_parameters: SceneParameters,
    gravity: float,
    p_full: np.ndarray,
) -> LiftObject:
    """Compile ``object_id``'s Lift scene and find its resting poses and target rows."""
    obj = objects.load(object_id)
    stored = objects.benchmark_object(object_id)
    scene = compile_lift_scene(obj, params=scene_parameters, parts=stored.parts, gravity=gravity)
    poses, probabilities = stable_rest_poses(obj, stored.parts)
    points = part_points(stored.parts)
    rows = objects.rows(object_id)
    bench = objects.ref.benchmark
    eligible = rows[bench.fc_passed[rows] & (p_full[rows] >= TARGET_MIN_P)]
    return LiftObject(
        scene=scene,
        data=mujoco.MjData(scene.model),
        rest_poses=poses,
        rest_probabilities=probabilities,
        points=points,
        box_low=points.min(axis=0),
        box_high=points.max(axis=0),
        target_rows=eligible,
    )


def above_table(rest_pose: np.ndarray, grasps: np.ndarray, hand_points: np.ndarray) -> np.ndarray:
    """(N,) whether both hands of (N, 2, 4, 4) object-frame grasps stay above the table
    (:data:`TABLE_MARGIN`) with the object at ``rest_pose``."""
    world = rest_pose @ grasps
    return (lowest_hand_z(world, hand_points) >= TABLE_MARGIN).all(axis=-1)


def _feasible_rows(
    item: LiftObject, pose: int, bench: Benchmark, hand_points: np.ndarray
) -> np.ndarray:
    if pose not in item.feasible:
        rows = item.target_rows
        ok = above_table(item.rest_poses[pose], bench.poses[rows], hand_points)
        item.feasible[pose] = rows[ok]
    return item.feasible[pose]


def _pose_order(item: LiftObject, rng: np.random.Generator) -> list[int]:
    """Stable-pose indices: the top choices in a drawn order, then the rest by probability."""
    top = min(STABLE_POSE_CHOICES, len(item.rest_poses))
    weights = item.rest_probabilities[:top]
    weights = weights / weights.sum() if weights.sum() > 0 else np.full(top, 1.0 / top)
    drawn = rng.choice(top, size=top, replace=False, p=weights)
    return [int(i) for i in drawn] + list(range(top, len(item.rest_poses)))


def choose_target(
    kind: Any,
    object_id: str | None,
    *,
    objects: BenchmarkObjects,
    rng: np.random.Generator,
    load: Callable[[str], LiftObject],
    hand_points: np.ndarray,
) -> tuple[str, LiftObject, int, np.ndarray | None, int, bool]:
    """Object, its data (``load``), resting pose index, target grasp (object frame) or None,
    target row (-1 if none) and whether the target stays above the table, for a target ``kind``
    of :func:`~dg16m_env.envs.lift.targets.parse_target_option`."""
    bench = objects.ref.benchmark
    if not isinstance(kind, str):  # None, a row or poses
        object_id = objects.choose(rng, object_id)
        item = load(object_id)
        order = _pose_order(item, rng)
        if kind is None:
            return object_id, item, order[0], None, -1, True
        row = kind if isinstance(kind, int) else -1
        grasp = bench.poses[row].copy() if row >= 0 else kind
        for pose in order:
            if above_table(item.rest_poses[pose], grasp[None], hand_points)[0]:
                return object_id, item, pose, grasp, row, True
        return object_id, item, order[0], grasp, row, False
    given = object_id is not None
    tried: set[str] = set()
    while True:
        object_id = objects.choose(rng, object_id if given else None)
        item = load(object_id)
        for pose in _pose_order(item, rng):
            rows = _feasible_rows(item, pose, bench, hand_points)
            if rows.size:
                row = int(rows[rng.integers(rows.size)])
                return object_id, item, pose, bench.poses[row].copy(), row, True
        tried.add(object_id)
        if given or tried >= set(objects.object_ids):
            raise ValueError(
                f"target_grasp='benchmark': expected an object with a benchmark dual grasp "
                f"(force-closure pass, p >= {TARGET_MIN_P}) whose hands stay above the table "
                f"in a stable pose, found none for {sorted(tried)[:5]}"
            )


def draw_placement(
    item: LiftObject, pose_index: int, centre_of_mass: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The object's resting pose (4, 4) on the table (its stable pose ``pose_index``, a yaw and
    an offset) and the hands' start grasp centres (2, 3) and rotations (2, 3, 3): on opposite
    sides, clear of the object's bounding cylinder (v0's *Randomisations*).

    ``centre_of_mass``: (3,) the object's, object frame (m).
    """
    yaw = rng.uniform(-math.pi, math.pi)
    offset = rng.uniform(-OBJECT_OFFSET, OBJECT_OFFSET, size=2)
    turn = np.eye(4)
    turn[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    turn[:2, 3] = offset
    rest = turn @ item.rest_poses[pose_index]
    world_points = item.points @ rest[:3, :3].T + rest[:3, 3]
    com = rest[:3, :3] @ centre_of_mass
    com = com + rest[:3, 3]
    radius = float(np.linalg.norm(world_points[:, :2] - com[:2], axis=1).max())
    top = float(world_points[:, 2].max())

    azimuth = rng.uniform(0.0, 2.0 * math.pi)
    azimuths = (azimuth, azimuth + math.pi + rng.uniform(-math.pi / 4, math.pi / 4))
    centres, rotations = np.zeros((2, 3)), np.zeros((2, 3, 3))
    for k, phi in enumerate(azimuths):
        distance = radius + HAND_REACH + rng.uniform(*START_CLEARANCE)
        height = top * rng.uniform(0.5, 1.0) + rng.uniform(*START_HEIGHT)
        direction = np.array([math.cos(phi), math.sin(phi), 0.0])
        centres[k] = com + distance * direction
        centres[k, 2] = height
        pitch = rng.uniform(0.0, math.pi / 4)
        roll = rng.uniform(-math.pi / 2, math.pi / 2)
        approach = -direction * math.cos(pitch) + np.array([0.0, 0.0, -math.sin(pitch)])
        side = np.cross(approach, [0.0, 0.0, 1.0])
        side /= np.linalg.norm(side)
        normal = np.cross(side, approach)
        closing = math.cos(roll) * side + math.sin(roll) * normal
        rotations[k] = np.column_stack([closing, approach, np.cross(closing, approach)])
    return rest, centres, rotations


def order_target(
    grasp: np.ndarray, rest: np.ndarray, depth: float, commanded: np.ndarray
) -> np.ndarray:
    """The target's hands listed so that hand k goes to the nearer one (smaller sum of distances
    from the ``commanded`` grasp centres (2, 3) to the target's at the object's ``rest`` pose)."""
    goal = (rest @ grasp)[:, :3, 3] + depth * (rest @ grasp)[:, :3, 1]
    straight = np.linalg.norm(goal - commanded, axis=1).sum()
    swapped = np.linalg.norm(goal[::-1] - commanded, axis=1).sum()
    if swapped < straight:
        return grasp[::-1].copy()
    return grasp
