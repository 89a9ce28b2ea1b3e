"""The real-object benchmark: 300 furniture models from Debian's ``sweethome3d-furniture``.

Where the objects come from: ``dg16m objects import-sweethome3d`` (:mod:`dataset_gen.real.sweethome3d`)
writes a folder of repaired, decimated meshes in metres with a ``manifest.json`` (source,
creator, licence, sha256 of every OBJ file) and ``ATTRIBUTION.md``.

The split (:data:`REAL_SPLIT_FILE`, shipped in the package, format ``dg16m-real-split``)
--------------------------------------------------------------------------------------------
:func:`make_split` orders the imported objects of each catalogue category by a seeded
permutation (``seed``) and gives each category a quota of the ``size`` benchmark objects in
proportion to its share of the imported objects (largest remainders). The benchmark is the
first ``quota`` objects of each category's order that the build admits (a category that runs
out of objects leaves its places to those with the most left, :func:`chosen_ids`); the training
split is every other imported object that the build did not reject. Keys::

    {"format": "dg16m-real-split", "schema_version": 1, "source": "...", "seed": 0,
     "size": 300, "categories": {"<category>": {"quota": q, "order": [id, ...]}, ...},
     "benchmark": [id, ...], "train": [id, ...],
     "rejected": {id: {"stage": "...", "reason": "...", "error": "..."}},
     "import_failed": {id: "error"}, "sha256": {id: "<sha256 of the OBJ file>"},
     "revisions": [{"revision": n, "note": "...", "added": [id, ...], "removed": [id, ...],
                    "changed_sha256": [id, ...]}, ...]}

``revisions`` (absent in a split never revised) lists each :func:`revise_split`: a revised import
keeps every order as a prefix, rejects the ids it refuses at stage ``"import"`` and appends its
new ids, so a build's finished objects keep their places.

The build (:func:`build_real_benchmark`)
----------------------------------------
``dg16m benchmark build-real --meshes DIR --out OUT`` builds the benchmark split with
:data:`REAL_PARAMETERS` (the paper's four arms and ``fc_robust``, K = 8) under
:data:`REAL_LIMITS`: an object that gives fewer than ``min_passing`` force-closure-passing
pairs (checked before its decomposition and before its trials) or whose decomposition,
sampling or trials run past their budgets is rejected with its stage and replaced by the next
object of its category's order; so is a built object whose hulls stand off its mesh by more
than :data:`MAX_HULL_P95_MM` (p95). Each mesh must match the sha256 the split records (a changed
mesh is an error, never a silent relabel); the file carries every mesh, so using it needs no
mesh folder. The build resumes (``OUT/manifest.json``); the split it ends with is written to
``OUT/real_split.json`` (copy it over :data:`REAL_SPLIT_FILE` with the file to ship both).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dataset_gen.io.manifest import read_manifest, write_manifest
from dataset_gen.objects.decomposition import DecompositionParameters
from dataset_gen.real.sweethome3d import attribution_text
from dataset_gen.sources.object_source import ObjectSource, object_seed
from dg16m_core.atomic import write_bytes_atomic, write_json_atomic, write_text_atomic
from dg16m_core.hashing import file_sha256
from dg16m_env.benchmark.build import (
    BuildLimits,
    build_objects,
    build_parameters,
    write_built_benchmark,
)
from dg16m_env.benchmark.model import BenchmarkError, BenchmarkParameters
from dg16m_env.benchmark.sources import BenchmarkSource
from dg16m_env.physics.simulator import Simulator, check_simulator

DATA = Path(__file__).parents[1] / "data"
REAL_SPLIT_FILE = DATA / "real_split.json"
"""The real benchmark's split, shipped with the package."""

REAL_BENCHMARK = DATA / "benchmark_real.h5"
"""The real benchmark file, shipped with the package once built."""

SPLIT_FORMAT = "dg16m-real-split"
SPLIT_SCHEMA_VERSION = 1

REAL_SIZE = 300
"""Objects in the real benchmark (the paper's 300)."""

