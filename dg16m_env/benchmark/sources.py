"""Where a benchmark's objects come from: :class:`BenchmarkSource` (an object, optionally with a
DG16M file of its grasps), the procedural split, a folder of the user's meshes, a folder of DG16M
files (:func:`file_benchmark_sources`), splits by name (:func:`read_split`), and the move of a
file's poses to the Panda hand (:func:`retarget_poses`, :func:`file_poses`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dataset_gen.grasps.gripper import get_gripper
from dataset_gen.io import (
    DualGraspSet,
    read_dg16m,
)
from dataset_gen.objects.grasp_object import (
    MESH_SUFFIXES,
    check_mesh_folder,
)
from dataset_gen.sources.object_source import (
    ObjectSource,
    mesh_sources,
    procedural_sources,
    read_ids,
)
from dataset_gen.sources.procedural import benchmark_specs
from dg16m_core.errors import Dg16mError, MeshError
from dg16m_env.benchmark.model import BenchmarkError

# --------------------------------------------------------------------------------------------
# Building one object
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BenchmarkSource:
    """One object to benchmark: where it comes from, and optionally a DG16M file of its grasps.

    Attributes:
        source: the object (procedural or mesh file).
        grasp_file: a DG16M file (release schema) whose pairs are simulated instead of sampling.
        grasp_gripper: the gripper whose frame the file's poses use (the release: robotiq_2f85;
            files written by dg16m record theirs); poses are moved so that their contacts sit at
            the Panda hand's contact depth.
        reseat_max: re-seating limit (m; 0 = off, the default): each open hand deeper in the
            object than the protocol's ``invalid_penetration`` is moved back along its approach
            axis up to this far until it clears (:func:`dg16m_env.physics.reseat.reseat_poses`). Meant
            for DG16M files made for another gripper; it changes the grasp, and every shift is
            stored and reported. Recorded per object (``objects/reseat_max``).
    """

    source: ObjectSource
    grasp_file: Path | None = None
    grasp_gripper: str | None = None
    reseat_max: float = 0.0

    def __post_init__(self) -> None:
        value = self.reseat_max
        if not (isinstance(value, (int, float)) and np.isfinite(value) and value >= 0):
            raise BenchmarkError(
                f"{self.object_id}: reseat_max: expected a finite number >= 0 m, found {value!r}"
            )

    @property
    def object_id(self) -> str:
        return self.source.object_id


def retarget_poses(poses: np.ndarray, from_gripper: str, to_gripper: str = "panda") -> np.ndarray:
    """Move grasp poses along their approach axis so that contacts made at ``from_gripper``'s
    contact depth sit at ``to_gripper``'s (both in the dg16m grasp frame; (..., 4, 4), m)."""
    shift = get_gripper(from_gripper).contact_depth - get_gripper(to_gripper).contact_depth
    out = np.array(poses, dtype=np.float64, copy=True)
    out[..., :3, 3] += shift * out[..., :3, 1]
    return out


def file_gripper(data: DualGraspSet, gripper: str | None = None) -> str:
    """The gripper whose frame a DG16M file's poses use: ``gripper`` when given, else the one the
    file records, else robotiq_2f85 (the release's)."""
    return gripper or data.metadata.get("gripper", "robotiq_2f85")


def file_poses(data: DualGraspSet, rows: np.ndarray, gripper: str | None = None) -> np.ndarray:
    """(len(rows), 2, 4, 4) the Panda hand poses of a DG16M file's pairs ``rows``: the file's
    poses moved from :func:`file_gripper`'s frame to the Panda's (:func:`retarget_poses`)."""
    return retarget_poses(data.grasps[rows], file_gripper(data, gripper))


# --------------------------------------------------------------------------------------------
# Building many objects
# --------------------------------------------------------------------------------------------


def procedural_benchmark_sources(limit: int | None = None) -> list[BenchmarkSource]:
    """The 300 procedural benchmark objects (the first ``limit`` when given)."""
    specs = benchmark_specs()
    if limit is not None:
        if limit < 1:
            raise BenchmarkError(f"--limit: expected an integer >= 1, found {limit}")
        specs = specs[:limit]
    return [BenchmarkSource(s) for s in procedural_sources(specs)]


def read_split(split: str) -> list[str]:
    """Object ids from a split (:func:`dataset_gen.sources.object_source.read_ids`): a text file (one id per
    line, ``#`` comments), a JSON file's list (``split.json:key``) or ``a,b,c``."""
    try:
        return read_ids(split, flag="--split")
    except MeshError as exc:
        raise BenchmarkError(str(exc)) from None


def split_id(name: str) -> str:
    """An object id from a split entry: a file stem (``couch``) or a file name (``couch.obj``,
    ``couch.h5``, any mesh suffix) gives the stem; other dots are kept (``table-1.5``)."""
    path = Path(name.strip())
    if path.suffix.lower() in {*MESH_SUFFIXES, ".h5"}:
        return path.stem
    return path.name


def _split_ids(split: Sequence[str]) -> list[str]:
    ids = [split_id(s) for s in split]
    repeated = sorted({i for i in ids if ids.count(i) > 1})
    if repeated:
        raise BenchmarkError(f"--split: expected each object once, found {repeated} repeated")
    return ids


