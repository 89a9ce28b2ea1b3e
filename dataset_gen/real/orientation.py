"""Which way is up: a source mesh's up axis (given, detected or its format's convention) and the
one turn that makes a y-up mesh z up.

dg16m writes and simulates meshes z up (gravity along -z). Other applications write y up (OBJ by
convention: Sweet Home 3D, Blender's default export; glTF by its specification, and trimesh reads
its coordinates as they are) or z up (STL, PLY, OFF, 3MF). ``dg16m objects repair`` turns every
source z up (:func:`up_axis`, :func:`turn_z_up`); the Sweet Home 3D importer uses the same
:data:`Y_UP_TO_Z_UP`; ``objects check`` reports the axis it assumed, and ``benchmark build
--meshes`` says which files may be y up (:func:`build_up_note`).
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from dataset_gen.objects.grasp_object import MESH_SUFFIXES
from dg16m_core.errors import MeshError

UP_AXES = ("y", "z")
"""The up axes a mesh file can have (``--up``); ``"auto"`` decides per file."""
"""Up axes a source mesh may have; dg16m writes and simulates meshes z up."""

Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""Rotation by +90 degrees about x (right-handed, det +1): a y-up point ``(x, y, z)`` becomes
``(x, -z, y)``, so the source's up (``+y``) becomes ``+z`` and its front (``+z``, towards the
viewer in y-up applications) becomes ``-y``. Applied as ``vertices @ Y_UP_TO_Z_UP.T``."""


def turn_z_up(mesh: trimesh.Trimesh, up: str) -> trimesh.Trimesh:
    """``mesh`` with its up axis ``up`` (``"y"`` or ``"z"``) turned to ``+z``: a copy turned by
    :data:`Y_UP_TO_Z_UP` for ``"y"`` (a rotation: volumes, normals and winding are kept), the
    mesh itself for ``"z"``. Lengths in the mesh's units.

    Raises:
        MeshError: ``up`` is not one of :data:`UP_AXES`.
    """
    if up not in UP_AXES:
        raise MeshError(f"--up: expected one of {', '.join(UP_AXES)}, found {up!r}")
    if up == "z":
        return mesh
    vertices = np.asarray(mesh.vertices, dtype=np.float64) @ Y_UP_TO_Z_UP.T
    return trimesh.Trimesh(vertices, np.asarray(mesh.faces), process=False)


UP_CHOICES = ("auto", *UP_AXES)
"""What ``--up`` takes: ``auto`` (:func:`up_axis`), or the source's up axis."""

UP_CONVENTIONS: Mapping[str, tuple[str, str]] = {
    ".obj": ("y", "OBJ files are y up by convention"),
    ".glb": ("y", "glTF is y up by its specification"),
    ".gltf": ("y", "glTF is y up by its specification"),
    ".dae": ("y", "COLLADA is y up unless its <up_axis> says otherwise"),
    ".stl": ("z", "STL files are z up by convention (CAD, 3D printing)"),
    ".ply": ("z", "PLY files are z up by convention (scans, CAD)"),
    ".off": ("z", "OFF files are z up by convention"),
    ".3mf": ("z", "3MF is z up by its specification"),
}
"""The up axis ``--up auto`` assumes per suffix, and why."""

DG16M_KINDS = ("mesh-repair", "sweethome3d-import", "objects")
"""Manifest kinds of folders whose meshes dg16m wrote (z up)."""


@dataclass(frozen=True)
class UpAxis:
    """A source mesh's up axis.

    Attributes:
        axis: ``"y"`` or ``"z"`` (:data:`~dataset_gen.real.orientation.UP_AXES`).
        how: ``"given"`` (``--up y|z``), ``"detected"`` (written by dg16m, or a COLLADA
            ``<up_axis>``) or ``"assumed"`` (the format's convention).
        why: the reason, in words.
    """

    axis: str
    how: str
    why: str

    def note(self) -> str:
        """One line for people: the axis, why, and what was done with it."""
        turned = "turned z up (+90 deg about x)" if self.axis == "y" else "kept z up"
        other = "z" if self.axis == "y" else "y"
        hint = f"; pass --up {other} if wrong" if self.how == "assumed" else ""
        return f"up axis {self.axis} ({self.how}: {self.why}{hint}), {turned}"

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "note": self.note()}