REAL_DECOMPOSITION = DecompositionParameters(
    threshold=0.01, resolution=1000, mcts_iterations=60, mcts_nodes=12, mcts_max_depth=2
)
"""CoACD for the real benchmark: the default threshold (0.01) with a third of the default
search. On two repaired furniture meshes (an armchair and a bath) it gave the same hulls' fidelity
as the defaults (hull-to-mesh p95 2.34 / 0.96 mm against 2.31 / 1.01) in 18 / 27 s against
58 / 42 s; a coarser threshold is faster but not faithful (0.02: p95 6.5 mm on the armchair;
0.015: 4.1 mm)."""

HULL_GRID = 5e-5
"""The real benchmark's hull grid (m): CoACD's hull vertices are rounded to 0.05 mm multiples
before sampling and trials and stored as int32 (29 KB per object against float32's 60 KB,
shuffled and compressed, on 40 built objects; hulls were 53% of a built object's bytes)."""

REAL_PARAMETERS = BenchmarkParameters(
    n_robust=20, decomposition=REAL_DECOMPOSITION, hull_grid=HULL_GRID
)
"""The real benchmark's parameters: the defaults (200 grasps; 40 fc_pass, 20 fc_fail, 20
random, 20 farthest pairs per object; K = 8 perturbations), 20 ``fc_robust`` pairs,
:data:`REAL_DECOMPOSITION`, and hulls on :data:`HULL_GRID`."""

REAL_LIMITS = BuildLimits(min_passing=40, decompose_s=180.0, sample_s=120.0, label_s=240.0)
"""What the real build admits: 40 passing pairs (all ``n_passing``) and, per object, 180 CPU
seconds of decomposition, 120 of sampling and pairing and 240 of trials."""

MESH_LIMITS = REAL_LIMITS
"""What ``dg16m benchmark build --meshes`` admits by default: :data:`REAL_LIMITS`, CPU budgets
only, so that the same mesh gets the same verdict at any machine load (a stage also stops at
:data:`~dg16m_core.budget.WALL_FACTOR` times its budget in wall time, a safety net). From
2026-12-05 to 2026-12-06 it also bounded each object to 10 minutes of wall time, which a loaded
machine turned into rejections a quiet one did not make; builds started then are not resumed
with these limits (their manifests record ``object_wall_s``)."""


def _category(entry: Mapping[str, Any]) -> str:
    return str(entry["source"]["category"])


def import_entries(meshes: str | os.PathLike[str]) -> dict[str, Any]:
    """The ``manifest.json`` entries of an import folder.

    Raises:
        BenchmarkError: no folder or no import manifest in it.
    """
    path = Path(meshes) / "manifest.json"
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise BenchmarkError(
            f"--meshes: expected a folder written by 'dg16m objects import-sweethome3d' with "
            f"manifest.json, found {type(exc).__name__}: {exc}"
        ) from None
    if manifest.get("kind") != "sweethome3d-import":
        raise BenchmarkError(
            f"{path}: expected an import manifest (kind 'sweethome3d-import'), found kind "
            f"{manifest.get('kind')!r}"
        )
    return dict(manifest["entries"])


def make_split(
    entries: Mapping[str, Mapping[str, Any]], *, size: int = REAL_SIZE, seed: int = 0
) -> dict[str, Any]:
    """A fresh split of an import's objects (see the module docstring).

    Raises:
        BenchmarkError: fewer imported objects than ``size``.
    """
    ok = {k: e for k, e in entries.items() if e.get("status") == "ok"}
    if len(ok) < size:
        raise BenchmarkError(f"expected at least {size} imported objects, found {len(ok)}")
    by_category: dict[str, list[str]] = {}
    for object_id in sorted(ok):
        by_category.setdefault(_category(ok[object_id]), []).append(object_id)
    quota = _quotas({c: len(ids) for c, ids in by_category.items()}, size)
    categories = {}
    for c in sorted(by_category):
        rng = np.random.default_rng(object_seed(seed, f"real-split:{c}"))
        order = [by_category[c][i] for i in rng.permutation(len(by_category[c]))]
        categories[c] = {"quota": quota[c], "order": order}
    split = {
        "format": SPLIT_FORMAT,
        "schema_version": SPLIT_SCHEMA_VERSION,
        "source": "Debian sweethome3d-furniture 1.8-1 via dg16m objects import-sweethome3d",
        "seed": int(seed),
        "size": int(size),
        "categories": categories,
        "rejected": {},
        "import_failed": {
            k: str(e.get("error", "")) for k, e in sorted(entries.items()) if k not in ok
        },
        "sha256": {k: str(ok[k]["sha256"]) for k in sorted(ok)},
    }
    return with_membership(split)


