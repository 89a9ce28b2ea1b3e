"""The offline generator: meshes or procedural objects in, one release-schema HDF5 per object out.

Per object (:func:`generate_object`): antipodal single-arm sampling, all unique pairs with the
grasp-centre pruning and gripper-gripper collision rejection, force closure on every candidate
(verdict-only), then up to ``max_passing`` passing and ``max_failing`` failing pairs (failing
losses proven > ``failing_min_loss`` and computed exactly). The defaults are the release's
(:data:`~dg16m_core.parameters.PAPER`). The result is a :class:`~dataset_gen.io.DualGraspSet` in
the release schema with our extras under ``dg16m/``.

A dataset run (:func:`generate_dataset`) maps that task over objects with a local process pool or
Ray. Every object's random stream is derived from ``(seed, object id)`` alone, so the bytes of
each file do not depend on the worker count, the order or the backend. Files are written
atomically and the folder's ``manifest.json`` is rewritten after each object by the parent
process only; a rerun skips objects whose entry is ``ok`` and whose file exists, so an
interrupted run (even ``kill -9``) resumes to the same bytes. An object that cannot be loaded or
processed (a broken mesh, an implausible size) or that yields no dual grasp to store is recorded
as ``failed`` with its reason and does not stop the run.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from dataset_gen.force_closure import ForceClosureResult
from dataset_gen.grasps.clearance import collision_parts
from dataset_gen.grasps.pairing import (
    PairCandidates,
    candidate_pairs,
    dual_contacts,
    dual_poses,
    score_pairs,
    select_pairs,
)
from dataset_gen.grasps.robust import RobustSelection, robust_pairs
from dataset_gen.grasps.sampling import SingleArmGrasps, sample_antipodal_grasps
from dataset_gen.io import (
    DualGraspSet,
    package_version,
    read_manifest,
    write_dg16m,
)
from dataset_gen.objects.grasp_object import ConvexPart, GraspObject
from dataset_gen.pipeline.parallel import Backend, run_resumable
from dataset_gen.sources.object_source import ObjectSource, object_seed
from dg16m_core.atomic import write_bytes_atomic
from dg16m_core.checks import check_fields
from dg16m_core.errors import Dg16mError
from dg16m_core.parameters import PAPER, SELECTIONS

GRASPS_FOLDER = "grasps"

CONVENTIONS: tuple[str, ...] = ("physical", "release")
CLEARANCE_GEOMETRIES: tuple[str, ...] = ("decomposition", "mesh")


class GenerationError(Dg16mError, ValueError):
    """Bad generator arguments (counts, folders, backend)."""


@dataclass(frozen=True)
class GenerationParameters:
    """Everything that decides a generated file's bytes (besides the object and package version).

    Defaults are the DG16M release's (:data:`~dg16m_core.parameters.PAPER`) except the
    convention and the gripper-collision check, which are physical by default.

    Attributes:
        seed: global seed; each object's stream is derived from (seed, object id).
        gripper: gripper model name (``dataset_gen.grasps.gripper.GRIPPERS``).
        n_grasps: single-arm grasps sampled per object (at least 2).
        mu: friction coefficient for sampling and force closure.
        mass: object mass for the gravity wrench (kg).
        gravity: m/s^2.
        f_high: force bound per contact (N).
        threshold: force-closure threshold on the residual norm (N).
        convention: ``"physical"`` or ``"release"`` friction cones.
        min_center_distance: grasp-centre pruning distance (m; 0 prunes nothing).
        check_gripper_collision: reject pairs whose grippers collide (the release does not).
        max_passing, max_failing: pairs kept per object.
        failing_min_loss: failing pairs kept must have a loss above this (N; may be 0).
        selection: which passing pairs are kept: ``"paper"`` (the paper's gravity-only check,
            the default, to reproduce it) or ``"robust"`` (also a disturbance motion ratio
            <= 1 against every load of the simulation protocol, :mod:`dataset_gen.grasps.robust`;
            files then carry ``motion_ratio``).
        clearance_geometry: what a mesh object's open hands must clear: ``"decomposition"``
            (its CoACD convex parts, the geometry the simulator collides; the default, as the
            benchmark needs) or ``"mesh"`` (the exact mesh alone, as for procedural objects and
            as the DG16M release did: no CoACD, about 25 times faster on real furniture; a
            dataset for learning uses it). Procedural objects always use their exact mesh.

    Raises:
        GenerationError: a value of the wrong type or out of range ("NAME: expected X, found Y").
    """

    seed: int = 0
    gripper: str = "panda"
    n_grasps: int = PAPER.n_grasps
    mu: float = PAPER.mu
    mass: float = PAPER.mass
    gravity: float = PAPER.gravity
    f_high: float = PAPER.f_high
    threshold: float = PAPER.threshold
    convention: Literal["physical", "release"] = "physical"
    min_center_distance: float = PAPER.min_center_distance
    check_gripper_collision: bool = True
    max_passing: int = PAPER.max_passing
    max_failing: int = PAPER.max_failing
    failing_min_loss: float = PAPER.failing_min_loss
    selection: Literal["paper", "robust"] = "paper"
    clearance_geometry: Literal["decomposition", "mesh"] = "decomposition"

    def __post_init__(self) -> None:
        check_fields(
            self,
            error=GenerationError,
            integers={"seed": 0, "n_grasps": 2, "max_passing": 0, "max_failing": 0},
            zero_allowed=("min_center_distance", "failing_min_loss"),
            skip=(
                "gripper",
                "convention",
                "check_gripper_collision",
                "selection",
                "clearance_geometry",
            ),
        )
        if self.clearance_geometry not in CLEARANCE_GEOMETRIES:
            raise GenerationError(
                f"clearance_geometry: expected one of {CLEARANCE_GEOMETRIES}, found "
                f"{self.clearance_geometry!r}"
            )
        if self.selection not in SELECTIONS:
            raise GenerationError(
                f"selection: expected one of {SELECTIONS}, found {self.selection!r}"
            )
        if self.selection == "robust" and self.convention != "physical":
            raise GenerationError(
                "selection: expected 'paper' with the release convention (the robust check "
                "models contacts that push), found 'robust'"
            )
        if self.convention not in CONVENTIONS:
            raise GenerationError(
                f"convention: expected one of {CONVENTIONS}, found {self.convention!r}"
            )
        if not isinstance(self.check_gripper_collision, bool):
            raise GenerationError(
                "check_gripper_collision: expected True or False, found "
                f"{self.check_gripper_collision!r}"
            )
        if not isinstance(self.gripper, str) or not self.gripper:
            raise GenerationError(f"gripper: expected a gripper name, found {self.gripper!r}")

    def to_dict(self) -> dict[str, Any]:
        """The fields (stored in files and manifests); ``selection`` only when it is not the
        paper's and ``clearance_geometry`` only when it is not ``"decomposition"``, so files
        made with the defaults keep their bytes and older dataset folders still resume."""
        out = asdict(self)
        if out["selection"] == "paper":
            del out["selection"]
        if out["clearance_geometry"] == "decomposition":
            del out["clearance_geometry"]
        return out

    def force_closure_kwargs(self) -> dict[str, float]:
        """The force-closure check's keyword arguments (mass, gravity, mu, f_high, threshold)."""
        return {
            "mass": self.mass,
            "gravity": self.gravity,
            "mu": self.mu,
            "f_high": self.f_high,
            "threshold": self.threshold,
        }


