"""Antipodal single-arm grasp sampling (DG16M paper, Section III-A).

The output of this stage is a :class:`SingleArmGrasps`: gripper poses in the object frame with
the two jaw contacts each, which :mod:`dataset_gen.grasps.pairing` combines into dual-arm grasps.

Algorithm (:func:`sample_antipodal_grasps`)
-------------------------------------------
Batches of ``batch_size`` surface points are processed until ``n_grasps`` grasps are kept or
``max_candidates`` surface points have been drawn. Per batch, every random number is drawn up
front from the caller's generator, so the result depends only on the generator's state and the
arguments (never on timing or chunking); with the same ``max_candidates`` and ``batch_size``, a
smaller ``n_grasps`` returns a prefix of a larger one.

1. **Surface points** ``p1``: area-weighted (face drawn with probability proportional to its
   area, uniform barycentric point on it), with the face's outward normal ``n1``.
2. **Ray in the friction cone.** With ``alpha = atan(mu)`` and ``gamma = tan(alpha / 2)`` (the
   paper's notation), the ray direction is ``v = normalize(-n1 + gamma * r * u)``, ``u`` a unit
   tangent at angle ``phi ~ U[0, 2 pi)`` and ``r = sqrt(U[0, 1])``: uniform over the cone's
   circular cross-section, so ``v`` lies within ``alpha / 2`` of ``-n1``. The ray starts 1e-6 m
   (times the object size past 1 m) inside the surface; its first hit is ``p2`` on face ``f2``
   with outward normal ``n2``.
3. **Antipodal test**, with the full friction cone (half-angle ``atan(mu)``) at both contacts:
   the angle between ``p2 - p1`` and ``-n1`` and between ``p1 - p2`` and ``-n2`` are at most
   ``atan(mu)``; then the **opening test** ``min_width < |p2 - p1| <= max_opening -
   opening_margin``.
4. **Grasp axis and approach angles.** The closing axis is ``x = normalize(n1 - n2)``, the
   mean of the two outward normals (finger 0 on the ``p1`` side, at ``+x``), and the centre
   ``(p1 + p2) / 2``. The paper's axis is the contact line ``p1 - p2`` (``axis="contacts"``),
   but the jaws are flat pads: closed along a line tilted by up to ``alpha / 2`` against two
   parallel faces they touch with opposite pad corners, and those contacts are far from
   antipodal (measured on the airplane: 258 grasps from 50,000 surface points with the contact
   line, 500 from 4,096 with the normals). Each pair gets ``n_approach`` approach directions
   about ``x``, evenly spaced with a random offset; the pose puts the centre at
   ``(0, contact_depth, 0)`` in the grasp frame (as
   :meth:`~dataset_gen.grasps.gripper.GripperModel.pose_from_contacts`). Approaches are tried in
   rounds over the batch's pairs (round ``k`` tries approach ``k`` of every pair still without
   a grasp), and a pair keeps its first approach that passes step 5: **one grasp per contact
   pair**, as in the DG16M release (each of its single-arm poses has its own contact pair),
   which also spreads the grasps over the object.
5. **Gripper check and jaw contacts** with :func:`dataset_gen.grasps.gripper.contacts_from_pose`
   (``check_collision=True``): poses whose open gripper penetrates the object (``COLLISION``,
   ``TOO_WIDE``) or whose jaws close on nothing are dropped. A cheap ray-cast prefilter first
   drops poses whose gripper boxes are certainly crossed by the surface (most of them; the
   result is unchanged). The jaws' actual contacts replace the sampled ones: each is snapped
   onto the nearest mesh face (a contact patch's centre can sit up to ~1e-6 m off a curved
   surface; farther than :data:`SNAP_TOLERANCE_M`, e.g. a patch split over two separate
   features, the grasp is dropped), its normal is that face's normal, and the antipodal and
   minimum-width tests are repeated on these contacts.

Meshes that are not closed volumes (open, or inconsistently wound, like many ShapeNet meshes)
have no reliable outward side. There, each surface point casts a second ray about ``+n1`` (the
first one that passes steps 2-3 is used), a normal at ``p2`` is taken facing away from ``p1``,
and every returned contact normal is oriented towards the finger touching it (``+x`` side for
finger 0), which can negate the face's stored normal (counted in ``counts["normals_flipped"]``).
On closed volumes normals are always the faces' own outward normals.

Cost: the jaw closing in ``contacts_from_pose`` (70 exact ray casts per pose) dominates, a few
ms per grasp found; surface rays and the prefilter use Embree when trimesh has it.

Counts
------
:data:`STAGES` are contact-pair counts, non-increasing along the list: a pair counts at a stage
when at least one of its tried poses got that far. ``kept`` is the number of grasps returned.
Extra pose-level counts: ``poses_tried``, ``poses_prefiltered`` (sure collisions),
``poses_collision_free``, ``poses_closed``, ``poses_blocked_by_parts`` (closed with good
contacts but an open hand deeper than the simulator allows in ``collision_parts``); and
``batches``, ``normals_flipped``.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import trimesh

from dataset_gen.grasps.clearance import OpenHandClearance
from dataset_gen.grasps.gripper import ContactStatus, GripperModel, contacts_from_pose, get_gripper
from dataset_gen.objects.grasp_object import ConvexPart, GraspObject
from dg16m_core.checks import check_integer
from dg16m_core.errors import Dg16mError
from dg16m_core.parameters import PAPER

AxisChoice = Literal["normals", "contacts"]

STAGES: tuple[str, ...] = (
    "surface_points",
    "ray_hits",
    "antipodal",
    "within_opening",
    "poses",
    "collision_free",
    "closed",
    "contacts_antipodal",
    "kept",
)
"""Per-stage counts of :func:`sample_antipodal_grasps`, in order (non-increasing).

