"""ACRONYM grasp files: single-arm Panda grasps with FleX labels, read and converted to our frame.

ACRONYM grasp files (read only)
-------------------------------
=============================================  =========  ========================================
key                                            shape      meaning
=============================================  =========  ========================================
``grasps/transforms``                          (N, 4, 4)  Panda grasp poses, object mesh frame (m);
                                                          ACRONYM frame: x = closing, z = approach
``grasps/qualities/flex/object_in_gripper``    (N,)       1 when the FleX trial held the object
``grasps/qualities/flex/<other>``              (N,)       other FleX measurements (optional)
``object/file``, ``object/scale``              ()         mesh file and its scale
``object/mass``, ``object/com``                (), (3,)   optional: kg, m
``gripper/type``, ``gripper/configuration``    (), (K,)   optional: e.g. ``"panda"``, opening (m)
=============================================  =========  ========================================

``T_dg16m = T_acronym @ ACRONYM_TO_DG16M``: our x = ACRONYM x, our y = ACRONYM z (approach),
our z = x × y = ACRONYM -y; the origin is unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dg16m_core.errors import GraspFileError

from ._checks import (
    PathLike,
    _as_array,
    _assign,
    _check_finite,
    _check_object_file,
    _check_positive,
    _check_rigid,
    _check_shape,
    _frozen,
)
from ._hdf5 import (
    _check_dataset,
    _check_present,
    _read_numeric,
    _read_scalar,
    _read_string,
    open_hdf5,
)

ACRONYM_REQUIRED_KEYS = (
    "grasps/transforms",
    "grasps/qualities/flex/object_in_gripper",
    "object/file",
    "object/scale",
)
"""Datasets :func:`read_acronym` needs."""

_ACRONYM_FLEX = "grasps/qualities/flex"

ACRONYM_TO_DG16M = np.array(
    [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, -1.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]
)
"""(4, 4) rotation C with ``T_dg16m = T_acronym @ C``. Its columns are our axes written in the
ACRONYM gripper frame: x = (1, 0, 0), y = (0, 0, 1) (ACRONYM approach), z = x × y = (0, -1, 0)."""
ACRONYM_TO_DG16M.setflags(write=False)


def acronym_to_dg16m(transforms: np.ndarray) -> np.ndarray:
    """Convert (..., 4, 4) ACRONYM Panda grasp poses to the dg16m grasp frame.

    ``T_dg16m = T_acronym @ ACRONYM_TO_DG16M``: the closing axis (x) and the origin are kept, the
    approach axis moves from z to y. Returns a new float64 array of the same shape.
    """
    T = np.asarray(transforms, dtype=np.float64)
    if T.ndim < 2 or T.shape[-2:] != (4, 4):
        raise ValueError(f"transforms: expected shape (..., 4, 4), found {T.shape}")
    return T @ ACRONYM_TO_DG16M


def dg16m_to_acronym(transforms: np.ndarray) -> np.ndarray:
    """Inverse of :func:`acronym_to_dg16m`: (..., 4, 4) dg16m grasp poses to ACRONYM's frame."""
    T = np.asarray(transforms, dtype=np.float64)
    if T.ndim < 2 or T.shape[-2:] != (4, 4):
        raise ValueError(f"transforms: expected shape (..., 4, 4), found {T.shape}")
    return T @ ACRONYM_TO_DG16M.T


