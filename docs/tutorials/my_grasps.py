"""A small dual-grasp predictor on the observed point cloud (numpy, and trimesh for a denser
sample of the mesh in the collision test).

1. Contact pairs across a part narrower than the Panda's 8 cm opening: for every cloud point
   (in a seeded order), a partner whose outward normal is within 15 degrees of opposite to its
   own, 5 mm to 6.5 cm away along the closing line (the difference of the two normals) and at
   most 8 mm to its side.
2. A hand on each pair: it closes along that line (``+x``, finger 0 on the first point) and
   approaches (``+y``) at one of 12 angles about it, from outside first (the side away from the
   centre of mass); the first angle whose open hand keeps 1 cm from the object's surface (a
   dense sample of its mesh), and whose fingers meet nothing on their way to the contacts, is
   kept. 40 such hands, 1 cm apart at least.
3. Dual grasps: two hands at least 15 cm apart whose open hands do not overlap, best first:
   far apart, the line between them passing over the centre of mass (the origin; gravity
   pulls -z), the centre of mass half-way between them.
"""

from typing import Any

import numpy as np
import trimesh

from dataset_gen.grasps.gripper import PANDA

CONE = np.cos(np.radians(15.0))  # the two contacts' normals within 15 degrees of opposite
SIDE = 0.008  # how far a partner may lie to the side of the closing line (m)
MIN_WIDTH, MAX_WIDTH = 0.005, 0.065  # contact separation (m); the Panda opens 0.08
MARGIN = 0.01  # clearance kept between the open hand and any cloud point (m)
TOL = 0.004  # how far past a contact, along the closing line, a cloud point may lie (m)
PALM = PANDA.palm_box()
REACH = 0.18  # no part of the hand lies farther than this from its contacts (m)
HANDS = 40  # single-arm grasps to pair
OPEN = PANDA.max_opening / 2 + PANDA.finger_thickness  # outer faces of the open fingers (x, m)


def hits_cloud(local: np.ndarray, half_width: np.ndarray) -> np.ndarray:
    """(A, P, 3) cloud in A grasp frames -> (A,) True where the open hand would touch it."""
    palm = (np.abs(local - PALM.center) <= np.add(PALM.half_extents, MARGIN)).all(-1)
    x, y, z = np.moveaxis(local, -1, 0)
    finger = (  # swept by a finger from fully open down to its contact
        (np.abs(x) > half_width[:, None] + TOL)
        & (np.abs(x) <= OPEN + MARGIN)
        & (y >= PANDA.palm_depth - MARGIN)
        & (y <= PANDA.finger_tip + MARGIN)
        & (np.abs(z) <= PANDA.finger_width / 2 + MARGIN)
    )
    return (palm | finger).any(-1)


def hand_corners(pose: np.ndarray) -> np.ndarray:
    """(24, 3) corners of the open hand's palm and fingers in the object frame."""
    signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    local = [np.add(b.center, signs * b.half_extents) for b in PANDA.collision_boxes()]
    return np.concatenate(local) @ pose[:3, :3].T + pose[:3, 3]