def up_axis(path: Path, up: str = "auto") -> UpAxis:
    """The up axis of the mesh file ``path``: ``up`` when it is ``"y"`` or ``"z"``; for ``"auto"``,
    ``z`` for a mesh dg16m wrote (an OBJ whose header comment names dg16m, or a file in a folder
    whose ``manifest.json`` has a kind of :data:`DG16M_KINDS`), a COLLADA file's own
    ``<up_axis>``, else the format's convention (:data:`UP_CONVENTIONS`: OBJ and glTF y up;
    STL, PLY, OFF and 3MF z up).

    Raises:
        MeshError: ``up`` is not one of :data:`UP_CHOICES`.
    """
    if up not in UP_CHOICES:
        raise MeshError(f"--up: expected one of {', '.join(UP_CHOICES)}, found {up!r}")
    if up != "auto":
        return UpAxis(up, "given", f"--up {up}")
    suffix = path.suffix.lower()
    origin = written_by_dg16m(path)
    if origin is not None:
        return UpAxis("z", "detected", f"{origin}, z up")
    if suffix == ".dae":
        found = re.search(r"<up_axis>\s*([XYZ])_UP\s*</up_axis>", _head(path))
        if found and found.group(1) != "X":
            axis = found.group(1).lower()
            return UpAxis(axis, "detected", f"its <up_axis> is {found.group(1)}_UP")
    axis, why = UP_CONVENTIONS.get(suffix, ("z", f"{suffix or 'suffix-less'} files: z up"))
    return UpAxis(axis, "assumed", why)


def build_up_note(folder: str | Path) -> str:
    """What ``benchmark build --meshes folder`` does with the up axis, for people: it reads every
    file z up, and names the files that :func:`up_axis` (``auto``) takes for y up."""
    root = Path(folder)
    files = sorted(p for p in root.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
    axes = [(p, up_axis(p)) for p in files]
    y_up = [(p, a) for p, a in axes if a.axis == "y"]
    if not y_up:
        return f"up axis: every mesh read z up ({len(files)} meshes)"
    names = ", ".join(p.name for p, _ in y_up[:3]) + (", ..." if len(y_up) > 3 else "")
    why = "; ".join(sorted({a.why for _, a in y_up}))
    return (
        f"up axis: every mesh read z up; {len(y_up)} of {len(files)} may be y up ({names}: "
        f"{why}), and if so lie on their side: 'dg16m objects repair {root} --out REPAIRED' "
        "turns y-up files z up (--up z keeps z-up ones), then build from REPAIRED"
    )


def written_by_dg16m(path: Path) -> str | None:
    """Where dg16m wrote the mesh file ``path`` (z up, in metres), in words, or ``None``: a file
    in a folder whose ``manifest.json`` has a kind of :data:`DG16M_KINDS`, or an OBJ whose
    header comment names dg16m (what ``objects repair`` writes)."""
    kind = _dg16m_folder_kind(path.parent)
    if kind is not None:
        return f"a folder written by dg16m ({kind})"
    if path.suffix.lower() == ".obj":
        lines = _head(path, 1024).splitlines()[:5]
        if any(line.startswith("#") and "dg16m" in line for line in lines):
            return "written by dg16m"
    return None


def _head(path: Path, size: int = 4096) -> str:
    """The first ``size`` bytes of ``path`` as text (empty when unreadable)."""
    try:
        with path.open("rb") as file:
            return file.read(size).decode("utf-8", errors="replace")
    except OSError:
        return ""


def _dg16m_folder_kind(folder: Path) -> str | None:
    """The kind of ``folder/manifest.json`` when dg16m wrote it (:data:`DG16M_KINDS`), else None."""
    manifest = folder / "manifest.json"
    if not manifest.is_file():
        return None
    try:
        kind = json.loads(manifest.read_text("utf-8")).get("kind")
    except (OSError, ValueError, AttributeError):
        return None
    return kind if kind in DG16M_KINDS else None
