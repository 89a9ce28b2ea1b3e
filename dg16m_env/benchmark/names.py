"""Shipped benchmarks by short name: the procedural benchmark (:data:`EMBEDDED_BENCHMARK`, the
default everywhere a benchmark is taken) and the real-object one (:data:`REAL_BENCHMARK`), the
MuJoCo release that simulated them, and :func:`benchmark_file`, which turns a short name, a path
or ``None`` into a file.
"""

from __future__ import annotations

import difflib
import os
from collections.abc import Mapping
from pathlib import Path

from dg16m_env.benchmark.model import BENCHMARK_FILE, BenchmarkError

EMBEDDED_BENCHMARK = Path(__file__).parents[1] / "data" / BENCHMARK_FILE
"""The procedural benchmark built with the default parameters, shipped with the package."""

REAL_BENCHMARK = Path(__file__).parents[1] / "data" / "benchmark_real.h5"
"""The real-object benchmark (:mod:`dg16m_env.benchmark.real`): 300 furniture models, shipped."""

SHIPPED_BENCHMARKS: Mapping[str, Path] = {"procedural": EMBEDDED_BENCHMARK, "real": REAL_BENCHMARK}
"""Benchmarks by short name; ``"procedural"`` is the default everywhere a benchmark is taken."""

SHIPPED_MUJOCO_VERSION = "4.0.0"
"""The MuJoCo release that simulated the stored trials of both shipped benchmarks (pinned in
``pyproject.toml``). Another release changes contacts and so some trials: under 4.0.1 a rebuild
of the first procedural objects flips binary labels (BENCHMARKS.md, "MuJoCo version"). Files
built since 2026-12-03 record their version in ``metadata["mujoco"]``."""


def benchmark_file(benchmark: str | os.PathLike[str] | None = None) -> Path:
    """The file of a benchmark given by short name (:data:`SHIPPED_BENCHMARKS`), by path, or
    ``None`` (the procedural one).

    Raises:
        BenchmarkError: a short name whose file is not shipped in this installation, or a bare
            word that is neither a short name nor an existing file (a misspelled name).
    """
    if benchmark is None:
        return EMBEDDED_BENCHMARK
    if isinstance(benchmark, str) and benchmark in SHIPPED_BENCHMARKS:
        path = SHIPPED_BENCHMARKS[benchmark]
        if not path.is_file():
            raise BenchmarkError(
                f"benchmark {benchmark!r}: expected the shipped file {path}, found none (this "
                "installation lacks it: reinstall the package, or build it with "
                "'dg16m benchmark build-real' and pass the path of its benchmark.h5)"
            )
        return path
    path = Path(benchmark)
    if (
        isinstance(benchmark, str)
        and not path.suffix
        and len(path.parts) == 1
        and not path.exists()
    ):
        # a word, not a file: a misspelled short name
        names = ", ".join(SHIPPED_BENCHMARKS)
        close = [n for n in SHIPPED_BENCHMARKS if n.lower() == benchmark.lower()]
        close = close or difflib.get_close_matches(benchmark, list(SHIPPED_BENCHMARKS), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise BenchmarkError(
            f"benchmark: expected a file or one of: {names}, found {benchmark!r} (no such "
            f"file){hint}"
        )
    return path
