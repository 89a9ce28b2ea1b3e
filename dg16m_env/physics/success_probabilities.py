"""Grasp success rate (GSR) core: success probabilities of many dual grasps on many objects.

One call of :func:`dg16m_env.physics.labels.success_probability` labels all dual grasps of one object on
one compiled model (nominal + K perturbed trials each, benchmark protocol v2);
:func:`evaluate_objects` spreads objects over a process pool or Ray (the same task runner as the
generator, :func:`dataset_gen.pipeline.parallel.run_tasks`). Results are keyed by object id and do not
depend on the worker count or the backend.

GSR = the mean success probability over ALL submitted dual grasps: an invalid trial counts as a
failure, and the grasps of an object that cannot be simulated count as 0
(:meth:`GsrResult.success_rate`); the rate over valid nominal trials is reported beside it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dataset_gen.objects.decomposition import object_parts
from dataset_gen.objects.grasp_object import ConvexPart
from dataset_gen.pipeline.parallel import Backend, run_tasks
from dataset_gen.sources.object_source import ObjectSource
from dg16m_core.errors import Dg16mError
from dg16m_core.parameters import PAPER
from dg16m_core.progress import progress_bar
from dg16m_env.physics.labels import LEVELS, GraspLabels, PerturbationSpec, success_probability
from dg16m_env.physics.scene import SceneParameters, compile_scene
from dg16m_env.physics.simulator import Simulator, check_simulator
from dg16m_env.physics.trial_protocol import TrialProtocol, check_dual_grasps


class GsrError(Dg16mError, ValueError):
    """Bad GSR input (duplicate object ids, malformed grasp arrays)."""


@dataclass(frozen=True, eq=False)
class GraspJob:
    """The dual grasps of one object.

    Attributes:
        source: where the object comes from: an :class:`~dataset_gen.sources.object_source.ObjectSource`
            (a mesh file or a procedural family and seed), or a procedural object id such as
            ``"table-1000000"`` (made into its source).
        poses: (N, 2, 4, 4) hand poses, Panda grasp frame -> object frame (m).
        parts: convex parts to simulate (default: the object's own, or a cached CoACD
            decomposition for meshes).
        mass: object mass (kg; default ``PAPER.mass``, the release's).
    """

    source: ObjectSource
    poses: np.ndarray
    parts: tuple[ConvexPart, ...] | None = None
    mass: float = PAPER.mass

    def __post_init__(self) -> None:
        if isinstance(self.source, str):
            from dataset_gen.sources.procedural import ProceduralError, parse_object_id

            try:
                family, seed = parse_object_id(self.source)
            except ProceduralError as exc:
                raise GsrError(
                    f"source: expected an ObjectSource or a procedural object id, found "
                    f"{self.source!r} ({exc}); a mesh is ObjectSource(object_id, mesh=path)"
                ) from None
            source = ObjectSource(object_id=self.source, family=family, family_seed=seed)
            object.__setattr__(self, "source", source)
        elif not isinstance(self.source, ObjectSource):
            raise GsrError(
                "source: expected an ObjectSource or a procedural object id like "
                f"'table-1000000', found {type(self.source).__name__}"
            )

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
    """Per-object success probabilities and the grasp success rates.

    Attributes:
        results: ``{object id: GraspLabels}`` of the objects that were simulated.
        errors: ``{object id: message}`` of the objects that could not be simulated.
        submitted: ``{object id: number of dual grasps}`` for every job, simulated or not.
    """

    results: dict[str, GraspLabels] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)
    submitted: dict[str, int] = field(default_factory=dict)

    def success_rate(self, level: str = "full") -> float:
        """Mean success probability over every submitted dual grasp: invalid trials are
        failures and an object that could not be simulated counts its grasps as 0 (NaN when
        nothing was submitted)."""
        total = sum(self.submitted.values())
        won = sum(float(r.p(level).sum()) for r in self.results.values())
        return won / total if total else float("nan")

    def success_rate_valid(self, level: str = "full") -> float:
        """Mean success probability over the dual grasps whose nominal trial ran (reported
        beside :meth:`success_rate`, never instead of it; NaN when none ran)."""
        ran = sum(int(r.nominal.valid.sum()) for r in self.results.values())
        won = sum(float(r.p(level)[r.nominal.valid].sum()) for r in self.results.values())
        return won / ran if ran else float("nan")

    def __repr__(self) -> str:  # one GraspLabels per object: totals instead
        grasps = sum(self.submitted.values())
        return (
            f"GsrResult({len(self.results)} objects, {grasps} dual grasps, success rate "
            f"{self.success_rate():.3f}, {len(self.errors)} failed objects)"
        )

    def summary(self) -> dict[str, Any]:
        return {
            "objects": len(self.submitted),
            "dual_grasps": sum(self.submitted.values()),
            "failed_objects": dict(self.errors),
            **{f"success_rate_{level}": self.success_rate(level) for level in LEVELS},
            **{f"success_rate_valid_{level}": self.success_rate_valid(level) for level in LEVELS},
            "per_object": {k: v.summary() for k, v in sorted(self.results.items())},
        }


def evaluate_object(
    job: GraspJob,
    scene_params: SceneParameters,
    protocol: TrialProtocol,
    spec: PerturbationSpec | None = None,
    simulator: Simulator | None = None,
) -> GraspLabels:
    """Load, compile once and label every dual grasp of ``job`` (per-row seeds from
    ``(spec.seed, object id)``) with ``simulator`` (default C MuJoCo)."""
    poses = check_dual_grasps(job.poses)
    obj = job.source.load(job.mass)
    # stoppable: Ctrl-C and SIGTERM stop CoACD too when one worker runs it in the command's process
    parts = job.parts if job.parts is not None else object_parts(obj, stoppable=True)
    scene = compile_scene(obj, params=scene_params, parts=parts)
    return success_probability(scene, poses, spec=spec, protocol=protocol, simulator=simulator)


def _task(
    job: GraspJob,
    scene_params: SceneParameters,
    protocol: TrialProtocol,
    spec: PerturbationSpec,
    simulator: Simulator,
) -> GraspLabels | str:
    try:
        return evaluate_object(job, scene_params, protocol, spec, simulator)
    except Dg16mError as exc:  # a broken mesh fails only its own object
        return str(exc)


def evaluate_objects(
    jobs: Sequence[GraspJob],
    *,
    scene_params: SceneParameters | None = None,
    protocol: TrialProtocol | None = None,
    spec: PerturbationSpec | None = None,
    workers: int = 1,
    backend: Backend = "local",
    address: str | None = None,
    progress: bool = False,
    simulator: Simulator | str | None = None,
    on_result: Callable[[GraspJob, GraspLabels | str], None] | None = None,
) -> GsrResult:
    """Success probabilities of every job's dual grasps, objects in parallel (a progress bar
    over objects when ``progress``), trials on ``simulator`` (default C MuJoCo; with MuJoCo
    Warp on one GPU use ``workers=1``: each object's trials already fill the device).
    ``on_result(job, labels or error message)`` is called as each object finishes (e.g. to
    checkpoint it: an interrupt then loses only the objects in flight).

    Raises:
        GsrError: duplicate object ids.
        SimulatorError: the simulator cannot run here (checked before any object).
    """
    simulator = check_simulator(simulator)
    simulator.check_available()
    ids = [job.object_id for job in jobs]
    if len(set(ids)) != len(ids):
        raise GsrError(
            f"jobs: expected unique object ids, found {len(ids) - len(set(ids))} repeats"
        )
    out = GsrResult(submitted={job.object_id: len(np.asarray(job.poses)) for job in jobs})
    args = (
        scene_params or SceneParameters(),
        protocol or TrialProtocol(),
        spec or PerturbationSpec(),
        simulator,
    )
    results = run_tasks(_task, list(jobs), args, workers=workers, backend=backend, address=address)
    for job, result in progress_bar(results, total=len(jobs), desc="gsr", enabled=progress):
        if isinstance(result, str):
            out.errors[job.object_id] = result
        else:
            out.results[job.object_id] = result
        if on_result is not None:
            on_result(job, result)
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
