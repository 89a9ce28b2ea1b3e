"""MuJoCo Warp against C MuJoCo: the same benchmark rows labelled by both engines.

Samples ``--rows`` rows of a benchmark file, stratified by arm (all arms; seeded), or every row
of ``--objects`` objects drawn at random (seeded; the batches a build runs), and labels
each row (nominal + K perturbed trials, the file's own perturbation seeds, scene and protocol)
twice in this run: with C MuJoCo (the reference, :class:`~dg16m_env.physics.simulator.Simulator`
``"mujoco"``) and with MuJoCo Warp on ``--device`` (``cpu`` checks the path without a GPU). One
object's rows go through each engine in one call, so Warp steps them as one batch of worlds.

Reported, overall and per arm:

* **binary labels** (p >= 0.5) identical between the engines, at both levels (held through
  every disturbance; held under gravity), with a Wilson 95 % interval; the target is >= 98 %;
* **mean and largest |p_warp - p_cpu|**;
* **trial verdicts** (every trial's status) identical;
* the C labels against the file's stored labels (identical on the machine that built the file;
  on another CPU the last bits of MuJoCo can differ);
* with ``--chaos-shift M``, C MuJoCo against itself with every hand moved M metres (1e-7: about
  float32's resolution at 1 m): how many labels a change in the last bits flips on its own, the
  floor any second engine's agreement is to be read against;
* with ``--repeat``, Warp run twice: trials whose verdict changed between the two runs (GPU
  atomics make MuJoCo Warp non-deterministic unless ``--deterministic``);
* time in each engine and trials/s (the first Warp object includes kernel compilation: on the CPU
  device one to two minutes the first time, then cached in ``~/.cache/warp``; it is reported
  apart).

    nice .venv/bin/python bench/warp_agreement.py --rows 160 --device cpu --json runs/warp_cpu.json
    python bench/warp_agreement.py --rows 600 --device cuda:0 --repeat --json $OUT/agreement.json
    python bench/warp_agreement.py --benchmark runs/real/benchmark.h5 --mesh-root tests/data/meshes

Needs the optional extra: ``pip install 'dg16m[warp]'``.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from label_stability import machine, plan_work, sample_rows, wilson

from dg16m_core.atomic import write_json_atomic
from dg16m_env.benchmark.file import read_benchmark
from dg16m_env.benchmark.model import SOURCES
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.physics.labels import LEVELS, GraspLabels, concatenate_labels, success_probability
from dg16m_env.physics.scene import compile_scene
from dg16m_env.physics.simulator import Simulator

TARGET = 0.98
"""Binary labels identical between the engines on at least this share of sampled rows."""


@dataclass
class Arguments:
    benchmark: str = str(EMBEDDED_BENCHMARK)
    mesh_root: str | None = None
    rows: int = 160
    objects: int = 0
    seed: int = 0
    device: str = "cuda:0"
    worlds: int = 4096
    deterministic: bool = False
    repeat: bool = False
    chaos_shift: float = 0.0
    against: str | None = None
    json: str | None = None


def parse(argv: list[str] | None = None) -> Arguments:
    d = Arguments()
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--benchmark", default=d.benchmark, help="benchmark file (default: shipped)")
    p.add_argument("--mesh-root", default=None, help="folder of a mesh benchmark's meshes")
    p.add_argument("--rows", type=int, default=d.rows, help="rows, stratified by arm")
    p.add_argument(
        "--objects",
        type=int,
        default=d.objects,
        help="instead of --rows: every row of this many objects drawn at random (bigger batches "
        "per object, what a benchmark build runs)",
    )
    p.add_argument("--seed", type=int, default=d.seed, help="seed of the row sample")
    p.add_argument("--device", default=d.device, help="Warp device: cuda:0, cpu, ...")
    p.add_argument("--worlds", type=int, default=d.worlds, help="Warp worlds per batch")
    p.add_argument("--deterministic", action="store_true", help="Warp's deterministic mode")
    p.add_argument("--repeat", action="store_true", help="run Warp twice and compare")
    p.add_argument(
        "--chaos-shift",
        type=float,
        default=0.0,
        metavar="M",
        help="also label with C MuJoCo after moving every hand by M metres in a seeded random "
        "direction (e.g. 1e-7, float32's resolution at 1 m): the labels a change of the last "
        "bits alone flips, the floor for any second engine",
    )
    p.add_argument(
        "--against",
        default=None,
        metavar="FILE.h5",
        help="simulate nothing: compare the stored labels of --benchmark (C MuJoCo) with those "
        "of FILE.h5, the same rows rebuilt on MuJoCo Warp (dg16m benchmark build --simulator "
        "warp with the same seed)",
    )
    p.add_argument("--json", default=None, help="write the results here")
    return Arguments(**vars(p.parse_args(argv)))


def agreement(cpu: GraspLabels, warp: GraspLabels) -> dict[str, Any]:
    """Label and trial agreement of two labellings of the same rows."""
    out: dict[str, Any] = {"rows": int(cpu.n), "trials": int(cpu.status.size)}
    for level in LEVELS:
        same = cpu.label(level) == warp.label(level)
        low, high = wilson(int(same.sum()), int(same.size))
        diff = np.abs(warp.p(level) - cpu.p(level))
        out[level] = {
            "labels_identical": float(same.mean()) if same.size else None,
            "labels_identical_ci95": [low, high],
            "labels_differ": int((~same).sum()),
            "cpu_positive_warp_negative": int((cpu.label(level) & ~warp.label(level)).sum()),
            "cpu_negative_warp_positive": int((~cpu.label(level) & warp.label(level)).sum()),
            "mean_abs_dp": float(diff.mean()) if diff.size else None,
            "max_abs_dp": float(diff.max()) if diff.size else None,
            "mean_p_cpu": float(cpu.p(level).mean()) if diff.size else None,
            "mean_p_warp": float(warp.p(level).mean()) if diff.size else None,
        }
    out["trial_verdicts_identical"] = float(np.mean(cpu.status == warp.status))
    return out


def shifted(poses: np.ndarray, distance: float, rng: np.random.Generator) -> np.ndarray:
    """(N, 2, 4, 4) ``poses`` with each hand moved by ``distance`` (m) in a random direction."""
    direction = rng.normal(size=(*poses.shape[:2], 3))
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    out = poses.copy()
    out[:, :, :3, 3] += distance * direction
    return out


def per_row(order: np.ndarray, cpu: GraspLabels, warp: GraspLabels) -> dict[str, list]:
    """Every compared row: its index in the file and both engines' success probabilities."""
    return {
        "row": order.tolist(),
        **{f"p_{level}_cpu": cpu.p(level).tolist() for level in LEVELS},
        **{f"p_{level}_warp": warp.p(level).tolist() for level in LEVELS},
    }


