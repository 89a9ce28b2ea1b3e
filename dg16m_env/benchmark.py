"""The simulation benchmark: dual grasps on fixed objects, each labelled by a success probability.

Building (``dg16m benchmark build``)
------------------------------------
For each object of the procedural ``benchmark`` split (300 objects, 10 families x 30), of a
folder of the user's meshes (``--meshes DIR``: each mesh file is an object, in metres unless
``--scale``; real meshes are simulated through their CoACD convex parts,
:func:`dataset_gen.decomposition.object_parts`), or of the user's meshes with DG16M grasp files
(``--grasps``: a folder of ``<id>.h5`` or a folder written by ``dg16m generate``, which holds
``grasps/<id>.h5`` and, for procedural objects, ``meshes/``):

1. sample :attr:`BenchmarkParameters.n_grasps` antipodal single-arm grasps (Panda hand);
2. pair them like the generator (``PAPER.min_center_distance`` centre pruning, gripper-gripper
   collision: the *candidates*) and check force closure; draw the paper's four arms
   (Table III, :data:`SOURCES`): up to ``n_passing`` force-closure-passing candidates
   (``fc_pass``), ``n_failing`` failing candidates whose loss is proven above
   ``PAPER.failing_min_loss`` (``fc_fail``, as the release keeps them; a shortfall of passing
   pairs is filled from them), ``n_random`` pairs drawn uniformly among the candidates
   (``random``, the paper's random dual-arm pairs) and ``n_farthest`` of the pairs that join each
   grasp to the grasp whose centre is farthest from it (``farthest``, the paper's diametrically
   opposite pairing). With a DG16M file instead, draw its stored passing / failing pairs
   (:func:`choose_file_pairs`) and move their poses from the file's gripper to the Panda hand
   (:func:`retarget_poses`). Optionally (``BenchmarkSource.reseat_max`` > 0, ``--reseat``:
   meant for DG16M files whose poses were made for another gripper) re-seat the hands
   (:mod:`dg16m_env.reseat`): a hand whose open palm or fingers penetrate the object's convex
   parts deeper than the protocol's ``invalid_penetration`` is moved back along its approach
   axis in 1 mm steps up to ``reseat_max`` until it clears; a hand that cannot clear stays (its
   trial is invalid and counts as a failure, the row is kept). Re-seating changes the grasp
   (the stored contacts stay the file's): every hand's shift is stored
   (``grasps/reseat_shift``) and how many moved, and how far, is always reported;
3. label every pair with its success probability (:mod:`dg16m_env.labels`): the trial protocol
   (:mod:`dg16m_env.trial`) at the nominal pose and at K seeded perturbations of it, at two
   levels (held through every disturbance; held under gravity).

Objects are independent tasks (process pool or Ray); each finished object is written to
``OUT/objects/<id>.h5`` and recorded in ``OUT/manifest.json``, so an interrupted build resumes.
The last step concatenates them, in the order of the object list, into ``OUT/benchmark.h5``.
Results do not depend on the number of workers or the backend.

File schema (``format = "dg16m-benchmark"``, ``schema_version = 2``)
----------------------------------------------------------------------
Root attributes: ``format``, ``schema_version``, ``metadata`` (JSON: parameters, with scene,
protocol and perturbation; phases, status names, sources, package version; ``mujoco``, the
MuJoCo version that simulated the trials, in files written since 2026-12-03; ``simulator``, only
for another engine than C MuJoCo; ``reseat``, only when
some object was re-seated: per such object :meth:`dg16m_env.reseat.Reseat.summary`, i.e. the
limit, hands, hands penetrating before, hands not cleared, hands moved with the median and
largest shift).

``OUT/manifest.json`` records per object its pairs, trials, labels, invalid nominal trials with
their reasons (``invalid_reasons``: ``hand0_penetrates``, ``hand1_penetrates``,
``hands_overlap``) and, when re-seated, the same ``reseat`` summary.

``objects/`` (O rows): ``ids`` (str), ``families`` (str, "" for meshes), ``seeds`` (int64, -1 for
meshes), ``files`` (str: mesh file, relative to the build's mesh folder, "" for procedural),
``scales`` (float64), ``masses`` (float64, kg), ``parts`` (str: JSON list of
:meth:`~dataset_gen.objects.ConvexPart.to_dict`, object frame, m); optional (absent in files
written before them): ``centers_of_mass`` ((O, 3) float64, m, object frame: where the trial
applies the weight; absent = not known, ``None``), ``reseat_max`` ((O,) float64, m: the
re-seating limit the object was built with, 0 = off; absent = 0).

Mesh objects also carry (only when some object is a mesh): their meshes as read from their
files, ``mesh_counts`` ((O, 2) int64: vertices and faces per object, 0 for procedural ones),
``mesh_vertices`` ((sum V, 3) float64, m, the file's frame; or int32 multiples of
``10**-decimals`` m, ``decimals`` its attribute, when that holds every coordinate exactly, as
an OBJ file's fixed-point text does: read as ``multiples / 10**decimals`` in float64, with
``mesh_negative_zeros`` (int64 flat indices, present when any) set to -0.0),
``mesh_faces`` ((sum F, 3) int32, indices into the object's own vertices) and ``mesh_sha256`` ((O,) str,
:func:`dataset_gen.hashing.mesh_sha256` of the arrays; "" for procedural ones; a stored mesh
that does not hash to it is refused on reading; the carried mesh is the object, so no mesh folder
is read for it); and their convex hulls as arrays instead of JSON (``parts`` is then ``"[]"``):
``hull_objects`` ((O,) int32 hulls per object), ``hull_counts`` ((H,) int32 vertices per hull)
and ``hull_vertices`` ((sum, 3) float64, or float32 when every value is exactly a float32; m,
object frame; or int32 multiples of its attribute ``grid_m`` (m) when the benchmark was built
with ``hull_grid``, read as ``multiples * grid_m`` in float64, the vertices simulated).

``grasps/`` (N rows): ``object_index`` (int32 row of ``objects/``), ``poses`` (N, 2, 4, 4) float64
hand poses gripper -> object frame (m, dg16m grasp frame of the Panda hand),
``contact_points`` (N, 4, 3) float64 (m), ``contact_normals`` (N, 4, 3) float64 outward unit
normals (NaN when the source file has none), ``source`` (int8, index into :data:`SOURCES`),
``fc_passed`` (bool), ``fc_loss`` (float64, N: force-closure residual); optional:
``reseat_shift`` ((N, 2) float64, m: how far each hand was moved back along its approach axis
by re-seating, 0 = not moved; absent = zeros) and ``hand_line_distance`` ((N,) float64, m: the
distance from the object's centre of mass to the line through the two hands' grasp centres,
:func:`dg16m_env.trial.grasp_centres`; the weak mode of two parallel-jaw grasps is rotation
about that line; absent = not known, ``None``).

``sim/`` (N rows, see :class:`dg16m_env.trial.TrialResults`): ``status`` (int8
:class:`~dg16m_env.trial.TrialStatus`), ``success`` (bool, the nominal trial held),
``failing_phase`` (int8 index into :data:`~dg16m_env.trial.PHASES`, -1 none),
``invalid_reason`` (int8), ``max_displacement`` (float64, m), ``max_rotation_deg`` (float64),
``max_penetration`` (float64, m), ``contacts_after_close`` and ``contacts_final`` ((N, 2)
int16), ``ejected`` (bool): the nominal trial's full result.

``labels/`` (N rows, see :class:`dg16m_env.labels.GraspLabels`; K = ``n_perturbations``):
``trial_status`` and ``trial_phase`` ((N, K + 1) int8: every trial's status and failing phase,
column 0 the nominal trial), ``seeds`` (int64 per-row perturbation seeds), ``p_success`` and
``p_gravity`` (float64: the success probabilities at the two levels; checked against
``trial_status`` / ``trial_phase`` on reading), ``label`` (bool, ``p_success >= 0.5``).

Version 1 files (one trial per pair, three pair sources) are refused with a message that says
so; rebuild them with ``dg16m benchmark build``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from dataset_gen.atomic import atomic_path
from dataset_gen.budget import StageTimeoutError, run_with_budget
from dataset_gen.checks import check_fields, check_integer, check_number, known_fields
from dataset_gen.clearance import collision_parts
from dataset_gen.decomposition import (
    MIN_RELATIVE_HULL_VOLUME,
    DecompositionParameters,
    decomposition_report,
    object_parts,
)
from dataset_gen.errors import Dg16mError, MeshError
from dataset_gen.force_closure import evaluate
from dataset_gen.gripper import get_gripper
from dataset_gen.hashing import mesh_sha256
from dataset_gen.io import (
    DualGraspSet,
    package_version,
    read_dg16m,
    write_array,
)
from dataset_gen.objects import (
    MESH_SUFFIXES,
    ConvexPart,
    GraspObject,
    part_from_dict,
    read_mesh_arrays,
)
from dataset_gen.pairing import (
    candidate_pairs,
    dual_contacts,
    dual_poses,
    farthest_pairs,
    random_pairs,
    score_pairs,
    select_pairs,
)
from dataset_gen.parallel import Backend, run_resumable
from dataset_gen.parameters import PAPER
from dataset_gen.procedural import benchmark_specs
from dataset_gen.robust import robust_pairs
from dataset_gen.sampling import sample_antipodal_grasps
from dataset_gen.sources import (
    ObjectSource,
    mesh_sources,
    object_seed,
    procedural_sources,
    read_ids,
)
from dg16m_env.labels import (
    LEVELS,
    GraspLabels,
    LabelError,
    PerturbationSpec,
    concatenate_labels,
    row_seeds,
    success_probability,
)
from dg16m_env.rates import object_rate
from dg16m_env.reseat import reseat_poses, shift_summary
from dg16m_env.scene import SceneParameters, compile_scene
from dg16m_env.simulator import Simulator, check_simulator
from dg16m_env.trial import PHASES, TrialProtocol, TrialResults, TrialStatus, grasp_centres

FORMAT = "dg16m-benchmark"
SCHEMA_VERSION = 2
BENCHMARK_FILE = "benchmark.h5"
OBJECTS_FOLDER = "objects"

SOURCES = ("fc_pass", "fc_fail", "random", "farthest", "file_pass", "file_fail", "fc_robust")
"""Where a benchmark pair comes from (the arms): force-closure-passing candidates, failing
candidates with loss > ``PAPER.failing_min_loss``, random candidates, farthest pairs, the
passing / failing pairs of a user's DG16M file, or robust candidates (passing, and a disturbance
motion ratio <= 1 against every protocol load, :mod:`dataset_gen.robust`; an extra arm beyond
the paper, drawn when ``n_robust > 0``)."""

ARMS = ("fc_pass", "fc_fail", "random", "farthest")
"""The paper's four arms (Table III) of a sampled benchmark."""

