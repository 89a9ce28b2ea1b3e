"""Exceptions raised by dg16m for bad input.

Every error says what was expected and what was found, and names the file it came from. The
command line turns these into a one-line message and exit status 2; anything else is a bug and
keeps its traceback.
"""

from __future__ import annotations


class Dg16mError(Exception):
    """Base class for errors caused by the user's input (files, arguments, data)."""


class MeshError(Dg16mError, ValueError):
    """A mesh file could not be loaded, or its geometry is unusable for grasping."""


class GraspFileError(Dg16mError, ValueError):
    """A grasp file (DG16M release schema, ACRONYM, manifest) is missing, malformed or inconsistent."""


class GripperError(Dg16mError, ValueError):
    """A gripper name or a gripper pose is invalid."""


class ForceClosureError(Dg16mError, ValueError):
    """Force-closure input is malformed (shapes, NaN, zero normals, bad parameters)."""


class SolverError(Dg16mError, RuntimeError):
    """A convex solver ended without a usable solution (a status other than solved)."""