def _mesh_sources(
    meshes: str | os.PathLike[str], scale: float | None, allow_any_size: bool
) -> list[ObjectSource]:
    try:
        check_mesh_folder(meshes)
        return mesh_sources(meshes, scale=scale, allow_any_size=allow_any_size)
    except Dg16mError as exc:
        raise BenchmarkError(str(exc)) from None


def mesh_benchmark_sources(
    meshes: str | os.PathLike[str],
    split: Sequence[str] | None = None,
    *,
    scale: float | None = None,
    allow_any_size: bool = False,
    reseat_max: float = 0.0,
) -> list[BenchmarkSource]:
    """Sources for a folder of the user's meshes without grasp files: each mesh file is an
    object (id = file stem) whose pairs are sampled, paired and checked like the procedural
    ones (:func:`~dg16m_env.benchmark.arms.sampled_pairs`).

    Args:
        meshes: folder of mesh files (:data:`~dataset_gen.objects.grasp_object.MESH_SUFFIXES`).
        split: the object ids to take, in this order (stems or file names); default all.
        scale: factor applied to the files' coordinates (default: the files are in metres).
        allow_any_size: accept objects whose longest side is outside the dual-arm range.
        reseat_max: re-seating limit (m, see :class:`BenchmarkSource`; 0 = off).

    Raises:
        BenchmarkError: no folder, no mesh files in it, or a split id without a mesh.
    """
    by_stem = {s.object_id: s for s in _mesh_sources(meshes, scale, allow_any_size)}
    ids = _split_ids(split) if split is not None else list(by_stem)
    missing = [i for i in ids if i not in by_stem]
    if missing:
        raise BenchmarkError(
            f"--split: expected a mesh file for each id in {meshes}, found none for {missing} "
            f"(the folder holds {sorted(by_stem)})"
        )
    return [BenchmarkSource(by_stem[i], reseat_max=reseat_max) for i in ids]


def grasp_folders(
    grasps: str | os.PathLike[str], meshes: str | os.PathLike[str] | None = None
) -> tuple[Path, Path]:
    """The folders of DG16M files and of meshes for ``--grasps`` / ``--meshes``: ``grasps`` is
    either a folder of ``<id>.h5`` files or a folder written by ``dg16m generate`` (it holds
    ``grasps/<id>.h5``, ``manifest.json`` and, for procedural objects, ``meshes/``, used when
    ``meshes`` is not given).

    Raises:
        BenchmarkError: ``grasps`` is no folder or holds no DG16M files, or no mesh folder is
            given or found.
    """
    root = Path(grasps)
    if not root.is_dir():
        raise BenchmarkError(f"--grasps: expected a folder of DG16M files, found no folder {root}")
    grasp_dir = root
    if not any(root.glob("*.h5")) and (root / "grasps").is_dir():
        grasp_dir = root / "grasps"
    if not any(grasp_dir.glob("*.h5")):
        raise BenchmarkError(
            f"--grasps {root}: expected DG16M files <id>.h5 (or a 'dg16m generate' folder with "
            "grasps/<id>.h5), found none"
        )
    if meshes is not None:
        return grasp_dir, Path(meshes)
    if grasp_dir != root and (root / "meshes").is_dir():
        return grasp_dir, root / "meshes"
    raise BenchmarkError(
        f"--grasps {root}: expected --meshes (the objects' mesh files) or a meshes/ folder "
        "beside its grasps/, found neither"
    )


def file_benchmark_sources(
    meshes: str | os.PathLike[str] | None,
    grasps: str | os.PathLike[str],
    split: Sequence[str] | None = None,
    *,
    grasp_gripper: str | None = None,
    reseat_max: float = 0.0,
) -> list[BenchmarkSource]:
    """Sources for a user's meshes and DG16M files: ``<id>.h5`` pairs with the mesh whose
    file name its ``object/file`` names (or ``<id>.*``). ``grasps`` and ``meshes`` are resolved
    by :func:`grasp_folders` (a ``dg16m generate`` folder works; ``meshes`` may then be
    ``None``); ``split`` ids may be stems or file names; ``reseat_max``: see
    :class:`BenchmarkSource`. Each file's ``object/scale`` is the mesh's scale."""
    grasp_dir, mesh_dir = grasp_folders(grasps, meshes)
    by_stem = {s.object_id: s for s in _mesh_sources(mesh_dir, None, False)}
    by_name = {s.mesh.name: s for s in by_stem.values() if s.mesh is not None}
    files = sorted(grasp_dir.glob("*.h5"))
    ids = _split_ids(split) if split is not None else [p.stem for p in files]
    out = []
    for object_id in ids:
        grasp_file = grasp_dir / f"{object_id}.h5"
        if not grasp_file.is_file():
            raise BenchmarkError(f"{object_id}: expected grasp file {grasp_file}, found none")
        named = Path(read_dg16m(grasp_file).object_file).name
        source = by_name.get(named) or by_stem.get(object_id)
        if source is None:
            raise BenchmarkError(
                f"{object_id}: expected its mesh {named!r} (or {object_id}.*) in {mesh_dir}, "
                "found none"
            )
        source = replace(source, object_id=object_id)
        out.append(
            BenchmarkSource(
                source, grasp_file=grasp_file, grasp_gripper=grasp_gripper, reseat_max=reseat_max
            )
        )
    return out
