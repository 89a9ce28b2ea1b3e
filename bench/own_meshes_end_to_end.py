"""Your own meshes, end to end (issue 41 targets): raw furniture OBJ files -> ``dg16m objects
repair`` -> ``dg16m benchmark build --meshes`` with a verdict for every mesh, timed; and the
held-out thin vase, built alone.

The 12 raw files are taken from Debian's ``sweethome3d-furniture`` package (the KatorLegaz
library, Copyright 2003-2008 Andrew Kator & Jennifer Legaz, Creative Commons Attribution 3.0
United States; ``apt-get install -y sweethome3d-furniture``; nothing of it is shipped) as loose
OBJ files, not through the importer: units unknown, not watertight, many pieces, the situation
of a user with files from another application. Meshes whose units the repair refuses to guess
are rerun alone with ``--target-extent`` from the library's catalogue (the longest of its
width, depth and height), as the refusal message tells a user to do.

    .venv/bin/python bench/own_meshes_end_to_end.py --work runs/own12 --workers 2
    .venv/bin/python bench/own_meshes_end_to_end.py --work runs/vase --vase-only

Prints each command with its wall time, the verdict of every mesh and the totals; writes
``WORK/summary.json``. Reruns start from scratch (``WORK`` is emptied).
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import trimesh

from dg16m_core.atomic import write_json_atomic

LIBRARY = Path("/usr/share/sweethome3d/furniture/KatorLegaz.sh3f")
MODELS = (
    "mid-century-chair",
    "cafe-chair",
    "bench",
    "bar-stool",
    "cafe-table",
    "mid-century-sofa",
    "folding-table",
    "dining-chair",
    "office-chair",
    "custom-desk",
    "painted-bench",
    "utility-shelving",
)
DG16M = str(Path(sys.executable).parent / "dg16m")


def catalogue_extents(library: zipfile.ZipFile) -> dict[str, float]:
    """model name -> the longest of the catalogue's width, depth and height (m)."""
    text = library.read("PluginFurnitureCatalog.properties").decode("latin-1")
    fields: dict[str, dict[str, str]] = {}
    for line in text.splitlines():
        match = re.match(r"(\w+)#(\d+)=(.*)", line)
        if match:
            fields.setdefault(match.group(2), {})[match.group(1)] = match.group(3).strip()
    extents = {}
    for entry in fields.values():
        name = Path(entry.get("model", "")).stem
        if name in MODELS:
            extents[name] = max(float(entry[k]) for k in ("width", "depth", "height")) / 100.0
    return extents


def run(command: list[str]) -> tuple[float, int, str]:
    """Run a dg16m command; (wall seconds, exit status, output)."""
    print("$", " ".join(command), flush=True)
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    took = time.perf_counter() - started
    print(f"  exit {done.returncode} after {took:.1f} s", flush=True)
    return took, done.returncode, done.stdout + done.stderr


def thin_vase() -> trimesh.Trimesh:
    """The held-out vase-like case: a watertight thin shell (3 mm wall) of 1,344 faces."""
    z = np.linspace(0.0, 0.25, 12)
    r = 0.06 + 0.03 * np.sin(z / 0.25 * np.pi) - 0.02 * (z / 0.25)
    inner = np.c_[r - 0.003, z][::-1]
    inner[-1, 1] = 0.003
    profile = np.vstack([[0.0, 0.0], np.c_[r, z], inner, [0.0, 0.003]])
    return trimesh.creation.revolve(profile, sections=28)


def verdicts(build: Path) -> dict[str, dict[str, object]]:
    entries = json.loads((build / "manifest.json").read_text())["entries"]
    return {
        k: {
            "status": v["status"],
            "stage": v.get("stage"),
            "verdict": v.get("verdict") or v.get("error"),
            "stage_seconds": v.get("stage_seconds"),
        }
        for k, v in entries.items()
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, required=True, help="work folder (emptied)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--vase-only", action="store_true", help="only the thin vase")
    args = parser.parse_args()
    shutil.rmtree(args.work, ignore_errors=True)
    raw, repaired, built = args.work / "raw", args.work / "repaired", args.work / "built"
    raw.mkdir(parents=True)
    steps: list[dict[str, object]] = []
    if args.vase_only:
        thin_vase().export(raw / "vase.obj")
        shutil.copytree(raw, repaired)
    else:
        if not LIBRARY.is_file():
            raise SystemExit(f"expected {LIBRARY}: apt-get install -y sweethome3d-furniture")
        with zipfile.ZipFile(LIBRARY) as library:
            extents = catalogue_extents(library)
            for name in MODELS:
                (raw / f"{name}.obj").write_bytes(library.read(f"katorlegaz/{name}/{name}.obj"))
        took, code, out = run([DG16M, "objects", "repair", str(raw), "--out", str(repaired)])
        steps.append({"command": "objects repair (units guessed)", "seconds": took})
        refused = sorted(name for name in MODELS if not (repaired / f"{name}.obj").is_file())
        print(f"  units refused for {len(refused)} of {len(MODELS)}: {refused}")
        for name in refused:
            extent = ["--target-extent", f"{extents[name]:g}", "--no-progress"]
            took, code, out = run(
                [
                    DG16M,
                    "objects",
                    "repair",
                    str(raw / f"{name}.obj"),
                    "--out",
                    str(repaired),
                    *extent,
                ]
            )
            steps.append({"command": f"objects repair {name} --target-extent", "seconds": took})
    build_cmd = [DG16M, "benchmark", "build", "--meshes", str(repaired), "--out", str(built)]
    took, code, out = run([*build_cmd, "--workers", str(args.workers), "--no-progress"])
    steps.append({"command": "benchmark build --meshes", "seconds": took, "exit": code})
    print(out[-3000:])
    result = {"steps": steps, "verdicts": verdicts(built)}
    ok = sum(v["status"] == "ok" for v in result["verdicts"].values())
    print(
        f"{len(result['verdicts'])} meshes with a verdict: {ok} admitted, "
        f"{len(result['verdicts']) - ok} rejected; total "
        f"{sum(float(s['seconds']) for s in steps):.0f} s"  # type: ignore[arg-type]
    )
    write_json_atomic(args.work / "summary.json", result)


if __name__ == "__main__":
    main()
