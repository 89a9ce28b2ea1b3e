"""``dg16m reproduce table2|table3|fig4``: the paper's results re-run on our data, each table
(Markdown + CSV + JSON with every result record) and figure (PNG) beside the paper's numbers.

* **Table III** (pairing strategies): the reference submissions of ``dg16m baselines
  submissions`` (random, farthest and force-closure pairing, ``k`` dual grasps per object)
  scored with ``fce`` and ``gsr`` on the benchmark; object-resampled 95% intervals.
* **Table II** (classifiers trained on our labels vs DA2-style labels): each classifier
  checkpoint (:mod:`baselines.train_classifier`; the small ones shipped in
  ``baselines/checkpoints/`` by default) scored with the ``classifier`` evaluator: FCE and GSR of
  its top-k of each object's benchmark candidates, with the random ranking's expectation beside.
* **Fig. 4** (does Q(G) separate passing from failing pairs?): on the same generated train
  pairs, Q(G) split by our force-closure verdict and by DA2's keep rule
  (:mod:`baselines.da2_labels`, with the geometric zero of
  :func:`baselines.classifier_data.da2_passed`); histograms and ROC AUC. The JSON adds DA2's own
  quality (1 - l8b) split by its rule and the two verdicts' agreement.

``limit`` runs a table on the first objects of each category only (a procedural object's family,
a real object's catalogue category; a tiny configuration for tests and a quick look); the numbers
then carry wide intervals, and a table whose intervals rest on one object says so.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dg16m_core.atomic import atomic_path, write_json_atomic, write_text_atomic
from dg16m_env.benchmark.file import write_benchmark
from dg16m_env.evaluators import BenchmarkRef, load_benchmark_ref

from .pairing_baselines import BaselineError

PAPER_TABLE3 = {
    "random": {"fce": 16.33, "gsr": 23.66},
    "farthest": {"fce": 26.16, "gsr": 38.45},
    "force_closure": {"fce": 100.0, "gsr": 76.33},
}
"""The paper's Table III (percent): FCE and GSR of each pairing strategy."""

PAPER_TABLE2 = {
    ("cgdf", "dg16m"): {"fce": 88.73, "gsr": 76.34},
    ("cgdf", "da2"): {"fce": 65.25, "gsr": 54.33},
    ("pointnetgpd", "dg16m"): {"fce": 69.5, "gsr": 61.22},
    ("pointnetgpd", "da2"): {"fce": 61.8, "gsr": 53.26},
}
"""The paper's Table II (percent): FCE and GSR of each classifier's top grasps, by the labels
it was trained on."""

SHIPPED_CHECKPOINTS = Path(__file__).resolve().parent / "checkpoints"
"""The small trained checkpoints shipped with the package (``<model>-<labels>.pt``)."""


class ReproduceError(BaselineError):
    """A reproduction that cannot run (missing checkpoints or data, bad arguments)."""


def _percent(value: Any) -> str:
    if not isinstance(value, dict) or value.get("rate") is None:
        return "—"
    return f"{100 * value['rate']:.1f} [{100 * value['ci_low']:.1f}, {100 * value['ci_high']:.1f}]"


def _number(value: Any) -> float | str:
    if isinstance(value, dict) and value.get("rate") is not None:
        return round(100 * float(value["rate"]), 2)
    return ""


