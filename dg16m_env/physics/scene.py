"""The dual-gripper MuJoCo scene: one free object and two floating Franka Panda hands.

Physics only; the trial protocol (phases, disturbances, success) lives in :mod:`dg16m_env.physics.trial`.

The model is composed with :mod:`dm_control.mjcf`: a hand is its own MJCF model (palm, two finger
bodies on slide joints, a tendon, an equality and a force actuator), attached twice to the scene
on mocap frames. Geometry comes from :data:`dataset_gen.grasps.gripper.PANDA` (the same boxes the
generator checks collisions with), so nothing is written twice.

Frames and units (SI: m, kg, s, N)
----------------------------------
* World = the object frame of :class:`~dataset_gen.objects.grasp_object.GraspObject` at the start of a trial:
  the object body starts at the origin with identity orientation.
* Each hand body is a mocap body placed at a dg16m grasp pose (gripper frame -> object frame, see
  :mod:`dataset_gen.grasps.gripper`): ``+x`` closing axis, ``+y`` approach axis.
* Finger joints measure closing travel: 0 = fully open (inner faces ``max_opening`` apart),
  ``max_opening / 2`` = closed on the hand's axis.

Gravity
-------
The model's gravity is zero; the trial applies the object's weight as an external force at its
centre of mass (``xfrc_applied``), so "gravity off / on" is a per-step control and one compiled
model serves every phase. The fingers have no weight (a real Panda finger weighs 15 g; their
simulated mass is only there for numerical stability).

Contact (measured on this machine, see DESIGN.md)
-------------------------------------------------
``implicitfast`` integrator, elliptic friction cones, ``impratio`` 10, Newton solver, condim 4
(sliding and torsional friction), ``solref = [2 * timestep, 1]``, ``solimp = [0.95, 0.99, 0.001]``,
finger armature. Each convex part of the object is its own geom (MuJoCo collides a mesh geom as
its convex hull, so non-convex objects need their convex parts; see
:mod:`dataset_gen.objects.decomposition`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import mujoco
import numpy as np
from dm_control import mjcf

from dataset_gen.grasps.gripper import PANDA, GripperModel, get_gripper
from dataset_gen.objects.grasp_object import ConvexPart, GraspObject
from dg16m_core.checks import check_fields, check_number, known_fields
from dg16m_core.errors import Dg16mError
from dg16m_core.parameters import PAPER

HAND_NAMES = ("hand0", "hand1")
"""Attachment prefixes of the two hands (MJCF namespaces)."""

OBJECT_BODY = "object"
"""Name of the object's body."""

OBJECT_CONTACTS_SENSOR = "object_contacts"
"""Sensor ``(count, min signed distance)`` over all contacts of the object (m)."""

# Collision filtering: object geoms collide with hand geoms only (hands never touch each other in
# simulation; overlapping hands are rejected before a trial, see dg16m_env.physics.trial).
_OBJECT_CONTYPE, _OBJECT_CONAFFINITY = 1, 2
_HAND_CONTYPE, _HAND_CONAFFINITY = 2, 1


class SceneError(Dg16mError, ValueError):
    """A scene cannot be built from the given object, gripper or parameters."""


