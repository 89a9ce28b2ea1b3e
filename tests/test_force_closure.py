"""Force closure: hand-made physical cases, conventions, rank test, fast vs Clarabel, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from dataset_gen.force_closure import (
    SOLVED_CLARABEL,
    SOLVED_CLARABEL_TIGHT,
    SOLVED_FAST,
    SOLVED_NONE,
    axis_gravity_wrenches,
    contact_frames,
    evaluate,
    full_rank,
    grasp_matrix,
    grasp_quality,
    project_cone_ball,
)
from dataset_gen.force_closure.synthetic import FAMILIES, family_pairs
from dg16m_core.errors import ForceClosureError, SolverError
from dg16m_core.parameters import PAPER

METHODS = ["fast", "clarabel"]
UP = np.array([0.0, 0.0, 60.0])


def mixed_pairs(per_family: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``per_family`` pairs of every synthetic family, concatenated."""
    rng = np.random.default_rng(seed)
    parts = [family_pairs(family, per_family, rng) for family in FAMILIES]
    return np.concatenate([p for p, _ in parts]), np.concatenate([n for _, n in parts])


def pinch_path(steps: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``steps`` pairs on the straight path from a passing box pinch to a failing one: their
    losses run continuously from 0 to far above the threshold."""
    points, normals = family_pairs("box", 200, np.random.default_rng(seed))
    result = evaluate(points, normals, loss_rtol=None)
    good = int(np.flatnonzero(result.passed)[0])
    bad = int(np.flatnonzero(result.rank_ok & (result.loss_lower[:, 0] > 1.0))[0])
    t = np.linspace(0.0, 1.0, steps)[:, None, None]
    p = (1 - t) * points[good] + t * points[bad]
    n = (1 - t) * normals[good] + t * normals[bad]
    return p, n / np.linalg.norm(n, axis=-1, keepdims=True)


def plank_squeeze() -> tuple[np.ndarray, np.ndarray]:
    """A 0.6 m plank; each arm squeezes its two side faces (y = +-0.05) near one end."""
    points = np.array([[[-0.25, 0.05, 0], [-0.25, -0.05, 0], [0.25, 0.05, 0], [0.25, -0.05, 0]]])
    normals = np.array([[[0, 1, 0], [0, -1, 0], [0, 1, 0], [0, -1, 0]]], dtype=float)
    return points.astype(float), normals


def face_contacts(z: float) -> tuple[np.ndarray, np.ndarray]:
    """Four fingertips on the horizontal face at height z (outward normal sign(z) * +z)."""
    xy = [(0.03, 0.03), (-0.03, 0.03), (0.03, -0.03), (-0.03, -0.03)]
    points = np.array([[[x, y, z] for x, y in xy]])
    normals = np.tile([0.0, 0.0, np.sign(z)], (1, 4, 1))
    return points, normals


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("convention", ["physical", "release"])
def test_plank_squeezed_at_both_ends_holds(method: str, convention: str) -> None:
    points, normals = plank_squeeze()
    result = evaluate(points, normals, method=method, convention=convention)
    assert result.rank_ok[0]
    assert result.passed[0]
    assert result.loss[0] <= 1e-5
    forces = result.forces[0]
    assert np.allclose(forces.sum(axis=0), UP, atol=1e-4)  # contacts carry the weight
    assert np.allclose(np.cross(points[0], forces).sum(axis=0), 0.0, atol=1e-4)
    assert np.all(np.linalg.norm(forces, axis=1) <= 70.0 + 1e-6)


@pytest.mark.parametrize("method", METHODS)
def test_all_contacts_on_one_side_cannot_hold(method: str) -> None:
    points, normals = plank_squeeze()
    points[0, :, 1] = 0.05  # all four on the +y face, spread over it
    points[0, :, 2] = [0.02, -0.02, 0.02, -0.02]
    normals[0] = [0.0, 1.0, 0.0]
    for convention in ("physical", "release"):
        result = evaluate(points, normals, method=method, convention=convention)
        assert result.rank_ok[0]
        assert not result.passed[0]
        assert result.loss[0] > 1.0


@pytest.mark.parametrize("method", METHODS)
def test_forces_push_in_physical_and_pull_in_release(method: str) -> None:
    bottom_p, bottom_n = face_contacts(-0.05)
    top_p, top_n = face_contacts(0.05)
    physical_bottom = evaluate(bottom_p, bottom_n, method=method)
    release_bottom = evaluate(bottom_p, bottom_n, method=method, convention="release")
    physical_top = evaluate(top_p, top_n, method=method)
    release_top = evaluate(top_p, top_n, method=method, convention="release")
    # Resting on four fingertips holds physically; the release's pulling cones cannot.
    assert physical_bottom.passed[0]
    assert not release_bottom.passed[0]
    assert release_bottom.loss[0] == pytest.approx(60.0, abs=1e-4)
    # On the top face it is the other way round: the release "lifts" by pulling.
    assert release_top.passed[0]
    assert not physical_top.passed[0]
    assert physical_top.loss[0] == pytest.approx(60.0, abs=1e-4)
    # Push: force opposes the outward normal; pull: along it.
    assert np.all(np.einsum("kj,kj->k", physical_bottom.forces[0], bottom_n[0]) < -1.0)
    assert np.all(np.einsum("kj,kj->k", release_top.forces[0], top_n[0]) > 1.0)
    assert np.allclose(physical_bottom.forces[0], [0, 0, 15.0], atol=1e-3)


def test_plank_forces_push_inward_in_physical_and_pull_in_release() -> None:
    points, normals = plank_squeeze()
    for convention, sign in (("physical", -1.0), ("release", 1.0)):
        forces = evaluate(points, normals, convention=convention, method="clarabel").forces[0]
        normal_parts = np.einsum("kj,kj->k", forces, normals[0])
        assert np.all(sign * normal_parts >= -1e-6), (convention, normal_parts)
        assert np.any(sign * normal_parts > 1.0)


@pytest.mark.parametrize("method", METHODS)
def test_collinear_contacts_fail_the_rank_test(method: str) -> None:
    points = np.array([[[-0.2, 0, 0], [-0.1, 0, 0], [0.1, 0, 0], [0.2, 0, 0]]], dtype=float)
    normals = np.array([[[0, 0, 1], [0, 0, -1], [0, 1, 0], [0, -1, 0]]], dtype=float)
    result = evaluate(points, normals, method=method)
    assert not result.rank_ok[0]
    assert not result.passed[0]
    assert np.isnan(result.loss[0])
    assert result.solved_by[0, 0] == SOLVED_NONE
    assert result.quality[0] == pytest.approx(0.0, abs=1e-6)


def test_rank_test_equals_numpy_matrix_rank_on_near_collinear_contacts() -> None:
    rng = np.random.default_rng(7)
    points, normals = family_pairs("near_collinear", 3000, rng)
    expected = np.linalg.matrix_rank(grasp_matrix(points, normals)) == 6
    assert 0 < expected.sum() < expected.size  # both outcomes occur
    assert np.array_equal(full_rank(points, normals), expected)
    fast = evaluate(points, normals, method="fast", loss_rtol=None)
    assert np.array_equal(fast.rank_ok, expected)


def test_grasp_matrix_and_quality() -> None:
    rng = np.random.default_rng(3)
    points, normals = family_pairs("box", 50, rng)
    G = grasp_matrix(points, normals)
    assert G.shape == (50, 6, 12)
    R = contact_frames(normals)
    assert np.allclose(R[..., 2], normals)
    assert np.allclose(np.swapaxes(R, -1, -2) @ R, np.eye(3), atol=1e-12)
    expected = np.sqrt(np.linalg.det(G @ np.swapaxes(G, 1, 2)))
    assert np.allclose(grasp_quality(points), expected, rtol=1e-9)
    result = evaluate(points, normals, loss_rtol=None)
    assert np.allclose(result.quality, expected, rtol=1e-9)


def test_projection_onto_cone_and_ball() -> None:
    rng = np.random.default_rng(11)
    forces = rng.normal(scale=100.0, size=(2000, 3))
    axes = rng.normal(size=(2000, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    projected = project_cone_ball(forces, axes, 0.4, 70.0)
    normal = np.einsum("ij,ij->i", projected, axes)
    tangent = np.linalg.norm(projected - normal[:, None] * axes, axis=1)
    assert np.all(tangent <= 0.4 * normal + 1e-9)
    assert np.all(np.linalg.norm(projected, axis=1) <= 70.0 + 1e-9)
    # A projection is idempotent and no farther than any other feasible point (sampled).
    assert np.allclose(project_cone_ball(projected, axes, 0.4, 70.0), projected)
    candidates = project_cone_ball(rng.normal(scale=50.0, size=(2000, 3)), axes, 0.4, 70.0)
    assert np.all(
        np.linalg.norm(forces - projected, axis=1)
        <= np.linalg.norm(forces - candidates, axis=1) + 1e-9
    )


@pytest.mark.parametrize("convention", ["physical", "release"])
def test_fast_and_clarabel_agree_on_random_pairs(convention: str) -> None:
    points, normals = mixed_pairs(500, 2024)
    fast = evaluate(points, normals, convention=convention, method="fast")
    reference = evaluate(points, normals, convention=convention, method="clarabel")
    assert 0.05 < fast.passed.mean() < 0.95  # a mix of outcomes, not a trivial set
    assert np.array_equal(fast.rank_ok, reference.rank_ok)
    assert np.array_equal(fast.passed, reference.passed)
    assert (fast.solved_by == SOLVED_FAST).mean() > 0.8
    failing = reference.rank_ok & ~reference.passed
    # Exact-loss mode: failing losses agree with the interior-point optimum.
    rel = np.abs(fast.loss[failing] - reference.loss[failing]) / reference.loss[failing]
    assert np.max(rel) < 2e-3
    # Verdict-only mode: same verdicts; the loss is an upper bound above a proven lower bound.
    quick = evaluate(points, normals, convention=convention, method="fast", loss_rtol=None)
    assert np.array_equal(quick.passed, reference.passed)
    certified = (quick.solved_by[:, 0] == SOLVED_FAST) & failing
    assert np.all(quick.loss[certified] >= reference.loss[certified] * (1 - 1e-6))
    assert np.all(quick.loss_lower[certified, 0] <= reference.loss[certified] * (1 + 1e-6))
    assert np.all(quick.loss_lower[certified, 0] > 1e-5)
    assert not quick.loss_converged[certified].any()
    assert fast.loss_converged[fast.rank_ok].all()


def test_passing_forces_are_feasible_and_cancel_gravity() -> None:
    rng = np.random.default_rng(5)
    points, normals = family_pairs("sphere", 400, rng)
    for method in METHODS:
        result = evaluate(points, normals, method=method)
        forces = result.forces[result.passed]
        axes = -normals[result.passed]
        normal = np.einsum("nkj,nkj->nk", forces, axes)
        tangent = np.linalg.norm(forces - normal[..., None] * axes, axis=-1)
        assert np.all(tangent <= 0.4 * normal + 1e-7)
        assert np.all(np.linalg.norm(forces, axis=-1) <= 70.0 + 1e-7)
        assert np.allclose(forces.sum(axis=1), UP, atol=2e-5)


def test_axis_gravity_robustness_is_stricter() -> None:
    bottom_p, bottom_n = face_contacts(-0.05)
    plank_p, plank_n = plank_squeeze()
    points = np.concatenate([bottom_p, plank_p])
    normals = np.concatenate([bottom_n, plank_n])
    for method in METHODS:
        plain = evaluate(points, normals, method=method)
        robust = evaluate(points, normals, method=method, wrenches="axis_gravity")
        assert plain.passed.tolist() == [True, True]
        # Resting on fingertips cannot resist the weight pulling up; squeezing the plank can
        # only resist 60 N along its sides' normal (y) up to 70 N, so it holds every direction.
        assert robust.passed.tolist() == [False, True]
        assert robust.losses.shape == (2, 6)
        assert robust.losses[0, 1] == pytest.approx(60.0, abs=1e-4)  # +z pull on resting box
        assert np.allclose(robust.wrenches, axis_gravity_wrenches())
        assert robust.contact_forces.shape == (2, 6, 4, 3)


def test_results_are_deterministic() -> None:
    rng = np.random.default_rng(1)
    points, normals = family_pairs("box", 300, rng)
    a = evaluate(points, normals)
    b = evaluate(points, normals)
    for name in ("loss", "losses", "contact_forces", "quality"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes()
    assert np.array_equal(a.passed, b.passed)


def test_empty_input() -> None:
    result = evaluate(np.zeros((0, 4, 3)), np.ones((0, 4, 3)))
    assert result.n == 0
    assert result.contact_forces.shape == (0, 1, 4, 3)


@pytest.mark.parametrize(
    ("points", "normals", "match"),
    [
        (np.zeros((3, 4)), np.ones((3, 4)), r"expected shape \(N, 4, 3\).*found \(3, 4\)"),
        (np.zeros((2, 3, 3)), np.ones((2, 3, 3)), r"found \(2, 3, 3\)"),
        (np.zeros((2, 4, 3)), np.ones((3, 4, 3)), "one set per pair"),
        (np.full((1, 4, 3), np.nan), np.ones((1, 4, 3)), "NaN or inf.*pair 0"),
        (np.zeros((1, 4, 3)), np.full((1, 4, 3), np.inf), "contact_normals.*NaN or inf"),
        (np.zeros((2, 4, 3)), np.r_[np.ones((1, 4, 3)), np.zeros((1, 4, 3))], "pair 1 contact 0"),
        ("not numbers", np.ones((1, 4, 3)), "numeric array"),
    ],
)
def test_bad_input_gives_clear_errors(points: object, normals: object, match: str) -> None:
    with pytest.raises(ForceClosureError, match=match):
        evaluate(points, normals)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"mu": -0.1}, "mu: expected a finite number >= 0"),
        ({"f_high": 0.0}, "f_high: expected a positive finite number, found 0.0"),
        ({"threshold": float("nan")}, "threshold"),
        ({"convention": "outward"}, "convention: expected one of"),
        ({"method": "cvxpy"}, "method: expected one of"),
        ({"wrenches": np.zeros((2, 5))}, r"wrenches: expected shape \(K, 6\)"),
        ({"wrenches": "sideways"}, "wrenches: expected None"),
    ],
)
def test_bad_parameters_give_clear_errors(kwargs: dict, match: str) -> None:
    points, normals = plank_squeeze()
    with pytest.raises(ForceClosureError, match=match):
        evaluate(points, normals, **kwargs)


def test_failed_clarabel_solve_raises(monkeypatch: pytest.MonkeyPatch) -> None:
    import clarabel

    from dataset_gen.force_closure import clarabel_solver

    class Stopped:
        status = clarabel.SolverStatus.MaxIterations
        iterations = 200
        x = [0.0] * 13
        z = [0.0] * 35

    class FakeSolver:
        def __init__(self, *args: object) -> None:
            pass

        def solve(self) -> Stopped:
            return Stopped()

    monkeypatch.setattr(clarabel_solver.clarabel, "DefaultSolver", FakeSolver)
    points, normals = plank_squeeze()
    with pytest.raises(SolverError, match="expected status Solved or AlmostSolved, found"):
        evaluate(points, normals, method="clarabel")
    # A tight re-solve only sharpens a solve that succeeded: its failures are no error, and the
    # bounds it returns (zero forces: loss 60) are still valid.
    axes, wrench = -normals, PAPER.gravity_wrench()[None]
    batch = clarabel_solver.solve_batch(points, axes, wrench, mu=0.4, f_high=70.0, tight=True)
    assert batch.statuses[0].startswith("unconverged: ")
    assert batch.losses[0] == pytest.approx(60.0)
    assert batch.lower[0] <= 60.0


def test_solved_by_reports_the_fallback() -> None:
    rng = np.random.default_rng(9)
    points, normals = family_pairs("box", 200, rng)
    result = evaluate(points, normals, method="fast", max_iterations=1)
    # With a one-iteration budget most passes cannot be certified and go to Clarabel.
    assert (result.solved_by == SOLVED_CLARABEL).any()
    reference = evaluate(points, normals, method="clarabel")
    assert np.array_equal(result.passed, reference.passed)
    assert 0.0 < result.fallback_fraction <= 1.0


@pytest.mark.slow
@pytest.mark.parametrize("convention", ["physical", "release"])
def test_fast_matches_clarabel_on_many_pairs(convention: str) -> None:
    points, normals = mixed_pairs(5000, 99)
    quick = evaluate(points, normals, convention=convention, loss_rtol=None)
    reference = evaluate(points, normals, convention=convention, method="clarabel")
    assert np.array_equal(quick.passed, reference.passed)
    assert quick.fallback_fraction < 0.02
    assert quick.verdict_proven.all()


def test_defaults_are_the_papers_parameters() -> None:
    import inspect

    defaults = inspect.signature(evaluate).parameters
    for name in ("mass", "gravity", "mu", "f_high", "threshold"):
        assert defaults[name].default == getattr(PAPER, name)
    points, normals = plank_squeeze()
    result = evaluate(points, normals)
    for name in ("mass", "gravity", "mu", "f_high", "threshold"):
        assert result.parameters[name] == getattr(PAPER, name)
    assert np.array_equal(result.wrenches[0], PAPER.gravity_wrench())


@pytest.mark.parametrize("convention", ["physical", "release"])
def test_lower_bounds_are_proven_by_every_method(convention: str) -> None:
    """A lower bound from one solver never exceeds a loss attained by the other (L lies between)."""
    points, normals = mixed_pairs(300, 17)
    fast = evaluate(points, normals, convention=convention, method="fast", loss_rtol=None)
    clarabel = evaluate(points, normals, convention=convention, method="clarabel")
    solved = clarabel.rank_ok
    for a, b in ((fast, clarabel), (clarabel, fast)):
        assert np.all(np.isfinite(a.loss_lower[solved]))
        assert np.all(a.loss_lower[solved] >= 0.0)
        assert np.all(a.loss_lower[solved] <= b.losses[solved] * (1 + 1e-9) + 1e-12)
        assert np.all(np.isnan(a.loss_lower[~solved]))
    # Clarabel's dual bound is close to its attained loss: measured within 1.3e-6 relative.
    failing = solved & ~clarabel.passed
    gap = clarabel.losses[failing, 0] - clarabel.loss_lower[failing, 0]
    assert np.all(gap <= 1e-5 * clarabel.losses[failing, 0] + 1e-7)
    # Every verdict here is proven; failures by a lower bound above the threshold.
    for result in (fast, clarabel):
        assert result.verdict_proven.all()
        fails = result.rank_ok & ~result.passed
        assert np.all(result.pair_loss_lower[fails] > PAPER.threshold)
        assert np.all(result.pair_loss_lower[~result.rank_ok] == 0.0)


def test_straddling_bounds_are_solved_again_tightly(monkeypatch: pytest.MonkeyPatch) -> None:
    """With loose first solves, pairs whose bounds straddle the threshold are re-solved at tight
    tolerances: verdicts then match default-tolerance solves wherever those are proven."""
    from dataset_gen.force_closure import clarabel_solver

    points, normals = pinch_path(400, 4)
    reference = evaluate(points, normals, method="clarabel")
    near = np.abs(reference.loss / PAPER.threshold - 1.0) < 1.0
    assert near.sum() >= 3  # the path crosses the threshold with a few pairs close to it
    loose = {"tol_gap_abs": 1e-4, "tol_gap_rel": 1e-4, "tol_feas": 1e-4}
    retries = tuple({**loose, **changes} for changes in clarabel_solver.RETRY_SETTINGS)
    monkeypatch.setattr(clarabel_solver, "RETRY_SETTINGS", retries)
    loose_batch = clarabel_solver.solve_batch(
        points, -normals, np.tile(PAPER.gravity_wrench(), (len(points), 1)), mu=0.4, f_high=70.0
    )
    straddled = (loose_batch.losses > PAPER.threshold) & ~(loose_batch.lower > PAPER.threshold)
    assert straddled.any()
    result = evaluate(points, normals, method="clarabel")
    tight = result.solved_by[:, 0] == SOLVED_CLARABEL_TIGHT
    assert np.array_equal(tight, straddled)
    assert result.fallback_fraction == 1.0
    proven = result.verdict_proven & reference.verdict_proven
    assert proven.mean() > 0.95
    assert np.array_equal(result.passed[proven], reference.passed[proven])
    # A tight re-solve never makes a bound worse than the loose solve's.
    assert np.all(result.losses[tight, 0] <= loose_batch.losses[tight] * (1 + 1e-12))
    assert np.all(result.loss_lower[tight, 0] >= loose_batch.lower[tight] - 1e-15)


def test_settings_reproduce_a_result() -> None:
    points, normals = mixed_pairs(50, 8)
    first = evaluate(points, normals, convention="release", wrenches="axis_gravity", mu=0.5)
    again = evaluate(points[:20], normals[:20], **first.settings())
    assert again.parameters == {**first.parameters, "method": again.parameters["method"]}
    assert np.array_equal(again.passed, first.passed[:20])
    assert np.array_equal(again.wrenches, first.wrenches)


def test_numpy_scalars_are_accepted_and_bools_rejected() -> None:
    points, normals = plank_squeeze()
    result = evaluate(points, normals, mu=np.float32(0.4), max_iterations=np.int64(50))
    assert result.passed[0]
    with pytest.raises(ForceClosureError, match="mass: expected a positive finite number"):
        evaluate(points, normals, mass=True)
    with pytest.raises(ForceClosureError, match="chunk_size: expected an integer >= 1, found 0"):
        evaluate(points, normals, chunk_size=0)


def test_best_of_keeps_the_lower_loss_and_the_higher_bound() -> None:
    from dataset_gen.force_closure.clarabel_solver import ClarabelBatch, best_of

    forces = np.arange(3 * 12, dtype=float).reshape(3, 4, 3)
    first = ClarabelBatch(forces, np.array([2.0, 1.0, 1.0]), np.array([0.5, 0.9, 0.9]), ["a"] * 3)
    second = ClarabelBatch(
        -forces, np.array([1.0, 2.0, np.nan]), np.array([0.7, np.nan, 0.2]), ["b"] * 3
    )
    best = best_of(first, second)
    assert best.losses.tolist() == [1.0, 1.0, 1.0]
    assert best.lower.tolist() == [0.7, 0.9, 0.9]
    assert np.array_equal(best.forces, np.stack([-forces[0], forces[1], forces[2]]))
    assert best.statuses == ["b"] * 3
