"""Benchmark protocol v2: success probabilities over perturbed trials, the contact requirement,
the two levels, early exit, and the sampling rules of the benchmark's four arms.

Dual grasps are placed by hand on a 0.6 m, 4 kg box plank (as in ``test_sim.py``); a trial there
costs about 10 ms. The arms are checked on two procedural benchmark objects with 60 grasps.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

from planks import DOWN, SIDE, THICKNESS, dual, hand, plank

from dataset_gen.grasps.gripper import PANDA
from dataset_gen.grasps.pairing import candidate_pairs, score_pairs
from dataset_gen.grasps.sampling import sample_antipodal_grasps
from dataset_gen.sources.object_source import object_seed, procedural_sources
from dataset_gen.sources.procedural import benchmark_specs
from dg16m_core.errors import Dg16mError
from dg16m_env.benchmark.arms import sampled_pairs
from dg16m_env.benchmark.model import SOURCES, BenchmarkParameters
from dg16m_env.physics.labels import (
    GraspLabels,
    LabelError,
    PerturbationSpec,
    concatenate_labels,
    perturb_poses,
    row_seeds,
    success_probability,
)
from dg16m_env.physics.scene import Scene, compile_scene
from dg16m_env.physics.trial import run_trials
from dg16m_env.physics.trial_measures import grasp_centres
from dg16m_env.physics.trial_protocol import PHASES, TrialProtocol, TrialResults, TrialStatus

CLOSE, GRAVITY = PHASES.index("close"), PHASES.index("gravity")


# --------------------------------------------------------------------------------------------
# Objects and grasps (the plank of test_sim.py)
# --------------------------------------------------------------------------------------------


# Holds through the whole default protocol (both ends squeezed).
HOLD = dual(hand(-0.25, "y", DOWN), hand(0.25, "y", DOWN))
# Both hands near one end: the plank turns out of them under gravity.
FAIL_GRAVITY = dual(hand(-0.25, "y", DOWN), hand(-0.15, "y", DOWN))
# Hand 0 squeezes the plank's middle across top and bottom; hand 1 closes on air 0.3 m past the
# plank's end. Without the contact requirement hand 0 alone holds the plank through everything.
ONE_HAND_IN_AIR = dual(hand(0.0, "z", SIDE), hand(0.6, "z", SIDE))
# Open finger 1 of hand 0 moved 0.04 m along the closing axis: inside the plank (invalid).
INSIDE = HOLD.copy()
INSIDE[0, :3, 3] += 0.04 * INSIDE[0, :3, 0]
# HOLD with hand 0 lowered along its approach until its palm face sits 0.1 mm into the plank's
# top (valid: under invalid_penetration = 0.5 mm); a 1 mm / 1 degree perturbation puts the palm
# deeper than 0.5 mm (invalid) or lifts it clear (the grasp holds), so its trials are mixed.
PALM_ON_TOP = HOLD.copy()
PALM_ON_TOP[0, :3, 3] += (
    PANDA.contact_depth - PANDA.palm_depth - THICKNESS / 2.0 + 1e-4
) * PALM_ON_TOP[0, :3, 1]

# 2x the default disturbance: HOLD fails in the force-z disturbance, a grasp 0.3 m wide with pads
# on the top and bottom faces still holds (measured).
STRONG = TrialProtocol(disturbance_force_fraction=2.0)
HOLDS_STRONG = dual(hand(-0.1, "z", SIDE), hand(0.2, "z", SIDE))


@pytest.fixture(scope="module")
def scene() -> Scene:
    """0.6 m, 4 kg plank."""
    return compile_scene(plank(0.6, 4.0, "short_plank"))


def results_equal(a: TrialResults, b: TrialResults) -> None:
    for name in TrialResults.ARRAY_FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype, name
        assert np.array_equal(x, y, equal_nan=True), f"{name}: {x} != {y}"


def labels_equal(a: GraspLabels, b: GraspLabels) -> None:
    assert a.spec == b.spec
    for name in ("status", "failing_phase", "seeds"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype, name
        assert np.array_equal(x, y), f"{name}: {x} != {y}"
    results_equal(a.nominal, b.nominal)


def rotation_angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(...) angle of the rotation taking ``b`` (..., 3, 3) to ``a`` (degrees; atan2 form,
    accurate at small angles)."""
    rel = a @ np.swapaxes(b, -1, -2)
    skew = rel - np.swapaxes(rel, -1, -2)
    sin = 0.5 * np.linalg.norm(
        np.stack([skew[..., 2, 1], skew[..., 0, 2], skew[..., 1, 0]], axis=-1), axis=-1
    )
    cos = 0.5 * (np.trace(rel, axis1=-2, axis2=-1) - 1.0)
    return np.degrees(np.arctan2(sin, cos))