def hands_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two open hands overlap (boxes' corners and centres inside the other's boxes)."""
    for one, other in ((a, b), (b, a)):
        pts = np.concatenate([hand_corners(one), one[:3, 3:].T])
        local = (pts - other[:3, 3]) @ other[:3, :3]
        for box in PANDA.collision_boxes():
            if (np.abs(local - box.center) <= np.add(box.half_extents, 0.01)).all(-1).any():
                return True
    return False


def predict(observation: dict[str, Any], k: int = 10) -> tuple[np.ndarray, np.ndarray]:
    points = observation["points"].astype(np.float64)  # (P, 3) object frame (m)
    normals = observation["normals"].astype(np.float64)  # (P, 3) unit, outward
    mesh = trimesh.Trimesh(observation["mesh_vertices"], observation["mesh_faces"], process=False)
    dense, _ = trimesh.sample.sample_surface(mesh, 30_000, seed=0)  # for the collision test
    rng = np.random.default_rng(0)
    seeds = rng.permutation(len(points))  # every point, in a seeded order

    # 1. each seed's partner on an opposite face, as little to the side of the closing line as can be
    s, j = np.nonzero(normals[seeds] @ normals.T <= -CONE)  # normals within 15 degrees of opposite
    x = normals[seeds[s]] - normals[j]
    x /= np.linalg.norm(x, axis=1, keepdims=True)  # the closing line
    gap = points[seeds[s]] - points[j]
    width = (gap * x).sum(1)
    side = np.linalg.norm(gap - width[:, None] * x, axis=1)  # off the line (the pads are 2 cm wide)
    ok = (width >= MIN_WIDTH) & (width <= MAX_WIDTH) & (side <= SIDE)
    off = np.full((len(seeds), len(points)), np.inf)
    off[s[ok], j[ok]] = side[ok]
    partner = off.argmin(axis=1)
    good = np.isfinite(off.min(axis=1))
    p0, p1 = points[seeds[good]], points[partner[good]]  # finger 0 on p0, finger 1 on p1
    n0, n1 = normals[seeds[good]], normals[partner[good]]

    # 2. a collision-free hand on each pair, approaching from outside
    hands, centres = [], []
    for a, b, na, nb in zip(p0, p1, n0, n1, strict=True):
        x = (na - nb) / np.linalg.norm(na - nb)
        centre = (a + b) / 2
        u = np.cross(x, [0.0, 0.0, 1.0] if abs(x[2]) < 0.9 else [1.0, 0.0, 0.0])
        u /= np.linalg.norm(u)
        angles = np.linspace(0, 2 * np.pi, 12, endpoint=False)
        ys = np.cos(angles)[:, None] * u + np.sin(angles)[:, None] * np.cross(x, u)
        ys = ys[np.argsort(ys @ centre)]  # towards the centre of mass first: from outside
        frames = np.stack([np.broadcast_to(x, ys.shape), ys, np.cross(x, ys)], axis=2)
        origins = centre - PANDA.contact_depth * ys  # the flange
        near = dense[np.linalg.norm(dense - centre, axis=1) < REACH]
        local = (near[None] - origins[:, None]) @ frames  # (12, n, 3) in the 12 grasp frames
        free = ~hits_cloud(local, np.full(len(ys), abs((a - b) @ x) / 2))
        if free.any() and all(np.linalg.norm(centre - c) > 0.01 for c in centres):
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = frames[free.argmax()], origins[free.argmax()]
            hands.append(pose)
            centres.append(centre)
            if len(hands) == HANDS:
                break
    if len(hands) < 2:
        raise ValueError(f"expected at least 2 collision-free antipodal hands, found {len(hands)}")

    # 3. pairs of hands, far apart with the centre of mass between them
    c = np.array(centres)
    i, j = np.triu_indices(len(c), k=1)
    spread = np.linalg.norm(c[i] - c[j], axis=1)
    d = (c[i] - c[j]) / np.maximum(spread, 1e-9)[:, None]
    # gravity's lever (m) about the line between the hands, which two pinches can hardly resist
    lever = np.abs((np.cross(c[i], [0.0, 0.0, 1.0]) * d).sum(1))
    beyond = np.abs(((c[i] + c[j]) / 2 * d).sum(1))  # centre of mass off the middle, along d
    score = spread - 40 * lever - beyond
    order = np.argsort(-score)
    order = order[spread[order] >= 0.15]
    chosen = []
    for row in order:
        if not hands_overlap(hands[i[row]], hands[j[row]]):
            chosen.append(row)
            if len(chosen) == k:
                break
    if not chosen:  # no two hands far apart: the best-scored pair anyway
        chosen = [int(np.argmax(score))]
    poses = np.array([[hands[i[r]], hands[j[r]]] for r in chosen])  # (K, 2, 4, 4) grasp -> object
    return poses, score[chosen]
