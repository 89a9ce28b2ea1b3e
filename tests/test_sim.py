"""MuJoCo scene and trial protocol: grasps that hold and fail, invalid poses, determinism,
bad input, the load schedule, the compiled scene's contact settings, a procedural object.

Objects are small box planks built from one exact convex part, and dual grasps are placed by hand
with ``PANDA.pose_from_contacts`` (grasp frame: ``+x`` closing axis, ``+y`` approach, contacts at
``(+-w/2, contact_depth, 0)``). A trial here costs a few milliseconds; the whole file runs in a few
seconds.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

pytest.importorskip("mujoco")

import mujoco
from planks import (
    DOWN,
    FAIL_HORIZONTAL,
    FAIL_VERTICAL,
    HOLD_FROM_ABOVE,
    HOLD_FROM_SIDE,
    SIDE,
    dual,
    finger_inside,
    hand,
    plank,
)

from dataset_gen.grasps.gripper import PANDA
from dataset_gen.objects.grasp_object import make_object
from dg16m_core.errors import Dg16mError
from dg16m_env.physics.scene import Scene, SceneError, SceneParameters, compile_scene
from dg16m_env.physics.trial import run_trials
from dg16m_env.physics.trial_measures import analyse, grasp_centres
from dg16m_env.physics.trial_protocol import (
    DIRECTIONS,
    PHASES,
    InvalidReason,
    TrialError,
    TrialProtocol,
    TrialResults,
    TrialStatus,
    schedule,
    simulate,
)

# --------------------------------------------------------------------------------------------
# Objects and grasps
# --------------------------------------------------------------------------------------------


def fields_equal(a: TrialResults, b: TrialResults) -> None:
    for name in TrialResults.ARRAY_FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype, name
        assert np.array_equal(x, y, equal_nan=True), f"{name}: {x} != {y}"


# --------------------------------------------------------------------------------------------
# 1-2. Physics: a grasp that holds, grasps that fail
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("grasp", [HOLD_FROM_ABOVE, HOLD_FROM_SIDE], ids=["above", "side"])
def test_plank_squeezed_at_both_ends_holds(short_scene: Scene, grasp: np.ndarray) -> None:
    results = run_trials(short_scene, grasp[None])
    assert results.status[0] == TrialStatus.SUCCESS, results.summary()
    assert results.success.tolist() == [True]
    assert results.failing_phase[0] == -1
    assert results.phase_name(0) == ""
    assert results.invalid_reason[0] == InvalidReason.NONE
    assert results.max_displacement[0] < 5e-3  # measured ~4e-5 m
    assert results.max_rotation_deg[0] < 1.0  # measured ~0.008 deg
    assert 0.0 <= results.max_penetration[0] < 1e-3  # measured ~2.9e-4 m
    assert (results.contacts_after_close[0] > 0).all()
    assert (results.contacts_final[0] > 0).all()
    assert not results.ejected[0]
    summary = results.summary()
    assert summary["success"] == 1
    assert summary["failed"] == summary["unstable"] == 0


@pytest.mark.parametrize(
    ("grasp", "phase"),
    [(FAIL_HORIZONTAL, "gravity"), (FAIL_VERTICAL, None)],
    ids=["closing-horizontally", "closing-vertically"],
)
def test_hands_close_together_near_one_end_of_a_heavy_plank_fail(
    long_scene: Scene, grasp: np.ndarray, phase: str | None
) -> None:
    protocol = TrialProtocol()
    results = run_trials(long_scene, grasp[None], protocol)
    assert results.status[0] == TrialStatus.FAILED, results.summary()
    assert results.phase_name(0) in PHASES
    if phase is not None:
        assert results.phase_name(0) == phase
    assert results.invalid_reason[0] == InvalidReason.NONE
    # The hands did close on the plank: it fell out of a real grasp, not out of open hands.
    assert (results.contacts_after_close[0] > 0).all()
    # The verdict is backed by the reported motion.
    assert (
        results.max_displacement[0] > protocol.max_displacement
        or results.max_rotation_deg[0] > protocol.max_rotation_deg
    )
    assert not results.ejected[0]
    assert results.max_penetration[0] < 1e-3


def test_a_failure_is_judged_in_a_later_phase_when_the_earlier_ones_are_held(
    short_scene: Scene,
) -> None:
    """The failing phase is where the bounds break, not always "gravity": the hold grasp with a
    10x disturbance force fails in a disturbance phase."""
    protocol = TrialProtocol(disturbance_force_fraction=5.0)
    results = run_trials(short_scene, HOLD_FROM_ABOVE[None], protocol)
    assert results.status[0] == TrialStatus.FAILED
    assert PHASES.index(results.phase_name(0)) >= PHASES.index("force+x")


# --------------------------------------------------------------------------------------------
# 3. Invalid poses
# --------------------------------------------------------------------------------------------


def test_open_fingers_in_the_object_make_the_trial_invalid(short_scene: Scene) -> None:
    good0, good1 = HOLD_FROM_ABOVE
    grasps = np.stack(
        [
            dual(finger_inside(good0), good1),
            dual(good0, finger_inside(good1)),
            HOLD_FROM_ABOVE,  # a valid trial in the same call still runs
        ]
    )
    protocol = TrialProtocol()
    results = run_trials(short_scene, grasps, protocol)
    assert results.status.tolist() == [
        TrialStatus.INVALID,
        TrialStatus.INVALID,
        TrialStatus.SUCCESS,
    ]
    assert results.invalid_reason.tolist() == [
        InvalidReason.HAND0_PENETRATES,
        InvalidReason.HAND1_PENETRATES,
        InvalidReason.NONE,
    ]
    assert results.valid.tolist() == [False, False, True]
    # Not simulated: no motion, no contacts, no phase.
    assert np.isnan(results.max_displacement[:2]).all()
    assert np.isnan(results.max_rotation_deg[:2]).all()
    assert (results.failing_phase[:2] == -1).all()
    assert (results.contacts_after_close[:2] == 0).all()
    assert (results.contacts_final[:2] == 0).all()
    # The reported penetration is the open hand's: the whole 0.02 m finger is inside.
    assert (results.max_penetration[:2] > protocol.invalid_penetration).all()
    np.testing.assert_allclose(results.max_penetration[:2], 0.02, atol=1e-3)
    summary = results.summary()
    assert summary["invalid"] == 2
    assert summary["success"] == 1


def test_overlapping_hands_make_the_trial_invalid(short_scene: Scene) -> None:
    pose = HOLD_FROM_ABOVE[0]
    near = hand(-0.20, "y", DOWN)  # palms 0.063 m wide along the plank, 0.05 m apart: overlap
    grasps = np.stack([dual(pose, pose), dual(pose, near)])
    results = run_trials(short_scene, grasps)
    assert results.status.tolist() == [TrialStatus.INVALID] * 2
    assert results.invalid_reason.tolist() == [InvalidReason.HANDS_OVERLAP] * 2
    assert np.isnan(results.max_displacement).all()
    # Both hands are clear of the object.
    assert (results.max_penetration < TrialProtocol().invalid_penetration).all()


def test_hands_0_1_m_apart_do_not_overlap(short_scene: Scene) -> None:
    grasp = dual(hand(-0.25, "y", DOWN), hand(-0.15, "y", DOWN))
    results = run_trials(short_scene, grasp[None])
    assert results.invalid_reason[0] == InvalidReason.NONE
    assert results.status[0] != TrialStatus.INVALID


# --------------------------------------------------------------------------------------------
# 4. Determinism
# --------------------------------------------------------------------------------------------


def test_trials_are_bit_for_bit_reproducible(short_scene: Scene) -> None:
    fail_short = dual(hand(-0.25, "y", DOWN), hand(-0.15, "y", DOWN))  # fails in gravity
    wanted = np.stack([HOLD_FROM_ABOVE, fail_short, HOLD_FROM_SIDE])
    first = run_trials(short_scene, wanted)
    assert first.status.tolist() == [TrialStatus.SUCCESS, TrialStatus.FAILED, TrialStatus.SUCCESS]
    fields_equal(first, run_trials(short_scene, wanted))

    # The same trials among others, in another order and other batch sizes.
    pose = HOLD_FROM_ABOVE[0]
    others = [
        dual(pose, pose),  # invalid
        dual(hand(-0.1, "z", SIDE), hand(0.2, "z", SIDE)),
        dual(hand(0.25, "y", DOWN), hand(0.15, "y", DOWN)),
    ]
    mixed = np.stack([others[0], wanted[2], others[1], wanted[0], others[2], wanted[1]])
    rows = np.array([3, 5, 1])
    for batch_size in (64, 1, 2, 4):
        protocol = TrialProtocol(batch_size=batch_size)
        fields_equal(first, run_trials(short_scene, mixed, protocol).select(rows))

    # A freshly compiled scene of the same object gives the same numbers.
    fields_equal(first, run_trials(compile_scene(plank(0.6, 4.0, "short_plank")), wanted))


def test_simulate_replays_what_run_trials_judged(short_scene: Scene) -> None:
    """``simulate`` (one rollout, for replay) agrees with ``run_trials`` (segmented rollouts).
    Not bit for bit: the segments restart MuJoCo's solver warm start, so the last digits of
    the solution differ."""
    grasps = np.stack([HOLD_FROM_ABOVE, dual(hand(-0.25, "y", DOWN), hand(-0.15, "y", DOWN))])
    protocol = TrialProtocol()
    judged = run_trials(short_scene, grasps, protocol)
    states, sensors, plan = simulate(short_scene, grasps, protocol)
    assert states.shape[:2] == sensors.shape[:2] == (2, plan.nstep)
    replay = analyse(
        short_scene, states, sensors, plan, protocol, grasp_centres(short_scene, grasps)
    )
    for name in ("status", "failing_phase", "contacts_after_close", "ejected"):
        assert np.array_equal(getattr(judged, name), getattr(replay, name)), name
    np.testing.assert_allclose(replay.max_displacement, judged.max_displacement, rtol=1e-6)
    np.testing.assert_allclose(replay.max_rotation_deg, judged.max_rotation_deg, rtol=1e-6)


def test_a_stalled_trajectory_is_unstable_not_a_success(short_scene: Scene) -> None:
    """mujoco.rollout repeats the last state after a simulation warning: a held object that
    stops in time must be reported UNSTABLE, not judged a success."""
    grasps = HOLD_FROM_ABOVE[None]
    protocol = TrialProtocol()
    states, sensors, plan = simulate(short_scene, grasps, protocol)
    anchors = grasp_centres(short_scene, grasps)
    assert analyse(short_scene, states, sensors, plan, protocol, anchors).success[0]
    frozen = states.copy()
    frozen[:, plan.nstep // 2 :] = frozen[:, plan.nstep // 2 - 1 : plan.nstep // 2]
    judged = analyse(short_scene, frozen, sensors, plan, protocol, anchors)
    assert judged.status[0] == TrialStatus.UNSTABLE
    assert not judged.ejected[0], "a stalled state is unstable, not an ejection"


def test_an_object_thrown_faster_than_max_speed_is_ejected(short_scene: Scene) -> None:
    """``ejected`` is its own measure: the object's speed (read at the free joint's dof address)
    over ``max_speed``; such a trial is also UNSTABLE."""
    grasps = HOLD_FROM_ABOVE[None]
    protocol = TrialProtocol()
    states, sensors, plan = simulate(short_scene, grasps, protocol)
    anchors = grasp_centres(short_scene, grasps)
    model = short_scene.model
    joint = model.body_jntadr[short_scene.object_body]
    vel = 1 + model.nq + model.jnt_dofadr[joint]  # state = [time, qpos, qvel, ...]
    assert short_scene.object_qvel == slice(model.jnt_dofadr[joint], model.jnt_dofadr[joint] + 6)
    thrown = states.copy()
    step = plan.close_end + 10
    thrown[0, step, vel : vel + 3] = (0.0, 2.0 * protocol.max_speed, 0.0)
    judged = analyse(short_scene, thrown, sensors, plan, protocol, anchors)
    assert judged.status[0] == TrialStatus.UNSTABLE
    assert judged.ejected[0]
    assert judged.phase_name(0) == PHASES[plan.phase[step]]
    # The object's angular velocity is not its speed: spinning fast is not an ejection.
    spun = states.copy()
    spun[0, step, vel + 3 : vel + 6] = (0.0, 0.0, 2.0 * protocol.max_speed)
    assert not analyse(short_scene, spun, sensors, plan, protocol, anchors).ejected[0]


# --------------------------------------------------------------------------------------------
# 5. Bad input
# --------------------------------------------------------------------------------------------


def _bad_grasps() -> list[tuple[str, np.ndarray]]:
    nan = HOLD_FROM_ABOVE.copy()
    nan[1, 0, 3] = np.nan
    inf = HOLD_FROM_ABOVE.copy()
    inf[0, 2, 3] = np.inf
    scaled = HOLD_FROM_ABOVE.copy()
    scaled[0, :3, :3] *= 1.1
    sheared = HOLD_FROM_ABOVE.copy()
    sheared[1, 0, 1] += 0.05
    mirrored = HOLD_FROM_ABOVE.copy()
    mirrored[0, :3, 0] *= -1.0  # orthonormal, det -1
    last_row = HOLD_FROM_ABOVE.copy()
    last_row[1, 3, 0] = 1.0
    return [
        ("one hand", HOLD_FROM_ABOVE[:1][None]),
        ("three hands", np.stack([HOLD_FROM_ABOVE[0]] * 3)[None]),
        ("single pose", HOLD_FROM_ABOVE[0]),
        ("3x4 poses", HOLD_FROM_ABOVE[None, :, :3, :]),
        ("flat", HOLD_FROM_ABOVE.ravel()),
        ("nan", nan[None]),
        ("inf", inf[None]),
        ("scaled rotation", scaled[None]),
        ("sheared rotation", sheared[None]),
        ("reflection", mirrored[None]),
        ("last row", last_row[None]),
    ]


@pytest.mark.parametrize(("label", "grasps"), _bad_grasps(), ids=[b[0] for b in _bad_grasps()])
def test_malformed_grasps_are_rejected(short_scene: Scene, label: str, grasps: np.ndarray) -> None:
    with pytest.raises(TrialError, match="expected"):
        run_trials(short_scene, grasps)
    with pytest.raises(TrialError, match="expected"):
        simulate(short_scene, grasps)


def test_the_bad_dual_grasp_is_named(short_scene: Scene) -> None:
    grasps = np.stack([HOLD_FROM_ABOVE] * 3)
    grasps[2, 1, :3, :3] *= 2.0
    with pytest.raises(TrialError, match="dual grasp 2"):
        run_trials(short_scene, grasps)


def test_a_single_dual_grasp_and_nested_lists_are_accepted(short_scene: Scene) -> None:
    a = run_trials(short_scene, HOLD_FROM_ABOVE)  # (2, 4, 4)
    b = run_trials(short_scene, HOLD_FROM_ABOVE[None].tolist())
    assert a.n == b.n == 1
    fields_equal(a, b)


def test_trial_error_is_a_value_error() -> None:
    for error in (TrialError, SceneError):
        assert issubclass(error, ValueError)
        assert issubclass(error, Dg16mError)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"timestep": 0.0},
        {"timestep": float("inf")},
        {"friction": -0.1},
        {"friction": float("nan")},
        {"squeeze_force": 0.0},
        {"finger_mass": -1.0},
        {"finger_damping": 0.0},
        {"torsional_friction": -0.001},
        {"rolling_friction": float("nan")},
        {"finger_armature": -0.01},
        {"iterations": 0},
        {"iterations": 2.5},
        {"object_mass": 0.0},
        {"object_mass": float("nan")},
        {"solref": (0.01,)},
        {"solimp": (0.9, 0.95)},
    ],
    ids=str,
)
def test_bad_scene_parameters_raise_scene_error(kwargs: dict) -> None:
    with pytest.raises(SceneError, match="expected"):
        SceneParameters(**kwargs)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"impratio": float("nan")},
        {"impratio": -1.0},
        {"solref": (float("nan"), 1.0)},
        {"solref": (0.001, 1.0)},
        {"solimp": (2.0, -1.0, 0.001)},
        {"object_mass": "x"},
        {"timestep": True},
    ],
    ids=str,
)
def test_bad_impratio_solref_solimp_raise_scene_error(kwargs: dict) -> None:
    with pytest.raises(SceneError, match="expected"):
        SceneParameters(**kwargs)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"gravity": 0.0},
        {"gravity": float("nan")},
        {"close_time": 0.0},
        {"gravity_time": -0.1},
        {"disturbance_time": float("inf")},
        {"ramp_time": 0.0},
        {"disturbance_force_fraction": -0.5},
        {"disturbance_torque_arm": float("nan")},
        {"max_displacement": 0.0},
        {"max_rotation_deg": -1.0},
        {"invalid_penetration": 0.0},
        {"max_speed": float("inf")},
        {"batch_size": 0},
        {"batch_size": 2.5},
    ],
    ids=str,
)
def test_bad_protocol_values_raise_trial_error(kwargs: dict) -> None:
    with pytest.raises(TrialError, match="expected"):
        TrialProtocol(**kwargs)


def test_zero_disturbances_are_allowed() -> None:
    protocol = TrialProtocol(disturbance_force_fraction=0.0, disturbance_torque_arm=0.0)
    assert protocol.disturbance_force_fraction == 0.0


def test_an_object_without_parts_cannot_be_simulated() -> None:
    mesh = trimesh.creation.box(extents=(0.6, 0.04, 0.04))
    obj = make_object(mesh, object_id="no_parts", mass=4.0)
    assert not obj.parts
    with pytest.raises(SceneError, match="expected convex parts"):
        compile_scene(obj)
    with pytest.raises(SceneError, match="expected convex parts"):
        compile_scene(plank(0.6, 4.0), parts=[])


# --------------------------------------------------------------------------------------------
# 6. The schedule
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "protocol",
    [
        TrialProtocol(),
        TrialProtocol(
            gravity=9.81,
            close_time=0.1,
            gravity_time=0.08,
            disturbance_time=0.05,
            ramp_time=0.02,
            disturbance_force_fraction=0.3,
            disturbance_torque_arm=0.1,
        ),
    ],
    ids=["default", "custom"],
)
def test_schedule_phases_and_loads(short_scene: Scene, protocol: TrialProtocol) -> None:
    dt = short_scene.model.opt.timestep
    plan = schedule(short_scene, protocol)
    steps = protocol.phase_steps(dt)
    assert len(steps) == len(PHASES) == 14
    np.testing.assert_array_equal(
        steps,
        np.round(
            np.array(
                [protocol.close_time, protocol.gravity_time, *[protocol.disturbance_time] * 12]
            )
            / dt
        ),
    )
    # Phases in PHASES order, each for its number of steps.
    assert plan.nstep == steps.sum() == len(plan.wrench)
    assert plan.wrench.shape == (plan.nstep, 6)
    assert (np.diff(plan.phase) >= 0).all()
    np.testing.assert_array_equal(np.bincount(plan.phase, minlength=len(PHASES)), steps)
    assert plan.close_end == steps[0]
    assert (plan.phase[: plan.close_end] == 0).all()

    mass = short_scene.object_mass
    assert mass == pytest.approx(4.0)
    weight = mass * protocol.gravity
    force = protocol.disturbance_force_fraction * weight
    torque = force * protocol.disturbance_torque_arm
    gravity = np.array([0.0, 0.0, -weight, 0.0, 0.0, 0.0])
    targets = [np.zeros(6), gravity]
    for kind, magnitude, offset in (("force", force, 0), ("torque", torque, 3)):
        for direction in DIRECTIONS:
            sign = 1.0 if direction[0] == "+" else -1.0
            load = gravity.copy()
            load[offset + "xyz".index(direction[1])] += sign * magnitude
            targets.append(load)
            assert PHASES[len(targets) - 1] == f"{kind}{direction}"

    # No load while the hands close.
    assert (plan.wrench[: plan.close_end] == 0.0).all()
    # Each phase ramps linearly from the previous load to its own, then holds it.
    ramp = max(1, round(protocol.ramp_time / dt))
    starts = np.concatenate([[0], np.cumsum(steps)[:-1]])
    for p in range(1, len(PHASES)):
        rows = plan.wrench[starts[p] : starts[p] + steps[p]]
        n = min(ramp, int(steps[p]))
        np.testing.assert_allclose(rows[n - 1 :], np.broadcast_to(targets[p], rows[n - 1 :].shape))
        alpha = (np.arange(1, n + 1) / n)[:, None]
        expected = (1 - alpha) * targets[p - 1] + alpha * targets[p]
        np.testing.assert_allclose(rows[:n], expected, atol=1e-12)
    # Hence the load never jumps by more than one ramp step.
    jumps = np.abs(np.diff(plan.wrench, axis=0)).max(axis=0)
    assert (jumps <= np.abs(np.diff(np.array(targets), axis=0)).max(axis=0) / ramp + 1e-9).all()


def test_schedule_uses_the_scene_timestep_and_mass() -> None:
    params = SceneParameters(timestep=0.004, object_mass=2.5)
    scene = compile_scene(plank(0.6, 4.0), params=params)
    assert scene.model.opt.timestep == 0.004
    assert scene.object_mass == pytest.approx(2.5)
    protocol = TrialProtocol()
    plan = schedule(scene, protocol)
    np.testing.assert_array_equal(
        np.bincount(plan.phase, minlength=len(PHASES)), protocol.phase_steps(0.004)
    )
    gravity_rows = plan.wrench[plan.phase == 1][-1]
    np.testing.assert_allclose(gravity_rows, [0, 0, -2.5 * protocol.gravity, 0, 0, 0])


# --------------------------------------------------------------------------------------------
# 7. The scene
# --------------------------------------------------------------------------------------------


CUSTOM_CONTACT = SceneParameters(
    friction=0.7,
    torsional_friction=0.01,
    rolling_friction=0.0002,
    solref=(0.01, 0.9),
    solimp=(0.9, 0.97, 0.002),
)


@pytest.mark.parametrize("params", [SceneParameters(), CUSTOM_CONTACT], ids=["default", "custom"])
def test_every_geom_has_the_scene_contact_parameters(params: SceneParameters) -> None:
    """Object and hand geoms agree (MuJoCo mixes the two geoms' values of a contact, taking the
    larger friction: attached hands that kept MuJoCo's default friction 1.0 made every contact
    1.0)."""
    scene = compile_scene(plank(0.6, 4.0), params=params)
    model = scene.model
    hand_geoms = np.concatenate(scene.hand_geoms)
    assert len(scene.object_geoms) == 1
    assert len(hand_geoms) == 6
    assert model.ngeom == len(scene.object_geoms) + len(hand_geoms)
    friction = (params.friction, params.torsional_friction, params.rolling_friction)
    for geom in range(model.ngeom):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, geom)
        np.testing.assert_allclose(model.geom_friction[geom], friction, err_msg=name)
        assert model.geom_condim[geom] == 4, name
        np.testing.assert_allclose(model.geom_solref[geom], params.contact_solref, err_msg=name)
        np.testing.assert_allclose(model.geom_solimp[geom, :3], params.solimp, err_msg=name)
    if params.solref[0] <= 0:
        assert params.contact_solref == (2.0 * params.timestep, 1.0)
    # The contacts the trial makes carry the same values.
    data = mujoco.MjData(model)
    data.mocap_pos[scene.hand_mocap] = HOLD_FROM_ABOVE[:, :3, 3]
    for i, pose in enumerate(HOLD_FROM_ABOVE):
        mujoco.mju_mat2Quat(data.mocap_quat[scene.hand_mocap[i]], pose[:3, :3].ravel())
    data.qpos[scene.finger_qpos.ravel()] = PANDA.max_opening / 4.0 + 1e-4  # pads just inside
    mujoco.mj_forward(model, data)
    assert data.ncon > 0
    for c in range(data.ncon):
        contact = data.contact[c]
        assert contact.dim == 4
        np.testing.assert_allclose(contact.friction[:3], [friction[0], friction[0], friction[1]])
        np.testing.assert_allclose(contact.solref, params.contact_solref)


def test_physics_options(short_scene: Scene) -> None:
    opt, params = short_scene.model.opt, short_scene.params
    assert opt.timestep == params.timestep
    assert opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert opt.solver == mujoco.mjtSolver.mjSOL_NEWTON
    assert opt.impratio == params.impratio == 10.0
    assert opt.iterations == params.iterations
    np.testing.assert_array_equal(opt.gravity, [0.0, 0.0, 0.0])  # the trial applies the weight


def test_hands_are_mocap_bodies_that_never_touch_each_other(short_scene: Scene) -> None:
    model = short_scene.model
    assert model.nmocap == 2
    assert sorted(short_scene.hand_mocap.tolist()) == [0, 1]
    np.testing.assert_array_equal(
        model.body_mocapid[short_scene.hand_bodies], short_scene.hand_mocap
    )
    assert (model.body_parentid[short_scene.hand_bodies] == 0).all()  # children of the world
    assert model.body_mass[short_scene.object_body] == pytest.approx(4.0)

    def collide(a: int, b: int) -> bool:
        return bool(
            (model.geom_contype[a] & model.geom_conaffinity[b])
            or (model.geom_contype[b] & model.geom_conaffinity[a])
        )

    hand_geoms = np.concatenate(short_scene.hand_geoms)
    assert (hand_geoms >= 0).all()
    for a in hand_geoms:  # neither across the hands nor within one hand
        for b in hand_geoms:
            assert not collide(a, b), (a, b)
    for a in short_scene.object_geoms:
        for b in hand_geoms:
            assert collide(a, b)
    # The object's only body is the free one, with its parts.
    assert (model.geom_bodyid[short_scene.object_geoms] == short_scene.object_body).all()
    assert model.jnt_type[model.body_jntadr[short_scene.object_body]] == mujoco.mjtJoint.mjJNT_FREE


@pytest.mark.parametrize("squeeze", [70.0, 40.0])
def test_squeeze_actuators(squeeze: float) -> None:
    scene = compile_scene(plank(0.6, 4.0), params=SceneParameters(squeeze_force=squeeze))
    model = scene.model
    assert model.nu == 2
    for actuator in scene.squeeze_actuators:
        assert model.actuator_ctrllimited[actuator]
        np.testing.assert_allclose(model.actuator_ctrlrange[actuator], [0.0, squeeze])
    if squeeze == 70.0:
        assert squeeze == PANDA.max_force
    # The actuator really pushes (a `general` actuator without an affine bias gives zero force):
    # each finger joint gets the squeeze force, in the closing direction.
    data = mujoco.MjData(model)
    data.ctrl[scene.squeeze_actuators] = squeeze
    mujoco.mj_forward(model, data)
    np.testing.assert_allclose(data.actuator_force[scene.squeeze_actuators], squeeze)
    for name in ("hand0/finger0", "hand0/finger1", "hand1/finger0", "hand1/finger1"):
        joint = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        assert data.qfrc_actuator[model.jnt_dofadr[joint]] == pytest.approx(squeeze), name


def test_hand_geometry_matches_the_gripper_model(short_scene: Scene) -> None:
    """Palm and fingers where PANDA puts them; a finger joint's travel closes the jaw."""
    model = short_scene.model
    data = mujoco.MjData(model)
    pose = HOLD_FROM_ABOVE[1]
    data.mocap_pos[short_scene.hand_mocap[1]] = pose[:3, 3]
    mujoco.mju_mat2Quat(data.mocap_quat[short_scene.hand_mocap[1]], pose[:3, :3].ravel())
    geoms = short_scene.hand_geoms[1]

    def in_gripper_frame(geom: int) -> np.ndarray:
        return pose[:3, :3].T @ (data.geom_xpos[geom] - pose[:3, 3])

    mujoco.mj_forward(model, data)
    for geom, box in zip(geoms, PANDA.collision_boxes(), strict=True):
        np.testing.assert_allclose(in_gripper_frame(geom), box.center, atol=1e-9)
        np.testing.assert_allclose(model.geom_size[geom], box.half_extents, atol=1e-12)
    travel = PANDA.max_opening / 2.0
    data.qpos[short_scene.finger_qpos[1]] = travel  # fully closed: inner faces meet at x = 0
    mujoco.mj_forward(model, data)
    for geom, box in zip(geoms[1:], PANDA.finger_boxes(0.0), strict=True):
        np.testing.assert_allclose(in_gripper_frame(geom), box.center, atol=1e-9)


