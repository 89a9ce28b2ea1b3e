"""Generator cost per object, by stage, against today's reference path, and a projection of the
full dataset's cost.

Runs the whole per-object pipeline (load, antipodal sampling, pairing with gripper collision,
force closure on every candidate, selection, writing) on the real meshes shipped with the tests
(``tests/data/meshes``: dining chair, couch, dining table), the real DG16M airplane mesh (when
``../shared/data/real`` is present) and procedural objects, one core. Each object runs twice:
with the package's engines, and with the reference engines of before issue 45 (trimesh's exact
``RayMeshIntersector`` for the jaw rays, one collision classification per pose, both defined
here); the written files must be byte-identical, and the ratio of the two times is printed.
Sampling is split into its two costly parts, the jaw rays and the open-hand collision
classification. The reference is the
release's own run time for the same airplane (226 s, recorded with the release data on another
machine with the release's Robotiq gripper: an indication, not a like-for-like timing); the
projection is ``objects x mean time per object / cores``. Also reports the fraction of
candidate pairs passing and the pairing ablations of the paper's Table III.

    .venv/bin/python bench/generate_object.py                 # about two minutes
    .venv/bin/python bench/generate_object.py --procedural 20 --json runs/generate_object.json
    .venv/bin/python bench/generate_object.py --meshes DIR --procedural 2   # your real meshes
    .venv/bin/python bench/generate_object.py --procedural 4 \
        --real-ids blendswap-cc-0-foldingchair,blendswap-cc-0-stool2,scopia-bar-chair
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

import dataset_gen.grasps.gripper as gripper_module
from dataset_gen.grasps.gripper import ContactStatus, nearest_hits
from dataset_gen.grasps.pairing import strategy_pass_rates
from dataset_gen.grasps.sampling import sample_antipodal_grasps
from dataset_gen.io import write_dg16m
from dataset_gen.pipeline.generate import (
    GenerationParameters,
    StageTimes,
    generate_object,
)
from dataset_gen.sources.object_source import ObjectSource, object_seed, procedural_sources
from dataset_gen.sources.procedural import object_specs

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "data" / "real"
MESHES = ROOT / "tests" / "data" / "meshes"
RELEASE_AIRPLANE_SECONDS = 226.0  # ../shared/data/real/README.md: the release code's run time


@dataclass
class Arguments:
    procedural: int = 10
    meshes: str = str(MESHES)
    real_ids: str = ""
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
    parser.add_argument(
        "--meshes", default=defaults.meshes, help="folder of real meshes (.obj, metres)"
    )
    parser.add_argument(
        "--real-ids",
        default=defaults.real_ids,
        help="also these objects of the shipped real benchmark (their repaired, decimated "
        "meshes, ~2,500 faces), comma-separated",
    )
    parser.add_argument("--json", default=None)
    return Arguments(**vars(parser.parse_args()))


# --------------------------------------------------------------------------------------------
# Today's reference path (before issue 45), kept here to measure against in the same run
# --------------------------------------------------------------------------------------------


def reference_first_hits(
    mesh: Any, origins: np.ndarray, directions: np.ndarray, max_distance: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The jaw rays' first hits through trimesh's exact intersector (pure Python over an
    R-tree), as the generator computed them before issue 45."""
    from trimesh.ray.ray_triangle import RayMeshIntersector

    hits = RayMeshIntersector(mesh).intersects_id(
        origins, directions, multiple_hits=True, return_locations=True
    )
    return nearest_hits(origins, directions, max_distance, *hits)


def reference_classify_many(checker: Any, poses: np.ndarray) -> np.ndarray:
    """The open-hand classification pose by pose through trimesh's collision manager (which
    rebuilds the hand's collision geometry on every call), each pose with its own
    ``mesh.contains`` calls, as before issue 45."""
    import trimesh

    manager = checker.__dict__.get("reference_manager")
    if manager is None:
        manager = checker.__dict__["reference_manager"] = trimesh.collision.CollisionManager()
        manager.add_object("object", checker.mesh)
    out = np.empty(len(poses), dtype=np.int8)
    for i, T in enumerate(poses):
        palm_hit = manager.in_collision_single(checker.palm_mesh, transform=T)
        finger_hit = manager.in_collision_single(checker.finger_mesh, transform=T)
        if not (palm_hit or finger_hit) and checker.solid:
            centres = checker._box_centres @ T[:3, :3].T + T[:3, 3]
            palm_hit = bool(checker.mesh.contains(centres[:1])[0])
            finger_hit = bool(checker.mesh.contains(centres[1:]).any())
        if finger_hit and checker._crosses_both_fingers(T):
            out[i] = ContactStatus.TOO_WIDE
        elif palm_hit or finger_hit:
            out[i] = ContactStatus.COLLISION
        else:
            out[i] = ContactStatus.OK
    return out