EMBEDDED_BENCHMARK = Path(__file__).with_name("data") / BENCHMARK_FILE
"""The procedural benchmark built with the default parameters, shipped with the package."""

REAL_BENCHMARK = Path(__file__).with_name("data") / "benchmark_real.h5"
"""The real-object benchmark (:mod:`dg16m_env.real_benchmark`): 300 furniture models, shipped."""

SHIPPED_BENCHMARKS: Mapping[str, Path] = {"procedural": EMBEDDED_BENCHMARK, "real": REAL_BENCHMARK}
"""Benchmarks by short name; ``"procedural"`` is the default everywhere a benchmark is taken."""

SHIPPED_MUJOCO_VERSION = "4.0.0"
"""The MuJoCo release that simulated the stored trials of both shipped benchmarks (pinned in
``pyproject.toml``). Another release changes contacts and so some trials: under 4.0.1 a rebuild
of the first procedural objects flips binary labels (BENCHMARKS.md, "MuJoCo version"). Files
built since 2026-12-03 record their version in ``metadata["mujoco"]``."""


def benchmark_file(benchmark: str | os.PathLike[str] | None = None) -> Path:
    """The file of a benchmark given by short name (:data:`SHIPPED_BENCHMARKS`), by path, or
    ``None`` (the procedural one).

    Raises:
        BenchmarkError: a short name whose file is not shipped in this installation.
    """
    if benchmark is None:
        return EMBEDDED_BENCHMARK
    if isinstance(benchmark, str) and benchmark in SHIPPED_BENCHMARKS:
        path = SHIPPED_BENCHMARKS[benchmark]
        if not path.is_file():
            raise BenchmarkError(
                f"benchmark {benchmark!r}: expected the shipped file {path}, found none (this "
                "installation lacks it: reinstall the package, or build it with "
                "'dg16m benchmark build-real' and pass the path of its benchmark.h5)"
            )
        return path
    return Path(benchmark)


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
            (:mod:`dataset_gen.robust`). Drawn after the other arms, so they do not change.
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
            default: :class:`dataset_gen.decomposition.DecompositionParameters`' defaults); the
            parts are stored in the file, so labels never depend on a re-run of CoACD.
        hull_grid: round a mesh object's CoACD hull vertices to multiples of this many metres
            before anything uses them (sampling, simulation), so the file stores them exactly
            as int32 multiples, in half float32's compressed bytes (None, the default: as
            CoACD gave them). The real benchmark's 5e-5 m moves a vertex at most 0.025 mm
            per axis, against hulls that stand off the mesh by ~0.8 mm (p95); a sliver hull
            the grid flattens to no volume is left out (:func:`grid_parts`).

    ``mu``, ``mass``, ``f_high``, ``threshold``, ``min_center_distance`` and the scene's and
    protocol's friction, squeeze force and gravity default to the paper's values
    (:data:`dataset_gen.parameters.PAPER`).
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
        """Keyword arguments of :func:`dataset_gen.decomposition.object_parts`."""
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


# --------------------------------------------------------------------------------------------
# File I/O
# --------------------------------------------------------------------------------------------


def _strings(group: h5py.Group, name: str, values: Sequence[str]) -> None:
    group.create_dataset(
        name, data=list(values), dtype=h5py.string_dtype("utf-8"), track_times=False
    )


