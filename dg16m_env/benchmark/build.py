"""Building a benchmark (``dg16m benchmark build``): one object at a time (:func:`benchmark_object`:
choose its arms, optionally re-seat, label every pair by its success probability), with limits and
budgets for real meshes (:class:`BuildLimits`), as resumable tasks over a process pool or Ray
(:func:`build_benchmark`, :func:`build_objects`), concatenated into ``benchmark.h5``
(:func:`write_built_benchmark`). The steps are described in :mod:`dg16m_env.benchmark`.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from dataset_gen.grasps.gripper import PANDA
from dataset_gen.io import (
    failed_entries,
    package_version,
    read_dg16m,
)
from dataset_gen.objects.decomposition import (
    MIN_RELATIVE_HULL_VOLUME,
    DecompositionParameters,
    decomposition_report,
    object_parts,
)
from dataset_gen.objects.grasp_object import (
    ConvexPart,
)
from dataset_gen.pipeline.parallel import Backend, run_resumable
from dataset_gen.sources.object_source import (
    object_seed,
)
from dg16m_core.budget import (
    WALL_FACTOR,
    StageCrashError,
    StageTimeoutError,
    run_with_budget,
)
from dg16m_core.checks import check_integer, check_number
from dg16m_core.errors import Dg16mError
from dg16m_env.benchmark.arms import (
    ObjectRejectedError,
    _file_pairs,
    _object_metadata,
    sampled_pairs,
    screen_counts,
    screen_verdict,
)
from dg16m_env.benchmark.file import grid_multiples, on_grid, read_benchmark, write_benchmark
from dg16m_env.benchmark.model import (
    BENCHMARK_FILE,
    OBJECTS_FOLDER,
    SOURCES,
    Benchmark,
    BenchmarkError,
    BenchmarkParameters,
    concatenate,
    hand_line_distance,
)
from dg16m_env.benchmark.sources import BenchmarkSource
from dg16m_env.benchmark.verdicts import (
    crash_verdict,
    kept_rejections,
    rejection_entry,
    seconds,
    timeout_verdict,
)
from dg16m_env.physics.labels import row_seeds, success_probability
from dg16m_env.physics.reseat import reseat_poses, shift_summary
from dg16m_env.physics.scene import compile_scene
from dg16m_env.physics.simulator import Simulator, check_simulator
from dg16m_env.physics.trial_measures import grasp_centres
from dg16m_env.physics.trial_protocol import PHASES, TrialStatus


def _grid_hull(part: ConvexPart, grid: float, min_volume: float) -> ConvexPart | None:
    """``part`` with its vertices on the grid, or None when that flattens it (a sliver thinner
    than the grid) to no volume above ``min_volume`` (m^3), as CoACD's own output is filtered
    (:data:`dataset_gen.objects.decomposition.MIN_RELATIVE_HULL_VOLUME`)."""
    if part.kind != "mesh" or part.vertices is None:
        return part
    rounded = on_grid(grid_multiples(part.vertices, grid), grid)
    try:
        volume = ConvexHull(rounded).volume
    except (QhullError, ValueError):  # flat or collinear once on the grid
        return None
    if not volume > min_volume:
        return None
    return ConvexPart("mesh", part.pose, (), rounded)


def grid_parts(
    parts: Sequence[ConvexPart], grid: float, mesh_vertices: np.ndarray
) -> tuple[ConvexPart, ...]:
    """A mesh's CoACD hulls on the grid (m), without those it flattens (``_grid_hull``).

    Raises:
        BenchmarkError: every hull flattened.
    """
    box_volume = float(np.prod(np.ptp(np.asarray(mesh_vertices, dtype=np.float64), axis=0)))
    min_volume = MIN_RELATIVE_HULL_VOLUME * box_volume
    kept = tuple(p for p in (_grid_hull(part, grid, min_volume) for part in parts) if p is not None)
    if not kept:
        raise BenchmarkError(
            f"hull_grid {grid}: expected some convex hulls with volume on the grid, found "
            f"all {len(parts)} flattened"
        )
    return kept


def _no_stage(name: str) -> None:
    del name


FALLBACK_SEED_STEP = 1
"""The decomposition fallback's seed is the settings' seed plus this (:func:`fallback_decomposition`)."""


def fallback_decomposition(params: BenchmarkParameters) -> DecompositionParameters:
    """The settings a build tries once when CoACD crashed on a mesh with ``params``' own: the
    same ones with CoACD's next seed (``seed + 1``), so its search tries other cutting planes
    (a crash in CoACD's triangulation of a cut, as on a thin-walled vase with coacd 1.0.14,
    depends on the planes) at the same concavity threshold, hence the same fidelity to the
    mesh. Deterministic. (CoACD's own voxel remesh, ``preprocess="on"``, was not chosen: at
    its resolution of 50 cells it closes or thickens walls of a few mm, and it ran for minutes
    at the default threshold on a plain box.)"""
    current = params.decomposition or DecompositionParameters()
    return replace(current, seed=(current.seed + FALLBACK_SEED_STEP) % 2**32)


def benchmark_object(
    item: BenchmarkSource,
    params: BenchmarkParameters,
    simulator: Simulator | None = None,
    *,
    min_passing: int = 0,
    on_stage: Callable[[str], None] | None = None,
    decompose_fallback: bool = False,
) -> Benchmark:
    """Choose, optionally re-seat (``item.reseat_max``; the summary goes to
    ``metadata["reseat"]``) and simulate one object's dual grasps on ``simulator`` (default C
    MuJoCo; another engine is named in ``metadata["simulator"]``), with each pair's hand-line
    distance and the object's centre of mass (see the module docstring).

    Args:
        min_passing: for sampled objects, the fewest ``fc_pass`` pairs the object must give
            (0 = any): checked before the convex decomposition
            (:func:`~dg16m_env.benchmark.arms.screen_passing`) and
            after sampling, before any trial; :class:`ObjectRejectedError` says which.
        on_stage: called with ``"load"``, ``"screen"`` (only with ``min_passing``),
            ``"decompose"``, ``"sample"`` and ``"label"`` as the work enters each (for time
            budgets, :func:`dg16m_core.budget.run_with_budget`).
        decompose_fallback: decompose with :func:`fallback_decomposition` (after CoACD crashed
            on this mesh with the parameters' settings).
    """
    stage = on_stage or _no_stage
    stage("load")
    simulator = check_simulator(simulator)
    source = item.source
    data = read_dg16m(item.grasp_file) if item.grasp_file is not None else None
    if data is not None and source.mesh is not None and source.scale is None:
        # A DG16M file records the mesh scale its contacts were computed with; that scale is
        # authoritative, so the size is not second-guessed.
        source = replace(source, scale=data.object_scale, allow_any_size=True)
    obj = source.load(params.mass)
    decomposition = params.decomposition_kwargs()
    if decompose_fallback:
        decomposition = {"params": fallback_decomposition(params)}
    if min_passing and data is None:
        stage("screen")
        grasps, found = screen_counts(obj, params)
        if found < min_passing:
            raise ObjectRejectedError(
                "screen",
                f"{obj.object_id}: expected at least {min_passing} force-closure-passing "
                f"candidate pairs, found {found} before the clearance rule (screening)",
                screen_verdict(grasps, found, min_passing, PANDA.max_opening),
            )
    stage("decompose")
    parts = object_parts(obj, **decomposition)
    if params.hull_grid is not None and not obj.parts:
        parts = grid_parts(parts, params.hull_grid, obj.mesh.vertices)
    stage("sample")
    rng = np.random.default_rng(object_seed(params.seed, f"benchmark:{obj.object_id}"))
    rows = (
        _file_pairs(item, data, params, rng)
        if data is not None
        else sampled_pairs(obj, params, rng, parts=parts)
    )
    if min_passing and data is None:
        found = int(np.sum(rows["source"] == SOURCES.index("fc_pass")))
        if found < min_passing:
            raise ObjectRejectedError(
                "sample",
                f"{obj.object_id}: expected at least {min_passing} fc_pass pairs, found {found} "
                "with the open-hand clearance rule",
                f"only {found} force-closure pairs leave both open hands clear of the object "
                f"({min_passing} needed): the fingers would start inside it almost everywhere",
            )
    stage("label")
    scene = compile_scene(obj, params=params.scene, parts=parts)
    n = len(rows["poses"])
    reseat = None
    if item.reseat_max > 0:
        reseat = reseat_poses(
            scene,
            rows["poses"],
            max_shift=item.reseat_max,
            limit=params.protocol.invalid_penetration,
        )
        rows["poses"] = reseat.poses
    labels = success_probability(
        scene,
        rows["poses"],
        spec=params.perturbation,
        seeds=row_seeds(params.perturbation.seed, obj.object_id, n),
        protocol=params.protocol,
        simulator=simulator,
    )
    center_of_mass = obj.mass_properties.center_of_mass
    bench = Benchmark(
        objects=[_object_metadata(obj, source, parts, item.reseat_max)],
        object_index=np.zeros(n, dtype=np.int32),
        labels=labels,
        metadata=benchmark_metadata(params, simulator),
        reseat_shift=reseat.shift if reseat is not None else np.zeros((n, 2)),
        hand_line_distance=hand_line_distance(grasp_centres(scene, rows["poses"]), center_of_mass),
        **rows,
    )
    if reseat is not None:
        bench.metadata["reseat"] = {obj.object_id: reseat.summary()}
    return bench


def benchmark_metadata(
    params: BenchmarkParameters, simulator: Simulator | None = None
) -> dict[str, Any]:
    """The file's metadata; a build on another engine than C MuJoCo names it (engine, device,
    versions) under ``"simulator"`` (files labelled by C MuJoCo, the shipped one included,
    have no such key). ``"mujoco"`` is the MuJoCo version that simulated the trials: a MuJoCo
    release changes contacts, so the stored trials are reproducible with that version only
    (the shipped files, written before this key, were simulated with 4.0.0)."""
    import mujoco

    out: dict[str, Any] = {
        "parameters": params.to_dict(),
        "phases": list(PHASES),
        "statuses": [s.name.lower() for s in TrialStatus],
        "sources": list(SOURCES),
        "created_by": f"dg16m {package_version()}",
        "mujoco": mujoco.__version__,
    }
    if simulator is not None and not simulator.is_default:
        out["simulator"] = simulator.describe()
    return out


class NothingBuiltError(BenchmarkError):
    """Every object of a build failed, so there is no benchmark to write.

    Attributes:
        failed: each object id -> its reason (from the manifest).
    """

    def __init__(self, message: str, failed: Mapping[str, str]) -> None:
        super().__init__(message)
        self.failed = dict(failed)


@dataclass(frozen=True)
class BuildLimits:
    """What a build admits and how long it waits for one object (real meshes vary widely: one
    wardrobe took CoACD 18 minutes and then gave no pair).

    Attributes:
        min_passing: the fewest ``fc_pass`` pairs an object must give to be built (0 = any);
            checked before the decomposition and before the trials
            (:func:`benchmark_object`).
        decompose_s: CPU seconds for the convex decomposition (None = no limit).
        sample_s: CPU seconds for sampling, pairing and force closure (and the screening).
        label_s: CPU seconds for the trials.
        object_wall_s: wall seconds for the whole object, all stages together (None = no such
            bound; a loaded machine stretches wall time, so such a bound makes verdicts depend
            on load: the defaults have none).

    Budgets are the child process's CPU seconds (:func:`dg16m_core.budget.run_with_budget`),
    not wall time, so that a loaded machine does not reject what a quiet one admits: the same
    mesh gets the same verdict at any load. :data:`~dg16m_core.budget.WALL_FACTOR` times a
    budget in wall time is only a safety net for a stage that waits or hangs; its verdict says
    so, and a resumed build redoes such an object. ``dg16m benchmark build --stage-budget
    STAGE=SECONDS`` sets them (:meth:`with_stage_budgets`).

    An object past a budget is stopped (its child process is killed) and recorded as failed
    with ``rejected: "time budget"``, the stage, which ``limit`` ended it (``"cpu"``, ``"wall"``
    or ``"object"``) and the ``cpu_seconds`` it had used; one whose child crashed (a signal,
    out of memory) with ``rejected: "crashed"``, the ``signal`` or ``exit_code`` and the
    ``cpu_seconds`` (a crash in CoACD is retried once with :func:`fallback_decomposition`
    within what is left of the budget, recorded under ``decompose_fallback``); one with too
    few pairs with ``rejected: "too few passing pairs"``; each with a ``verdict`` in words.
    With any budget, and for every mesh object, the object runs in a child process
    (:func:`dg16m_core.budget.run_with_budget`; about 2 s to start) that Ctrl-C and SIGTERM stop
    at once.

    The bound on one object's wall time: ``object_wall_s`` where set, else the sum over its
    stages of :data:`~dg16m_core.budget.WALL_FACTOR` times each budget (``screen`` takes
    ``sample_s``).
    """

    min_passing: int = 0
    decompose_s: float | None = None
    sample_s: float | None = None
    label_s: float | None = None
    object_wall_s: float | None = None

    def __post_init__(self) -> None:
        check_integer("min_passing", self.min_passing, error=BenchmarkError)
        for name in ("decompose_s", "sample_s", "label_s", "object_wall_s"):
            if getattr(self, name) is not None:
                check_number(name, getattr(self, name), error=BenchmarkError)

    def wall_bound_s(self) -> float | None:
        """The most wall seconds one object can take before its verdict (child start aside):
        ``object_wall_s``, or the stages' wall caps summed; None without any bound."""
        if self.object_wall_s is not None:
            return float(self.object_wall_s)
        stages = self.budgets()
        return WALL_FACTOR * sum(stages.values()) if stages else None

    def budgets(self) -> dict[str, float]:
        """Seconds per stage of :func:`benchmark_object` that has a budget."""
        stages = {
            "screen": self.sample_s,
            "decompose": self.decompose_s,
            "sample": self.sample_s,
            "label": self.label_s,
        }
        return {k: float(v) for k, v in stages.items() if v is not None}

    def to_dict(self) -> dict[str, Any]:
        """For the manifest's parameters (``object_wall_s`` only where set: the manifests of
        builds made before it existed still match)."""
        values = asdict(self)
        if values["object_wall_s"] is None:
            del values["object_wall_s"]
        return values

    def with_stage_budgets(self, budgets: Sequence[str]) -> BuildLimits:
        """These limits with the budgets of ``STAGE=SECONDS`` texts (``--stage-budget``; the
        stages of :data:`BUDGET_STAGES`, CPU seconds > 0; a later text for the same stage
        wins).

        Raises:
            BenchmarkError: not ``STAGE=SECONDS``, an unknown stage, or not seconds > 0.
        """
        changes: dict[str, float] = {}
        for text in budgets:
            stage, sep, seconds = str(text).partition("=")
            if not sep:
                raise BenchmarkError(
                    f"--stage-budget: expected STAGE=SECONDS (e.g. decompose=600), found {text!r}"
                )
            if stage not in BUDGET_STAGES:
                raise BenchmarkError(
                    f"--stage-budget: expected one of {', '.join(BUDGET_STAGES)} (the screen "
                    f"shares sample's budget), found {stage!r}"
                )
            try:
                value = float(seconds)
            except ValueError:
                value = math.nan
            if not (math.isfinite(value) and value > 0):
                raise BenchmarkError(
                    f"--stage-budget {stage}: expected CPU seconds > 0, found {seconds!r}"
                )
            changes[BUDGET_STAGES[stage]] = value
        return replace(self, **changes)


