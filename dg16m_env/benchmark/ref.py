"""The benchmark an evaluator scores against, with the sha256 every result records.

A :class:`BenchmarkRef` may stand for a *subset* of its file's objects
(:meth:`BenchmarkRef.subset`, ``dg16m evaluate --objects / --limit``): it keeps the file's path
and sha256, holds only the chosen objects, and its :meth:`~BenchmarkRef.record` says that the
run is partial (``"partial": true``, ``"subset": [ids]``, ``"of": N``), so a score over a few
objects is never mistaken for a score over the benchmark.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from dg16m_core.arguments import listed_ids
from dg16m_core.hashing import file_sha256
from dg16m_env.benchmark.file import read_benchmark
from dg16m_env.benchmark.model import Benchmark, BenchmarkError
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK, benchmark_file


@dataclass(frozen=True, eq=False)
class BenchmarkRef:
    """A loaded benchmark file and its identity.

    Attributes:
        path: the file.
        sha256: hex sha256 of its bytes.
        embedded: whether it is the benchmark shipped with the package.
        benchmark: its contents.
        mesh_root: the folder of its meshes (mesh benchmarks only).
        full_objects: the number of objects of the whole file when this ref holds a subset of
            them (:meth:`subset`); None for the whole benchmark.
    """

    path: Path
    sha256: str
    embedded: bool
    benchmark: Benchmark
    mesh_root: Path | None = None
    full_objects: int | None = None

    @property
    def object_ids(self) -> list[str]:
        return [o.object_id for o in self.benchmark.objects]

    @property
    def families(self) -> list[str]:
        return [o.family for o in self.benchmark.objects]

    @property
    def partial(self) -> bool:
        """Whether this ref holds only some of its file's objects."""
        return self.full_objects is not None

    def categories(self) -> list[str]:
        """Each object's category: its family (procedural objects), else its catalogue category
        in the shipped real split (:data:`dg16m_env.benchmark.real.REAL_SPLIT_FILE`) for the
        real objects, else ``""`` (a mesh object of another benchmark)."""
        families = self.families
        if all(families):
            return families
        category = _real_categories()
        return [
            f or category.get(o.object_id, "")
            for f, o in zip(families, self.benchmark.objects, strict=True)
        ]

    def subset(self, object_ids: Sequence[str]) -> BenchmarkRef:
        """This benchmark restricted to ``object_ids`` (in the benchmark's order): same file and
        sha256, a record that says the run is partial. The ids of the whole benchmark give the
        whole benchmark back.

        Raises:
            BenchmarkError: no ids, repeated ids, or ids the benchmark does not hold.
        """
        ids = [str(i) for i in object_ids]
        known = self.object_ids
        known_set, wanted = set(known), set(ids)
        unknown = [i for i in ids if i not in known_set]
        if unknown:
            raise BenchmarkError(
                f"objects: expected ids of the benchmark ({len(known)} objects, e.g. "
                f"{known[:2]}), found unknown: {', '.join(unknown[:10])}"
                + (f" and {len(unknown) - 10} more" if len(unknown) > 10 else "")
            )
        if not ids:
            raise BenchmarkError("objects: expected at least one object id, found none")
        repeated = sorted({i for i in ids if ids.count(i) > 1})
        if repeated:
            raise BenchmarkError(f"objects: expected distinct ids, found repeated: {repeated}")
        total = self.full_objects if self.full_objects is not None else len(known)
        chosen = [i for i in known if i in wanted]  # the benchmark's order
        if len(chosen) == total:
            return self
        return replace(self, benchmark=self.benchmark.select_objects(chosen), full_objects=total)

    def first(self, limit: int) -> BenchmarkRef:
        """The first ``limit`` objects of the benchmark (:meth:`subset`).

        Raises:
            BenchmarkError: ``limit`` < 1.
        """
        if isinstance(limit, bool) or not isinstance(limit, int) or limit < 1:
            raise BenchmarkError(f"limit: expected an integer >= 1, found {limit!r}")
        return self.subset(self.object_ids[:limit])

    def record(self) -> dict[str, Any]:
        """What a result records of the benchmark; a subset adds ``"partial": True``, its ids
        (``"subset"``) and the number of objects of the whole benchmark (``"of"``)."""
        out: dict[str, Any] = {
            "sha256": self.sha256,
            "objects": len(self.benchmark.objects),
            "embedded": self.embedded,
        }
        if self.partial:
            out.update({"partial": True, "subset": self.object_ids, "of": self.full_objects})
        return out


def record_is_partial(record: Any) -> bool:
    """Whether a result's benchmark record (:meth:`BenchmarkRef.record`) is of a subset."""
    return isinstance(record, dict) and bool(record.get("partial") or record.get("subset"))


def _real_categories() -> dict[str, str]:
    """Object id -> catalogue category of the shipped real split (empty when this installation
    lacks the file; a malformed one raises :class:`BenchmarkError`)."""
    from dg16m_env.benchmark.real import REAL_SPLIT_FILE, read_split

    if not REAL_SPLIT_FILE.is_file():
        return {}
    split = read_split(REAL_SPLIT_FILE)
    return {i: c for c, v in split["categories"].items() for i in v["order"]}


def parse_object_ids(text: str) -> list[str]:
    """``--objects``'s value: comma-separated ids, or the path of a file with one id a line
    (blank lines and ``#`` comments skipped).

    Raises:
        BenchmarkError: nothing in it.
    """
    path = Path(text)
    ids = listed_ids(text, path if "," not in text and path.is_file() else None)
    if not ids:
        raise BenchmarkError(f"--objects: expected object ids (a,b,c or a file), found {text!r}")
    return ids


def load_benchmark_ref(
    benchmark: str | os.PathLike[str] | BenchmarkRef | None = None,
    mesh_root: str | os.PathLike[str] | None = None,
    *,
    lazy: bool = False,
) -> BenchmarkRef:
    """Read a benchmark (a file, a short name of :data:`~dg16m_env.benchmark.names.SHIPPED_BENCHMARKS`
    such as ``"real"``, default: the embedded procedural benchmark) and hash it. ``lazy``: read
    each object's parts and mesh when first used (:func:`~dg16m_env.benchmark.file.read_benchmark`).

    Raises:
        BenchmarkError: the file is missing or malformed.
    """
    if isinstance(benchmark, BenchmarkRef):
        return benchmark
    path = benchmark_file(benchmark)
    bench = read_benchmark(path, lazy=lazy)  # validates, says so when the file is missing
    return BenchmarkRef(
        path=path,
        sha256=file_sha256(path),
        embedded=path.resolve() == EMBEDDED_BENCHMARK.resolve(),
        benchmark=bench,
        mesh_root=Path(mesh_root) if mesh_root is not None else None,
    )
