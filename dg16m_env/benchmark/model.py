"""The benchmark in memory: its rows, objects and parameters (:class:`Benchmark`,
:class:`BenchmarkObject`, :class:`BenchmarkParameters`), the arms (:data:`SOURCES`, :data:`ARMS`) and
:class:`BenchmarkError`. The file that stores it is :mod:`dg16m_env.benchmark.file` (its schema is
in that module's docstring); how it is built is :mod:`dg16m_env.benchmark.build`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from dataset_gen.objects.decomposition import (
    DecompositionParameters,
)
from dataset_gen.objects.grasp_object import (
    ConvexPart,
    GraspObject,
)
from dataset_gen.sources.object_source import (
    ObjectSource,
)
from dg16m_core.checks import check_fields, check_number, known_fields
from dg16m_core.errors import Dg16mError, MeshError
from dg16m_core.parameters import PAPER
from dg16m_env.physics.labels import (
    LEVELS,
    GraspLabels,
    LabelError,
    PerturbationSpec,
    concatenate_labels,
)
from dg16m_env.physics.scene import SceneParameters
from dg16m_env.physics.trial_protocol import TrialProtocol, TrialResults
from dg16m_env.rates import object_rate

FORMAT = "dg16m-benchmark"
SCHEMA_VERSION = 2
BENCHMARK_FILE = "benchmark.h5"
OBJECTS_FOLDER = "objects"

SOURCES = ("fc_pass", "fc_fail", "random", "farthest", "file_pass", "file_fail", "fc_robust")
"""Where a benchmark pair comes from (the arms): force-closure-passing candidates, failing
candidates with loss > ``PAPER.failing_min_loss``, random candidates, farthest pairs, the
passing / failing pairs of a user's DG16M file, or robust candidates (passing, and a disturbance
motion ratio <= 1 against every protocol load, :mod:`dataset_gen.grasps.robust`; an extra arm beyond
the paper, drawn when ``n_robust > 0``)."""

ARMS = ("fc_pass", "fc_fail", "random", "farthest")
"""The paper's four arms (Table III) of a sampled benchmark."""


FLOAT_SIM = ("max_displacement", "max_rotation_deg", "max_penetration")
"""The float fields of the trial results (the others are codes, counts and flags)."""


class BenchmarkError(Dg16mError, ValueError):
    """Bad benchmark arguments or a malformed benchmark file."""


