"""Does a rebuilt benchmark file reproduce another one? Every row, trial and label, field by field.

    .venv/bin/dg16m benchmark build --out runs/rebuild --workers 2 --no-progress
    .venv/bin/python bench/compare_benchmarks.py dg16m_env/data/benchmark.h5 runs/rebuild/benchmark.h5

For each per-row array of the two files (poses, contacts, sources, force-closure verdicts and
losses, the nominal trials' statuses, phases, counts and float measures, the labelled trials'
statuses and phases, the rows' seeds, p and the binary labels) it prints how many rows are
identical (NaN equal to NaN; a float row is identical only bit for bit) and the largest absolute
difference of a float field; then the fields one file stores and the other does not. Exit
status 0 when every shared field is identical in every row, 1 otherwise (2 when the files hold
different objects or row counts).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from dg16m_env.benchmark.file import read_benchmark
from dg16m_env.physics.trial_protocol import TrialResults

ROW_FIELDS = ("poses", "contact_points", "contact_normals", "source", "fc_passed", "fc_loss")
OPTIONAL_ROW_FIELDS = ("hand_line_distance", "reseat_shift")
LABEL_FIELDS = ("status", "failing_phase", "seeds")


def identical_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) bool: row i of ``a`` equals row i of ``b`` in every entry (NaN equals NaN)."""
    a, b = a.reshape(len(a), -1), b.reshape(len(b), -1)
    same = a == b
    if np.issubdtype(a.dtype, np.floating):
        same |= np.isnan(a) & np.isnan(b)
    return np.all(same, axis=1)


def max_difference(a: np.ndarray, b: np.ndarray) -> float | None:
    """Largest |a - b| over the entries where both are finite (None for non-float arrays)."""
    if not np.issubdtype(a.dtype, np.floating):
        return None
    both = np.isfinite(a) & np.isfinite(b)
    return float(np.max(np.abs(a[both] - b[both]))) if np.any(both) else 0.0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("reference", type=Path, help="benchmark file to compare against")
    parser.add_argument("rebuilt", type=Path, help="benchmark file to check")
    args = parser.parse_args(argv)
    ref, new = read_benchmark(args.reference), read_benchmark(args.rebuilt)
    ids = [o.object_id for o in ref.objects], [o.object_id for o in new.objects]
    if ids[0] != ids[1] or ref.n != new.n:
        print(
            f"expected the same objects and rows, found {len(ids[0])} objects / {ref.n} rows "
            f"against {len(ids[1])} / {new.n}" + ("" if ids[0] == ids[1] else " (other ids)"),
            file=sys.stderr,
        )
        return 2
    print(f"{len(ids[0])} objects, {ref.n} rows")
    fields: list[tuple[str, np.ndarray, np.ndarray]] = []
    fields += [(name, getattr(ref, name), getattr(new, name)) for name in ROW_FIELDS]
    for name in OPTIONAL_ROW_FIELDS:
        a, b = getattr(ref, name), getattr(new, name)
        if a is None or b is None:
            stored = "the rebuilt file only" if a is None and b is not None else None
            stored = stored or ("the reference only" if b is None and a is not None else "neither")
            print(f"{name:28s} stored in {stored}")
        else:
            fields.append((name, a, b))
    fields += [
        (f"trials.{name}", getattr(ref.trials, name), getattr(new.trials, name))
        for name in TrialResults.ARRAY_FIELDS
    ]
    fields += [
        (f"labels.{name}", getattr(ref.labels, name), getattr(new.labels, name))
        for name in LABEL_FIELDS
    ]
    fields += [("p", ref.p(), new.p()), ("label", ref.label(), new.label())]
    differing = 0
    for name, a, b in fields:
        same = identical_rows(np.asarray(a), np.asarray(b))
        diff = max_difference(np.asarray(a), np.asarray(b))
        shown = "" if diff is None else f", max |difference| {diff:.3g}"
        print(f"{name:28s} identical rows {int(same.sum())} / {len(same)}{shown}")
        differing += int(not np.all(same))
    print("every shared field identical" if not differing else f"{differing} fields differ")
    return 1 if differing else 0


if __name__ == "__main__":
    sys.exit(main())