def write_benchmark(path: str | os.PathLike[str], bench: Benchmark, *, level: int = 4) -> None:
    """Write ``bench`` to ``path`` atomically and deterministically (equal data, equal bytes)."""
    metadata = json.dumps(bench.metadata, sort_keys=True, allow_nan=False)
    with atomic_path(path) as tmp, h5py.File(tmp, "w", track_order=False) as f:
        f.attrs.create("format", FORMAT, dtype=h5py.string_dtype("utf-8"))
        f.attrs.create("schema_version", np.int64(SCHEMA_VERSION))
        f.attrs.create("metadata", metadata, dtype=h5py.string_dtype("utf-8"))
        objects = f.create_group("objects", track_order=False)
        _strings(objects, "ids", [o.object_id for o in bench.objects])
        _strings(objects, "families", [o.family for o in bench.objects])
        _strings(objects, "files", [o.file for o in bench.objects])
        hulls = [_hull_parts(o) for o in bench.objects]
        _strings(
            objects,
            "parts",
            [
                "[]"
                if h is not None
                else json.dumps([p.to_dict() for p in o.parts], sort_keys=True)
                for o, h in zip(bench.objects, hulls, strict=True)
            ],
        )
        if any(h is not None for h in hulls):
            grid = bench.metadata.get("parameters", {}).get("hull_grid")
            _write_hulls(objects, hulls, level, grid)
        write_array(objects, "seeds", np.array([o.seed for o in bench.objects], np.int64), None)
        write_array(objects, "scales", np.array([o.scale for o in bench.objects]), None)
        write_array(objects, "masses", np.array([o.mass for o in bench.objects]), None)
        write_array(
            objects, "reseat_max", np.array([o.reseat_max for o in bench.objects], float), None
        )
        if any(o.has_mesh for o in bench.objects):
            _write_meshes(objects, bench.objects, level)
        if bench.objects and all(o.center_of_mass is not None for o in bench.objects):
            centers = np.array([o.center_of_mass for o in bench.objects], dtype=np.float64)
            write_array(objects, "centers_of_mass", centers, None)
        grasps = f.create_group("grasps", track_order=False)
        write_array(grasps, "object_index", bench.object_index.astype(np.int32), level)
        write_array(grasps, "poses", bench.poses.astype(np.float64), level)
        write_array(grasps, "contact_points", bench.contact_points.astype(np.float64), level)
        write_array(grasps, "contact_normals", bench.contact_normals.astype(np.float64), level)
        write_array(grasps, "source", bench.source.astype(np.int8), level)
        write_array(grasps, "fc_passed", bench.fc_passed.astype(bool), level)
        write_array(grasps, "fc_loss", bench.fc_loss.astype(np.float64), level)
        write_array(grasps, "reseat_shift", bench.reseat_shift.astype(np.float64), level)
        if bench.hand_line_distance is not None:
            distance = bench.hand_line_distance.astype(np.float64)
            write_array(grasps, "hand_line_distance", distance, level)
        sim = f.create_group("sim", track_order=False)
        for name in TrialResults.ARRAY_FIELDS:
            write_array(sim, name, np.asarray(getattr(bench.trials, name)), level)
        write_array(sim, "success", bench.trials.success, level)
        labels = f.create_group("labels", track_order=False)
        write_array(labels, "trial_status", bench.labels.status.astype(np.int8), level)
        write_array(labels, "trial_phase", bench.labels.failing_phase.astype(np.int8), level)
        write_array(labels, "seeds", bench.labels.seeds.astype(np.int64), level)
        write_array(labels, "p_success", bench.labels.p_success, level)
        write_array(labels, "p_gravity", bench.labels.p_gravity, level)
        write_array(labels, "label", bench.labels.label(), level)


def _hull_parts(obj: BenchmarkObject) -> list[np.ndarray] | None:
    """A mesh object's parts as hull vertex arrays when every part is a hull in the object
    frame (CoACD's), stored as arrays (``objects/hull_*``); else ``None`` (parts as JSON)."""
    if obj.family or not obj.parts:
        return None
    identity = np.eye(4)
    if not all(
        p.kind == "mesh" and p.vertices is not None and np.array_equal(p.pose, identity)
        for p in obj.parts
    ):
        return None
    return [np.asarray(p.vertices, dtype=np.float64) for p in obj.parts]


def _write_hulls(
    objects: h5py.Group,
    hulls: Sequence[list[np.ndarray] | None],
    level: int,
    grid: float | None = None,
) -> None:
    per_object = np.array([0 if h is None else len(h) for h in hulls], dtype=np.int32)
    arrays = [v for h in hulls if h is not None for v in h]
    write_array(objects, "hull_objects", per_object, None)
    write_array(objects, "hull_counts", np.array([len(v) for v in arrays], dtype=np.int32), level)
    vertices = np.concatenate(arrays).reshape(-1, 3)
    if grid is not None:
        multiples = grid_multiples(vertices, grid)
        fits = np.abs(multiples).max(initial=0) < 2**31
        if fits and same_bits(on_grid(multiples, grid), vertices):  # built on the grid
            write_array(objects, "hull_vertices", multiples.astype(np.int32), level)
            objects["hull_vertices"].attrs.create("grid_m", np.float64(grid))
            return
    single = vertices.astype(np.float32)
    if np.array_equal(single.astype(np.float64), vertices):  # exactly float32: half the bytes
        vertices = single
    write_array(objects, "hull_vertices", vertices, level)


def _read_hulls(f: h5py.File, path: Path, o: int) -> list[list[ConvexPart]]:
    """The parts stored as hull arrays (``objects/hull_*``), per object (empty when none)."""
    if "objects/hull_objects" not in f:
        return [[] for _ in range(o)]
    per_object = _read(f, path, "objects/hull_objects", (o,), "i")
    counts = _read(f, path, "objects/hull_counts", (int(per_object.sum()),), "i")
    vertices = _read(f, path, "objects/hull_vertices", (None, 3), "fi")
    if vertices.dtype.kind == "i":
        grid = f["objects/hull_vertices"].attrs.get("grid_m")
        if grid is None or not np.isfinite(grid) or not float(grid) > 0:
            raise BenchmarkError(
                f"{path}: objects/hull_vertices: expected integer multiples with a positive "
                f"'grid_m' attribute (m), found grid_m {grid!r}"
            )
        vertices = on_grid(vertices, float(grid))
    if per_object.min(initial=0) < 0 or counts.min(initial=4) < 4 or counts.sum() != len(vertices):
        raise BenchmarkError(
            f"{path}: objects/hull_counts: expected counts >= 4 summing to the "
            f"{len(vertices)} hull vertices stored, found sum {int(counts.sum())}"
        )
    out: list[list[ConvexPart]] = []
    starts = np.concatenate([[0], np.cumsum(counts)])
    k = 0
    identity = np.eye(4)
    for n in per_object.tolist():
        parts = []
        for _ in range(n):
            block = vertices[starts[k] : starts[k + 1]].astype(np.float64)
            try:
                parts.append(ConvexPart("mesh", identity, (), block))
            except Dg16mError as exc:
                raise BenchmarkError(f"{path}: objects/hull_vertices, hull {k}: {exc}") from None
            k += 1
        out.append(parts)
    return out


def _write_meshes(objects: h5py.Group, items: Sequence[BenchmarkObject], level: int) -> None:
    counts = np.array(
        [
            (len(o.mesh_vertices), len(o.mesh_faces))
            if o.mesh_vertices is not None and o.mesh_faces is not None
            else (0, 0)
            for o in items
        ],
        dtype=np.int64,
    ).reshape(-1, 2)
    vertices = [o.mesh_vertices for o in items if o.mesh_vertices is not None]
    faces = [o.mesh_faces for o in items if o.mesh_faces is not None]
    write_array(objects, "mesh_counts", counts, None)
    stacked = np.concatenate(vertices).astype(np.float64).reshape(-1, 3)
    decimals = _decimal_places(stacked)
    if decimals is None:
        write_array(objects, "mesh_vertices", stacked, level)
    else:
        multiples = np.round(stacked * 10.0**decimals).astype(np.int32)
        write_array(objects, "mesh_vertices", multiples, level)
        objects["mesh_vertices"].attrs.create("decimals", np.int64(decimals))
        negative_zeros = np.flatnonzero(np.signbit(stacked) & (stacked == 0))
        if negative_zeros.size:  # an OBJ file's "-0.00000000": kept, for the hash
            write_array(objects, "mesh_negative_zeros", negative_zeros.astype(np.int64), level)
    write_array(objects, "mesh_faces", np.concatenate(faces).astype(np.int32).reshape(-1, 3), level)
    _strings(objects, "mesh_sha256", [o.mesh_sha256 for o in items])


