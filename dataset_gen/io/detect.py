"""Which grasp file format a file holds (DG16M release schema or ACRONYM)."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from dg16m_core.errors import GraspFileError

from ._checks import PathLike
from ._hdf5 import open_hdf5


def detect_format(path: PathLike) -> Literal["dg16m", "acronym"]:
    """Which grasp file format ``path`` holds: ``"dg16m"`` (``grasps/grasps``) or ``"acronym"``
    (``grasps/transforms``). Raises :class:`GraspFileError` for anything else."""
    path = Path(path)
    with open_hdf5(path) as f:
        if "grasps/grasps" in f:
            return "dg16m"
        if "grasps/transforms" in f:
            return "acronym"
        found = sorted(f.keys())
    raise GraspFileError(
        f"{path}: expected a DG16M file (grasps/grasps) or an ACRONYM file (grasps/transforms), "
        f"found top-level keys {found}"
    )
