"""The lift scene: one free object resting on a table under real gravity, two floating Panda hands.

Physics only; the task (actions, observations, reward, success) lives in
:mod:`dg16m_env.envs.lift.task`.

The model is the benchmark's trial scene (:func:`dg16m_env.physics.scene.scene_model`: the object as its
convex parts with its inertia, two :func:`~dg16m_env.physics.scene.hand_model` hands, the contact
settings of :class:`~dg16m_env.physics.scene.SceneParameters`) recomposed with :mod:`dm_control.mjcf`
for lifting:

* **Gravity** is real (``-gravity`` along world ``z``, default the protocol's ``PAPER.gravity``,
  10 m/s^2), not an external force as in the trial.
* **Table**: a fixed box whose top face is the plane ``z = 0``, :data:`TABLE_HALF_SIZE` m from its
  centre (the world origin) to each side. It collides with the object only; the hands pass through
  it (the task keeps them above it, see :func:`lowest_hand_z`).
* **Hands**: each hand is a free body (the attachment frame of its hand model) held by a stiff
  weld (:data:`WELD_TIMECONST`) to a mocap *target* body ``hand<k>_target``. The task moves the
  targets kinematically (they stand for the arms); the hands follow within a fraction of a
  millimetre and, unlike mocap bodies, have real velocities, so friction at the pads carries the
  object when the hands lift. (A mocap body moves by teleporting: MuJoCo gives it zero velocity,
  and an object squeezed between mocap fingers stays put while the fingers slide up past it.)
  Hands and fingers are gravity-compensated (the arm carries them); the fingers weigh nothing
  along their slides, as in the trial scene.
* **Fingers**: the squeeze motor of each hand takes a signed force in
  ``[-squeeze_force, squeeze_force]`` (N per finger): positive closes, negative opens (the trial
  scene's motor only closes).
* **Sensors**: the trial scene's contact sensors (all object contacts, contacts per hand) plus
  one per finger: ``hand<k>_finger<i>_contacts`` counts the contacts between the object and
  finger ``i`` of hand ``k``.

Frames and units (SI: m, kg, s, N)
----------------------------------
World = table frame: ``z`` up, the table top at ``z = 0``, the table centred on the origin. Hand
frames are dg16m grasp frames (see :mod:`dataset_gen.grasps.gripper`: ``+x`` closing axis, ``+y``
approach axis, origin at the flange). The object's body frame is its object frame (the frame of
its benchmark grasps).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
import trimesh
from dm_control import mjcf

from dataset_gen.grasps.gripper import PANDA, GripperModel, get_gripper
from dataset_gen.objects.grasp_object import ConvexPart, GraspObject
from dg16m_core.checks import check_number
from dg16m_core.parameters import PAPER
from dg16m_env.physics.scene import (
    HAND_NAMES,
    OBJECT_BODY,
    OBJECT_CONTACTS_SENSOR,
    SceneError,
    SceneIndices,
    SceneParameters,
    compile_model,
    named_index,
    object_parts_or_error,
    scene_indices,
    scene_model,
)

TABLE_HALF_SIZE = 1.0
"""Half side of the square table top (m); the table spans ``[-1, 1] x [-1, 1]`` m."""

TABLE_THICKNESS = 0.05
"""Thickness of the table box (m); its top face is ``z = 0``."""

WELD_TIMECONST = 0.01
"""Time constant of the welds holding the hands to their targets (s; damping ratio 1). Holding
half of a 6 kg object, a hand lags its target by about 0.1 mm."""

CYLINDER_SEGMENTS = 64
"""Points per rim used to approximate a cylinder part in the resting-pose hull."""

TABLE_RGBA = (0.62, 0.5, 0.38, 1.0)
"""Colour of the table top (wood)."""

HAND_RGBA = ((0.95, 0.55, 0.15, 1.0), (0.2, 0.7, 0.95, 1.0))
"""Finger colours of hand 0 (orange) and hand 1 (blue), as in :mod:`dg16m_env.physics.replay`."""

# Collision filtering of the table: it collides with the object (contype 1 in the trial scene)
# and not with the hands (contype 2).
_TABLE_CONTYPE, _TABLE_CONAFFINITY = 0, 1


def _attachment_frame(root: mjcf.RootElement, name: str) -> mjcf.Element:
    frame = root.find("attachment_frame", name)
    if frame is None:  # the trial scene's layout changed
        raise SceneError(f"internal: expected the hand attachment frame {name!r}, found none")
    return frame


def lift_model(
    obj: GraspObject,
    *,
    gripper: str | GripperModel = PANDA,
    params: SceneParameters | None = None,
    parts: Sequence[ConvexPart] | None = None,
    gravity: float = PAPER.gravity,
) -> mjcf.RootElement:
    """Compose the MJCF lift scene for one object (see the module docstring).

    Args:
        obj: the object (object frame; its mass properties give the inertia).
        gripper: the hand model (both hands are the same).
        params: physical constants (contact, squeeze force, timestep).
        parts: convex parts in the object frame; default ``obj.parts``.
        gravity: gravitational acceleration (m/s^2, > 0; acts along world ``-z``).

    Returns:
        The root MJCF element; :func:`compile_lift_scene` turns it into a :class:`LiftScene`.

    Raises:
        SceneError: bad gravity, or no convex parts.
    """
    gravity = check_number("gravity", gravity, error=SceneError)
    params = params or SceneParameters()
    root = scene_model(obj, gripper=gripper, params=params, parts=parts)
    root.model = f"dg16m_lift_{obj.object_id}"
    root.option.gravity = (0.0, 0.0, -float(gravity))
    root.asset.add(
        "texture",
        name="grid",
        type="2d",
        builtin="checker",
        rgb1=TABLE_RGBA[:3],
        rgb2=tuple(0.9 * c for c in TABLE_RGBA[:3]),
        width=256,
        height=256,
    )
    material = root.asset.add("material", name="table", texture="grid", texrepeat=(8, 8))
    root.worldbody.add(
        "geom",
        name="table",
        type="box",
        size=(TABLE_HALF_SIZE, TABLE_HALF_SIZE, TABLE_THICKNESS / 2.0),
        pos=(0.0, 0.0, -TABLE_THICKNESS / 2.0),
        contype=_TABLE_CONTYPE,
        conaffinity=_TABLE_CONAFFINITY,
        material=material,
    )
    root.worldbody.add(
        "light", pos=(1.0, -1.0, 2.5), dir=(-0.4, 0.4, -1.0), diffuse=(0.4, 0.4, 0.4)
    )
    object_body = root.find("body", OBJECT_BODY)
    force = float(params.squeeze_force)
    for index, name in enumerate(HAND_NAMES):
        frame = _attachment_frame(root, name)
        frame.mocap = None  # a free body welded to a mocap target instead (module docstring)
        frame.add("freejoint")
        target = root.worldbody.add("body", name=f"{name}_target", mocap=True)
        root.equality.add(
            "weld",
            name=f"{name}_weld",
            body1=target,
            body2=frame,
            relpose=(0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0),
            solref=(WELD_TIMECONST, 1.0),
        )
        root.find("actuator", f"{name}/squeeze").ctrlrange = (-force, force)
        for finger in ("finger0", "finger1"):
            body = root.find("body", f"{name}/{finger}")
            body.gravcomp = 1.0
            root.sensor.add(
                "contact",
                name=f"{name}_{finger}_contacts",
                body1=object_body,
                body2=body,
                data="found",
            )
            root.find("geom", f"{name}/{finger}").rgba = HAND_RGBA[index]
        palm = [0.5 + 0.5 * c for c in HAND_RGBA[index][:3]]
        root.find("geom", f"{name}/palm").rgba = (*palm, 1.0)
    return root


@dataclass
class LiftScene(SceneIndices):
    """A compiled lift scene with the indices the task needs: :class:`SceneIndices`' (the hands
    are free bodies welded to mocap targets; ``object_qvel``'s linear part is the body origin's,
    world frame, its angular part in the body frame) and

    Attributes:
        hand_qpos: (2,) ``qpos`` addresses of the hands' free joints (pos (3), quat (4)).
        hand_qvel: (2,) ``qvel`` addresses of the hands' free joints.
        target_mocap: (2,) mocap ids of the hands' targets: always ``[0, 1]`` (the scene's only
            mocap bodies, so ``data.mocap_pos`` holds the targets in hand order).
        finger_contacts: (2, 2) ``sensordata`` addresses of the contact counts between the
            object and finger ``i`` of hand ``k``.
        hand_contacts: (2,) ``sensordata`` addresses of the contact counts between the object
            and each hand (palm and fingers).
        object_contacts: ``sensordata`` address of the object's contact count (table included).
        table_geom: geom id of the table.
        gravity: m/s^2.

    The compiled model also has the hands' ``body_gravcomp`` set to 1 (an attachment frame takes
    no ``gravcomp`` attribute in :mod:`dm_control.mjcf`).
    """

    hand_qpos: np.ndarray
    hand_qvel: np.ndarray
    target_mocap: np.ndarray
    finger_contacts: np.ndarray
    hand_contacts: np.ndarray
    object_contacts: int
    table_geom: int
    gravity: float

    def __repr__(self) -> str:  # the model and its XML are large: name what they hold
        model = self.model
        return (
            f"LiftScene({self.object_id!r}, mass {self.object_mass:.3g} kg, "
            f"{len(self.object_geoms)} object geoms, {model.nbody} bodies, "
            f"timestep {model.opt.timestep:g} s, gravity {self.gravity:g} m/s^2)"
        )


def compile_lift_scene(
    obj: GraspObject,
    *,
    gripper: str | GripperModel = PANDA,
    params: SceneParameters | None = None,
    parts: Sequence[ConvexPart] | None = None,
    gravity: float = PAPER.gravity,
) -> LiftScene:
    """Build and compile the lift scene for ``obj`` (see :func:`lift_model` for the arguments).

    Raises:
        SceneError: bad arguments, or MuJoCo could not compile the scene.
    """
    params = params or SceneParameters()
    gripper_model = get_gripper(gripper)
    root = lift_model(obj, gripper=gripper_model, params=params, parts=parts, gravity=gravity)
    model, xml = compile_model(root, obj.object_id)
    indices = scene_indices(model, xml, obj.object_id, gripper_model, params)

    def named(kind: mujoco.mjtObj, name: str) -> int:
        return named_index(model, kind, name)

    body, geom, sensor = (
        mujoco.mjtObj.mjOBJ_BODY,
        mujoco.mjtObj.mjOBJ_GEOM,
        mujoco.mjtObj.mjOBJ_SENSOR,
    )
    hand_bodies = indices["hand_bodies"]
    model.body_gravcomp[hand_bodies] = 1.0  # the arms carry the hands (see LiftScene)
    hand_joints = model.body_jntadr[hand_bodies]
    if np.any(model.jnt_type[hand_joints] != mujoco.mjtJoint.mjJNT_FREE):
        raise SceneError("internal: expected a free joint on each hand of the lift scene")
    target_mocap = np.array(
        [model.body_mocapid[named(body, f"{name}_target")] for name in HAND_NAMES]
    )
    if not np.array_equal(target_mocap, np.arange(len(HAND_NAMES))):  # the task relies on it
        raise SceneError(f"internal: expected the hand targets as mocap 0, 1, found {target_mocap}")
    return LiftScene(
        **indices,
        hand_qpos=model.jnt_qposadr[hand_joints].copy(),
        hand_qvel=model.jnt_dofadr[hand_joints].copy(),
        target_mocap=target_mocap,
        finger_contacts=np.array(
            [
                [model.sensor_adr[named(sensor, f"{name}_finger{i}_contacts")] for i in (0, 1)]
                for name in HAND_NAMES
            ]
        ),
        hand_contacts=np.array(
            [model.sensor_adr[named(sensor, f"{name}_contacts")] for name in HAND_NAMES]
        ),
        object_contacts=int(model.sensor_adr[named(sensor, OBJECT_CONTACTS_SENSOR)]),
        table_geom=named(geom, "table"),
        gravity=float(gravity),
    )


# --------------------------------------------------------------------------------------------
# Geometry: resting poses and hand clearance
# --------------------------------------------------------------------------------------------


def part_points(parts: Sequence[ConvexPart]) -> np.ndarray:
    """(P, 3) points whose convex hull is the union hull of ``parts`` (object frame, m): box
    corners, cylinder rims (:data:`CYLINDER_SEGMENTS` points each) and mesh vertices."""
    points = []
    for part in parts:
        if part.kind == "box":
            signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij"))
            local = signs.reshape(3, -1).T * np.asarray(part.size)
        elif part.kind == "cylinder":
            radius, half_length = part.size
            angle = np.linspace(0.0, 2.0 * np.pi, CYLINDER_SEGMENTS, endpoint=False)
            rim = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)
            local = np.concatenate(
                [np.column_stack([rim, np.full(len(rim), z)]) for z in (-half_length, half_length)]
            )
        else:
            assert part.vertices is not None
            local = np.asarray(part.vertices, dtype=np.float64)
        points.append(local @ part.pose[:3, :3].T + part.pose[:3, 3])
    return np.concatenate(points)


def stable_rest_poses(
    obj: GraspObject, parts: Sequence[ConvexPart] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The object's stable resting poses on the table, most probable first.

    ``trimesh``'s :meth:`~trimesh.Trimesh.compute_stable_poses` on the convex hull of the
    simulated parts (what touches the table) with the object's centre of mass: each pose puts the
    hull's lowest point on ``z = 0`` and the centre of mass on the ``z`` axis (``x = y = 0``).

    Returns:
        poses: (n, 4, 4) object frame -> world transforms.
        probabilities: (n,) the quasi-static probability of each pose (sums to ~1).

    Raises:
        SceneError: no convex parts.
    """
    points = part_points(object_parts_or_error(obj, parts))
    hull = trimesh.convex.convex_hull(points)
    com = np.asarray(obj.mass_properties.center_of_mass, dtype=np.float64)
    transforms, probabilities = hull.compute_stable_poses(center_mass=com)
    order = np.argsort(-np.asarray(probabilities), kind="stable")
    poses = np.asarray(transforms, dtype=np.float64)[order]
    for pose in poses:  # exact contact with the table and the centre of mass over the origin
        pose[2, 3] -= float((points @ pose[:3, :3].T + pose[:3, 3])[:, 2].min())
        pose[:2, 3] -= pose[:2, :3] @ com + pose[:2, 3]
    return poses, np.asarray(probabilities, dtype=np.float64)[order]


