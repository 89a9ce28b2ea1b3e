"""The offline generator: meshes or procedural objects in, one release-schema HDF5 per object out.

Per object (:func:`generate_object`): antipodal single-arm sampling, all unique pairs with the
0.1 m centre pruning and gripper-gripper collision rejection, force closure on every candidate
(verdict-only), then up to 2000 passing and 2000 failing pairs (failing losses proven > 0.5 and
computed exactly). The result is a :class:`~dataset_gen.io.DualGraspSet` in the release schema
with our extras under ``dg16m/``.

A dataset run (:func:`generate_dataset`) maps that task over objects with a local process pool or
Ray. Every object's random stream is derived from ``(seed, object id)`` alone, so the bytes of
each file do not depend on the worker count, the order or the backend. Files are written
atomically and the folder's ``manifest.json`` is rewritten after each object by the parent
process only; a rerun skips objects whose entry is ``ok`` and whose file exists, so an
interrupted run (even ``kill -9``) resumes to the same bytes. An object that cannot be loaded or
processed (a broken mesh) is recorded as ``failed`` with its reason and does not stop the run.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .atomic import write_bytes_atomic
from .errors import Dg16mError
from .io import (
    DualGraspSet,
    package_version,
    write_dg16m,
)
from .objects import GraspObject
from .pairing import candidate_pairs, dual_contacts, dual_poses, score_pairs, select_pairs
from .parallel import Backend, run_resumable
from .sampling import sample_antipodal_grasps
from .sources import ObjectSource, object_seed

GRASPS_FOLDER = "grasps"


class GenerationError(Dg16mError, ValueError):
    """Bad generator arguments (counts, folders, backend)."""


@dataclass(frozen=True)
class GenerationParameters:
    """Everything that decides a generated file's bytes (besides the object and package version).

    Attributes:
        seed: global seed; each object's stream is derived from (seed, object id).
        gripper: gripper model name (``dataset_gen.gripper.GRIPPERS``).
        n_grasps: single-arm grasps sampled per object (the release: 500).
        mu: friction coefficient for sampling and force closure.
        mass: object mass for the gravity wrench (kg; the release: 6).
        gravity: m/s^2 (the release: 10).
        f_high: force bound per contact (N; the release: 70).
        threshold: force-closure threshold on the residual norm (the release: 1e-5).
        convention: ``"physical"`` or ``"release"`` friction cones.
        min_center_distance: grasp-centre pruning distance (m; the release: 0.1).
        check_gripper_collision: reject pairs whose grippers collide (the release does not).
        max_passing, max_failing: pairs kept per object (the release: 2000 each).
        failing_min_loss: failing pairs kept must have a loss above this (the release: 0.5).
    """

    seed: int = 0
    gripper: str = "panda"
    n_grasps: int = 500
    mu: float = 0.4
    mass: float = 6.0
    gravity: float = 10.0
    f_high: float = 70.0
    threshold: float = 1e-5
    convention: Literal["physical", "release"] = "physical"
    min_center_distance: float = 0.1
    check_gripper_collision: bool = True
    max_passing: int = 2000
    max_failing: int = 2000
    failing_min_loss: float = 0.5

    def __post_init__(self) -> None:
        for name in ("n_grasps", "max_passing", "max_failing"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 0 or (name == "n_grasps" and value < 2):
                raise GenerationError(
                    f"{name}: expected an integer >= {2 if name == 'n_grasps' else 0}, found {value!r}"
                )
        if not isinstance(self.seed, int) or self.seed < 0:
            raise GenerationError(f"seed: expected an integer >= 0, found {self.seed!r}")


@dataclass
class StageTimes:
    """Seconds spent per stage of one object."""

    load: float = 0.0
    sampling: float = 0.0
    pairing: float = 0.0
    force_closure: float = 0.0
    selection: float = 0.0
    writing: float = 0.0

    @property
    def total(self) -> float:
        return sum(asdict(self).values())


def generate_object(
    obj: GraspObject,
    params: GenerationParameters,
    *,
    object_file: str,
    times: StageTimes | None = None,
) -> DualGraspSet:
    """Run sampling, pairing, force closure and selection for one object.

    Args:
        obj: the object, centred (object frame, m).
        params: generator parameters; the random stream is ``object_seed(params.seed, id)``.
        object_file: the string stored as ``object/file``.
        times: filled with the seconds spent per stage when given.

    Returns:
        The object's dual grasps (release schema) with extras: ``single_grasps`` (M, 4, 4),
        ``single_contact_points`` / ``single_contact_normals`` (M, 2, 3), ``single_widths`` (M,),
        ``pair_indices`` (S, 2) rows of the single grasps, ``contact_normals`` (S, 4, 3) outward
        normals used by the check, ``quality`` (S,) Q(G); metadata holds the parameters, the
        seeds, per-stage counts and the package version.
    """
    times = times if times is not None else StageTimes()
    rng = np.random.default_rng(object_seed(params.seed, obj.object_id))
    start = time.perf_counter()
    grasps = sample_antipodal_grasps(
        obj, gripper=params.gripper, n_grasps=params.n_grasps, mu=params.mu, rng=rng
    )
    times.sampling = time.perf_counter() - start

    start = time.perf_counter()
    candidates = candidate_pairs(
        grasps,
        min_center_distance=params.min_center_distance,
        check_gripper_collision=params.check_gripper_collision,
    )
    times.pairing = time.perf_counter() - start

    start = time.perf_counter()
    fc_kwargs = {
        "mass": params.mass,
        "gravity": params.gravity,
        "mu": params.mu,
        "f_high": params.f_high,
        "threshold": params.threshold,
    }
    result = score_pairs(grasps, candidates.pairs, convention=params.convention, **fc_kwargs)
    times.force_closure = time.perf_counter() - start

    start = time.perf_counter()
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
    data = DualGraspSet(
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
        },
        metadata={
            "object_id": obj.object_id,
            "gripper": params.gripper,
            "parameters": asdict(params),
            "object_seed": object_seed(params.seed, obj.object_id),
            "counts": counts,
            "generator": f"dg16m {package_version()}",
        },
    )
    times.selection = time.perf_counter() - start
    return data


def _task(source: ObjectSource, out: str, params: GenerationParameters) -> dict[str, Any]:
    """Load, generate and write one object; returns its manifest entry."""
    relative = f"{GRASPS_FOLDER}/{source.object_id}.h5"
    try:
        obj = source.load(params.mass)
        data = generate_object(obj, params, object_file=source.object_file)
    except Dg16mError as exc:  # a broken mesh (or an unusable object) fails only its own entry
        return {"status": "failed", "files": {}, "error": str(exc)}
    files = {"grasps": relative}
    if source.mesh is None:  # procedural: store the mesh so the folder is self-contained
        files["mesh"] = source.object_file
        write_bytes_atomic(Path(out) / files["mesh"], obj.mesh.export(file_type="obj").encode())
    write_dg16m(Path(out) / relative, data)
    return {
        "status": "ok",
        "files": files,
        "pairs": data.n,
        "passing": int(data.passing_indices.size),
        "failing": int(data.failed_indices.size),
        "counts": data.metadata["counts"],
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
            other parameters.
    """
    return run_resumable(
        _task,
        sources,
        (str(Path(out).resolve()), params),
        root=Path(out),
        kind="grasps",
        parameters=asdict(params),
        folders=(GRASPS_FOLDER, "meshes"),
        error=GenerationError,
        workers=workers,
        backend=backend,
        address=address,
        progress=progress,
        desc="generate",
        on_entry=on_object,
    )