def _quotas(counts: Mapping[str, int], size: int) -> dict[str, int]:
    """``size`` places shared in proportion to ``counts`` (largest remainders; ties by name)."""
    total = sum(counts.values())
    shares = {c: size * n / total for c, n in counts.items()}
    quota = {c: int(np.floor(v)) for c, v in shares.items()}
    left = size - sum(quota.values())
    for c in sorted(shares, key=lambda c: (-(shares[c] - quota[c]), c))[:left]:
        quota[c] += 1
    return quota


def revise_split(
    split: Mapping[str, Any], entries: Mapping[str, Mapping[str, Any]], *, note: str
) -> dict[str, Any]:
    """``split`` brought up to date with a revised import (``entries``), keeping every order it
    has, so that objects already built keep their places:

    * an ordered id the import now fails (or lost) is rejected at stage ``"import"`` with the
      import's error;
    * an ordered id whose OBJ bytes changed is kept with its new sha256 and listed (its build,
      if any, is stale and must be redone);
    * imported ids that no order holds are appended to their category's order in a seeded
      permutation (a new category gets one), after every id already there;
    * quotas are shared again in proportion to the imported objects per category.

    The change is recorded under ``revisions`` (with ``note``).

    Raises:
        BenchmarkError: fewer usable imported objects than the split's size.
    """
    out = check_split(dict(split))  # a copy: the caller's split is left as it was
    ok = {k: e for k, e in entries.items() if e.get("status") == "ok"}
    if len(ok) < out["size"]:
        raise BenchmarkError(f"expected at least {out['size']} imported objects, found {len(ok)}")
    revision = len(out.get("revisions", [])) + 1
    rejected = dict(out["rejected"])
    categories = {
        c: {"quota": v["quota"], "order": list(v["order"])} for c, v in out["categories"].items()
    }
    ordered = {i for c in categories.values() for i in c["order"]}
    removed = sorted(i for i in ordered if i not in ok and i not in rejected)
    for object_id in removed:
        error = str(entries.get(object_id, {}).get("error", "not in the import"))
        rejected[object_id] = {"stage": "import", "reason": "import failed", "error": error}
    old_sha = out["sha256"]
    changed = sorted(i for i in ordered if i in ok and old_sha.get(i) != ok[i]["sha256"])
    added: dict[str, list[str]] = {}
    for object_id in sorted(set(ok) - ordered):
        added.setdefault(_category(ok[object_id]), []).append(object_id)
    for c, ids in sorted(added.items()):
        rng = np.random.default_rng(object_seed(out["seed"], f"real-split-revision-{revision}:{c}"))
        categories.setdefault(c, {"quota": 0, "order": []})["order"] += [
            ids[i] for i in rng.permutation(len(ids))
        ]
    counts = {c: sum(i in ok for i in v["order"]) for c, v in categories.items()}
    for c, quota in _quotas(counts, out["size"]).items():
        categories[c]["quota"] = quota
    out["categories"] = {c: categories[c] for c in sorted(categories)}
    out["rejected"] = rejected
    out["import_failed"] = {
        k: str(e.get("error", ""))
        for k, e in sorted(entries.items())
        if k not in ok and k not in ordered
    }
    out["sha256"] = {
        **{k: v for k, v in old_sha.items() if k not in removed},
        **{k: str(ok[k]["sha256"]) for k in sorted(ok)},
    }
    out["revisions"] = [
        *out.get("revisions", []),
        {
            "revision": revision,
            "note": note,
            "added": sorted(i for ids in added.values() for i in ids),
            "removed": removed,
            "changed_sha256": changed,
        },
    ]
    return with_membership(out)


