"""The 1,000 ``random_urdfs`` objects of PyPI's ``pybullet`` wheel, sized for two arms.

``pip install pybullet`` installs ``pybullet_data/random_urdfs/NNN/NNN.obj`` (NNN = 000-999):
each a rigid object of five to eight closed convex blobs (some overlapping, some apart: a
union leaves 2-4 separate pieces), a few hundred faces, modelled about 6-10 units across and
shown 0.015 times that (9-15 cm) by their URDF files; zlib licence (Bullet Physics). They are
read from the installed package; nothing is downloaded.

:func:`import_random_urdfs` writes each as ``<out>/random_urdfs-NNN.obj`` in metres, scaled
uniformly to a longest side drawn from :data:`~dataset_gen.real.sweethome3d.SIZE_RANGE_M`
(0.3-1.2 m, seeded by the id: DA2 scaled its ShapeNet objects into that range), with a
``manifest.json`` (kind ``"pybullet-import"``: per object the source file, its sha256, the scale,
the size, the number of separate pieces and the sha256 of the written file). The blobs are
merged by an exact boolean union (manifold3d), so that overlapping ones make one closed volume
and the object's volume and mass properties count each point once; the pieces that stay apart
are kept as one rigid object, as pybullet simulates it. An object whose union is not closed is
recorded as failed with the reason, not repaired. Resumable like every folder of the generator.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from dataset_gen.sources.object_source import object_seed
from dg16m_core.atomic import write_bytes_atomic
from dg16m_core.errors import Dg16mError

from .sweethome3d import SIZE_RANGE_M

IMPORT_KIND = "pybullet-import"
"""The ``kind`` of an import folder's ``manifest.json``."""
LICENCE = "Zlib"
"""The objects' licence (pybullet's data)."""
CREATOR = "Bullet Physics (pybullet_data random_urdfs)"
SOURCE_URL = "https://pypi.org/project/pybullet/"
COUNT = 1000
"""Objects in ``random_urdfs``."""


class PybulletObjectsError(Dg16mError, ValueError):
    """pybullet is not installed, or its data folder is not as expected."""


@dataclass(frozen=True)
class RandomUrdf:
    """One ``random_urdfs`` object: ``object_id`` ``"random_urdfs-NNN"`` and its OBJ file."""

    object_id: str
    path: Path


def data_folder() -> Path:
    """The installed ``pybullet_data/random_urdfs`` folder.

    Raises:
        PybulletObjectsError: pybullet is not installed, or the folder is missing.
    """
    try:
        import pybullet_data
    except ImportError:
        raise PybulletObjectsError(
            "sources: expected the pybullet package for its random_urdfs objects (pip install "
            "pybullet), found it not installed; leave pybullet out of --sources"
        ) from None
    folder = Path(pybullet_data.getDataPath()) / "random_urdfs"
    if not folder.is_dir():
        raise PybulletObjectsError(
            f"sources: expected pybullet's random_urdfs folder at {folder}, found none"
        )
    return folder


def random_urdfs(folder: Path | None = None) -> list[RandomUrdf]:
    """Every ``NNN/NNN.obj`` under ``folder`` (default :func:`data_folder`), sorted by NNN."""
    root = data_folder() if folder is None else Path(folder)
    found = sorted(p for p in root.glob("[0-9][0-9][0-9]/[0-9][0-9][0-9].obj"))
    if not found:
        raise PybulletObjectsError(f"sources: expected NNN/NNN.obj files in {root}, found none")
    return [RandomUrdf(f"random_urdfs-{p.stem}", p) for p in found]


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def import_one(item: RandomUrdf, out: str, seed: int) -> dict[str, Any]:
    """Write one object scaled to its drawn size; returns its manifest entry (``failed`` with
    the reason for a blob that is not one closed volume; never raises for a bad file)."""
    base = {"source": {"file": f"random_urdfs/{item.path.parent.name}/{item.path.name}"}}
    try:
        raw = item.path.read_bytes()
        mesh = trimesh.load(item.path, file_type="obj", force="mesh", process=True)
    except (OSError, ValueError) as exc:
        return {**base, "status": "failed", "files": {}, "error": f"unreadable: {exc}"}
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        return {**base, "status": "failed", "files": {}, "error": "expected faces, found none"}
    try:
        mesh = trimesh.boolean.union(mesh.split(only_watertight=False), engine="manifold")
    except ValueError as exc:  # manifold3d refuses a piece that is not a closed volume
        return {**base, "status": "failed", "files": {}, "error": f"union failed: {exc}"}
    if not mesh.is_watertight or len(mesh.faces) == 0:
        return {
            **base,
            "status": "failed",
            "files": {},
            "error": "expected closed pieces, found a union that is not watertight",
        }
    rng = np.random.default_rng(object_seed(seed, f"pybullet-size:{item.object_id}"))
    longest = float(rng.uniform(*SIZE_RANGE_M))
    scale = longest / float(mesh.extents.max())
    mesh.apply_scale(scale)
    text = mesh.export(file_type="obj", include_normals=False, include_texture=False)
    data = (
        f"# {item.object_id}: pybullet_data random_urdfs ({LICENCE}), scaled x{scale:.6g}\n{text}"
    )
    encoded = data.encode()
    name = f"{item.object_id}.obj"
    write_bytes_atomic(Path(out) / name, encoded)
    return {
        **base,
        "status": "ok",
        "files": {"mesh": name},
        "source_sha256": _sha256(raw),
        "sha256": _sha256(encoded),
        "scale": scale,
        "extents_m": [float(v) for v in mesh.extents],
        "faces": len(mesh.faces),
        "pieces": int(mesh.body_count),
        "licence": LICENCE,
        "creator": CREATOR,
    }


def import_random_urdfs(
    out: str | Path,
    items: Sequence[RandomUrdf],
    *,
    seed: int = 0,
    workers: int = 1,
    progress: bool = True,
    keep_failed: bool = False,
) -> dict[str, Any]:
    """Import ``items`` into ``out`` (resumable: finished objects are skipped, and with
    ``keep_failed`` the failed ones too); returns the manifest (kind :data:`IMPORT_KIND`).

    Raises:
        PybulletObjectsError: ``out`` holds an import made with another seed.
    """
    from dataset_gen.pipeline.parallel import run_resumable

    root = Path(out)
    return run_resumable(
        import_one,
        items,
        (str(root), int(seed)),
        root=root,
        kind=IMPORT_KIND,
        parameters={"seed": int(seed), "size_range_m": list(SIZE_RANGE_M)},
        folders=(".",),
        error=PybulletObjectsError,
        workers=workers,
        progress=progress,
        desc="pybullet",
        keep_failed=keep_failed,
    )
