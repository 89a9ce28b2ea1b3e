"""Rates over benchmark rows with confidence intervals from resampling objects.

Rows of one object are not independent (one geometry, one grasp sampler), so a confidence
interval that resamples rows is too narrow. :func:`object_rate` resamples whole objects with
replacement (a cluster bootstrap) and reports the percentile interval of the pooled rate.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dg16m_core.checks import check_integer
from dg16m_core.errors import Dg16mError


class RateError(Dg16mError, ValueError):
    """Bad input to a rate: shapes that do not match, a bad level or resample count."""


def object_rate(
    values: np.ndarray,
    groups: np.ndarray,
    rows: np.ndarray | None = None,
    n_resamples: int = 2000,
    seed: int = 0,
    *,
    level: float = 0.95,
) -> dict[str, Any]:
    """Mean of ``values`` over ``rows`` with an object-resampled confidence interval.

    Args:
        values: (N,) per-row values (a success probability, a 0/1 label).
        groups: (N,) object index of each row.
        rows: (N,) bool rows to include (default all).
        n_resamples: bootstrap resamples of the objects.
        seed: seed of the resampling.
        level: confidence level of the percentile interval.

    Returns:
        ``{"rate", "ci_low", "ci_high", "rows", "objects"}`` (``rate`` and the bounds are
        ``None`` when no row is included).
    """
    values = np.asarray(values, dtype=np.float64)
    groups = np.asarray(groups)
    rows = np.ones(values.shape, dtype=bool) if rows is None else np.asarray(rows, dtype=bool)
    if values.ndim != 1 or groups.shape != values.shape or rows.shape != values.shape:
        raise RateError(
            f"values, groups, rows: expected three (N,) arrays, found {values.shape}, "
            f"{groups.shape}, {rows.shape}"
        )
    check_integer("n_resamples", n_resamples, minimum=1, error=RateError)
    if not 0.0 < level < 1.0:
        raise RateError(f"level: expected a number in (0, 1), found {level!r}")
    if not rows.any():
        return {"rate": None, "ci_low": None, "ci_high": None, "rows": 0, "objects": 0}
    _, group = np.unique(groups[rows], return_inverse=True)
    sums = np.bincount(group, weights=values[rows])
    counts = np.bincount(group).astype(np.float64)
    rng = np.random.default_rng(seed)
    picks = rng.integers(0, sums.size, size=(n_resamples, sums.size))
    resampled = sums[picks].sum(axis=1) / counts[picks].sum(axis=1)
    tail = (1.0 - level) / 2.0
    low, high = np.quantile(resampled, [tail, 1.0 - tail])
    return {
        "rate": float(sums.sum() / counts.sum()),
        "ci_low": float(low),
        "ci_high": float(high),
        "rows": int(rows.sum()),
        "objects": int(sums.size),
    }