def _write_table(
    out: Path, stem: str, header: Sequence[str], rows: Sequence[Sequence[Any]]
) -> None:
    """``out/<stem>.md`` and ``out/<stem>.csv``, atomically."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    write_text_atomic(out / f"{stem}.md", "\n".join(lines) + "\n")
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    write_text_atomic(out / f"{stem}.csv", buffer.getvalue())


def limited_benchmark(
    out: Path, limit: int | None, benchmark: Any = None, mesh_root: Any = None
) -> BenchmarkRef:
    """The benchmark (with ``mesh_root``, the folder of a mesh benchmark's meshes when the file
    does not carry them), or (``limit``) its first ``limit`` objects per category written to
    ``out/benchmark-<limit>.h5``. A category is an object's family, or for the real benchmark's
    meshes (no family) its catalogue category in the real split
    (:meth:`~dg16m_env.benchmark.ref.BenchmarkRef.categories`); mesh objects of no known category
    are one category."""
    ref = load_benchmark_ref(benchmark, mesh_root)
    if limit is None:
        return ref
    if limit < 1:
        raise ReproduceError(f"limit: expected objects per category >= 1, found {limit}")
    taken: dict[str, int] = {}
    ids = []
    for obj, category in zip(ref.benchmark.objects, ref.categories(), strict=True):
        if taken.get(category, 0) < limit:
            taken[category] = taken.get(category, 0) + 1
            ids.append(obj.object_id)
    path = out / f"benchmark-{limit}.h5"
    with atomic_path(path) as tmp:
        write_benchmark(tmp, ref.benchmark.select_objects(ids))
    return load_benchmark_ref(path, ref.mesh_root)


def one_object_note(objects: int) -> str | None:
    """A note when the intervals rest on one object (resampling one object gives ``[x, x]``:
    no interval at all), else None."""
    if objects == 1:
        return (
            "note: every interval rests on one object (resampling one object cannot vary); "
            "use a larger --limit for intervals"
        )
    return None


def table3(
    out: str | os.PathLike[str],
    *,
    mesh_root: str | os.PathLike[str] | None = None,
    benchmark: Any = None,
    limit: int | None = None,
    k: int = 10,
    seed: int = 0,
    workers: int = 1,
    progress: bool = True,
) -> dict[str, Any]:
    """Table III (see the module docstring); returns the JSON it writes."""
    from baselines.reference_submissions import write_reference_submissions
    from dg16m_env.evaluators import submission_evaluators

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ref = limited_benchmark(out, limit, benchmark, mesh_root)
    strategies = tuple(PAPER_TABLE3)
    paths = write_reference_submissions(
        out / "submissions",
        benchmark=ref,
        mesh_root=ref.mesh_root,
        k=k,
        seed=seed,
        workers=workers,
        strategies=strategies,
        progress=progress,
    )
    results: dict[str, dict[str, Any]] = {}
    rows = []
    evaluators = submission_evaluators(
        ["fce", "gsr"], ref, workers=workers, seed=seed, progress=progress
    )
    for strategy in strategies:
        scored = {name: ev.evaluate(paths[strategy]) for name, ev in evaluators.items()}
        results[strategy] = {name: r.to_dict() for name, r in scored.items()}
        fce, gsr = scored["fce"].metrics["fce"], scored["gsr"].metrics["gsr"]
        gravity = scored["gsr"].metrics.get("gsr_gravity")
        rows.append(
            [
                strategy,
                _percent(fce),
                PAPER_TABLE3[strategy]["fce"],
                _percent(gsr),
                _percent(gravity),
                PAPER_TABLE3[strategy]["gsr"],
            ]
        )
    header = [
        "pairing",
        "FCE % (ours, 95% CI)",
        "FCE % (paper)",
        "GSR % (ours, full protocol)",
        "GSR % (ours, gravity)",
        "GSR % (paper)",
    ]
    note = one_object_note(len(ref.object_ids))
    if note is not None:
        rows.append([note, "", "", "", "", ""])
        if progress:
            print(note)
    _write_table(out, "table3", header, rows)
    payload = {
        "table": "III",
        "benchmark": ref.record(),
        "objects": len(ref.object_ids),
        "categories": sorted(set(ref.categories())),
        "note": note,
        "k": k,
        "seed": seed,
        "paper": PAPER_TABLE3,
        "results": results,
    }
    write_json_atomic(out / "table3.json", payload)
    return payload


def checkpoint_paths(folder: str | os.PathLike[str] | None) -> dict[tuple[str, str], Path]:
    """``(model, labels) -> path`` of the ``<model>-<labels>.pt`` files in ``folder`` (default:
    the shipped checkpoints).

    Raises:
        ReproduceError: no checkpoint there.
    """
    folder = Path(folder) if folder is not None else SHIPPED_CHECKPOINTS
    found = {}
    for path in sorted(folder.glob("*.pt")) if folder.is_dir() else []:
        model, _, labels = path.stem.partition("-")
        if (model, labels) in PAPER_TABLE2:
            found[(model, labels)] = path
    if not found:
        raise ReproduceError(
            f"{folder}: expected classifier checkpoints <model>-<labels>.pt (e.g. cgdf-dg16m.pt, "
            "written by python -m baselines.train_classifier), found none"
        )
    return found


def table2(
    out: str | os.PathLike[str],
    *,
    mesh_root: str | os.PathLike[str] | None = None,
    checkpoints: str | os.PathLike[str] | None = None,
    benchmark: Any = None,
    limit: int | None = None,
    k: int = 10,
    progress: bool = True,
) -> dict[str, Any]:
    """Table II (see the module docstring); returns the JSON it writes."""
    from baselines.grasp_geometry import load_checkpoint
    from dg16m_env.evaluators import make

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    found = checkpoint_paths(checkpoints)
    ref = limited_benchmark(out, limit, benchmark, mesh_root)
    evaluator = make("classifier", benchmark=ref, k=k, progress=progress)
    results, rows, chance = {}, [], None
    for (model, labels), path in found.items():
        classifier, extra = load_checkpoint(path)
        result = evaluator.evaluate(classifier)
        results[f"{model}-{labels}"] = {
            "checkpoint": str(path),
            "training": extra,
            **result.to_dict(),
        }
        metrics = result.metrics
        chance = result.details.get("chance", chance)
        paper = PAPER_TABLE2[(model, labels)]
        rows.append(
            [
                model,
                labels,
                _percent(metrics.get(f"fce_top{k}")),
                paper["fce"],
                _percent(metrics.get(f"gsr_top{k}_full")),
                paper["gsr"],
                _percent(metrics.get("ap_full")),
            ]
        )
    if isinstance(chance, dict):
        rows.append(
            [
                "random ranking (expected)",
                "—",
                _chance(chance, f"fce_top{k}"),
                "—",
                _chance(chance, f"gsr_top{k}_full"),
                "—",
                _chance(chance, "ap_full"),
            ]
        )
    header = [
        "classifier",
        "trained on",
        f"FCE top-{k} % (ours)",
        "FCE % (paper)",
        f"GSR top-{k} % (ours)",
        "GSR % (paper)",
        "AP (ours)",
    ]
    _write_table(out, "table2", header, rows)
    payload = {
        "table": "II",
        "benchmark": ref.record(),
        "objects": len(ref.object_ids),
        "k": k,
        "paper": {f"{m}-{lab}": v for (m, lab), v in PAPER_TABLE2.items()},
        "results": results,
    }
    write_json_atomic(out / "table2.json", payload)
    return payload


def _chance(chance: dict[str, Any], key: str) -> str:
    """A random ranking's expected rate (the classifier evaluator's ``details["chance"]``)."""
    value = chance.get(key)
    return f"{100 * value:.1f}" if isinstance(value, (int, float)) else "—"


def fig4(
    out: str | os.PathLike[str],
    *,
    data: str | os.PathLike[str] | None = None,
    objects: int = 20,
    seed: int = 0,
    workers: int = 1,
    progress: bool = True,
) -> dict[str, Any]:
    """Fig. 4 (see the module docstring): from the generated files in ``data``, or from
    ``objects`` procedural train objects generated into ``out/data`` first."""
    from baselines.classifier_data import da2_passed, grasp_files
    from baselines.da2_labels import GEOMETRIC_ZERO, agreement, da2_labels_for_file, fig4_figure
    from baselines.da2_labels import quality_separation as separation
    from dataset_gen.io import read_dg16m

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if data is None:
        from dataset_gen.pipeline.generate import GenerationParameters, generate_dataset
        from dataset_gen.sources.object_source import procedural_sources
        from dataset_gen.sources.procedural import object_specs

        data = out / "data"
        generate_dataset(
            procedural_sources(object_specs(objects, seed=seed, split="train")),
            data,
            GenerationParameters(seed=seed),
            workers=workers,
            progress=progress,
        )
    quality, ours, da2, da2_quality = [], [], [], []
    for path in grasp_files(data):
        grasps = read_dg16m(path)
        if "quality" not in grasps.extras:
            raise ReproduceError(f"{path}: expected our Q(G) in extras['quality'], found none")
        passed = np.zeros(len(grasps.grasps), dtype=bool)
        passed[grasps.passing_indices] = True
        verdict = da2_labels_for_file(grasps, zero_tol=GEOMETRIC_ZERO)
        quality.append(np.asarray(grasps.extras["quality"], dtype=np.float64))
        ours.append(passed)
        da2.append(da2_passed(grasps))
        da2_quality.append(np.asarray(verdict.quality, dtype=np.float64))
    q, p_ours, p_da2 = np.concatenate(quality), np.concatenate(ours), np.concatenate(da2)
    q_da2 = np.concatenate(da2_quality)
    figure = fig4_figure(
        (q, p_ours), (q, p_da2), xlabels=("Q(G) = sqrt(det(G G^T))", "Q(G) = sqrt(det(G G^T))")
    )
    with atomic_path(out / "fig4.png") as tmp:
        figure.savefig(tmp, format="png", dpi=130)
    payload = {
        "figure": "4",
        "pairs": int(q.size),
        "files": len(quality),
        "q_by_dg16m_label": separation(q, p_ours),
        "q_by_da2_label": separation(q, p_da2),
        "da2_quality_by_da2_label": separation(q_da2, p_da2),
        "agreement": agreement(p_ours, p_da2),
    }
    write_json_atomic(out / "fig4.json", payload)
    return payload
