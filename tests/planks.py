"""Test helpers shared by the trial tests: a plank with one exact convex part and Panda hand
poses that squeeze it (importable from tests/ as ``planks``)."""

from __future__ import annotations

import numpy as np
import trimesh

from dataset_gen.gripper import PANDA
from dataset_gen.objects import ConvexPart, GraspObject, make_object

THICKNESS = 0.04  # m, the planks' square cross-section
DOWN, SIDE = (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)  # approach directions (object frame)


def plank(length: float, mass: float, object_id: str = "plank") -> GraspObject:
    """A ``length x 0.04 x 0.04`` m box along x, centred at the origin, one exact convex part."""
    half = (length / 2.0, THICKNESS / 2.0, THICKNESS / 2.0)
    mesh = trimesh.creation.box(extents=2.0 * np.asarray(half))
    return make_object(
        mesh, object_id=object_id, mass=mass, parts=[ConvexPart("box", np.eye(4), half)]
    )


def hand(x: float, closing: str, approach: tuple[float, float, float]) -> np.ndarray:
    """(4, 4) Panda pose squeezing the plank at ``x`` across its thickness along world ``closing``
    ("y": pads on the side faces, across the width; "z": pads on the top and bottom faces)."""
    axis = np.array([0.0, 1.0, 0.0]) if closing == "y" else np.array([0.0, 0.0, 1.0])
    centre = np.array([x, 0.0, 0.0])
    half = THICKNESS / 2.0 * axis
    return PANDA.pose_from_contacts(centre + half, centre - half, np.asarray(approach))


def dual(*poses: np.ndarray) -> np.ndarray:
    """(2, 4, 4) the two hands' poses of a dual grasp."""
    return np.stack(poses)