BUDGET_STAGES = {"decompose": "decompose_s", "sample": "sample_s", "label": "label_s"}
"""The stages ``--stage-budget`` names, each with its :class:`BuildLimits` field (the screen
takes ``sample_s``)."""


def _budgeted_object(
    item: BenchmarkSource,
    params: BenchmarkParameters,
    simulator: Simulator,
    min_passing: int,
    decompose_fallback: bool = False,
    *,
    on_stage: Callable[[str], None],
) -> Benchmark:
    return benchmark_object(
        item,
        params,
        simulator,
        min_passing=min_passing,
        on_stage=on_stage,
        decompose_fallback=decompose_fallback,
    )


def _run_object(
    item: BenchmarkSource,
    params: BenchmarkParameters,
    simulator: Simulator,
    limits: BuildLimits | None,
) -> tuple[Benchmark, dict[str, float], dict[str, Any] | None]:
    """One object built in a budget child where needed: ``(benchmark, wall seconds per stage,
    the decomposition fallback's record or None)``. A crash in CoACD is retried once with
    :func:`fallback_decomposition`, its decomposition budget what the crashed run left; an
    exception raised after that carries the record as its ``fallback``."""
    min_passing = limits.min_passing if limits is not None else 0
    budgets = limits.budgets() if limits is not None else {}
    wall = limits.object_wall_s if limits is not None else None
    if not (budgets or wall is not None or item.source.mesh is not None):
        return benchmark_object(item, params, simulator, min_passing=min_passing), {}, None
    # a child process: budgets, crashes that end only the object, and CoACD stopped by Ctrl-C
    # or SIGTERM within a second
    args = (item, params, simulator, min_passing)
    try:
        done = run_with_budget(_budgeted_object, args, budgets, total_wall_s=wall)
        return done.value, done.times, None
    except StageCrashError as crash:
        if crash.stage != "decompose":
            raise
        first = crash
    record: dict[str, Any] = {"tried": False, "worked": False, "settings": FALLBACK_WORDS}
    retry = dict(budgets)
    if "decompose" in budgets:
        retry["decompose"] = budgets["decompose"] - (first.cpu_seconds or 0.0)
        if retry["decompose"] < 1.0:
            record["outcome"] = "no CPU budget left for it"
            first.fallback = record  # type: ignore[attr-defined]
            raise first
    try:
        done = run_with_budget(_budgeted_object, (*args, True), retry, total_wall_s=wall)
    except (StageCrashError, StageTimeoutError) as again:
        record["tried"] = True
        if again.stage in AFTER_DECOMPOSE:  # decomposed: the rest of the object failed
            record.update(worked=True, outcome="it decomposed the mesh")
            again.fallback = record  # type: ignore[attr-defined]
            raise
        record["outcome"] = (
            "it crashed too"
            if isinstance(again, StageCrashError) and again.stage == "decompose"
            else crash_verdict(again)
            if isinstance(again, StageCrashError)
            else timeout_verdict(again)
        )
        first.fallback = record  # type: ignore[attr-defined]
        raise first from None
    except Dg16mError as exc:  # e.g. too few pairs after the decomposition
        decomposed = getattr(exc, "stage", "") in AFTER_DECOMPOSE
        record.update(tried=True, worked=decomposed, outcome=str(exc))
        if decomposed:
            record["outcome"] = "it decomposed the mesh"
        exc.fallback = record  # type: ignore[attr-defined]
        raise
    record.update(tried=True, worked=True, outcome="it decomposed the mesh")
    return done.value, done.times, record


