"""Parallel-jaw gripper models and jaw closing (``contacts_from_pose``).

Grasp frame convention (all grippers, all files written by dg16m)
-----------------------------------------------------------------
A grasp is a (4, 4) rigid transform ``T`` from the gripper frame to the object frame:

* ``+x`` is the closing axis: finger 0 sits at ``x = +opening/2``, finger 1 at ``-opening/2``;
  they close towards ``x = 0``.
* ``+y`` is the approach axis, pointing from the palm towards the fingertips (into the object).
* ``+z = x × y`` is normal to the plane of the fingers.
* The origin lies on the approach axis at the gripper's base; the contact points of an ideal
  centred grasp lie at ``(±w/2, contact_depth, 0)``.

This is the frame of the DG16M release's ``grasps/grasps`` (checked on a real release file: both
contacts of every stored single-arm grasp sit at ``x = ±w/2, y = 0.0675 m, z = 0``, and no object
surface lies at ``y < 0``). The release sampled with a Robotiq 2F-85, so :data:`ROBOTIQ_2F85` has
``contact_depth = 0.0675`` and its palm face at ``y = 0``.

ACRONYM files use ``+z`` as the approach axis; ``dataset_gen.io.acronym_to_dg16m`` converts.
The Franka Panda hand here has its origin at the hand's mounting flange, like ACRONYM's.

Geometry is a set of boxes (palm and two fingers) fitted to the real hands: for the Panda to the
ACRONYM Panda collision mesh (fingers 0.0585-0.1122 m along the approach axis, 0.02 x 0.02 m pads,
0.08 m opening), for the 2F-85 to the public drawing (approximate, documented per field).
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import fcl
import numpy as np
import trimesh

from dataset_gen.objects.grasp_object import GraspObject, is_rigid
from dataset_gen.objects.ray_hits import segment_hits
from dg16m_core.errors import GripperError
from dg16m_core.parameters import PAPER

# --------------------------------------------------------------------------------------------
# Geometry
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Box:
    """Axis-aligned box in the gripper frame.

    Attributes:
        center: (3,) m.
        half_extents: (3,) m.
    """

    center: tuple[float, float, float]
    half_extents: tuple[float, float, float]

    def to_mesh(self) -> trimesh.Trimesh:
        mesh = trimesh.creation.box(extents=2.0 * np.asarray(self.half_extents))
        mesh.apply_translation(self.center)
        return mesh

    @property
    def corners(self) -> np.ndarray:
        """(8, 3) corner points."""
        signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, -1).T
        return np.asarray(self.center) + signs * np.asarray(self.half_extents)


@dataclass(frozen=True)
class GripperModel:
    """A parallel-jaw gripper in the dg16m grasp frame (see the module docstring). Units: m, N.

    Attributes:
        name: registry name.
        max_opening: distance between the inner finger faces when fully open (m).
        palm_depth: y of the palm face; the object may not come closer to the origin (m).
        finger_tip: y of the fingertips (m).
        contact_depth: y of the pad centre, where sampled grasps put their contacts (m).
        finger_thickness: finger size along x, outward from the inner face (m).
        finger_width: finger size along z (m).
        palm_half_extents: (3,) half sizes of the palm box, which spans y in
            ``[palm_depth - 2 * palm_half_extents[1], palm_depth]`` (m).
        max_force: continuous squeezing force of the hand (N).
    """

    name: str
    max_opening: float
    palm_depth: float
    finger_tip: float
    contact_depth: float
    finger_thickness: float
    finger_width: float
    palm_half_extents: tuple[float, float, float]
    max_force: float
    description: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if not (self.palm_depth < self.contact_depth < self.finger_tip):
            raise GripperError(
                f"{self.name}: expected palm_depth < contact_depth < finger_tip, found "
                f"{self.palm_depth}, {self.contact_depth}, {self.finger_tip}"
            )

    @property
    def finger_length(self) -> float:
        """Length of the closing region along the approach axis (m)."""
        return self.finger_tip - self.palm_depth

    def _opening(self, opening: float | None) -> float:
        if opening is None:
            return self.max_opening
        if not (0.0 <= opening <= self.max_opening):
            raise GripperError(
                f"{self.name}: expected an opening in [0, {self.max_opening}] m, found {opening}"
            )
        return float(opening)

    def palm_box(self) -> Box:
        hx, hy, hz = self.palm_half_extents
        return Box((0.0, self.palm_depth - hy, 0.0), (hx, hy, hz))

    def finger_boxes(self, opening: float | None = None) -> tuple[Box, Box]:
        """Finger 0 (at +x) and finger 1 (at -x) for ``opening`` (default: fully open)."""
        w = self._opening(opening)
        hx = self.finger_thickness / 2.0
        hy = self.finger_length / 2.0
        y = self.palm_depth + hy
        half = (hx, hy, self.finger_width / 2.0)
        return Box((w / 2.0 + hx, y, 0.0), half), Box((-w / 2.0 - hx, y, 0.0), half)

    def collision_boxes(self, opening: float | None = None) -> tuple[Box, ...]:
        """Palm, finger 0, finger 1."""
        return (self.palm_box(), *self.finger_boxes(opening))

    def collision_mesh(self, opening: float | None = None) -> trimesh.Trimesh:
        """All collision boxes as one mesh in the gripper frame."""
        return trimesh.util.concatenate([b.to_mesh() for b in self.collision_boxes(opening)])

    def control_points(self, opening: float | None = None) -> np.ndarray:
        """(6, 3) keypoints for learning: base, palm centre, finger 0 base and tip, finger 1 base
        and tip (inner faces). The usual compact gripper template for grasp networks."""
        w = self._opening(opening) / 2.0
        return np.array(
            [
                [0.0, 0.0, 0.0],
                [0.0, self.palm_depth, 0.0],
                [w, self.palm_depth, 0.0],
                [w, self.finger_tip, 0.0],
                [-w, self.palm_depth, 0.0],
                [-w, self.finger_tip, 0.0],
            ]
        )

    def surface_points(
        self, count: int, *, seed: int = 0, opening: float | None = None
    ) -> np.ndarray:
        """(count, 3) points sampled uniformly on the collision geometry (deterministic in seed)."""
        if count <= 0:
            raise GripperError(f"count: expected a positive number of points, found {count}")
        points, _ = trimesh.sample.sample_surface(self.collision_mesh(opening), count, seed=seed)
        return np.asarray(points, dtype=np.float64)

    def skeleton(self, opening: float | None = None) -> np.ndarray:
        """(5, 2, 3) line segments for drawing: stem, cross bar, two fingers, tip marker."""
        w = self._opening(opening) / 2.0
        stem_start = self.palm_depth - 2.0 * self.palm_half_extents[1]
        return np.array(
            [
                [[0.0, stem_start, 0.0], [0.0, self.palm_depth, 0.0]],
                [[-w, self.palm_depth, 0.0], [w, self.palm_depth, 0.0]],
                [[w, self.palm_depth, 0.0], [w, self.finger_tip, 0.0]],
                [[-w, self.palm_depth, 0.0], [-w, self.finger_tip, 0.0]],
                [[-w, self.contact_depth, 0.0], [w, self.contact_depth, 0.0]],
            ]
        )

    def pose_from_contacts(
        self, p0: np.ndarray, p1: np.ndarray, approach: np.ndarray
    ) -> np.ndarray:
        """(4, 4) grasp frame putting finger 0 on ``p0`` and finger 1 on ``p1`` (object frame, m).

        ``approach`` is made orthogonal to the grasp axis; the contacts land at
        ``(±|p0 - p1|/2, contact_depth, 0)``.
        """
        p0, p1, approach = (np.asarray(v, dtype=np.float64) for v in (p0, p1, approach))
        x = p0 - p1
        norm = np.linalg.norm(x)
        if norm <= 1e-9:
            raise GripperError("expected two distinct contact points, found coincident ones")
        x /= norm
        y = approach - x * (approach @ x)
        if np.linalg.norm(y) <= 1e-9:
            raise GripperError("expected an approach direction not parallel to the grasp axis")
        y /= np.linalg.norm(y)
        T = np.eye(4)
        T[:3, 0], T[:3, 1], T[:3, 2] = x, y, np.cross(x, y)
        T[:3, 3] = (p0 + p1) / 2.0 - self.contact_depth * y
        return T


PANDA = GripperModel(
    name="panda",
    max_opening=0.08,
    palm_depth=0.066,
    finger_tip=0.1122,
    contact_depth=0.1034,
    finger_thickness=0.02,
    finger_width=0.02,
    palm_half_extents=(0.1025, 0.033, 0.0316),
    # The release's force bound f_high is, by definition, this hand's continuous force.
    max_force=PAPER.f_high,
    description=(
        "Franka Emika Panda hand. Origin at the flange; palm face at 0.066 m (the hull of the "
        "ACRONYM collision mesh between the fingers), fingertips at 0.1122 m, contact depth at "
        f"Franka's TCP (0.1034 m). {PAPER.f_high:g} N continuous force."
    ),
)
"""The Franka Emika Panda hand: the gripper of the benchmark's trials (its ``description``)."""

