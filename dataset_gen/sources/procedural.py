"""The embedded default object library: large objects a two-armed robot carries.

Every object is an exact union of convex primitives (:class:`~dataset_gen.objects.grasp_object.ConvexPart`
boxes, cylinders and, for the tub's floor, one convex prism), built deterministically from a
``(family, seed)`` pair. The parts double as the object's exact convex decomposition for the
simulator, and the union (manifold3d) is the watertight mesh that grasps are sampled on.

Families
--------
Listed in :data:`FAMILIES`, in an order that is part of the id and split contract (never reorder;
new families go at the end). Lengths in metres; the graspable feature of each family is named.

``table``
    Top on four square or round legs, optional aprons. Grasp: the top's overhanging edge
    (0.02-0.05 thick) or a leg (0.03-0.06).
``bench``
    Long narrow seat on two slab legs with a stretcher, or on four posts with side stretchers.
    Grasp: seat edge (0.025-0.05), slab legs, stretchers.
``crate``
    Open box: floor plate and four rim walls, optional divider walls. Grasp: a wall's rim
    (0.012-0.03 thick), one finger inside the crate.
``tub``
    Regular polygonal ring wall of 8-16 box segments on a polygonal floor. Grasp: the rim
    (0.015-0.035 thick).
``chair``
    Seat on four legs; the rear legs continue up as back posts carrying a top rail and 0-2 slats;
    optional side stretchers. Grasp: the back's top rail (0.015-0.03), legs, seat edge.
``shelf``
    Bookcase: two side panels, 2-5 boards, optional back panel. Grasp: a side panel's front edge
    (0.015-0.03), one finger inside a compartment.
``ladder``
    Lying flat: two rails along x and 3-8 round or square rungs. Grasp: a rung (0.024-0.04) or a
    rail (0.02-0.04 wide).
``board``
    Plank or panel (0.012-0.05 thick), optionally on 1-3 battens underneath. Grasp: its edge.
``frame``
    Lying flat rectangular frame of square bars, or of round tubes joined by corner blocks, with
    0-2 cross bars. Grasp: any bar (0.02-0.05).
``barrel_with_handles``
    Upright cylinder body with two U handles (three boxes each) on opposite sides, horizontal or
    vertical, standing 0.04-0.07 off the body so a finger fits behind the grip bar. Grasp: a grip
    bar (0.015-0.03).

Every object's longest side is in [:data:`MIN_LONGEST_SIDE_M`, :data:`MAX_LONGEST_SIDE_M`]
(0.3-1.2 m, guaranteed by the parameter ranges and checked in :func:`build_parts`), every part is
at least :data:`MIN_FEATURE_M` (0.012 m) thick, and every object has a feature thinner than a
Panda hand's 0.08 m opening with room around it for a 0.025 m finger.

Ids, seeds and splits
---------------------
An object's id is ``f"{family}-{seed:07d}"``, e.g. ``"crate-0000042"``. Train objects use seeds
in ``[0, BENCHMARK_SEED_BASE)``; the benchmark is the fixed set of seeds
``[BENCHMARK_SEED_BASE, BENCHMARK_SEED_BASE + BENCHMARK_PER_FAMILY)`` of the first
:data:`N_BENCHMARK_FAMILIES` families (10 x 30 = 300 objects, also if families are added later).
So the split of an object follows from its id alone and train and benchmark can never overlap.

Parameters come from ``np.random.default_rng(np.random.SeedSequence([seed, crc32(family)]))``,
which is stable across machines, processes and Python versions (Python's ``hash`` is not). The
union mesh is put in a canonical vertex and face order, so the same ``(family, seed)`` gives
byte-identical exported meshes.
"""

from __future__ import annotations

import io
import math
import re
import zlib
from collections.abc import Callable, Sequence
from typing import Literal

import numpy as np
import trimesh

from dataset_gen.objects.grasp_object import (
    DEFAULT_MASS_KG,
    ConvexPart,
    GraspObject,
    make_object,
    parts_to_mesh,
)
from dg16m_core.errors import Dg16mError

Split = Literal["train", "benchmark"]

FAMILIES: tuple[str, ...] = (
    "table",
    "bench",
    "crate",
    "tub",
    "chair",
    "shelf",
    "ladder",
    "board",
    "frame",
    "barrel_with_handles",
)
"""Object families in their fixed order (part of the id/split contract: never reorder)."""

BENCHMARK_SEED_BASE = 1_000_000
"""First benchmark seed; train seeds are ``[0, BENCHMARK_SEED_BASE)``."""

BENCHMARK_PER_FAMILY = 30
"""Benchmark objects per benchmark family."""

N_BENCHMARK_FAMILIES = 10
"""The benchmark uses the first this-many entries of :data:`FAMILIES` (10 x 30 = 300 objects)."""