# --------------------------------------------------------------------------------------------
# 1. Determinism and row independence
# --------------------------------------------------------------------------------------------


def test_same_spec_and_seeds_give_the_same_bytes(scene: Scene) -> None:
    grasps = np.stack([HOLD, PALM_ON_TOP, FAIL_GRAVITY])
    spec = PerturbationSpec(n_perturbations=3)
    seeds = np.array([11, 22, 33], dtype=np.int64)
    first = success_probability(scene, grasps, spec=spec, seeds=seeds)
    again = success_probability(scene, grasps, spec=spec, seeds=seeds.copy())
    labels_equal(first, again)
    assert first.status.shape == first.failing_phase.shape == (3, 4)
    assert first.status.dtype == first.failing_phase.dtype == np.int8
    # The batch size of the rollouts changes nothing.
    one_by_one = success_probability(
        scene, grasps, spec=spec, seeds=seeds, protocol=TrialProtocol(batch_size=1)
    )
    for name in ("status", "failing_phase"):
        assert np.array_equal(getattr(first, name), getattr(one_by_one, name)), name

    centres = grasp_centres(scene, grasps)
    poses = perturb_poses(grasps, centres, seeds, spec)
    assert poses.shape == (3, 3, 2, 4, 4)
    assert poses.tobytes() == perturb_poses(grasps, centres, seeds.copy(), spec).tobytes()
    # Another seed moves every perturbed hand elsewhere.
    other = perturb_poses(grasps, centres, seeds + 1, spec)
    assert not np.isclose(other, poses).all(axis=(-2, -1)).any()
    # Default seeds derive from the spec's seed and the object id.
    default = success_probability(scene, grasps[:1], spec=spec)
    np.testing.assert_array_equal(default.seeds, row_seeds(spec.seed, scene.object_id, 1))
    assert default.seeds.dtype == np.int64
    assert not np.array_equal(row_seeds(0, "a", 4), row_seeds(1, "a", 4))
    assert not np.array_equal(row_seeds(0, "a", 4), row_seeds(0, "b", 4))
    np.testing.assert_array_equal(row_seeds(7, "a", 4), row_seeds(7, "a", 4))
    assert (row_seeds(7, "a", 100) >= 0).all()


def test_a_row_is_labelled_the_same_alone_or_among_others(scene: Scene) -> None:
    spec = PerturbationSpec(n_perturbations=3)
    a, b = HOLD, PALM_ON_TOP
    seeds = np.array([5, 9], dtype=np.int64)
    both = success_probability(scene, np.stack([a, b]), spec=spec, seeds=seeds)
    alone = success_probability(scene, b[None], spec=spec, seeds=seeds[1:])
    labels_equal(both.select(np.array([1])), alone)
    # In the other order, too.
    swapped = success_probability(scene, np.stack([b, a]), spec=spec, seeds=seeds[::-1].copy())
    labels_equal(swapped.select(np.array([0])), alone)
    # Labelling the rows apart and concatenating gives the joint labels.
    first = success_probability(scene, a[None], spec=spec, seeds=seeds[:1])
    labels_equal(concatenate_labels([first, alone]), both)
    # The perturbed poses of a row depend on its seed alone.
    grasps = np.stack([a, b])
    centres = grasp_centres(scene, grasps)
    together = perturb_poses(grasps, centres, seeds, spec)
    apart = perturb_poses(grasps[1:], centres[1:], seeds[1:], spec)
    assert together[1].tobytes() == apart[0].tobytes()


# --------------------------------------------------------------------------------------------
# 2. Perturbation geometry
# --------------------------------------------------------------------------------------------