def test_scene_keeps_its_inputs(short_scene: Scene) -> None:
    assert short_scene.object_id == "short_plank"
    assert short_scene.gripper == PANDA
    assert short_scene.params == SceneParameters()
    assert "<mujoco" in short_scene.xml
    assert short_scene.object_qpos.stop - short_scene.object_qpos.start == 7


# --------------------------------------------------------------------------------------------
# 8. A procedural object
# --------------------------------------------------------------------------------------------


def test_procedural_benchmark_object_runs_without_instability() -> None:
    from dataset_gen.grasps.pairing import candidate_pairs, dual_poses
    from dataset_gen.grasps.sampling import sample_antipodal_grasps
    from dataset_gen.sources.procedural import benchmark_specs, make_procedural_object

    family, seed = benchmark_specs()[0]
    obj = make_procedural_object(family, seed)
    assert obj.parts
    scene = compile_scene(obj)
    assert len(scene.object_geoms) == len(obj.parts)

    single = sample_antipodal_grasps(obj, n_grasps=16, rng=np.random.default_rng(0))
    pairs = candidate_pairs(single).pairs
    assert len(pairs) >= 8
    grasps = dual_poses(single, pairs[:: len(pairs) // 8][:8])
    # Plus one dual grasp with an open hand in the middle of the object's first part.
    inside = grasps[0].copy()
    inside[1, :3, 3] = obj.parts[0].pose[:3, 3] - PANDA.contact_depth * inside[1, :3, 1]
    grasps = np.concatenate([grasps, inside[None]])

    results = run_trials(scene, grasps)
    assert results.n == 9
    assert not (results.status == TrialStatus.UNSTABLE).any(), results.summary()
    assert not results.ejected.any()
    assert results.status[-1] == TrialStatus.INVALID
    ran = results.valid
    assert ran.sum() >= 4, results.summary()
    assert np.isfinite(results.max_displacement[ran]).all()
    assert np.isfinite(results.max_rotation_deg[ran]).all()
    assert (results.max_penetration[ran] < 2e-3).all()  # measured <= 4.1e-4 m
    # Sampled antipodal grasps put both pads on the object.
    assert (results.contacts_after_close[ran] > 0).all()
    # Outcomes and phases are consistent.
    failed = results.status == TrialStatus.FAILED
    assert (results.failing_phase[failed] >= 0).all()
    assert (results.failing_phase[~failed] == -1).all()


# --------------------------------------------------------------------------------------------
# One conversion, one constructor from stored parameters, readable records
# --------------------------------------------------------------------------------------------


def test_quaternions_round_trip_through_the_one_conversion() -> None:
    from scipy.spatial.transform import Rotation

    from dg16m_env.physics.scene import quat_from_matrix, quat_to_matrix

    rotations = Rotation.random(12, random_state=0).as_matrix().reshape(3, 4, 3, 3)
    quats = quat_from_matrix(rotations)
    assert quats.shape == (3, 4, 4)
    np.testing.assert_allclose(np.linalg.norm(quats, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(quat_to_matrix(quats), rotations, atol=1e-12)


def test_scene_parameters_and_protocol_from_stored_dicts() -> None:
    params = SceneParameters(timestep=0.004, solimp=(0.9, 0.95, 0.002))
    stored = params.to_dict()
    assert isinstance(stored["solimp"], list)
    assert SceneParameters.from_dict(stored) == params
    with pytest.raises(SceneError, match=r"found unknown \['fricton'\]"):
        SceneParameters.from_dict({"fricton": 0.5})
    with pytest.raises(SceneError, match="expected a mapping"):
        SceneParameters.from_dict([("timestep", 0.004)])  # type: ignore[arg-type]
    protocol = TrialProtocol(batch_size=8, max_rotation_deg=5.0)
    assert TrialProtocol.from_dict(protocol.to_dict()) == protocol
    with pytest.raises(TrialError, match="expected keys among"):
        TrialProtocol.from_dict({"max_rotation": 5.0})


def test_results_print_short_and_count_invalid_reasons(short_scene: Scene) -> None:
    good0, good1 = HOLD_FROM_ABOVE
    grasps = np.stack(
        [dual(finger_inside(good0), good1), dual(good0, good0), dual(good0, finger_inside(good1))]
    )
    results = run_trials(short_scene, grasps)
    assert results.invalid_reasons() == {
        "hand0_penetrates": 1,
        "hand1_penetrates": 1,
        "hands_overlap": 1,
    }
    text = repr(results)
    assert text == "TrialResults(3 trials: 0 success, 0 failed, 3 invalid, 0 unstable)"


def test_open_hand_penetration_names_the_part(short_scene: Scene) -> None:
    from dg16m_env.physics.trial_protocol import HAND_PARTS, open_hand_penetration

    good0, good1 = HOLD_FROM_ABOVE
    depth = open_hand_penetration(
        short_scene, np.stack([dual(finger_inside(good0), good1), HOLD_FROM_ABOVE])
    )
    assert depth.shape == (2, 2, len(HAND_PARTS))
    inside = depth > TrialProtocol().invalid_penetration
    # Moved along +x (its closing axis), hand 0's finger 1 lies in the plank; nothing else does.
    assert inside[0].tolist() == [[False, False, True], [False, False, False]]
    assert not inside[1].any()
