"""Test helpers shared by the trial tests: a plank with one exact convex part, Panda hand poses
that squeeze it, and the dual grasps the tests judge (importable from tests/ as ``planks``)."""

from __future__ import annotations

import numpy as np
import trimesh

from dataset_gen.grasps.gripper import PANDA
from dataset_gen.objects.grasp_object import ConvexPart, GraspObject, make_object

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


def finger_inside(pose: np.ndarray) -> np.ndarray:
    """``pose`` moved 0.04 m along its closing axis: the open finger 1 (inner face at -0.04 m,
    0.02 m thick) then lies inside the 0.04 m thick plank."""
    moved = pose.copy()
    moved[:3, 3] += 0.04 * moved[:3, 0]
    return moved


SHORT_PLANK = (0.6, 4.0, "short_plank")  # length (m), mass (kg), id
LONG_PLANK = (1.0, 6.0, "long_plank")

# Both ends squeezed, each hand 0.05 m from an end, closing across the 0.04 m thickness.
HOLD_FROM_ABOVE = dual(hand(-0.25, "y", DOWN), hand(0.25, "y", DOWN))
HOLD_FROM_SIDE = dual(hand(-0.25, "z", SIDE), hand(0.25, "z", SIDE))

# Long heavy plank, both hands near one end, 0.1 m apart (0.45 and 0.35 m from the centre):
# gravity's torque about the grasp is 6 kg * 10 m/s^2 * 0.4 m = 24 N m.
#
# Closing vertically (pads on the top and bottom faces, approach from the side), as first asked:
# the couple has to come from the two hands pushing the plank up and down, i.e. from driving the
# fingers of one hand backwards along their closing axis against the 70 N squeeze (measured: the
# fingers of the inner hand are pushed open and the plank pivots about the outer hand, 8.4 deg
# by the end of the gravity phase, 11.3-12.6 deg in force+x for hands 0.43-0.47 m out, then it
# jams at ~14.4 deg). It does fail, but only by a few degrees past max_rotation_deg (10).
FAIL_VERTICAL = dual(hand(0.45, "z", SIDE), hand(0.35, "z", SIDE))
# Closing horizontally (pads on the side faces, approach from above) the same torque acts about
# the closing axis: only pad friction (at most ~0.4 * 140 N per hand, 0.1 m apart: ~6 N m) and
# torsional friction resist it, so this cannot hold at all (measured: ~44 deg in the gravity phase).
FAIL_HORIZONTAL = dual(hand(0.45, "y", DOWN), hand(0.35, "y", DOWN))
