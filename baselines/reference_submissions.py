"""Reference submissions: one submission file per pairing baseline, for a benchmark.

:func:`write_reference_submissions` writes to ``out_dir``:

``random.h5``, ``farthest.h5``, ``force_closure.h5``
    the :class:`~baselines.pairing_baselines.PairingBaseline` predictions for every benchmark
    object, run in process (trusted code) on the object's observation
    (:func:`dg16m_env.subjects.observation.object_observation`) with the benchmark's parameters (grasp
    count, friction, pruning distance, mass, gravity, force bound, threshold). The grasps are
    sampled once per object and shared by the three strategies (the same result as calling
    each predictor). Objects run in parallel with :func:`dataset_gen.pipeline.parallel.run_tasks`; the
    files do not depend on ``workers``.
``benchmark_fc_pass.h5``
    the benchmark's own stored ``fc_pass`` rows: the first ``k`` per object in stored order,
    scores ``-fc_loss``.

Each file records ``benchmark`` (``"embedded"`` for the shipped benchmark, else its sha256) and
``metadata = {"baseline", "k", "seed", "created_by"}`` (``n_grasps`` too for the sampled ones).

Command line: ``dg16m baselines submissions --out DIR`` or
``python -m baselines.reference_submissions --out DIR [--k 10] [--workers 2] [--benchmark PATH]
[--strategies a,b]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from baselines.pairing_baselines import PAIRING_STRATEGIES, BaselineError, PairingBaseline
from baselines.submission_arguments import DEFAULT_STRATEGIES, add_submission_arguments
from dataset_gen.io import package_version
from dataset_gen.pipeline.parallel import check_backend, run_tasks
from dg16m_core.checks import check_integer
from dg16m_core.errors import Dg16mError
from dg16m_core.progress import progress_bar
from dg16m_env.benchmark.model import SOURCES, Benchmark, BenchmarkObject
from dg16m_env.benchmark.ref import BenchmarkRef, load_benchmark_ref
from dg16m_env.subjects.observation import object_observation
from dg16m_env.subjects.submission import EMBEDDED
from dg16m_env.subjects.submission_reader import validate_submission
from dg16m_env.subjects.submission_writer import write_submission

STORED_STRATEGIES: tuple[str, ...] = ("benchmark_fc_pass",)
"""Reference submissions taken from the benchmark's stored rows (no sampling)."""

STRATEGIES: tuple[str, ...] = (*PAIRING_STRATEGIES, *STORED_STRATEGIES)
"""Every reference submission :func:`write_reference_submissions` can write."""

Prediction = tuple[np.ndarray, np.ndarray]
"""``poses (K, 2, 4, 4)`` (object frame, m) and ``scores (K,)``."""


class ReferenceSubmissionError(BaselineError):
    """Some baseline yielded no grasp on some object: its file was not written.

    Attributes:
        written: the files that were written (name -> path).
        failures: baseline name -> object id -> error message.
    """

    def __init__(self, written: dict[str, Path], failures: dict[str, dict[str, str]]) -> None:
        self.written = written
        self.failures = failures
        lines = [
            f"{name}: expected a dual grasp on every object, found {len(errors)} failed "
            f"(not written), e.g. {next(iter(errors))}: {next(iter(errors.values()))}"
            for name, errors in failures.items()
        ]
        lines += [f"wrote {path}  ({name})" for name, path in written.items()]
        super().__init__("\n".join(lines))


def parse_strategies(text: str | Sequence[str]) -> tuple[str, ...]:
    """Baseline names from ``"a,b,c"`` or a sequence, checked (known, no repeats, at least one).

    Raises:
        BaselineError: an unknown or repeated name, or none.
    """
    names = [s.strip() for s in text.split(",")] if isinstance(text, str) else list(text)
    names = [n for n in names if n]
    if not names:
        raise BaselineError(f"--strategies: expected names among {STRATEGIES}, found none")
    unknown = [n for n in names if n not in STRATEGIES]
    if unknown:
        raise BaselineError(f"--strategies: expected names among {STRATEGIES}, found {unknown}")
    if len(set(names)) != len(names):
        raise BaselineError(f"--strategies: expected each name once, found {names}")
    return tuple(names)