@dataclass
class StageTimes:
    """Seconds spent per stage of one object."""

    load: float = 0.0
    decomposition: float = 0.0
    sampling: float = 0.0
    pairing: float = 0.0
    force_closure: float = 0.0
    selection: float = 0.0
    writing: float = 0.0

    @property
    def total(self) -> float:
        return sum(asdict(self).values())

    @contextmanager
    def measure(self, stage: str) -> Iterator[None]:
        """Time the ``with`` block into the field ``stage`` (left as it was if the block
        raises)."""
        start = time.perf_counter()
        yield
        setattr(self, stage, time.perf_counter() - start)


def generate_object(
    obj: GraspObject,
    params: GenerationParameters,
    *,
    object_file: str,
    times: StageTimes | None = None,
    stoppable: bool = False,
) -> DualGraspSet:
    """Run sampling, pairing, force closure and selection for one object.

    Args:
        obj: the object, centred (object frame, m).
        params: generator parameters; the random stream is ``object_seed(params.seed, id)``.
        object_file: the string stored as ``object/file``.
        times: filled with the seconds spent per stage when given.
        stoppable: a command's call: Ctrl-C and SIGTERM stop it within a second also while
            CoACD decomposes the mesh (it then runs in a child process; same parts).

    Returns:
        The object's dual grasps (release schema) with extras: ``single_grasps`` (M, 4, 4),
        ``single_contact_points`` / ``single_contact_normals`` (M, 2, 3), ``single_widths`` (M,),
        ``pair_indices`` (S, 2) rows of the single grasps, ``contact_normals`` (S, 4, 3) outward
        normals used by the check, ``quality`` (S,) Q(G); metadata holds the parameters, the
        seeds, per-stage counts and the package version. S may be 0 (see :func:`no_pairs_reason`).
    """
    times = times if times is not None else StageTimes()
    rng = np.random.default_rng(object_seed(params.seed, obj.object_id))
    with times.measure("decomposition"):
        decomposed = params.clearance_geometry == "decomposition"
        parts = collision_parts(obj, stoppable=stoppable) if decomposed else None
    with times.measure("sampling"):
        grasps = sample_antipodal_grasps(
            obj,
            gripper=params.gripper,
            n_grasps=params.n_grasps,
            mu=params.mu,
            rng=rng,
            collision_parts=parts,
        )
    with times.measure("pairing"):
        candidates = candidate_pairs(
            grasps,
            min_center_distance=params.min_center_distance,
            check_gripper_collision=params.check_gripper_collision,
        )
    with times.measure("force_closure"):
        result = score_pairs(
            grasps, candidates.pairs, convention=params.convention, **params.force_closure_kwargs()
        )
    with times.measure("selection"):
        robust = None
        if params.selection == "robust":
            robust = _robust_selection(obj, params, grasps, candidates, result, rng)
            result = replace(result, passed=robust.robust)
        data = _select_and_assemble(
            obj, params, grasps, candidates, result, rng, object_file, robust=robust, parts=parts
        )
    return data


