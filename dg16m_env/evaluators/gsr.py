"""``gsr``: grasp success rate of submitted dual grasps in simulation (the paper's GSR).

Every submitted dual grasp is labelled like a benchmark row (:mod:`dg16m_env.physics.labels`, benchmark
protocol v2): the trial protocol at the nominal hand poses and at K seeded perturbations of
them (each hand moved by d and turned by theta), on the object's stored convex parts and mass,
with the benchmark's scene and protocol. Its success probability p is the share of its K + 1
trials that held. GSR = the mean p over ALL submitted grasps: an invalid trial (an open hand
penetrates the object, the hands overlap) is a failure, and an object that cannot be simulated
counts its grasps as 0. Metrics, each with an object-resampled 95 % confidence interval:

* ``gsr`` (headline): held through all twelve disturbances;
* ``gsr_gravity``: held under gravity (the paper's description of its benchmark);
* ``gsr_valid`` / ``gsr_valid_gravity``: the same over grasps whose nominal trial ran
  (reported beside the headline, never instead of it);
* ``label_rate``: the share with p >= 0.5.

Per-grasp seeds are :func:`dg16m_env.physics.labels.row_seeds` of (``perturbation_seed``, object id),
so the benchmark's own rows, submitted in their stored order, get exactly their stored p.

Arguments of ``make("gsr", ...)``: ``benchmark``, ``mesh_root``, ``n_perturbations`` and
``perturbation_seed`` (default: the benchmark's), ``workers``, ``backend``
(``"local"``/``"ray"``), ``address``, ``n_resamples`` and ``seed`` (confidence intervals),
``progress``, ``simulator`` (a :class:`~dg16m_env.physics.simulator.Simulator` or its name; default C
MuJoCo, the engine of the shipped labels). A result computed on another engine names it in its
parameters (``"simulator"``), so it is never mistaken for a C MuJoCo score.
"""

from __future__ import annotations

import os
import sys
from dataclasses import replace
from typing import Any

import numpy as np

from dataset_gen.pipeline.parallel import Backend
from dg16m_env.benchmark.ref import BenchmarkRef
from dg16m_env.physics.labels import LEVELS, GraspLabels, concatenate_labels
from dg16m_env.physics.simulator import Simulator, SimulatorError, check_simulator
from dg16m_env.physics.success_probabilities import GraspJob, evaluate_objects
from dg16m_env.physics.trial_protocol import PHASES, TrialResults, TrialStatus
from dg16m_env.subjects.submission import Submission

from .checkpoint import CheckpointError, CheckpointRequest, ObjectCheckpoint
from .registry import EvaluatorError, register
from .result import EvaluationResult, breakdown, object_means
from .submissions import SubmissionEvaluator, submission_record


