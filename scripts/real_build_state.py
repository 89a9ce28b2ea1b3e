"""Carry a real-benchmark build between machines (a maintainer's step; see
:mod:`dg16m_env.benchmark.real_build_state`).

    python scripts/real_build_state.py save --meshes /work/real/meshes --build /work/real/build
    python scripts/real_build_state.py restore --meshes /work/real/meshes --build /work/real/build

``save`` packs the import folder (each OBJ xz-compressed, exact bytes) and the build's finished
objects into ``--state`` (default ``data/real-build`` of this repository, kept in git while the
build is unfinished); ``restore`` unpacks them, checking every mesh against its sha256, so that
``dg16m benchmark build-real`` resumes where the last machine stopped.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from dg16m_core.errors import Dg16mError
from dg16m_env.benchmark.real import read_split
from dg16m_env.benchmark.real_build_state import restore_build_state, save_build_state

DEFAULT_STATE = Path(__file__).resolve().parents[1] / "data" / "real-build"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("action", choices=("save", "restore"))
    parser.add_argument("--meshes", type=Path, required=True, help="the import folder")
    parser.add_argument("--build", type=Path, default=None, help="the build-real folder")
    parser.add_argument(
        "--state", type=Path, default=DEFAULT_STATE, help=f"state folder (default {DEFAULT_STATE})"
    )
    args = parser.parse_args(argv)
    try:
        if args.action == "save":
            counts = save_build_state(args.meshes, args.build, args.state)
        else:
            counts = restore_build_state(args.state, args.meshes, args.build)
    except Dg16mError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(f"{args.action}: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    missing = sorted(i for i in read_split()["sha256"] if not (args.meshes / f"{i}.obj").is_file())
    if missing:  # the build's replacements need them; a plain rerun would retry refused models
        print(
            f"{len(missing)} objects of the split are not imported yet; import them with\n"
            f"  dg16m objects import-sweethome3d --out {args.meshes} --workers 2 --ids "
            + ",".join(missing)
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