def chosen_ids(split: Mapping[str, Any]) -> list[str]:
    """The benchmark objects: per category (sorted), the first ``quota`` ids of its order that
    are not rejected. A category whose order runs out (every other object rejected) leaves its
    unfilled places to the categories with the most objects left (ties: by name), one place at a
    time, so the benchmark keeps its size while any object is left."""
    rejected = split["rejected"]
    kept = {
        name: [i for i in category["order"] if i not in rejected]
        for name, category in split["categories"].items()
    }
    take = {name: min(c["quota"], len(kept[name])) for name, c in split["categories"].items()}
    deficit = sum(c["quota"] for c in split["categories"].values()) - sum(take.values())
    while deficit > 0:
        spare = {
            name: len(kept[name]) - take[name] for name in kept if len(kept[name]) > take[name]
        }
        if not spare:
            break
        name = min(spare, key=lambda n: (-spare[n], n))
        take[name] += 1
        deficit -= 1
    return [i for name in sorted(kept) for i in kept[name][: take[name]]]


def with_membership(split: Mapping[str, Any]) -> dict[str, Any]:
    """``split`` with ``benchmark`` (:func:`chosen_ids`) and ``train`` (every other ordered,
    not rejected id, sorted) filled in."""
    out = dict(split)
    benchmark = chosen_ids(split)
    members = set(benchmark)
    ordered = [i for c in split["categories"].values() for i in c["order"]]
    out["benchmark"] = benchmark
    out["train"] = sorted(i for i in ordered if i not in members and i not in split["rejected"])
    return out


def check_split(split: Any, where: str = "split") -> dict[str, Any]:
    """``split`` if it is a well-formed split (module docstring), else :class:`BenchmarkError`."""
    if not isinstance(split, dict) or split.get("format") != SPLIT_FORMAT:
        found = split.get("format") if isinstance(split, dict) else type(split).__name__
        raise BenchmarkError(f"{where}: expected format {SPLIT_FORMAT!r}, found {found!r}")
    if split.get("schema_version") != SPLIT_SCHEMA_VERSION:
        raise BenchmarkError(
            f"{where}: expected schema_version {SPLIT_SCHEMA_VERSION}, found "
            f"{split.get('schema_version')!r}"
        )
    for key in ("categories", "benchmark", "train", "rejected", "sha256"):
        if key not in split:
            raise BenchmarkError(f"{where}: expected key {key!r}, found it missing")
    overlap = set(split["benchmark"]) & set(split["train"])
    if overlap:
        raise BenchmarkError(
            f"{where}: expected disjoint benchmark and train ids, found {sorted(overlap)[:5]} in both"
        )
    return split


def read_split(path: str | os.PathLike[str] = REAL_SPLIT_FILE) -> dict[str, Any]:
    """The split at ``path`` (default: the shipped one), checked.

    Raises:
        BenchmarkError: missing or malformed.
    """
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise BenchmarkError(
            f"{path}: expected a real-benchmark split (JSON), found {type(exc).__name__}: {exc}"
        ) from None
    return check_split(data, str(path))


def write_split(path: str | os.PathLike[str], split: Mapping[str, Any]) -> None:
    """Write ``split`` atomically (sorted keys, so equal splits give equal bytes)."""
    write_json_atomic(path, check_split(with_membership(split), str(path)))