def _robust_selection(
    obj: GraspObject,
    params: GenerationParameters,
    grasps: SingleArmGrasps,
    candidates: PairCandidates,
    result: ForceClosureResult,
    rng: np.random.Generator,
) -> RobustSelection:
    """The robust pairs among the passing candidates, enough of them for ``max_passing``."""
    points, normals = dual_contacts(grasps, candidates.pairs)
    return robust_pairs(
        points,
        normals,
        result.passed,
        rng=rng,
        wanted=params.max_passing,
        mass_properties=obj.mass_properties,
        **params.force_closure_kwargs(),
    )


def _select_and_assemble(
    obj: GraspObject,
    params: GenerationParameters,
    grasps: SingleArmGrasps,
    candidates: PairCandidates,
    result: ForceClosureResult,
    rng: np.random.Generator,
    object_file: str,
    *,
    robust: RobustSelection | None = None,
    parts: Sequence[ConvexPart] | None = None,
) -> DualGraspSet:
    """Keep up to ``max_passing`` + ``max_failing`` scored candidates and build the file's data
    (with the robust selection's motion ratios and counts when given)."""
    points, normals = dual_contacts(grasps, candidates.pairs)
    selection = select_pairs(
        result,
        points,
        normals,
        rng=rng,
        max_passing=params.max_passing,
        max_failing=params.max_failing,
        failing_min_loss=params.failing_min_loss,
    )
    rows = selection.indices
    pairs = candidates.pairs[rows]
    n_pass = int(selection.passed.sum())
    counts = {
        "sampled": grasps.n,
        **{f"sampling_{k}": int(v) for k, v in grasps.counts.items()},
        **{f"pairs_{k}": int(v) for k, v in candidates.counts.items()},
        "rank_deficient": int((~result.rank_ok).sum()),
        "passing": int(result.passed.sum()),
        **{f"selection_{k}": int(v) for k, v in selection.counts.items()},
    }
    extras: dict[str, np.ndarray] = {}
    if robust is not None:
        counts.update({f"robust_{k}": int(v) for k, v in robust.counts.items()})
        extras["motion_ratio"] = robust.ratio[rows]
    return DualGraspSet(
        grasps=dual_poses(grasps, pairs),
        contact_points=points[rows],
        contact_forces=selection.contact_forces,
        loss_values=selection.loss,
        passing_indices=np.arange(n_pass, dtype=np.int64),
        failed_indices=np.arange(n_pass, selection.n, dtype=np.int64),
        object_file=object_file,
        object_scale=float(obj.scale),
        extras={
            "single_grasps": grasps.poses,
            "single_contact_points": grasps.contact_points,
            "single_contact_normals": grasps.contact_normals,
            "single_widths": grasps.widths,
            "pair_indices": pairs.astype(np.int64),
            "contact_normals": normals[rows],
            "quality": selection.quality,
            **extras,
        },
        metadata={
            "object_id": obj.object_id,
            "gripper": params.gripper,
            "parameters": params.to_dict(),
            "object_seed": object_seed(params.seed, obj.object_id),
            "counts": counts,
            "generator": f"dg16m {package_version()}",
            **(
                {"collision_parts": {"source": "coacd", "count": len(parts)}}
                if parts is not None
                else {}
            ),
        },
    )


