"""Success probabilities: the label of a dual grasp under small changes of hand pose.

Benchmark protocol v2 (``../shared/DESIGN.md``). One trial at the exact pose is not a label: a
flat finger sits flush on a flat face, and a 1 mm / 1 degree change of hand pose flips about 10 %
of the force-closure-passing verdicts. So each dual grasp is simulated at its nominal pose and at
K seeded perturbations of it (:func:`perturb_poses`): each hand independently turned by
``rotation_deg`` about a uniformly random axis through its grasp centre and moved by
``translation`` in a uniformly random direction (both magnitudes exact, directions random).

* ``p_success`` = trials that held through the whole protocol / (K + 1) (the headline level);
* ``p_gravity`` = trials that held through *close* and *gravity* (the paper's description:
  close, gravity on, the object stays put); a trial that failed or turned unstable only during
  the disturbances counts as held at this level;
* an invalid trial (an open hand in the object, hands overlapping) counts as a failure at both
  levels, and so does a hand that touches nothing at the end of *close*
  (:attr:`~dg16m_env.physics.trial.TrialProtocol.min_contacts_after_close`);
* binary label: ``p >= 0.5``; rows with ``0.2 < p < 0.8`` are *uncertain*.

Each row's perturbations come from its own seed (:func:`row_seeds`: derived from a global seed
and a key such as the object id), so any row can be relabelled alone, in any order or batch,
and gives the same bytes on the same machine. :func:`success_probability` is the public entry
point: any set of dual grasps on any compiled scene.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from dataset_gen.sources.object_source import object_seed
from dg16m_core.checks import check_fields, check_integer, known_fields
from dg16m_core.errors import Dg16mError
from dg16m_env.physics.scene import Scene
from dg16m_env.physics.simulator import Simulator
from dg16m_env.physics.trial import run_trials
from dg16m_env.physics.trial_measures import grasp_centres
from dg16m_env.physics.trial_protocol import (
    PHASES,
    TrialProtocol,
    TrialResults,
    TrialStatus,
    check_dual_grasps,
)

GRAVITY_PHASE = PHASES.index("gravity")
"""Trials whose first failure comes after this phase held under gravity."""

UNCERTAIN = (0.2, 0.8)
"""Rows with ``UNCERTAIN[0] < p < UNCERTAIN[1]`` are flagged uncertain."""

LEVELS = ("full", "gravity")
"""The two levels of the protocol: held through all twelve disturbances (the headline), held
under gravity (the paper's description)."""


class LabelError(Dg16mError, ValueError):
    """Bad perturbation parameters, seeds or label arrays."""


@dataclass(frozen=True)
class PerturbationSpec:
    """How a dual grasp's success probability is measured (SI units).

    Attributes:
        n_perturbations: K, perturbed trials per dual grasp besides the nominal one.
        translation: d, each hand is moved by exactly this distance in a random direction (m).
        rotation_deg: theta, each hand is turned by exactly this angle about a random axis
            through its grasp centre (degrees).
        seed: global seed; each row's own seed derives from it (:func:`row_seeds`).
    """

    n_perturbations: int = 8
    translation: float = 0.001
    rotation_deg: float = 1.0
    seed: int = 0

    def __post_init__(self) -> None:
        check_fields(
            self,
            error=LabelError,
            integers={"n_perturbations": 0, "seed": 0},
            zero_allowed=("translation", "rotation_deg"),
        )

    @property
    def trials(self) -> int:
        """Trials per dual grasp (K + 1)."""
        return self.n_perturbations + 1

    def to_dict(self) -> dict[str, Any]:
        """The fields as a dict (:meth:`from_dict` reads it back)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PerturbationSpec:
        """The spec :meth:`to_dict` wrote (missing keys take their defaults).

        Raises:
            LabelError: not a mapping, unknown keys or bad values.
        """
        return cls(**known_fields(cls, data, what="perturbation", error=LabelError))


def row_seeds(seed: int, key: str, n: int) -> np.ndarray:
    """(n,) int64 non-negative per-row seeds, a function of ``(seed, key)`` only (``key``: e.g.
    the object id, so two objects never share perturbations)."""
    check_integer("seed", seed, minimum=0, error=LabelError)
    check_integer("n", n, minimum=0, error=LabelError)
    rng = np.random.default_rng(object_seed(seed, f"perturb:{key}"))
    return rng.integers(0, np.iinfo(np.int64).max, size=n, dtype=np.int64)


def _unit_vectors(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """(*shape, 3) uniformly random unit vectors."""
    v = rng.standard_normal((*shape, 3))
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    while np.any(norm < 1e-12):  # probability ~0; redraw rather than divide by zero
        v = np.where(norm < 1e-12, rng.standard_normal(v.shape), v)
        norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / norm


def _rotations(axes: np.ndarray, angle: float) -> np.ndarray:
    """(..., 3, 3) rotations by ``angle`` (rad) about unit ``axes`` (..., 3) (Rodrigues); the
    identity exactly when ``angle`` is 0."""
    x, y, z = axes[..., 0], axes[..., 1], axes[..., 2]
    zero = np.zeros_like(x)
    k = np.stack(
        [
            np.stack([zero, -z, y], axis=-1),
            np.stack([z, zero, -x], axis=-1),
            np.stack([-y, x, zero], axis=-1),
        ],
        axis=-2,
    )
    eye = np.broadcast_to(np.eye(3), k.shape)
    return eye + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def perturb_poses(
    grasps: np.ndarray, centres: np.ndarray, seeds: np.ndarray, spec: PerturbationSpec
) -> np.ndarray:
    """The K perturbed versions of each dual grasp.

    Args:
        grasps: (N, 2, 4, 4) hand poses, gripper frame -> object frame (m).
        centres: (N, 2, 3) each hand's grasp centre in the object frame (m), the point the hand
            turns about (:func:`dg16m_env.physics.trial.grasp_centres`).
        seeds: (N,) per-row seeds (:func:`row_seeds`).
        spec: K, d and theta.

    Returns:
        (N, K, 2, 4, 4) perturbed poses: rotation ``R' = Q R``, position
        ``t' = t + (Q - I)(t - c) + d u`` with ``Q`` a rotation by theta about a random unit axis
        and ``u`` a random unit vector, drawn per hand from the row's seed (axes first, then
        directions). With d = theta = 0 every perturbed pose equals the nominal bit for bit.
    """
    grasps = np.asarray(grasps, dtype=np.float64)
    seeds = np.asarray(seeds)
    n, k = len(grasps), spec.n_perturbations
    if seeds.shape != (n,) or seeds.dtype.kind not in "iu":
        raise LabelError(f"seeds: expected ({n},) integers, found {seeds.shape} {seeds.dtype}")
    if n and seeds.min() < 0:
        raise LabelError(f"seeds: expected non-negative integers, found {int(seeds.min())}")
    if n and int(seeds.max()) > np.iinfo(np.int64).max:  # stored as int64
        raise LabelError(f"seeds: expected integers below 2**63, found {int(seeds.max())}")
    axes = np.empty((n, k, 2, 3))
    directions = np.empty((n, k, 2, 3))
    for i, seed in enumerate(seeds.tolist()):
        rng = np.random.default_rng(seed)
        axes[i] = _unit_vectors(rng, (k, 2))
        directions[i] = _unit_vectors(rng, (k, 2))
    q = _rotations(axes, np.radians(spec.rotation_deg))  # (N, K, 2, 3, 3)
    rot = grasps[:, None, :, :3, :3]
    pos = grasps[:, None, :, :3, 3]
    out = np.broadcast_to(grasps[:, None], (n, k, 2, 4, 4)).copy()
    out[..., :3, :3] = q @ rot
    lever = (pos - centres[:, None])[..., None]
    turned = ((q - np.eye(3)) @ lever)[..., 0]
    out[..., :3, 3] = pos + turned + spec.translation * directions
    return out


def trial_poses(
    scene: Scene, grasps: np.ndarray, seeds: np.ndarray, spec: PerturbationSpec
) -> np.ndarray:
    """(N, K + 1, 2, 4, 4) the hand poses of every trial of each dual grasp: column 0 the nominal
    poses, columns 1..K the perturbations (:func:`perturb_poses` about the scene's grasp centres,
    :func:`~dg16m_env.physics.trial.grasp_centres`). ``grasps``: (N, 2, 4, 4); ``seeds``: (N,)."""
    perturbed = perturb_poses(grasps, grasp_centres(scene, grasps), seeds, spec)
    return np.concatenate([grasps[:, None], perturbed], axis=1)


@dataclass(eq=False)
class GraspLabels:
    """Success probabilities of N dual grasps (see the module docstring).

    Attributes:
        nominal: the nominal trials' full results (N rows).
        status: (N, K + 1) :class:`~dg16m_env.physics.trial.TrialStatus` codes (int8); column 0 is the
            nominal trial, columns 1.. the perturbed ones.
        failing_phase: (N, K + 1) index into :data:`~dg16m_env.physics.trial.PHASES` (int8, -1 none).
        seeds: (N,) int64 per-row perturbation seeds.
        spec: the perturbation parameters.
    """

    nominal: TrialResults
    status: np.ndarray
    failing_phase: np.ndarray
    seeds: np.ndarray
    spec: PerturbationSpec

    def __post_init__(self) -> None:
        n, trials = self.nominal.n, self.spec.trials
        for name in ("status", "failing_phase"):
            arr = getattr(self, name)
            if arr.shape != (n, trials):
                raise LabelError(
                    f"{name}: expected shape ({n}, {trials}) (rows, K + 1 trials), found "
                    f"{arr.shape}"
                )
        if self.seeds.shape != (n,):
            raise LabelError(f"seeds: expected shape ({n},), found {self.seeds.shape}")
        if n and not np.array_equal(self.status[:, 0], self.nominal.status):
            raise LabelError("status: expected column 0 to be the nominal trials' status")

    @property
    def n(self) -> int:
        return self.nominal.n

    @property
    def held(self) -> np.ndarray:
        """(N, K + 1) bool, True where the trial held through the whole protocol."""
        return self.status == TrialStatus.SUCCESS

    @property
    def held_gravity(self) -> np.ndarray:
        """(N, K + 1) bool, True where the trial ran and nothing broke before the end of
        *gravity*."""
        ran = self.status != TrialStatus.INVALID
        later = (self.failing_phase < 0) | (self.failing_phase > GRAVITY_PHASE)
        return ran & later

    @property
    def p_success(self) -> np.ndarray:
        """(N,) probability of holding through the whole protocol (the headline level)."""
        return self.held.mean(axis=1)

    @property
    def p_gravity(self) -> np.ndarray:
        """(N,) probability of holding under gravity (the paper's level)."""
        return self.held_gravity.mean(axis=1)

    def p(self, level: str = "full") -> np.ndarray:
        """(N,) ``p_success`` for ``"full"``, ``p_gravity`` for ``"gravity"``."""
        if level not in LEVELS:
            raise LabelError(f"level: expected one of {LEVELS}, found {level!r}")
        return self.p_success if level == "full" else self.p_gravity

    def label(self, level: str = "full") -> np.ndarray:
        """(N,) bool binary labels: ``p >= 0.5``."""
        return self.p(level) >= 0.5

    def uncertain(self, level: str = "full") -> np.ndarray:
        """(N,) bool: ``0.2 < p < 0.8``."""
        p = self.p(level)
        return (p > UNCERTAIN[0]) & (p < UNCERTAIN[1])

    def select(self, rows: np.ndarray) -> GraspLabels:
        """The labels of rows ``rows``."""
        return GraspLabels(
            nominal=self.nominal.select(rows),
            status=self.status[rows],
            failing_phase=self.failing_phase[rows],
            seeds=self.seeds[rows],
            spec=self.spec,
        )

    def summary(self) -> dict[str, Any]:
        """Counts and rates over all rows (JSON-ready)."""
        out: dict[str, Any] = {"rows": self.n, "trials_per_row": self.spec.trials}
        for level in LEVELS:
            p = self.p(level)
            out[level] = {
                "mean_p": float(p.mean()) if self.n else float("nan"),
                "label_rate": float(self.label(level).mean()) if self.n else float("nan"),
                "uncertain": int(self.uncertain(level).sum()),
            }
        out["nominal"] = self.nominal.summary()
        return out

    def __repr__(self) -> str:  # N rows of arrays: counts, not contents
        return (
            f"GraspLabels({self.n} dual grasps x {self.spec.trials} trials, "
            f"{int(self.label().sum())} labelled success, "
            f"{int(self.uncertain().sum())} uncertain)"
        )


def concatenate_labels(parts: Sequence[GraspLabels]) -> GraspLabels:
    """One :class:`GraspLabels` from several with the same spec (rows appended in order)."""
    if not parts:
        raise LabelError("expected at least one set of labels, found none")
    spec = parts[0].spec
    if any(p.spec != spec for p in parts):
        raise LabelError("expected labels measured with one perturbation spec, found several")
    nominal = TrialResults(
        **{
            k: np.concatenate([getattr(p.nominal, k) for p in parts])
            for k in TrialResults.ARRAY_FIELDS
        },
        protocol=parts[0].nominal.protocol,
    )
    return GraspLabels(
        nominal=nominal,
        status=np.concatenate([p.status for p in parts]),
        failing_phase=np.concatenate([p.failing_phase for p in parts]),
        seeds=np.concatenate([p.seeds for p in parts]),
        spec=spec,
    )


def success_probability(
    scene: Scene,
    grasps: np.ndarray | Sequence[np.ndarray],
    *,
    spec: PerturbationSpec | None = None,
    seeds: np.ndarray | None = None,
    protocol: TrialProtocol | None = None,
    progress: bool = False,
    simulator: Simulator | str | None = None,
) -> GraspLabels:
    """Success probabilities of N dual grasps on one object (nominal + K perturbed trials each).

    Args:
        scene: the object's compiled scene (:func:`dg16m_env.physics.scene.compile_scene`).
        grasps: (N, 2, 4, 4) hand poses, Panda grasp frame -> object frame (m).
        spec: K, d, theta and the global seed (default :class:`PerturbationSpec`).
        seeds: (N,) per-row seeds; default :func:`row_seeds` of ``(spec.seed, scene.object_id)``.
        protocol: the trial protocol (default :class:`~dg16m_env.physics.trial.TrialProtocol`).
        progress: show a progress bar over trial batches.
        simulator: the physics engine (default C MuJoCo; :mod:`dg16m_env.physics.simulator`). All
            K + 1 trials of every row of the object go through it together, so MuJoCo Warp
            steps them as one batch of worlds.

    Returns:
        :class:`GraspLabels` in the order of ``grasps``.

    Raises:
        TrialError: malformed grasps.
        LabelError: malformed seeds.
        SimulatorError: ``"warp"`` without its optional extra or device.
    """
    spec = spec or PerturbationSpec()
    grasps = check_dual_grasps(grasps)
    n, trials = len(grasps), spec.trials
    if seeds is None:
        seeds = row_seeds(spec.seed, scene.object_id, n)
    everything = trial_poses(scene, grasps, seeds, spec)
    results = run_trials(
        scene,
        everything.reshape(n * trials, 2, 4, 4),
        protocol,
        progress=progress,
        simulator=simulator,
    )
    return GraspLabels(
        nominal=results.select(np.arange(n) * trials),
        status=results.status.reshape(n, trials),
        failing_phase=results.failing_phase.reshape(n, trials),
        seeds=np.asarray(seeds, dtype=np.int64).copy(),
        spec=spec,
    )