def real_sources(
    meshes: str | os.PathLike[str], ids: Sequence[str], split: Mapping[str, Any]
) -> list[BenchmarkSource]:
    """Sources for ``ids`` from an import folder, each OBJ checked against the sha256 the split
    records (and then hashed as arrays into the benchmark file).

    Raises:
        BenchmarkError: missing meshes (all named, with the import command that makes them), or
            one whose bytes differ from the recorded hash.
    """
    root = Path(meshes)
    missing = [i for i in ids if not (root / f"{i}.obj").is_file()]
    if missing:  # e.g. replacements of rejected objects, beyond what a partial import holds
        raise BenchmarkError(
            f"{root}: expected a mesh for each of the {len(ids)} objects to build, found none for "
            f"{len(missing)} ({', '.join(missing[:3])}{', ...' if len(missing) > 3 else ''}); "
            f"import them: dg16m objects import-sweethome3d --out {root} --ids " + ",".join(missing)
        )
    out = []
    for object_id in ids:
        path = root / f"{object_id}.obj"
        expected = split["sha256"].get(object_id)
        found = file_sha256(path)
        if expected != found:
            raise BenchmarkError(
                f"{object_id}: expected {path} with sha256 {expected}, found {found} (the mesh "
                "changed since the split was made: re-import it or make a new split)"
            )
        out.append(BenchmarkSource(ObjectSource(object_id, mesh=path, allow_any_size=False)))
    return out


def build_real_benchmark(
    meshes: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    split: Mapping[str, Any] | None = None,
    params: BenchmarkParameters = REAL_PARAMETERS,
    limits: BuildLimits = REAL_LIMITS,
    limit: int | None = None,
    workers: int = 1,
    progress: bool = True,
    simulator: Simulator | str | None = None,
) -> tuple[Path, dict[str, Any]]:
    """Build (or resume) the real benchmark in ``out`` with replacements (module docstring).

    A resumed build replaces the objects its folder already rejected without building them
    again (their entries in ``manifest.json`` stay as they are).

    Args:
        meshes: the import folder.
        out: the build folder (``manifest.json``, ``objects/``, ``benchmark.h5``,
            ``real_split.json``).
        split: the split to start from (default: the shipped one).
        limit: build only the first ``limit`` benchmark objects (a pilot; replacements too).

    Returns:
        ``(benchmark.h5, the split the build ended with)``.
    """
    simulator = check_simulator(simulator)
    simulator.check_available()
    split = dict(check_split(dict(split if split is not None else read_split())))
    split["rejected"] = dict(split["rejected"])
    root = Path(out)
    parameters = build_parameters([], params, simulator, limits)
    forget_stale_objects(root, split)
    # Resuming: objects this folder already rejected stay rejected (replaced, not retried;
    # their failures are deterministic or ran past a budget).
    previous = read_manifest(root)["entries"] if (root / "manifest.json").is_file() else {}
    while new := rejections(previous, chosen_ids(split)):
        split["rejected"].update(new)
    while True:
        ids = chosen_ids(split)
        if limit is not None:
            ids = _first_per_category(split, limit)
        sources = real_sources(meshes, ids, split)  # each file checked against the split's hash
        _record_sources(root, ids, split)
        manifest = build_objects(
            sources,
            root,
            params,
            simulator=simulator,
            limits=limits,
            workers=workers,
            progress=progress,
            parameters=parameters,
        )
        new = rejections(manifest["entries"], ids)
        split["rejected"].update(new)
        if not new:
            break
    split = with_membership(split)
    if limit is not None:
        split["benchmark"] = ids
    write_json_atomic(root / "real_split.json", split)
    path = write_built_benchmark(root, ids, manifest, params, simulator)
    built = [i for i in ids if manifest["entries"].get(i, {}).get("status") == "ok"]
    write_text_atomic(root / ATTRIBUTION_FILE, benchmark_attribution(meshes, built))
    return path, split


ATTRIBUTION_FILE = "ATTRIBUTION.md"
"""The attribution a build writes beside its ``benchmark.h5`` (CC-BY-3.0 asks for creator,
licence and what was modified); shipped as :data:`REAL_ATTRIBUTION`."""

REAL_ATTRIBUTION = DATA / ATTRIBUTION_FILE
"""The shipped real benchmark's attribution."""


