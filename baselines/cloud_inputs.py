"""The inputs of the cloud grasp sampler (:mod:`baselines.cloud_grasps`): the checked point cloud
with normals (:class:`Cloud`, made by :func:`check_cloud`, which refuses a malformed cloud with a
:class:`CloudError` that says what was expected and found) and the sampler's parameters
(:class:`CloudSamplerConfig`; the "module docstring" it refers to is that of
:mod:`baselines.cloud_grasps`). Units: metres, object frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from dataset_gen.grasps.gripper import GripperModel, get_gripper
from dg16m_core.checks import check_fields
from dg16m_core.errors import Dg16mError
from dg16m_core.parameters import PAPER

MIN_POINTS = 16
"""Fewest cloud points accepted (after the mask)."""

NORMAL_TOLERANCE = 1e-3
"""Largest ``| |n| - 1 |`` of an input normal; normals are renormalised after the check."""


class CloudError(Dg16mError, ValueError):
    """A malformed cloud or bad sampler arguments."""


@dataclass(frozen=True)
class Cloud:
    """A checked point cloud with normals (object frame).

    Attributes:
        points: (P, 3) float64 points (m).
        normals: (P, 3) float64 unit outward normals.
        spacing: median distance from a point to its nearest distinct neighbour (m): the
            cloud's resolution.
    """

    points: np.ndarray
    normals: np.ndarray
    spacing: float

    @property
    def n(self) -> int:
        """Number of points P."""
        return int(self.points.shape[0])

    @cached_property
    def tree(self) -> cKDTree:
        """A k-d tree of the points (built once)."""
        return cKDTree(self.points)


def check_cloud(
    points: np.ndarray,
    normals: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    min_points: int = MIN_POINTS,
) -> Cloud:
    """Validate a cloud and keep its real points.

    Args:
        points: (P, 3) float points (m), object frame.
        normals: (P, 3) float unit outward normals at ``points``.
        mask: optional (P,) validity (1 / True = a real point, 0 = padding, as the environments'
            partial observation); padding rows are dropped before any other check.
        min_points: fewest real points accepted.

    Returns:
        The :class:`Cloud` (float64, C-contiguous, normals renormalised).

    Raises:
        CloudError: wrong shapes or dtypes, NaN or infinite values, normals that are not unit
            (``NORMAL_TOLERANCE``), fewer than ``min_points`` points.
    """
    arrays = {}
    for name, value in (("points", points), ("normals", normals)):
        array = np.asarray(value)
        if array.dtype.kind not in "iuf":
            raise CloudError(f"{name}: expected a float array, found dtype {array.dtype}")
        if array.ndim != 2 or array.shape[1] != 3:
            raise CloudError(f"{name}: expected shape (P, 3), found {array.shape}")
        arrays[name] = np.asarray(array, dtype=np.float64)
    pts, nrm = arrays["points"], arrays["normals"]
    if pts.shape != nrm.shape:
        raise CloudError(f"normals: expected the shape of points {pts.shape}, found {nrm.shape}")
    if mask is not None:
        keep = np.asarray(mask)
        if keep.shape != (len(pts),):
            raise CloudError(f"mask: expected shape ({len(pts)},), found {keep.shape}")
        if keep.dtype.kind not in "biuf" or not np.isfinite(keep.astype(np.float64)).all():
            raise CloudError(f"mask: expected finite 0 / 1 values, found dtype {keep.dtype}")
        keep = keep.astype(np.float64) > 0.5
        pts, nrm = pts[keep], nrm[keep]
    for name, array in (("points", pts), ("normals", nrm)):
        bad = np.flatnonzero(~np.isfinite(array).all(axis=1))
        if bad.size:
            raise CloudError(
                f"{name}: expected finite values, found NaN or inf in {bad.size} rows "
                f"(first: row {int(bad[0])})"
            )
    if len(pts) < min_points:
        raise CloudError(f"points: expected at least {min_points} points, found {len(pts)}")
    length = np.linalg.norm(nrm, axis=1)
    off = np.abs(length - 1.0)
    if off.max() > NORMAL_TOLERANCE:
        row = int(np.argmax(off))
        raise CloudError(
            f"normals: expected unit vectors (within {NORMAL_TOLERANCE}), found length "
            f"{length[row]:.4g} at row {row}"
        )
    nrm = nrm / length[:, None]
    return Cloud(np.ascontiguousarray(pts), np.ascontiguousarray(nrm), _spacing(pts))


def _spacing(points: np.ndarray) -> float:
    """Median distance (m) from a point to its nearest distinct neighbour."""
    distance, _ = cKDTree(points).query(points, k=2)
    nearest = distance[:, 1]
    nearest = nearest[nearest > 0.0]
    return float(np.median(nearest)) if nearest.size else 0.0


@dataclass(frozen=True)
class CloudSamplerConfig:
    """Parameters of :func:`~baselines.cloud_grasps.cloud_dual_candidates` (SI units; see the module docstring).

    Attributes:
        mu: friction coefficient; the friction cone's half-angle is ``atan(mu)``.
        n_seeds: first contacts drawn from the cloud (fewer when the cloud is smaller).
        n_approach: approach directions tried per contact pair.
        max_grasps: single-arm grasps kept (the first in seed order).
        max_pairs: dual candidates kept (a seeded uniform subset).
        min_width: smallest contact separation and jaw width (m).
        opening_margin: the jaws must be at least this much narrower than fully open (m).
        tolerance: how far a cloud point may reach into the hand's palm or finger volumes (m).
        clearance_factor: the hand's volumes are grown by this times the cloud's spacing
            (:attr:`Cloud.spacing`) on every side but the fingers' contact faces.
        pad_margin: a contact must lie this far inside its pad's footprint (m).
        min_center_distance: the two grasps' centres at least this far apart (m).
        gripper: a gripper name (:data:`dataset_gen.grasps.gripper.GRIPPERS`).
        enclosing: also sample enclosing grasps (:func:`sample_enclosing_grasps`: the hand
            approaches a point against its normal and closes on whatever lies between its
            fingers), which need only one observed side of a thin part.
        n_enclosing_seeds: points the enclosing grasps approach (fewer when the cloud is
            smaller).
        n_closing: closing-axis directions tried per enclosing seed, evenly spaced over half a
            turn about the approach with a seeded offset.
        enclosing_reach: how far the fingertips pass the approached point (m; at most the pad
            length ``finger_tip - palm_depth``).
        free_space_margin: with depth views (:class:`DepthViews`), a point of the open hand
            counts as seen free when a camera saw a surface at least this much farther along
            its pixel's ray (m; about a pixel's footprint at a metre, 6.5 mm at 128 pixels).
        free_space_fingers: test the open fingers' volumes as well as the palm's (else the
            palm's only: fingers next to a surface sit where a pixel's footprint blurs seen
            and unseen space).
    """

    mu: float = PAPER.mu
    n_seeds: int = 2048
    n_approach: int = 8
    max_grasps: int = 200
    max_pairs: int = 1024
    min_width: float = 1e-3
    opening_margin: float = 1e-3
    tolerance: float = 2e-3
    clearance_factor: float = 1.0
    pad_margin: float = 1e-3
    min_center_distance: float = PAPER.min_center_distance
    gripper: str = "panda"
    enclosing: bool = False
    n_enclosing_seeds: int = 512
    n_closing: int = 6
    enclosing_reach: float = 0.03
    free_space_margin: float = 0.01
    free_space_fingers: bool = True

    def __post_init__(self) -> None:
        check_fields(
            self,
            error=CloudError,
            integers={
                "n_seeds": 1,
                "n_approach": 1,
                "max_grasps": 2,
                "max_pairs": 1,
                "n_enclosing_seeds": 1,
                "n_closing": 1,
            },
            zero_allowed=(
                "tolerance",
                "clearance_factor",
                "pad_margin",
                "opening_margin",
                "min_center_distance",
            ),
            skip=("gripper", "enclosing", "free_space_fingers"),
        )
        for flag in ("enclosing", "free_space_fingers"):
            if not isinstance(getattr(self, flag), bool):
                raise CloudError(
                    f"{flag}: expected a bool, found {type(getattr(self, flag)).__name__}"
                )
        model = get_gripper(self.gripper)
        if self.max_width(model) <= self.min_width:
            raise CloudError(
                f"opening_margin: expected max_opening - opening_margin > min_width "
                f"({self.min_width} m), found {self.max_width(model)} m"
            )
        pad = model.finger_tip - model.palm_depth
        if self.enclosing_reach > pad:
            raise CloudError(
                f"enclosing_reach: expected at most the pad length {pad:.4g} m, found "
                f"{self.enclosing_reach} m"
            )

    def max_width(self, model: GripperModel) -> float:
        """The widest jaw opening a grasp may use (m)."""
        return model.max_opening - self.opening_margin


__all__ = [
    "MIN_POINTS",
    "NORMAL_TOLERANCE",
    "Cloud",
    "CloudError",
    "CloudSamplerConfig",
    "check_cloud",
]
