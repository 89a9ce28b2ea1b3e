"""The benchmark an evaluator scores against, with the sha256 every result records."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dataset_gen.hashing import file_sha256
from dg16m_env.benchmark.file import read_benchmark
from dg16m_env.benchmark.model import Benchmark
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
    """

    path: Path
    sha256: str
    embedded: bool
    benchmark: Benchmark
    mesh_root: Path | None = None

    @property
    def object_ids(self) -> list[str]:
        return [o.object_id for o in self.benchmark.objects]

    @property
    def families(self) -> list[str]:
        return [o.family for o in self.benchmark.objects]

    def record(self) -> dict[str, Any]:
        """What a result records of the benchmark."""
        return {
            "sha256": self.sha256,
            "objects": len(self.benchmark.objects),
            "embedded": self.embedded,
        }


def load_benchmark_ref(
    benchmark: str | os.PathLike[str] | BenchmarkRef | None = None,
    mesh_root: str | os.PathLike[str] | None = None,
) -> BenchmarkRef:
    """Read a benchmark (a file, a short name of :data:`~dg16m_env.benchmark.names.SHIPPED_BENCHMARKS`
    such as ``"real"``, default: the embedded procedural benchmark) and hash it.

    Raises:
        BenchmarkError: the file is missing or malformed.
    """
    if isinstance(benchmark, BenchmarkRef):
        return benchmark
    path = benchmark_file(benchmark)
    bench = read_benchmark(path)  # validates, and says so when the file is missing
    return BenchmarkRef(
        path=path,
        sha256=file_sha256(path),
        embedded=path.resolve() == EMBEDDED_BENCHMARK.resolve(),
        benchmark=bench,
        mesh_root=Path(mesh_root) if mesh_root is not None else None,
    )
