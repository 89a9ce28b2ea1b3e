"""Convex decomposition: CoACD's old settings against dg16m's defaults, in the same run.

For each mesh, on one core and without the cache:

* old: CoACD's own ``preprocess_mode="auto"`` (it voxel-remeshes meshes it calls non-manifold,
  including watertight ones that trimesh and manifold3d accept) at threshold 0.05, the settings
  dg16m used before;
* new: :class:`dataset_gen.objects.decomposition.DecompositionParameters` defaults (our "auto": the voxel
  repair only for meshes that are not a volume; the default threshold).

Prints faces, watertightness, then per setting the hull count, the one-sided hull-to-mesh
deviation (p95 and max, mm; :func:`dataset_gen.objects.decomposition.decomposition_report`), the extra
volume and the time, and the time ratio new/old. Meshes are loaded as dg16m loads them (object
frame); a mesh next to a grasp file of the same stem (``NAME.h5``, DG16M or ACRONYM) gets that
file's scale, as ``dg16m sim`` does.

    .venv/bin/python bench/decomposition.py               # tests/data/meshes + shared real meshes
    .venv/bin/python bench/decomposition.py --meshes ../tmp/realm --json runs/decomposition.json
    .venv/bin/python bench/decomposition.py --meshes tests/data/meshes/couch.obj --threshold 0.02
"""

from __future__ import annotations

import os

# One core: no OpenMP (CoACD), BLAS or numba threads (set before they are imported).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dataset_gen.objects import decomposition as dec
from dataset_gen.objects.grasp_object import MESH_SUFFIXES, load_object
from dg16m_core.atomic import write_json_atomic
from dg16m_core.errors import Dg16mError
from dg16m_core.json_values import json_ready

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_FOLDERS = (ROOT / "tests" / "data" / "meshes", ROOT.parent / "shared" / "data" / "real")
OLD_THRESHOLD = 0.05
"""The threshold dg16m used with CoACD's own preprocessing before the defaults were measured."""


@dataclass
class Arguments:
    meshes: list[str] = field(default_factory=list)
    threshold: float = dec.DEFAULT_THRESHOLD
    samples: int = 20000
    json: str | None = None


class UsageError(Dg16mError, ValueError):
    """Bad arguments (reported in one line, exit status 2)."""


def parse(argv: list[str] | None = None) -> Arguments:
    defaults = Arguments()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--meshes",
        nargs="+",
        default=[],
        help="mesh files or folders (default: the OBJ files of tests/data/meshes and "
        "../shared/data/real, those present)",
    )
    parser.add_argument(
        "--threshold",
        type=float,
        default=defaults.threshold,
        help=f"new settings' threshold (default: {defaults.threshold:g}, the library's)",
    )
    parser.add_argument(
        "--samples", type=int, default=defaults.samples, help="report samples per mesh"
    )
    parser.add_argument("--json", default=None, help="also write every number here (atomically)")
    return Arguments(**vars(parser.parse_args(argv)))


def mesh_files(names: list[str]) -> list[Path]:
    """The mesh files named or found (sorted, non-recursive) in the folders named."""
    if not names:  # the test meshes and the real objects (OBJ: the gripper there is an STL)
        return [p for d in DEFAULT_FOLDERS if d.is_dir() for p in sorted(d.glob("*.obj"))]
    found: list[Path] = []
    for name in names:
        path = Path(name)
        if path.is_dir():
            found.extend(p for p in sorted(path.iterdir()) if _is_mesh(p))
        elif path.is_file():
            found.append(path)
        else:
            raise UsageError(f"--meshes: expected a mesh file or folder, found {name!r} missing")
    if not found:
        raise UsageError(f"--meshes: expected at least one mesh file, found none in {names}")
    return found


def _is_mesh(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() in MESH_SUFFIXES


def grasp_file_scale(path: Path) -> float | None:
    """The ``object/scale`` of a grasp file ``path.with_suffix('.h5')``, else ``None``."""
    grasps = path.with_suffix(".h5")
    if not grasps.is_file():
        return None
    from dataset_gen import io

    if io.detect_format(grasps) == "acronym":
        return float(io.read_acronym(grasps).object_scale)
    return float(io.read_dg16m(grasps).object_scale)


def run_old(mesh: Any, name: str) -> tuple[tuple[dec.ConvexPart, ...], float]:
    """CoACD with its own "auto" preprocessing at threshold 0.05 (what dg16m did before)."""
    import coacd

    coacd.set_log_level("error")
    params = dec.DecompositionParameters(threshold=OLD_THRESHOLD, preprocess="off")
    kwargs = {
        **params.coacd_kwargs("off"),
        "preprocess_mode": "auto",
        # the old defaults, whatever the new ones are
        "max_ch_vertex": 256,
        "merge": True,
        "decimate": False,
    }
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int32)
    start = time.perf_counter()
    result = coacd.run_coacd(coacd.Mesh(vertices, faces), **kwargs)
    seconds = time.perf_counter() - start
    min_volume = dec.MIN_RELATIVE_HULL_VOLUME * float(np.prod(np.ptp(vertices, axis=0)))
    parts = tuple(p for p in (dec._hull_part(h, min_volume) for h, _ in result) if p is not None)
    if not parts:
        raise Dg16mError(f"{name}: CoACD (old settings) returned no usable hull")
    return parts, seconds