def _real(name: str, value: object) -> float:
    """``value`` as a float if it is a finite number of any sign (not a bool); else SceneError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SceneError(f"{name}: expected a finite number, found {value!r}")
    return float(value)


@dataclass(frozen=True)
class SceneParameters:
    """Physical constants of the scene (SI units).

    Attributes:
        timestep: integration step (s).
        friction: sliding friction coefficient between fingers and object (the force-closure
            check's ``mu``; default ``PAPER.mu``, the release's value).
        torsional_friction: torsional friction (m), MuJoCo's second friction coefficient.
        rolling_friction: rolling friction (m).
        squeeze_force: closing force of each finger (N): one tendon actuator drives both finger
            joints of a hand, so each finger pushes with this force (default ``PAPER.f_high``:
            the Panda's continuous force, also the force-closure check's bound).
        finger_mass: simulated mass of a finger (kg).
        finger_damping: viscous damping of a finger joint (N s/m); with ``squeeze_force`` it
            sets the free closing speed (``squeeze_force / finger_damping`` m/s).
        finger_armature: added inertia of a finger joint (kg).
        solref: contact ``[timeconst, dampratio]``; ``timeconst <= 0`` means ``2 * timestep``.
        solimp: contact impedance ``[dmin, dmax, width]`` (width in m).
        impratio: frictional-to-normal impedance ratio.
        iterations: Newton solver iterations per step.
        object_mass: mass of the object (kg); ``None`` uses the object's own mass properties.
    """

    timestep: float = 0.002
    friction: float = PAPER.mu
    torsional_friction: float = 0.005
    rolling_friction: float = 0.0001
    squeeze_force: float = PAPER.f_high
    finger_mass: float = 1.0
    finger_damping: float = 500.0
    finger_armature: float = 0.05
    solref: tuple[float, float] = (-1.0, 1.0)
    solimp: tuple[float, float, float] = (0.95, 0.99, 0.001)
    impratio: float = 10.0
    iterations: int = 50
    object_mass: float | None = None

    def __post_init__(self) -> None:
        check_fields(
            self,
            error=SceneError,
            integers={"iterations": 1},
            zero_allowed=("torsional_friction", "rolling_friction", "finger_armature"),
            skip=("impratio", "solref", "solimp", "object_mass"),
        )
        if check_number("impratio", self.impratio, error=SceneError) < 1:
            raise SceneError(f"impratio: expected a number >= 1, found {self.impratio!r}")
        if self.object_mass is not None:
            check_number("object_mass", self.object_mass, error=SceneError)
        if len(self.solref) != 2 or len(self.solimp) != 3:
            raise SceneError(
                f"solref/solimp: expected 2 and 3 numbers, found {self.solref} and {self.solimp}"
            )
        timeconst = _real("solref[0]", self.solref[0])
        check_number("solref[1]", self.solref[1], error=SceneError)  # the damping ratio
        if timeconst > 0 and timeconst < 2 * self.timestep:
            raise SceneError(
                f"solref[0]: expected a time constant >= 2 * timestep = {2 * self.timestep} s "
                f"(or <= 0 for that default), found {timeconst}"
            )
        dmin, dmax, width = (_real(f"solimp[{i}]", v) for i, v in enumerate(self.solimp))
        if not (0 < dmin <= dmax < 1) or width <= 0:
            raise SceneError(
                "solimp: expected 0 < dmin <= dmax < 1 and a positive width (m), found "
                f"{self.solimp}"
            )

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SceneParameters:
        """The parameters :meth:`to_dict` wrote (e.g. a benchmark file's metadata).

        Lists become tuples; missing keys take their defaults.

        Raises:
            SceneError: ``data`` is not a mapping, has unknown keys or bad values.
        """
        values = known_fields(cls, data, what="scene parameters", error=SceneError)
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})

    @property
    def contact_solref(self) -> tuple[float, float]:
        """``solref`` with the default time constant resolved to ``2 * timestep`` (s, 1)."""
        timeconst = self.solref[0] if self.solref[0] > 0 else 2.0 * self.timestep
        return (float(timeconst), float(self.solref[1]))

    def to_dict(self) -> dict[str, Any]:
        """The fields as a JSON-ready dict, tuples as lists (:meth:`from_dict` reads it back)."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}


# --------------------------------------------------------------------------------------------
# Model composition
# --------------------------------------------------------------------------------------------


def quat_from_matrix(rotations: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions ``(w, x, y, z)`` of (..., 3, 3) rotations (MuJoCo's
    ``mju_mat2Quat``, the conversion used everywhere in :mod:`dg16m_env`)."""
    rotations = np.asarray(rotations, dtype=np.float64)
    flat = rotations.reshape(-1, 3, 3)
    out = np.empty((len(flat), 4))
    for i, R in enumerate(flat):
        mujoco.mju_mat2Quat(out[i], np.ascontiguousarray(R).ravel())
    return out.reshape(*rotations.shape[:-2], 4)


def quat_to_matrix(quat: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices of (..., 4) quaternions (w, x, y, z), normalised here."""
    q = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def _contact_defaults(model: mjcf.RootElement, params: SceneParameters) -> None:
    """Contact settings for every geom of ``model`` (an attached model keeps its own defaults,
    and MuJoCo mixes the two geoms' values, taking the larger friction: both sides must agree)."""
    geom = model.default.geom
    geom.condim = 4
    geom.friction = (params.friction, params.torsional_friction, params.rolling_friction)
    geom.solref = params.contact_solref
    geom.solimp = params.solimp


def hand_model(gripper: GripperModel, params: SceneParameters, name: str) -> mjcf.RootElement:
    """One parallel-jaw hand as an MJCF model (attach it on a mocap frame).

    Bodies: the hand root (palm box), ``finger0`` (at ``+x``, closes along ``-x``) and ``finger1``
    (at ``-x``, closes along ``+x``), each with a slide joint whose coordinate is its closing travel
    (m, 0 = open). A fixed tendon ``grip = q0 + q1`` carries one motor whose control is the
    squeezing force per finger (N, in ``[0, squeeze_force]``); an equality keeps ``q0 = q1``
    (the Panda's fingers are mechanically coupled).
    """
    model = mjcf.RootElement(model=name)
    _contact_defaults(model, params)
    palm = gripper.palm_box()
    model.worldbody.add(
        "geom",
        name="palm",
        type="box",
        size=palm.half_extents,
        pos=palm.center,
        contype=_HAND_CONTYPE,
        conaffinity=_HAND_CONAFFINITY,
        rgba=(0.85, 0.85, 0.88, 1.0),
    )
    travel = gripper.max_opening / 2.0
    finger_half = (
        gripper.finger_thickness / 2.0,
        gripper.finger_length / 2.0,
        gripper.finger_width / 2.0,
    )
    for index, (box, axis) in enumerate(
        zip(gripper.finger_boxes(), ((-1.0, 0.0, 0.0), (1.0, 0.0, 0.0)), strict=True)
    ):
        body = model.worldbody.add("body", name=f"finger{index}")
        body.add(
            "inertial",
            pos=box.center,
            mass=params.finger_mass,
            diaginertia=[params.finger_mass * 1e-4] * 3,
        )
        body.add(
            "joint",
            name=f"finger{index}",
            type="slide",
            axis=axis,
            range=(0.0, travel),
            limited=True,
            damping=params.finger_damping,
            armature=params.finger_armature,
        )
        body.add(
            "geom",
            name=f"finger{index}",
            type="box",
            size=finger_half,
            pos=box.center,
            contype=_HAND_CONTYPE,
            conaffinity=_HAND_CONAFFINITY,
            rgba=(0.2, 0.2, 0.22, 1.0),
        )
    tendon = model.tendon.add("fixed", name="grip")
    tendon.add("joint", joint="finger0", coef=1.0)
    tendon.add("joint", joint="finger1", coef=1.0)
    model.equality.add(
        "joint",
        joint1="finger0",
        joint2="finger1",
        polycoef=(0, 1, 0, 0, 0),
        solref=params.contact_solref,
        solimp=params.solimp,
    )
    model.actuator.add(
        "motor",
        name="squeeze",
        tendon="grip",
        gear=(1.0,),
        ctrllimited=True,
        ctrlrange=(0.0, params.squeeze_force),
    )
    return model


def _add_part(body: Any, model: mjcf.RootElement, part: ConvexPart, index: int) -> None:
    common = {
        "name": f"part{index}",
        "pos": part.pose[:3, 3],
        "quat": quat_from_matrix(part.pose[:3, :3]),
        "contype": _OBJECT_CONTYPE,
        "conaffinity": _OBJECT_CONAFFINITY,
        "rgba": (0.55, 0.65, 0.8, 1.0),
    }
    if part.kind == "box":
        body.add("geom", type="box", size=part.size, **common)
    elif part.kind == "cylinder":
        body.add("geom", type="cylinder", size=part.size, **common)
    else:
        assert part.vertices is not None
        mesh = model.asset.add("mesh", name=f"part{index}", vertex=part.vertices.ravel())
        body.add("geom", type="mesh", mesh=mesh, **common)


def object_parts_or_error(
    obj: GraspObject, parts: Sequence[ConvexPart] | None
) -> tuple[ConvexPart, ...]:
    """The convex parts to simulate: ``parts`` if given, else the object's own."""
    chosen = tuple(parts) if parts is not None else obj.parts
    if not chosen:
        raise SceneError(
            f"{obj.object_id}: expected convex parts (procedural objects carry them; for a mesh "
            "use dataset_gen.objects.decomposition.object_parts), found none. A mesh geom collides as its "
            "convex hull, which gives false successes on non-convex objects."
        )
    return chosen


def scene_model(
    obj: GraspObject,
    *,
    gripper: str | GripperModel = PANDA,
    params: SceneParameters | None = None,
    parts: Sequence[ConvexPart] | None = None,
) -> mjcf.RootElement:
    """Compose the MJCF scene for one object (see the module docstring for frames and units).

    Args:
        obj: the object (object frame; its mass properties give the inertia).
        gripper: the hand model (both hands are the same).
        params: physical constants.
        parts: convex parts in the object frame; default ``obj.parts``.

    Returns:
        The root MJCF element; :func:`compile_scene` turns it into a :class:`Scene`.
    """
    params = params or SceneParameters()
    gripper = get_gripper(gripper)
    chosen = object_parts_or_error(obj, parts)
    root = mjcf.RootElement(model=f"dg16m_{obj.object_id}")
    root.compiler.angle = "radian"
    root.option.timestep = params.timestep
    root.option.integrator = "implicitfast"
    root.option.cone = "elliptic"
    root.option.impratio = params.impratio
    root.option.solver = "Newton"
    root.option.iterations = params.iterations
    root.option.gravity = (0.0, 0.0, 0.0)
    _contact_defaults(root, params)
    visual = getattr(root.visual, "global")  # "global" is a Python keyword
    visual.offwidth, visual.offheight = 1280, 960
    root.worldbody.add("light", pos=(0, 0, 3), dir=(0, 0, -1), directional=True)

    mass_props = obj.mass_properties
    mass = params.object_mass if params.object_mass is not None else mass_props.mass
    inertia = np.asarray(mass_props.inertia) * (mass / mass_props.mass)
    body = root.worldbody.add("body", name=OBJECT_BODY)
    body.add("freejoint", name=OBJECT_BODY)
    body.add(
        "inertial",
        pos=mass_props.center_of_mass,
        mass=mass,
        fullinertia=(
            inertia[0, 0],
            inertia[1, 1],
            inertia[2, 2],
            inertia[0, 1],
            inertia[0, 2],
            inertia[1, 2],
        ),
    )
    for index, part in enumerate(chosen):
        _add_part(body, root, part, index)

    # Per-step measurements for the trial protocol: all object contacts (count, deepest signed
    # distance in m; negative = penetration) and the contact count with each hand.
    root.sensor.add(
        "contact", name=OBJECT_CONTACTS_SENSOR, body1=body, data="found dist", reduce="mindist"
    )
    for name in HAND_NAMES:
        frame = root.attach(hand_model(gripper, params, name))
        frame.mocap = True
        root.sensor.add(
            "contact", name=f"{name}_contacts", body1=body, subtree2=frame, data="found"
        )
    return root


@dataclass
class SceneIndices:
    """What every compiled scene of an object and two hands indexes: the trial scene
    (:class:`Scene`) and the Lift task's (:class:`~dg16m_env.physics.lift_scene.LiftScene`) add
    their own to these (:func:`scene_indices` finds them in a compiled model).

    Attributes:
        model: the compiled ``mujoco.MjModel``.
        object_id: the object's id.
        object_mass: kg.
        object_body: body id of the object.
        object_qpos: slice of ``qpos`` holding the object's free joint (pos (3), quat (4)).
        object_qvel: slice of ``qvel`` holding the free joint's velocity (linear (3) in the
            world frame, then angular (3)), from ``model.jnt_dofadr``.
        hand_bodies: (2,) body ids of the hands.
        hand_geoms: per hand, the geom ids of palm and fingers.
        object_geoms: geom ids of the object's parts.
        finger_qpos: (2, 2) ``qpos`` addresses of each hand's finger joints.
        squeeze_actuators: (2,) actuator ids of the hands' squeeze motors.
        gripper: the hand model.
        params: the physical constants it was built with.
        xml: the MJCF text (for inspection and replay).
    """

    model: mujoco.MjModel
    object_id: str
    object_mass: float
    object_body: int
    object_qpos: slice
    object_qvel: slice
    hand_bodies: np.ndarray
    hand_geoms: tuple[np.ndarray, np.ndarray]
    object_geoms: np.ndarray
    finger_qpos: np.ndarray
    squeeze_actuators: np.ndarray
    gripper: GripperModel
    params: SceneParameters
    xml: str


@dataclass
class Scene(SceneIndices):
    """A compiled scene with the indices the trial protocol needs: :class:`SceneIndices`' (the
    hands are mocap bodies) and

    Attributes:
        hand_mocap: (2,) mocap ids of the hands.
    """

    hand_mocap: np.ndarray

    def __repr__(self) -> str:  # the model and its XML are large: name what they hold
        model = self.model
        return (
            f"Scene({self.object_id!r}, mass {self.object_mass:.3g} kg, "
            f"{len(self.object_geoms)} object geoms, {model.nbody} bodies, {model.ngeom} geoms, "
            f"timestep {model.opt.timestep:g} s, gripper {self.gripper.name!r})"
        )


def named_index(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str) -> int:
    """The id of the ``kind`` element ``name`` of a compiled scene (``SceneError`` if none)."""
    index = mujoco.mj_name2id(model, kind, name)
    if index < 0:
        raise SceneError(f"internal: expected {name!r} in the compiled scene, found none")
    return int(index)


def scene_indices(
    model: mujoco.MjModel,
    xml: str,
    object_id: str,
    gripper: GripperModel,
    params: SceneParameters,
) -> dict[str, Any]:
    """The :class:`SceneIndices` of a compiled scene, by field name.

    Raises:
        SceneError: an element of the object or the hands is missing (an internal error).
    """
    body, geom = mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_GEOM
    joint, actuator = mujoco.mjtObj.mjOBJ_JOINT, mujoco.mjtObj.mjOBJ_ACTUATOR
    object_body = named_index(model, body, OBJECT_BODY)
    object_joint = named_index(model, joint, OBJECT_BODY)
    address, dof = int(model.jnt_qposadr[object_joint]), int(model.jnt_dofadr[object_joint])
    return {
        "model": model,
        "object_id": object_id,
        "object_mass": float(model.body_mass[object_body]),
        "object_body": object_body,
        "object_qpos": slice(address, address + 7),
        "object_qvel": slice(dof, dof + 6),
        # dm_control names the attachment frame "<model>/"
        "hand_bodies": np.array([named_index(model, body, f"{n}/") for n in HAND_NAMES]),
        "hand_geoms": tuple(
            np.array([named_index(model, geom, f"{n}/{g}") for g in ("palm", "finger0", "finger1")])
            for n in HAND_NAMES
        ),
        "object_geoms": np.flatnonzero(model.geom_bodyid == object_body),
        "finger_qpos": np.array(
            [
                [model.jnt_qposadr[named_index(model, joint, f"{n}/finger{i}")] for i in (0, 1)]
                for n in HAND_NAMES
            ]
        ),
        "squeeze_actuators": np.array(
            [named_index(model, actuator, f"{n}/squeeze") for n in HAND_NAMES]
        ),
        "gripper": gripper,
        "params": params,
        "xml": xml,
    }


def compile_model(root: mjcf.RootElement, object_id: str) -> tuple[mujoco.MjModel, str]:
    """Compile an MJCF scene; returns the model and its XML.

    Raises:
        SceneError: MuJoCo's compiler refused it (degenerate meshes and the like).
    """
    xml = root.to_xml_string()
    try:
        return mujoco.MjModel.from_xml_string(xml, root.get_assets()), xml
    except ValueError as exc:
        raise SceneError(f"{object_id}: MuJoCo could not compile the scene: {exc}") from exc


def compile_scene(
    obj: GraspObject,
    *,
    gripper: str | GripperModel = PANDA,
    params: SceneParameters | None = None,
    parts: Sequence[ConvexPart] | None = None,
) -> Scene:
    """Build and compile the scene for ``obj`` (once per object; every trial reuses it)."""
    params = params or SceneParameters()
    gripper_model = get_gripper(gripper)
    root = scene_model(obj, gripper=gripper_model, params=params, parts=parts)
    model, xml = compile_model(root, obj.object_id)
    indices = scene_indices(model, xml, obj.object_id, gripper_model, params)
    return Scene(
        **indices,
        hand_mocap=np.array([model.body_mocapid[b] for b in indices["hand_bodies"]]),
    )