ROBOTIQ_2F85 = GripperModel(
    name="robotiq_2f85",
    max_opening=0.085,
    palm_depth=0.0,
    finger_tip=0.0875,
    contact_depth=0.0675,
    finger_thickness=0.01,
    finger_width=0.022,
    palm_half_extents=(0.05, 0.06, 0.02),
    max_force=235.0,
    description=(
        "Robotiq 2F-85, the gripper the DG16M release sampled with, in the release's frame: palm "
        "face at y = 0 and contacts at y = 0.0675 m (both measured on a release file). The palm box "
        "is fitted to the region the release's grasps keep free of the object (|x| < 0.05, "
        "|z| < 0.02, y < 0); pads are 22 mm wide, 85 mm stroke. The release's own collision "
        "model was shorter: object material sits where these fingertips are for some of its grasps."
    ),
)
"""The Robotiq 2F-85 in the DG16M release's frame: the gripper the release sampled with."""

GRIPPERS: dict[str, GripperModel] = {g.name: g for g in (PANDA, ROBOTIQ_2F85)}
"""Registered grippers by name."""


def get_gripper(name: str | GripperModel) -> GripperModel:
    """Look up a gripper by name (``"panda"``, ``"robotiq_2f85"``); models pass through."""
    if isinstance(name, GripperModel):
        return name
    try:
        return GRIPPERS[name]
    except KeyError:
        raise GripperError(f"gripper: expected one of {sorted(GRIPPERS)}, found {name!r}") from None