def no_pairs_reason(counts: dict[str, int], params: GenerationParameters) -> str:
    """Why an object yielded no dual grasp to store, from its per-stage ``counts``."""
    sampled = counts.get("sampled", 0)
    if sampled < 2:
        return (
            f"no dual grasps: expected at least 2 single-arm grasps, found {sampled} (of "
            f"{params.n_grasps} asked): is the object's size right for the {params.gripper} "
            "gripper?"
        )
    pairs = counts.get("pairs_pairs", 0)
    pruned = counts.get("pairs_pruned_distance", 0)
    collide = counts.get("pairs_gripper_collision", 0)
    remaining = counts.get("pairs_remaining", 0)
    if remaining == 0:
        return (
            f"no dual grasps: {sampled} single-arm grasps give {pairs} pairs, {pruned} with "
            f"grasp centres closer than {params.min_center_distance:g} m and {collide} whose "
            "grippers collide, none left: is the object too small for two hands?"
        )
    return (
        f"no dual grasps: {remaining} candidate pairs, {counts.get('passing', 0)} passing force "
        f"closure, none kept (at most {params.max_passing} passing and {params.max_failing} "
        f"failing pairs with a loss above {params.failing_min_loss:g} N)"
    )


def source_kind(source: ObjectSource) -> str:
    """``"procedural"`` or ``"mesh"``: what a dataset entry was made from."""
    return "procedural" if source.mesh is None and source.mesh_arrays is None else "mesh"


def _entry_kind(entry: Mapping[str, Any]) -> str | None:
    """What an existing entry was made from (entries before the ``source`` field: a procedural
    object's folder stores its mesh; a failed entry says nothing)."""
    if "source" in entry:
        return str(entry["source"])
    if entry.get("status") != "ok":
        return None
    return "procedural" if "mesh" in entry.get("files", {}) else "mesh"


def check_same_sources(out: Path, sources: Sequence[ObjectSource]) -> None:
    """Refuse to add objects of one kind (procedural, meshes) to a dataset of the other.

    Raises:
        GenerationError: ``out`` holds entries of the other kind.
    """
    path = out / "manifest.json"
    if not path.is_file() or not sources:
        return
    entries = read_manifest(out)["entries"]
    wanted = {source_kind(s) for s in sources}
    found = {_entry_kind(e) for e in entries.values()} - {None}
    other = found - wanted
    if other:
        count = sum(_entry_kind(e) in other for e in entries.values())
        raise GenerationError(
            f"{out}: expected a dataset of {' and '.join(sorted(wanted))} objects to add to, "
            f"found {count} {' and '.join(sorted(other))} objects in it (one dataset holds one "
            "kind; use another --out)"
        )


