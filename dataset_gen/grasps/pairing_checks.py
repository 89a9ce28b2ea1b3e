"""Input checks of the pairing modules: :class:`PairingError` and the validation of grasp sets,
pair indices, counts, non-negative numbers and random generators.

Shared by :mod:`dataset_gen.grasps.pairing` (candidates, gripper-gripper collision, ablations) and
:mod:`dataset_gen.grasps.pairing_selection` (the selection of stored pairs), with the array types they
annotate with; every check raises :class:`PairingError` with the name of the bad argument.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dataset_gen.grasps.sampling import SingleArmGrasps
from dg16m_core.checks import check_integer, check_number
from dg16m_core.errors import Dg16mError

IntArray = NDArray[np.int64]
FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


class PairingError(Dg16mError, ValueError):
    """Pairing or selection input is malformed (grasp sets, pair indices, parameters)."""


# --------------------------------------------------------------------------------------------
# Validation helpers
# --------------------------------------------------------------------------------------------


def _check_grasps(grasps: object) -> SingleArmGrasps:
    if not isinstance(grasps, SingleArmGrasps):
        raise PairingError(
            f"grasps: expected a dataset_gen.grasps.sampling.SingleArmGrasps, found {type(grasps).__name__}"
        )
    return grasps


def _check_pairs(pairs: object, m: int) -> IntArray:
    """(P, 2) int64 grasp indices in ``[0, m)`` with distinct members."""
    array = np.asarray(pairs)
    if array.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    if array.ndim != 2 or array.shape[1] != 2:
        raise PairingError(f"pairs: expected shape (P, 2), found {array.shape}")
    if not np.issubdtype(array.dtype, np.integer):
        raise PairingError(f"pairs: expected integer grasp indices, found dtype {array.dtype}")
    array = array.astype(np.int64, copy=False)
    bad = (array < 0) | (array >= m)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        raise PairingError(
            f"pairs: expected grasp indices in [0, {m}), found {array[row].tolist()} at row {row}"
        )
    same = array[:, 0] == array[:, 1]
    if same.any():
        row = int(np.flatnonzero(same)[0])
        raise PairingError(
            f"pairs: expected two different grasps per pair, found {array[row].tolist()} at row {row}"
        )
    return array


def _check_nonnegative(name: str, value: float) -> float:
    """A finite number >= 0 (numpy scalars too; not a bool or a string) as a float."""
    return check_number(name, value, allow_zero=True, error=PairingError)


def _check_count(name: str, value: int | None, *, allow_none: bool = False) -> int | None:
    """An integer >= 0 (numpy integers too; not a bool), or None with ``allow_none``."""
    if value is None and allow_none:
        return None
    return check_integer(name, value, minimum=0, error=PairingError)


def _check_rng(rng: object) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise PairingError(
            f"rng: expected a numpy.random.Generator (np.random.default_rng(seed)), found "
            f"{type(rng).__name__}"
        )
    return rng


__all__ = [
    "BoolArray",
    "FloatArray",
    "IntArray",
    "PairingError",
]