@contextmanager
def engines(reference: bool, spent: dict[str, float]) -> Iterator[None]:
    """Run with the package's engines or the reference ones; ``spent`` accumulates the seconds
    in the jaw rays (``rays``) and the collision classification (``collision``)."""
    checker = gripper_module._CollisionChecker
    saved = gripper_module._first_hits, checker.classify_many
    first_hits = reference_first_hits if reference else saved[0]
    classify = reference_classify_many if reference else saved[1]

    def timed_hits(*args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return first_hits(*args, **kwargs)
        finally:
            spent["rays"] += time.perf_counter() - start

    def timed_classify(self: Any, poses: np.ndarray) -> np.ndarray:
        start = time.perf_counter()
        try:
            return classify(self, poses)
        finally:
            spent["collision"] += time.perf_counter() - start

    gripper_module._first_hits, checker.classify_many = timed_hits, timed_classify
    try:
        yield
    finally:
        gripper_module._first_hits, checker.classify_many = saved


def timed_object(
    source: ObjectSource, params: GenerationParameters, path: Path, reference: bool
) -> tuple[Any, StageTimes, dict[str, float], Any]:
    """Generate and write one object; returns the object, its stage times and the seconds in
    the jaw rays and the collision classification."""
    times = StageTimes()
    spent = {"rays": 0.0, "collision": 0.0}
    with engines(reference, spent):
        start = time.perf_counter()
        obj = source.load(params.mass)
        times.load = time.perf_counter() - start
        data = generate_object(obj, params, object_file=source.object_file, times=times)
        start = time.perf_counter()
        write_dg16m(path, data)
        times.writing = time.perf_counter() - start
    return obj, times, spent, data


def run(source: ObjectSource, params: GenerationParameters, folder: Path) -> dict:
    new_file, old_file = folder / f"{source.object_id}.h5", folder / f"{source.object_id}.ref.h5"
    obj, times, spent, data = timed_object(source, params, new_file, reference=False)
    _, old_times, old_spent, _ = timed_object(source, params, old_file, reference=True)
    counts = data.metadata["counts"]
    rng = np.random.default_rng(object_seed(params.seed, source.object_id))
    grasps = sample_antipodal_grasps(obj, n_grasps=params.n_grasps, rng=rng)
    ablation = strategy_pass_rates(grasps, rng=np.random.default_rng(params.seed))
    return {
        "object": source.object_id,
        "faces": len(obj.mesh.faces),
        "times": asdict(times) | spent,
        "total": times.total,
        "reference_times": asdict(old_times) | old_spent,
        "reference_total": old_times.total,
        "identical_file": new_file.read_bytes() == old_file.read_bytes(),
        "candidates": counts["pairs_remaining"],
        "passing": counts["passing"],
        "pass_fraction": counts["passing"] / max(counts["pairs_remaining"], 1),
        "stored": data.n,
        "ablation": ablation,
    }


def real_benchmark_meshes(ids: str, folder: Path) -> list[Path]:
    """The meshes the shipped real benchmark carries for ``ids`` (comma-separated), written to
    ``folder`` as OBJ files."""
    if not ids:
        return []
    import trimesh

    from dg16m_env.benchmark import REAL_BENCHMARK, read_benchmark

    objects = {o.object_id: o for o in read_benchmark(REAL_BENCHMARK).objects}
    paths = []
    for object_id in ids.split(","):
        if object_id not in objects:
            raise SystemExit(
                f"--real-ids: expected an object of the real benchmark, found {object_id!r}"
            )
        o = objects[object_id]
        path = folder / f"{object_id}.obj"
        trimesh.Trimesh(o.mesh_vertices, o.mesh_faces, process=False).export(path)
        paths.append(path)
    return paths


def main() -> None:
    args = parse()
    params = GenerationParameters(seed=args.seed)
    sources = [ObjectSource(p.stem, mesh=p) for p in sorted(Path(args.meshes).glob("*.obj"))]
    carried = tempfile.TemporaryDirectory()
    sources += [
        ObjectSource(path.stem, mesh=path)
        for path in real_benchmark_meshes(args.real_ids, Path(carried.name))
    ]
    airplane = REAL / "dg16m_airplane.obj"
    if airplane.is_file():
        sources.append(ObjectSource("airplane", mesh=airplane))
    real = {s.object_id for s in sources}
    sources += procedural_sources(object_specs(args.procedural, seed=args.seed))
    # Warm up the compiled kernels (force closure, jaw rays), both paths, outside the timings;
    # the meshes' convex parts (CoACD) are computed here once and read from the cache after.
    warm_up = GenerationParameters(n_grasps=20)
    with tempfile.TemporaryDirectory() as tmp:
        for source in [s for s in sources if s.object_id in real] + sources[-1:]:
            for reference in (False, True):
                timed_object(source, warm_up, Path(tmp) / "warm.h5", reference)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for source in sources:
            row = run(source, params, Path(tmp))
            rows.append(row)
            t = row["times"]
            print(
                f"{row['object']:26s} {row['faces']:6d} faces  total {row['total']:6.2f} s  "
                f"(load {t['load']:.2f}, sampling {t['sampling']:.2f} [jaw rays {t['rays']:.2f}, "
                f"collision {t['collision']:.2f}], pairing+collision {t['pairing']:.2f}, force "
                f"closure {t['force_closure']:.2f}, selection {t['selection']:.2f}, writing "
                f"{t['writing']:.2f})  reference {row['reference_total']:6.2f} s "
                f"[rays {row['reference_times']['rays']:.2f}, collision "
                f"{row['reference_times']['collision']:.2f}]  "
                f"x{row['reference_total'] / row['total']:.1f}  "
                f"{'identical file' if row['identical_file'] else 'FILES DIFFER'}  "
                f"candidates {row['candidates']}, passing {row['pass_fraction']:.3f}"
            )
    print()
    for group, members in (("real meshes", real), ("procedural", None)):
        chosen = [r for r in rows if (r["object"] in real) == (members is not None)]
        new, old = sum(r["total"] for r in chosen), sum(r["reference_total"] for r in chosen)
        print(
            f"{group}: {new / len(chosen):.2f} s per object (reference {old / len(chosen):.2f} s), "
            f"x{old / new:.1f}; {sum(r['identical_file'] for r in chosen)} of {len(chosen)} files "
            "identical"
        )
    procedural = [r for r in rows if r["object"] not in real]
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
        from dg16m_core.atomic import write_json_atomic

        write_json_atomic(Path(args.json), {"rows": rows, "mean_procedural_seconds": mean})


if __name__ == "__main__":
    main()