def _task(source: ObjectSource, out: str, params: GenerationParameters) -> dict[str, Any]:
    """Load, generate and write one object; returns its manifest entry.

    An object that cannot be loaded or yields no dual grasp is ``failed`` with its reason (no
    file is written, and a rerun tries it again). Ctrl-C and SIGTERM stop it within a second,
    also inside CoACD (with one worker it runs in the command's process).
    """
    kind = source_kind(source)
    try:
        obj = source.load(params.mass)
        data = generate_object(obj, params, object_file=source.object_file, stoppable=True)
    except Dg16mError as exc:  # a broken mesh (or an unusable object) fails only its own entry
        return {"status": "failed", "files": {}, "error": str(exc), "source": kind}
    return write_object(source, obj, data, out, params)


def write_object(
    source: ObjectSource,
    obj: GraspObject,
    data: DualGraspSet,
    out: str | os.PathLike[str],
    params: GenerationParameters,
) -> dict[str, Any]:
    """Write one generated object into the dataset folder ``out`` (``grasps/<id>.h5``, and
    ``meshes/<id>.obj`` for a procedural object, so the folder is self-contained); returns its
    manifest entry (``failed`` with the reason, and nothing written, when ``data`` holds no dual
    grasp)."""
    relative = f"{GRASPS_FOLDER}/{source.object_id}.h5"
    kind = source_kind(source)
    counts = data.metadata["counts"]
    if data.n == 0:
        return {
            "status": "failed",
            "files": {},
            "error": no_pairs_reason(counts, params),
            "counts": counts,
            "source": kind,
        }
    files = {"grasps": relative}
    if source.mesh is None:  # procedural: store the mesh so the folder is self-contained
        files["mesh"] = source.object_file
        write_bytes_atomic(Path(out) / files["mesh"], obj.mesh.export(file_type="obj").encode())
    write_dg16m(Path(out) / relative, data)
    return {
        "status": "ok",
        "source": kind,
        "files": files,
        "pairs": data.n,
        "passing": int(data.passing_indices.size),
        "failing": int(data.failed_indices.size),
        "counts": counts,
    }


def generate_dataset(
    sources: Sequence[ObjectSource],
    out: str | os.PathLike[str],
    params: GenerationParameters,
    *,
    workers: int = 1,
    backend: Backend = "local",
    address: str | None = None,
    progress: bool = True,
    on_object: Callable[[str, dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """Generate every object not yet finished in ``out``; returns the final manifest.

    Args:
        sources: the objects (unique ids).
        out: dataset folder: ``grasps/<id>.h5`` and ``manifest.json``.
        params: generator parameters (stored in the manifest; a rerun must use the same).
        workers: local processes (``backend="local"``).
        backend: ``"local"`` (process pool; 1 worker runs in this process) or ``"ray"``.
        address: Ray address (``"auto"`` or ``host:port``); None starts a local Ray on loopback.
        progress: show a progress bar with objects/s and ETA.
        on_object: called with (object id, entry) after each object is recorded.

    Raises:
        GenerationError: bad arguments, duplicate ids, or ``out`` holds a dataset made with
            other parameters or of the other kind of objects (procedural or meshes).
    """
    check_same_sources(Path(out), sources)
    return run_resumable(
        _task,
        sources,
        (str(Path(out).resolve()), params),
        root=Path(out),
        kind="grasps",
        parameters=params.to_dict(),
        folders=(GRASPS_FOLDER, "meshes"),
        error=GenerationError,
        workers=workers,
        backend=backend,
        address=address,
        progress=progress,
        desc="generate",
        on_entry=on_object,
    )