``surface_points`` drawn; ``ray_hits``: the cone ray hit the mesh; ``antipodal``: both contacts
within the friction cone; ``within_opening``: the gripper can span them; ``poses``: pairs with
at least one approach tried (the rest were not needed); ``collision_free``: an approach whose
open gripper does not penetrate the object; ``closed``: the jaws close on two contacts;
``contacts_antipodal``: those contacts pass the antipodal and width tests; ``kept``: returned
(after truncation to ``n_grasps``)."""

RAY_OFFSET_M = 1e-6
"""How far inside the surface the cone ray starts (m, for objects up to 1 m; scaled beyond)."""

SNAP_TOLERANCE_M = 1e-4
"""Largest distance a jaw contact may be moved onto the mesh surface (m)."""

_ANGLE_EPS = 1e-12


class SamplingError(Dg16mError, ValueError):
    """Invalid arguments to the grasp sampler."""


@dataclass(frozen=True)
class SingleArmGrasps:
    """M single-arm grasps on one object (object frame, metres).

    Attributes:
        poses: ``(M, 4, 4)`` gripper poses in the dg16m grasp frame (``+x`` closing axis with
            finger 0 at ``+x``, ``+y`` approach); see :mod:`dataset_gen.grasps.gripper`.
        contact_points: ``(M, 2, 3)`` contacts of finger 0 and finger 1.
        contact_normals: ``(M, 2, 3)`` unit OUTWARD normals of the faces hit at the contacts.
        face_ids: ``(M, 2)`` indices of those faces in the object's mesh.
        widths: ``(M,)`` jaw separation at the contacts (m).
        gripper: the gripper model's name (``dataset_gen.grasps.gripper.GRIPPERS``).
        counts: per-stage counts of the sampler (e.g. ``surface_points``, ``ray_hits``,
            ``antipodal``, ``within_opening``, ``poses``, ``collision_free``, ``kept``).
    """

    poses: np.ndarray
    contact_points: np.ndarray
    contact_normals: np.ndarray
    face_ids: np.ndarray
    widths: np.ndarray
    gripper: str
    counts: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        m = int(np.asarray(self.poses).shape[0]) if np.asarray(self.poses).ndim == 3 else -1
        expected = {
            "poses": (m, 4, 4),
            "contact_points": (m, 2, 3),
            "contact_normals": (m, 2, 3),
            "face_ids": (m, 2),
            "widths": (m,),
        }
        for name, shape in expected.items():
            value = np.asarray(getattr(self, name))
            if value.shape != shape or m < 0:
                raise ValueError(
                    f"SingleArmGrasps.{name}: expected shape {shape}, found {value.shape}"
                )

    @property
    def n(self) -> int:
        """Number of grasps M."""
        return int(self.poses.shape[0])

    @property
    def centers(self) -> np.ndarray:
        """``(M, 3)`` grasp centres: the midpoints of the two contacts (used for pruning)."""
        return self.contact_points.mean(axis=1)


# --------------------------------------------------------------------------------------------
# Public entry point
# --------------------------------------------------------------------------------------------


def sample_antipodal_grasps(
    obj: GraspObject | trimesh.Trimesh,
    *,
    gripper: str | GripperModel = "panda",
    n_grasps: int = PAPER.n_grasps,
    mu: float = PAPER.mu,
    n_approach: int = 8,
    rng: np.random.Generator,
    max_candidates: int | None = None,
    batch_size: int = 2048,
    min_width: float = 1e-3,
    opening_margin: float = 1e-3,
    rays_per_finger: tuple[int, int] = (7, 5),
    axis: AxisChoice = "normals",
    prefilter: bool | None = None,
    collision_parts: Sequence[ConvexPart] | None = None,
    progress: bool = False,
) -> SingleArmGrasps:
    """Sample up to ``n_grasps`` collision-free antipodal grasps on ``obj`` (see the module doc).

    Args:
        obj: the object (its centred object frame) or a mesh in any frame.
        gripper: a name from :data:`dataset_gen.grasps.gripper.GRIPPERS` or a model.
        n_grasps: grasps wanted (500 in the DG16M release).
        mu: friction coefficient (dimensionless); the friction cone's half-angle is ``atan(mu)``,
            the sampling cone's ``atan(mu) / 2``.
        n_approach: approach angles tried per contact pair (rad spacing ``2 pi / n_approach``).
        rng: the only source of randomness; the same state gives identical arrays.
        max_candidates: most surface points to draw (default ``100 * n_grasps``). When they
            run out first, fewer grasps are returned; ``counts["kept"]`` says how many.
        batch_size: surface points per batch.
        min_width: smallest contact separation and jaw width accepted (m).
        opening_margin: the sampled contacts must be at least this much narrower than the
            gripper's maximum opening (m).
        rays_per_finger: ray grid per finger passed to ``contacts_from_pose``.
        axis: the closing axis of a contact pair: ``"normals"`` (default) the mean of the two
            outward face normals, ``"contacts"`` the line through the sampled contacts (the
            paper's). See the module doc.
        prefilter: before ``contacts_from_pose``, drop poses whose gripper boxes are crossed by
            the surface along a grid of line segments (ray casts; a sure collision, so the
            result is the same, only faster). Default: on when the ray engine is Embree.
        collision_parts: the convex parts the simulator collides (object frame, m). When given,
            a grasp is kept only if its open hand is also clear of them by the simulator's rule
            (:mod:`dataset_gen.grasps.clearance`: no box deeper than
            ``PROTOCOL.invalid_penetration``), so it is valid in simulation; the generator and
            the benchmark pass a mesh's CoACD parts. ``None``: the exact-mesh test only.
        progress: show a progress bar (dg16m_core.progress) of the grasps found.

    Returns:
        :class:`SingleArmGrasps` with ``min(n_grasps, found)`` grasps, in a deterministic order
        (batch, approach round, surface point), and ``counts`` (:data:`STAGES` and extras).

    Raises:
        SamplingError: bad arguments or a mesh without faces. GripperError: unknown gripper.
    """
    model = get_gripper(gripper)
    mesh = _mesh_of(obj)
    n_grasps = _positive_int("n_grasps", n_grasps)
    n_approach = _positive_int("n_approach", n_approach)
    batch_size = _positive_int("batch_size", batch_size)
    max_candidates = _positive_int(
        "max_candidates", 100 * n_grasps if max_candidates is None else max_candidates
    )
    _check_options(rays_per_finger, axis, rng, mu)
    max_width = _max_width(model, min_width, opening_margin)

    sampler = _Sampler(
        mesh=mesh,
        model=model,
        mu=float(mu),
        n_approach=n_approach,
        min_width=float(min_width),
        max_width=float(max_width),
        rays_per_finger=(int(rays_per_finger[0]), int(rays_per_finger[1])),
        axis=axis,
        prefilter=_has_fast_rays(mesh) if prefilter is None else bool(prefilter),
        clearance=OpenHandClearance(collision_parts, model) if collision_parts else None,
    )
    return sampler.run(
        n_grasps=n_grasps,
        rng=rng,
        max_candidates=max_candidates,
        batch_size=batch_size,
        progress=progress,
    )


def _mesh_of(obj: object) -> trimesh.Trimesh:
    """The mesh to sample: ``obj.mesh`` of a :class:`GraspObject`, or ``obj`` itself; it must
    have faces with a positive area."""
    mesh = obj.mesh if isinstance(obj, GraspObject) else obj
    if not isinstance(mesh, trimesh.Trimesh):
        raise SamplingError(
            f"obj: expected a GraspObject or trimesh.Trimesh, found {type(obj).__name__}"
        )
    if len(mesh.faces) == 0 or not float(mesh.area) > 0.0:
        raise SamplingError(
            f"obj: expected a mesh with surface area, found {len(mesh.faces)} faces"
        )
    return mesh


def _check_options(rays_per_finger: object, axis: object, rng: object, mu: float) -> None:
    """Check the ray grid, the axis choice, the generator and the friction coefficient."""
    if (
        not isinstance(rays_per_finger, tuple | list)
        or len(rays_per_finger) != 2
        or not all(
            isinstance(v, int | np.integer) and not isinstance(v, bool) and v >= 1
            for v in rays_per_finger
        )
    ):
        raise SamplingError(
            f"rays_per_finger: expected two integers >= 1, found {rays_per_finger!r}"
        )
    if axis not in ("normals", "contacts"):
        raise SamplingError(f"axis: expected 'normals' or 'contacts', found {axis!r}")
    if not isinstance(rng, np.random.Generator):
        raise SamplingError(f"rng: expected a numpy.random.Generator, found {type(rng).__name__}")
    if not (isinstance(mu, numbers.Real) and math.isfinite(mu) and mu >= 0.0):
        raise SamplingError(f"mu: expected a finite friction coefficient >= 0, found {mu!r}")


def _max_width(model: GripperModel, min_width: float, opening_margin: float) -> float:
    """The widest contact separation accepted, ``max_opening - opening_margin`` (m), after
    checking both lengths and that it exceeds ``min_width``."""
    for name, value in (("min_width", min_width), ("opening_margin", opening_margin)):
        if not (isinstance(value, numbers.Real) and math.isfinite(value) and value >= 0.0):
            raise SamplingError(f"{name}: expected a finite length >= 0 m, found {value!r}")
    max_width = model.max_opening - opening_margin
    if not max_width > min_width:
        raise SamplingError(
            f"opening_margin: expected max_opening - opening_margin > min_width "
            f"({model.max_opening} - {opening_margin} > {min_width} m), found "
            f"{max_width:.6g} m"
        )
    return max_width


def _positive_int(name: str, value: object) -> int:
    """An integer >= 1 (numpy integers too; not a bool)."""
    return check_integer(name, value, minimum=1, error=SamplingError)


# --------------------------------------------------------------------------------------------
# Implementation
# --------------------------------------------------------------------------------------------


@dataclass
class _Batch:
    """Contact pairs of one batch that pass the opening test (finger 0 on ``p0``)."""

    p0: np.ndarray  # (P, 3)
    p1: np.ndarray  # (P, 3)
    axis: np.ndarray  # (P, 3) unit closing axis x, from finger 1 towards finger 0
    offsets: np.ndarray  # (P,) approach angle offsets (rad)


@dataclass
class _Found:
    """Grasps accepted from one chunk of poses."""

    poses: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    widths: np.ndarray
    flipped: np.ndarray  # (m, 2) bool


class _Sampler:
    def __init__(
        self,
        *,
        mesh: trimesh.Trimesh,
        model: GripperModel,
        mu: float,
        n_approach: int,
        min_width: float,
        max_width: float,
        rays_per_finger: tuple[int, int],
        axis: AxisChoice,
        prefilter: bool,
        clearance: OpenHandClearance | None = None,
    ) -> None:
        self.mesh = mesh
        self.clearance = clearance
        self.axis = axis
        self.model = model
        self.n_approach = n_approach
        self.min_width = min_width
        self.max_width = max_width
        self.rays_per_finger = rays_per_finger
        self.gamma = math.tan(math.atan(mu) / 2.0)
        self.cos_cone = 1.0 / math.sqrt(1.0 + mu * mu)  # cos(atan(mu))
        self.closed = bool(mesh.is_volume)
        self.face_normals = np.asarray(mesh.face_normals, dtype=np.float64)
        self.triangles = np.asarray(mesh.triangles, dtype=np.float64)
        areas = np.asarray(mesh.area_faces, dtype=np.float64)
        self.area_cdf = np.cumsum(areas) / areas.sum()
        self.ray_offset = RAY_OFFSET_M * max(1.0, float(np.max(mesh.extents)))
        self.counts = dict.fromkeys(STAGES, 0)
        self.counts.update(
            poses_tried=0,
            poses_prefiltered=0,
            poses_collision_free=0,
            poses_closed=0,
            batches=0,
            normals_flipped=0,
            poses_blocked_by_parts=0,
        )
        self.prefilter = _SureCollisions(mesh, model) if prefilter else None

    # -- driver --------------------------------------------------------------------------------

    def run(
        self,
        *,
        n_grasps: int,
        rng: np.random.Generator,
        max_candidates: int,
        batch_size: int,
        progress: bool,
    ) -> SingleArmGrasps:
        from dg16m_core.progress import progress_bar

        found: list[_Found] = []
        total = 0
        drawn = 0
        with progress_bar(
            total=n_grasps, unit="grasp", desc="sampling", enabled=progress, leave=False
        ) as bar:
            while total < n_grasps and drawn < max_candidates:
                size = min(batch_size, max_candidates - drawn)
                drawn += size
                self.counts["batches"] += 1
                batch = self._contact_pairs(size, rng)
                for chunk in self._grasp_batch(batch, n_grasps - total):
                    found.append(chunk)
                    total += len(chunk.widths)
                    bar.update(min(len(chunk.widths), n_grasps - bar.n))

        def stack(name: str, shape: tuple[int, ...], dtype: type) -> np.ndarray:
            parts = [getattr(f, name) for f in found]
            if not parts:
                return np.zeros((0, *shape), dtype=dtype)
            return np.ascontiguousarray(np.concatenate(parts)[:n_grasps], dtype=dtype)

        flipped = stack("flipped", (2,), bool)
        self.counts["kept"] = len(flipped)
        self.counts["normals_flipped"] = int(flipped.sum())
        return SingleArmGrasps(
            poses=stack("poses", (4, 4), np.float64),
            contact_points=stack("points", (2, 3), np.float64),
            contact_normals=stack("normals", (2, 3), np.float64),
            face_ids=stack("faces", (2,), np.int64),
            widths=stack("widths", (), np.float64),
            gripper=self.model.name,
            counts={k: int(v) for k, v in self.counts.items()},
        )

    # -- steps 1-3: surface points, cone rays, antipodal and opening tests ------------------------

    def _contact_pairs(self, size: int, rng: np.random.Generator) -> _Batch:
        # All of the batch's random numbers, drawn in a fixed order.
        face_u = rng.random(size)
        bary_u = rng.random((size, 2))
        phi = rng.random(size) * (2.0 * np.pi)
        radius = np.sqrt(rng.random(size))
        offsets = rng.random(size) * (2.0 * np.pi / self.n_approach)

        faces = np.minimum(
            np.searchsorted(self.area_cdf, face_u, side="right"), len(self.area_cdf) - 1
        )
        s = np.sqrt(bary_u[:, 0])
        weights = np.stack([1.0 - s, s * (1.0 - bary_u[:, 1]), s * bary_u[:, 1]], axis=1)
        points = np.einsum("nk,nki->ni", weights, self.triangles[faces])
        normals = self.face_normals[faces]
        t1, t2 = _tangent_basis(normals)
        tangent = (np.cos(phi)[:, None] * t1 + np.sin(phi)[:, None] * t2) * (self.gamma * radius)[
            :, None
        ]
        self.counts["surface_points"] += size

        # Closed volumes: one ray about -n1. Otherwise also one about +n1 (sign -1).
        signs = (1.0,) if self.closed else (1.0, -1.0)
        n_rays = len(signs)
        inward = np.concatenate([-sign * normals for sign in signs])  # (S*B, 3) the -n1 axis
        directions = _unit(inward + np.tile(tangent, (n_rays, 1)))
        p1 = np.tile(points, (n_rays, 1))
        origins = p1 + self.ray_offset * inward
        hit_face = np.full(len(origins), -1, dtype=np.int64)
        p2 = np.full_like(origins, np.nan)
        tri, ray, loc = self.mesh.ray.intersects_id(
            origins, directions, multiple_hits=False, return_locations=True
        )
        hit_face[ray] = tri
        p2[ray] = loc
        hit = hit_face >= 0

        n1 = -inward
        n2 = np.where(hit[:, None], self.face_normals[np.maximum(hit_face, 0)], np.nan)
        with np.errstate(invalid="ignore"):
            if not self.closed:  # the exit face's normal points away from p1
                n2 = np.where((np.einsum("ij,ij->i", n2, directions) < 0)[:, None], -n2, n2)
            axis = p2 - p1
            width = np.linalg.norm(axis, axis=1)
            axis = axis / np.where(width > 0, width, 1.0)[:, None]
            antipodal = (
                hit
                & (width > 0)
                & (np.einsum("ij,ij->i", axis, -n1) >= self.cos_cone - _ANGLE_EPS)
                & (np.einsum("ij,ij->i", axis, n2) >= self.cos_cone - _ANGLE_EPS)
            )
            spanned = antipodal & (width > self.min_width) & (width <= self.max_width)

        # A point counts at a stage when any of its rays got there; it uses its first full pass.
        def per_point(mask: np.ndarray) -> np.ndarray:
            return mask.reshape(n_rays, size).any(axis=0)

        self.counts["ray_hits"] += int(per_point(hit).sum())
        self.counts["antipodal"] += int(per_point(antipodal).sum())
        ok = spanned.reshape(n_rays, size)
        keep = ok.any(axis=0)
        self.counts["within_opening"] += int(keep.sum())
        choice = np.argmax(ok, axis=0)[keep] * size + np.flatnonzero(keep)
        finger0, finger1 = p1[choice], p2[choice]
        # "normals": the mean of the two outward normals (n1 points to +x, n2 to -x)
        along = finger0 - finger1 if self.axis == "contacts" else n1[choice] - n2[choice]
        x = _unit(along)
        return _Batch(p0=finger0, p1=finger1, axis=x, offsets=offsets[keep])

    # -- steps 4-5: approaches, gripper check, jaw contacts ----------------------------------------

    def _grasp_batch(self, batch: _Batch, needed: int) -> Iterator[_Found]:
        """Try approach rounds over the batch's pairs until ``needed`` grasps are found."""
        n_pairs = len(batch.offsets)
        if n_pairs == 0:
            return
        x = batch.axis
        b1, b2 = _tangent_basis(x)
        centre = 0.5 * (batch.p0 + batch.p1)
        done = np.zeros(n_pairs, dtype=bool)
        reached = {name: np.zeros(n_pairs, dtype=bool) for name in STAGES[4:8]}
        found = 0
        rate = 0.25  # running estimate of grasps per tried pose, sizes the next chunk
        tried = 0
        try:
            for k in range(self.n_approach):
                todo = np.flatnonzero(~done)
                start = 0
                while start < len(todo) and found < needed:
                    want = math.ceil((needed - found) / max(rate, 0.02) * 1.05)
                    idx = todo[start : start + int(np.clip(want, 32, 1024))]
                    start += len(idx)
                    theta = batch.offsets[idx] + 2.0 * np.pi * k / self.n_approach
                    y = np.cos(theta)[:, None] * b1[idx] + np.sin(theta)[:, None] * b2[idx]
                    poses = np.zeros((len(idx), 4, 4))
                    poses[:, :3, 0] = x[idx]
                    poses[:, :3, 1] = y
                    poses[:, :3, 2] = np.cross(x[idx], y)
                    poses[:, :3, 3] = centre[idx] - self.model.contact_depth * y
                    poses[:, 3, 3] = 1.0
                    chunk, flags = self._evaluate(poses)
                    for name, flag in zip(STAGES[4:8], flags, strict=True):
                        reached[name][idx] |= flag
                    done[idx[flags[-1]]] = True
                    found += len(chunk.widths)
                    tried += len(idx)
                    rate = max(found, 1) / tried
                    if len(chunk.widths):
                        yield chunk
                if found >= needed:
                    break
        finally:
            for name, flag in reached.items():
                self.counts[name] += int(flag.sum())

    def _evaluate(self, poses: np.ndarray) -> tuple[_Found, tuple[np.ndarray, ...]]:
        """Gripper check and jaw contacts for (m, 4, 4) poses; per-pose stage flags."""
        m = len(poses)
        status = np.full(m, ContactStatus.COLLISION, dtype=np.int8)
        jaw_points = np.full((m, 2, 3), np.nan)
        jaw_faces = np.full((m, 2), -1, dtype=np.int64)
        jaw_width = np.full(m, np.nan)
        rest = np.arange(m)
        if self.prefilter is not None:
            rest = np.flatnonzero(~self.prefilter.sure_collisions(poses))
            self.counts["poses_prefiltered"] += m - len(rest)
        if len(rest):
            jaws = contacts_from_pose(
                self.mesh,
                poses[rest],
                gripper=self.model,
                rays_per_finger=self.rays_per_finger,
                check_collision=True,
            )
            status[rest] = jaws.status
            jaw_points[rest] = jaws.points
            jaw_faces[rest] = jaws.face_ids
            jaw_width[rest] = jaws.width
        collision_free = (status == ContactStatus.OK) | (status == ContactStatus.MISS)
        closed = status == ContactStatus.OK
        self.counts["poses_tried"] += len(poses)
        self.counts["poses_collision_free"] += int(collision_free.sum())
        self.counts["poses_closed"] += int(closed.sum())

        rows = np.flatnonzero(closed)
        points, faces, normals, flipped, good = self._contacts(
            poses[rows], jaw_points[rows], jaw_faces[rows], jaw_width[rows]
        )
        if self.clearance is not None and good.any():
            candidates = np.flatnonzero(good)
            clear = self.clearance.clear(poses[rows[candidates]])
            good[candidates[~clear]] = False
            self.counts["poses_blocked_by_parts"] += int((~clear).sum())
        accepted = np.zeros(len(poses), dtype=bool)
        accepted[rows[good]] = True
        chunk = _Found(
            poses=poses[rows[good]],
            points=points[good],
            normals=normals[good],
            faces=faces[good],
            widths=jaw_width[rows[good]],
            flipped=flipped[good],
        )
        return chunk, (np.ones(len(poses), dtype=bool), collision_free, closed, accepted)

    def _contacts(
        self, poses: np.ndarray, points: np.ndarray, faces: np.ndarray, jaw_width: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Snap jaw contacts onto the mesh, take face normals, re-test antipodality and width."""
        m = len(poses)
        flat_points = points.reshape(-1, 3).copy()
        flat_faces = faces.reshape(-1).copy()
        on_face = trimesh.triangles.closest_point(self.triangles[flat_faces], flat_points)
        distance = np.linalg.norm(on_face - flat_points, axis=1)
        off = np.flatnonzero(distance > 1e-9)
        if len(off):
            closest, dist, tri = trimesh.proximity.closest_point(self.mesh, flat_points[off])
            flat_points[off] = closest
            flat_faces[off] = tri
            distance[off] = dist
        snapped = (distance <= SNAP_TOLERANCE_M).reshape(m, 2).all(axis=1)
        points = flat_points.reshape(m, 2, 3)
        faces = flat_faces.reshape(m, 2)
        normals = self.face_normals[faces]
        flipped = np.zeros((m, 2), dtype=bool)
        if not self.closed:  # face the finger: finger 0 sits on the +x side, finger 1 on -x
            outward = poses[:, None, :3, 0] * np.array([1.0, -1.0])[None, :, None]
            flipped = np.einsum("mki,mki->mk", normals, outward) < 0
            normals = np.where(flipped[..., None], -normals, normals)
        axis = points[:, 1] - points[:, 0]  # from finger 0's contact to finger 1's
        separation = np.linalg.norm(axis, axis=1)
        axis = axis / np.where(separation > 0, separation, 1.0)[:, None]
        good = (
            snapped
            & (separation > self.min_width)
            & (jaw_width > self.min_width)
            & (np.einsum("ij,ij->i", axis, -normals[:, 0]) >= self.cos_cone - _ANGLE_EPS)
            & (np.einsum("ij,ij->i", axis, normals[:, 1]) >= self.cos_cone - _ANGLE_EPS)
        )
        return points, faces, normals, flipped, good


class _SureCollisions:
    """Cheap sure-collision test for open-gripper poses by ray casts along box segments.

    Each collision box of the open gripper carries a 3 x 3 grid of segments along each of its
    axes (its 12 edges, face and centre lines). A segment that meets the surface strictly
    between its ends proves that the surface enters the box, which ``contacts_from_pose`` also
    reports (COLLISION or TOO_WIDE); segments that meet nothing prove nothing, and those poses
    go to the full check. The two centre lines of the palm's face towards the fingers are cast
    first (they alone catch ~95% of the sure collisions of antipodal poses); the other segments
    only for the poses they leave.
    """

    def __init__(self, mesh: trimesh.Trimesh, model: GripperModel, grid: int = 3) -> None:
        self.mesh = mesh
        starts, directions, lengths, first = [], [], [], []
        levels = np.linspace(-1.0, 1.0, grid)
        palm = model.palm_box()
        palm_face_centre = np.asarray(palm.center) + np.array([0.0, palm.half_extents[1], 0.0])
        for box in model.collision_boxes():
            centre = np.asarray(box.center, dtype=np.float64)
            half = np.asarray(box.half_extents, dtype=np.float64)
            for axis in range(3):
                others = [a for a in range(3) if a != axis]
                for u in levels:
                    for v in levels:
                        start = centre.copy()
                        start[axis] -= half[axis]
                        start[others[0]] += u * half[others[0]]
                        start[others[1]] += v * half[others[1]]
                        direction = np.zeros(3)
                        direction[axis] = 1.0
                        middle = start + half[axis] * direction
                        starts.append(start)
                        directions.append(direction)
                        lengths.append(2.0 * half[axis])
                        first.append(box == palm and np.allclose(middle, palm_face_centre))
        order = np.argsort(~np.array(first), kind="stable")
        self.n_first = int(np.sum(first))
        self.starts = np.array(starts)[order]
        self.directions = np.array(directions)[order]
        self.lengths = np.array(lengths)[order]

    def sure_collisions(self, poses: np.ndarray) -> np.ndarray:
        """(m,) bool: poses whose open gripper certainly intersects the surface."""
        sure = self._crossed(poses, slice(0, self.n_first))
        rest = np.flatnonzero(~sure)
        if len(rest):
            sure[rest] = self._crossed(poses[rest], slice(self.n_first, None))
        return sure

    def _crossed(self, poses: np.ndarray, segments: slice) -> np.ndarray:
        starts = self.starts[segments]
        m, k = len(poses), len(starts)
        if m == 0 or k == 0:
            return np.zeros(m, dtype=bool)
        R, t = poses[:, :3, :3], poses[:, :3, 3]
        origins = (np.einsum("mij,kj->mki", R, starts) + t[:, None, :]).reshape(-1, 3)
        directions = np.einsum("mij,kj->mki", R, self.directions[segments]).reshape(-1, 3)
        _, ray, loc = self.mesh.ray.intersects_id(
            origins, directions, multiple_hits=False, return_locations=True
        )
        along = np.einsum("ij,ij->i", loc - origins[ray], directions[ray])
        limit = np.tile(self.lengths[segments], m)[ray]
        inside = (along > 1e-7) & (along < limit - 1e-7)
        crossed = np.zeros(m * k, dtype=bool)
        crossed[ray[inside]] = True
        return crossed.reshape(m, k).any(axis=1)


def _has_fast_rays(mesh: trimesh.Trimesh) -> bool:
    return type(mesh.ray).__module__.endswith("ray_pyembree")


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _tangent_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing unit vectors ``n`` (k, 3) to right-handed frames."""
    helper = np.zeros_like(n)
    helper[np.arange(len(n)), np.argmin(np.abs(n), axis=1)] = 1.0
    t1 = _unit(np.cross(n, helper))
    return t1, np.cross(n, t1)


__all__ = [
    "RAY_OFFSET_M",
    "SNAP_TOLERANCE_M",
    "STAGES",
    "SamplingError",
    "SingleArmGrasps",
    "sample_antipodal_grasps",
]
