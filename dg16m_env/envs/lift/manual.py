"""The sections that the Lift versions' pages share, written once.

A version's page (its module docstring, shown by the docs' environment pages and the API
reference) is complete on its own, and v1, v2 and v3 state the same rewards, observation table
and (v2, v3) arguments: the docstring of :mod:`.v1`, :mod:`.v2` or :mod:`.v3` names a shared
section by a line ``<<name>>`` and :func:`fill` (called by the module on import) puts the text
there. A version whose text differs writes its own section instead. Standard library only.
"""

from __future__ import annotations

REWARDS = """\
Rewards
-------
``reward_mode`` (default ``"dense"``); the reward is the sum of ``info["reward_terms"]``.

* ``"dense"``: on a step that does not succeed, all terms are >= 0 and sum to at most
  ``R = MAX_STEP_REWARD`` = 5 (:func:`~dg16m_env.envs.lift.reward.dense_terms`):
  ``reach = 1 - tanh(5 d)`` (``d`` the mean distance, m, from each hand's grasp centre to its
  target's; to the object's box without a target), ``align = 1 - theta / pi`` (mean jaw angle to
  the target, rad; 0 without one), ``grasp = 0.5`` per hand grasping with both fingers,
  ``lift = clip(lift / lift_height, 0, 1)`` while both hands grasp, ``hold = 1`` while a hold is
  under way. The **success step pays** ``R * (T - t + 1)`` (``success``, the other terms 0),
  where ``t`` is the step's number (1 for the first step) and ``T`` = ``episode_steps`` (200). An
  unstable step and a failed episode's last step pay 0; a failure ends the episode, so it
  forfeits what the steps left could have paid.
* ``"normalized_dense"``: the dense terms divided by ``R`` (a step pays at most 1; the success
  step ``T - t + 1``).
* ``"sparse"``: 1 on the success step, else 0.

**Bound** (every mode): from any step ``t`` of any episode, what the steps ``t .. T`` can earn
without succeeding is at most ``R * (T - t + 1)`` (dense; ``T - t + 1`` normalised, 0 sparse),
which is exactly what succeeding at step ``t`` pays (sparse: 1). So of two episodes that agree
up to step ``t - 1``, the one that succeeds at step ``t`` has the higher or equal return: a
policy that hovers with the object lifted never out-earns one that completes the hold
(``tests/test_lift_v1.py`` checks it seed for seed against a policy that lifts only 5 cm).
"""
"""The *Rewards* section: the reward modes, the success payment and the bound (v1, v2, v3)."""


STATE_MODES = """\
Observation modes
-----------------
``obs_mode`` (default ``"state"``; spaces by
:func:`~dg16m_env.envs.lift.observations.observation_space`):

* ``"state"``: ``Box((117,), float32)``, world frame, the parts of
  :data:`~dg16m_env.envs.lift.observations.STATE_LAYOUT` in order:

  ============================  ==  ============================================================
  part                          n   content (units)
  ============================  ==  ============================================================
  ``centre_errors``             6   per hand: its grasp centre minus its target's (m; 0 without)
  ``rotation_errors``           6   per hand: rotation vector (rad, world) turning it onto the
                                    nearer of its target and the target turned by pi about the
                                    approach axis (the same parallel grasp); 0 without a target
  ``grasp_centres``             6   per hand: grasp centre minus the object's position (m)
  ``hand_poses``                18  per hand: flange position (m) + 6D rotation
  ``commanded_poses``           18  per hand: commanded grasp centre (m) + 6D rotation (where
                                    the arm is told to be; the hand follows within ~1 mm)
  ``finger_openings``           2   distance between each hand's finger faces (m, 0-0.08)
  ``finger_contacts``           4   1 where finger i of hand k touches the object (h0f0, h0f1,
                                    h1f0, h1f1)
  ``object_position``           3   object frame origin (m)
  ``object_rotation``           6   object rotation, 6D
  ``object_linear_velocity``    3   m/s
  ``object_angular_velocity``   3   rad/s, world frame
  ``object_size``               3   bounding box side lengths, object frame (m)
  ``object_box_centre``         3   its centre, object frame (m)
  ``lift``                      1   centre-of-mass height above its resting height (m)
  ``target_poses``              18  target dual grasp at the object's pose: flange position (m)
                                    + 6D rotation per hand; 0 without a target
  ``target_flag``               1   1 with a target grasp, else 0
  ``previous_action``           14  the last action (0 after reset)
  ``elapsed``                   1   steps taken / ``episode_steps``
  ``hold``                      1   the current hold's length / ``hold_time`` (0-1)
  ============================  ==  ============================================================

  A 6D rotation is ``[R[:, 0], R[:, 1]]``. Values are clipped to the space's bounds.
* ``"state_dict"``: a ``Dict`` space of the same parts, one ``Box`` each.
"""
"""The start of *Observation modes*: ``"state"`` with its table, and ``"state_dict"`` (v1, v2, v3)."""