@dataclass(frozen=True)
class BenchmarkParameters:
    """Everything that decides a benchmark's content (besides the objects and package version).

    Attributes:
        seed: global seed; each object's stream derives from (seed, object id).
        n_grasps: single-arm grasps sampled per object.
        n_passing: force-closure-passing candidate pairs per object (fewer if not available; the
            shortfall is filled with failing candidates).
        n_failing: failing candidate pairs per object (loss proven > ``failing_min_loss``).
        n_random: pairs drawn uniformly among the candidates per object.
        n_farthest: farthest pairs per object (drawn among the pairs joining each grasp to the
            grasp whose centre is farthest from it).
        n_robust: robust pairs per object (``fc_robust``, beyond the paper; 0, the default,
            draws none): passing candidates whose disturbance motion ratio is at most 1
            (:mod:`dataset_gen.grasps.robust`). Drawn after the other arms, so they do not change.
        failing_min_loss: failing candidates must have a loss above this (N).
        mu: friction coefficient (sampling, force closure and simulation).
        mass: object mass (kg).
        f_high: force bound per contact in the force-closure check (N).
        threshold: force-closure threshold (N).
        min_center_distance: pruning distance of the candidates (m).
        scene: simulation constants (``friction`` is set from ``mu``).
        protocol: trial protocol (``gravity`` is used by force closure too).
        perturbation: K, d and theta of the success probabilities (its seed is the labels').
        decomposition: CoACD's settings for mesh objects without convex parts (None, the
            default: :class:`dataset_gen.objects.decomposition.DecompositionParameters`' defaults); the
            parts are stored in the file, so labels never depend on a re-run of CoACD.
        hull_grid: round a mesh object's CoACD hull vertices to multiples of this many metres
            before anything uses them (sampling, simulation), so the file stores them exactly
            as int32 multiples, in half float32's compressed bytes (None, the default: as
            CoACD gave them). The real benchmark's 5e-5 m moves a vertex at most 0.025 mm
            per axis, against hulls that stand off the mesh by ~0.8 mm (p95); a sliver hull
            the grid flattens to no volume is left out (:func:`~dg16m_env.benchmark.build.grid_parts`).

    ``mu``, ``mass``, ``f_high``, ``threshold``, ``min_center_distance`` and the scene's and
    protocol's friction, squeeze force and gravity default to the paper's values
    (:data:`dg16m_core.parameters.PAPER`).
    """

    seed: int = 0
    n_grasps: int = 200
    n_passing: int = 40
    n_failing: int = 20
    n_random: int = 20
    n_farthest: int = 20
    n_robust: int = 0
    failing_min_loss: float = PAPER.failing_min_loss
    mu: float = PAPER.mu
    mass: float = PAPER.mass
    f_high: float = PAPER.f_high
    threshold: float = PAPER.threshold
    min_center_distance: float = PAPER.min_center_distance
    scene: SceneParameters = field(default_factory=SceneParameters)
    protocol: TrialProtocol = field(default_factory=TrialProtocol)
    perturbation: PerturbationSpec = field(default_factory=PerturbationSpec)
    decomposition: DecompositionParameters | None = None
    hull_grid: float | None = None

    def __post_init__(self) -> None:
        if self.hull_grid is not None:
            check_number("hull_grid", self.hull_grid, error=BenchmarkError)
        if self.decomposition is not None and not isinstance(
            self.decomposition, DecompositionParameters
        ):
            raise BenchmarkError(
                "decomposition: expected DecompositionParameters or None, found "
                f"{type(self.decomposition).__name__}"
            )
        check_fields(
            self,
            error=BenchmarkError,
            integers={
                "seed": 0,
                "n_grasps": 2,
                "n_passing": 0,
                "n_failing": 0,
                "n_random": 0,
                "n_farthest": 0,
                "n_robust": 0,
            },
            zero_allowed=("min_center_distance", "failing_min_loss"),
            skip=("scene", "protocol", "perturbation", "decomposition", "hull_grid"),
        )
        if self.scene.friction != self.mu:
            object.__setattr__(self, "scene", replace(self.scene, friction=self.mu))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields; ``n_robust`` only when an extra arm is drawn (so a benchmark
        built without it records the same parameters as before that arm existed)."""
        out = asdict(self)
        out["scene"] = self.scene.to_dict()
        if out["n_robust"] == 0:
            del out["n_robust"]
        if self.hull_grid is None:
            del out["hull_grid"]
        if self.decomposition is None:
            del out["decomposition"]
        else:
            out["decomposition"] = self.decomposition.to_dict()
        return out

    def decomposition_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`dataset_gen.objects.decomposition.object_parts`."""
        return {} if self.decomposition is None else {"params": self.decomposition}

    def force_closure_kwargs(self) -> dict[str, float]:
        """The force-closure problem of the benchmark's pairs: keyword arguments of
        :func:`dataset_gen.force_closure.evaluate` (``mass``, ``gravity`` from the protocol,
        ``mu``, ``f_high``, ``threshold``)."""
        return {
            "mass": self.mass,
            "gravity": self.protocol.gravity,
            "mu": self.mu,
            "f_high": self.f_high,
            "threshold": self.threshold,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> BenchmarkParameters:
        """The parameters :meth:`to_dict` wrote (a benchmark file's ``metadata["parameters"]``),
        with their scene and protocol; missing keys take their defaults.

        Raises:
            BenchmarkError: not a mapping, unknown keys or bad values (at any level).
        """
        values = known_fields(cls, data, what="parameters", error=BenchmarkError)
        try:
            if "scene" in values:
                values["scene"] = SceneParameters.from_dict(values["scene"])
            if "protocol" in values:
                values["protocol"] = TrialProtocol.from_dict(values["protocol"])
            if "perturbation" in values:
                values["perturbation"] = PerturbationSpec.from_dict(values["perturbation"])
            if "decomposition" in values:
                values["decomposition"] = DecompositionParameters(
                    **known_fields(
                        DecompositionParameters,
                        values["decomposition"],
                        what="decomposition",
                        error=BenchmarkError,
                    )
                )
        except Dg16mError as exc:
            raise BenchmarkError(f"parameters: {exc}") from None
        return cls(**values)


# --------------------------------------------------------------------------------------------
# In-memory benchmark
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class BenchmarkObject:
    """One object of a benchmark (see the file schema in the module docstring).

    ``center_of_mass`` ((3,) m, object frame) is ``None`` when the file predates it;
    ``reseat_max`` (m) is the re-seating limit the object's rows were built with (0 = off).
    """

    object_id: str
    family: str
    seed: int
    file: str
    scale: float
    mass: float
    parts: tuple[ConvexPart, ...]
    center_of_mass: np.ndarray | None = None
    reseat_max: float = 0.0
    mesh_vertices: np.ndarray | None = field(default=None, repr=False)
    mesh_faces: np.ndarray | None = field(default=None, repr=False)
    mesh_sha256: str = ""

    @property
    def has_mesh(self) -> bool:
        """The file carries this object's mesh (no mesh folder is needed to load it)."""
        return self.mesh_vertices is not None and self.mesh_faces is not None

    def source(self, mesh_root: str | os.PathLike[str] | None = None) -> ObjectSource:
        """Where the object comes from (procedural: family and seed; mesh: the mesh the file
        carries, checked against its ``mesh_sha256`` when the file was read; for files that
        carry none, ``mesh_root / file`` at the stored scale).

        Raises:
            BenchmarkError: a mesh object the file does not carry and no ``mesh_root``.
        """
        if self.family:
            return ObjectSource(self.object_id, family=self.family, family_seed=self.seed)
        if self.has_mesh:  # the object is what the file carries
            assert self.mesh_vertices is not None
            assert self.mesh_faces is not None
            return ObjectSource(
                self.object_id,
                mesh=Path(self.file),
                scale=self.scale,
                allow_any_size=True,
                mesh_arrays=(self.mesh_vertices, self.mesh_faces),
            )
        if mesh_root is None:
            raise BenchmarkError(
                f"{self.object_id}: expected a mesh folder holding {self.file!r}, found none given"
            )
        # The stored scale is what the benchmark was built with: no plausibility check on size.
        return ObjectSource(
            self.object_id,
            mesh=Path(mesh_root) / self.file,
            scale=self.scale,
            allow_any_size=True,
        )

    def load(self, mesh_root: str | os.PathLike[str] | None = None) -> GraspObject:
        """Rebuild the :class:`GraspObject` (see :meth:`source`) at the stored mass.

        Raises:
            BenchmarkError: no mesh to load, or a broken one.
        """
        try:
            return self.source(mesh_root).load(self.mass)
        except MeshError as exc:
            raise BenchmarkError(str(exc)) from None

    def __repr__(self) -> str:  # parts hold every hull vertex: count them instead
        origin = f"{self.family} seed {self.seed}" if self.family else f"mesh {self.file!r}"
        return (
            f"BenchmarkObject({self.object_id!r}, {origin}, scale {self.scale:.4g}, "
            f"mass {self.mass:.4g} kg, {len(self.parts)} convex parts)"
        )


@dataclass(eq=False)
class Benchmark:
    """Benchmark rows (N dual grasps over O objects); see the module docstring for units.

    Attributes:
        objects: the O objects.
        object_index: (N,) int32.
        poses: (N, 2, 4, 4).
        contact_points, contact_normals: (N, 4, 3).
        source: (N,) int8 index into :data:`SOURCES`.
        fc_passed: (N,) bool.
        fc_loss: (N,) float64.
        labels: the success probabilities (every trial's status, the nominal trial's full
            result, the perturbation seeds).
        metadata: parameters and provenance (JSON-ready).
        reseat_shift: (N, 2) float64 how far re-seating moved each hand back (m; zeros when
            nothing moved or the file predates it).
        hand_line_distance: (N,) float64 distance from the object's centre of mass to the line
            through the hands' grasp centres (m), or ``None`` when the file predates it.
    """

    objects: list[BenchmarkObject]
    object_index: np.ndarray
    poses: np.ndarray
    contact_points: np.ndarray
    contact_normals: np.ndarray
    source: np.ndarray
    fc_passed: np.ndarray
    fc_loss: np.ndarray
    labels: GraspLabels
    metadata: dict[str, Any] = field(default_factory=dict)
    reseat_shift: np.ndarray | None = None
    hand_line_distance: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.reseat_shift is None:
            self.reseat_shift = np.zeros((self.n, 2))

    @property
    def n(self) -> int:
        return int(self.object_index.size)

    @property
    def trials(self) -> TrialResults:
        """The nominal trials' full results."""
        return self.labels.nominal

    def p(self, level: str = "full") -> np.ndarray:
        """(N,) success probabilities at ``level`` (``"full"``: every disturbance, the headline;
        ``"gravity"``: held under gravity, the paper's)."""
        return self.labels.p(level)

    def label(self, level: str = "full") -> np.ndarray:
        """(N,) bool binary labels (``p >= 0.5``) at ``level``."""
        return self.labels.label(level)

    def arm_rows(self, arm: str) -> np.ndarray:
        """(N,) bool: the rows of one arm (:data:`SOURCES`)."""
        if arm not in SOURCES:
            raise BenchmarkError(f"arm: expected one of {SOURCES}, found {arm!r}")
        return self.source == SOURCES.index(arm)

    def parameters(self) -> BenchmarkParameters:
        """The parameters the benchmark was built with (from its metadata; scene and protocol
        included), e.g. ``bench.parameters().scene`` to compile a scene the way it was labelled.

        Raises:
            BenchmarkError: the metadata's parameters are malformed.
        """
        return BenchmarkParameters.from_dict(self.metadata.get("parameters", {}))

    def __repr__(self) -> str:  # N rows of poses and contacts: counts, not contents
        return (
            f"Benchmark({len(self.objects)} objects, {self.n} dual grasps, "
            f"{int(self.label().sum())} labelled success, {int((~self.trials.valid).sum())} "
            f"invalid nominal trials, {self.labels.spec.trials} trials per pair)"
        )

    def object_rows(self, object_id: str) -> np.ndarray:
        """Rows of one object."""
        ids = [o.object_id for o in self.objects]
        if object_id not in ids:
            raise BenchmarkError(f"object: expected one of the {len(ids)} ids, found {object_id!r}")
        return np.flatnonzero(self.object_index == ids.index(object_id))

    def select_objects(self, object_ids: Sequence[str]) -> Benchmark:
        """A benchmark of the given objects only (in the given order, rows in their stored
        order within each object), e.g. a small benchmark for tests.

        Raises:
            BenchmarkError: an unknown or repeated id.
        """
        if len(set(object_ids)) != len(object_ids):
            raise BenchmarkError(f"object_ids: expected unique ids, found {list(object_ids)}")
        rows = [self.object_rows(i) for i in object_ids]  # raises on unknown ids
        index = np.concatenate(
            [np.full(r.size, k, dtype=np.int32) for k, r in enumerate(rows)] or [np.zeros(0)]
        ).astype(np.int32)
        take = np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64)
        by_id = {o.object_id: o for o in self.objects}
        return Benchmark(
            objects=[by_id[i] for i in object_ids],
            object_index=index,
            poses=self.poses[take],
            contact_points=self.contact_points[take],
            contact_normals=self.contact_normals[take],
            source=self.source[take],
            fc_passed=self.fc_passed[take],
            fc_loss=self.fc_loss[take],
            labels=self.labels.select(take),
            metadata=dict(self.metadata),
            reseat_shift=self.reseat_shift[take],
            hand_line_distance=(
                None if self.hand_line_distance is None else self.hand_line_distance[take]
            ),
        )

    def summary(self, *, n_resamples: int = 2000, seed: int = 0) -> dict[str, Any]:
        """Per arm and level: FCE, GSR over all pairs and over valid ones (with object-resampled
        95 % confidence intervals, :func:`dg16m_env.rates.object_rate`), label rate, uncertain
        fraction; plus the nominal trials' counts (JSON-ready)."""
        valid = self.trials.valid
        by_arm: dict[str, Any] = {}
        for k, name in enumerate(SOURCES):
            rows = self.source == k
            if not rows.any():
                continue
            entry: dict[str, Any] = {
                "pairs": int(rows.sum()),
                "objects": int(np.unique(self.object_index[rows]).size),
                "valid": int((rows & valid).sum()),
                "fce": float(self.fc_passed[rows].mean()),
            }
            for level in LEVELS:
                p = self.p(level)
                entry[level] = {
                    "gsr": object_rate(p, self.object_index, rows, n_resamples, seed),
                    "gsr_valid": object_rate(p, self.object_index, rows & valid, n_resamples, seed),
                    "label_rate": float(self.label(level)[rows].mean()),
                    "uncertain_fraction": float(self.labels.uncertain(level)[rows].mean()),
                }
            by_arm[name] = entry
        return {
            "objects": len(self.objects),
            "pairs": self.n,
            "trials_per_pair": self.labels.spec.trials,
            "perturbation": self.labels.spec.to_dict(),
            "nominal_trials": self.trials.summary(),
            "by_arm": by_arm,
        }


