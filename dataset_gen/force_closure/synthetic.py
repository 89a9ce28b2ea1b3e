"""Random four-contact sets with known geometry, for tests and the throughput benchmark.

Every family returns ``(points (N, 4, 3), outward_normals (N, 4, 3))`` in an object frame whose
origin is the centre of mass, and every draw comes from the given ``numpy.random.Generator``.
"""

from __future__ import annotations

import numpy as np

from .geometry import FloatArray

FAMILIES: tuple[str, ...] = ("sphere", "box", "random", "near_collinear")
"""The synthetic contact families :func:`family_pairs` makes."""


def _unit(v: FloatArray) -> FloatArray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def sphere_pairs(n: int, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """Two roughly antipodal jaw contacts per arm on spheres of radius 0.05-0.3 m.

    Each jaw's second contact is the first one reflected through the centre and jittered by up
    to 30 degrees, so friction cones (mu = 0.4 is 21.8 degrees) hold some pairs and not others.
    """
    radius = rng.uniform(0.05, 0.3, size=(n, 1, 1))
    first = _unit(rng.normal(size=(n, 2, 3)))
    jitter = np.deg2rad(30.0) * rng.uniform(0.0, 1.0, size=(n, 2, 1))
    tangent = _unit(np.cross(first, rng.normal(size=(n, 2, 3))))
    second = _unit(-first * np.cos(jitter) + tangent * np.sin(jitter))
    normals = np.stack([first[:, 0], second[:, 0], first[:, 1], second[:, 1]], axis=1)
    return normals * radius, normals


def box_pairs(n: int, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """Each arm pinches two opposite faces of a random box (half sizes 0.02-0.4 m).

    The pinch points are offset independently on the two faces, so the squeeze can leave the
    friction cone.
    """
    half = rng.uniform(0.02, 0.4, size=(n, 1, 3))
    axis = rng.integers(0, 3, size=(n, 2))
    points = np.zeros((n, 4, 3))
    normals = np.zeros((n, 4, 3))
    for arm in range(2):
        a = axis[:, arm]
        for jaw, sign in enumerate((1.0, -1.0)):
            k = 2 * arm + jaw
            p = rng.uniform(-1.0, 1.0, size=(n, 3)) * half[:, 0]
            p[np.arange(n), a] = sign * half[np.arange(n), 0, a]
            points[:, k] = p
            normals[np.arange(n), k, a] = sign
    return points, normals


def random_pairs(n: int, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """Points uniform in a 0.3 m ball with uniformly random normals (almost all fail)."""
    points = _unit(rng.normal(size=(n, 4, 3))) * 0.3 * rng.uniform(0, 1, size=(n, 4, 1)) ** (1 / 3)
    return points, _unit(rng.normal(size=(n, 4, 3)))


def near_collinear_pairs(n: int, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """Four contacts within 10^U(-17, -2) m of a common line: the rank test's hard cases."""
    direction = _unit(rng.normal(size=(n, 1, 3)))
    base = rng.uniform(-0.1, 0.1, size=(n, 1, 3))
    along = rng.uniform(-0.3, 0.3, size=(n, 4, 1))
    offset = 10.0 ** rng.uniform(-17.0, -2.0, size=(n, 1, 1))
    points = base + along * direction + offset * _unit(rng.normal(size=(n, 4, 3)))
    exact = rng.uniform(size=n) < 0.2
    points[exact] = base[exact] + along[exact] * direction[exact]
    return points, _unit(rng.normal(size=(n, 4, 3)))


def family_pairs(family: str, n: int, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """Dispatch by family name (one of :data:`FAMILIES`)."""
    makers = {
        "sphere": sphere_pairs,
        "box": box_pairs,
        "random": random_pairs,
        "near_collinear": near_collinear_pairs,
    }
    if family not in makers:
        raise ValueError(f"family: expected one of {FAMILIES}, found {family!r}")
    return makers[family](n, rng)
