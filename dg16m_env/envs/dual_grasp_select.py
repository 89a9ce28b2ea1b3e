"""``dg16m_env/DualGraspSelect-v0``: pick one of K candidate dual grasps of the benchmark.

Registered when :mod:`dg16m_env` is imported; see :class:`DualGraspSelectEnv`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from dg16m_core.checks import check_integer

from .common import (
    STATUS_LABEL,
    STATUS_NOT_RUN,
    EnvArgumentError,
    OneStepGraspEnv,
    Outcome,
    candidate_spaces,
    check_discrete_action,
    check_in_limit,
    cloud_spaces,
    fc_verdict,
)
from .spaces import action_from_poses

REWARD_MODES = ("simulate", "label")
"""``"simulate"``: one trial of the chosen candidate; ``"label"``: a draw from its stored p."""

DEFAULT_CANDIDATES = 16
"""Candidate dual grasps per episode unless asked otherwise."""


class DualGraspSelectEnv(OneStepGraspEnv):
    """Choose one of K candidate dual grasps of a benchmark object: how a grasp classifier
    becomes a policy.

    ## Description

    As ``DualGraspPose-v0`` (:class:`~dg16m_env.envs.dual_grasp_pose.DualGraspPoseEnv`), but
    the observation also carries K candidate dual grasps of the object, drawn from its
    benchmark rows (every arm: force-closure passing and failing, random and farthest pairs),
    and the action picks one. The candidates are a random sample of the object's rows in random
    order (the stored rows are grouped by arm; their order never shows). ``step`` then
    runs ONE trial of the benchmark's protocol at the candidate's stored poses, with the
    benchmark's pose noise (``reward_mode="simulate"``, the default: the reward's mean is about
    the stored success probability ``p``), or draws the reward from the stored ``p`` without
    simulating (``reward_mode="label"``: Bernoulli(``p`` at ``level``) from the environment's
    generator; for training: some 300 times faster than simulating with ``fc_info=False``
    (the force-closure info costs about 9 ms the first time a row is picked), and the same
    distribution of rewards as the K + 1 trials ``p`` counts, not a new trial).

    ## Action Space

    ``Discrete(K)``: the slot of the chosen candidate (Python or numpy integer). Anything else
    (a float, a string, an out-of-range slot) raises ``ValueError`` naming the space. An object
    with fewer than K rows leaves the last slots empty: picking one gives reward 0 and
    ``info["invalid_reason"] = "empty_slot"`` (no trial).

    ## Observation Space

    ``Dict`` of flat float32 vectors (:func:`~dg16m_env.envs.common.structured_observation`
    reshapes them), object frame, metres: ``points``, ``normals``, ``bounds`` (and ``mask`` in
    partial mode) as in ``DualGraspPose-v0``, plus

    * ``candidates`` (18 K,) = (K, 2, 9): each candidate's two hand poses encoded as a Pose
      action (position and 6D rotation, :mod:`dg16m_env.envs.spaces`);
    * ``candidate_contacts`` (24 K,) = (K, 4, 6): its four stored contacts, point (m) then
      outward unit normal (zeros where the benchmark stores none);
    * ``candidate_mask`` (K,): 1 for a candidate, 0 for an empty slot (zeros everywhere else).

    ## Rewards

    1.0 when the chosen candidate holds the object at ``level`` (``"full"``: through the whole
    protocol; ``"gravity"``: under gravity), in the simulated trial or the label draw; else 0.0.

    ## Starting State

    The object at rest at the origin of its frame; K candidates drawn.

    ## Episode End

    Every episode terminates after its one step (``terminated=True``, ``truncated=False``).

    ## Info

    ``reset``: ``object_id`` and ``rows`` ((K,) int64: the benchmark row of each slot, -1 for
    an empty slot; for scoring a classifier against the stored labels). ``step``: as
    ``DualGraspPose-v0`` (``success``, ``is_success``, ``object_id``, ``fc_passed``,
    ``fc_reason``, ``slip_m``, ``rotation_deg``, ``failing_phase``, ``invalid_reason``,
    ``status``) plus ``row`` (the benchmark row, None for an empty slot) and ``p`` (its stored
    success probability at ``level``). The force-closure verdict is that of the jaws closed at
    the candidate's stored poses (:func:`dg16m_env.evaluators.fce.fce_verdicts`, cached per row).
    In label mode no trial runs: ``status`` is ``"label"`` and ``slip_m``, ``rotation_deg``,
    ``failing_phase`` and ``invalid_reason`` are None.

    ## Randomisations

    All from ``self.np_random``: the object, the cameras and point subsample (partial mode), the
    candidates and their order, the pose noise (simulate) or the label draw (label).

    ## Arguments

    Those of ``DualGraspPose-v0`` (``benchmark``, ``object_ids``, ``mesh_root``, ``n_points``,
    ``obs_mode``, ``n_cameras``, ``camera_resolution``, ``level``, ``perturb``, ``fc_info``,
    ``render_mode``, ``render_width``, ``render_height``, ``vector_kwargs``), plus

    * ``n_candidates`` (16): K.
    * ``reward_mode`` (``"simulate"``): ``"simulate"`` or ``"label"`` (see Description).

    ## Version History

    * v0: initial. Later (same id, same default): `benchmark` also takes a shipped benchmark's
      short name (`"procedural"`, the default, or `"real"`: 300 furniture models, shipped
      since 2026-12-03), and mesh benchmarks that carry their meshes need no `mesh_root`.
    """

    def __init__(
        self,
        *,
        n_candidates: int = DEFAULT_CANDIDATES,
        reward_mode: str = "simulate",
        **kwargs: Any,
    ) -> None:
        self.n_candidates = check_integer(
            "n_candidates", n_candidates, minimum=1, error=EnvArgumentError
        )
        if not isinstance(reward_mode, str) or reward_mode not in REWARD_MODES:
            raise EnvArgumentError(
                f"reward_mode: expected one of {REWARD_MODES}, found {reward_mode!r}"
            )
        self.reward_mode = reward_mode
        super().__init__(**kwargs)
        self.action_space = spaces.Discrete(self.n_candidates)
        self.observation_space = spaces.Dict(
            {
                **cloud_spaces(self.n_points, self.obs_mode == "partial"),
                **candidate_spaces(self.n_candidates),
            }
        )
        self._p = self.benchmark.p(self.level)
        self._contact_normals = np.nan_to_num(self.benchmark.contact_normals, nan=0.0)
        self._rows = np.full(self.n_candidates, -1, dtype=np.int64)
        self._fc_cache: dict[int, tuple[bool, str]] = {}

    def _reset_extra(self, object_id: str) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        bench = self.benchmark
        rows = self.objects.rows(object_id)
        k = min(self.n_candidates, rows.size)
        chosen = rows[self.np_random.choice(rows.size, size=k, replace=False)]
        self._rows = np.full(self.n_candidates, -1, dtype=np.int64)
        self._rows[:k] = chosen
        poses = bench.poses[chosen]
        check_in_limit(object_id, "its candidate hand positions", poses[:, :, :3, 3])
        encoded = np.zeros((self.n_candidates, 2, 9), dtype=np.float32)
        encoded[:k] = action_from_poses(poses)
        contacts = np.zeros((self.n_candidates, 4, 6), dtype=np.float32)
        contacts[:k, :, :3] = bench.contact_points[chosen]
        contacts[:k, :, 3:] = self._contact_normals[chosen]
        mask = np.zeros(self.n_candidates, dtype=np.float32)
        mask[:k] = 1.0
        extra = {
            "candidates": encoded.reshape(-1),
            "candidate_contacts": contacts.reshape(-1),
            "candidate_mask": mask,
        }
        return extra, {"rows": self._rows.copy()}

    def _fc(self, row: int) -> tuple[bool | None, str | None]:
        if not self.fc_info:
            return None, None
        if row not in self._fc_cache:
            assert self.object_id is not None
            obj = self.objects.load(self.object_id)
            self._fc_cache[row] = fc_verdict(obj, self.benchmark.poses[row], self._fc_kwargs)
        return self._fc_cache[row]

    def _act(self, action: Any) -> Outcome:
        slot = check_discrete_action(action, self.action_space)
        row = int(self._rows[slot])
        if row < 0:
            return Outcome(
                success=False,
                status=STATUS_NOT_RUN,
                invalid_reason="empty_slot",
                fc_passed=False if self.fc_info else None,
                extra={"row": None, "p": None},
            )
        p = float(self._p[row])
        poses = self.benchmark.poses[row]
        if self.reward_mode == "label":
            fc = self._fc(row)
            outcome = Outcome(
                success=bool(self.np_random.random() < p),
                status=STATUS_LABEL,
                fc_passed=fc[0],
                fc_reason=fc[1],
                poses=poses,
            )
        else:
            outcome = self._run(poses, self._fc(row))
        outcome.extra = {"row": row, "p": p}
        return outcome