MAX_DECIMALS = 9


def _from_decimals(multiples: np.ndarray, decimals: int) -> np.ndarray:
    """(V, 3) integers -> (V, 3) float64 ``multiples / 10**decimals`` (m): correctly rounded,
    so equal to the float an OBJ file's decimal text parses to."""
    return np.asarray(multiples, dtype=np.int64).astype(np.float64) / 10.0**decimals


def _decimal_places(vertices: np.ndarray) -> int | None:
    """The fewest decimal places (<= :data:`MAX_DECIMALS`) that hold every coordinate exactly
    as an int32 multiple (a mesh read from an OBJ file's fixed-point text: 8 for trimesh's),
    or None (stored as float64)."""
    for decimals in range(MAX_DECIMALS + 1):
        scaled = np.round(vertices * 10.0**decimals)
        if np.abs(scaled).max(initial=0) >= 2**31:
            return None
        if same_bits(_from_decimals(scaled.astype(np.int64), decimals), vertices + 0.0):
            return decimals  # (-0.0 + 0.0 is 0.0: negative zeros are stored apart)
    return None


def _read_meshes(
    f: h5py.File, path: Path, o: int
) -> list[tuple[np.ndarray, np.ndarray, str] | None]:
    """The carried meshes (``objects/mesh_*``), checked against their hashes; ``None`` for an
    object without one (procedural) or when the file carries none."""
    if "objects/mesh_counts" not in f:
        return [None] * o
    counts = _read(f, path, "objects/mesh_counts", (o, 2), "i")
    vertices = _read(f, path, "objects/mesh_vertices", (None, 3), "fi")
    if vertices.dtype.kind == "i":
        decimals = f["objects/mesh_vertices"].attrs.get("decimals")
        if decimals is None or not 0 <= int(decimals) <= MAX_DECIMALS:
            raise BenchmarkError(
                f"{path}: objects/mesh_vertices: expected integer multiples with a 'decimals' "
                f"attribute in [0, {MAX_DECIMALS}], found decimals {decimals!r}"
            )
        vertices = _from_decimals(vertices, int(decimals))
        if "objects/mesh_negative_zeros" in f:
            zeros = _read(f, path, "objects/mesh_negative_zeros", (None,), "i")
            if zeros.size and (zeros.min() < 0 or zeros.max() >= vertices.size):
                raise BenchmarkError(
                    f"{path}: objects/mesh_negative_zeros: expected flat indices in "
                    f"[0, {vertices.size}), found [{zeros.min()}, {zeros.max()}]"
                )
            vertices.reshape(-1)[zeros] = -0.0
    faces = _read(f, path, "objects/mesh_faces", (None, 3), "i")
    hashes = [s.decode() for s in _read(f, path, "objects/mesh_sha256", (o,), "OS")]
    if (
        counts.min(initial=0) < 0
        or counts[:, 0].sum() != len(vertices)
        or counts[:, 1].sum() != len(faces)
    ):
        raise BenchmarkError(
            f"{path}: objects/mesh_counts: expected counts summing to the {len(vertices)} "
            f"vertices and {len(faces)} faces stored, found sums {counts.sum(axis=0).tolist()}"
        )
    out: list[tuple[np.ndarray, np.ndarray, str] | None] = []
    v0 = f0 = 0
    for i, (nv, nf) in enumerate(counts.tolist()):
        if nv == 0:
            out.append(None)
            continue
        v, fc = vertices[v0 : v0 + nv].astype(np.float64), faces[f0 : f0 + nf].astype(np.int64)
        v0, f0 = v0 + nv, f0 + nf
        if fc.size and (fc.min() < 0 or fc.max() >= nv):
            raise BenchmarkError(
                f"{path}: objects/mesh_faces of object {i}: expected indices in [0, {nv}), "
                f"found [{fc.min()}, {fc.max()}]"
            )
        if mesh_sha256(v, fc) != hashes[i]:
            raise BenchmarkError(
                f"{path}: objects/mesh_sha256 of object {i}: expected the stored mesh to hash to "
                f"{hashes[i]}, found {mesh_sha256(v, fc)} (the mesh bytes were changed)"
            )
        out.append((v, fc, hashes[i]))
    return out


def _read(
    f: h5py.File, path: Path, key: str, shape: tuple[int | None, ...], kinds: str
) -> np.ndarray:
    if key not in f:
        raise BenchmarkError(f"{path}: expected dataset {key!r}, found it missing")
    arr = f[key][()]
    if (
        arr.dtype.kind not in kinds
        or arr.ndim != len(shape)
        or any(want is not None and got != want for got, want in zip(arr.shape, shape, strict=True))
    ):
        raise BenchmarkError(
            f"{path}: {key}: expected shape {shape} of kind {kinds!r}, found {arr.shape} "
            f"{arr.dtype}"
        )
    return arr