def reference_baselines(
    ref: BenchmarkRef,
    strategies: Sequence[str] = PAIRING_STRATEGIES,
    *,
    k: int = 10,
    seed: int = 0,
    n_grasps: int | None = None,
) -> list[PairingBaseline]:
    """The pairing baselines with the benchmark's parameters (``n_grasps`` defaults to the
    benchmark's), one per pairing strategy in ``strategies`` (other names are skipped)."""
    params = ref.benchmark.parameters()
    base = PairingBaseline(
        "random",
        k=k,
        n_grasps=params.n_grasps if n_grasps is None else n_grasps,
        seed=seed,
        min_center_distance=params.min_center_distance,
        **params.force_closure_kwargs(),  # mass, gravity, mu, f_high, threshold
    )
    return [replace(base, strategy=s) for s in strategies if s in PAIRING_STRATEGIES]


def predict_object(
    item: BenchmarkObject, mesh_root: str | None, baselines: Sequence[PairingBaseline]
) -> dict[str, Prediction | str]:
    """Run several pairing baselines on one benchmark object (a task of
    :func:`dataset_gen.pipeline.parallel.run_tasks`); they must share ``seed``, ``n_grasps`` and ``mu``.

    Returns:
        baseline name -> its prediction, or a message when the object or the baseline failed.
    """
    try:
        observation = object_observation(item.load(mesh_root))
        sampled = baselines[0].sample(observation)
    except Dg16mError as exc:  # a broken object fails only its own entries
        return {b.name: f"{type(exc).__name__}: {exc}" for b in baselines}
    out: dict[str, Prediction | str] = {}
    for baseline in baselines:
        try:
            out[baseline.name] = baseline.choose(sampled)
        except Dg16mError as exc:
            out[baseline.name] = f"{type(exc).__name__}: {exc}"
    return out


def stored_fc_pass(bench: Benchmark, k: int) -> dict[str, Prediction | str]:
    """The benchmark's own first ``k`` ``fc_pass`` rows per object, in stored order, scored
    ``-fc_loss`` (a message for an object without such rows)."""
    out: dict[str, Prediction | str] = {}
    fc_pass = SOURCES.index("fc_pass")
    for obj in bench.objects:
        rows = bench.object_rows(obj.object_id)
        rows = rows[bench.source[rows] == fc_pass][:k]
        if rows.size == 0:
            out[obj.object_id] = "expected at least one stored fc_pass row, found none"
        else:
            out[obj.object_id] = (bench.poses[rows], 0.0 - bench.fc_loss[rows])
    return out