def measure(path: Path, args: Arguments) -> dict[str, Any]:
    scale = grasp_file_scale(path)
    obj = load_object(path, scale=scale, allow_any_size=True)
    mesh, name = obj.mesh, path.name
    rows: dict[str, Any] = {
        "mesh": str(path),
        "scale": obj.scale,
        "faces": len(mesh.faces),
        "watertight": bool(mesh.is_watertight),
        "volume": bool(mesh.is_volume),
        "longest_side_m": float(np.max(mesh.extents)),
    }
    old_parts, old_seconds = run_old(mesh, name)
    old = dec.decomposition_report(
        mesh, old_parts, samples=args.samples, name=name, stats={"seconds": old_seconds}
    )
    params = dec.DecompositionParameters(threshold=args.threshold)
    stats: dict[str, Any] = {}
    new_parts = dec.convex_decomposition(
        mesh, params=params, use_cache=False, name=name, stats=stats
    )
    new = dec.decomposition_report(mesh, new_parts, samples=args.samples, name=name, stats=stats)
    rows["old"] = {**old.to_dict(), "preprocess": "coacd-auto", "threshold": OLD_THRESHOLD}
    rows["new"] = {**new.to_dict(), "parameters": params.to_dict()}
    rows["time_ratio_new_over_old"] = new.seconds / old.seconds
    return rows


HEADER = (
    f"{'mesh':<28} {'faces':>6} {'wt':>3} | {'old hulls':>9} {'p95':>6} {'max':>6} {'s':>6} | "
    f"{'prep':>4} {'hulls':>5} {'p95':>6} {'max':>6} {'extra':>6} {'s':>6} | {'new/old':>7}"
)


def format_row(row: dict[str, Any]) -> str:
    old, new = row["old"], row["new"]
    extra = new["extra_volume"]
    return (
        f"{Path(row['mesh']).name[:28]:<28} {row['faces']:>6} "
        f"{'y' if row['watertight'] else 'n':>3} | {old['hulls']:>9} "
        f"{old['deviation_p95'] * 1e3:>6.2f} {old['deviation_max'] * 1e3:>6.2f} "
        f"{old['seconds']:>6.1f} | {new['preprocess']:>4} {new['hulls']:>5} "
        f"{new['deviation_p95'] * 1e3:>6.2f} {new['deviation_max'] * 1e3:>6.2f} "
        f"{'n/a' if extra is None else f'{extra:+.1%}':>6} {new['seconds']:>6.1f} | "
        f"{row['time_ratio_new_over_old']:>7.2f}"
    )


def run(args: Arguments) -> int:
    if not 0.0 < args.threshold <= 1.0:
        raise UsageError(f"--threshold: expected a number in (0, 1], found {args.threshold}")
    if args.samples < 100:
        raise UsageError(f"--samples: expected an integer >= 100, found {args.samples}")
    paths = mesh_files(args.meshes)
    print(
        f"CoACD {dec.coacd_version()}, one core; old = CoACD 'auto' preprocessing, threshold "
        f"{OLD_THRESHOLD:g}; new = dg16m defaults, threshold {args.threshold:g}; deviation "
        f"(one-sided, hull to mesh) in mm over {args.samples} samples; times in s"
    )
    print(HEADER)
    rows = []
    for path in paths:
        row = measure(path, args)
        rows.append(row)
        print(format_row(row), flush=True)
    if args.json:
        report = {
            "coacd_version": dec.coacd_version(),
            "old": {"preprocess_mode": "auto (CoACD's)", "threshold": OLD_THRESHOLD},
            "new": dec.DecompositionParameters(threshold=args.threshold).to_dict(),
            "meshes": rows,
        }
        write_json_atomic(Path(args.json), json_ready(report))
        print(f"wrote {args.json}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    try:
        return run(args)
    except Dg16mError as exc:
        print(f"decomposition: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