def read_benchmark(path: str | os.PathLike[str]) -> Benchmark:
    """Read a benchmark file (validating the schema in the module docstring).

    Raises:
        BenchmarkError: not a benchmark file, wrong version, missing or mis-shaped datasets,
            indices out of range, non-finite poses.
    """
    path = Path(path)
    try:
        f = h5py.File(path, "r")
    except (OSError, FileNotFoundError) as exc:
        raise BenchmarkError(
            f"{path}: expected a dg16m benchmark HDF5 file, found: {exc}"
        ) from None
    with f:
        fmt = f.attrs.get("format")
        fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
        if fmt != FORMAT:
            raise BenchmarkError(f"{path}: expected format {FORMAT!r}, found {fmt!r}")
        version = int(f.attrs.get("schema_version", -1))
        if version == 1:
            raise BenchmarkError(
                f"{path}: expected schema_version {SCHEMA_VERSION}, found 1: a version 1 "
                "benchmark labels each pair with one trial at the exact pose (written before "
                "benchmark protocol v2); "
                "version 2 labels are success probabilities over perturbed trials. Rebuild it "
                "with `dg16m benchmark build` (the shipped benchmark is version 2)"
            )
        if version != SCHEMA_VERSION:
            raise BenchmarkError(
                f"{path}: expected schema_version {SCHEMA_VERSION}, found {version}"
            )
        try:
            metadata = json.loads(f.attrs["metadata"])
        except (KeyError, ValueError) as exc:
            raise BenchmarkError(f"{path}: expected JSON metadata, found: {exc}") from None
        ids = [s.decode() for s in _read(f, path, "objects/ids", (None,), "OS")]
        o = len(ids)
        families = [s.decode() for s in _read(f, path, "objects/families", (o,), "OS")]
        files = [s.decode() for s in _read(f, path, "objects/files", (o,), "OS")]
        parts_json = [s.decode() for s in _read(f, path, "objects/parts", (o,), "OS")]
        seeds = _read(f, path, "objects/seeds", (o,), "i")
        scales = _read(f, path, "objects/scales", (o,), "f")
        masses = _read(f, path, "objects/masses", (o,), "f")
        reseat_max = (
            _read(f, path, "objects/reseat_max", (o,), "f")
            if "objects/reseat_max" in f
            else np.zeros(o)
        )
        centers = (
            _read(f, path, "objects/centers_of_mass", (o, 3), "f")
            if "objects/centers_of_mass" in f
            else None
        )
        meshes = _read_meshes(f, path, o)
        hulls = _read_hulls(f, path, o)
        index = _read(f, path, "grasps/object_index", (None,), "i")
        n = index.size
        arrays = {
            "poses": _read(f, path, "grasps/poses", (n, 2, 4, 4), "f"),
            "contact_points": _read(f, path, "grasps/contact_points", (n, 4, 3), "f"),
            "contact_normals": _read(f, path, "grasps/contact_normals", (n, 4, 3), "f"),
            "source": _read(f, path, "grasps/source", (n,), "i"),
            "fc_passed": _read(f, path, "grasps/fc_passed", (n,), "b"),
            "fc_loss": _read(f, path, "grasps/fc_loss", (n,), "f"),
            "reseat_shift": (
                _read(f, path, "grasps/reseat_shift", (n, 2), "f")
                if "grasps/reseat_shift" in f
                else np.zeros((n, 2))
            ),
            "hand_line_distance": (
                _read(f, path, "grasps/hand_line_distance", (n,), "f")
                if "grasps/hand_line_distance" in f
                else None
            ),
        }
        sim = {}
        for name in TrialResults.ARRAY_FIELDS:
            shape: tuple[int | None, ...] = (n, 2) if name.startswith("contacts") else (n,)
            kinds = "f" if name in FLOAT_SIM else ("b" if name == "ejected" else "i")
            sim[name] = _read(f, path, f"sim/{name}", shape, kinds)
        try:
            parameters = BenchmarkParameters.from_dict(metadata.get("parameters", {}))
        except Dg16mError as exc:
            raise BenchmarkError(f"{path}: metadata: {exc}") from None
        trials = parameters.perturbation.trials
        label_arrays = {
            "status": _read(f, path, "labels/trial_status", (n, trials), "i"),
            "failing_phase": _read(f, path, "labels/trial_phase", (n, trials), "i"),
            "seeds": _read(f, path, "labels/seeds", (n,), "i"),
        }
        stored_p = {
            "p_success": _read(f, path, "labels/p_success", (n,), "f"),
            "p_gravity": _read(f, path, "labels/p_gravity", (n,), "f"),
        }
        stored_label = _read(f, path, "labels/label", (n,), "b")
    codes = label_arrays["status"]
    if n and not np.isin(codes, [s.value for s in TrialStatus]).all():
        raise BenchmarkError(
            f"{path}: labels/trial_status: expected TrialStatus codes 0-{len(TrialStatus) - 1}, "
            f"found {int(codes[~np.isin(codes, [s.value for s in TrialStatus])][0])}"
        )
    phases = label_arrays["failing_phase"]
    if n and (phases.min() < -1 or phases.max() >= len(PHASES)):
        raise BenchmarkError(
            f"{path}: labels/trial_phase: expected values in [-1, {len(PHASES)}), found "
            f"[{phases.min()}, {phases.max()}]"
        )
    if n and (index.min() < 0 or index.max() >= o):
        raise BenchmarkError(
            f"{path}: grasps/object_index: expected values in [0, {o}), found "
            f"[{index.min()}, {index.max()}]"
        )
    if not np.isfinite(arrays["poses"]).all():
        raise BenchmarkError(f"{path}: grasps/poses: expected finite poses, found NaN/inf")
    optional = {
        "grasps/reseat_shift": arrays["reseat_shift"],
        "grasps/hand_line_distance": arrays["hand_line_distance"],
        "objects/reseat_max": reseat_max,
        "objects/centers_of_mass": centers,
    }
    for key, values in optional.items():
        if values is None or not values.size:
            continue
        if not np.isfinite(values).all():
            raise BenchmarkError(f"{path}: {key}: expected finite values, found NaN/inf")
        if key != "objects/centers_of_mass" and values.min() < 0:
            raise BenchmarkError(
                f"{path}: {key}: expected values >= 0 m, found {float(values.min())!r}"
            )
    if n and (arrays["source"].min() < 0 or arrays["source"].max() >= len(SOURCES)):
        raise BenchmarkError(f"{path}: grasps/source: expected values in [0, {len(SOURCES)})")
    objects = []
    for i in range(o):
        try:
            parts = tuple(part_from_dict(p) for p in json.loads(parts_json[i]))
        except (ValueError, TypeError, Dg16mError) as exc:
            raise BenchmarkError(f"{path}: objects/parts[{i}] ({ids[i]}): {exc}") from None
        parts = (*parts, *hulls[i])
        objects.append(
            BenchmarkObject(
                ids[i],
                families[i],
                int(seeds[i]),
                files[i],
                float(scales[i]),
                float(masses[i]),
                parts,
                center_of_mass=None if centers is None else centers[i].astype(np.float64),
                reseat_max=float(reseat_max[i]),
                **(
                    {}
                    if meshes[i] is None
                    else dict(
                        zip(("mesh_vertices", "mesh_faces", "mesh_sha256"), meshes[i], strict=True)
                    )
                ),
            )
        )
    try:
        labels = GraspLabels(
            nominal=TrialResults(**sim, protocol=parameters.protocol),
            spec=parameters.perturbation,
            status=label_arrays["status"].astype(np.int8),
            failing_phase=label_arrays["failing_phase"].astype(np.int8),
            seeds=label_arrays["seeds"].astype(np.int64),
        )
    except LabelError as exc:
        raise BenchmarkError(f"{path}: labels: {exc}") from None
    for name, stored in stored_p.items():
        derived = getattr(labels, name)
        if not np.array_equal(stored, derived):
            row = int(np.argmax(stored != derived))
            raise BenchmarkError(
                f"{path}: labels/{name}: expected the fraction of held trials in "
                f"labels/trial_status, found {stored[row]!r} against {derived[row]!r} in row {row}"
            )
    if not np.array_equal(stored_label, labels.label()):
        row = int(np.argmax(stored_label != labels.label()))
        raise BenchmarkError(
            f"{path}: labels/label: expected p_success >= 0.5, found {bool(stored_label[row])} "
            f"with p_success {labels.p_success[row]!r} in row {row}"
        )
    return Benchmark(
        objects=objects,
        object_index=index.astype(np.int32),
        labels=labels,
        metadata=metadata,
        **arrays,
    )


# --------------------------------------------------------------------------------------------
# Building one object
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BenchmarkSource:
    """One object to benchmark: where it comes from, and optionally a DG16M file of its grasps.

    Attributes:
        source: the object (procedural or mesh file).
        grasp_file: a DG16M file (release schema) whose pairs are simulated instead of sampling.
        grasp_gripper: the gripper whose frame the file's poses use (the release: robotiq_2f85;
            files written by dg16m record theirs); poses are moved so that their contacts sit at
            the Panda hand's contact depth.
        reseat_max: re-seating limit (m; 0 = off, the default): each open hand deeper in the
            object than the protocol's ``invalid_penetration`` is moved back along its approach
            axis up to this far until it clears (:func:`dg16m_env.reseat.reseat_poses`). Meant
            for DG16M files made for another gripper; it changes the grasp, and every shift is
            stored and reported. Recorded per object (``objects/reseat_max``).
    """

    source: ObjectSource
    grasp_file: Path | None = None
    grasp_gripper: str | None = None
    reseat_max: float = 0.0

    def __post_init__(self) -> None:
        value = self.reseat_max
        if not (isinstance(value, (int, float)) and np.isfinite(value) and value >= 0):
            raise BenchmarkError(
                f"{self.object_id}: reseat_max: expected a finite number >= 0 m, found {value!r}"
            )

    @property
    def object_id(self) -> str:
        return self.source.object_id