# --------------------------------------------------------------------------------------------
# Closing the jaws
# --------------------------------------------------------------------------------------------


class ContactStatus(enum.IntEnum):
    """Outcome of closing the jaws at one pose."""

    OK = 0
    """Both jaws touch the object; contacts are valid."""
    MISS = 1
    """The jaws close on nothing."""
    COLLISION = 2
    """The open gripper (palm or fingers) already intersects the object."""
    TOO_WIDE = 3
    """The object crosses both open fingers: it is wider than the opening there."""
    INVALID_POSE = 4
    """The transform is not rigid or not finite."""


_REASONS = {
    ContactStatus.OK: "both jaws touch the object",
    ContactStatus.MISS: "the jaws close on nothing",
    ContactStatus.COLLISION: "the open gripper intersects the object",
    ContactStatus.TOO_WIDE: "the object is wider than the opening (it crosses both open fingers)",
    ContactStatus.INVALID_POSE: "the pose is not a finite rigid transform",
}


@dataclass(frozen=True)
class JawContacts:
    """Result of :func:`contacts_from_pose` for N poses (object frame, m).

    Attributes:
        status: (N,) :class:`ContactStatus` codes (int8).
        points: (N, 2, 3) contact of finger 0 (+x) and finger 1 (-x); NaN unless OK.
        normals: (N, 2, 3) unit outward face normals at the contacts (pointing at the finger);
            NaN unless OK. The force a finger applies pushes along ``-normal``.
        face_ids: (N, 2) index of the touched face; -1 unless OK.
        width: (N,) distance between the jaws when they stop (m); NaN unless OK.
    """

    status: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    face_ids: np.ndarray
    width: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        """(N,) bool mask of poses with two valid contacts."""
        return self.status == ContactStatus.OK

    def reason(self, index: int) -> str:
        """Human-readable outcome of pose ``index``."""
        return _REASONS[ContactStatus(int(self.status[index]))]


