"""Where objects come from: mesh files or procedural ``(family, seed)`` specs, and their seeds.

An :class:`ObjectSource` names one object and builds it on demand (in a worker process, so only
the source crosses process boundaries). :func:`object_seed` derives each object's random stream
from a global seed and the object id alone, which makes every per-object result independent of
the worker count, order and backend. Used by the generator and the simulation benchmark.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dataset_gen.objects.grasp_object import (
    MESH_SUFFIXES,
    GraspObject,
    clean_mesh,
    load_object,
    make_object,
)
from dataset_gen.sources.procedural import make_procedural_object
from dg16m_core.arguments import listed_ids
from dg16m_core.errors import MeshError


@dataclass(frozen=True)
class ObjectSource:
    """Where one object comes from: a mesh file or a procedural (family, seed).

    ``scale`` and ``allow_any_size`` apply to mesh files (see
    :func:`~dataset_gen.objects.grasp_object.load_object`): a file whose scaled size is implausible for a
    dual-arm object fails to load unless ``allow_any_size``.

    ``mesh_arrays`` ((V, 3) float64 vertices, (F, 3) faces, as
    :func:`~dataset_gen.objects.grasp_object.read_mesh_arrays` reads the file) stand in for the file (a
    benchmark that carries its meshes, whose hashes it checks on reading); ``mesh.name`` then
    only names the object's file.
    """

    object_id: str
    mesh: Path | None = None
    family: str | None = None
    family_seed: int | None = None
    scale: float | None = None
    allow_any_size: bool = False
    mesh_arrays: tuple[np.ndarray, np.ndarray] | None = field(
        default=None, compare=False, repr=False
    )

    def load(self, mass: float) -> GraspObject:
        """Build the object (raises :class:`~dg16m_core.errors.MeshError` for broken meshes)."""
        if self.mesh_arrays is not None:
            return self._load_arrays(mass)
        if self.mesh is not None:
            return load_object(
                self.mesh,
                object_id=self.object_id,
                scale=self.scale,
                mass=mass,
                allow_any_size=self.allow_any_size,
            )
        if self.family is None or self.family_seed is None:
            raise MeshError(
                f"{self.object_id}: expected a mesh file or a procedural (family, seed), "
                "found neither"
            )
        return make_procedural_object(self.family, self.family_seed, mass=mass)

    def _load_arrays(self, mass: float) -> GraspObject:
        """The object from ``mesh_arrays``, exactly as :func:`load_object` builds it from the
        file those arrays were read from (clean, scale, centre)."""
        assert self.mesh_arrays is not None
        vertices, faces = self.mesh_arrays
        name = str(self.mesh) if self.mesh is not None else self.object_id
        mesh, report = clean_mesh(vertices, faces, name=name)
        return make_object(
            mesh,
            object_id=self.object_id,
            scale=self.scale,
            mass=mass,
            source=self.mesh,
            cleaning=report,
        )

    @property
    def object_file(self) -> str:
        """The ``object/file`` string stored in the output; for procedural objects the mesh is
        written there, relative to the dataset folder."""
        if self.mesh is not None:
            return self.mesh.name
        return f"meshes/{self.object_id}.obj"


def object_seed(seed: int, object_id: str) -> int:
    """A 64-bit seed for one object from the global seed and its id (sha256, stable everywhere)."""
    digest = hashlib.sha256(f"dg16m:{seed}:{object_id}".encode()).digest()
    return int.from_bytes(digest[:8], "little")


def mesh_sources(
    folder: str | os.PathLike[str],
    *,
    scale: float | None = None,
    allow_any_size: bool = False,
) -> list[ObjectSource]:
    """One source per mesh file in ``folder`` (not recursive), sorted by file name, each loaded
    with ``scale`` and ``allow_any_size``.

    Raises:
        MeshError: the folder does not exist, holds no mesh files, or two files share a stem.
    """
    root = Path(folder)
    if not root.is_dir():
        raise MeshError(f"--meshes: expected a folder of mesh files, found no folder {root}")
    files = sorted(p for p in root.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
    if not files:
        raise MeshError(
            f"--meshes {root}: expected mesh files ({', '.join(sorted(MESH_SUFFIXES))}), found none"
        )
    stems: dict[str, Path] = {}
    for path in files:
        if path.stem in stems:
            raise MeshError(
                f"--meshes {root}: expected unique file stems (object ids), found "
                f"{stems[path.stem].name} and {path.name}"
            )
        stems[path.stem] = path
    return [
        ObjectSource(object_id=p.stem, mesh=p, scale=scale, allow_any_size=allow_any_size)
        for p in files
    ]


def procedural_sources(specs: Sequence[tuple[str, int]]) -> list[ObjectSource]:
    """Sources for procedural ``(family, seed)`` specs (see :mod:`dataset_gen.sources.procedural`)."""
    from dataset_gen.sources.procedural import object_id as procedural_id

    return [
        ObjectSource(object_id=procedural_id(family, seed), family=family, family_seed=seed)
        for family, seed in specs
    ]


def read_ids(text: str, flag: str = "--ids") -> list[str]:
    """Object ids from ``text``: a file (one id per line; ``#`` starts a comment), a JSON file
    and a key holding a list of ids (``split.json:train``, e.g. the real benchmark's shipped
    split file), or ``a,b,c``. ``flag`` names the option in messages.

    Raises:
        MeshError: no id in it, or a JSON key that is not a list of ids.
    """
    import json

    path = Path(text)
    file, _, key = text.rpartition(":")
    if not path.is_file() and file.endswith(".json") and Path(file).is_file():
        try:
            value = json.loads(Path(file).read_text("utf-8")).get(key)
        except (ValueError, AttributeError) as exc:
            raise MeshError(f"{flag} {text}: expected a JSON object, found {exc}") from None
        if not isinstance(value, list) or not all(isinstance(i, str) for i in value):
            raise MeshError(
                f"{flag} {text}: expected key {key!r} to hold a list of ids, found "
                f"{type(value).__name__}"
            )
        ids = [i for i in value if i]
    else:
        ids = listed_ids(text, path if path.is_file() else None)
    if not ids:
        raise MeshError(f"{flag} {text}: expected object ids (a file of ids or a,b,c), found none")
    return ids


def select_sources(sources: Sequence[ObjectSource], ids: Sequence[str]) -> list[ObjectSource]:
    """The sources of ``ids``, in that order.

    Raises:
        MeshError: an id twice, or ids with no source (named, with an example of the known).
    """
    by_id = {s.object_id: s for s in sources}
    unknown = [i for i in ids if i not in by_id]
    if unknown:
        example = next(iter(by_id), "?")
        raise MeshError(
            f"--ids: expected ids of the mesh folder's files (e.g. {example!r}), found "
            f"{len(unknown)} unknown: {', '.join(unknown[:5])}"
        )
    if len(set(ids)) != len(ids):
        twice = next(i for i in ids if list(ids).count(i) > 1)
        raise MeshError(f"--ids: expected each id once, found {twice!r} twice")
    return [by_id[i] for i in ids]
