"""Generator cost per object, by stage, and a projection of the full dataset's cost.

Runs the whole per-object pipeline (load, antipodal sampling, pairing with gripper collision,
force closure on every candidate, selection, writing) on the real DG16M airplane mesh (when
``../shared/data/real`` is present) and on procedural objects, one core. The reference is the
release's own run time for the same airplane (226 s, recorded with the release data on another
machine with the release's Robotiq gripper: an indication, not a like-for-like timing); the
projection is ``objects x mean time per object / cores``. Also reports the fraction of
candidate pairs passing and the pairing ablations of the paper's Table III.

    .venv/bin/python bench/generate_object.py                 # about a minute
    .venv/bin/python bench/generate_object.py --procedural 20 --json runs/generate_object.json
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from dataset_gen.generate import (
    GenerationParameters,
    StageTimes,
    generate_object,
)
from dataset_gen.io import write_dg16m
from dataset_gen.pairing import strategy_pass_rates
from dataset_gen.procedural import object_specs
from dataset_gen.sampling import sample_antipodal_grasps
from dataset_gen.sources import ObjectSource, object_seed, procedural_sources

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
RELEASE_AIRPLANE_SECONDS = 226.0  # ../shared/data/real/README.md: the release code's run time


@dataclass
class Arguments:
    procedural: int = 10
    dataset_objects: int = 4000
    cores: int = 64
    seed: int = 0
    json: str | None = None


def parse() -> Arguments:
    defaults = Arguments()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--procedural", type=int, default=defaults.procedural)
    parser.add_argument("--dataset-objects", type=int, default=defaults.dataset_objects)
    parser.add_argument("--cores", type=int, default=defaults.cores)
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--json", default=None)
    return Arguments(**vars(parser.parse_args()))


def run(source: ObjectSource, params: GenerationParameters, folder: Path) -> dict:
    times = StageTimes()
    start = time.perf_counter()
    obj = source.load(params.mass)
    times.load = time.perf_counter() - start
    data = generate_object(obj, params, object_file=source.object_file, times=times)
    start = time.perf_counter()
    write_dg16m(folder / f"{source.object_id}.h5", data)
    times.writing = time.perf_counter() - start
    counts = data.metadata["counts"]
    rng = np.random.default_rng(object_seed(params.seed, source.object_id))
    grasps = sample_antipodal_grasps(obj, n_grasps=params.n_grasps, rng=rng)
    ablation = strategy_pass_rates(grasps, rng=np.random.default_rng(params.seed))
    return {
        "object": source.object_id,
        "times": asdict(times),
        "total": times.total,
        "candidates": counts["pairs_remaining"],
        "passing": counts["passing"],
        "pass_fraction": counts["passing"] / max(counts["pairs_remaining"], 1),
        "stored": data.n,
        "ablation": ablation,
    }


def main() -> None:
    args = parse()
    params = GenerationParameters(seed=args.seed)
    sources = []
    airplane = REAL / "dg16m_airplane.obj"
    if airplane.is_file():
        sources.append(ObjectSource("airplane", mesh=airplane))
    sources += procedural_sources(object_specs(args.procedural, seed=args.seed))
    # Warm up the compiled force-closure kernel outside the timings.
    warm_up = GenerationParameters(n_grasps=20)
    generate_object(sources[-1].load(warm_up.mass), warm_up, object_file="x")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for source in sources:
            row = run(source, params, Path(tmp))
            rows.append(row)
            t = row["times"]
            print(
                f"{row['object']:26s} total {row['total']:6.2f} s  (load {t['load']:.2f}, sampling "
                f"{t['sampling']:.2f}, pairing+collision {t['pairing']:.2f}, force closure "
                f"{t['force_closure']:.2f}, selection {t['selection']:.2f}, writing "
                f"{t['writing']:.2f})  candidates {row['candidates']}, passing "
                f"{row['pass_fraction']:.3f}"
            )
    procedural = [r for r in rows if r["object"] != "airplane"]
    mean = float(np.mean([r["total"] for r in procedural]))
    print()
    for r in rows:
        if r["object"] == "airplane":
            print(
                f"airplane: {r['total']:.2f} s end to end vs the release's "
                f"{RELEASE_AIRPLANE_SECONDS:.0f} s (another machine and gripper): "
                f"{RELEASE_AIRPLANE_SECONDS / r['total']:.0f}x"
            )
    fractions = [r["pass_fraction"] for r in procedural]
    print(
        f"procedural: mean {mean:.2f} s per object; candidate pass fraction "
        f"{min(fractions):.3f}-{max(fractions):.3f} (mean {np.mean(fractions):.3f})"
    )
    hours = args.dataset_objects * mean / args.cores / 3600
    print(
        f"projection: {args.dataset_objects} objects x {mean:.2f} s / {args.cores} cores = "
        f"{hours:.2f} h ({args.dataset_objects * mean / 3600:.1f} core-hours)"
    )
    print("pairing ablations (fraction of each strategy's pairs passing force closure):")
    for r in rows:
        a = r["ablation"]
        print(
            f"  {r['object']:26s} random {a['random']:.3f}  farthest {a['farthest']:.3f}  "
            f"force-closure candidates {a['force_closure']:.3f}  (selected passing pairs: 1.000)"
        )
    if args.json:
        from dataset_gen.atomic import write_json_atomic

        write_json_atomic(Path(args.json), {"rows": rows, "mean_procedural_seconds": mean})


if __name__ == "__main__":
    main()