def contacts_from_pose(
    obj: GraspObject | trimesh.Trimesh,
    T: np.ndarray,
    *,
    gripper: str | GripperModel = "panda",
    opening: float | None = None,
    rays_per_finger: tuple[int, int] = (7, 5),
    check_collision: bool = True,
) -> JawContacts:
    """Close the jaws of ``gripper`` at pose(s) ``T`` onto the object and report the contacts.

    Each finger sweeps its inner face (from the palm face to the fingertip, the full finger
    width) along the closing axis across the whole opening; it stops at the first surface point
    it meets (a grid of ``rays_per_finger`` = (along approach, along z) rays). A floating object
    is thereby pushed to the middle, so the contacts are the object's extreme points along the
    closing axis inside the jaws. Where several rays tie (a face parallel to the pad), the contact
    is the centre of the touching patch.

    Args:
        obj: the object (object frame) or a mesh.
        T: (4, 4) or (N, 4, 4) grasp poses in the object frame (dg16m grasp frame convention).
        gripper: a name from :data:`GRIPPERS` or a :class:`GripperModel`.
        opening: finger opening before closing (m); default fully open.
        rays_per_finger: ray grid size on each finger face.
        check_collision: reject poses whose open gripper intersects the object.

    Returns:
        :class:`JawContacts` with N rows (N = 1 for a single (4, 4) pose).

    Raises:
        GripperError: ``T`` does not have shape (4, 4) or (N, 4, 4), or bad gripper arguments.
    """
    model = get_gripper(gripper)
    w = model._opening(opening)
    mesh = obj.mesh if isinstance(obj, GraspObject) else obj
    poses = _check_poses(T, rays_per_finger)
    n = len(poses)
    status = _pose_status(mesh, model, w, poses, check_collision)
    points = np.full((n, 2, 3), np.nan)
    normals = np.full((n, 2, 3), np.nan)
    face_ids = np.full((n, 2), -1, dtype=np.int64)
    width = np.full(n, np.nan)
    todo = np.flatnonzero(status == ContactStatus.OK)
    if len(todo) == 0:
        return JawContacts(status, points, normals, face_ids, width)

    origins, dirs = _finger_rays(model, w, poses[todo], rays_per_finger)
    k = origins.shape[2]
    hits = _first_hits(mesh, origins.reshape(-1, 3), dirs.reshape(-1, 3), max_distance=w)
    distance, location, hit_face = (a.reshape(len(todo), 2, k, *a.shape[1:]) for a in hits)

    # Both fingers sweep the same lines in opposite directions, so a closed surface between the
    # jaws is met by both; a single touching finger only happens when grazing an edge: a miss.
    both = np.isfinite(distance).any(axis=2).all(axis=1)  # (m,)
    status[todo[~both]] = ContactStatus.MISS

    face_normals = np.asarray(mesh.face_normals, dtype=np.float64)
    for row in np.flatnonzero(both):
        i = todo[row]
        for finger in range(2):
            points[i, finger], normals[i, finger], face_ids[i, finger] = _finger_patch(
                distance[row, finger],
                location[row, finger],
                hit_face[row, finger],
                dirs[row, finger, 0],
                face_normals,
            )
        width[i] = w - float(np.nanmin(distance[row, 0]) + np.nanmin(distance[row, 1]))
    return JawContacts(status, points, normals, face_ids, width)


