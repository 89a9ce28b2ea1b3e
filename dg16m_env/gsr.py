"""Grasp success rate (GSR) core: simulate many dual grasps on many objects.

One call of :func:`dg16m_env.trial.run_trials` evaluates all dual grasps of one object on one
compiled model; :func:`evaluate_objects` spreads objects over a process pool or Ray (the same task
runner as the generator, :func:`dataset_gen.parallel.run_tasks`). Results are keyed by object id
and do not depend on the worker count or the backend.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dataset_gen.errors import Dg16mError
from dataset_gen.objects import ConvexPart
from dataset_gen.parallel import Backend, run_tasks
from dataset_gen.parameters import PAPER
from dataset_gen.sources import ObjectSource
from dg16m_env.decomposition import object_parts
from dg16m_env.scene import SceneParameters, compile_scene
from dg16m_env.trial import TrialProtocol, TrialResults, check_dual_grasps, run_trials


class GsrError(Dg16mError, ValueError):
    """Bad GSR input (duplicate object ids, malformed grasp arrays)."""


@dataclass(frozen=True, eq=False)
class GraspJob:
    """The dual grasps of one object.

    Attributes:
        source: where the object comes from (procedural id or mesh file).
        poses: (N, 2, 4, 4) hand poses, Panda grasp frame -> object frame (m).
        parts: convex parts to simulate (default: the object's own, or a cached CoACD
            decomposition for meshes).
        mass: object mass (kg; default ``PAPER.mass``, the release's).
    """

    source: ObjectSource
    poses: np.ndarray
    parts: tuple[ConvexPart, ...] | None = None
    mass: float = PAPER.mass

    @property
    def object_id(self) -> str:
        return self.source.object_id

    def __repr__(self) -> str:  # poses and parts are arrays: count them
        parts = "own parts" if self.parts is None else f"{len(self.parts)} parts"
        return (
            f"GraspJob({self.object_id!r}, {len(np.asarray(self.poses))} dual grasps, {parts}, "
            f"mass {self.mass:g} kg)"
        )


@dataclass
class GsrResult:
    """Per-object trial results and the overall grasp success rate."""

    results: dict[str, TrialResults] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)

    def success_rate(self) -> float:
        """Successes / simulated (valid) trials over all objects (NaN when none ran)."""
        ran = sum(int(r.valid.sum()) for r in self.results.values())
        won = sum(int(r.success.sum()) for r in self.results.values())
        return won / ran if ran else float("nan")

    def __repr__(self) -> str:  # one TrialResults per object: totals instead
        trials = sum(r.n for r in self.results.values())
        return (
            f"GsrResult({len(self.results)} objects, {trials} trials, success rate "
            f"{self.success_rate():.3f}, {len(self.errors)} failed objects)"
        )

    def summary(self) -> dict[str, Any]:
        return {
            "objects": len(self.results),
            "failed_objects": dict(self.errors),
            "success_rate": self.success_rate(),
            "per_object": {k: v.summary() for k, v in sorted(self.results.items())},
        }


def evaluate_object(
    job: GraspJob, scene_params: SceneParameters, protocol: TrialProtocol
) -> TrialResults:
    """Load, compile once and run every dual grasp of ``job``."""
    poses = check_dual_grasps(job.poses)
    obj = job.source.load(job.mass)
    parts = job.parts if job.parts is not None else object_parts(obj)
    scene = compile_scene(obj, params=scene_params, parts=parts)
    return run_trials(scene, poses, protocol)


def _task(
    job: GraspJob, scene_params: SceneParameters, protocol: TrialProtocol
) -> TrialResults | str:
    try:
        return evaluate_object(job, scene_params, protocol)
    except Dg16mError as exc:  # a broken mesh fails only its own object
        return str(exc)


def evaluate_objects(
    jobs: Sequence[GraspJob],
    *,
    scene_params: SceneParameters | None = None,
    protocol: TrialProtocol | None = None,
    workers: int = 1,
    backend: Backend = "local",
    address: str | None = None,
) -> GsrResult:
    """Simulate every job's dual grasps, objects in parallel.

    Raises:
        GsrError: duplicate object ids.
    """
    ids = [job.object_id for job in jobs]
    if len(set(ids)) != len(ids):
        raise GsrError(
            f"jobs: expected unique object ids, found {len(ids) - len(set(ids))} repeats"
        )
    out = GsrResult()
    args = (scene_params or SceneParameters(), protocol or TrialProtocol())
    for job, result in run_tasks(
        _task, list(jobs), args, workers=workers, backend=backend, address=address
    ):
        if isinstance(result, str):
            out.errors[job.object_id] = result
        else:
            out.results[job.object_id] = result
    out.results = dict(sorted(out.results.items()))
    return out


def jobs_from_mapping(
    poses: Mapping[str, np.ndarray], sources: Mapping[str, ObjectSource]
) -> list[GraspJob]:
    """Jobs from ``{object id: (N, 2, 4, 4) poses}`` and ``{object id: source}``."""
    missing = sorted(set(poses) - set(sources))
    if missing:
        raise GsrError(f"poses: expected a source for every object, found none for {missing[:3]}")
    return [GraspJob(sources[i], np.asarray(poses[i])) for i in sorted(poses)]