@dataclass(frozen=True, eq=False, repr=False)
class AcronymGrasps:
    """Single-arm Panda grasps of one object from an ACRONYM file, validated.

    Attributes:
        transforms_acronym: (N, 4, 4) float64 raw ACRONYM poses, gripper to object mesh frame
            (m); ACRONYM gripper frame: x = closing axis, z = approach axis.
        success: (N,) bool FleX label ``object_in_gripper``.
        object_file: mesh path as stored (relative to the ACRONYM root).
        object_scale: scale applied to the mesh file (positive).
        object_mass: kg, or None when absent.
        object_com: (3,) float64 centre of mass in the scaled mesh frame (m), or None.
        gripper_type: e.g. ``"panda"``, or None.
        gripper_configuration: (K,) float64 gripper opening parameters (m), or None.
        qualities: every (N,) dataset under ``grasps/qualities/flex`` as float64, by name.
        transforms: (N, 4, 4) float64 the same poses in the dg16m grasp frame (computed:
            ``transforms_acronym @ ACRONYM_TO_DG16M``; x = closing, y = approach).
    """

    transforms_acronym: np.ndarray
    success: np.ndarray
    object_file: str
    object_scale: float
    object_mass: float | None = None
    object_com: np.ndarray | None = None
    gripper_type: str | None = None
    gripper_configuration: np.ndarray | None = None
    qualities: dict[str, np.ndarray] = field(default_factory=dict)
    transforms: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        key = "grasps/transforms"
        T = _as_array(self.transforms_acronym, key, "f", "float")
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise GraspFileError(f"{key}: expected (N, 4, 4), found {T.shape}")
        n = T.shape[0]
        _check_finite(key, T, "grasp")
        T = _frozen(T, np.float64)
        _check_rigid(key, T, "grasp")
        skey = f"{_ACRONYM_FLEX}/object_in_gripper"
        s = _as_array(self.success, skey, "biuf", "0/1 or bool")
        _check_shape(skey, s.shape, (n,), " to match grasps/transforms")
        if s.dtype.kind != "b" and not np.isin(s, (0, 1)).all():
            bad = np.flatnonzero(~np.isin(s, (0, 1)))
            raise GraspFileError(
                f"{skey}: expected 0/1 labels, found {len(bad)} other value(s) "
                f"(first: grasp {int(bad[0])} = {s[bad[0]]!r})"
            )
        success = _frozen(s, bool)
        object_file = _check_object_file("object/file", self.object_file)
        object_scale = _check_positive("object/scale", self.object_scale)
        mass = (
            None if self.object_mass is None else _check_positive("object/mass", self.object_mass)
        )
        com = None
        if self.object_com is not None:
            com = _as_array(self.object_com, "object/com", "iuf", "numeric")
            _check_shape("object/com", com.shape, (3,), "")
            _check_finite("object/com", com.reshape(1, 3), "row")
            com = _frozen(com, np.float64)
        gripper_type = self.gripper_type
        if gripper_type is not None and not isinstance(gripper_type, str):
            raise GraspFileError(f"gripper/type: expected a string, found {gripper_type!r}")
        config = None
        if self.gripper_configuration is not None:
            config = _as_array(
                self.gripper_configuration, "gripper/configuration", "iuf", "numeric"
            )
            if config.ndim != 1:
                raise GraspFileError(f"gripper/configuration: expected (K,), found {config.shape}")
            _check_finite("gripper/configuration", config.reshape(1, -1), "row")
            config = _frozen(config, np.float64)
        qualities: dict[str, np.ndarray] = {}
        for name, value in dict(self.qualities).items():
            qkey = f"{_ACRONYM_FLEX}/{name}"
            q = _as_array(value, qkey, "biuf", "numeric")
            _check_shape(qkey, q.shape, (n,), " to match grasps/transforms")
            qualities[str(name)] = _frozen(q, np.float64)
        converted = _frozen(acronym_to_dg16m(T), np.float64)

        _assign(
            self,
            transforms_acronym=T,
            success=success,
            object_file=object_file,
            object_scale=object_scale,
            object_mass=mass,
            object_com=com,
            gripper_configuration=config,
            qualities=dict(sorted(qualities.items())),
            transforms=converted,
        )

    @property
    def n(self) -> int:
        """Number of grasps N."""
        return int(self.transforms_acronym.shape[0])

    def __repr__(self) -> str:
        return (
            f"AcronymGrasps(n={self.n}, success={int(self.success.sum())}, "
            f"object_file={self.object_file!r}, object_scale={self.object_scale!r}, "
            f"gripper_type={self.gripper_type!r})"
        )


def read_acronym(path: PathLike) -> AcronymGrasps:
    """Read an ACRONYM grasp file (single-arm Panda grasps with FleX labels).

    Raises:
        GraspFileError: not an HDF5 file, required keys missing, wrong dtype or shape, non-finite
            or non-rigid transforms, labels other than 0/1, bad optional fields.
    """
    path = Path(path)
    with open_hdf5(path) as f:
        _check_present(path, f, ACRONYM_REQUIRED_KEYS, "ACRONYM grasp")
        ds = f["grasps/transforms"]
        if len(ds.shape) != 3 or ds.shape[1:] != (4, 4):
            raise GraspFileError(f"{path}: grasps/transforms: expected (N, 4, 4), found {ds.shape}")
        transforms = _read_numeric(path, ds, "f", "float")
        success = _read_numeric(path, f[f"{_ACRONYM_FLEX}/object_in_gripper"], "biuf", "0/1")
        qualities: dict[str, np.ndarray] = {}
        for name in f[_ACRONYM_FLEX]:
            item = _check_dataset(path, f, f"{_ACRONYM_FLEX}/{name}")
            if item.shape != ds.shape[:1]:
                raise GraspFileError(
                    f"{path}: {_ACRONYM_FLEX}/{name}: expected {ds.shape[:1]} to match "
                    f"grasps/transforms, found {item.shape}"
                )
            qualities[name] = _read_numeric(path, item, "biuf", "numeric")
        object_file = _read_string(path, f["object/file"])
        object_scale = _read_scalar(path, f["object/scale"])
        optional: dict[str, Any] = {}
        if "object/mass" in f:
            optional["object_mass"] = _read_scalar(path, _check_dataset(path, f, "object/mass"))
        for key, attr in (
            ("object/com", "object_com"),
            ("gripper/configuration", "gripper_configuration"),
        ):
            if key in f:
                optional[attr] = _read_numeric(path, _check_dataset(path, f, key), "iuf", "numeric")
        if "gripper/type" in f:
            optional["gripper_type"] = _read_string(path, _check_dataset(path, f, "gripper/type"))
    try:
        return AcronymGrasps(
            transforms_acronym=transforms,
            success=success,
            object_file=object_file,
            object_scale=object_scale,
            qualities=qualities,
            **optional,
        )
    except GraspFileError as exc:
        raise GraspFileError(f"{path}: {exc}") from None