def _choose(rows: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    if count >= rows.size:
        return rows
    return np.sort(rng.choice(rows, size=count, replace=False))


def retarget_poses(poses: np.ndarray, from_gripper: str, to_gripper: str = "panda") -> np.ndarray:
    """Move grasp poses along their approach axis so that contacts made at ``from_gripper``'s
    contact depth sit at ``to_gripper``'s (both in the dg16m grasp frame; (..., 4, 4), m)."""
    shift = get_gripper(from_gripper).contact_depth - get_gripper(to_gripper).contact_depth
    out = np.array(poses, dtype=np.float64, copy=True)
    out[..., :3, 3] += shift * out[..., :3, 1]
    return out


def file_gripper(data: DualGraspSet, gripper: str | None = None) -> str:
    """The gripper whose frame a DG16M file's poses use: ``gripper`` when given, else the one the
    file records, else robotiq_2f85 (the release's)."""
    return gripper or data.metadata.get("gripper", "robotiq_2f85")


def file_poses(data: DualGraspSet, rows: np.ndarray, gripper: str | None = None) -> np.ndarray:
    """(len(rows), 2, 4, 4) the Panda hand poses of a DG16M file's pairs ``rows``: the file's
    poses moved from :func:`file_gripper`'s frame to the Panda's (:func:`retarget_poses`)."""
    return retarget_poses(data.grasps[rows], file_gripper(data, gripper))


def _object_metadata(
    obj: GraspObject, source: ObjectSource, parts: Sequence[ConvexPart], reseat_max: float
) -> BenchmarkObject:
    mesh: dict[str, Any] = {}
    if source.mesh is not None:  # a mesh object carries its mesh as read from its file
        vertices, faces = (
            source.mesh_arrays if source.mesh_arrays is not None else read_mesh_arrays(source.mesh)
        )
        mesh = {
            "mesh_vertices": np.asarray(vertices, dtype=np.float64),
            "mesh_faces": np.asarray(faces, dtype=np.int64),
            "mesh_sha256": mesh_sha256(vertices, faces),
        }
    return BenchmarkObject(
        **mesh,
        object_id=obj.object_id,
        family=source.family or "",
        seed=int(source.family_seed) if source.family_seed is not None else -1,
        file=source.mesh.name if source.mesh is not None else "",
        scale=float(obj.scale),
        mass=float(obj.mass_properties.mass),
        parts=tuple(parts),
        center_of_mass=np.asarray(obj.mass_properties.center_of_mass, dtype=np.float64).copy(),
        reseat_max=float(reseat_max),
    )


def hand_line_distance(centres: np.ndarray, center_of_mass: np.ndarray) -> np.ndarray:
    """(N,) distance (m) from ``center_of_mass`` (3,) to the line through each pair's two grasp
    centres ``centres`` (N, 2, 3) (:func:`dg16m_env.trial.grasp_centres`, object frame); the
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


def sampled_pairs(
    obj: GraspObject,
    params: BenchmarkParameters,
    rng: np.random.Generator,
    *,
    parts: Sequence[ConvexPart] | None = None,
) -> dict[str, np.ndarray]:
    """One object's pairs of the four arms (see the module docstring), in arm order.

    Draws from ``rng`` in a fixed order: grasps, the passing block, the failing pool's order,
    the random candidates, the farthest pairs, then the robust pairs. ``parts``: the object's
    convex parts when the caller already has them (the open-hand clearance rule is checked
    against them; default: :func:`dataset_gen.clearance.collision_parts`).
    """
    grasps = sample_antipodal_grasps(
        obj,
        n_grasps=params.n_grasps,
        mu=params.mu,
        rng=rng,
        collision_parts=collision_parts(obj, parts),
    )
    candidates = candidate_pairs(grasps, min_center_distance=params.min_center_distance)
    fc_kwargs = params.force_closure_kwargs()
    verdict = score_pairs(grasps, candidates.pairs, **fc_kwargs)
    cand_points, cand_normals = dual_contacts(grasps, candidates.pairs)
    take_pass = min(params.n_passing, int(np.sum(verdict.passed)))
    selection = select_pairs(
        verdict,
        cand_points,
        cand_normals,
        rng=rng,
        max_passing=params.n_passing,
        max_failing=params.n_failing + params.n_passing - take_pass,
        failing_min_loss=params.failing_min_loss,
    )
    random = random_pairs(grasps.n, params.n_random, rng, among=candidates.pairs)
    farthest = farthest_pairs(grasps)
    farthest = farthest[_choose(np.arange(len(farthest)), params.n_farthest, rng)]
    arms = {
        "fc_pass": candidates.pairs[selection.passing_indices],
        "fc_fail": candidates.pairs[selection.failing_indices],
        "random": random,
        "farthest": farthest,
    }
    if params.n_robust > 0:
        robust = robust_pairs(
            cand_points,
            cand_normals,
            verdict.passed,
            rng=rng,
            wanted=params.n_robust,
            mass_properties=obj.mass_properties,
            protocol=params.protocol.disturbances(),
            **fc_kwargs,
        )
        found = np.flatnonzero(robust.robust)
        arms["fc_robust"] = candidates.pairs[_choose(found, params.n_robust, rng)]
    pairs = np.concatenate(list(arms.values())).reshape(-1, 2)
    source = np.concatenate(
        [np.full(len(v), SOURCES.index(k), dtype=np.int8) for k, v in arms.items()]
    )
    points, normals = dual_contacts(grasps, pairs)
    exact = evaluate(points, normals, loss_rtol=1e-3, **fc_kwargs)  # exact losses, few pairs
    return {
        "poses": dual_poses(grasps, pairs),
        "contact_points": points,
        "contact_normals": normals,
        "source": source,
        "fc_passed": exact.passed,
        "fc_loss": exact.loss,
    }


def choose_file_pairs(
    data: DualGraspSet,
    n_passing: int | None,
    n_failing: int | None,
    rng: np.random.Generator,
    *,
    fill: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Which of a DG16M file's stored pairs to simulate: a seeded sample of its passing and of
    its failing pairs (each sorted; ``None`` takes all of that kind).

    Args:
        data: the file's contents (:func:`dataset_gen.io.read_dg16m`).
        n_passing: passing pairs to draw (at most).
        n_failing: failing pairs to draw (at most).
        rng: the stream the samples come from (passing first, then failing).
        fill: when the file has fewer passing pairs than ``n_passing``, draw the shortfall from
            the failing ones (the benchmark's rule, so every object keeps its row count).

    Returns:
        ``(passing, failing)`` row indices into ``data``.
    """
    passing = np.sort(data.passing_indices)
    take_pass = passing if n_passing is None else _choose(passing, n_passing, rng)
    want_fail = n_failing
    if fill and n_failing is not None and n_passing is not None:
        want_fail = n_failing + n_passing - take_pass.size
    failed = np.sort(data.failed_indices)
    take_fail = failed if want_fail is None else _choose(failed, want_fail, rng)
    return take_pass, take_fail


def _file_pairs(
    item: BenchmarkSource,
    data: DualGraspSet,
    params: BenchmarkParameters,
    rng: np.random.Generator,
) -> dict[str, np.ndarray]:
    take_pass, take_fail = choose_file_pairs(data, params.n_passing, params.n_failing, rng)
    rows = np.concatenate([take_pass, take_fail])
    normals = data.extras.get("contact_normals")
    return {
        "poses": file_poses(data, rows, item.grasp_gripper),
        "contact_points": data.contact_points[rows],
        "contact_normals": (
            normals[rows] if normals is not None else np.full((rows.size, 4, 3), np.nan)
        ),
        "source": np.concatenate(
            [
                np.full(take_pass.size, SOURCES.index("file_pass")),
                np.full(take_fail.size, SOURCES.index("file_fail")),
            ]
        ).astype(np.int8),
        "fc_passed": np.concatenate(
            [np.ones(take_pass.size, bool), np.zeros(take_fail.size, bool)]
        ),
        "fc_loss": data.loss_values[rows],
    }


class ObjectRejectedError(BenchmarkError):
    """An object that cannot give the benchmark enough passing pairs (see
    :func:`benchmark_object`'s ``min_passing``); ``stage`` says where it was found out."""

    def __init__(self, stage: str, message: str) -> None:
        super().__init__(message)
        self.stage = stage

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.stage, str(self)))