AFTER_DECOMPOSE = ("sample", "label")
"""The stages of :func:`benchmark_object` after the decomposition."""

FALLBACK_WORDS = "CoACD's next seed (other cutting planes, the same threshold)"
"""The decomposition fallback (:func:`fallback_decomposition`) in words."""


def _object_task(
    item: BenchmarkSource,
    out: str,
    params: BenchmarkParameters,
    simulator: Simulator,
    limits: BuildLimits | None = None,
) -> dict[str, Any]:
    relative = f"{OBJECTS_FOLDER}/{item.object_id}.h5"
    try:
        bench, times, fallback = _run_object(item, params, simulator, limits)
    except (StageTimeoutError, StageCrashError, ObjectRejectedError) as exc:
        return rejection_entry(item, exc)
    except Dg16mError as exc:  # a broken mesh or grasp file fails only its own entry
        return {"status": "failed", "files": {}, "error": str(exc)}
    write_benchmark(Path(out) / relative, bench)
    summary = bench.trials.summary()
    entry = {
        "status": "ok",
        "files": {"benchmark": relative},
        "pairs": bench.n,
        "trials": bench.n * bench.labels.spec.trials,
        "labelled_success": int(bench.label().sum()),
        "mean_p_success": float(bench.p().mean()) if bench.n else 0.0,
        "invalid": summary["invalid"],
        "invalid_reasons": bench.trials.invalid_reasons(),
        "max_penetration_m": summary["max_penetration_m"],
    }
    if fallback is not None:
        entry["decompose_fallback"] = fallback
    if item.reseat_max > 0:
        entry["reseat"] = bench.metadata.get("reseat", {}).get(
            item.object_id, {"max_shift_m": item.reseat_max, **shift_summary(bench.reseat_shift)}
        )
    if limits is not None:
        entry["arms"] = {
            name: int(np.sum(bench.source == k))
            for k, name in enumerate(SOURCES)
            if np.any(bench.source == k)
        }
        built = bench.objects[0]
        entry["parts"] = len(built.parts)
        if not built.family:  # a mesh: how far its hulls stand off it (hull to mesh, one-sided)
            report = decomposition_report(built.load().mesh, built.parts, seed=0)
            entry["hull_deviation_mm"] = {
                "max": round(1000 * report.deviation_max, 3),
                "p95": round(1000 * report.deviation_p95, 3),
                "mean": round(1000 * report.deviation_mean, 3),
            }
        if times:
            entry["stage_seconds"] = seconds(times)
    return entry


