"""The DG16M paper's parameters, defined once.

Every default that reproduces the paper or its release (the generator, the force-closure check,
the benchmark, the simulated scene and trial, the evaluators and the bench scripts) derives from
:data:`PAPER`. A second literal copy of any of these numbers is a bug waiting to happen: import
the object instead::

    from dg16m_core.parameters import PAPER

    def evaluate(points, normals, *, mu: float = PAPER.mu, ...): ...

Values were measured on the released code and a real release file (``DESIGN.md``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class PaperParameters:
    """The DG16M release's parameters (SI units).

    Attributes:
        mass: object mass for the gravity wrench (kg).
        gravity: gravitational acceleration (m/s^2); with ``mass`` a 60 N weight.
        mu: Coulomb friction coefficient at every contact (sampling, force closure, simulation).
        f_high: upper bound on each contact force's norm (N; the Franka hand's continuous force).
        threshold: force closure passes when the optimal residual norm ``L`` is at most this (N).
        n_grasps: single-arm grasps sampled per object.
        min_center_distance: dual grasps whose grasp centres are closer than this are pruned (m).
        max_passing: force-closure-passing dual grasps kept per object.
        max_failing: failing dual grasps kept per object.
        failing_min_loss: failing dual grasps are drawn among those with ``L`` above this (N).
    """

    mass: float = 6.0
    gravity: float = 10.0
    mu: float = 0.4
    f_high: float = 70.0
    threshold: float = 1e-5
    n_grasps: int = 500
    min_center_distance: float = 0.1
    max_passing: int = 2000
    max_failing: int = 2000
    failing_min_loss: float = 0.5

    @property
    def weight(self) -> float:
        """The object's weight ``mass * gravity`` (N)."""
        return self.mass * self.gravity

    def gravity_wrench(self) -> np.ndarray:
        """(6,) the external wrench of gravity at the origin: ``(0, 0, -m g, 0, 0, 0)`` (N, N m)."""
        return np.array([0.0, 0.0, -self.weight, 0.0, 0.0, 0.0])

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


PAPER = PaperParameters()
"""The parameters of the DG16M paper and release; import this, never the numbers."""


@dataclass(frozen=True)
class DisturbanceProtocol:
    """The simulation protocol's loads, bounds and open-hand tolerance (SI units), defined once.

    The simulator's trial protocol (``TrialProtocol``) takes its defaults from here, and
    so do the generator's open-hand clearance rule (:mod:`dataset_gen.grasps.clearance`) and the robust
    pair selection (:mod:`dataset_gen.grasps.robust`), which never import the simulator.

    Attributes:
        close_time: closing phase, gravity off (s).
        gravity_time: gravity phase (s).
        disturbance_time: duration of each of the 12 disturbances (s).
        ramp_time: each phase's load ramps from the previous one over this time (s).
        disturbance_force_fraction: each disturbance force is this fraction of the weight.
        disturbance_torque_arm: lever arm turning the disturbance force into a torque (m).
        max_displacement: allowed slip of the object at either hand's grasp centre (m).
        max_rotation_deg: allowed rotation of the object (degrees).
        invalid_penetration: an open hand deeper than this in the object's collision geometry
            cannot start a trial, and the generator does not keep it (m).
    """

    close_time: float = 0.5
    gravity_time: float = 0.4
    disturbance_time: float = 0.2
    ramp_time: float = 0.05
    disturbance_force_fraction: float = 0.5
    disturbance_torque_arm: float = 0.05
    max_displacement: float = 0.02
    max_rotation_deg: float = 10.0
    invalid_penetration: float = 5e-4

    @property
    def held_time(self) -> float:
        """How long gravity acts on a held object: the gravity phase and the 12 disturbances (s)."""
        return self.gravity_time + 12 * self.disturbance_time

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


PROTOCOL = DisturbanceProtocol()
"""The simulation protocol's defaults (beyond the paper: its loads and bounds); import this."""

SELECTIONS: tuple[str, ...] = ("paper", "robust")
"""Pair selections of the generator: the paper's (force closure under gravity only) and the robust
one (:mod:`dataset_gen.grasps.robust`: also against every load of :data:`PROTOCOL`)."""