def screen_passing(obj: GraspObject, params: BenchmarkParameters) -> int:
    """How many force-closure-passing candidate pairs the object gives before its convex
    decomposition exists: ``params.n_grasps`` grasps sampled against the mesh alone (no
    open-hand clearance rule, which needs the parts), paired and checked as
    :func:`sampled_pairs` does, from a stream of its own (the benchmark's draws do not change).
    An upper estimate of what the build will find: the clearance rule only removes grasps."""
    rng = np.random.default_rng(object_seed(params.seed, f"benchmark-screen:{obj.object_id}"))
    grasps = sample_antipodal_grasps(obj, n_grasps=params.n_grasps, mu=params.mu, rng=rng)
    candidates = candidate_pairs(grasps, min_center_distance=params.min_center_distance)
    if len(candidates.pairs) == 0:
        return 0
    verdict = score_pairs(grasps, candidates.pairs, **params.force_closure_kwargs())
    return int(np.sum(verdict.passed))


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two float64 arrays hold the same bytes (so -0.0 differs from 0.0, as in a
    hash)."""
    a, b = np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def grid_multiples(vertices: np.ndarray, grid: float) -> np.ndarray:
    """(V, 3) vertices (m) -> (V, 3) int64 nearest multiples of ``grid`` (m)."""
    return np.round(np.asarray(vertices, dtype=np.float64) / grid).astype(np.int64)


def on_grid(multiples: np.ndarray, grid: float) -> np.ndarray:
    """(V, 3) integer multiples of ``grid`` (m) -> (V, 3) float64 vertices (m); the one
    formula both the build and the reader use, so stored hulls are the simulated ones."""
    return np.asarray(multiples, dtype=np.int64).astype(np.float64) * grid


def _grid_hull(part: ConvexPart, grid: float, min_volume: float) -> ConvexPart | None:
    """``part`` with its vertices on the grid, or None when that flattens it (a sliver thinner
    than the grid) to no volume above ``min_volume`` (m^3), as CoACD's own output is filtered
    (:data:`dataset_gen.decomposition.MIN_RELATIVE_HULL_VOLUME`)."""
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
    """A mesh's CoACD hulls on the grid (m), without those it flattens (:func:`_grid_hull`).

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