def compare_files(args: Arguments) -> int:
    """``--against``: two builds of the same rows, their stored labels compared row by row."""
    cpu_bench, warp_bench = read_benchmark(args.benchmark), read_benchmark(args.against)
    if cpu_bench.n != warp_bench.n or not np.array_equal(cpu_bench.poses, warp_bench.poses):
        print(
            f"expected the same rows in {args.benchmark} and {args.against}, found "
            f"{cpu_bench.n} and {warp_bench.n} rows with other poses (build both with one seed)"
        )
        return 2
    result = {
        "arguments": asdict(args),
        "machine": machine(),
        "simulator": warp_bench.metadata.get("simulator", {"name": "mujoco"}),
        "overall": agreement(cpu_bench.labels, warp_bench.labels),
        "rows": per_row(np.arange(cpu_bench.n), cpu_bench.labels, warp_bench.labels),
        "per_arm": {
            SOURCES[a]: agreement(
                cpu_bench.labels.select(cpu_bench.source == a),
                warp_bench.labels.select(cpu_bench.source == a),
            )
            for a in np.unique(cpu_bench.source)
        },
    }
    return finish(result, args)


def run(args: Arguments) -> int:
    if args.against is not None:
        return compare_files(args)
    bench = read_benchmark(args.benchmark)
    params = bench.parameters()
    if args.objects > 0:
        rng = np.random.default_rng(args.seed)
        chosen = rng.choice(
            len(bench.objects), size=min(args.objects, len(bench.objects)), replace=False
        )
        rows = np.flatnonzero(np.isin(bench.object_index, chosen))
    else:
        rows = sample_rows(bench, args.rows, args.seed)
    works = plan_work(bench, rows, None)  # the file's stored per-row seeds
    simulator = Simulator(
        name="warp", device=args.device, worlds=args.worlds, deterministic=args.deterministic
    )
    simulator.check_available()
    print(
        f"{args.benchmark}: {rows.size} rows of {bench.n} on {len(works)} objects, K = "
        f"{bench.labels.spec.n_perturbations}; Warp on {simulator.warp_device}",
        flush=True,
    )
    cpu_parts, warp_parts, again_parts, chaos_parts = [], [], [], []
    seconds = {"cpu": 0.0, "warp": 0.0, "warp_first_object": 0.0, "warp_repeat": 0.0}
    for k, work in enumerate(works):
        obj = work.item.load(args.mesh_root)
        scene = compile_scene(obj, params=params.scene, parts=work.item.parts)

        def label(
            engine: Simulator | None, poses: np.ndarray | None = None, scene=scene, work=work
        ) -> tuple[GraspLabels, float]:
            start = time.perf_counter()
            labels = success_probability(
                scene,
                work.poses if poses is None else poses,
                spec=bench.labels.spec,
                seeds=work.seeds[0],
                protocol=params.protocol,
                simulator=engine,
            )
            return labels, time.perf_counter() - start

        cpu, cpu_s = label(None)
        warp, warp_s = label(simulator)
        seconds["cpu"] += cpu_s
        seconds["warp_first_object" if k == 0 else "warp"] += warp_s
        cpu_parts.append(cpu)
        warp_parts.append(warp)
        if args.repeat:
            again, again_s = label(simulator)
            seconds["warp_repeat"] += again_s
            again_parts.append(again)
        if args.chaos_shift > 0:
            rng = np.random.default_rng([args.seed, k])
            chaos_parts.append(label(None, shifted(work.poses, args.chaos_shift, rng))[0])
        same = float(np.mean(cpu.label() == warp.label()))
        print(
            f"  {k + 1}/{len(works)} {work.object_id}: {work.rows.size} rows, labels identical "
            f"{100 * same:.0f} %, C {cpu_s:.1f} s, Warp {warp_s:.1f} s",
            flush=True,
        )
    cpu, warp = concatenate_labels(cpu_parts), concatenate_labels(warp_parts)
    order = np.concatenate([w.rows for w in works])
    stored = bench.labels.select(order)
    arms = bench.source[order]
    trials = int(cpu.status.size)
    first_trials = int(cpu_parts[0].status.size)
    result: dict[str, Any] = {
        "arguments": asdict(args),
        "machine": machine(),
        "simulator": simulator.describe(),
        "overall": agreement(cpu, warp),
        "per_arm": {
            SOURCES[a]: agreement(cpu.select(arms == a), warp.select(arms == a))
            for a in np.unique(arms)
        },
        "cpu_vs_stored": {
            "labels_identical": float(np.mean(cpu.label() == stored.label())),
            "trial_verdicts_identical": float(np.mean(cpu.status == stored.status)),
        },
        "rows": per_row(order, cpu, warp),
        "seconds": seconds,
        "trials_per_s": {
            "cpu": trials / seconds["cpu"],
            "warp_after_first_object": (
                (trials - first_trials) / seconds["warp"] if seconds["warp"] > 0 else None
            ),
        },
    }
    if args.chaos_shift > 0:
        result["cpu_vs_cpu_shifted"] = {
            "shift_m": args.chaos_shift,
            **agreement(cpu, concatenate_labels(chaos_parts)),
        }
    if args.repeat:
        again = concatenate_labels(again_parts)
        result["warp_repeat"] = {
            "trial_verdicts_changed": int(np.sum(again.status != warp.status)),
            "labels_changed": int(np.sum(again.label() != warp.label())),
            "trials": trials,
        }
    return finish(result, args)