def _check_poses(T: np.ndarray, rays_per_finger: tuple[int, int]) -> np.ndarray:
    """(N, 4, 4) float poses from ``T`` ((4, 4) or (N, 4, 4)); checks the ray grid size."""
    poses = np.asarray(T, dtype=np.float64)
    if poses.shape == (4, 4):
        poses = poses[None]
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise GripperError(f"T: expected shape (4, 4) or (N, 4, 4), found {np.shape(T)}")
    n_rows, n_cols = rays_per_finger
    if n_rows < 1 or n_cols < 1:
        raise GripperError(f"rays_per_finger: expected positive counts, found {rays_per_finger}")
    return poses


def _pose_status(
    mesh: trimesh.Trimesh,
    model: GripperModel,
    w: float,
    poses: np.ndarray,
    check_collision: bool,
) -> np.ndarray:
    """(N,) int8 :class:`ContactStatus` before closing: invalid (non-rigid) poses and, with
    ``check_collision``, open grippers (opening ``w``) that intersect the object."""
    n = len(poses)
    status = np.full(n, ContactStatus.OK, dtype=np.int8)
    valid = np.asarray(is_rigid(poses, atol=1e-5)).reshape(n)
    status[~valid] = ContactStatus.INVALID_POSE
    if check_collision and valid.any():
        rows = np.flatnonzero(valid)
        status[rows] = _collision_checker(mesh, model, w).classify_many(poses[rows])
    return status


