"""The DG16M paper's parameters, defined once.

Every default that reproduces the paper or its release (the generator, the force-closure check,
the benchmark, the simulated scene and trial, the evaluators and the bench scripts) derives from
:data:`PAPER`. A second literal copy of any of these numbers is a bug waiting to happen: import
the object instead::

    from dataset_gen.parameters import PAPER

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