def concatenate(parts: Sequence[Benchmark], metadata: Mapping[str, Any] | None = None) -> Benchmark:
    """One benchmark from several (objects appended in order; hand-line distances only when
    every part has them)."""
    if not parts:
        raise BenchmarkError("expected at least one object's benchmark, found none")
    objects: list[BenchmarkObject] = []
    index = []
    for part in parts:
        index.append(part.object_index + len(objects))
        objects.extend(part.objects)
    try:
        labels = concatenate_labels([p.labels for p in parts])
    except LabelError as exc:
        raise BenchmarkError(str(exc)) from None
    return Benchmark(
        objects=objects,
        object_index=np.concatenate(index).astype(np.int32),
        poses=np.concatenate([p.poses for p in parts]),
        contact_points=np.concatenate([p.contact_points for p in parts]),
        contact_normals=np.concatenate([p.contact_normals for p in parts]),
        source=np.concatenate([p.source for p in parts]),
        fc_passed=np.concatenate([p.fc_passed for p in parts]),
        fc_loss=np.concatenate([p.fc_loss for p in parts]),
        labels=labels,
        metadata=dict(metadata if metadata is not None else parts[0].metadata),
        reseat_shift=np.concatenate([p.reseat_shift for p in parts]),
        hand_line_distance=(
            np.concatenate([p.hand_line_distance for p in parts])
            if all(p.hand_line_distance is not None for p in parts)
            else None
        ),
    )


def hand_line_distance(centres: np.ndarray, center_of_mass: np.ndarray) -> np.ndarray:
    """(N,) distance (m) from ``center_of_mass`` (3,) to the line through each pair's two grasp
    centres ``centres`` (N, 2, 3) (:func:`dg16m_env.physics.trial.grasp_centres`, object frame); the
    distance to the common point when both centres coincide. A dual grasp turns most easily
    about that line: the further the centre of mass from it, the larger the torque a sideways
    load puts about it."""
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 2, 3)
    start = centres[:, 0]
    axis = centres[:, 1] - start
    length = np.linalg.norm(axis, axis=1)
    to_com = np.asarray(center_of_mass, dtype=np.float64) - start
    across = np.linalg.norm(np.cross(axis, to_com), axis=1)
    point = np.linalg.norm(to_com, axis=1)
    return np.where(length > 0, across / np.where(length > 0, length, 1.0), point)