def _random_grasps(n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 2, 4, 4) random rigid hand poses."""
    q, r = np.linalg.qr(rng.standard_normal((n * 2, 3, 3)))
    q = q * np.sign(np.diagonal(r, axis1=-2, axis2=-1))[:, None, :]
    q[np.linalg.det(q) < 0, :, 0] *= -1.0
    out = np.broadcast_to(np.eye(4), (n * 2, 4, 4)).copy()
    out[:, :3, :3] = q
    out[:, :3, 3] = rng.uniform(-0.5, 0.5, (n * 2, 3))
    return out.reshape(n, 2, 4, 4)


@pytest.mark.parametrize(
    ("d", "theta"), [(0.001, 1.0), (0.005, 7.5), (0.0, 3.0), (0.002, 0.0)], ids=str
)
def test_each_hand_moves_by_exactly_d_and_turns_by_exactly_theta(
    scene: Scene, d: float, theta: float
) -> None:
    grasps = np.concatenate(
        [
            np.stack([HOLD, FAIL_GRAVITY, ONE_HAND_IN_AIR]),
            _random_grasps(40, np.random.default_rng(3)),
        ]
    )
    n, k = len(grasps), 5
    spec = PerturbationSpec(n_perturbations=k, translation=d, rotation_deg=theta)
    centres = grasp_centres(scene, grasps)
    seeds = row_seeds(0, "geometry", n)
    poses = perturb_poses(grasps, centres, seeds, spec)
    assert poses.shape == (n, k, 2, 4, 4)
    assert poses.dtype == np.float64

    # Rigid: orthonormal rotations with det +1, last row exactly 0 0 0 1.
    rot = poses[..., :3, :3]
    np.testing.assert_allclose(
        rot @ np.swapaxes(rot, -1, -2), np.broadcast_to(np.eye(3), rot.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-12)
    assert (poses[..., 3, :] == np.array([0.0, 0.0, 0.0, 1.0])).all()

    # The grasp centre moves by exactly d ...
    moved = grasp_centres(scene, poses.reshape(n * k, 2, 4, 4)).reshape(n, k, 2, 3)
    shift = moved - centres[:, None]
    np.testing.assert_allclose(np.linalg.norm(shift, axis=-1), d, rtol=0, atol=1e-12)
    # ... and the hand turns by exactly theta about it.
    angle = rotation_angle_deg(rot, grasps[:, None, :, :3, :3])
    np.testing.assert_allclose(angle, theta, rtol=0, atol=1e-9)
    # Every point of the hand keeps its distance to the (moved) grasp centre.
    tip = np.array([0.0, PANDA.finger_tip, 0.0, 1.0])
    before = (grasps @ tip)[..., :3] - centres
    after = (poses @ tip)[..., :3] - moved
    np.testing.assert_allclose(
        np.linalg.norm(after, axis=-1),
        np.broadcast_to(np.linalg.norm(before, axis=-1)[:, None], after.shape[:-1]),
        rtol=0,
        atol=1e-12,
    )

    # Directions and axes are random: each hand its own, and no preferred direction.
    if d > 0:
        u = (shift / d).reshape(-1, 3)
        assert len(np.unique(np.round(u, 9), axis=0)) == len(u)
        assert np.linalg.norm(u.mean(axis=0)) < 0.15
    if theta > 0:
        rel = rot @ np.swapaxes(grasps[:, None, :, :3, :3], -1, -2)
        axes = np.stack(
            [
                rel[..., 2, 1] - rel[..., 1, 2],
                rel[..., 0, 2] - rel[..., 2, 0],
                rel[..., 1, 0] - rel[..., 0, 1],
            ],
            axis=-1,
        )
        axes = (axes / np.linalg.norm(axes, axis=-1, keepdims=True)).reshape(-1, 3)
        assert len(np.unique(np.round(axes, 9), axis=0)) == len(axes)
        assert np.linalg.norm(axes.mean(axis=0)) < 0.15


def test_a_zero_perturbation_reproduces_the_nominal_trial(scene: Scene) -> None:
    grasps = np.stack([HOLD, FAIL_GRAVITY, ONE_HAND_IN_AIR, INSIDE, HOLDS_STRONG])
    spec = PerturbationSpec(n_perturbations=3, translation=0.0, rotation_deg=0.0)
    seeds = np.arange(len(grasps), dtype=np.int64)
    poses = perturb_poses(grasps, grasp_centres(scene, grasps), seeds, spec)
    for i in range(len(grasps)):
        for k in range(spec.n_perturbations):
            assert poses[i, k].tobytes() == grasps[i].tobytes(), (i, k)

    labels = success_probability(scene, grasps, spec=spec, seeds=seeds, protocol=STRONG)
    # Outcomes of every kind are among the nominal trials ...
    assert labels.status[:, 0].tolist() == [
        TrialStatus.FAILED,
        TrialStatus.FAILED,
        TrialStatus.FAILED,
        TrialStatus.INVALID,
        TrialStatus.SUCCESS,
    ]
    assert [PHASES[p] if p >= 0 else "" for p in labels.failing_phase[:, 0]] == [
        "force-z",
        "gravity",
        "close",
        "",
        "",
    ]
    # ... and every perturbed trial repeats its nominal one.
    for name in ("status", "failing_phase"):
        arr = getattr(labels, name)
        assert (arr == arr[:, :1]).all(), f"{name}:\n{arr}"
    # Column 0 is the nominal trial: the same as running the grasps alone.
    results_equal(labels.nominal, run_trials(scene, grasps, STRONG))
    np.testing.assert_array_equal(labels.p_success, [0.0, 0.0, 0.0, 0.0, 1.0])
    # K = 0: the nominal trial alone.
    alone = success_probability(
        scene, grasps, spec=PerturbationSpec(n_perturbations=0), seeds=seeds, protocol=STRONG
    )
    assert alone.status.shape == (len(grasps), 1)
    np.testing.assert_array_equal(alone.status[:, 0], labels.status[:, 0])
    np.testing.assert_array_equal(alone.p_success, labels.p_success)


# --------------------------------------------------------------------------------------------
# 3. Invalid trials count as failures; p from the trial statuses
# --------------------------------------------------------------------------------------------


def test_invalid_trials_count_as_failures_in_both_levels(scene: Scene) -> None:
    grasps = np.stack([INSIDE, PALM_ON_TOP, HOLD, FAIL_GRAVITY, ONE_HAND_IN_AIR])
    spec = PerturbationSpec(n_perturbations=8)
    trials = spec.trials
    labels = success_probability(
        scene, grasps, spec=spec, seeds=np.arange(100, 105, dtype=np.int64)
    )
    status, phase = labels.status, labels.failing_phase

    # An open hand in the object: every trial invalid, p = 0 at both levels.
    assert (status[0] == TrialStatus.INVALID).all()
    assert labels.nominal.status[0] == TrialStatus.INVALID
    assert labels.p_success[0] == labels.p_gravity[0] == 0.0
    assert not labels.label()[0]
    assert not labels.label("gravity")[0]

    # The palm on the plank's top: some trials invalid, the others hold; the invalid ones stay
    # in the denominator.
    invalid = int((status[1] == TrialStatus.INVALID).sum())
    held = int((status[1] == TrialStatus.SUCCESS).sum())
    assert 0 < invalid < trials, status[1]
    assert held > 0, status[1]
    assert labels.p_success[1] == held / trials
    assert labels.p_success[1] < held / (trials - invalid)
    assert labels.p_gravity[1] == int(labels.held_gravity[1].sum()) / trials

    # Every row: p from the statuses and phases, counted over all K + 1 trials.
    ran = status != TrialStatus.INVALID
    gravity_held = ran & ((phase < 0) | (phase > GRAVITY))
    np.testing.assert_array_equal(labels.held, status == TrialStatus.SUCCESS)
    np.testing.assert_array_equal(labels.held_gravity, gravity_held)
    np.testing.assert_array_equal(
        labels.p_success, (status == TrialStatus.SUCCESS).sum(axis=1) / trials
    )
    np.testing.assert_array_equal(labels.p_gravity, gravity_held.sum(axis=1) / trials)
    np.testing.assert_array_equal(labels.p("full"), labels.p_success)
    np.testing.assert_array_equal(labels.p("gravity"), labels.p_gravity)
    assert (labels.failing_phase[~ran] == -1).all()
    assert labels.p_success[2] == 1.0
    assert labels.p_success[3] == labels.p_gravity[3] == 0.0
    assert labels.p_success[4] == labels.p_gravity[4] == 0.0


def _synthetic(status: list[list[int]], phase: list[list[int]]) -> GraspLabels:
    status_arr = np.array(status, dtype=np.int8)
    n, trials = status_arr.shape
    nominal = TrialResults.empty(n, TrialProtocol())
    nominal.status[:] = status_arr[:, 0]
    return GraspLabels(
        nominal=nominal,
        status=status_arr,
        failing_phase=np.array(phase, dtype=np.int8),
        seeds=np.arange(n, dtype=np.int64),
        spec=PerturbationSpec(n_perturbations=trials - 1),
    )


def test_probabilities_labels_and_uncertainty_from_trial_codes() -> None:
    S, F, I, U = (int(s) for s in TrialStatus)  # noqa: E741
    force = PHASES.index("force+x")
    labels = _synthetic(
        [
            [S] * 5 + [I] * 5,  # p = 0.5 exactly: labelled success, uncertain
            [S] * 2 + [F] * 8,  # p = 0.2: not uncertain (strict bounds)
            [S] * 8 + [I] * 2,  # p = 0.8: not uncertain
            [F, U, F, F, U, F, I, I, F, S],  # disturbance failures hold under gravity
            [S] * 3 + [F] * 7,  # p = 0.3: uncertain, labelled failure
        ],
        [
            [-1] * 5 + [-1] * 5,
            [-1] * 2 + [CLOSE] * 8,
            [-1] * 10,
            [force, force, GRAVITY, CLOSE, GRAVITY, len(PHASES) - 1, -1, -1, force, -1],
            [-1] * 3 + [GRAVITY] * 7,
        ],
    )
    np.testing.assert_array_equal(labels.p_success, [0.5, 0.2, 0.8, 0.1, 0.3])
    # Row 3: held under gravity = the failures and instabilities after gravity and the success.
    np.testing.assert_array_equal(labels.held_gravity[3], [1, 1, 0, 0, 0, 1, 0, 0, 1, 1])
    np.testing.assert_array_equal(labels.p_gravity, [0.5, 0.2, 0.8, 0.5, 0.3])
    np.testing.assert_array_equal(labels.label(), [True, False, True, False, False])
    np.testing.assert_array_equal(labels.label("gravity"), [True, False, True, True, False])
    np.testing.assert_array_equal(labels.uncertain(), [True, False, False, False, True])
    np.testing.assert_array_equal(labels.uncertain("gravity"), [True, False, False, True, True])
    with pytest.raises(LabelError, match="level"):
        labels.p("headline")
    summary = labels.summary()
    assert summary["rows"] == 5
    assert summary["trials_per_row"] == 10
    assert summary["full"]["uncertain"] == 2
    assert summary["gravity"]["uncertain"] == 3


# --------------------------------------------------------------------------------------------
# 4. The contact requirement
# --------------------------------------------------------------------------------------------


def test_a_hand_touching_nothing_fails_in_close(scene: Scene) -> None:
    mirrored = ONE_HAND_IN_AIR[::-1].copy()  # hand 0 in the air, hand 1 on the plank
    grasps = np.stack([ONE_HAND_IN_AIR, mirrored])
    results = run_trials(scene, grasps)
    assert results.status.tolist() == [TrialStatus.FAILED] * 2
    assert [results.phase_name(i) for i in range(2)] == ["close", "close"]
    assert results.contacts_after_close[0, 1] == 0
    assert results.contacts_after_close[0, 0] > 0
    assert results.contacts_after_close[1, 0] == 0
    assert results.contacts_after_close[1, 1] > 0
    # The plank did not move: the failure is the missing contact, not slip.
    protocol = TrialProtocol()
    assert (results.max_displacement < protocol.max_displacement).all()
    assert (results.max_rotation_deg < protocol.max_rotation_deg).all()

    # Without the requirement the one hand holds the plank through the whole protocol.
    free = TrialProtocol(min_contacts_after_close=0)
    relaxed = run_trials(scene, grasps, free)
    assert relaxed.status.tolist() == [TrialStatus.SUCCESS] * 2, relaxed.summary()
    assert (relaxed.failing_phase == -1).all()
    np.testing.assert_array_equal(relaxed.contacts_after_close, results.contacts_after_close)

    # And in the labels: no trial holds at either level with it, every trial without it.
    spec = PerturbationSpec(n_perturbations=2)
    seeds = np.array([1, 2], dtype=np.int64)
    strict = success_probability(scene, grasps, spec=spec, seeds=seeds)
    assert (strict.failing_phase == CLOSE).all()
    np.testing.assert_array_equal(strict.p_success, [0.0, 0.0])
    np.testing.assert_array_equal(strict.p_gravity, [0.0, 0.0])
    lenient = success_probability(scene, grasps, spec=spec, seeds=seeds, protocol=free)
    np.testing.assert_array_equal(lenient.p_success, [1.0, 1.0])


def test_the_contact_count_is_a_threshold_on_each_hand(scene: Scene) -> None:
    base = run_trials(scene, HOLD[None])
    assert base.status[0] == TrialStatus.SUCCESS
    fewest = int(base.contacts_after_close[0].min())
    assert fewest >= 1
    enough = run_trials(scene, HOLD[None], TrialProtocol(min_contacts_after_close=fewest))
    assert enough.status[0] == TrialStatus.SUCCESS
    too_many = run_trials(scene, HOLD[None], TrialProtocol(min_contacts_after_close=fewest + 1))
    assert too_many.status[0] == TrialStatus.FAILED
    assert too_many.phase_name(0) == "close"


# --------------------------------------------------------------------------------------------
# 5. Two levels
# --------------------------------------------------------------------------------------------


def test_a_disturbance_failure_holds_at_the_gravity_level(scene: Scene) -> None:
    """5x the default disturbance force: HOLD keeps the plank under gravity and loses it in a
    disturbance phase."""
    protocol = TrialProtocol(disturbance_force_fraction=5.0)
    grasps = np.stack([HOLD, FAIL_GRAVITY, ONE_HAND_IN_AIR, INSIDE])
    spec = PerturbationSpec(n_perturbations=2)
    labels = success_probability(
        scene, grasps, spec=spec, seeds=np.arange(4, dtype=np.int64), protocol=protocol
    )
    assert (labels.status[0] == TrialStatus.FAILED).all()
    assert (labels.failing_phase[0] > GRAVITY).all(), labels.failing_phase[0]
    assert labels.held_gravity[0].all()
    assert not labels.held[0].any()
    assert labels.p_gravity[0] == 1.0
    assert labels.p_success[0] == 0.0
    assert labels.label("gravity")[0]
    assert not labels.label("full")[0]
    # Failures in gravity or close, and invalid trials, hold at neither level.
    assert (labels.failing_phase[1] == GRAVITY).all()
    assert (labels.failing_phase[2] == CLOSE).all()
    assert not labels.held_gravity[1:].any()
    np.testing.assert_array_equal(labels.p_gravity[1:], [0.0, 0.0, 0.0])
    assert (labels.p_gravity >= labels.p_success).all()


def test_p_gravity_is_never_below_p_success(scene: Scene) -> None:
    grasps = np.stack([HOLD, PALM_ON_TOP, FAIL_GRAVITY, HOLDS_STRONG])
    for protocol in (TrialProtocol(), STRONG):
        labels = success_probability(
            scene,
            grasps,
            spec=PerturbationSpec(n_perturbations=3),
            seeds=np.arange(4, dtype=np.int64),
            protocol=protocol,
        )
        assert (labels.p_gravity >= labels.p_success).all()
        assert (labels.held_gravity | ~labels.held).all()  # held fully => held under gravity


# --------------------------------------------------------------------------------------------
# 6. Early exit
# --------------------------------------------------------------------------------------------


def test_early_exit_does_not_change_verdicts(scene: Scene) -> None:
    grasps = np.stack([HOLD, HOLDS_STRONG, ONE_HAND_IN_AIR, FAIL_GRAVITY, INSIDE, PALM_ON_TOP])
    for protocol in (STRONG, TrialProtocol(batch_size=4)):
        early = run_trials(scene, grasps, protocol, early_exit=True)
        full = run_trials(scene, grasps, protocol, early_exit=False)
        if protocol is STRONG:
            # Every kind of outcome: success, failures in close, gravity and a disturbance.
            assert early.status.tolist() == [1, 0, 1, 1, 2, 1], early.summary()
            assert [early.phase_name(i) for i in range(early.n - 1)] == [
                "force-z",
                "",
                "close",
                "gravity",
                "",
            ]
            assert early.failing_phase[-1] > GRAVITY
        for name in (
            "status",
            "failing_phase",
            "contacts_after_close",
            "max_displacement",
            "max_rotation_deg",
        ):
            assert np.array_equal(getattr(early, name), getattr(full, name), equal_nan=True), name
        results_equal(early, full)


# --------------------------------------------------------------------------------------------
# 7. The arms of a sampled benchmark
# --------------------------------------------------------------------------------------------


ARM_PARAMS = BenchmarkParameters(n_grasps=60, n_passing=6, n_failing=4, n_random=40, n_farthest=4)


@pytest.mark.parametrize(("spec_index", "shortfall"), [(0, False), (3, True)], ids=["table", "tub"])
def test_sampled_arms_follow_their_rules(spec_index: int, shortfall: bool) -> None:
    params = ARM_PARAMS
    obj = procedural_sources(benchmark_specs()[spec_index : spec_index + 1])[0].load(params.mass)
    stream = object_seed(params.seed, f"benchmark:{obj.object_id}")
    rows = sampled_pairs(obj, params, np.random.default_rng(stream))
    # The same grasps, by replaying the stream (sampled_pairs draws the grasps first).
    grasps = sample_antipodal_grasps(
        obj, n_grasps=params.n_grasps, mu=params.mu, rng=np.random.default_rng(stream)
    )
    index = {pose.tobytes(): i for i, pose in enumerate(grasps.poses)}
    assert len(index) == grasps.n
    pairs = np.array([[index[p.tobytes()] for p in row] for row in rows["poses"]])
    assert (pairs[:, 0] != pairs[:, 1]).all()
    source = rows["source"]
    assert (np.diff(source) >= 0).all(), "rows in arm order"
    arm = {
        name: source == SOURCES.index(name) for name in ("fc_pass", "fc_fail", "random", "farthest")
    }
    assert set(source.tolist()) <= {0, 1, 2, 3}

    candidates = candidate_pairs(grasps, min_center_distance=params.min_center_distance)
    candidate_set = {tuple(p) for p in candidates.pairs.tolist()}
    fc_kwargs = params.force_closure_kwargs()
    assert fc_kwargs["gravity"] == params.protocol.gravity
    available_pass = int(score_pairs(grasps, candidates.pairs, **fc_kwargs).passed.sum())

    # Counts: never above the request; a shortfall of passing pairs is filled with failing ones.
    n_pass, n_fail = int(arm["fc_pass"].sum()), int(arm["fc_fail"].sum())
    assert n_pass == min(params.n_passing, available_pass)
    assert (n_pass < params.n_passing) == shortfall
    assert n_fail == params.n_failing + params.n_passing - n_pass
    assert int(arm["random"].sum()) == params.n_random
    assert 0 < int(arm["farthest"].sum()) <= params.n_farthest

    # fc_pass: candidates that pass force closure.
    passing = pairs[arm["fc_pass"]]
    assert {tuple(p) for p in passing.tolist()} <= candidate_set
    assert rows["fc_passed"][arm["fc_pass"]].all()
    assert score_pairs(grasps, passing, **fc_kwargs).passed.all()
    # fc_fail: candidates that fail, with a loss above failing_min_loss.
    failing = pairs[arm["fc_fail"]]
    assert {tuple(p) for p in failing.tolist()} <= candidate_set
    assert not rows["fc_passed"][arm["fc_fail"]].any()
    assert (rows["fc_loss"][arm["fc_fail"]] > params.failing_min_loss).all()
    assert not score_pairs(grasps, failing, **fc_kwargs).passed.any()
    # random: distinct candidates (collision-free, centres at least the pruning distance apart).
    random = pairs[arm["random"]]
    assert len({tuple(sorted(p)) for p in random.tolist()}) == len(random)
    assert {tuple(p) for p in random.tolist()} <= candidate_set
    centers = np.asarray(grasps.centers)
    gap = np.linalg.norm(centers[random[:, 0]] - centers[random[:, 1]], axis=1)
    assert (gap >= params.min_center_distance).all()
    # farthest: one grasp of each pair has the other as its farthest grasp (by centre).
    distance = np.linalg.norm(centers[:, None] - centers[None], axis=-1)
    farthest = distance.max(axis=1)
    for i, j in pairs[arm["farthest"]].tolist():
        assert distance[i, j] == farthest[i] or distance[i, j] == farthest[j], (i, j)
    assert len({tuple(sorted(p)) for p in pairs[arm["farthest"]].tolist()}) == int(
        arm["farthest"].sum()
    )
    # Contacts are the pairs' grasps' contacts.
    np.testing.assert_array_equal(
        rows["contact_points"],
        np.concatenate(
            [grasps.contact_points[pairs[:, 0]], grasps.contact_points[pairs[:, 1]]], axis=1
        ),
    )


# --------------------------------------------------------------------------------------------
# 8. Validation
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"n_perturbations": -1}, "n_perturbations"),
        ({"n_perturbations": 2.5}, "n_perturbations"),
        ({"n_perturbations": True}, "n_perturbations"),
        ({"translation": -0.001}, "translation"),
        ({"translation": float("nan")}, "translation"),
        ({"translation": float("inf")}, "translation"),
        ({"translation": True}, "translation"),
        ({"rotation_deg": -1.0}, "rotation_deg"),
        ({"rotation_deg": float("nan")}, "rotation_deg"),
        ({"rotation_deg": "1"}, "rotation_deg"),
        ({"seed": -1}, "seed"),
        ({"seed": False}, "seed"),
    ],
    ids=str,
)
def test_bad_perturbation_specs_name_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(LabelError, match=rf"^{field}: expected"):
        PerturbationSpec(**kwargs)


def test_perturbation_spec_round_trip_and_unknown_keys() -> None:
    spec = PerturbationSpec(n_perturbations=2, translation=0.002, rotation_deg=0.5, seed=3)
    assert PerturbationSpec.from_dict(spec.to_dict()) == spec
    assert PerturbationSpec.from_dict({}) == PerturbationSpec()
    # The protocol's defaults: d = 1 mm, theta = 1 degree (DESIGN.md), K = 8 (chosen by
    # measurement, BENCHMARKS.md "Label stability").
    default = PerturbationSpec()
    assert (default.n_perturbations, default.translation, default.rotation_deg) == (8, 1e-3, 1.0)
    assert default.trials == 9
    assert PerturbationSpec(n_perturbations=0, translation=0.0, rotation_deg=0.0).trials == 1
    with pytest.raises(LabelError, match=r"unknown \['k'\]"):
        PerturbationSpec.from_dict({"k": 4})
    with pytest.raises(LabelError, match="expected a mapping"):
        PerturbationSpec.from_dict([("seed", 1)])  # type: ignore[arg-type]
    with pytest.raises(LabelError, match="translation"):
        PerturbationSpec.from_dict({"translation": -1.0})
    assert issubclass(LabelError, ValueError)
    assert issubclass(LabelError, Dg16mError)


@pytest.mark.parametrize(
    "seeds",
    [
        np.array([1, 2, 3], dtype=np.int64),  # one too many
        np.array([1], dtype=np.int64),  # one too few
        np.array([[1], [2]], dtype=np.int64),  # (N, 1)
        np.array([1.0, 2.0]),  # floats
        np.array([1, -2], dtype=np.int64),  # negative
        np.array(["a", "b"]),
    ],
    ids=["3", "1", "2x1", "float", "negative", "str"],
)
def test_perturb_poses_rejects_bad_seeds(scene: Scene, seeds: np.ndarray) -> None:
    grasps = np.stack([HOLD, FAIL_GRAVITY])
    with pytest.raises(LabelError, match=r"^seeds: expected"):
        perturb_poses(grasps, grasp_centres(scene, grasps), seeds, PerturbationSpec())
    with pytest.raises(LabelError, match=r"^seeds: expected"):
        success_probability(scene, grasps, seeds=seeds)


def test_bad_label_arrays_and_mixed_specs_are_refused(scene: Scene) -> None:
    with pytest.raises(LabelError, match="seed"):
        row_seeds(-1, "x", 3)
    with pytest.raises(LabelError, match=r"^n: expected"):
        row_seeds(0, "x", -1)
    good = _synthetic([[0, 1, 0]], [[-1, CLOSE, -1]])
    with pytest.raises(LabelError, match="status: expected shape"):
        GraspLabels(
            nominal=good.nominal,
            status=good.status[:, :2],
            failing_phase=good.failing_phase,
            seeds=good.seeds,
            spec=good.spec,
        )
    with pytest.raises(LabelError, match="column 0"):
        GraspLabels(
            nominal=good.nominal,
            status=np.array([[1, 0, 0]], dtype=np.int8),
            failing_phase=good.failing_phase,
            seeds=good.seeds,
            spec=good.spec,
        )
    other = _synthetic([[0, 1]], [[-1, CLOSE]])
    with pytest.raises(LabelError, match="one perturbation spec"):
        concatenate_labels([good, other])
    with pytest.raises(LabelError, match="at least one"):
        concatenate_labels([])


def test_seeds_that_do_not_fit_the_stored_int64_are_refused() -> None:
    """A uint64 seed >= 2**63 would wrap to a negative stored seed that cannot relabel its row."""
    big = np.array([2**63 + 5], dtype=np.uint64)
    with pytest.raises(LabelError, match="below 2\\*\\*63"):
        perturb_poses(
            np.eye(4)[None, None].repeat(2, axis=1), np.zeros((1, 2, 3)), big, PerturbationSpec()
        )
