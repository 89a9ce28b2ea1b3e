"""The robust pair selection: the disturbance motion ratio on hand-made cases, the protocol's loads
defined once, the generator's and the benchmark's robust modes."""

from __future__ import annotations

import numpy as np
import pytest

from dataset_gen.force_closure import evaluate
from dataset_gen.grasps.robust import (
    LOAD_NAMES,
    RobustError,
    disturbance_motion,
    protocol_loads,
    robust_pairs,
)
from dataset_gen.objects.grasp_object import MassProperties
from dataset_gen.pipeline.generate import GenerationError, GenerationParameters, generate_object
from dataset_gen.sources.procedural import make_procedural_object
from dg16m_core.parameters import PAPER, PROTOCOL

# A 0.8 x 0.04 x 0.04 m bar pinched from above and below by two hands 0.6 m apart: contacts on
# its top and bottom faces (normals +-z), the hand line along x through the origin.
BAR_POINTS = np.array(
    [[[-0.3, 0.0, 0.02], [-0.3, 0.0, -0.02], [0.3, 0.0, 0.02], [0.3, 0.0, -0.02]]]
)
BAR_NORMALS = np.array([[[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]])
# A 6 kg body with a radius of gyration of 0.2 m about every axis.
INERTIA = PAPER.mass * 0.2**2 * np.eye(3)
PROPS = MassProperties(PAPER.mass, np.zeros(3), INERTIA, None, "solid")


def _motion(center_of_mass: tuple[float, float, float]):
    com = np.asarray(center_of_mass)
    return disturbance_motion(BAR_POINTS, BAR_NORMALS, center_of_mass=com, inertia=INERTIA)


def test_hand_line_through_the_centre_of_mass_is_robust() -> None:
    motion = _motion((0.0, 0.0, 0.0))
    assert motion.robust()[0]
    assert motion.ratio[0] < 0.5
    # Gravity is resisted exactly, so it moves nothing over the whole held time.
    assert motion.losses[0, 0] <= PAPER.threshold
    assert motion.displacement[0, 0] < 1e-6


def test_hand_line_far_from_the_centre_of_mass_is_not_robust_though_it_passes_the_paper() -> None:
    # The centre of mass hangs 0.3 m below the hand line: gravity acts along the line joining
    # them (no torque about the hand line), so the paper's gravity-only check passes, but a
    # sideways push (30 N along y) turns the object about the hand line with 9 N m, more than
    # the pads' friction can hold (about 2.2 N m).
    com = np.array([0.0, 0.0, -0.3])
    paper = evaluate(BAR_POINTS - com, BAR_NORMALS)
    assert paper.passed[0]
    motion = _motion(tuple(com))
    assert not motion.robust()[0]
    worst = int(np.argmax(motion.rotation_deg[0]))
    assert LOAD_NAMES[worst] in ("force+y", "force-y")
    assert motion.rotation_deg[0, worst] > PROTOCOL.max_rotation_deg
    # Moving the centre of mass towards the hand line makes it robust again.
    assert _motion((0.0, 0.0, -0.03)).robust()[0]


def test_protocol_loads_are_the_trial_schedule() -> None:
    pytest.importorskip("mujoco")
    from dg16m_env.physics.scene import compile_scene
    from dg16m_env.physics.trial_protocol import PHASES, TrialProtocol, schedule

    assert PHASES[1:] == LOAD_NAMES
    obj = make_procedural_object("crate", 3)
    scene = compile_scene(obj)
    protocol = TrialProtocol()
    plan = schedule(scene, protocol)
    wrenches, durations = protocol_loads(
        scene.object_mass, protocol.gravity, protocol.disturbances()
    )
    for k in range(1, len(PHASES)):
        steps = np.flatnonzero(plan.phase == k)
        np.testing.assert_allclose(plan.wrench[steps[-1]], wrenches[k - 1], atol=1e-12)
        if k > 1:
            assert len(steps) * scene.model.opt.timestep == pytest.approx(durations[k - 1])
    held = np.flatnonzero(plan.phase >= 1).size * scene.model.opt.timestep
    assert held == pytest.approx(durations[0])


def test_rank_deficient_pairs_are_never_robust_and_bad_inputs_are_refused() -> None:
    collinear = np.array([[[x, 0.0, 0.0] for x in (-0.3, -0.1, 0.1, 0.3)]])
    normals = np.array([[[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]] * 2])
    motion = disturbance_motion(collinear, normals, center_of_mass=np.zeros(3), inertia=INERTIA)
    assert np.isinf(motion.ratio[0])
    assert not motion.robust()[0]
    with pytest.raises(RobustError, match=r"expected points and normals of shape \(N, 4, 3\)"):
        disturbance_motion(
            BAR_POINTS[0], BAR_NORMALS[0], center_of_mass=np.zeros(3), inertia=INERTIA
        )
    with pytest.raises(RobustError, match="positive definite"):
        disturbance_motion(BAR_POINTS, BAR_NORMALS, center_of_mass=np.zeros(3), inertia=-INERTIA)
    with pytest.raises(RobustError, match="finite"):
        disturbance_motion(
            BAR_POINTS, BAR_NORMALS, center_of_mass=np.full(3, np.nan), inertia=INERTIA
        )
    empty = disturbance_motion(
        np.zeros((0, 4, 3)), np.zeros((0, 4, 3)), center_of_mass=np.zeros(3), inertia=INERTIA
    )
    assert empty.ratio.shape == (0,)


def test_robust_pairs_stops_once_enough_are_found_and_is_seeded() -> None:
    offsets = np.linspace(-0.3, 0.0, 40)  # the centre of mass from 0.3 m below the line to on it
    points = np.repeat(BAR_POINTS, 40, axis=0) - offsets[:, None, None] * np.array([0, 0, 1.0])
    normals = np.repeat(BAR_NORMALS, 40, axis=0)
    passed = np.ones(40, dtype=bool)
    passed[::7] = False
    every = robust_pairs(
        points, normals, passed, rng=np.random.default_rng(0), wanted=None,
        mass_properties=PROPS, chunk_size=8,
    )  # fmt: skip
    assert every.counts["evaluated"] == passed.sum()
    assert not every.robust[~passed].any()
    assert np.isnan(every.ratio[~passed]).all()
    # Robust exactly where the centre of mass is close enough to the hand line.
    robust_offsets = np.abs(offsets[every.robust])
    assert robust_offsets.max() < np.abs(offsets[passed & ~every.robust]).min()
    some = robust_pairs(
        points, normals, passed, rng=np.random.default_rng(0), wanted=3,
        mass_properties=PROPS, chunk_size=8,
    )  # fmt: skip
    assert some.counts["evaluated"] < every.counts["evaluated"]
    assert some.counts["robust"] >= 3
    assert not (some.robust & ~every.robust).any()
    again = robust_pairs(
        points, normals, passed, rng=np.random.default_rng(0), wanted=3,
        mass_properties=PROPS, chunk_size=8,
    )  # fmt: skip
    np.testing.assert_array_equal(again.robust, some.robust)


def test_generator_robust_selection_keeps_only_robust_passing_pairs() -> None:
    obj = make_procedural_object("bench", 4)
    common = {"n_grasps": 60, "max_passing": 30, "max_failing": 10}
    paper = generate_object(obj, GenerationParameters(**common), object_file="bench.obj")
    robust = generate_object(
        obj, GenerationParameters(**common, selection="robust"), object_file="bench.obj"
    )
    assert "motion_ratio" not in paper.extras  # the paper's files are unchanged
    assert "selection" not in paper.metadata["parameters"]
    ratio = robust.extras["motion_ratio"]
    assert robust.passing_indices.size > 0
    assert (ratio[robust.passing_indices] <= 1.0).all()
    assert np.isnan(ratio[robust.failed_indices]).all()
    counts = robust.metadata["counts"]
    assert counts["robust_robust"] >= robust.passing_indices.size
    assert robust.metadata["parameters"]["selection"] == "robust"
    # The robust pairs are passing pairs of the paper's check.
    check = evaluate(
        robust.contact_points[robust.passing_indices],
        robust.extras["contact_normals"][robust.passing_indices],
    )
    assert check.passed.all()
    with pytest.raises(GenerationError, match="selection: expected one of"):
        GenerationParameters(selection="best")
    with pytest.raises(GenerationError, match="release convention"):
        GenerationParameters(selection="robust", convention="release")