def benchmark_object(
    item: BenchmarkSource,
    params: BenchmarkParameters,
    simulator: Simulator | None = None,
    *,
    min_passing: int = 0,
    on_stage: Callable[[str], None] | None = None,
) -> Benchmark:
    """Choose, optionally re-seat (``item.reseat_max``; the summary goes to
    ``metadata["reseat"]``) and simulate one object's dual grasps on ``simulator`` (default C
    MuJoCo; another engine is named in ``metadata["simulator"]``), with each pair's hand-line
    distance and the object's centre of mass (see the module docstring).

    Args:
        min_passing: for sampled objects, the fewest ``fc_pass`` pairs the object must give
            (0 = any): checked before the convex decomposition (:func:`screen_passing`) and
            after sampling, before any trial; :class:`ObjectRejectedError` says which.
        on_stage: called with ``"load"``, ``"screen"`` (only with ``min_passing``),
            ``"decompose"``, ``"sample"`` and ``"label"`` as the work enters each (for time
            budgets, :func:`dataset_gen.budget.run_with_budget`).
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
    if min_passing and data is None:
        stage("screen")
        found = screen_passing(obj, params)
        if found < min_passing:
            raise ObjectRejectedError(
                "screen",
                f"{obj.object_id}: expected at least {min_passing} force-closure-passing "
                f"candidate pairs, found {found} before the clearance rule (screening)",
            )
    stage("decompose")
    parts = object_parts(obj, **params.decomposition_kwargs())
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


# --------------------------------------------------------------------------------------------
# Building many objects
# --------------------------------------------------------------------------------------------


def procedural_benchmark_sources(limit: int | None = None) -> list[BenchmarkSource]:
    """The 300 procedural benchmark objects (the first ``limit`` when given)."""
    specs = benchmark_specs()
    if limit is not None:
        if limit < 1:
            raise BenchmarkError(f"--limit: expected an integer >= 1, found {limit}")
        specs = specs[:limit]
    return [BenchmarkSource(s) for s in procedural_sources(specs)]


def read_split(split: str) -> list[str]:
    """Object ids from a split (:func:`dataset_gen.sources.read_ids`): a text file (one id per
    line, ``#`` comments), a JSON file's list (``split.json:key``) or ``a,b,c``."""
    try:
        return read_ids(split, flag="--split")
    except MeshError as exc:
        raise BenchmarkError(str(exc)) from None


def split_id(name: str) -> str:
    """An object id from a split entry: a file stem (``couch``) or a file name (``couch.obj``,
    ``couch.h5``, any mesh suffix) gives the stem; other dots are kept (``table-1.5``)."""
    path = Path(name.strip())
    if path.suffix.lower() in {*MESH_SUFFIXES, ".h5"}:
        return path.stem
    return path.name


def _split_ids(split: Sequence[str]) -> list[str]:
    ids = [split_id(s) for s in split]
    repeated = sorted({i for i in ids if ids.count(i) > 1})
    if repeated:
        raise BenchmarkError(f"--split: expected each object once, found {repeated} repeated")
    return ids


def _mesh_sources(
    meshes: str | os.PathLike[str], scale: float | None, allow_any_size: bool
) -> list[ObjectSource]:
    try:
        return mesh_sources(meshes, scale=scale, allow_any_size=allow_any_size)
    except Dg16mError as exc:
        raise BenchmarkError(str(exc)) from None


def mesh_benchmark_sources(
    meshes: str | os.PathLike[str],
    split: Sequence[str] | None = None,
    *,
    scale: float | None = None,
    allow_any_size: bool = False,
    reseat_max: float = 0.0,
) -> list[BenchmarkSource]:
    """Sources for a folder of the user's meshes without grasp files: each mesh file is an
    object (id = file stem) whose pairs are sampled, paired and checked like the procedural
    ones (:func:`sampled_pairs`).

    Args:
        meshes: folder of mesh files (:data:`~dataset_gen.objects.MESH_SUFFIXES`).
        split: the object ids to take, in this order (stems or file names); default all.
        scale: factor applied to the files' coordinates (default: the files are in metres).
        allow_any_size: accept objects whose longest side is outside the dual-arm range.
        reseat_max: re-seating limit (m, see :class:`BenchmarkSource`; 0 = off).

    Raises:
        BenchmarkError: no folder, no mesh files in it, or a split id without a mesh.
    """
    by_stem = {s.object_id: s for s in _mesh_sources(meshes, scale, allow_any_size)}
    ids = _split_ids(split) if split is not None else list(by_stem)
    missing = [i for i in ids if i not in by_stem]
    if missing:
        raise BenchmarkError(
            f"--split: expected a mesh file for each id in {meshes}, found none for {missing} "
            f"(the folder holds {sorted(by_stem)})"
        )
    return [BenchmarkSource(by_stem[i], reseat_max=reseat_max) for i in ids]


def grasp_folders(
    grasps: str | os.PathLike[str], meshes: str | os.PathLike[str] | None = None
) -> tuple[Path, Path]:
    """The folders of DG16M files and of meshes for ``--grasps`` / ``--meshes``: ``grasps`` is
    either a folder of ``<id>.h5`` files or a folder written by ``dg16m generate`` (it holds
    ``grasps/<id>.h5``, ``manifest.json`` and, for procedural objects, ``meshes/``, used when
    ``meshes`` is not given).

    Raises:
        BenchmarkError: ``grasps`` is no folder or holds no DG16M files, or no mesh folder is
            given or found.
    """
    root = Path(grasps)
    if not root.is_dir():
        raise BenchmarkError(f"--grasps: expected a folder of DG16M files, found no folder {root}")
    grasp_dir = root
    if not any(root.glob("*.h5")) and (root / "grasps").is_dir():
        grasp_dir = root / "grasps"
    if not any(grasp_dir.glob("*.h5")):
        raise BenchmarkError(
            f"--grasps {root}: expected DG16M files <id>.h5 (or a 'dg16m generate' folder with "
            "grasps/<id>.h5), found none"
        )
    if meshes is not None:
        return grasp_dir, Path(meshes)
    if grasp_dir != root and (root / "meshes").is_dir():
        return grasp_dir, root / "meshes"
    raise BenchmarkError(
        f"--grasps {root}: expected --meshes (the objects' mesh files) or a meshes/ folder "
        "beside its grasps/, found neither"
    )


def file_benchmark_sources(
    meshes: str | os.PathLike[str] | None,
    grasps: str | os.PathLike[str],
    split: Sequence[str] | None = None,
    *,
    grasp_gripper: str | None = None,
    reseat_max: float = 0.0,
) -> list[BenchmarkSource]:
    """Sources for a user's meshes and DG16M files: ``<id>.h5`` pairs with the mesh whose
    file name its ``object/file`` names (or ``<id>.*``). ``grasps`` and ``meshes`` are resolved
    by :func:`grasp_folders` (a ``dg16m generate`` folder works; ``meshes`` may then be
    ``None``); ``split`` ids may be stems or file names; ``reseat_max``: see
    :class:`BenchmarkSource`. Each file's ``object/scale`` is the mesh's scale."""
    grasp_dir, mesh_dir = grasp_folders(grasps, meshes)
    by_stem = {s.object_id: s for s in _mesh_sources(mesh_dir, None, False)}
    by_name = {s.mesh.name: s for s in by_stem.values() if s.mesh is not None}
    files = sorted(grasp_dir.glob("*.h5"))
    ids = _split_ids(split) if split is not None else [p.stem for p in files]
    out = []
    for object_id in ids:
        grasp_file = grasp_dir / f"{object_id}.h5"
        if not grasp_file.is_file():
            raise BenchmarkError(f"{object_id}: expected grasp file {grasp_file}, found none")
        named = Path(read_dg16m(grasp_file).object_file).name
        source = by_name.get(named) or by_stem.get(object_id)
        if source is None:
            raise BenchmarkError(
                f"{object_id}: expected its mesh {named!r} (or {object_id}.*) in {mesh_dir}, "
                "found none"
            )
        source = replace(source, object_id=object_id)
        out.append(
            BenchmarkSource(
                source, grasp_file=grasp_file, grasp_gripper=grasp_gripper, reseat_max=reseat_max
            )
        )
    return out


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

    Budgets are the child process's CPU seconds (:func:`dataset_gen.budget.run_with_budget`),
    not wall time, so that a loaded machine does not reject what a quiet one admits (and 4x the
    budget in wall time stops a stage that waits).

    An object past a budget is stopped (its child process is killed) and recorded as failed
    with ``rejected: "time budget"`` and the stage; one with too few pairs with ``rejected:
    "too few passing pairs"``. With any budget each object runs in a child process
    (:func:`dataset_gen.budget.run_with_budget`; about 2 s to start).
    """

    min_passing: int = 0
    decompose_s: float | None = None
    sample_s: float | None = None
    label_s: float | None = None

    def __post_init__(self) -> None:
        check_integer("min_passing", self.min_passing, error=BenchmarkError)
        for name in ("decompose_s", "sample_s", "label_s"):
            if getattr(self, name) is not None:
                check_number(name, getattr(self, name), error=BenchmarkError)

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
        return asdict(self)


def _budgeted_object(
    item: BenchmarkSource,
    params: BenchmarkParameters,
    simulator: Simulator,
    min_passing: int,
    *,
    on_stage: Callable[[str], None],
) -> Benchmark:
    return benchmark_object(item, params, simulator, min_passing=min_passing, on_stage=on_stage)


def _seconds(times: Mapping[str, float]) -> dict[str, float]:
    return {k: round(float(v), 1) for k, v in times.items()}


def _object_task(
    item: BenchmarkSource,
    out: str,
    params: BenchmarkParameters,
    simulator: Simulator,
    limits: BuildLimits | None = None,
) -> dict[str, Any]:
    relative = f"{OBJECTS_FOLDER}/{item.object_id}.h5"
    times: dict[str, float] = {}
    min_passing = limits.min_passing if limits is not None else 0
    try:
        if limits is not None and limits.budgets():
            done = run_with_budget(
                _budgeted_object, (item, params, simulator, min_passing), limits.budgets()
            )
            bench, times = done.value, done.times
        else:
            bench = benchmark_object(item, params, simulator, min_passing=min_passing)
    except (StageTimeoutError, ObjectRejectedError) as exc:
        timeout = isinstance(exc, StageTimeoutError)
        entry = {
            "status": "failed",
            "files": {},
            "error": f"{item.object_id}: {exc}" if timeout else str(exc),
            "rejected": "time budget" if timeout else "too few passing pairs",
            "stage": exc.stage,
        }
        if getattr(exc, "stage_times", None):  # set by run_with_budget
            entry["stage_seconds"] = _seconds(exc.stage_times)
        return entry
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
            entry["stage_seconds"] = _seconds(times)
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
) -> Path:
    """Build (or resume) a benchmark in ``out``; returns the path of ``benchmark.h5``.

    ``limits`` (:class:`BuildLimits`): the fewest passing pairs an object must give and time
    budgets per stage; objects that fail them are left out and listed in the manifest with
    the reason and stage (recorded in its parameters, so a resume with other limits is
    refused).

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
) -> dict[str, Any]:
    """Build (or resume) every object of ``items`` into ``root/objects/``; returns the
    manifest (one entry per object: ``ok`` with counts, or ``failed`` with the reason)."""
    return run_resumable(
        _object_task,
        items,
        (str(root.resolve()), params, simulator, limits),
        root=root,
        kind="benchmark",
        parameters=(
            dict(parameters)
            if parameters is not None
            else build_parameters(items, params, simulator, limits)
        ),
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
        BenchmarkError: none of them finished (the reasons are named).
    """
    done = [i for i in ids if manifest["entries"].get(i, {}).get("status") == "ok"]
    if not done:
        reasons = sorted(
            {manifest["entries"][i].get("error", "?") for i in ids if i in manifest["entries"]}
        )
        raise BenchmarkError(
            f"{root}: expected at least one object to build, found all failed: "
            + "; ".join(reasons[:5])
            + (f" (and {len(reasons) - 5} more, see manifest.json)" if len(reasons) > 5 else "")
        )
    parts = [read_benchmark(root / manifest["entries"][i]["files"]["benchmark"]) for i in done]
    metadata = benchmark_metadata(params, simulator)
    reseat = {k: v for part in parts for k, v in part.metadata.get("reseat", {}).items()}
    if reseat:
        metadata["reseat"] = reseat
    path = root / BENCHMARK_FILE
    write_benchmark(path, concatenate(parts, metadata))
    return path
