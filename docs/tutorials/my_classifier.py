"""A toy dual-grasp classifier: prefer pairs whose hands are far apart."""

from typing import Any

import numpy as np


def score(observation: dict[str, Any], poses: np.ndarray) -> np.ndarray:
    # poses: (N, 2, 4, 4) every benchmark candidate of one object; return (N,) scores
    return np.linalg.norm(poses[:, 0, :3, 3] - poses[:, 1, :3, 3], axis=1)
