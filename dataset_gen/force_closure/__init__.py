"""Force closure for four-contact dual-arm grasps: the paper's SOCP, exact and fast.

``evaluate(contact_points, contact_normals, ...)`` is the entry point; see
:mod:`dataset_gen.force_closure.core` for the conventions and a worked example. Its defaults are
the paper's parameters, :data:`dg16m_core.parameters.PAPER`.

Floor 1 of :mod:`dataset_gen`. May import: :mod:`dg16m_core` and this folder (numpy, SciPy,
numba, Clarabel).
"""

from .core import (
    CERTIFICATE_MARGIN,
    CONVENTIONS,
    METHODS,
    SOLVED_CLARABEL,
    SOLVED_CLARABEL_TIGHT,
    SOLVED_FAST,
    SOLVED_NONE,
    ForceClosureResult,
    axis_gravity_wrenches,
    evaluate,
    gravity_wrench,
)
from .geometry import contact_frames, full_rank, grasp_matrix, grasp_quality, project_cone_ball

__all__ = [
    "CERTIFICATE_MARGIN",
    "CONVENTIONS",
    "METHODS",
    "SOLVED_CLARABEL",
    "SOLVED_CLARABEL_TIGHT",
    "SOLVED_FAST",
    "SOLVED_NONE",
    "ForceClosureResult",
    "axis_gravity_wrenches",
    "contact_frames",
    "evaluate",
    "full_rank",
    "grasp_matrix",
    "grasp_quality",
    "gravity_wrench",
    "project_cone_ball",
]