BENCHMARK_SIZE = N_BENCHMARK_FAMILIES * BENCHMARK_PER_FAMILY
"""Number of benchmark objects (300)."""

MIN_LONGEST_SIDE_M = 0.3
"""Smallest longest bounding-box side of a procedural object (m)."""

MAX_LONGEST_SIDE_M = 1.2
"""Largest longest bounding-box side of a procedural object (m)."""

MIN_FEATURE_M = 0.012
"""Thinnest part dimension any family produces (m)."""

_ID_PATTERN = re.compile(r"^([a-z_]+)-([0-9]{7})$")


class ProceduralError(Dg16mError, ValueError):
    """A procedural family, seed, object id or object-spec request is invalid."""


# --------------------------------------------------------------------------------------------
# Ids, seeds and splits
# --------------------------------------------------------------------------------------------


def _check_family(family: str) -> None:
    if family not in FAMILIES:
        raise ProceduralError(f"family: expected one of {', '.join(FAMILIES)}, found {family!r}")


def split_of(family: str, seed: int) -> Split:
    """The split an object belongs to: ``"benchmark"`` or ``"train"``.

    Benchmark iff ``family`` is one of the first :data:`N_BENCHMARK_FAMILIES` families and
    ``seed`` is in ``[BENCHMARK_SEED_BASE, BENCHMARK_SEED_BASE + BENCHMARK_PER_FAMILY)``; train iff
    ``seed`` is in ``[0, BENCHMARK_SEED_BASE)``.

    Raises:
        ProceduralError: unknown family, or a seed in neither range.
    """
    _check_family(family)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ProceduralError(f"seed: expected an integer, found {seed!r}")
    seed = int(seed)
    if 0 <= seed < BENCHMARK_SEED_BASE:
        return "train"
    benchmark_end = BENCHMARK_SEED_BASE + BENCHMARK_PER_FAMILY
    if BENCHMARK_SEED_BASE <= seed < benchmark_end:
        if FAMILIES.index(family) < N_BENCHMARK_FAMILIES:
            return "benchmark"
        raise ProceduralError(
            f"seed: family {family!r} is not in the benchmark; expected a train seed in "
            f"[0, {BENCHMARK_SEED_BASE}), found {seed}"
        )
    raise ProceduralError(
        f"seed: expected a train seed in [0, {BENCHMARK_SEED_BASE}) or a benchmark seed in "
        f"[{BENCHMARK_SEED_BASE}, {benchmark_end}), found {seed}"
    )


def object_id(family: str, seed: int) -> str:
    """The object id ``f"{family}-{seed:07d}"``; validates family and seed like :func:`split_of`."""
    split_of(family, seed)
    return f"{family}-{int(seed):07d}"


def parse_object_id(oid: str) -> tuple[str, int]:
    """Inverse of :func:`object_id`: ``"crate-0000042"`` -> ``("crate", 42)``.

    Raises:
        ProceduralError: the id is malformed, names an unknown family, or has an invalid seed.
    """
    match = _ID_PATTERN.match(oid) if isinstance(oid, str) else None
    if match is None:
        raise ProceduralError(f"object id: expected '<family>-<7 digits>', found {oid!r}")
    family, seed = match.group(1), int(match.group(2))
    if family not in FAMILIES:
        raise ProceduralError(
            f"object id {oid!r}: expected a family in {', '.join(FAMILIES)}, found {family!r}"
        )
    split_of(family, seed)
    return family, seed


def benchmark_specs() -> list[tuple[str, int]]:
    """The 300 benchmark ``(family, seed)`` pairs, interleaved: seed-major, families in order."""
    families = FAMILIES[:N_BENCHMARK_FAMILIES]
    return [
        (family, BENCHMARK_SEED_BASE + k)
        for k in range(BENCHMARK_PER_FAMILY)
        for family in families
    ]