def write_reference_submissions(
    out_dir: str | os.PathLike[str],
    *,
    benchmark: str | os.PathLike[str] | BenchmarkRef | None = None,
    mesh_root: str | os.PathLike[str] | None = None,
    k: int = 10,
    seed: int = 0,
    workers: int = 1,
    strategies: Sequence[str] = DEFAULT_STRATEGIES,
    n_grasps: int | None = None,
    progress: bool = True,
) -> dict[str, Path]:
    """Write one submission file ``out_dir/<name>.h5`` per baseline (see the module docstring).

    Args:
        out_dir: output folder (created).
        benchmark: benchmark file or reference (default: the embedded benchmark).
        mesh_root: the meshes of a mesh benchmark.
        k: dual grasps per object and baseline (at most; fewer when an object has fewer).
        seed: the sampled baselines' global seed.
        workers: local processes for the sampled baselines.
        strategies: names among :data:`STRATEGIES`.
        n_grasps: single-arm grasps sampled per object (default: the benchmark's).
        progress: show a progress bar over the objects.

    Returns:
        name -> path of each file, in the order of ``strategies``.

    Raises:
        BaselineError: bad arguments.
        ReferenceSubmissionError: a baseline yielded no grasp on some object; the other files are
            written (listed in the exception).
    """
    names = parse_strategies(strategies)
    k = check_integer("k", k, minimum=1, error=BaselineError)
    seed = check_integer("seed", seed, minimum=0, error=BaselineError)
    check_backend("local", workers, error=BaselineError)
    ref = load_benchmark_ref(benchmark, mesh_root)
    bench = ref.benchmark
    baselines = reference_baselines(ref, names, k=k, seed=seed, n_grasps=n_grasps)
    results: dict[str, dict[str, Prediction | str]] = {name: {} for name in names}
    if baselines:
        root = str(ref.mesh_root) if ref.mesh_root is not None else None
        tasks = run_tasks(predict_object, bench.objects, (root, baselines), workers=workers)
        for item, out in progress_bar(
            tasks, total=len(bench.objects), desc="baselines", unit="object", enabled=progress
        ):
            for name, prediction in out.items():
                results[name][item.object_id] = prediction
    if "benchmark_fc_pass" in names:
        results["benchmark_fc_pass"] = stored_fc_pass(bench, k)

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    created_by = f"dg16m {package_version()}"
    grasps = {b.name: b.n_grasps for b in baselines}
    written: dict[str, Path] = {}
    failures: dict[str, dict[str, str]] = {}
    for name in names:
        by_object = results[name]
        failed = {i: v for i, v in by_object.items() if isinstance(v, str)}
        if failed:
            failures[name] = {i: failed[i] for i in sorted(failed)}
            continue
        metadata: dict[str, Any] = {"baseline": name, "k": k, "seed": seed}
        if name in grasps:
            metadata["n_grasps"] = grasps[name]
        metadata["created_by"] = created_by
        path = write_submission(
            out / f"{name}.h5",
            {i: v[0] for i, v in by_object.items()},
            scores={i: v[1] for i, v in by_object.items()},
            benchmark=EMBEDDED if ref.embedded else ref.sha256,
            metadata=metadata,
        )
        problems = validate_submission(
            path, object_ids=ref.object_ids, benchmark_sha256=ref.sha256, embedded=ref.embedded
        )
        if problems:  # a bug here, not the user's input: say exactly what
            raise BaselineError(
                f"{path}: expected a valid submission, found {len(problems)} problem(s), e.g. "
                f"{problems[0]}"
            )
        written[name] = path
    if failures:
        raise ReferenceSubmissionError(written, failures)
    return written


def run_submissions(args: argparse.Namespace) -> int:
    """Run the parsed arguments of :func:`~baselines.submission_arguments.add_submission_arguments`
    (``dg16m baselines submissions`` and :func:`main`): 0 when every file is written, 1 when some
    baseline failed on some object (its file is not written; the others are)."""
    start = time.perf_counter()
    try:
        paths = write_reference_submissions(
            args.out,
            benchmark=args.benchmark,
            mesh_root=args.mesh_root,
            k=args.k,
            seed=args.seed,
            workers=args.workers,
            strategies=parse_strategies(args.strategies),
            progress=not args.no_progress,
        )
    except ReferenceSubmissionError as exc:
        print(exc)
        return 1
    for name, path in paths.items():
        print(f"wrote {path}  ({name})")
    print(f"{len(paths)} submissions in {time.perf_counter() - start:.1f} s")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m baselines.reference_submissions --out DIR [--k] [--seed] [--workers]
    [--benchmark] [--mesh-root] [--strategies] [--no-progress]``; returns the exit status
    (0 written, 1 some baseline failed on some object, 2 bad input)."""
    parser = argparse.ArgumentParser(
        prog="python -m baselines.reference_submissions",
        description="Write the reference submissions of the pairing baselines "
        "(same as 'dg16m baselines submissions').",
    )
    add_submission_arguments(parser)
    args = parser.parse_args(argv)
    try:
        return run_submissions(args)
    except Dg16mError as exc:
        print(f"{parser.prog}: error: {exc}", file=sys.stderr)
        return 2


__all__ = [
    "DEFAULT_STRATEGIES",
    "STORED_STRATEGIES",
    "STRATEGIES",
    "ReferenceSubmissionError",
    "parse_strategies",
    "predict_object",
    "reference_baselines",
    "run_submissions",
    "stored_fc_pass",
    "write_reference_submissions",
]


if __name__ == "__main__":
    raise SystemExit(main())
