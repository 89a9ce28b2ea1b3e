"""Run a grasp predictor given as code (``module:callable``) in a child process, with limits.

A *predictor* is a function ``observation -> dual grasps``. It runs **only on this machine**, for
your own code: ``dg16m evaluate --predictor`` and ``dg16m submission make --predictor`` turn its
output into a submission file, and only that file (data, validated, never unpickled) is uploaded.
The leaderboard server never runs uploaded code.

Isolation model
---------------
The limits guard against mistakes (a hang, a leak, a crash), not against hostile code: the child
runs with your user's rights, sees your files and may use the network (on the cloud track, every
file but the benchmark's: see below).

* ``run_predictor`` starts one child process (``multiprocessing`` "spawn", Linux). Before
  importing the target, the child sets ``RLIMIT_CORE`` to 0 and ``RLIMIT_AS`` (virtual address
  space, soft and hard) to ``memory_limit_mb`` MiB (0: no limit). The limit counts the whole
  process: the interpreter and numpy already take about 150 MiB of address space (more with many
  BLAS threads), every thread reserves its stack, and CUDA maps far more than it uses, so GPU
  predictors need ``memory_limit_mb=0``. A limit below the child's baseline is a
  :class:`PredictorError`. The child also makes itself a process group leader and asks to be killed
  when this process dies. The predictor's own ``multiprocessing`` (pools, locks) uses this
  process's start method, not "spawn"; SIGTERM ends the child through its normal exit, so what
  it registered with the resource tracker is released.
* The child imports the target and reports back; an import failure (module or file not found,
  missing attribute, not callable, an exception at import, ``startup_time_limit_s`` exceeded) is
  one :class:`PredictorError`, raised before any object is run.
* Each observation is sent to the child (pickled: our own data, this process to the child). The
  child writes the result to a ``.npz`` file in a private temporary folder and answers with a
  JSON message; this process never unpickles anything the child produced
  (``np.load(..., allow_pickle=False)``) and validates every array itself.
* Each call may take ``time_limit_s``; the first call of each child process may in addition use
  what the import left of ``startup_time_limit_s`` (lazy model loading, JIT warm-up). A call that
  runs over is killed with the whole child (SIGTERM, then SIGKILL), and a fresh child takes the
  remaining objects; a child that dies (segfault, ``os._exit``, the kernel's OOM killer) is
  replaced the same way. If a replacement fails to start, the remaining objects fail with that
  reason.
  An exception raised by the callable (``MemoryError`` at the address-space limit included) is
  caught in the child and becomes that object's error; the child goes on.

The observation / return contract
---------------------------------
The callable receives one object's observation, a ``dict`` with the keys of
:func:`dg16m_env.subjects.observation.object_observation` (``object_id``, ``family``, ``points`` (P, 3)
float32, ``normals`` (P, 3) float32, ``bounds`` (2, 3), ``mesh_vertices`` (V, 3),
``mesh_faces`` (F, 3); object frame, m), and returns one of

* an array (K, 2, 4, 4): K dual grasps, the two hand poses of each (Panda grasp frame -> object
  frame, m), finite rigid transforms within the bounds a submission file accepts (the
  tolerances of :mod:`dg16m_env.subjects.submission`), 1 <= K <= ``max_grasps``;
* a tuple ``(poses, scores)`` with ``scores`` (K,) finite, higher = better;
* a dict ``{"poses": poses, "scores": scores}`` (``scores`` optional).

On the cloud track (``track="cloud"``, ``dg16m evaluate --predictor X --track cloud``) the
observation is :func:`dg16m_env.subjects.cloud_observation.cloud_observation` instead: no mesh.
See "The cloud track" below for its keys.

A bare return must be an array object (numpy, or anything with ``__array__``; torch tensors are
moved to the CPU first); inside a tuple or dict, anything ``np.asarray`` takes (lists too). Float
or integer dtypes only; everything is converted to float64. A call should not depend on earlier calls: after a
timeout or a crash a fresh process (a fresh import) runs the remaining objects.

"spawn" starts the child by importing the parent's ``__main__`` module: a script that calls
:func:`run_predictor` must do so under ``if __name__ == "__main__":``.

Every failure is recorded per object in :attr:`PredictorRun.errors` (the last line of a message is
its summary). :func:`submission_from_predictor` writes placeholder dual grasps that cannot
succeed (both hands 5 m away from the object) for each failed object, as many as the most grasps
the predictor returned for any object (:func:`failed_placeholders`), so a failed object scores 0
and weighs as much as an answered one; it never leaves the denominator. The failures are listed in
the submission's metadata.

The cloud track
---------------
A robot sees an object through its depth cameras, never its mesh. ``track="cloud"`` scores a
predictor on that footing; the harness, not the predictor, makes the observation:

* per object, ``n_cameras`` (default 2) depth cameras at poses drawn from
  ``object_seed(camera_seed, "cameras:<object id>")`` (fixed per object by the benchmark and
  ``camera_seed``, default 0: the same for every predictor), 128 x 128 pixels, 45 degrees
  vertical field of view, ray cast on the object's mesh in this process (no OpenGL);
* a seeded sensor model (``noise="kinect"``, the default: axial depth noise ``sigma(z) = 0.0012 +
  0.0019 (z - 0.4)^2`` m, pixels missing at grazing angles from 65 degrees on and at depth
  edges; ``noise="none"``: ideal depth), seeded by ``object_seed(noise_seed, "noise:<object
  id>")``;
* the observation holds ``points`` (P, 3) float32 (every depth pixel back-projected, P varies),
  ``normals`` (P, 3) float32 estimated from the noisy depth image (3 x 3 neighbourhoods, turned
  toward the camera), ``pixels`` (P, 3) int32 (camera, row, column), ``depth`` (C, H, W) float32
  (m along each optical axis, 0 = missing), ``intrinsics`` (3, 3) (K, pixels),
  ``camera_poses`` (C, 4, 4) (camera -> object frame, OpenCV axes: x right, y down, z forward)
  and ``fovy_deg``; no ``mesh_vertices``, ``mesh_faces``, ``bounds``, ``object_id`` or ``family``
  (an id names a procedural shape, which the generator could rebuild). Everything else of the
  contract (the object frame, the return value, the limits) is as above.

The harness enforces it. The mesh never leaves this process, and where Linux Landlock is
available (:mod:`dg16m_env.subjects.sandbox`) the child, before importing the target, makes
itself unable to read the benchmark file, the mesh folder and the package's data folder
(reading any of them raises ``PermissionError``, which fails that object). Where Landlock is
unavailable the run goes on with a warning and records ``"sandbox": "none"``. The submission's
metadata records the run's provenance under ``"track"``
(:func:`dg16m_env.subjects.track.track_record`: the track's name, the harness version, the
noise model and seed, the cameras and their seed, the sha256 of the predictor's source file, the
sandbox); a mesh-track run records ``{"name": "mesh", ...}``, and a file without the key is
mesh-track by construction. The record is self-declared, as the tracks of GraspNet-1Billion
are: the leaderboard shows tracks apart and never ranks one against the other.

The child process and its supervision (limits, messages, the checks of what it returns) are
:mod:`dg16m_env.subjects.predictor_process`; this module runs a predictor over a benchmark's
objects and turns its answers into a submission.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
import warnings
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from dg16m_env.benchmark.ref import BenchmarkRef
    from dg16m_env.subjects.cloud_observation import CloudTrack
from dg16m_env.subjects.predictor_process import (
    _METADATA_ERROR_BYTES,
    PredictorError,
    PredictorSpec,
    _StartError,
    _Worker,
)

#: Placeholder written for an object the predictor failed on: both hands, identity rotation,
#: 5 m from the object's centre of mass, where no grasp can touch it. (1, 2, 4, 4), m.
FAILED_PLACEHOLDER = np.tile(np.eye(4), (1, 2, 1, 1))
FAILED_PLACEHOLDER[0, 0, :3, 3] = (5.0, 0.0, 0.0)
FAILED_PLACEHOLDER[0, 1, :3, 3] = (5.0, 0.5, 0.0)
FAILED_PLACEHOLDER.setflags(write=False)


def failed_placeholders(answered: Mapping[str, np.ndarray]) -> np.ndarray:
    """The dual grasps written for an object the predictor failed on: :data:`FAILED_PLACEHOLDER`
    repeated as many times as the most grasps of any answered object (``answered``: object id
    -> (K, 2, 4, 4) poses), at least once. (K, 2, 4, 4), m."""
    k = max((len(p) for p in answered.values()), default=1)
    return np.repeat(FAILED_PLACEHOLDER, max(k, 1), axis=0)


@dataclass(eq=False)
class PredictorRun:
    """What a predictor produced, per object id, in the order the objects were run.

    Attributes:
        poses: object id -> (K, 2, 4, 4) float64 hand poses (m), for the objects that succeeded.
        scores: object id -> (K,) float64 scores, for those that returned scores.
        errors: object id -> error message (last line: the summary), for those that failed.
        seconds: object id -> wall seconds from sending the observation to the answer (s).
        target: the predictor's target.
        restarts: child processes started after a timeout or a death.
        sandbox: the read restriction its processes reported (:mod:`dg16m_env.subjects.sandbox`:
            ``"landlock-abi-N"``, or ``"none"`` where it was unavailable; the weakest of them);
            None when none was asked for.
    """

    poses: dict[str, np.ndarray] = field(default_factory=dict)
    scores: dict[str, np.ndarray] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    target: str = ""
    restarts: int = 0
    sandbox: str | None = None

    @property
    def object_ids(self) -> list[str]:
        """Every object run, in order."""
        return list(self.seconds)

    def summary(self) -> dict[str, Any]:
        """Counts, times (s) and every error (JSON-ready)."""
        seconds = list(self.seconds.values())
        return {
            "target": self.target,
            "objects": len(self.seconds),
            "succeeded": len(self.poses),
            "failed": len(self.errors),
            "restarts": self.restarts,
            "sandbox": self.sandbox,
            "dual_grasps": int(sum(len(p) for p in self.poses.values())),
            "seconds_total": float(sum(seconds)),
            "seconds_max": float(max(seconds, default=0.0)),
            "errors": dict(self.errors),
        }

    def __repr__(self) -> str:  # arrays: count them
        return (
            f"PredictorRun({self.target!r}: {len(self.poses)} objects succeeded, "
            f"{len(self.errors)} failed, {self.restarts} restarts)"
        )


def _object_id(observation: Any, run: PredictorRun) -> tuple[str, Any]:
    """The object id (a new, non-empty str) and the observation of an item of ``observations``:
    a dict with its ``object_id``, or an ``(object id, observation)`` pair (an observation
    without the id, e.g. the cloud track's)."""
    if isinstance(observation, tuple) and len(observation) == 2:
        object_id, observation = observation
    else:
        object_id = observation.get("object_id") if isinstance(observation, Mapping) else None
    if not isinstance(object_id, str) or not object_id:
        raise PredictorError(
            "observations: expected dicts with a non-empty str 'object_id', found "
            f"{type(observation).__name__} with object_id {object_id!r}"
        )
    if object_id in run.seconds:
        raise PredictorError(f"observations: expected unique object ids, found {object_id!r} twice")
    if not isinstance(observation, Mapping):
        raise PredictorError(
            f"observations: expected dicts, found {type(observation).__name__} for {object_id!r}"
        )
    return object_id, observation


def run_predictor(
    spec: PredictorSpec,
    observations: Iterable[Mapping[str, Any]],
    *,
    max_grasps: int = 100,
    progress: bool = False,
    forbidden: Iterable[str | os.PathLike[str]] | None = None,
) -> PredictorRun:
    """Run ``spec.target`` on every observation in a child process (see the module docstring).

    Args:
        spec: the target and its limits.
        observations: observation dicts (:func:`dg16m_env.subjects.observation.object_observation`),
            consumed lazily, one at a time; each needs a unique str ``object_id``, or is an
            ``(object id, observation)`` pair (only the observation is sent).
        max_grasps: dual grasps per object at most (K <= max_grasps).
        progress: show a progress bar (and each failure) on stderr.
        forbidden: paths the child must not read
            (:func:`dg16m_env.subjects.sandbox.restrict_reading`, before the target is imported;
            recorded in :attr:`PredictorRun.sandbox`); None: no restriction.

    Returns:
        Per object: the validated grasps, or the error (timeouts, deaths, exceptions and invalid
        return values do not stop the run).

    Raises:
        PredictorError: the target cannot be imported or is not callable, the child cannot start
            (e.g. a memory limit under its baseline), a malformed observation, bad ``max_grasps``.
    """
    if not isinstance(spec, PredictorSpec):
        raise PredictorError(f"spec: expected a PredictorSpec, found {type(spec).__name__}")
    if isinstance(max_grasps, bool) or not isinstance(max_grasps, (int, np.integer)):
        raise PredictorError(f"max_grasps: expected an integer >= 1, found {max_grasps!r}")
    if max_grasps < 1:
        raise PredictorError(f"max_grasps: expected an integer >= 1, found {max_grasps}")
    max_grasps = int(max_grasps)
    run = PredictorRun(target=spec.target)
    workdir = Path(tempfile.mkdtemp(prefix="dg16m-predictor-"))  # private: mode 0700
    blocked = None if forbidden is None else tuple(os.fspath(p) for p in forbidden)
    worker = _Worker(spec, max_grasps, workdir, blocked)
    bar = None
    try:
        try:
            worker.start()
        except _StartError as exc:
            raise PredictorError(f"predictor {spec.target!r} failed to start: {exc}") from None
        run.sandbox = worker.sandbox
        if progress:
            from dg16m_core.progress import progress_bar

            total = len(observations) if hasattr(observations, "__len__") else None
            bar = progress_bar(total=total, unit="object", desc="predictor")
        broken: str | None = None  # why no child can run the rest
        for index, item in enumerate(observations):
            object_id, observation = _object_id(item, run)
            started = time.perf_counter()
            outcome: tuple[np.ndarray, np.ndarray | None] | str
            if broken is None and not worker.alive:
                try:
                    worker.start()
                    run.restarts += 1
                    run.sandbox = _weakest(run.sandbox, worker.sandbox)
                except _StartError as exc:
                    reason = str(exc).splitlines()[-1] if str(exc) else "unknown"
                    broken = f"not run: the predictor could not be restarted: {reason}"
            if broken is not None:
                outcome = broken
            else:
                limit = spec.time_limit_s
                if worker.calls == 0:  # the first call may use what the import left over
                    limit += max(0.0, spec.startup_time_limit_s - worker.startup_s)
                outcome = worker.ask(index, observation, limit)
            run.seconds[object_id] = time.perf_counter() - started
            if isinstance(outcome, str):
                run.errors[object_id] = outcome
                if bar is not None:
                    bar.write(f"predictor: {object_id}: {outcome.splitlines()[-1]}")
            else:
                run.poses[object_id] = outcome[0]
                if outcome[1] is not None:
                    run.scores[object_id] = outcome[1]
            if bar is not None:  # one refresh per object (a log shows each update once)
                bar.set_postfix(failed=len(run.errors), refresh=False)
                bar.update(1)
        worker.close()
    finally:
        worker.stop()
        shutil.rmtree(workdir, ignore_errors=True)
        if bar is not None:
            bar.close()
    return run


def _weakest(a: str | None, b: str | None) -> str | None:
    """The weaker of two children's sandboxes (``"none"`` wins; None: not reported)."""
    if a is None or b is None:
        return a or b
    return "none" if "none" in (a, b) else a


# --------------------------------------------------------------------------------------------
# Submissions


class _Observations:
    """The benchmark's observations, built one at a time (sized, for the progress bar): mesh
    track, the observation dicts; cloud track (``cloud`` given), ``(object id, cloud
    observation)`` pairs."""

    def __init__(
        self,
        ref: BenchmarkRef,
        mesh_root: Path | None,
        n_points: int,
        seed: int,
        cloud: CloudTrack | None = None,
    ) -> None:
        self.ref, self.mesh_root, self.n_points, self.seed = ref, mesh_root, n_points, seed
        self.cloud = cloud

    def __len__(self) -> int:
        return len(self.ref.benchmark.objects)

    def __iter__(self) -> Iterator[dict[str, Any] | tuple[str, dict[str, Any]]]:
        from dg16m_env.subjects.observation import object_observation

        for obj in self.ref.benchmark.objects:
            grasp_object = obj.load(self.mesh_root)
            if self.cloud is not None:
                yield obj.object_id, self.cloud.observe(grasp_object)
            else:
                yield object_observation(grasp_object, n_points=self.n_points, seed=self.seed)


def _metadata_errors(
    errors: Mapping[str, str], budget: int = _METADATA_ERROR_BYTES
) -> dict[str, str]:
    """Each error's summary line, shortened so that all of them fit in about ``budget`` bytes."""
    if not errors:
        return {}
    cap = max(40, min(200, budget // len(errors) - max(len(i) for i in errors) - 8))
    out = {}
    for object_id, message in errors.items():
        summary = message.splitlines()[-1] if message else ""
        out[object_id] = summary if len(summary) <= cap else summary[: cap - 3] + "..."
    return out


def submission_from_predictor(
    spec: PredictorSpec,
    out_path: str | os.PathLike[str],
    *,
    benchmark: str | os.PathLike[str] | BenchmarkRef | None = None,
    mesh_root: str | os.PathLike[str] | None = None,
    n_points: int = 2048,
    seed: int = 0,
    max_grasps: int = 100,
    progress: bool = True,
    track: str = "mesh",
    cloud: CloudTrack | None = None,
) -> tuple[Path, PredictorRun]:
    """Run a predictor on every benchmark object (every object of a subset ref,
    :meth:`~dg16m_env.benchmark.ref.BenchmarkRef.subset`, and only those) and write its
    submission file atomically.

    Each object's observation (:func:`dg16m_env.subjects.observation.object_observation` with
    ``n_points`` and ``seed``) is built just before it is needed. An object the predictor failed
    on gets :func:`failed_placeholders` (as many copies of :data:`FAILED_PLACEHOLDER`, a dual
    grasp 5 m away that cannot succeed, as the most grasps the predictor returned for any
    object; no score): it scores 0, stays in the denominator and weighs as much there as an
    object the predictor answered, so failing on hard objects cannot raise a rate. The metadata
    records ``predictor`` (the target), ``failed_objects`` (id -> the error's summary line,
    shortened), ``failed_grasps_per_object``, ``n_points``, ``seed``, ``max_grasps``, the
    limits and ``track`` (:func:`dg16m_env.subjects.track.track_record`).

    ``track="cloud"``: each observation is the cloud track's
    (:func:`dg16m_env.subjects.cloud_observation.cloud_observation` with ``cloud``, default
    cameras and noise when None; ``n_points`` and ``seed`` are then unused), and the predictor's
    process cannot read the benchmark file, its mesh folder or the package's data folder
    (:mod:`dg16m_env.subjects.sandbox`; where Landlock is unavailable it runs anyway, with a
    warning, and the metadata says ``"sandbox": "none"``).

    Args:
        spec: the predictor and its limits.
        out_path: the submission file (HDF5) to write.
        benchmark: a benchmark file, a loaded :class:`BenchmarkRef`, or None for the embedded one.
        mesh_root: folder of a mesh benchmark's meshes (default: the ref's).
        n_points: points per observation.
        seed: seed of the observations' point clouds.
        max_grasps: dual grasps per object at most.
        progress: show a progress bar on stderr.
        track: ``"mesh"`` or ``"cloud"`` (:data:`dg16m_env.subjects.track.TRACKS`).
        cloud: the cloud track's cameras and noise (``track="cloud"`` only).

    Returns:
        The file written and the run (every error in full).

    Raises:
        PredictorError: see :func:`run_predictor`.
        BenchmarkError: an unreadable benchmark, a mesh object without ``mesh_root``.
        ObservationError: a bad ``n_points`` or ``seed``, a bad ``track`` or ``cloud``.
    """
    from dg16m_core.checks import check_integer
    from dg16m_env.benchmark.ref import load_benchmark_ref
    from dg16m_env.subjects.observation import ObservationError
    from dg16m_env.subjects.submission import EMBEDDED
    from dg16m_env.subjects.submission_writer import PartialSubmissionWarning, write_submission

    check_integer("n_points", n_points, minimum=1, error=ObservationError)
    check_integer("seed", seed, minimum=0, error=ObservationError)
    from dg16m_env.subjects.cloud_observation import CloudTrack
    from dg16m_env.subjects.track import TRACKS, forbidden_paths, track_record

    if track not in TRACKS:
        raise ObservationError(f"track: expected one of {TRACKS}, found {track!r}")
    if cloud is not None and (track != "cloud" or not isinstance(cloud, CloudTrack)):
        raise ObservationError(
            f"cloud: expected a CloudTrack with track='cloud', found {type(cloud).__name__} with "
            f"track={track!r}"
        )
    if track == "cloud" and cloud is None:
        cloud = CloudTrack()
    ref = load_benchmark_ref(benchmark, mesh_root)
    root = Path(mesh_root) if mesh_root is not None else ref.mesh_root
    run = run_predictor(
        spec,
        _Observations(ref, root, int(n_points), int(seed), cloud),
        max_grasps=max_grasps,
        progress=progress,
        forbidden=forbidden_paths(ref.path, root) if cloud is not None else None,
    )
    if cloud is not None and not (run.sandbox or "").startswith("landlock-"):
        warnings.warn(
            "cloud track: the predictor's process could read the benchmark (Linux Landlock is "
            "unavailable here); the submission records sandbox 'none'",
            stacklevel=2,
        )
    failed = failed_placeholders(run.poses)
    poses = {i: run.poses.get(i, failed) for i in ref.object_ids}
    metadata = {
        "predictor": spec.target,
        "failed_objects": _metadata_errors(run.errors),
        "failed_grasps_per_object": len(failed),
        "n_points": int(n_points),
        "seed": int(seed),
        "max_grasps": int(max_grasps),
        "time_limit_s": spec.time_limit_s,
        "memory_limit_mb": spec.memory_limit_mb,
        "track": track_record(
            track,
            spec.target,
            path=spec.path,
            cloud=cloud.record() if cloud is not None else None,
            sandbox=run.sandbox,
        ),
    }
    if ref.partial:
        metadata["objects"] = {"subset": ref.object_ids, "of": ref.full_objects}
    with warnings.catch_warnings():
        if ref.partial:  # asked for: a subset of the benchmark (``dg16m evaluate --limit``)
            warnings.simplefilter("ignore", PartialSubmissionWarning)
        path = write_submission(
            out_path,
            poses,
            scores=run.scores,
            benchmark=EMBEDDED if ref.embedded else ref.sha256,
            metadata=metadata,
        )
    return path, run