def _reseat_parameters(items: Sequence[BenchmarkSource]) -> dict[str, Any]:
    """The re-seating limits of a build, for its manifest's parameters (so a resume with other
    limits is refused): nothing when every object has it off (manifests of builds without
    re-seating are unchanged)."""
    limits = sorted({float(item.reseat_max) for item in items})
    if limits in ([0.0], []):
        return {}
    return {"reseat_max": limits[0] if len(limits) == 1 else limits}


def build_benchmark(
    items: Sequence[BenchmarkSource],
    out: str | os.PathLike[str],
    params: BenchmarkParameters | None = None,
    *,
    workers: int = 1,
    backend: Backend = "local",
    address: str | None = None,
    progress: bool = True,
    simulator: Simulator | str | None = None,
    limits: BuildLimits | None = None,
    retry_rejected: bool = False,
) -> Path:
    """Build (or resume) a benchmark in ``out``; returns the path of ``benchmark.h5``.

    ``limits`` (:class:`BuildLimits`): the fewest passing pairs an object must give and time
    budgets per stage; objects that fail them are left out and listed in the manifest with
    the reason and stage (recorded in its parameters, so a resume with other limits is
    refused). A resume keeps the rejections whose inputs and settings are unchanged
    (:func:`~dg16m_env.benchmark.verdicts.kept_rejections`) unless ``retry_rejected``.

    ``simulator`` runs the trials (default C MuJoCo; with MuJoCo Warp on one GPU keep
    ``workers=1``: one object's trials already fill the device). A build with another engine
    records it in its manifest's parameters (a resume with another engine is refused) and in
    the file's metadata.

    Raises:
        BenchmarkError: duplicate ids, ``out`` holds a benchmark made with other parameters, or
            no object succeeded.
        SimulatorError: the simulator cannot run here (checked before any object).
    """
    params = params or BenchmarkParameters()
    simulator = check_simulator(simulator)
    simulator.check_available()
    root = Path(out)
    manifest = build_objects(
        items,
        root,
        params,
        simulator=simulator,
        limits=limits,
        workers=workers,
        backend=backend,
        address=address,
        progress=progress,
        retry_rejected=retry_rejected,
    )
    return write_built_benchmark(
        root, [item.object_id for item in items], manifest, params, simulator
    )


