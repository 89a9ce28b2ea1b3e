"""``dg16m_env/DualGraspPose-v0``: propose two hand poses, get one trial of the benchmark.

Registered when :mod:`dg16m_env` is imported; see :class:`DualGraspPoseEnv`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from .common import (
    STATUS_NOT_RUN,
    EnvArgumentError,
    OneStepGraspEnv,
    Outcome,
    check_box_action,
    cloud_spaces,
    structured_observation,
)
from .pose_surface_actions import poses_from_surface_action, surface_action_bounds
from .spaces import pose_action_bounds, poses_from_action

ACTION_MODES = ("pose", "surface")
"""``"pose"`` (default): two free hand poses; ``"surface"``: two hands on observed surface
points (:mod:`dg16m_env.envs.pose_surface_actions`)."""


class DualGraspPoseEnv(OneStepGraspEnv):
    """Two Panda hands grasp a benchmark object at the poses the agent proposes (free poses, or
    hands placed on observed surface points); one trial of the benchmark's protocol says whether
    the object is held.

    ## Description

    Each episode is one step. ``reset`` draws an object of the benchmark (uniformly, with the
    environment's generator, or ``options={"object_id": ...}``) and shows its point cloud. The
    action is a dual grasp: two hand poses (Panda grasp frame -> object frame). ``step`` runs
    ONE trial of the benchmark's protocol (:mod:`dg16m_env.physics.trial`: the open hands at the poses,
    close, gravity, twelve pushes and twists) on the object's compiled scene, with the
    benchmark's pose noise: each hand turned by the benchmark's ``theta`` (1 degree) about a
    random axis through its grasp centre and moved by ``d`` (1 mm) in a random direction, drawn
    from the environment's generator. The stored label of a benchmark pair is its success
    probability ``p`` over its nominal trial and ``K`` such perturbed trials, so the reward at a
    benchmark pair's poses is a Bernoulli draw whose mean is (up to the nominal trial's weight
    ``1 / (K + 1)``) that ``p``. ``perturb=False`` runs the exact poses (the nominal trial).

    ## Action Space

    ``action_mode="pose"`` (default): ``Box(-1, 1, (2, 9), float32)``: per hand ``[p (3), a (3),
    b (3)]``, the position ``p`` (m, object frame, within ±1 m) and the continuous 6D rotation
    (:mod:`dg16m_env.envs.spaces`): ``a`` the closing axis, ``b`` the approach axis,
    orthonormalised by Gram-Schmidt. An action whose 6D rotation is degenerate (an axis of
    length < 1e-3 or ``a`` parallel to ``b``) is not an error: no trial runs, reward 0,
    ``info["invalid_reason"] = "degenerate_rotation"``.

    ``action_mode="surface"``: ``Box(-1, 1, (2, 3), float32)``: per hand ``[point, roll,
    depth]``, a hand placed on a point of the cloud the agent saw at reset, approaching along
    the point's inward normal (:mod:`dg16m_env.envs.pose_surface_actions`):

    * ``point`` picks a valid point (``mask`` 1 in partial mode) by its height rank:
      ``i = floor((point + 1) / 2 * n)`` clipped to ``[0, n - 1]`` among the ``n`` valid points
      sorted by object-frame ``z`` (ascending, stable): -1 the lowest, 1 the highest;
    * the approach axis (grasp frame ``+y``) is the point's inward normal ``-n̂``; the closing
      axis (``+x``) is, before the roll, the object frame's ``+z`` projected perpendicular to the
      approach (``+x`` projected when the approach is within about 26 degrees of vertical);
    * ``roll`` turns the closing axis by ``pi * roll`` rad about the approach axis
      (right-handed): ``roll = 0`` closes vertically on a side face, ``±0.5`` horizontally;
    * ``depth`` sets the flange's standoff along the outward normal, linearly from 0.066 m
      (``depth = -1``: the Panda's palm face on the tangent plane, grasp centre 37.4 mm inside
      the surface) to 0.1122 m (``depth = 1``: the fingertips on the tangent plane, grasp centre
      8.8 mm outside); the grasp centre (0.1034 m from the flange) sits on the point at
      ``depth`` about 0.62.

    The two poses then run the same trial as in pose mode. A chosen point whose normal is
    degenerate (shorter than 0.5 or not finite), or an observation without a valid point, is
    not an error: no trial runs, reward 0, ``info["invalid_reason"] = "degenerate_normal"``
    (or ``"no_valid_point"``). ``info["point_index"]``: the chosen points' indices into the
    observation's cloud (-1 where none).

    In both modes float64 arrays and lists are cast; anything outside the space (NaN, out of
    bounds, wrong shape, strings or objects) raises ``ValueError`` naming the space.

    ## Observation Space

    ``Dict`` of flat float32 vectors (:func:`~dg16m_env.envs.common.structured_observation`
    reshapes them), object frame (origin at the centre of mass), metres:

    * ``points`` (3 P,): P = ``n_points`` surface points; ``obs_mode="full"``: drawn uniformly
      by area over the whole surface, the same for every episode on an object
      (:func:`dg16m_env.subjects.observation.object_observation`, seed 0); ``obs_mode="partial"``: what
      ``n_cameras`` seeded depth cameras see (:mod:`dg16m_env.physics.cameras`), subsampled or
      zero-padded to P;
    * ``normals`` (3 P,): unit outward normals of the face under each point (partial mode:
      the face of the convex part that the pixel sees, found from the segmentation image,
      exact rather than estimated from neighbouring depths);
    * ``bounds`` (6,): the object's axis-aligned box, min corner then max corner (the whole
      object in both modes);
    * ``mask`` (P,), partial mode only: 1 for a real point, 0 for padding.

    ## Rewards

    1.0 when the object is held at ``level``: ``"full"`` (default), held through the whole
    protocol; ``"gravity"``, held under gravity (nothing broke before the end of the gravity
    phase). 0.0 otherwise (failed, unstable, invalid trial, degenerate rotation or normal).

    ## Starting State

    The object at rest at the origin of its frame, open hands at the action's poses.

    ## Episode End

    Every episode terminates after its one step (``terminated=True``, ``truncated=False``);
    step again only after ``reset``.

    ## Info

    ``reset``: ``object_id``. ``step``: ``success`` and ``is_success`` (bool; ManiSkill's and
    stable-baselines3's keys), ``object_id``, ``fc_passed`` and ``fc_reason`` (the force-closure
    verdict of the jaws closed at the nominal action poses,
    :func:`dg16m_env.evaluators.fce.fce_verdicts`; None with ``fc_info=False``), ``slip_m``
    (largest slip at the hands' grasp centres, m), ``rotation_deg`` (largest rotation of the
    object), ``failing_phase`` (a :data:`dg16m_env.physics.trial.PHASES` name, or None),
    ``invalid_reason`` (``hand0_penetrates``, ``hand1_penetrates``, ``hands_overlap``,
    ``degenerate_rotation``, ``degenerate_normal``, ``no_valid_point`` or None), ``status`` (``success``, ``failed``, ``invalid``,
    ``unstable``, or ``not_run``); surface mode only: ``point_index`` (a tuple of two ints).
    Entries that do not apply are None.

    ## Randomisations

    All from ``self.np_random`` (seeded by ``reset(seed=...)``): the object, the camera poses and
    the point subsample (partial mode), the pose noise of each trial. The same seed and action
    give the same observation bytes, reward and info.

    ## Arguments

    * ``action_mode`` (``"pose"``): ``"pose"`` or ``"surface"`` (see Action Space).
    * ``benchmark``: benchmark file or :class:`~dg16m_env.benchmark.ref.BenchmarkRef`
      (default: the procedural benchmark shipped with dg16m); its parameters give the protocol,
      the pose noise and the force-closure problem.
    * ``object_ids``: draw only among these objects (default: all).
    * ``mesh_root``: the folder of a mesh benchmark's meshes.
    * ``n_points`` (1024): points in the cloud.
    * ``obs_mode`` (``"full"``): ``"full"`` or ``"partial"``.
    * ``n_cameras`` (1): depth cameras of the partial observation (1 or 2).
    * ``camera_resolution`` (128): depth image side (pixels).
    * ``level`` (``"full"``): ``"full"`` or ``"gravity"`` (see Rewards).
    * ``perturb`` (True): apply the benchmark's pose noise before the trial.
    * ``fc_info`` (True): compute ``fc_passed`` / ``fc_reason`` (about 9 ms a step).
    * ``render_mode`` (None): None or ``"rgb_array"``.
    * ``render_width`` (480), ``render_height`` (360): picture size (pixels).
    * ``vector_kwargs``: ignored (``gym.make_vec``'s, see :mod:`dg16m_env.envs.common`).

    ## Vector environments

    ``gym.make_vec(id, num_envs, vectorization_mode="sync" | "async")`` uses the ``SAME_STEP``
    autoreset mode registered for this id: every step is a real trial (see
    :mod:`dg16m_env.envs.common`).

    ## Version History

    * v0: initial. Later (same id, same default): `benchmark` also takes a shipped benchmark's
      short name (`"procedural"`, the default, or `"real"`: 300 furniture models, shipped
      since 2026-12-03), and mesh benchmarks that carry their meshes need no `mesh_root`.
      Later still (same id, same default, issue 40): ``action_mode="surface"``, hands placed on
      observed surface points; ``action_mode="pose"`` (the default) is unchanged bit for bit.
    """

    def __init__(self, *, action_mode: str = "pose", **kwargs: Any) -> None:
        if not isinstance(action_mode, str) or action_mode not in ACTION_MODES:
            raise EnvArgumentError(
                f"action_mode: expected one of {ACTION_MODES}, found {action_mode!r}"
            )
        super().__init__(**kwargs)
        self.action_mode = action_mode
        if action_mode == "pose":
            low, high = pose_action_bounds(2)
        else:
            low, high = surface_action_bounds(2)
        self.action_space = spaces.Box(low=low, high=high, dtype=np.float32)
        self.observation_space = spaces.Dict(
            cloud_spaces(self.n_points, self.obs_mode == "partial")
        )

    def _not_run(self, reason: str, extra: dict[str, Any] | None = None) -> Outcome:
        fc = (False, "invalid_pose") if self.fc_info else (None, None)
        return Outcome(
            success=False,
            status=STATUS_NOT_RUN,
            invalid_reason=reason,
            fc_passed=fc[0],
            fc_reason=fc[1],
            extra=extra or {},
        )

    def _act(self, action: Any) -> Outcome:
        checked = check_box_action(action, self.action_space)
        if self.action_mode == "surface":
            return self._act_surface(checked)
        poses, valid = poses_from_action(checked)
        if not valid.all():  # bounds already checked: only a degenerate rotation is left
            return self._not_run("degenerate_rotation")
        return self.trial(poses)

    def _act_surface(self, checked: np.ndarray) -> Outcome:
        assert self._observation is not None
        cloud = structured_observation(self._observation)
        poses, valid, indices, reasons = poses_from_surface_action(
            checked, cloud["points"], cloud["normals"], cloud.get("mask")
        )
        extra = {"point_index": tuple(int(i) for i in indices)}
        if not valid.all():
            return self._not_run(next(r for r in reasons if r is not None), extra)
        outcome = self.trial(poses)
        outcome.extra.update(extra)
        return outcome