def _finger_rays(
    model: GripperModel, w: float, poses: np.ndarray, rays_per_finger: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """Ray origins and directions (M, 2, K, 3) of a grid on each finger's inner face at opening
    ``w``, swept towards the other finger, for (M, 4, 4) ``poses`` (object frame)."""
    n_rows, n_cols = rays_per_finger
    inset = 1e-4
    ys = np.linspace(model.palm_depth + inset, model.finger_tip - inset, n_rows)
    zs = np.linspace(-model.finger_width / 2 + inset, model.finger_width / 2 - inset, n_cols)
    grid = np.stack(np.meshgrid(ys, zs, indexing="ij"), axis=-1).reshape(-1, 2)
    k = len(grid)
    local_origins = np.zeros((2, k, 3))
    local_origins[0, :, 0], local_origins[1, :, 0] = w / 2.0, -w / 2.0
    local_origins[:, :, 1:] = grid
    local_dirs = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    R = poses[:, :3, :3]
    t = poses[:, :3, 3]
    origins = np.einsum("nij,fkj->nfki", R, local_origins) + t[:, None, None, :]
    dirs = np.broadcast_to(np.einsum("nij,fj->nfi", R, local_dirs)[:, :, None, :], origins.shape)
    return origins, dirs


def _finger_patch(
    distance: np.ndarray,
    location: np.ndarray,
    hit_face: np.ndarray,
    ray_dir: np.ndarray,
    face_normals: np.ndarray,
    tie: float = 1e-6,
) -> tuple[np.ndarray, np.ndarray, int]:
    """One finger's contact from its K rays: the centre of the rays that tie for the nearest hit
    (within ``tie`` m), their mean face normal turned to face the finger, and the hit face
    nearest that centre."""
    near = np.flatnonzero(distance <= np.nanmin(distance) + tie)
    patch = location[near]
    centre = patch.mean(axis=0)
    faces = hit_face[near]
    normal = face_normals[faces].mean(axis=0)
    if normal @ ray_dir > 0:  # open or inconsistently wound meshes: face the finger
        normal = -normal
    norm = np.linalg.norm(normal)
    normal = -ray_dir if norm <= 1e-12 else normal / norm
    face = int(faces[np.argmin(np.linalg.norm(patch - centre, axis=1))])
    return centre, normal, face


def _first_hits(
    mesh: trimesh.Trimesh, origins: np.ndarray, directions: np.ndarray, max_distance: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First hit of each ray within ``max_distance`` (exact float64 triangle intersection,
    :func:`dataset_gen.objects.ray_hits.segment_hits`): the nearest hit, ties broken by face index.

    Returns distance (R,) (inf where none), location (R, 3) (NaN where none), face (R,) (-1).
    """
    hits = segment_hits(mesh, origins, directions, max_distance)
    return nearest_hits(origins, directions, max_distance, *hits)


def nearest_hits(
    origins: np.ndarray,
    directions: np.ndarray,
    max_distance: float,
    tri: np.ndarray,
    ray: np.ndarray,
    loc: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first hit of each of the R rays among hits (H,) ``tri``, ``ray``, (H, 3) ``loc``: the
    nearest with ``0 <= dot(loc - origin, direction) <= max_distance``, ties broken by face
    index. Returns distance (R,) (inf where none), location (R, 3) (NaN where none), face (R,)
    (-1)."""
    count = len(origins)
    distance = np.full(count, np.inf)
    location = np.full((count, 3), np.nan)
    face = np.full(count, -1, dtype=np.int64)
    if len(ray) == 0:
        return distance, location, face
    along = np.einsum("ij,ij->i", loc - origins[ray], directions[ray])
    keep = (along >= 0.0) & (along <= max_distance)
    tri, ray, loc, along = tri[keep], ray[keep], loc[keep], along[keep]
    order = np.lexsort((tri, along, ray))  # nearest first per ray; ties broken by face id
    tri, ray, loc, along = tri[order], ray[order], loc[order], along[order]
    first = np.ones(len(ray), dtype=bool)
    first[1:] = ray[1:] != ray[:-1]
    distance[ray[first]] = along[first]
    location[ray[first]] = loc[first]
    face[ray[first]] = tri[first]
    return distance, location, face


def _collision_checker(
    mesh: trimesh.Trimesh, model: GripperModel, opening: float
) -> _CollisionChecker:
    """The checker of ``mesh`` for this gripper and opening, built once and kept in the mesh's
    own cache (trimesh drops it when the mesh's data change), so calling
    :func:`contacts_from_pose` pose by pose does not rebuild the collision manager each time."""
    key = f"dg16m_collision_checker:{model.name}:{opening!r}"
    if key not in mesh._cache:
        mesh._cache[key] = _CollisionChecker(mesh, model, opening)
    return mesh._cache[key]


def _fcl_geometry(mesh: trimesh.Trimesh) -> Any:
    """The python-fcl geometry of ``mesh``: convex or a BVH, as trimesh's collision manager
    makes it."""
    if mesh.is_convex:
        return trimesh.collision.mesh_to_convex(mesh)
    return trimesh.collision.mesh_to_BVH(mesh)


class _CollisionChecker:
    """Open-gripper collision tests against one object (python-fcl)."""

    def __init__(self, mesh: trimesh.Trimesh, model: GripperModel, opening: float) -> None:
        self.mesh = mesh
        self.model = model
        self.opening = opening
        self.palm = model.palm_box()
        self.fingers = model.finger_boxes(opening)
        self.palm_mesh = self.palm.to_mesh()
        self.finger_mesh = trimesh.util.concatenate([b.to_mesh() for b in self.fingers])
        self.solid = bool(mesh.is_watertight and mesh.is_winding_consistent)
        # python-fcl geometry built once (trimesh's in_collision_single rebuilds the query
        # mesh's BVH on every call), chosen as trimesh's collision manager does
        self._object = fcl.CollisionObject(_fcl_geometry(mesh), fcl.Transform())
        self._palm_geometry = _fcl_geometry(self.palm_mesh)
        self._finger_geometry = _fcl_geometry(self.finger_mesh)

    def _surface_hit(self, geometry: Any, T: np.ndarray) -> bool:
        """Whether the surfaces of ``geometry`` at pose ``T`` and of the object intersect."""
        query = fcl.CollisionObject(geometry, fcl.Transform(T[:3, :3], T[:3, 3]))
        result = fcl.CollisionResult()
        fcl.collide(self._object, query, fcl.CollisionRequest(), result)
        return bool(result.is_collision)

    @cached_property
    def _box_centres(self) -> np.ndarray:
        return np.array([b.center for b in (self.palm, *self.fingers)])

    def classify(self, T: np.ndarray) -> ContactStatus:
        """OK, TOO_WIDE or COLLISION for one rigid pose."""
        return ContactStatus(int(self.classify_many(np.asarray(T)[None])[0]))

    def classify_many(self, poses: np.ndarray) -> np.ndarray:
        """(M,) int8 OK, TOO_WIDE or COLLISION for (M, 4, 4) rigid poses.

        The surface tests run pose by pose (python-fcl, on geometry built once); the test for boxes buried inside a
        solid object runs once for every pose the surface tests cleared (one
        ``mesh.contains`` call: its answer for a point does not depend on the other points)."""
        palm_hit = np.array([self._surface_hit(self._palm_geometry, T) for T in poses], bool)
        finger_hit = np.array([self._surface_hit(self._finger_geometry, T) for T in poses], bool)
        clear = np.flatnonzero(~(palm_hit | finger_hit))
        if self.solid and len(clear):
            # Surface tests miss a box buried entirely inside a solid object.
            rotations, translations = poses[clear, :3, :3], poses[clear, :3, 3]
            centres = np.einsum("bj,mij->mbi", self._box_centres, rotations)
            centres += translations[:, None, :]
            inside = np.asarray(self.mesh.contains(centres.reshape(-1, 3)), bool)
            inside = inside.reshape(len(clear), -1)
            palm_hit[clear] = inside[:, 0]
            finger_hit[clear] = inside[:, 1:].any(axis=1)
        status = np.full(len(poses), ContactStatus.OK, dtype=np.int8)
        status[palm_hit | finger_hit] = ContactStatus.COLLISION
        for i in np.flatnonzero(finger_hit):
            if self._crosses_both_fingers(poses[i]):
                status[i] = ContactStatus.TOO_WIDE
        return status

    def _crosses_both_fingers(self, T: np.ndarray) -> bool:
        """Whether the surface cuts both inner finger faces' rectangles."""
        R, t = T[:3, :3], T[:3, 3]
        m = self.model
        for sign in (1.0, -1.0):
            origin = R @ np.array([sign * self.opening / 2.0, 0.0, 0.0]) + t
            segments = trimesh.intersections.mesh_plane(self.mesh, R[:, 0], origin)
            if len(segments) == 0:
                return False
            local = (segments - t) @ R  # (S, 2, 3) in the gripper frame
            yz = local[:, :, 1:]
            lo = np.array([m.palm_depth, -m.finger_width / 2.0])
            hi = np.array([m.finger_tip, m.finger_width / 2.0])
            if not _segments_hit_rectangle(yz, lo, hi).any():
                return False
        return True


def _segments_hit_rectangle(segments: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(S,) whether 2D segments (S, 2, 2) intersect the axis-aligned rectangle [lo, hi]
    (Liang-Barsky clipping, vectorised)."""
    p0 = segments[:, 0]
    d = segments[:, 1] - p0
    t0 = np.zeros(len(segments))
    t1 = np.ones(len(segments))
    inside = np.ones(len(segments), dtype=bool)
    for axis in range(2):
        for bound, sign in ((lo[axis], -1.0), (hi[axis], 1.0)):
            p = sign * d[:, axis]
            q = sign * (bound - p0[:, axis])
            parallel = np.abs(p) < 1e-15
            inside &= ~(parallel & (q < 0))
            with np.errstate(divide="ignore", invalid="ignore"):
                r = np.where(parallel, 0.0, q / np.where(parallel, 1.0, p))
            t0 = np.where(~parallel & (p < 0), np.maximum(t0, r), t0)
            t1 = np.where(~parallel & (p > 0), np.minimum(t1, r), t1)
    return inside & (t0 <= t1)


def transform_points(T: np.ndarray, points: Sequence[Sequence[float]] | np.ndarray) -> np.ndarray:
    """Apply (..., 4, 4) transforms to (P, 3) points: returns (..., P, 3)."""
    T = np.asarray(T, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64)
    return np.einsum("...ij,pj->...pi", T[..., :3, :3], pts) + T[..., None, :3, 3]


__all__ = [
    "GRIPPERS",
    "PANDA",
    "ROBOTIQ_2F85",
    "Box",
    "ContactStatus",
    "GripperModel",
    "JawContacts",
    "contacts_from_pose",
    "get_gripper",
    "transform_points",
]