def build_parameters(
    items: Sequence[BenchmarkSource],
    params: BenchmarkParameters,
    simulator: Simulator,
    limits: BuildLimits | None,
) -> dict[str, Any]:
    """The manifest parameters of a build (a resume must match them)."""
    engine = {} if simulator.is_default else {"simulator": simulator.name}
    extra = {} if limits is None else {"limits": limits.to_dict()}
    return json.loads(
        json.dumps({**params.to_dict(), **_reseat_parameters(items), **engine, **extra})
    )


def build_objects(
    items: Sequence[BenchmarkSource],
    root: Path,
    params: BenchmarkParameters,
    *,
    simulator: Simulator,
    limits: BuildLimits | None = None,
    workers: int = 1,
    backend: Backend = "local",
    address: str | None = None,
    progress: bool = True,
    parameters: Mapping[str, Any] | None = None,
    retry_rejected: bool = False,
) -> dict[str, Any]:
    """Build (or resume) every object of ``items`` into ``root/objects/``; returns the
    manifest (one entry per object: ``ok`` with counts, or ``failed`` with the reason). A
    resume does not redo an object ``root`` already rejected with the same inputs and
    settings (:func:`~dg16m_env.benchmark.verdicts.kept_rejections`; its entry stays as it
    is) unless ``retry_rejected``."""
    parameters = (
        dict(parameters)
        if parameters is not None
        else build_parameters(items, params, simulator, limits)
    )
    kept = {} if retry_rejected else kept_rejections(root, items, parameters)
    return run_resumable(
        _object_task,
        [item for item in items if item.object_id not in kept],
        (str(root.resolve()), params, simulator, limits),
        root=root,
        kind="benchmark",
        parameters=parameters,
        folders=(OBJECTS_FOLDER,),
        error=BenchmarkError,
        workers=workers,
        backend=backend,
        address=address,
        progress=progress,
        desc="benchmark",
    )


