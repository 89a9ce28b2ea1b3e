"""``dg16m objects repair`` on meshes it has never seen: time per mesh, deviation, units guess.

Two sets, one process, one core:

1. the mesh files of ``../shared/data/real`` (the DG16M airplane in metres, two ACRONYM meshes in
   their own units, the Franka hand), through :func:`dataset_gen.real.own_meshes.repair_one`
   with the units guess, exactly as the command runs them;
2. ``--sweethome3d N`` models drawn (seeded) from Debian's ``sweethome3d-furniture`` libraries
   among those the importer keeps, written as the raw OBJ files of the library (their own
   units: centimetres for most, metres for some, arbitrary for KatorLegaz), repaired with
   ``--target-extent`` = the catalogue's longest side (so every model is timed), and the
   units guess of each file checked against the catalogue: right (the guessed scale within
   20% of the true one), asked (refused with the flags to pass) or wrong;
3. with ``--units-all``, the units guess alone on every raw file the importer keeps, by the
   unit the file is really in, and for other accepted ranges than the shipped one.

Prints per mesh the seconds (read, repair, deviation, write), faces, the deviation (repaired to
source mean and p95, source to repaired p95, mm) and the units verdict; then p10/p50/p90.

    OMP_NUM_THREADS=1 nice -n 5 .venv/bin/python bench/objects_repair.py --sweethome3d 40
    .venv/bin/python bench/objects_repair.py --sweethome3d 0 --units-all   # ~2 min: guess only
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import json
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from dataset_gen.real.own_meshes import (
    INPUT_SUFFIXES,
    RepairItem,
    decide_units,
    read_source,
    repair_one,
)
from dataset_gen.real.repair import RepairParameters
from dg16m_core.errors import Dg16mError
from dg16m_core.hashing import file_sha256

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def _row(name: str, entry: dict[str, Any], verdict: str) -> dict[str, Any]:
    row: dict[str, Any] = {"mesh": name, "status": entry["status"], "units": verdict}
    row["seconds"] = round(entry["seconds"], 2)
    if entry["status"] == "ok":
        dev = entry["deviation_m"]
        row.update(
            faces=entry["faces"],
            source_faces=entry["source"]["faces"],
            source_pieces=entry["source"]["pieces"],
            repaired=entry["repair"] is not None,
            to_source_mean_mm=round(1000 * dev["to_source_mean"], 2),
            to_source_p95_mm=round(1000 * dev["to_source_p95"], 2),
            from_source_p95_mm=round(1000 * dev["from_source_p95"], 2),
        )
    else:
        row["error"] = entry["error"]
    print(
        f"{name:48s} {row['status']:6s} {row['seconds']:6.1f} s  "
        + (
            f"{row['source_faces']:6d} -> {row['faces']:5d} faces  dev mean "
            f"{row['to_source_mean_mm']:5.1f} p95 {row['to_source_p95_mm']:5.1f} back p95 "
            f"{row['from_source_p95_mm']:6.1f} mm"
            if entry["status"] == "ok"
            else row["error"][:90]
        )
        + f"  [{verdict}]",
        flush=True,
    )
    return row


def _guess_verdict(longest_file: float, true_scale: float | None) -> str:
    try:
        decision = decide_units(longest_file)
    except Dg16mError:
        return "asked"
    if true_scale is None:
        return f"guessed {decision.units}"
    right = abs(np.log(decision.scale / true_scale)) <= np.log(1.2)
    return f"{'right' if right else 'WRONG'}: guessed {decision.units}"


def shared_rows(out: Path, params: RepairParameters) -> list[dict[str, Any]]:
    rows = []
    if not SHARED.is_dir():
        print(f"{SHARED}: absent, skipped")
        return rows
    for path in sorted(p for p in SHARED.iterdir() if p.suffix.lower() in INPUT_SUFFIXES):
        item = RepairItem(path.stem, str(path), file_sha256(path))
        entry = repair_one(item, str(out), None, None, params)
        if entry["status"] != "ok" and "cannot guess the units" in entry.get("error", ""):
            longest = max(entry["source"]["extents_file_units"])  # time it at a plausible size
            entry = repair_one(item, str(out), None, float(np.clip(longest, 0.3, 1.0)), params)
            verdict = "asked (timed at a target extent)"
        else:
            verdict = "guessed" if entry["status"] == "ok" else "-"
        rows.append(_row(path.name, entry, verdict))
    return rows


def sweethome3d_rows(
    count: int, seed: int, out: Path, raw: Path, params: RepairParameters
) -> list[dict[str, Any]]:
    from dataset_gen.real.sweethome3d import DEFAULT_ROOT, read_catalogs, usable_entries

    if count <= 0:
        return []
    if not DEFAULT_ROOT.is_dir():
        print(f"{DEFAULT_ROOT}: absent (apt-get install sweethome3d-furniture), skipped")
        return []
    entries = usable_entries(read_catalogs())
    rng = np.random.default_rng(seed)
    rows = []
    for index in rng.choice(len(entries), size=min(count, len(entries)), replace=False):
        entry = entries[int(index)]
        with zipfile.ZipFile(DEFAULT_ROOT / f"{entry.library}.sh3f") as archive:
            data = archive.read(entry.model)
        path = raw / f"{entry.object_id}.obj"
        path.write_bytes(data)  # materials and textures left out: the geometry only
        true_longest = float(entry.size_m.max())
        try:
            mesh, _ = read_source(path)
        except Dg16mError as exc:
            print(f"{entry.object_id}: unreadable ({exc})")
            continue
        longest_file = float(np.max(mesh.extents))
        verdict = _guess_verdict(longest_file, true_longest / longest_file)
        target = float(np.clip(true_longest, 0.05, 5.0))
        item = RepairItem(entry.object_id, str(path), file_sha256(path))
        result = repair_one(item, str(out), None, target, params)
        rows.append(_row(entry.object_id, result, verdict))
    return rows


def _truth(scale: float) -> str:
    """The unit a file is in, from its true metres per file unit (within 20%), or "own"."""
    for unit, factor in (("m", 1.0), ("cm", 0.01), ("mm", 0.001)):
        if abs(np.log(scale / factor)) <= np.log(1.2):
            return unit
    return "own"


def units_guess_all(bands: list[tuple[float, float]]) -> dict[str, Any]:
    """The units guess on every raw file the importer keeps (read only, no repair): right,
    asked, wrong per true unit for the shipped rule, and in all for other ranges."""
    from dataset_gen.objects.grasp_object import TYPICAL_EXTENT_M
    from dataset_gen.real.sweethome3d import DEFAULT_ROOT, read_catalogs, read_model, usable_entries

    if not DEFAULT_ROOT.is_dir():
        print(f"{DEFAULT_ROOT}: absent (apt-get install sweethome3d-furniture), skipped")
        return {}
    files = []
    for entry in usable_entries(read_catalogs()):
        try:
            longest = float(np.max(read_model(entry).extents))
        except Dg16mError:
            continue
        files.append((longest, float(entry.size_m.max()) / longest))
    factors = {"m": 1.0, "cm": 0.01, "mm": 0.001}

    def verdicts(low: float, high: float) -> list[tuple[str, str]]:
        out = []
        for longest, scale in files:
            fits = [u for u, f in factors.items() if low <= longest * f <= high]
            truth = _truth(scale)
            if len(fits) != 1:
                out.append((truth, "asked"))
            else:
                right = abs(np.log(factors[fits[0]] / scale)) <= np.log(1.2)
                out.append((truth, "right" if right else "wrong"))
        return out

    shipped = verdicts(*TYPICAL_EXTENT_M)
    table = {
        truth: {
            v: sum(1 for t, x in shipped if t == truth and x == v)
            for v in ("right", "asked", "wrong")
        }
        for truth in ("cm", "m", "mm", "own")
    }
    result = {"files": len(files), "shipped_range_m": list(TYPICAL_EXTENT_M), "by_unit": table}
    result["ranges"] = {
        f"{low:g}-{high:g}": {
            v: sum(1 for _, x in verdicts(low, high) if x == v) for v in ("right", "asked", "wrong")
        }
        for low, high in bands
    }
    print(f"\nunits guess on every raw file: {json.dumps(result, indent=1)}")
    return result


def _pct(values: list[float]) -> str:
    if not values:
        return "-"
    return " / ".join(f"{v:.1f}" for v in np.percentile(values, [10, 50, 90]))


def summary(rows: list[dict[str, Any]], title: str) -> dict[str, Any]:
    ok = [r for r in rows if r["status"] == "ok"]
    out = {
        "meshes": len(rows),
        "ok": len(ok),
        "seconds_p10_p50_p90": _pct([r["seconds"] for r in ok]),
        "seconds_max": max((r["seconds"] for r in ok), default=None),
        "to_source_mean_mm": _pct([r["to_source_mean_mm"] for r in ok]),
        "to_source_p95_mm": _pct([r["to_source_p95_mm"] for r in ok]),
        "from_source_p95_mm": _pct([r["from_source_p95_mm"] for r in ok]),
        "units": {
            v: sum(1 for r in rows if r["units"].split(":")[0] == v)
            for v in sorted({r["units"].split(":")[0] for r in rows})
        },
        "failures": {r["mesh"]: r["error"] for r in rows if r["status"] != "ok"},
    }
    print(f"\n{title}: {json.dumps(out, indent=1)}")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sweethome3d", type=int, default=40, help="models drawn (default 40)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--units-all", action="store_true", help="also the units guess on all 574 raw files"
    )
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    params = RepairParameters()
    with tempfile.TemporaryDirectory() as tmp:
        out, raw = Path(tmp) / "out", Path(tmp) / "raw"
        out.mkdir()
        raw.mkdir()
        shared = shared_rows(out, params)
        furniture = sweethome3d_rows(args.sweethome3d, args.seed, out, raw, params)
    result = {
        "shared": {"rows": shared, "summary": summary(shared, "shared/data/real")},
        "sweethome3d": {"rows": furniture, "summary": summary(furniture, "sweethome3d")},
    }
    if args.units_all:
        bands = [(0.3, 2.0), (0.25, 2.0), (0.2, 2.0), (0.3, 2.5), (0.1, 3.0), (0.05, 5.0)]
        result["units_all"] = units_guess_all(bands)
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