POINTCLOUD_TRACKED = """\
* ``"pointcloud"``: ``Dict(state, points, normals, mask)``: the ``"state"`` vector, and a
  fixed-size cloud of ``n_points`` points of the object (world frame, m), their outward normals
  and a mask (1 = a point, 0 = padding): what ``n_cameras`` seeded depth cameras (those of
  ``DualGraspPose-v0``, :mod:`dg16m_env.physics.cameras`, drawn with the env's generator at
  reset) saw of the object, carried with the object's pose as it moves (an object tracker).
"""
"""The ``"pointcloud"`` mode of v1 and v2 (an ``(n_points, 3)`` cloud; v3 states its flat one)."""


ARGUMENTS_AND_INFO = """\
Arguments
---------
* ``benchmark``: benchmark file or reference (default: the one shipped with dg16m);
  ``object_ids``: draw only among these objects (default: all); ``mesh_root``: folder of a mesh
  benchmark's meshes.
* ``target_grasp``: ``"benchmark"`` (default: each reset draws a benchmark dual grasp of the
  object that passed force closure with ``p("full") >= 0.5``) or ``None`` (no target; its
  observation slots are 0). Reset options: ``object_id``, and ``target_grasp`` (a benchmark
  row, (2, 4, 4) hand poses in the object frame, or None).
* ``reward_mode``: ``"dense"`` (default), ``"normalized_dense"`` or ``"sparse"``;
  ``obs_mode``: ``"state"`` (default), ``"state_dict"`` or ``"pointcloud"``; ``n_points``
  (512), ``n_cameras`` (1 or 2), ``camera_resolution`` (128 pixels): the cloud's.
* ``lift_height`` (0.10 m) and ``hold_time`` (1.0 s): the success rule's.
* ``episode_steps``: ``T``, the steps after which the env truncates the episode itself (200 =
  10 s at 20 Hz, the registered ``max_episode_steps``); it sets the reward bound and the
  ``elapsed`` fraction. For a longer episode give ``gym.make(..., episode_steps=N,
  max_episode_steps=N)`` (Gymnasium's ``TimeLimit`` would cut it at 200).
* ``render_mode``: ``None`` or ``"rgb_array"``; ``width``, ``height``: image size (480 x 360).

A keyword the version does not take raises ``TypeError`` naming the class, the id and the
nearest keyword.

Info
----
Reset: ``object_id``, ``stable_pose`` (index into the object's stable poses, most probable
first), ``target_row`` (benchmark row of the target, -1 if none or given as poses),
``target_above_table``, ``rest_height`` (resting centre-of-mass height, m), ``settle_speed``
(m/s), ``hands_clear`` (no hand touches the object), ``success`` / ``is_success`` (False),
``fail`` (False), ``elapsed_steps`` (0). Step: ``object_id``, ``success``, ``is_success``,
``termination``, ``reward_terms``, ``lift`` (m), ``hold_time`` (s of the current hold),
``slip`` ((2,) m, since the hold began), ``grasping`` ((2,) bool: each hand touches the object
with both fingers), ``target_row``, ``fail`` (the episode ended in failure on this step) and
``elapsed_steps``.
"""
"""The *Arguments* and *Info* sections of v2 and v3 (v1 states its own from v0's)."""

SECTIONS: dict[str, str] = {
    "rewards": REWARDS,
    "state_modes": STATE_MODES,
    "pointcloud_tracked": POINTCLOUD_TRACKED,
    "arguments_and_info": ARGUMENTS_AND_INFO,
}
"""Name (as written ``<<name>>`` in a docstring) -> its text."""


def fill(doc: str | None) -> str | None:
    """``doc`` with each line ``<<name>>`` replaced by :data:`SECTIONS` ``[name]`` (None, as
    under ``python -OO``, stays None); a name that is not a section raises ``KeyError``."""
    if doc is None:
        return None
    lines = []
    for line in doc.split("\n"):
        if line.startswith("<<") and line.endswith(">>"):
            lines.append(SECTIONS[line[2:-2]].rstrip("\n"))
        else:
            lines.append(line)
    return "\n".join(lines)