def hand_points(gripper: str | GripperModel = PANDA) -> np.ndarray:
    """(48, 3) corners of the hand's collision boxes fully open and fully closed (gripper frame,
    m): their convex hull holds the hand at any opening."""
    model = get_gripper(gripper)
    return np.concatenate(
        [
            box.corners
            for opening in (0.0, model.max_opening)
            for box in model.collision_boxes(opening)
        ]
    )


def lowest_hand_z(poses: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(...) the lowest world ``z`` of a hand (``points`` from :func:`hand_points`) at each of the
    (..., 4, 4) hand poses (gripper -> world, m)."""
    poses = np.asarray(poses, dtype=np.float64)
    z = np.einsum("...j,pj->...p", poses[..., 2, :3], points) + poses[..., 2, 3, None]
    return z.min(axis=-1)


_MOCAP_STATE = int(mujoco.mjtState.mjSTATE_MOCAP_POS | mujoco.mjtState.mjSTATE_MOCAP_QUAT)
_BADQACC = int(mujoco.mjtWarning.mjWARN_BADQACC)
_NO_SENSORS = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)


def step_hand_targets(model: mujoco.MjModel, data: mujoco.MjData, targets: np.ndarray) -> bool:
    """One physics step per row of ``targets`` ((n, 14): both hands' target flange positions
    (m), then their quaternions: the ``mjSTATE_MOCAP_POS | mjSTATE_MOCAP_QUAT`` state of the
    scene's two mocap bodies), the row set before its step. The sensors (contact counts) are
    computed at the last step only: they feed nothing back into the physics (the scene has no
    sensor history). Returns whether the simulation went unstable on the way (MuJoCo's
    bad-acceleration warning, or a position or velocity that is not finite)."""
    badqacc = data.warning[_BADQACC]
    warnings_before = int(badqacc.number)
    flags = model.opt.disableflags
    model.opt.disableflags = flags | _NO_SENSORS
    try:
        for row in targets[:-1]:
            mujoco.mj_setState(model, data, row, _MOCAP_STATE)
            mujoco.mj_step(model, data)
    finally:
        model.opt.disableflags = flags
    mujoco.mj_setState(model, data, targets[-1], _MOCAP_STATE)
    mujoco.mj_step(model, data)
    return (
        int(badqacc.number) > warnings_before
        or not np.isfinite(data.qpos).all()
        or not np.isfinite(data.qvel).all()
    )
