"""Robust pair selection: the paper's force-closure problem posed for every load of the protocol.

The paper keeps a dual grasp when its four point contacts can cancel gravity at the centroid
(:func:`dataset_gen.force_closure.evaluate`). The simulation protocol (``DESIGN.md``,
:data:`dg16m_core.parameters.PROTOCOL`) then pushes the object sideways and twists it; two
parallel-jaw grasps are weak against turning about the line joining the hands, which a
gravity-only check does not see (procedural objects: success 0.99 when that line passes within
50 mm of the centre of mass, 0.24 beyond 300 mm). Point contacts cannot cancel most of the
protocol's loads exactly: a strict certificate against all 13 passes almost nothing (1 of 1,261
procedural passing pairs), yet most such grasps hold, because a load the contacts cannot quite
cancel moves the object only a little within the 0.2 s it lasts.

The criterion (the **disturbance motion ratio**) asks how far each load's unresisted part would
carry the object:

1. the 13 loads: the weight ``m g`` (acting for the whole held time, 2.8 s) and the weight plus
   each of the 12 disturbances (a force of ``disturbance_force_fraction * m g`` along +-x, +-y,
   +-z, then a torque of that force times ``disturbance_torque_arm`` about the same axes; each
   acting for ``disturbance_time``, 0.2 s), all at the centre of mass;
2. for each load, the paper's optimisation (same contacts, cones, force bound ``f_high`` and
   norm): the contact forces that come closest to cancelling it, and their residual wrench
   ``r = (r_f, r_tau)`` about the centre of mass;
3. the residual as a constant load on the free object for the load's duration ``t``: linear
   acceleration ``a = r_f / m``, angular ``alpha = I^-1 r_tau``; the slip at each hand's grasp
   centre (the midpoint of its two contacts, at ``h`` from the centre of mass) is
   ``|a + alpha x h| t^2 / 2`` and the rotation ``|alpha| t^2 / 2``;
4. the ratio: the largest slip over ``max_displacement`` (2 cm) or rotation over
   ``max_rotation_deg`` (10 degrees), over both hands and all 13 loads. A pair is **robust** when
   it passes the paper's check and its ratio is at most 1: no protocol load, unresisted for its
   duration, would move the object past the protocol's bounds.

The model is deliberately simple (rigid object, constant residual, no contact patches or
torsion, which real pads add): it contains no fitted constant, only the protocol's own loads,
durations and bounds. Measured on the shipped procedural benchmark (300 objects, success
probabilities from 9 trials per pair): passing pairs with ratio <= 1 (23% of them) have mean
success 0.983 against 0.691 for all passing pairs; the ratio ranks passing pairs with AUC 0.84
(``bench/robust_selection.py``, BENCHMARKS.md).

Frames and units: contacts in the object frame (m), outward normals; the centre of mass and the
inertia (kg m^2, about the centre of mass, object-frame axes) from
:attr:`dataset_gen.objects.grasp_object.GraspObject.mass_properties` scaled to ``mass``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from dataset_gen.force_closure import evaluate
from dataset_gen.objects.grasp_object import MassProperties
from dg16m_core.errors import Dg16mError
from dg16m_core.parameters import PAPER, PROTOCOL, DisturbanceProtocol
from dg16m_core.parameters import SELECTIONS as SELECTIONS  # its home before 0.2.0

N_LOADS = 13
"""Gravity alone, then gravity plus each of the 12 disturbances (the protocol's order)."""

LOAD_NAMES = (
    "gravity",
    *(f"{kind}{sign}{axis}" for kind in ("force", "torque") for axis in "xyz" for sign in "+-"),
)
"""Names of the 13 loads, in the order of :func:`protocol_loads` (the trial's phase names)."""


class RobustError(Dg16mError, ValueError):
    """Bad inputs to the robust criterion (shapes, mass properties)."""


def protocol_loads(
    mass: float = PAPER.mass,
    gravity: float = PAPER.gravity,
    protocol: DisturbanceProtocol = PROTOCOL,
) -> tuple[np.ndarray, np.ndarray]:
    """The protocol's 13 loads on the object, about its centre of mass.

    Returns:
        wrenches: (13, 6) force (N) and torque (N m), in :data:`LOAD_NAMES` order.
        durations: (13,) how long each acts on a held object (s).
    """
    weight = mass * gravity
    force = protocol.disturbance_force_fraction * weight
    torque = force * protocol.disturbance_torque_arm
    wrenches = np.zeros((N_LOADS, 6))
    wrenches[:, 2] = -weight
    for k, name in enumerate(LOAD_NAMES[1:], start=1):
        axis = "xyz".index(name[-1])
        sign = 1.0 if name[-2] == "+" else -1.0
        if name.startswith("force"):
            wrenches[k, axis] += sign * force
        else:
            wrenches[k, 3 + axis] += sign * torque
    durations = np.full(N_LOADS, protocol.disturbance_time)
    durations[0] = protocol.held_time
    return wrenches, durations


@dataclass(frozen=True)
class DisturbanceMotion:
    """The criterion's numbers for N dual grasps (see the module docstring).

    Attributes:
        ratio: (N,) the disturbance motion ratio; ``inf`` for rank-deficient contacts.
        displacement: (N, 13) largest slip of the two grasp centres per load (m).
        rotation_deg: (N, 13) rotation per load (degrees).
        losses: (N, 13) residual-wrench norm per load (N, the paper's ``L``).
    """

    ratio: np.ndarray
    displacement: np.ndarray
    rotation_deg: np.ndarray
    losses: np.ndarray

    def robust(self) -> np.ndarray:
        """(N,) the ratio is at most 1 (combine with the paper's verdict to select pairs)."""
        return self.ratio <= 1.0


def disturbance_motion(
    contact_points: np.ndarray,
    contact_normals: np.ndarray,
    *,
    center_of_mass: np.ndarray,
    inertia: np.ndarray,
    mass: float = PAPER.mass,
    gravity: float = PAPER.gravity,
    mu: float = PAPER.mu,
    f_high: float = PAPER.f_high,
    threshold: float = PAPER.threshold,
    protocol: DisturbanceProtocol = PROTOCOL,
    loss_rtol: float = 1e-2,
) -> DisturbanceMotion:
    """The disturbance motion ratio of N dual grasps (physical convention: contacts push).

    Args:
        contact_points: (N, 4, 3) contacts, hand 0's two then hand 1's (object frame, m).
        contact_normals: (N, 4, 3) outward unit normals at the contacts.
        center_of_mass: (3,) m, object frame.
        inertia: (3, 3) kg m^2 about the centre of mass, for ``mass``.
        mass, gravity, mu, f_high, threshold: the force-closure problem (the paper's defaults).
        protocol: the loads, their durations and the bounds.
        loss_rtol: accuracy of the residuals (relative; 1% moves the ratio by about 1%).

    Raises:
        RobustError: shapes other than documented, non-finite values, a singular inertia.
    """
    points = np.asarray(contact_points, dtype=np.float64)
    normals = np.asarray(contact_normals, dtype=np.float64)
    if points.ndim != 3 or points.shape[1:] != (4, 3) or normals.shape != points.shape:
        raise RobustError(
            "contacts: expected points and normals of shape (N, 4, 3), found "
            f"{points.shape} and {normals.shape}"
        )
    com = np.asarray(center_of_mass, dtype=np.float64)
    inertia = np.asarray(inertia, dtype=np.float64)
    if com.shape != (3,) or inertia.shape != (3, 3):
        raise RobustError(
            "mass properties: expected a (3,) centre of mass and a (3, 3) inertia, found "
            f"{com.shape} and {inertia.shape}"
        )
    if not (np.all(np.isfinite(com)) and np.all(np.isfinite(inertia))):
        raise RobustError("mass properties: expected finite values, found NaN or inf")
    eigen = np.linalg.eigvalsh(0.5 * (inertia + inertia.T))
    if eigen.min() <= 0:
        raise RobustError(
            f"inertia: expected a positive definite matrix, found eigenvalues {eigen.tolist()}"
        )
    n = len(points)
    wrenches, durations = protocol_loads(mass, gravity, protocol)
    if n == 0:
        empty = np.zeros((0, N_LOADS))
        return DisturbanceMotion(np.zeros(0), empty, empty.copy(), empty.copy())
    relative = points - com
    result = evaluate(
        relative,
        normals,
        mass=mass,
        gravity=gravity,
        mu=mu,
        f_high=f_high,
        threshold=threshold,
        wrenches=wrenches,
        loss_rtol=loss_rtol,
    )
    forces = np.nan_to_num(result.contact_forces)  # (N, 13, 4, 3); NaN where rank-deficient
    residual_force = forces.sum(axis=2) + wrenches[None, :, :3]
    residual_torque = np.cross(relative[:, None], forces).sum(axis=2) + wrenches[None, :, 3:]
    linear = residual_force / mass
    angular = residual_torque @ np.linalg.inv(inertia).T
    half_t2 = 0.5 * durations**2
    # Each hand's grasp centre: the midpoint of its two contacts (hand 0: contacts 0 and 1).
    centres = np.stack([relative[:, 0:2].mean(axis=1), relative[:, 2:4].mean(axis=1)], axis=1)
    slip = np.stack(
        [
            np.linalg.norm(linear + np.cross(angular, centres[:, None, h]), axis=-1)
            for h in range(2)
        ],
        axis=-1,
    ).max(axis=-1)
    displacement = slip * half_t2
    rotation_deg = np.degrees(np.linalg.norm(angular, axis=-1) * half_t2)
    ratio = np.maximum(
        displacement / protocol.max_displacement, rotation_deg / protocol.max_rotation_deg
    ).max(axis=1)
    ratio = np.where(result.rank_ok, ratio, np.inf)
    return DisturbanceMotion(
        ratio=ratio,
        displacement=displacement,
        rotation_deg=rotation_deg,
        losses=np.where(result.rank_ok[:, None], result.losses, np.nan),
    )


@dataclass(frozen=True)
class RobustSelection:
    """Which of N scored pairs are robust (see :func:`robust_pairs`).

    Attributes:
        robust: (N,) bool: passed the paper's check and has a motion ratio <= 1.
        ratio: (N,) the motion ratio where it was computed, NaN elsewhere.
        counts: ``evaluated`` (pairs whose ratio was computed), ``robust``.
    """

    robust: np.ndarray
    ratio: np.ndarray
    counts: dict[str, int]


def robust_pairs(
    contact_points: np.ndarray,
    contact_normals: np.ndarray,
    passed: np.ndarray,
    *,
    rng: np.random.Generator,
    wanted: int | None,
    mass_properties: MassProperties,
    chunk_size: int = 1024,
    **kwargs: Any,
) -> RobustSelection:
    """The robust pairs among N scored ones, looked for in a random order until ``wanted`` are
    found (the ratio costs 13 force-closure solves per pair; the paper's check already ran).

    Args:
        contact_points, contact_normals: (N, 4, 3) the scored pairs' contacts.
        passed: (N,) the paper's verdicts; only passing pairs are candidates.
        rng: draws the order (one permutation of the passing rows).
        wanted: stop once this many robust pairs are found (``None``: evaluate every passing
            pair). The robust ones found are a uniform sample of all robust pairs.
        mass_properties: the object's (:attr:`dataset_gen.objects.grasp_object.GraspObject.mass_properties`);
            its inertia is scaled to ``mass``.
        chunk_size: pairs per batched call.
        kwargs: further arguments of :func:`disturbance_motion` (mass, gravity, mu, f_high,
            threshold, protocol).
    """
    mass = float(kwargs.get("mass", PAPER.mass))
    center_of_mass = mass_properties.center_of_mass
    inertia = np.asarray(mass_properties.inertia) * (mass / mass_properties.mass)
    passed = np.asarray(passed, dtype=bool)
    n = passed.shape[0]
    order = rng.permutation(np.flatnonzero(passed))
    robust = np.zeros(n, dtype=bool)
    ratio = np.full(n, np.nan)
    found = evaluated = 0
    for start in range(0, order.size, chunk_size):
        if wanted is not None and found >= wanted:
            break
        rows = order[start : start + chunk_size]
        motion = disturbance_motion(
            contact_points[rows],
            contact_normals[rows],
            center_of_mass=center_of_mass,
            inertia=inertia,
            **kwargs,
        )
        ratio[rows] = motion.ratio
        robust[rows] = motion.robust()
        evaluated += rows.size
        found = int(robust.sum())
    return RobustSelection(robust, ratio, {"evaluated": evaluated, "robust": found})