def benchmark_attribution(meshes: str | os.PathLike[str], ids: Sequence[str]) -> str:
    """``ATTRIBUTION.md`` for the objects ``ids`` of a real benchmark file, from the import
    folder's manifest (source library, model, creator, licence, modification of each).

    Raises:
        BenchmarkError: an id the import does not hold, or holds without its source record.
    """
    entries = import_entries(meshes)
    missing = [i for i in ids if entries.get(i, {}).get("status") != "ok"]
    if missing:
        raise BenchmarkError(
            f"{meshes}: expected an imported object for every benchmark id, found none for "
            f"{', '.join(missing[:5])}"
            + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
        )
    chosen = [entries[i] for i in ids]
    fields = ("library", "name", "model", "creator", "licence", "licence_files")
    for object_id, entry in zip(ids, chosen, strict=True):
        lacking = [f for f in fields if f not in entry.get("source", {})]
        if lacking or "modified" not in entry:
            raise BenchmarkError(
                f"{meshes}/manifest.json: {object_id}: expected the source record of an import "
                f"(source.{', source.'.join(fields)}, modified), found it without "
                + ", ".join(
                    [f"source.{f}" for f in lacking] + ([] if "modified" in entry else ["modified"])
                )
            )
    return attribution_text(
        chosen,
        subject="The meshes carried in the benchmark file beside this one",
        note=(
            f"The benchmark file (`benchmark.h5` of a `dg16m benchmark build-real` build, "
            f"`benchmark_real.h5` as shipped in the package) carries these {len(ids)} meshes "
            "(repaired and decimated as stated), their CoACD convex hulls and their labelled dual "
            "grasps. Rebuilding it needs the Debian package: `apt-get install -y "
            "sweethome3d-furniture`."
        ),
    )


SOURCES_FILE = "sources.json"
"""In a build folder: the sha256 of the mesh file each object was (or is being) built from."""


def _record_sources(root: Path, ids: Sequence[str], split: Mapping[str, Any]) -> None:
    path = root / SOURCES_FILE
    built_from = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    built_from.update({i: split["sha256"][i] for i in ids})
    root.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, dict(sorted(built_from.items())))


def forget_stale_objects(root: str | os.PathLike[str], split: Mapping[str, Any]) -> list[str]:
    """Forget the objects of a build folder that were built from other mesh bytes than the
    split records now (a revised import, :func:`revise_split`): their manifest entries are
    removed, so the build makes them again instead of reusing them. Returns their ids."""
    folder = Path(root)
    path = folder / SOURCES_FILE
    if not (path.is_file() and (folder / "manifest.json").is_file()):
        return []
    built_from = json.loads(path.read_text(encoding="utf-8"))
    manifest = read_manifest(folder)
    stale = sorted(
        i
        for i in manifest["entries"]
        if i in built_from and built_from[i] != split["sha256"].get(i)
    )
    if stale:
        for object_id in stale:
            del manifest["entries"][object_id]
        write_manifest(folder, manifest)
    return stale


MAX_HULL_P95_MM = 2.0
"""The real benchmark admits an object whose CoACD hulls stand off its mesh by at most this
much (hull-to-mesh p95, mm; the build's manifest records it per object): a coarser one is
rejected at the decomposition stage and replaced like any other."""


def rejections(entries: Mapping[str, Any], ids: Sequence[str]) -> dict[str, dict[str, str]]:
    """The objects of ``ids`` the build rejects, by id: those that failed (their stage and
    reason) and those built whose hull-to-mesh p95 is over :data:`MAX_HULL_P95_MM`."""
    out: dict[str, dict[str, str]] = {}
    for object_id in ids:
        entry = entries.get(object_id, {})
        if entry.get("status") == "failed":
            out[object_id] = {
                "stage": entry.get("stage", "load"),
                "reason": entry.get("rejected", "error"),
                "error": entry.get("error", ""),
            }
            continue
        p95 = entry.get("hull_deviation_mm", {}).get("p95") if entry.get("status") == "ok" else None
        if p95 is not None and p95 > MAX_HULL_P95_MM:
            out[object_id] = {
                "stage": "decompose",
                "reason": "hull deviation",
                "error": f"{object_id}: expected hull-to-mesh p95 <= {MAX_HULL_P95_MM:g} mm, "
                f"found {p95:g} mm",
            }
    return out


