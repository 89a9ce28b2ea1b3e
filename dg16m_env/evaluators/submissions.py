"""What the submission evaluators (``fce``, ``gsr``) share: their base class (the benchmark, the
parallel backend, the confidence-interval settings) and their subject, a
:class:`~dg16m_env.subjects.submission.Submission` in memory or a submission file, checked against the
benchmark before anything is scored."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from dataset_gen.pipeline.parallel import Backend, check_backend
from dg16m_env.benchmark.ref import BenchmarkRef, load_benchmark_ref
from dg16m_env.physics.simulator import Simulator
from dg16m_env.subjects.submission import Submission
from dg16m_env.subjects.submission_reader import read_submission
from dg16m_env.subjects.track import track_name

from .registry import Evaluator, EvaluatorError, evaluator_class, make


def as_submission(subject: Any, ref: BenchmarkRef) -> Submission:
    """A validated submission for the benchmark ``ref``.

    Args:
        subject: a :class:`Submission`, or the path of a submission file (validated in full by
            :func:`dg16m_env.subjects.submission_reader.read_submission`).
        ref: the benchmark scored against.

    Raises:
        SubmissionInvalid: the file has problems (every one is listed).
        EvaluatorError: an in-memory submission whose objects or shapes do not match.
    """
    if isinstance(subject, (str, os.PathLike)):
        return read_submission(
            subject, object_ids=ref.object_ids, benchmark_sha256=ref.sha256, embedded=ref.embedded
        )
    if not isinstance(subject, Submission):
        raise EvaluatorError(
            f"subject: expected a Submission or a submission file path, found "
            f"{type(subject).__name__}"
        )
    missing = sorted(set(ref.object_ids) - set(subject.poses))
    unknown = sorted(set(subject.poses) - set(ref.object_ids))
    if missing or unknown:
        raise EvaluatorError(
            f"submission: expected the benchmark's {len(ref.object_ids)} objects, found "
            f"{len(missing)} missing (e.g. {missing[:3]}) and {len(unknown)} unknown "
            f"(e.g. {unknown[:3]})"
        )
    for object_id, poses in subject.poses.items():
        shape = np.shape(poses)
        if len(shape) != 4 or shape[1:] != (2, 4, 4) or shape[0] < 1:
            raise EvaluatorError(
                f"objects/{object_id}/poses: expected shape (K >= 1, 2, 4, 4), found {shape}"
            )
    return subject


def submission_record(submission: Submission) -> dict[str, Any]:
    """What a result records of the submission it scored."""
    return {
        "kind": "submission",
        "sha256": submission.sha256,
        "objects": len(submission.poses),
        "dual_grasps": submission.n_grasps,
        "metadata": dict(submission.metadata),
        "track": track_name(submission.metadata),
    }


def stacked(submission: Submission, object_ids: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """All dual grasps in benchmark object order: ``poses (N, 2, 4, 4)`` and ``object_index
    (N,)`` into ``object_ids``."""
    poses = [np.asarray(submission.poses[i], dtype=np.float64) for i in object_ids]
    index = np.concatenate([np.full(len(p), k, dtype=np.int64) for k, p in enumerate(poses)])
    return np.concatenate(poses), index


class SubmissionEvaluator(Evaluator):
    """Base of the evaluators that score a submission against a benchmark.

    Subclasses keep their own keyword-only ``__init__`` (its signature is what ``make`` checks)
    and pass these arguments on: ``benchmark`` (path or :class:`BenchmarkRef`, default the
    embedded benchmark), ``mesh_root``, ``workers``, ``backend``, ``address``, ``n_resamples``
    and ``seed`` (the object-resampled confidence intervals), ``progress``.
    """

    subject_kind = "submission"

    def __init__(
        self,
        *,
        benchmark: str | os.PathLike[str] | BenchmarkRef | None,
        mesh_root: str | os.PathLike[str] | None,
        workers: int,
        backend: Backend,
        address: str | None,
        n_resamples: int,
        seed: int,
        progress: bool,
    ) -> None:
        check_backend(backend, workers, error=EvaluatorError)
        self.ref = load_benchmark_ref(benchmark, mesh_root)
        self.workers, self.backend, self.address = workers, backend, address
        self.n_resamples, self.seed, self.progress = n_resamples, seed, progress

    def run_parameters(self) -> dict[str, Any]:
        """Every argument that can change a score (a result's ``parameters``)."""
        raise NotImplementedError

    def run_seeds(self) -> dict[str, int]:
        """Every seed used, by name (a result's ``seeds``)."""
        return {"resample": self.seed}

    def planned(self) -> dict[str, Any]:
        """See :meth:`Evaluator.planned`."""
        from dg16m_core.json_values import json_ready

        return json_ready(
            {
                **self.identity(),
                "benchmark": self.ref.record(),
                "parameters": self.run_parameters(),
                "seeds": self.run_seeds(),
            }
        )

    def rows(self, subject: Any) -> tuple[Submission, np.ndarray, np.ndarray]:
        """The validated submission and its dual grasps in benchmark object order (``poses
        (N, 2, 4, 4)``, ``object_index (N,)``; see :func:`as_submission`, :func:`stacked`)."""
        submission = as_submission(subject, self.ref)
        return (submission, *stacked(submission, self.ref.object_ids))


def submission_evaluators(
    names: list[str],
    benchmark: BenchmarkRef,
    *,
    workers: int = 1,
    backend: Backend = "local",
    address: str | None = None,
    seed: int = 0,
    n_perturbations: int | None = None,
    progress: bool = False,
    simulator: Simulator | None = None,
) -> dict[str, Evaluator]:
    """The named evaluators of submission files, built with one set of run options (what
    ``dg16m evaluate`` and the leaderboard's workers score with).

    Args:
        names: registered evaluator names, each of which scores a submission.
        benchmark: the benchmark scored against.
        workers, backend, address: the parallel backend.
        seed: seed of the confidence intervals.
        n_perturbations: ``gsr``'s perturbed trials per grasp (default: the benchmark's).
        simulator: ``gsr``'s physics engine (default C MuJoCo).
        progress: progress bars.

    Raises:
        EvaluatorError: an unknown name, or an evaluator of something else.
    """
    out: dict[str, Evaluator] = {}
    for name in names:
        kind = evaluator_class(name).subject_kind
        if kind != "submission":
            raise EvaluatorError(
                f"evaluators: expected evaluators of submissions (e.g. fce, gsr), found {name!r} "
                f"that scores a {kind}"
            )
        kwargs: dict[str, Any] = {
            "benchmark": benchmark,
            "workers": workers,
            "backend": backend,
            "address": address,
            "seed": seed,
            "progress": progress,
        }
        if name == "gsr" and n_perturbations is not None:
            kwargs["n_perturbations"] = n_perturbations
        if name == "gsr" and simulator is not None:
            kwargs["simulator"] = simulator
        out[name] = make(name, **kwargs)
    return out
