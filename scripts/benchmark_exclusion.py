"""Write ``dg16m_env/data/benchmark_exclusion.json``: the shipped benchmarks' objects by hash.

Run after a shipped benchmark file changes (``tests/test_dataset_exclusion.py`` fails until
then)::

    .venv/bin/python scripts/benchmark_exclusion.py

It reads both shipped benchmarks' 600 objects (about 30 s) and records what
:func:`dg16m_env.benchmark.exclusion.computed_exclusion` finds, so that ``dg16m dataset build``
starts without reading them.
"""

from __future__ import annotations

from dg16m_core.atomic import write_json_atomic
from dg16m_core.hashing import file_sha256
from dg16m_env.benchmark.exclusion import SHIPPED_EXCLUSION, computed_exclusion
from dg16m_env.benchmark.names import SHIPPED_BENCHMARKS, benchmark_file


def main() -> None:
    files = {name: benchmark_file(name) for name in sorted(SHIPPED_BENCHMARKS)}
    benchmarks = {name: file_sha256(path) for name, path in files.items()}
    exclusion = computed_exclusion(files, benchmarks)
    write_json_atomic(SHIPPED_EXCLUSION, exclusion.to_dict())
    print(f"wrote {SHIPPED_EXCLUSION}: {len(exclusion.geometry)} objects of {sorted(files)}")


if __name__ == "__main__":
    main()