@register("gsr")
class GraspSuccessRate(SubmissionEvaluator):
    """GSR of a submission (see the module docstring)."""

    version = "1"

    def __init__(
        self,
        *,
        benchmark: str | os.PathLike[str] | BenchmarkRef | None = None,
        mesh_root: str | os.PathLike[str] | None = None,
        n_perturbations: int | None = None,
        perturbation_seed: int | None = None,
        workers: int = 1,
        backend: Backend = "local",
        address: str | None = None,
        n_resamples: int = 2000,
        seed: int = 0,
        progress: bool = False,
        simulator: Simulator | str | None = None,
    ) -> None:
        super().__init__(
            benchmark=benchmark,
            mesh_root=mesh_root,
            workers=workers,
            backend=backend,
            address=address,
            n_resamples=n_resamples,
            seed=seed,
            progress=progress,
        )
        try:
            self.simulator = check_simulator(simulator)
            self.simulator.check_available()
        except SimulatorError as exc:
            raise EvaluatorError(f"gsr: {exc}") from None
        self.params = self.ref.benchmark.parameters()
        spec = self.params.perturbation
        changes: dict[str, Any] = {}
        if n_perturbations is not None:
            changes["n_perturbations"] = n_perturbations
        if perturbation_seed is not None:
            changes["seed"] = perturbation_seed
        try:
            self.spec = replace(spec, **changes)
        except ValueError as exc:
            raise EvaluatorError(f"gsr: {exc}") from None

    def run_parameters(self) -> dict[str, Any]:
        """The perturbations, the scene, the protocol and (when not C MuJoCo) the engine."""
        return {
            "perturbation": self.spec.to_dict(),
            "scene": self.params.scene.to_dict(),
            "protocol": self.params.protocol.to_dict(),
            **({} if self.simulator.is_default else {"simulator": self.simulator.describe()}),
        }

    def run_seeds(self) -> dict[str, int]:
        """The perturbations' seed and the confidence intervals' seed."""
        return {"perturbation": self.spec.seed, "resample": self.seed}

    def evaluate(
        self,
        subject: Submission | str | os.PathLike[str],
        *,
        checkpoint: CheckpointRequest | None = None,
    ) -> EvaluationResult:
        """Score ``subject``. With ``checkpoint``, each object's labels are recorded in its
        folder as it finishes, and a resumed run (``checkpoint.resume``) simulates only the
        objects not recorded there; the result is the same as without (see
        :mod:`dg16m_env.evaluators.checkpoint`), and the folder is removed once it is complete.

        Raises:
            CheckpointError: resuming a checkpoint of another run (subject, benchmark,
                parameters, seeds or versions).
        """
        submission, poses, index = self.rows(subject)
        ids = self.ref.object_ids
        jobs = [
            GraspJob(
                obj.source(self.ref.mesh_root), poses[index == k], parts=obj.parts, mass=obj.mass
            )
            for k, obj in enumerate(self.ref.benchmark.objects)
        ]
        store = None
        kept: dict[str, GraspLabels | str] = {}
        if checkpoint is not None:
            store = ObjectCheckpoint(checkpoint, {**self.planned(), "subject": submission.sha256})
            kept = {i: self._restored(e) for i, e in store.kept(list(ids)).items()}
            if kept:
                print(
                    f"gsr: resuming: {len(kept)} of {len(ids)} objects kept from {store.folder}",
                    file=sys.stderr,
                )
        position = {object_id: k for k, object_id in enumerate(ids)}

        def record(job: GraspJob, labels: GraspLabels | str) -> None:
            if store is not None:
                k = position[job.object_id]
                if isinstance(labels, str):
                    store.save(k, job.object_id, error=labels)
                else:
                    store.save(k, job.object_id, _label_arrays(labels))

        out = evaluate_objects(
            [job for job in jobs if job.object_id not in kept],
            scene_params=self.params.scene,
            protocol=self.params.protocol,
            spec=self.spec,
            workers=self.workers,
            backend=self.backend,
            address=self.address,
            progress=self.progress,
            simulator=self.simulator,
            on_result=record,
        )
        for object_id, labels in kept.items():
            if isinstance(labels, str):
                out.errors[object_id] = labels
            else:
                out.results[object_id] = labels
        out.results = dict(sorted(out.results.items()))
        result = self._result(submission, poses, index, out)
        if store is not None:
            store.finish()
        return result

    def _restored(self, entry: dict[str, Any]) -> GraspLabels | str:
        """An object's labels (or error) as a checkpoint recorded them."""
        if entry["error"] is not None:
            return str(entry["error"])
        arrays = entry["arrays"]
        try:
            nominal = TrialResults(
                **{k: arrays[f"nominal.{k}"] for k in TrialResults.ARRAY_FIELDS},
                protocol=self.params.protocol,
            )
            return GraspLabels(
                nominal=nominal,
                status=arrays["status"],
                failing_phase=arrays["failing_phase"],
                seeds=arrays["seeds"],
                spec=self.spec,
            )
        except (KeyError, ValueError) as exc:
            raise CheckpointError(
                f"gsr checkpoint of {entry['object_id']}: expected its labels, found {exc}; "
                "remove the checkpoint folder or run without --resume"
            ) from None

    def _result(
        self, submission: Submission, poses: np.ndarray, index: np.ndarray, out: Any
    ) -> EvaluationResult:
        """The result of the labels ``out`` (a :class:`GsrResult`) of every object."""
        ids = self.ref.object_ids
        # Grasps of objects that could not be simulated keep p = 0 and count as not run.
        p = {level: np.zeros(len(poses)) for level in LEVELS}
        ran = np.zeros(len(poses), dtype=bool)
        for k, object_id in enumerate(ids):
            labels = out.results.get(object_id)
            if labels is not None:
                rows = index == k
                for level in LEVELS:
                    p[level][rows] = labels.p(level)
                ran[rows] = labels.nominal.valid
        values = {
            "gsr": p["full"],
            "gsr_gravity": p["gravity"],
            "gsr_valid": p["full"],
            "gsr_valid_gravity": p["gravity"],
            "label_rate": (p["full"] >= 0.5).astype(np.float64),
        }
        metrics, per_family, per_object = breakdown(
            values,
            index,
            ids,
            self.ref.families,
            rows={"gsr_valid": ran, "gsr_valid_gravity": ran},
            n_resamples=self.n_resamples,
            seed=self.seed,
        )
        return self.result(
            benchmark=self.ref.record(),
            subject=submission_record(submission),
            parameters=self.run_parameters(),
            seeds=self.run_seeds(),
            headline="gsr",
            metrics=metrics,
            per_family=per_family,
            per_object=per_object,
            failures=dict(sorted(out.errors.items())),
            details={
                "object_mean": object_means(per_object, list(values)),
                **_trial_details(out.results.values()),
            },
        )


def _label_arrays(labels: GraspLabels) -> dict[str, np.ndarray]:
    """What a checkpoint records of an object's labels (its spec and protocol are the run's)."""
    return {
        **{f"nominal.{k}": getattr(labels.nominal, k) for k in TrialResults.ARRAY_FIELDS},
        "status": labels.status,
        "failing_phase": labels.failing_phase,
        "seeds": labels.seeds,
    }


def _trial_details(results: Any) -> dict[str, Any]:
    """Counts over every trial (nominal and perturbed) of the simulated objects."""
    results = list(results)
    if not results:
        return {"trials": 0}
    labels = concatenate_labels(results)
    status = labels.status.ravel()
    phase = labels.failing_phase.ravel()
    return {
        "trials": int(status.size),
        "trials_per_grasp": labels.spec.trials,
        "statuses": {s.name.lower(): int(np.sum(status == s)) for s in TrialStatus},
        "failing_phases": {
            name: int(np.sum(phase == k)) for k, name in enumerate(PHASES) if np.any(phase == k)
        },
        "uncertain": {level: int(labels.uncertain(level).sum()) for level in LEVELS},
        "nominal": labels.nominal.summary(),
    }