def write_built_benchmark(
    root: Path,
    ids: Sequence[str],
    manifest: Mapping[str, Any],
    params: BenchmarkParameters,
    simulator: Simulator,
) -> Path:
    """Concatenate the finished objects ``ids`` (in that order) into ``root/benchmark.h5``.

    Raises:
        NothingBuiltError: none of them finished (the reasons are named).
    """
    done = [i for i in ids if manifest["entries"].get(i, {}).get("status") == "ok"]
    if not done:
        reasons = sorted(
            {manifest["entries"][i].get("error", "?") for i in ids if i in manifest["entries"]}
        )
        raise NothingBuiltError(
            f"{root}: expected at least one object to build, found all failed: "
            + "; ".join(reasons[:5])
            + (f" (and {len(reasons) - 5} more, see manifest.json)" if len(reasons) > 5 else ""),
            failed_entries(manifest, ids),
        )
    parts = [read_benchmark(root / manifest["entries"][i]["files"]["benchmark"]) for i in done]
    metadata = benchmark_metadata(params, simulator)
    reseat = {k: v for part in parts for k, v in part.metadata.get("reseat", {}).items()}
    if reseat:
        metadata["reseat"] = reseat
    path = root / BENCHMARK_FILE
    write_benchmark(path, concatenate(parts, metadata))
    return path