def _first_per_category(split: Mapping[str, Any], limit: int) -> list[str]:
    """A pilot's ids: the chosen ids taken round-robin over the categories, ``limit`` of them."""
    chosen = chosen_ids(split)
    by_category: dict[str, list[str]] = {}
    cat_of = {i: c for c, v in split["categories"].items() for i in v["order"]}
    for object_id in chosen:
        by_category.setdefault(cat_of[object_id], []).append(object_id)
    out: list[str] = []
    depth = 0
    while len(out) < limit and any(depth < len(v) for v in by_category.values()):
        for name in sorted(by_category):
            if depth < len(by_category[name]) and len(out) < limit:
                out.append(by_category[name][depth])
        depth += 1
    return out


def ship_real_benchmark(
    build: str | os.PathLike[str], *, to: str | os.PathLike[str] = DATA, size: int = REAL_SIZE
) -> list[Path]:
    """Check a finished ``build-real`` folder and copy its benchmark file, split and attribution
    into ``to`` (the package's data folder by default) as :data:`REAL_BENCHMARK`,
    :data:`REAL_SPLIT_FILE` and :data:`REAL_ATTRIBUTION`, each atomically.

    Checked first (nothing is copied unless all hold): the three files are there; the split is
    well formed; the file reads (every carried mesh matches its stored hash) and holds exactly
    the split's ``size`` benchmark objects in its order, each with its mesh and convex parts;
    the attribution names every one of them.

    Returns:
        The paths written.

    Raises:
        BenchmarkError: naming the first check that failed.
    """
    from dg16m_env.benchmark.file import read_benchmark
    from dg16m_env.benchmark.model import BENCHMARK_FILE

    root = Path(build)
    names = (BENCHMARK_FILE, REAL_SPLIT_FILE.name, ATTRIBUTION_FILE)
    absent = [n for n in names if not (root / n).is_file()]
    if absent:
        raise BenchmarkError(
            f"{root}: expected a finished 'dg16m benchmark build-real' folder with "
            f"{', '.join(names)}, found no {', '.join(absent)}"
        )
    split = read_split(root / REAL_SPLIT_FILE.name)
    bench = read_benchmark(root / BENCHMARK_FILE)
    ids = [o.object_id for o in bench.objects]
    if len(split["benchmark"]) != size or ids != split["benchmark"]:
        raise BenchmarkError(
            f"{root}: expected {size} benchmark objects in the file, in the split's order, found "
            f"{len(ids)} in the file and {len(split['benchmark'])} in the split"
            + ("" if set(ids) == set(split["benchmark"]) else " (different ids)")
        )
    bare = [o.object_id for o in bench.objects if not (o.has_mesh and o.parts)]
    if bare:
        raise BenchmarkError(
            f"{root / BENCHMARK_FILE}: expected every object to carry its mesh and convex parts, "
            f"found {len(bare)} without: {', '.join(bare[:5])}"
        )
    attribution = (root / ATTRIBUTION_FILE).read_text(encoding="utf-8")
    unnamed = [i for i in ids if f"| {i} |" not in attribution]
    if unnamed:
        raise BenchmarkError(
            f"{root / ATTRIBUTION_FILE}: expected a row for every benchmark object, found none "
            f"for {len(unnamed)}: {', '.join(unnamed[:5])}"
        )
    target = Path(to)
    written = []
    for name, destination in zip(
        names, (REAL_BENCHMARK.name, REAL_SPLIT_FILE.name, REAL_ATTRIBUTION.name), strict=True
    ):
        write_bytes_atomic(target / destination, (root / name).read_bytes())
        written.append(target / destination)
    return written
