"""What a training dataset must leave out: the shipped benchmarks' objects, by hash.

:func:`benchmark_exclusion` reads both shipped benchmarks (procedural and real furniture) and
records every object's geometry sha256 (:func:`dataset_gen.collection.splits.geometry_sha256` of
the mesh the benchmark simulates, in its object frame), its id, and for the real benchmark the
sha256 of each object's imported OBJ file (from the real split,
:data:`dg16m_env.benchmark.real.REAL_SPLIT_FILE`), so that ``dg16m dataset build`` can refuse a
dataset that holds any of them under any name.

Reading the 600 objects takes about 30 s, so the result ships with the package
(:data:`SHIPPED_EXCLUSION`, written by ``scripts/benchmark_exclusion.py``; a test recomputes it)
and a dataset folder keeps its own copy (``exclusion.json``); either is used only while the
benchmark files' sha256 are the ones it records, else the objects are read again.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

from dataset_gen.collection.splits import Exclusion, geometry_sha256
from dg16m_core.hashing import file_sha256

from .names import EMBEDDED_BENCHMARK, SHIPPED_BENCHMARKS, benchmark_file
from .real import REAL_SPLIT_FILE
from .ref import load_benchmark_ref

SHIPPED_EXCLUSION = EMBEDDED_BENCHMARK.parent / "benchmark_exclusion.json"
"""The shipped benchmarks' exclusion (:meth:`~dataset_gen.collection.splits.Exclusion.to_dict`),
for the benchmark files it names by sha256."""


def _cached(path: Path | None, benchmarks: dict[str, str]) -> Exclusion | None:
    """The exclusion a dataset folder recorded, when it was made from these benchmark files."""
    if path is None or not path.is_file():
        return None
    try:
        found = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None  # unreadable: computed again (the build then checks the file itself)
    if not isinstance(found, dict) or found.get("benchmarks") != benchmarks:
        return None
    return Exclusion(
        geometry=found.get("geometry_sha256", {}),
        ids=found.get("ids", {}),
        source_sha256=found.get("source_sha256", {}),
        benchmarks=benchmarks,
    )


def benchmark_exclusion(
    names: Sequence[str] = tuple(SHIPPED_BENCHMARKS), *, cached: Path | None = None
) -> Exclusion:
    """The objects of the shipped benchmarks ``names`` (module docstring).

    Args:
        names: short names of :data:`~dg16m_env.benchmark.names.SHIPPED_BENCHMARKS`.
        cached: an ``exclusion.json`` written earlier; reused when it was made from the same
            benchmark files (by sha256).

    Raises:
        BenchmarkError: a benchmark file is missing or malformed.
    """
    files = {name: benchmark_file(name) for name in names}
    benchmarks = {name: file_sha256(path) for name, path in sorted(files.items())}
    for path in (cached, SHIPPED_EXCLUSION):
        reused = _cached(path, benchmarks)
        if reused is not None:
            return reused
    return computed_exclusion(files, benchmarks)


def computed_exclusion(files: dict[str, Path], benchmarks: dict[str, str]) -> Exclusion:
    """The exclusion read from the benchmark ``files`` themselves (name -> path; their sha256
    ``benchmarks``): every object loaded and hashed."""
    geometry: dict[str, str] = {}
    ids: dict[str, str] = {}
    for name, path in sorted(files.items()):
        ref = load_benchmark_ref(path)
        for obj in ref.benchmark.objects:
            mesh = obj.load(ref.mesh_root).mesh
            geometry[geometry_sha256(mesh.vertices, mesh.faces)] = f"{name}/{obj.object_id}"
            ids[obj.object_id] = name
    source_sha256: dict[str, str] = {}
    if "real" in files and REAL_SPLIT_FILE.is_file():
        split = json.loads(REAL_SPLIT_FILE.read_text(encoding="utf-8"))
        for object_id in split.get("benchmark", []):
            sha = split.get("sha256", {}).get(object_id)
            if isinstance(sha, str):
                source_sha256[sha] = f"real/{object_id}"
    return Exclusion(geometry=geometry, ids=ids, source_sha256=source_sha256, benchmarks=benchmarks)
