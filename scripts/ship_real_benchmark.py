"""Ship a finished real-benchmark build in the package (a maintainer's step).

    python scripts/ship_real_benchmark.py --build /work/real/build

Checks the build folder of ``dg16m benchmark build-real`` (its ``benchmark.h5`` reads with
every carried mesh matching its hash and holds exactly the split's 300 benchmark objects, each
with its mesh and hulls; ``ATTRIBUTION.md`` names every one) and only then copies it into
``dg16m_env/data/`` as ``benchmark_real.h5``, ``real_split.json`` and ``ATTRIBUTION.md``, each
atomically. Run the build once more first if it was written by a version without
``ATTRIBUTION.md``: the resumed build finds every object done and writes it.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from dg16m_core.errors import Dg16mError
from dg16m_env.benchmark.real import DATA, REAL_SIZE, ship_real_benchmark


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--build", type=Path, required=True, help="a build-real folder")
    parser.add_argument("--to", type=Path, default=DATA, help=f"data folder (default {DATA})")
    parser.add_argument(
        "--size", type=int, default=REAL_SIZE, help=f"benchmark objects (default {REAL_SIZE})"
    )
    args = parser.parse_args(argv)
    try:
        written = ship_real_benchmark(args.build, to=args.to, size=args.size)
    except Dg16mError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    for path in written:
        print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