def object_specs(count: int, *, seed: int = 0, split: Split = "train") -> list[tuple[str, int]]:
    """The first ``count`` ``(family, seed)`` pairs of a split.

    Train: object ``i`` is family ``FAMILIES[i % len(FAMILIES)]`` with seed
    ``seed + i // len(FAMILIES)``; all seeds must stay below :data:`BENCHMARK_SEED_BASE`.
    Benchmark: the first ``count`` of :func:`benchmark_specs` (``count <= 300``, ``seed == 0``).

    Raises:
        ProceduralError: negative or non-integer ``count``, unknown split, a train range that runs
            into the benchmark seeds, or a benchmark request with ``count > 300`` or ``seed != 0``.
    """
    for name, value in (("count", count), ("seed", seed)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ProceduralError(f"{name}: expected a non-negative integer, found {value!r}")
    count, seed = int(count), int(seed)
    if split == "benchmark":
        if seed != 0:
            raise ProceduralError(
                f"seed: the benchmark is a fixed set; expected seed 0, found {seed}"
            )
        if count > BENCHMARK_SIZE:
            raise ProceduralError(
                f"count: the benchmark has {BENCHMARK_SIZE} objects; expected at most "
                f"{BENCHMARK_SIZE}, found {count}"
            )
        return benchmark_specs()[:count]
    if split != "train":
        raise ProceduralError(f"split: expected 'train' or 'benchmark', found {split!r}")
    n = len(FAMILIES)
    if count and seed + (count - 1) // n >= BENCHMARK_SEED_BASE:
        raise ProceduralError(
            f"count/seed: train seeds must stay below {BENCHMARK_SEED_BASE}; expected "
            f"seed + (count - 1) // {n} < {BENCHMARK_SEED_BASE}, found "
            f"{seed} + ({count} - 1) // {n} = {seed + (count - 1) // n}"
        )
    return [(FAMILIES[i % n], seed + i // n) for i in range(count)]


def family_rng(family: str, seed: int) -> np.random.Generator:
    """The generator that draws an object's parameters (stable across machines and versions)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), zlib.crc32(family.encode())]))


# --------------------------------------------------------------------------------------------
# Part helpers
# --------------------------------------------------------------------------------------------


def _pose(rotation: np.ndarray | None, translation: Sequence[float]) -> np.ndarray:
    pose = np.eye(4)
    if rotation is not None:
        pose[:3, :3] = rotation
    pose[:3, 3] = translation
    return pose


def _rot_z(angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` radians about z."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _frame_with_z(axis: np.ndarray) -> np.ndarray:
    """(3, 3) rotation whose third column is the unit vector along ``axis`` (3,)."""
    z = np.asarray(axis, dtype=np.float64)
    z = z / np.linalg.norm(z)
    ref = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = ref - ref.dot(z) * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.column_stack([x, y, z])


def _box(
    center: Sequence[float], half_extents: Sequence[float], rotation: np.ndarray | None = None
) -> ConvexPart:
    """Box part with (3,) ``half_extents`` (m) at ``center`` (3,), rotated by (3, 3) ``rotation``
    (identity when ``None``)."""
    return ConvexPart("box", _pose(rotation, center), tuple(float(h) for h in half_extents))


def _span_box(lo: Sequence[float], hi: Sequence[float]) -> ConvexPart:
    """Axis-aligned box part between corners ``lo`` (3,) and ``hi`` (3,) (m)."""
    lo_a, hi_a = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    return _box(0.5 * (lo_a + hi_a), 0.5 * (hi_a - lo_a))


def _cylinder(p0: Sequence[float], p1: Sequence[float], radius: float) -> ConvexPart:
    """Cylinder part of ``radius`` (m) whose axis runs from point ``p0`` (3,) to ``p1`` (3,)."""
    a, b = np.asarray(p0, dtype=np.float64), np.asarray(p1, dtype=np.float64)
    axis = b - a
    return ConvexPart(
        "cylinder", _pose(_frame_with_z(axis), 0.5 * (a + b)), (radius, 0.5 * np.linalg.norm(axis))
    )


def _prism(polygon: np.ndarray, z0: float, z1: float) -> ConvexPart:
    """Convex prism part over the convex (N, 2) ``polygon`` (m) between heights ``z0 < z1``."""
    poly = np.asarray(polygon, dtype=np.float64)
    verts = np.vstack(
        [np.column_stack([poly, np.full(len(poly), z)]) for z in (float(z0), float(z1))]
    )
    return ConvexPart("mesh", np.eye(4), (), verts)


def _u(rng: np.random.Generator, low: float, high: float) -> float:
    """One uniform draw in [low, high)."""
    return float(rng.uniform(low, high))


def _coin(rng: np.random.Generator, p: float = 0.5) -> bool:
    """True with probability ``p``."""
    return bool(rng.random() < p)


def _post(x: float, y: float, z0: float, z1: float, size: float, round_: bool) -> ConvexPart:
    """Vertical leg between heights ``z0`` and ``z1``: square of side ``size`` or round of
    diameter ``size`` (m), centred on (``x``, ``y``)."""
    if round_:
        return _cylinder((x, y, z0), (x, y, z1), 0.5 * size)
    h = 0.5 * size
    return _span_box((x - h, y - h, z0), (x + h, y + h, z1))


# --------------------------------------------------------------------------------------------
# Family builders: each returns parts in a z-up frame, resting on z = 0
# --------------------------------------------------------------------------------------------


def _table(rng: np.random.Generator) -> list[ConvexPart]:
    length = _u(rng, 0.5, 1.2)
    width = _u(rng, 0.3, min(0.8, length))
    top_t = _u(rng, 0.02, 0.05)
    height = _u(rng, 0.3, 0.9)
    round_legs = _coin(rng)
    leg = _u(rng, 0.03, 0.06)
    overhang = _u(rng, 0.03, min(0.12, 0.2 * width))
    top_z0 = height - top_t
    parts = [_span_box((-length / 2, -width / 2, top_z0), (length / 2, width / 2, height))]
    lx = length / 2 - overhang - leg / 2
    ly = width / 2 - overhang - leg / 2
    parts += [
        _post(sx * lx, sy * ly, 0.0, height - top_t / 2, leg, round_legs)
        for sx in (-1, 1)
        for sy in (-1, 1)
    ]
    if _coin(rng):
        apron_h = _u(rng, 0.04, min(0.1, 0.3 * top_z0))
        apron_t = _u(rng, 0.015, min(0.025, leg))
        z0, z1 = top_z0 - apron_h, top_z0 + top_t / 2
        for s in (-1, 1):
            parts.append(_span_box((-lx, s * ly - apron_t / 2, z0), (lx, s * ly + apron_t / 2, z1)))
            parts.append(_span_box((s * lx - apron_t / 2, -ly, z0), (s * lx + apron_t / 2, ly, z1)))
    return parts


def _bench(rng: np.random.Generator) -> list[ConvexPart]:
    length = _u(rng, 0.7, 1.2)
    width = _u(rng, 0.22, 0.4)
    seat_t = _u(rng, 0.025, 0.05)
    height = _u(rng, 0.3, 0.5)
    seat_z0 = height - seat_t
    parts = [_span_box((-length / 2, -width / 2, seat_z0), (length / 2, width / 2, height))]
    inset = _u(rng, 0.03, 0.15)
    if _coin(rng):
        # Two slab legs joined by a stretcher under the seat's centre line.
        slab_t = _u(rng, 0.025, 0.05)
        slab_w = width - 2.0 * _u(rng, 0.005, 0.03)
        x = length / 2 - inset - slab_t / 2
        for s in (-1, 1):
            parts.append(
                _span_box(
                    (s * x - slab_t / 2, -slab_w / 2, 0.0),
                    (s * x + slab_t / 2, slab_w / 2, height - seat_t / 2),
                )
            )
        st_w, st_h = _u(rng, 0.025, 0.05), _u(rng, 0.03, 0.07)
        st_z = _u(rng, 0.3, 0.6) * seat_z0
        parts.append(_span_box((-x, -st_w / 2, st_z - st_h / 2), (x, st_w / 2, st_z + st_h / 2)))
    else:
        # Four posts with a stretcher along each long side.
        leg = _u(rng, 0.035, 0.06)
        round_legs = _coin(rng)
        x = length / 2 - inset - leg / 2
        y = width / 2 - _u(rng, 0.01, 0.04) - leg / 2
        parts += [
            _post(sx * x, sy * y, 0.0, height - seat_t / 2, leg, round_legs)
            for sx in (-1, 1)
            for sy in (-1, 1)
        ]
        st = _u(rng, 0.02, 0.7 * leg)
        st_z = _u(rng, 0.1, 0.3) * seat_z0 + st
        for s in (-1, 1):
            parts.append(
                _span_box((-x, s * y - st / 2, st_z - st / 2), (x, s * y + st / 2, st_z + st / 2))
            )
    return parts


def _crate(rng: np.random.Generator) -> list[ConvexPart]:
    length = _u(rng, 0.35, 1.0)
    width = _u(rng, 0.25, min(0.7, length))
    height = _u(rng, 0.15, 0.5)
    wall = _u(rng, 0.012, 0.03)
    floor = _u(rng, 0.012, 0.03)
    hx, hy = length / 2, width / 2
    parts = [_span_box((-hx, -hy, 0.0), (hx, hy, floor))]
    for s in (-1, 1):
        # Long walls run the full length; short walls fit between them (overlapping by wall/2).
        y0, y1 = sorted((s * hy, s * (hy - wall)))
        parts.append(_span_box((-hx, y0, 0.0), (hx, y1, height)))
        x0, x1 = sorted((s * hx, s * (hx - wall)))
        parts.append(_span_box((x0, -hy + wall / 2, 0.0), (x1, hy - wall / 2, height)))
    n_dividers = int(rng.integers(0, 3))
    divider_h = _u(rng, 0.5, 0.9) * height
    for k in range(1, n_dividers + 1):
        x = (length - 2 * wall) * (k / (n_dividers + 1) - 0.5)
        parts.append(
            _span_box((x - wall / 2, -hy + wall / 2, 0.0), (x + wall / 2, hy - wall / 2, divider_h))
        )
    return parts


def _tub(rng: np.random.Generator) -> list[ConvexPart]:
    n = int(rng.integers(8, 17))
    radius = _u(rng, 0.2, 0.55)  # circumradius of the outer wall polygon
    height = _u(rng, 0.15, 0.45)
    wall = _u(rng, 0.015, 0.035)
    floor = _u(rng, 0.012, 0.03)
    half_angle = math.pi / n
    apothem = radius * math.cos(half_angle)  # outer face distance from the axis
    mid = apothem - wall / 2
    half_len = apothem * math.tan(half_angle)  # outer edges meet exactly at the polygon corners
    parts = []
    for i in range(n):
        theta = 2.0 * math.pi * i / n
        center = (mid * math.cos(theta), mid * math.sin(theta), height / 2)
        parts.append(_box(center, (wall / 2, half_len, height / 2), _rot_z(theta)))
    # Floor: the mid-wall polygon, so it overlaps every segment by half the wall thickness.
    corner = mid / math.cos(half_angle)
    angles = 2.0 * math.pi * np.arange(n) / n + half_angle
    polygon = corner * np.column_stack([np.cos(angles), np.sin(angles)])
    parts.append(_prism(polygon, 0.0, floor))
    return parts


def _chair(rng: np.random.Generator) -> list[ConvexPart]:
    seat_w = _u(rng, 0.38, 0.55)  # x
    seat_d = _u(rng, 0.36, 0.5)  # y, back at +y
    seat_t = _u(rng, 0.02, 0.045)
    seat_h = _u(rng, 0.38, 0.5)
    back_h = _u(rng, 0.3, 0.5)
    round_legs = _coin(rng)
    leg = _u(rng, 0.028, 0.05)
    inset = _u(rng, 0.005, 0.03)
    x = seat_w / 2 - inset - leg / 2
    y = seat_d / 2 - inset - leg / 2
    top = seat_h + back_h
    parts = [
        _span_box((-seat_w / 2, -seat_d / 2, seat_h - seat_t), (seat_w / 2, seat_d / 2, seat_h))
    ]
    parts += [_post(sx * x, -y, 0.0, seat_h - seat_t / 2, leg, round_legs) for sx in (-1, 1)]
    parts += [_post(sx * x, y, 0.0, top, leg, round_legs) for sx in (-1, 1)]
    # Back: a top rail flush with the post tops, and 0-2 slats below with finger-sized gaps.
    n_rails = int(rng.integers(1, 4))  # the top rail and 0-2 slats
    rail_t = _u(rng, 0.015, min(0.03, 0.8 * leg))
    rail_h = _u(rng, 0.04, 0.09)
    slat_h = _u(rng, 0.03, 0.06)
    spans = [(top - rail_h, top)]
    if n_rails > 1:
        low = seat_h + 0.06 + slat_h / 2
        high = top - rail_h - 0.05 - slat_h / 2
        if high > low:
            spans += [(z - slat_h / 2, z + slat_h / 2) for z in np.linspace(high, low, n_rails - 1)]
    for z0, z1 in spans:
        parts.append(_span_box((-x, y - rail_t / 2, z0), (x, y + rail_t / 2, z1)))
    if _coin(rng):
        st = _u(rng, 0.015, 0.7 * leg)
        z = _u(rng, 0.08, 0.2)
        for s in (-1, 1):
            parts.append(
                _span_box((s * x - st / 2, -y, z - st / 2), (s * x + st / 2, y, z + st / 2))
            )
    return parts


def _shelf(rng: np.random.Generator) -> list[ConvexPart]:
    width = _u(rng, 0.4, 1.0)  # x
    depth = _u(rng, 0.2, 0.4)  # y, back at +y
    height = _u(rng, 0.5, 1.2)
    t = _u(rng, 0.015, 0.03)
    kick = _u(rng, 0.02, 0.08) if _coin(rng) else 0.0  # bottom board height
    hx = width / 2
    parts = [
        _span_box((x0, -depth / 2, 0.0), (x1, depth / 2, height))
        for x0, x1 in ((-hx, -hx + t), (hx - t, hx))
    ]
    max_boards = min(5, 1 + int((height - kick - t) / 0.15))
    n_boards = int(rng.integers(2, max_boards + 1))
    zs = np.linspace(kick, height - t, n_boards)
    gap = (height - kick - t) / (n_boards - 1)
    zs[1:-1] += rng.uniform(-0.15, 0.15, n_boards - 2) * gap
    # Boards reach half-way into the side panels; the top board is flush with their tops.
    for z0, z1 in [(z, z + t) for z in zs[:-1]] + [(height - t, height)]:
        parts.append(_span_box((-hx + t / 2, -depth / 2, z0), (hx - t / 2, depth / 2, z1)))
    if _coin(rng):
        back = _u(rng, 0.012, 0.02)
        parts.append(_span_box((-hx, depth / 2 - back, 0.0), (hx, depth / 2, height)))
    return parts


def _ladder(rng: np.random.Generator) -> list[ConvexPart]:
    length = _u(rng, 0.6, 1.2)  # x
    width = _u(rng, 0.28, 0.5)  # y, outer
    rail_w = _u(rng, 0.02, 0.04)
    rail_d = _u(rng, 0.045, 0.08)  # z
    end = _u(rng, 0.05, 0.12)
    y = width / 2 - rail_w / 2  # rail centre lines
    parts = [
        _span_box((-length / 2, y0, 0.0), (length / 2, y1, rail_d))
        for y0, y1 in ((-width / 2, -width / 2 + rail_w), (width / 2 - rail_w, width / 2))
    ]
    max_rungs = min(8, 1 + int((length - 2 * end) / 0.15))
    n_rungs = int(rng.integers(3, max_rungs + 1))
    zc = rail_d / 2
    round_rungs = _coin(rng)
    size = _u(rng, 0.024, min(0.04, 0.9 * rail_d))
    for x in np.linspace(-length / 2 + end, length / 2 - end, n_rungs):
        if round_rungs:
            parts.append(_cylinder((x, -y, zc), (x, y, zc), size / 2))
        else:
            parts.append(
                _span_box((x - size / 2, -y, zc - size / 2), (x + size / 2, y, zc + size / 2))
            )
    return parts


def _board(rng: np.random.Generator) -> list[ConvexPart]:
    length = _u(rng, 0.3, 1.2)  # x
    width = _u(rng, 0.1, min(0.8, length))  # y
    thick = _u(rng, 0.012, 0.05)
    max_battens = min(3, int(length / 0.2))
    n_battens = int(rng.integers(0, max_battens + 1))
    parts = []
    z0 = 0.0
    if n_battens:
        bw = _u(rng, 0.03, 0.07)
        bh = _u(rng, 0.015, 0.03)
        margin = _u(rng, 0.03, 0.08)
        by = width / 2 - _u(rng, 0.005, 0.03)
        xs = (
            [0.0]
            if n_battens == 1
            else np.linspace(-length / 2 + margin + bw / 2, length / 2 - margin - bw / 2, n_battens)
        )
        for x in xs:
            parts.append(_span_box((x - bw / 2, -by, 0.0), (x + bw / 2, by, bh + thick / 2)))
        z0 = bh
    parts.insert(0, _span_box((-length / 2, -width / 2, z0), (length / 2, width / 2, z0 + thick)))
    return parts


def _frame(rng: np.random.Generator) -> list[ConvexPart]:
    length = _u(rng, 0.4, 1.2)  # x
    width = _u(rng, 0.3, min(0.9, length))  # y
    n_cross = int(rng.integers(0, 3))
    xs_cross = [length * (k / (n_cross + 1) - 0.5) for k in range(1, n_cross + 1)]
    hx, hy = length / 2, width / 2
    if _coin(rng):
        bar = _u(rng, 0.02, 0.05)  # in-plane width
        depth = _u(rng, 0.02, 0.05)  # z
        parts = [
            _span_box((-hx, y0, 0.0), (hx, y1, depth))
            for y0, y1 in ((-hy, -hy + bar), (hy - bar, hy))
        ]
        # Short bars and cross bars fit between the long bars (overlapping them by bar/2).
        parts += [
            _span_box((x0, -hy + bar / 2, 0.0), (x1, hy - bar / 2, depth))
            for x0, x1 in [(-hx, -hx + bar), (hx - bar, hx)]
            + [(x - bar / 2, x + bar / 2) for x in xs_cross]
        ]
        return parts
    # Round tubes between corner blocks a little thicker than the tubes (covering their ends).
    r = _u(rng, 0.012, 0.025)
    d = 2.4 * r  # corner block side
    cx, cy = hx - d / 2, hy - d / 2
    corners = [(-cx, -cy), (cx, -cy), (cx, cy), (-cx, cy)]
    parts = [
        _span_box(
            (min(sx * hx, sx * (hx - d)), min(sy * hy, sy * (hy - d)), 0.0),
            (max(sx * hx, sx * (hx - d)), max(sy * hy, sy * (hy - d)), d),
        )
        for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))
    ]
    for (x0, y0), (x1, y1) in zip(corners, corners[1:] + corners[:1], strict=True):
        parts.append(_cylinder((x0, y0, d / 2), (x1, y1, d / 2), r))
    parts += [_cylinder((x, -cy, d / 2), (x, cy, d / 2), r) for x in xs_cross]
    return parts


def _barrel_with_handles(rng: np.random.Generator) -> list[ConvexPart]:
    radius = _u(rng, 0.15, 0.32)
    height = _u(rng, 0.35, 0.9)
    parts = [_cylinder((0.0, 0.0, 0.0), (0.0, 0.0, height), radius)]
    gap = _u(rng, 0.04, 0.07)  # clear space between body and grip bar, for a finger
    bar_r = _u(rng, 0.015, 0.03)  # grip bar thickness along the radius
    bar_s = _u(rng, 0.015, 0.03)  # grip bar thickness across
    arm = _u(rng, 0.012, 0.9 * bar_s)  # arm cross-section side, thinner than the bar
    horizontal = _coin(rng)
    span = _u(rng, 0.1, min(0.2, 1.2 * radius - 2 * arm))  # clear space between the arms
    inner = radius * math.cos(math.pi / 16)  # safely inside the 32-gon body
    r_bar = radius + gap + bar_r / 2
    off = span / 2 + arm / 2  # arm centre offset from the handle centre
    if horizontal:
        zh = height - _u(rng, 0.06, 0.15)
    else:
        zh = height / 2 + _u(rng, 0.0, max(0.0, height / 2 - off - arm - 0.03))
    for angle in (0.0, math.pi):
        rot = _rot_z(angle)  # handle frame: x outward along the radius, y tangential, z up
        if horizontal:
            bar_half = (bar_r / 2, off + arm, bar_s / 2)
            arm_at = [(t, zh) for t in (-off, off)]
            r_in = math.sqrt(inner**2 - (off + arm / 2) ** 2) - 0.01
        else:
            bar_half = (bar_r / 2, bar_s / 2, off + arm)
            arm_at = [(0.0, zh + dz) for dz in (-off, off)]
            r_in = inner - 0.01
        parts.append(_box(rot @ np.array([r_bar, 0.0, zh]), bar_half, rot))
        for t, z in arm_at:
            # Arms end at the bar's centre line, strictly inside the bar (no flush faces).
            center = rot @ np.array([(r_in + r_bar) / 2, t, z])
            parts.append(_box(center, ((r_bar - r_in) / 2, arm / 2, arm / 2), rot))
    return parts


_BUILDERS: dict[str, Callable[[np.random.Generator], list[ConvexPart]]] = {
    "table": _table,
    "bench": _bench,
    "crate": _crate,
    "tub": _tub,
    "chair": _chair,
    "shelf": _shelf,
    "ladder": _ladder,
    "board": _board,
    "frame": _frame,
    "barrel_with_handles": _barrel_with_handles,
}


# --------------------------------------------------------------------------------------------
# Public builders
# --------------------------------------------------------------------------------------------


def parts_bounds(parts: Sequence[ConvexPart]) -> np.ndarray:
    """(2, 3) axis-aligned bounds (min, max) of the parts' meshes (m), as meshed by the union."""
    points = np.vstack([np.asarray(part.to_mesh().vertices) for part in parts])
    return np.array([points.min(axis=0), points.max(axis=0)])


def build_parts(family: str, seed: int) -> list[ConvexPart]:
    """The convex parts of object ``(family, seed)`` in its z-up frame, resting on z = 0 (m).

    The frame is the builder's, before :func:`make_procedural_object` centres the object.

    Raises:
        ProceduralError: unknown family or invalid seed (see :func:`split_of`).
        RuntimeError: the builder broke its own size guarantee (a bug).
    """
    split_of(family, seed)
    parts = _BUILDERS[family](family_rng(family, seed))
    lo, hi = parts_bounds(parts)
    longest = float(np.max(hi - lo))
    if not (MIN_LONGEST_SIDE_M - 1e-9 <= longest <= MAX_LONGEST_SIDE_M + 1e-9) or abs(lo[2]) > 1e-9:
        raise RuntimeError(
            f"{object_id(family, seed)}: expected a longest side in [{MIN_LONGEST_SIDE_M}, "
            f"{MAX_LONGEST_SIDE_M}] m resting on z = 0, found {longest:.4f} m with bottom at "
            f"z = {lo[2]:.4g} m (a bug in the {family} builder)"
        )
    return parts


def canonical_mesh(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """A copy of ``mesh`` in a canonical order: vertices sorted by (x, y, z), every face rotated
    to start at its smallest vertex index (winding kept), faces sorted. Exact duplicate vertices
    are merged. The result depends only on the geometry, not on the input's ordering."""
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    unique, inverse = np.unique(vertices, axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[np.asarray(mesh.faces)]
    faces = faces[
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    ]
    shift = np.argmin(faces, axis=1)
    rows = np.arange(len(faces))[:, None]
    faces = faces[rows, (shift[:, None] + np.arange(3)) % 3]
    faces = faces[np.lexsort(faces.T[::-1])]
    return trimesh.Trimesh(vertices=unique, faces=faces, process=False)


def make_procedural_object(family: str, seed: int, *, mass: float = DEFAULT_MASS_KG) -> GraspObject:
    """Build object ``(family, seed)``: the union mesh of :func:`build_parts`, centred at its
    centroid, with its parts, ``mass`` (kg) and metadata ``{"family", "seed", "split"}``.

    The mesh survives its own OBJ export read back by a default ``trimesh.load`` (which merges
    close vertices) unchanged: see :func:`survives_default_load` and :func:`union_mesh`.

    Raises:
        ProceduralError: unknown family or invalid seed.
        RuntimeError: the union is not one connected watertight solid with positive volume, or
            does not survive a default load (a bug in a family builder).
    """
    split = split_of(family, seed)
    parts = build_parts(family, seed)
    oid = object_id(family, seed)

    def build(mesh: trimesh.Trimesh) -> GraspObject:
        return make_object(
            mesh,
            object_id=oid,
            mass=mass,
            parts=parts,
            metadata={"family": family, "seed": int(seed), "split": split},
        )

    union = union_mesh(parts)
    obj = build(union)
    reloads = survives_default_load(obj.mesh)
    if not reloads:
        obj = build(collapse_slivers(union))
        reloads = survives_default_load(obj.mesh)
    _check_solid(obj.mesh, oid, family, reloads)
    return obj


def union_mesh(parts: Sequence[ConvexPart]) -> trimesh.Trimesh:
    """The canonical union mesh of ``parts`` (:func:`~dataset_gen.objects.grasp_object.parts_to_mesh`).

    manifold3d computes the union in float32 coordinates, so parts that touch exactly (the tub's
    wall segments meet along their outer corner edges, its floor is coplanar with their bottoms)
    can leave sliver triangles whose vertices lie ~1e-8 m apart. The mesh is still watertight,
    but a loader that merges close vertices (a default ``trimesh.load``) pinches it into a
    non-manifold one. :func:`make_procedural_object` then collapses those slivers
    (:func:`collapse_slivers`); meshes that survive a default load are kept exactly as they are,
    which keeps every benchmark object's mesh byte-identical.
    """
    return canonical_mesh(parts_to_mesh(parts))


SLIVER_TOLERANCE_M = 1e-6
"""Edges shorter than this are collapsed by :func:`collapse_slivers` (m); far below any feature
(:data:`MIN_FEATURE_M`) and far above float32 rounding at object scale (~3e-8 m)."""


def collapse_slivers(
    mesh: trimesh.Trimesh, tolerance: float = SLIVER_TOLERANCE_M
) -> trimesh.Trimesh:
    """``mesh`` with its sliver features removed: manifold3d's ``simplify`` collapses edges
    shorter than ``tolerance`` (m) and vertices that lie within it of their neighbours' surface,
    keeping the mesh manifold; no surface moves by more than ``tolerance``. Canonical order."""
    import manifold3d

    solid = manifold3d.Manifold(
        manifold3d.Mesh64(
            vert_properties=np.asarray(mesh.vertices, dtype=np.float64),
            tri_verts=np.asarray(mesh.faces, dtype=np.uint64),
        )
    )
    simplified = solid.simplify(tolerance).to_mesh64()
    vertices = np.asarray(simplified.vert_properties, dtype=np.float64)[:, :3]
    faces = np.asarray(simplified.tri_verts, dtype=np.int64)
    return canonical_mesh(trimesh.Trimesh(vertices=vertices, faces=faces, process=False))


def survives_default_load(mesh: trimesh.Trimesh) -> bool:
    """Whether ``mesh`` exported as OBJ (as the library and the generator write it) and read back
    by a default ``trimesh.load`` keeps every vertex (none merged) and is watertight."""
    text = mesh.export(file_type="obj")
    loaded = trimesh.load(io.StringIO(text), file_type="obj")
    return (
        isinstance(loaded, trimesh.Trimesh)
        and len(loaded.vertices) == len(mesh.vertices)
        and len(loaded.faces) == len(mesh.faces)
        and bool(loaded.is_watertight)
    )


def _check_solid(mesh: trimesh.Trimesh, oid: str, family: str, reloads: bool) -> None:
    """Raise RuntimeError unless ``mesh`` is one watertight solid that survives a default load
    (``reloads``, from :func:`survives_default_load`)."""
    bodies = len(mesh.split(only_watertight=False))
    solid = mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0 and bodies == 1
    if not (solid and reloads):
        raise RuntimeError(
            f"{oid}: expected one watertight solid with positive volume that survives a default "
            f"trimesh.load of its OBJ, found watertight={mesh.is_watertight}, "
            f"volume={mesh.volume:.4g} m^3, {bodies} bodies, survives load={reloads} "
            f"(a bug in the {family} builder)"
        )
