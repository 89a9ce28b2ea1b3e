"""``fce``: force-closure efficiency of submitted dual grasps (the paper's FCE).

For each submitted dual grasp, each hand's jaws are closed on the object at its pose
(:func:`dataset_gen.grasps.gripper.contacts_from_pose`: the finger faces sweep until they touch), which
gives the four contacts; the two open hands must not overlap (the benchmark's gripper-gripper
check, :func:`dataset_gen.grasps.pairing.grippers_collide`); then the force-closure check
(:func:`dataset_gen.force_closure.evaluate`) runs with the benchmark's parameters (mass,
gravity, friction, force bound, threshold). FCE = passing / submitted: a grasp whose jaws miss,
whose open gripper collides with the object, that is too wide, whose pose is not rigid, or whose
hands overlap counts as failing, and the reason is counted (:data:`REASONS`). An object that
cannot be loaded counts all its grasps as failing (``object_failed``).

Arguments of ``make("fce", ...)``: ``benchmark`` (path or :class:`BenchmarkRef`, default the
embedded benchmark), ``mesh_root`` (mesh benchmarks), ``workers``, ``backend``
(``"local"``/``"ray"``), ``address``, ``n_resamples`` and ``seed`` (the object-resampled
confidence intervals), ``progress``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from dataset_gen.force_closure import evaluate
from dataset_gen.grasps.gripper import ContactStatus, contacts_from_pose
from dataset_gen.grasps.pairing import grippers_collide
from dataset_gen.grasps.sampling import SingleArmGrasps
from dataset_gen.objects.grasp_object import GraspObject
from dataset_gen.pipeline.parallel import Backend, run_tasks
from dg16m_core.errors import Dg16mError
from dg16m_core.progress import progress_bar
from dg16m_env.benchmark.model import BenchmarkObject
from dg16m_env.benchmark.ref import BenchmarkRef
from dg16m_env.subjects.submission import Submission

from .registry import register
from .result import EvaluationResult, breakdown, object_means
from .submissions import SubmissionEvaluator, submission_record

#: Verdict of one submitted dual grasp; index = the code stored per grasp.
REASONS = (
    "pass",
    "no_force_closure",
    "miss",
    "collision",
    "too_wide",
    "invalid_pose",
    "hands_overlap",
    "object_failed",
)

# A hand's contact status -> its reason; when both hands fail, the more basic failure is named.
_HAND_REASON = {
    ContactStatus.INVALID_POSE: "invalid_pose",
    ContactStatus.COLLISION: "collision",
    ContactStatus.TOO_WIDE: "too_wide",
    ContactStatus.MISS: "miss",
}


def fce_verdicts(
    obj: GraspObject, poses: np.ndarray, force_closure: dict[str, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Force-closure verdicts of dual grasps on one object.

    Args:
        obj: the object (object frame, origin at the centre of mass).
        poses: (K, 2, 4, 4) Panda hand poses (m).
        force_closure: keyword arguments of :func:`dataset_gen.force_closure.evaluate`
            (:meth:`~dg16m_env.benchmark.model.BenchmarkParameters.force_closure_kwargs`).

    Returns:
        ``codes (K,)`` int8 indices into :data:`REASONS` and ``loss (K,)`` float64 (the
        force-closure residual, N; NaN where no check ran).
    """
    poses = np.asarray(poses, dtype=np.float64)
    k = len(poses)
    jaws = [contacts_from_pose(obj, poses[:, hand]) for hand in (0, 1)]
    codes = np.full(k, REASONS.index("no_force_closure"), dtype=np.int8)
    for status, reason in _HAND_REASON.items():  # most basic first: it wins
        hit = (jaws[0].status == status) | (jaws[1].status == status)
        codes[hit & (codes == REASONS.index("no_force_closure"))] = REASONS.index(reason)
    ok = jaws[0].ok & jaws[1].ok
    loss = np.full(k, np.nan)
    if ok.any():
        grasps = SingleArmGrasps(
            poses=np.concatenate([poses[:, 0], poses[:, 1]]),
            contact_points=np.concatenate([jaws[0].points, jaws[1].points]),
            contact_normals=np.concatenate([jaws[0].normals, jaws[1].normals]),
            face_ids=np.concatenate([jaws[0].face_ids, jaws[1].face_ids]),
            widths=np.concatenate([jaws[0].width, jaws[1].width]),
            gripper="panda",
        )
        rows = np.flatnonzero(ok)
        overlap = grippers_collide(grasps, np.stack([rows, rows + k], axis=1))
        codes[rows[overlap]] = REASONS.index("hands_overlap")
        check = rows[~overlap]
        if check.size:
            points = np.concatenate([jaws[0].points[check], jaws[1].points[check]], axis=1)
            normals = np.concatenate([jaws[0].normals[check], jaws[1].normals[check]], axis=1)
            result = evaluate(points, normals, **force_closure)
            loss[check] = result.loss
            codes[check[result.passed]] = REASONS.index("pass")
    return codes, loss


