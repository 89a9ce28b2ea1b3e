"""Old import paths of :mod:`dataset_gen`, kept for one release after the package was laid out
in folders and its kernel became :mod:`dg16m_core` (0.2.0; see ``CHANGELOG.md``): importing one
still works and raises a :class:`DeprecationWarning` that names the new home.

* :data:`MOVED_MODULES`: a module that moved whole (``dataset_gen.gripper`` ->
  ``dataset_gen.grasps.gripper``) is the same module object under its old name.
* :data:`RENAMED_MODULES`: an old module whose name is now a folder's (``dataset_gen.objects``
  is the folder of object modules): the folder's ``__getattr__`` finds the old module's names
  in their new module (``dataset_gen.objects.GraspObject`` ->
  ``dataset_gen.objects.grasp_object.GraspObject``).

The mechanism is the kernel's (:mod:`dg16m_core.compat`); this module is the table.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from dg16m_core import compat
from dg16m_core.compat import REMOVED_IN

__all__ = ["MOVED_MODULES", "REMOVED_IN", "RENAMED_MODULES", "install", "moved_names"]

_D = "dataset_gen"
_K = "dg16m_core"

MOVED_MODULES: dict[str, tuple[str, ...]] = {
    # the kernel: what every package imports
    **{
        f"{_D}.{m}": (f"{_K}.{m}",)
        for m in (
            "errors",
            "checks",
            "atomic",
            "hashing",
            "json_values",
            "budget",
            "stopping",
            "distribution",
            "parameters",
            "figures",
        )
    },
    # objects: meshes, decomposition, mesh queries, ray hits
    f"{_D}.decomposition": (f"{_D}.objects.decomposition",),
    f"{_D}.mesh_queries": (f"{_D}.objects.mesh_queries",),
    f"{_D}.ray_hits": (f"{_D}.objects.ray_hits",),
    # grasps: gripper, sampling, clearance, pairing, selection, robust criterion
    **{
        f"{_D}.{m}": (f"{_D}.grasps.{m}",)
        for m in (
            "gripper",
            "sampling",
            "clearance",
            "pairing",
            "pairing_checks",
            "pairing_selection",
            "robust",
        )
    },
    # sources: procedural library, object folders
    f"{_D}.procedural": (f"{_D}.sources.procedural",),
    f"{_D}.library": (f"{_D}.sources.library",),
    # real meshes: repair, your own folders, Sweet Home 3D
    f"{_D}.repair": (f"{_D}.real.repair",),
    f"{_D}.repair_meshes": (f"{_D}.real.own_meshes",),
    f"{_D}.sweethome3d": (f"{_D}.real.sweethome3d",),
    # pipeline: runs, generate, stats, verify, render
    **{
        f"{_D}.{m}": (f"{_D}.pipeline.{m}",)
        for m in (
            "parallel",
            "generate",
            "stats",
            "verify",
            "verify_choices",
            "verify_contacts",
            "verify_report",
            "render",
        )
    },
    # cli: the generator's subcommands
    f"{_D}.commands": (f"{_D}.cli.objects", f"{_D}.cli.files"),
    f"{_D}.generate_command": (f"{_D}.cli.generate",),
    f"{_D}.verify_command": (f"{_D}.cli.verify",),
}
"""Old module name -> its new module(s); a name is looked up in them in order."""

RENAMED_MODULES: dict[str, str] = {
    f"{_D}.objects": f"{_D}.objects.grasp_object",
    f"{_D}.sources": f"{_D}.sources.object_source",
    f"{_D}.cli": f"{_K}.cli",
}
"""Old module whose name is now a folder's -> the module that holds its names."""


def moved_names(module: str) -> Callable[[str], Any]:
    """The ``__getattr__`` of the folder ``module`` (a key of :data:`RENAMED_MODULES`): the old
    module's names, with a :class:`DeprecationWarning`."""
    return compat.moved_names(module, RENAMED_MODULES[module])


def install() -> None:
    """Put the finder of the old module names on ``sys.meta_path`` (once)."""
    compat.install(MOVED_MODULES)
