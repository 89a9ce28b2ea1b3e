"""The pairs an object gives the benchmark: the paper's four arms drawn from sampled candidates
(:func:`sampled_pairs`), or a DG16M file's stored passing and failing pairs
(:func:`choose_file_pairs`), and the screen that rejects an object with too few passing pairs
before anything is simulated (:func:`screen_passing`, :class:`ObjectRejectedError`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from dataset_gen.force_closure import evaluate
from dataset_gen.grasps.clearance import collision_parts
from dataset_gen.grasps.pairing import (
    candidate_pairs,
    dual_contacts,
    dual_poses,
    farthest_pairs,
    random_pairs,
    score_pairs,
    select_pairs,
)
from dataset_gen.grasps.robust import robust_pairs
from dataset_gen.grasps.sampling import sample_antipodal_grasps
from dataset_gen.io import (
    DualGraspSet,
)
from dataset_gen.objects.grasp_object import (
    ConvexPart,
    GraspObject,
    read_mesh_arrays,
)
from dataset_gen.sources.object_source import (
    ObjectSource,
    object_seed,
)
from dg16m_core.hashing import mesh_sha256
from dg16m_env.benchmark.model import SOURCES, BenchmarkError, BenchmarkObject, BenchmarkParameters
from dg16m_env.benchmark.sources import BenchmarkSource, file_poses


def _choose(rows: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    if count >= rows.size:
        return rows
    return np.sort(rng.choice(rows, size=count, replace=False))


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
    against them; default: :func:`dataset_gen.grasps.clearance.collision_parts`).
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
    :func:`~dg16m_env.benchmark.build.benchmark_object`'s ``min_passing``); ``stage`` says where
    it was found out."""

    def __init__(self, stage: str, message: str, verdict: str = "") -> None:
        super().__init__(message)
        self.stage = stage
        self.verdict = verdict
        """What the rejection means for the object, in words a user understands."""

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.stage, str(self), self.verdict))


def screen_passing(obj: GraspObject, params: BenchmarkParameters) -> int:
    """How many force-closure-passing candidate pairs the object gives before its convex
    decomposition exists: ``params.n_grasps`` grasps sampled against the mesh alone (no
    open-hand clearance rule, which needs the parts), paired and checked as
    :func:`sampled_pairs` does, from a stream of its own (the benchmark's draws do not change).
    An upper estimate of what the build will find: the clearance rule only removes grasps."""
    return screen_counts(obj, params)[1]


def screen_counts(obj: GraspObject, params: BenchmarkParameters) -> tuple[int, int]:
    """``(grasps, passing)``: the single-arm grasps :func:`screen_passing` found on the mesh
    (the hand fits around the object there) and its count of force-closure-passing pairs."""
    rng = np.random.default_rng(object_seed(params.seed, f"benchmark-screen:{obj.object_id}"))
    grasps = sample_antipodal_grasps(obj, n_grasps=params.n_grasps, mu=params.mu, rng=rng)
    candidates = candidate_pairs(grasps, min_center_distance=params.min_center_distance)
    if len(candidates.pairs) == 0:
        return len(grasps.poses), 0
    verdict = score_pairs(grasps, candidates.pairs, **params.force_closure_kwargs())
    return len(grasps.poses), int(np.sum(verdict.passed))


def screen_verdict(grasps: int, passing: int, min_passing: int, opening_m: float) -> str:
    """Why an object that gave ``passing`` < ``min_passing`` pairs at the screen is rejected, in
    words: the hand (``opening_m`` wide) fits around no part of it, or too few of its grasps
    pair into force closure."""
    cm = f"{100 * opening_m:.0f} cm"
    if grasps == 0:
        return (
            f"the gripper ({cm} opening) fits around no part of this object: none of the sampled "
            "grasps closes on two opposite faces without the open hand touching the object "
            "(parts thicker than the opening, bulky or upholstered shapes, or walls the hand "
            "cannot reach around; check the units too)"
        )
    return (
        f"the gripper ({cm} opening) fits around this object in {grasps} sampled places, but "
        f"only {passing} pairs of those grasps hold it in force closure ({min_passing} needed): "
        "too few graspable parts (thin rims, legs, handles, edges)"
    )