@dataclass(frozen=True, eq=False)
class _ObjectWork:
    obj: BenchmarkObject
    poses: np.ndarray
    mesh_root: str | None

    @property
    def object_id(self) -> str:
        return self.obj.object_id


def _task(
    work: _ObjectWork, force_closure: dict[str, float]
) -> tuple[np.ndarray, np.ndarray] | str:
    try:
        obj = work.obj.load(work.mesh_root)
        return fce_verdicts(obj, work.poses, force_closure)
    except Dg16mError as exc:  # a broken mesh fails only its own object
        return f"{type(exc).__name__}: {exc}"


@register("fce")
class ForceClosureEfficiency(SubmissionEvaluator):
    """FCE of a submission (see the module docstring)."""

    version = "1"

    def __init__(
        self,
        *,
        benchmark: str | os.PathLike[str] | BenchmarkRef | None = None,
        mesh_root: str | os.PathLike[str] | None = None,
        workers: int = 1,
        backend: Backend = "local",
        address: str | None = None,
        n_resamples: int = 2000,
        seed: int = 0,
        progress: bool = False,
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

    def run_parameters(self) -> dict[str, Any]:
        """The force-closure parameters of the benchmark and the gripper."""
        force_closure = self.ref.benchmark.parameters().force_closure_kwargs()
        return {"force_closure": force_closure, "gripper": "panda"}

    def evaluate(self, subject: Submission | str | os.PathLike[str]) -> EvaluationResult:
        submission, poses, index = self.rows(subject)
        ids = self.ref.object_ids
        parameters = self.run_parameters()
        force_closure = parameters["force_closure"]
        mesh_root = str(self.ref.mesh_root) if self.ref.mesh_root is not None else None
        work = [
            _ObjectWork(obj, poses[index == k], mesh_root)
            for k, obj in enumerate(self.ref.benchmark.objects)
        ]
        codes = np.full(len(poses), REASONS.index("object_failed"), dtype=np.int8)
        loss = np.full(len(poses), np.nan)
        failures: dict[str, str] = {}
        results = run_tasks(
            _task,
            work,
            (force_closure,),
            workers=self.workers,
            backend=self.backend,
            address=self.address,
        )
        for item, out in progress_bar(results, total=len(work), desc="fce", enabled=self.progress):
            rows = index == ids.index(item.object_id)
            if isinstance(out, str):
                failures[item.object_id] = out
            else:
                codes[rows], loss[rows] = out
        passed = (codes == REASONS.index("pass")).astype(np.float64)
        metrics, per_family, per_object = breakdown(
            {"fce": passed},
            index,
            ids,
            self.ref.families,
            n_resamples=self.n_resamples,
            seed=self.seed,
        )
        for k, object_id in enumerate(ids):
            mine = codes[index == k]
            per_object[object_id]["reasons"] = _counts(mine)
        return self.result(
            benchmark=self.ref.record(),
            subject=submission_record(submission),
            parameters=parameters,
            seeds=self.run_seeds(),
            headline="fce",
            metrics=metrics,
            per_family=per_family,
            per_object=per_object,
            failures=failures,
            details={
                "object_mean": object_means(per_object, ["fce"]),
                "reasons": _counts(codes),
                "median_loss_of_checked": (
                    float(np.nanmedian(loss)) if np.isfinite(loss).any() else None
                ),
            },
        )


def _counts(codes: np.ndarray) -> dict[str, int]:
    counts = np.bincount(codes.astype(np.int64), minlength=len(REASONS))
    return {reason: int(n) for reason, n in zip(REASONS, counts, strict=True) if n}