def finish(result: dict[str, Any], args: Arguments) -> int:
    """Print the report, write the JSON; exit status 0 when the target is met."""
    report(result)
    if args.json:
        write_json_atomic(Path(args.json), result)
        print(f"wrote {args.json}")
    overall = result["overall"]["full"]["labels_identical"]
    return 0 if overall is not None and overall >= TARGET else 1


def report(result: dict[str, Any]) -> None:
    overall = result["overall"]
    print(f"\n{overall['rows']} rows, {overall['trials']} trials per engine")
    print(
        f"{'':12} {'labels identical (full)':>26} {'gravity':>10} {'mean |dp|':>10} {'trials':>8}"
    )
    rows = {"all": overall, **result["per_arm"]}
    for name, a in rows.items():
        full, gravity = a["full"], a["gravity"]
        low, high = full["labels_identical_ci95"]
        ci = f"[{100 * low:.1f}-{100 * high:.1f}]" if low is not None else ""
        print(
            f"{name:12} {100 * full['labels_identical']:7.1f} % {ci:>15} "
            f"{100 * gravity['labels_identical']:8.1f} % {full['mean_abs_dp']:10.3f} "
            f"{100 * a['trial_verdicts_identical']:6.1f} %"
        )
    full = overall["full"]
    print(
        f"label flips: C success / Warp failure {full['cpu_positive_warp_negative']}, "
        f"C failure / Warp success {full['cpu_negative_warp_positive']}; "
        f"mean p {full['mean_p_cpu']:.3f} (C) vs {full['mean_p_warp']:.3f} (Warp), "
        f"largest |dp| {full['max_abs_dp']:.3f}"
    )
    if "cpu_vs_stored" in result:
        stored = result["cpu_vs_stored"]
        print(
            f"C labels vs the file's: {100 * stored['labels_identical']:.1f} % labels, "
            f"{100 * stored['trial_verdicts_identical']:.1f} % trial verdicts identical"
        )
    if "cpu_vs_cpu_shifted" in result:
        c = result["cpu_vs_cpu_shifted"]
        print(
            f"C against C with every hand moved {c['shift_m']:g} m: "
            f"{100 * c['full']['labels_identical']:.1f} % labels, "
            f"{100 * c['trial_verdicts_identical']:.1f} % trial verdicts identical"
        )
    if "warp_repeat" in result:
        r = result["warp_repeat"]
        print(
            f"Warp run twice: {r['trial_verdicts_changed']} of {r['trials']} trial verdicts and "
            f"{r['labels_changed']} labels changed"
        )
    if "seconds" in result:
        s, rate = result["seconds"], result["trials_per_s"]
        warp_rate = rate["warp_after_first_object"]
        after = f"{warp_rate:.1f} trials/s after the first object" if warp_rate else "one object"
        print(
            f"time: C {s['cpu']:.1f} s ({rate['cpu']:.1f} trials/s, one core); Warp "
            f"{s['warp_first_object'] + s['warp']:.1f} s, the first object "
            f"{s['warp_first_object']:.1f} s with kernel loading ({after})"
        )
    verdict = "meets" if full["labels_identical"] >= TARGET else "misses"
    print(f"{verdict} the target: binary labels identical on >= {100 * TARGET:.0f} % of rows")


def main(argv: list[str] | None = None) -> int:
    return run(parse(argv))


if __name__ == "__main__":
    sys.exit(main())
