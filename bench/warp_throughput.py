"""Trials per second of MuJoCo Warp on the benchmark's scenes, against C MuJoCo in the same run.

For the first ``--objects`` objects of a benchmark file (default: the shipped procedural one),
takes each object's trials as a v2 build runs them (every row's nominal and K perturbed poses,
about 900 trials per object) and times :func:`dg16m_env.physics.trial.run_trials`:

* on MuJoCo Warp (``--device``), once per ``--worlds`` count, the object's trials repeated up to
  that many so that one batch fills the worlds; the wall time of the whole call (C validity
  check, device stepping, host judge), after a warm-up call on the first object that loads the
  kernels (on a GPU, graph captures stay inside the timing: a build pays them too);
* at the object's own trial count (the batch a build sends), which is what a rebuild runs;
* on C MuJoCo, one core, ``--cpu-trials`` of the same trials (the reference of the ratio).

Prints trials/s per setting, the ratio to one C MuJoCo core, the device memory high-water mark
(CUDA; Warp's memory pool) and the projected trial time of a 300-object rebuild at the build's
batch size. The target on a GPU is >= 2,000 trials/s.

    python bench/warp_throughput.py --device cuda:0 --objects 10 --worlds 1024 4096 8192 --json t.json
    nice .venv/bin/python bench/warp_throughput.py --device cpu --objects 1 --worlds 256 --cpu-trials 90

Needs the optional extra: ``pip install 'dg16m[warp]'``.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from label_stability import machine

from dg16m_core.atomic import write_json_atomic
from dg16m_env.benchmark.file import read_benchmark
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.physics.labels import trial_poses
from dg16m_env.physics.scene import compile_scene
from dg16m_env.physics.simulator import Simulator, import_warp
from dg16m_env.physics.trial import run_trials
from dg16m_env.physics.trial_protocol import TrialStatus

TARGET = 2000.0
"""Trials per second wanted on a GPU."""
REBUILD_OBJECTS = 300


@dataclass
class Arguments:
    benchmark: str = str(EMBEDDED_BENCHMARK)
    mesh_root: str | None = None
    objects: int = 5
    trials: int | None = None
    worlds: list[int] = field(default_factory=lambda: [1024, 4096, 8192])
    device: str = "cuda:0"
    cpu_trials: int = 270
    deterministic: bool = False
    json: str | None = None


def parse(argv: list[str] | None = None) -> Arguments:
    d = Arguments()
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--benchmark", default=d.benchmark)
    p.add_argument("--mesh-root", default=None)
    p.add_argument("--objects", type=int, default=d.objects, help="first N objects of the file")
    p.add_argument(
        "--trials", type=int, default=None, help="at most this many of each object's trials"
    )
    p.add_argument("--worlds", type=int, nargs="+", default=d.worlds, help="world counts")
    p.add_argument("--device", default=d.device, help="Warp device: cuda:0, cpu, ...")
    p.add_argument("--cpu-trials", type=int, default=d.cpu_trials, help="C MuJoCo reference")
    p.add_argument("--deterministic", action="store_true", help="Warp's deterministic mode")
    p.add_argument("--json", default=None, help="write the results here")
    return Arguments(**vars(p.parse_args(argv)))


def memory_high(wp: Any, device: Any) -> int | None:
    """Bytes: Warp's memory-pool high-water mark on a CUDA device (None elsewhere)."""
    if not device.is_cuda or not wp.is_mempool_enabled(device):
        return None
    return int(wp.get_mempool_used_mem_high(device))


def timed(scene: Any, poses: np.ndarray, protocol: Any, simulator: Simulator | None) -> float:
    start = time.perf_counter()
    results = run_trials(scene, poses, protocol, simulator=simulator)
    seconds = time.perf_counter() - start
    if np.any(results.status == TrialStatus.UNSTABLE):
        print(f"    note: {int(np.sum(results.status == TrialStatus.UNSTABLE))} unstable trials")
    return seconds


def run(args: Arguments) -> int:
    _, wp = import_warp()
    bench = read_benchmark(args.benchmark)
    params = bench.parameters()
    device = wp.get_device(args.device)
    print(f"{args.benchmark}: first {args.objects} objects; Warp on {device} ({device.name})")
    rows: list[dict[str, Any]] = []
    for k in range(min(args.objects, len(bench.objects))):
        item = bench.objects[k]
        mine = np.flatnonzero(bench.object_index == k)
        scene = compile_scene(item.load(args.mesh_root), params=params.scene, parts=item.parts)
        spec = bench.labels.spec
        poses = trial_poses(scene, bench.poses[mine], bench.labels.seeds[mine], spec)
        poses = poses.reshape(-1, 2, 4, 4)[: args.trials]
        entry: dict[str, Any] = {"object": item.object_id, "trials": len(poses), "warp": {}}
        cpu = poses[: args.cpu_trials]
        entry["cpu_trials_per_s"] = len(cpu) / timed(scene, cpu, params.protocol, None)
        own = Simulator(
            name="warp", device=args.device, worlds=len(poses), deterministic=args.deterministic
        )
        if k == 0:
            timed(scene, poses[:8], params.protocol, own)  # loads (first time: compiles) kernels
        entry["build_batch_trials_per_s"] = len(poses) / timed(scene, poses, params.protocol, own)
        for worlds in args.worlds:
            tiled = np.resize(poses, (worlds, 2, 4, 4))
            sim = Simulator(
                name="warp", device=args.device, worlds=worlds, deterministic=args.deterministic
            )
            entry["warp"][str(worlds)] = worlds / timed(scene, tiled, params.protocol, sim)
        entry["memory_high_bytes"] = memory_high(wp, device)
        rows.append(entry)
        rates = ", ".join(f"{w} worlds {r:.0f}" for w, r in entry["warp"].items())
        print(
            f"  {item.object_id}: C {entry['cpu_trials_per_s']:.1f} trials/s; Warp at the build "
            f"batch ({len(poses)}) {entry['build_batch_trials_per_s']:.0f}; {rates} trials/s",
            flush=True,
        )
        if args.json:  # after every object: a run stopped at a time limit keeps what it measured
            write_json_atomic(
                Path(args.json),
                {
                    "arguments": asdict(args),
                    "machine": machine(),
                    "objects": rows,
                    **summarise(rows, args),
                },
            )
    print_summary(summarise(rows, args))
    if args.json:
        print(f"wrote {args.json}")
    return 0


def summarise(rows: list[dict[str, Any]], args: Arguments) -> dict[str, Any]:
    cpu = float(np.median([r["cpu_trials_per_s"] for r in rows]))
    build = float(np.median([r["build_batch_trials_per_s"] for r in rows]))
    per_worlds = {str(w): float(np.median([r["warp"][str(w)] for r in rows])) for w in args.worlds}
    trials = float(np.mean([r["trials"] for r in rows]))
    return {
        "median_trials_per_s": {"cpu_one_core": cpu, "warp_build_batch": build, **per_worlds},
        "ratio_to_one_cpu_core": {k: v / cpu for k, v in per_worlds.items()},
        "projected_rebuild_trial_minutes": REBUILD_OBJECTS * trials / build / 60.0,
        "memory_high_bytes": max((r["memory_high_bytes"] or 0) for r in rows) or None,
        "best_trials_per_s": max([build, *per_worlds.values()]),
    }


def print_summary(summary: dict[str, Any]) -> None:
    rates = summary["median_trials_per_s"]
    print("\nmedian trials/s over the objects:")
    for name, rate in rates.items():
        ratio = summary["ratio_to_one_cpu_core"].get(name)
        extra = f"  ({ratio:.1f}x one C core)" if ratio is not None else ""
        label = f"{name} worlds" if name.isdigit() else name
        print(f"  {label:>20}: {rate:9.1f}{extra}")
    print(
        f"300-object rebuild, trials only, at the build batch: "
        f"{summary['projected_rebuild_trial_minutes']:.1f} min"
    )
    memory = summary["memory_high_bytes"]
    if memory:
        print(f"device memory high-water mark: {memory / 2**30:.2f} GiB")
    best = summary["best_trials_per_s"]
    print(f"{'meets' if best >= TARGET else 'misses'} {TARGET:.0f} trials/s (best {best:.0f})")


def main(argv: list[str] | None = None) -> int:
    return run(parse(argv))


if __name__ == "__main__":
    sys.exit(main())
