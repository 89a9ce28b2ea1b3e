"""DA2's frictionless dual-grasp criterion (:mod:`baselines.da2_labels`): hand-computed cases,
DA2's quirks, validation, and the Fig. 4 statistics."""

from __future__ import annotations

import json

import numpy as np
import pytest
from matplotlib.figure import Figure

from baselines.da2_labels import (
    EPS,
    GEOMETRIC_ZERO,
    DA2LabelError,
    agreement,
    compare_labels,
    da2_criterion,
    da2_labels_for_file,
    dg16m_passed,
    fig4_figure,
    quality_separation,
    roc_auc,
)
from baselines.pairing_baselines import BaselineError
from dataset_gen.io import DualGraspSet

X, Y, Z = np.eye(3)


def box_contacts(a: float, tilt: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Four contacts at +-x, +-y (half-size ``a``) with OUTWARD normals; the first normal is
    turned by ``tilt`` (rad) about z. Shapes (1, 4, 3)."""
    points = np.array([a * X, -a * X, a * Y, -a * Y])
    normals = np.array([X, -X, Y, -Y])
    normals[0] = [np.cos(tilt), -np.sin(tilt), 0.0]
    return points[None], normals[None]


def random_contacts(
    rng: np.random.Generator, n: int, scale: float = 0.2
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random pairs: (n, 4, 3) points (normal, std ``scale`` m) and unit normals."""
    points = rng.normal(scale=scale, size=(n, 4, 3))
    normals = rng.normal(size=(n, 4, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    return points, normals


def direct_grasp_matrix(points: np.ndarray) -> np.ndarray:
    """DA2's x_to_G for one pair, written out: (6, 12), block i = [I; [p_i]x]."""
    G = np.zeros((6, 12))
    for i, p in enumerate(points):
        G[:3, 3 * i : 3 * i + 3] = np.eye(3)
        for j, e in enumerate(np.eye(3)):
            G[3:, 3 * i + j] = np.cross(p, e)  # [p]x e_j
    return G


def test_box_in_plane_hand_computed() -> None:
    # G G^T = diag(4, 4, 4, 2a^2, 2a^2, 4a^2); inward unit forces cancel exactly: l8b = 0.
    a = 0.04
    r = da2_criterion(*box_contacts(a))
    expected = 2 * (EPS - 2 * a * a) ** 2 + (EPS - 4 * a * a) ** 2
    np.testing.assert_allclose(r.l8a, [expected], rtol=1e-9)
    assert r.l8b[0] == 0.0
    assert r.quality[0] == 1.0
    assert not r.passed[0]  # DA2's "0 is not qualified": an exactly balanced pair fails


def test_tilted_normal_hand_computed_and_kept() -> None:
    # l8b = |1 - cos t|^2 + sin^2 t + (a sin t)^2 with the first inward force (-cos t, sin t, 0).
    a, t = 0.04, 0.3
    r = da2_criterion(*box_contacts(a, tilt=t))
    l8b = (1 - np.cos(t)) ** 2 + np.sin(t) ** 2 + (a * np.sin(t)) ** 2
    np.testing.assert_allclose(r.l8b, [l8b], rtol=1e-12)
    np.testing.assert_allclose(r.quality, [1 - l8b], rtol=1e-12)
    assert r.l8a[0] > 0
    assert r.passed[0]


def test_well_conditioned_pair_with_zero_l8a_is_not_kept() -> None:
    # a = 0.1: eigenvalues 4, 4, 4, 0.02, 0.02, 0.04 >= eps, so l8a == 0 exactly and DA2 rejects
    # the pair although l8b is in (0, 1).
    r = da2_criterion(*box_contacts(0.1, tilt=0.3))
    assert r.l8a[0] == 0.0
    assert 0 < r.l8b[0] < 1
    assert not r.passed[0]


def test_degenerate_single_point() -> None:
    # All contacts at p: G G^T has rank 3 with eigenvalues 4(1 + |p|^2) (x2), 4, 0, 0, 0.
    p = np.array([0.03, -0.02, 0.01])
    points = np.tile(p, (1, 4, 1))
    normals = np.array([[X, -X, Y, -Y]])
    r = da2_criterion(points, normals)
    np.testing.assert_allclose(r.l8a, [3 * EPS**2], rtol=1e-9)
    assert r.l8a[0] >= 3 * EPS**2 * (1 - 1e-9)  # the largest possible l8a is 6 eps^2
    assert not r.passed[0]  # balanced forces: l8b = 0
    # ... but with unbalanced normals DA2 keeps a grasp whose four contacts coincide.
    t = 0.5
    normals = np.array([[X, -X, Y, [0.0, -np.cos(t), -np.sin(t)]]])
    r = da2_criterion(points, normals)
    assert 0 < r.l8b[0] < 1
    assert r.passed[0]


def test_l8a_threshold_is_vacuous() -> None:
    rng = np.random.default_rng(0)
    r = da2_criterion(*random_contacts(rng, 500))
    assert (r.l8a <= 6 * EPS**2 * (1 + 1e-9)).all()


def test_lambda_min_bound_for_parallel_jaw_pairs() -> None:
    # lambda_min(G G^T) <= sum_i d_i^2 <= w^2 (d_i: distance to the line joining the grasp
    # centres): a dual grasp with contact separations <= 0.08 m always has 0 < l8a < 0.01.
    rng = np.random.default_rng(1)
    n = 300
    centres = rng.normal(scale=0.3, size=(n, 2, 3))
    axes = rng.normal(size=(n, 2, 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    half = rng.uniform(0.001, 0.04, size=(n, 2, 1))
    ends = [centres[:, k] + sign * half[:, k] * axes[:, k] for k in (0, 1) for sign in (1, -1)]
    points = np.stack(ends, axis=1)
    _, normals = random_contacts(rng, n)
    r = da2_criterion(points, normals, center=rng.normal(size=3))
    assert (r.l8a > 0).all()
    assert (r.l8a < 0.01).all()


def test_eigenvalues_and_l8b_against_direct_construction() -> None:
    rng = np.random.default_rng(2)
    points, normals = random_contacts(rng, 1)
    r = da2_criterion(points, normals, normals="inward")
    G = direct_grasp_matrix(points[0])
    assert G.shape == (6, 12)
    lam = np.linalg.eigvalsh(G @ G.T)
    np.testing.assert_allclose(r.l8a, [np.sum(np.maximum(EPS - lam, 0.0) ** 2)], rtol=1e-9)
    wrench = G @ normals[0].reshape(12)
    np.testing.assert_allclose(r.l8b, [wrench @ wrench], rtol=1e-12)
    # G^T G (12 x 12) would add six zero eigenvalues: DA2 uses the 6 x 6 G G^T.
    assert np.linalg.eigvalsh(G.T @ G)[:6].max() < 1e-12


def test_outward_and_inward_agree_when_flipped() -> None:
    rng = np.random.default_rng(3)
    points, normals = random_contacts(rng, 50)
    out = da2_criterion(points, normals, normals="outward")
    inw = da2_criterion(points, -normals, normals="inward")
    same = da2_criterion(points, normals, normals="inward")  # sign-blind by construction
    for r in (inw, same):
        np.testing.assert_array_equal(r.l8a, out.l8a)
        np.testing.assert_allclose(r.l8b, out.l8b, rtol=1e-12)
        np.testing.assert_array_equal(r.passed, out.passed)


def test_translation_dependence() -> None:
    rng = np.random.default_rng(4)
    points, normals = random_contacts(rng, 20, scale=0.03)  # small spread: l8a > 0
    shift = np.array([0.3, -0.2, 0.5])
    base = da2_criterion(points, normals)
    moved = da2_criterion(points + shift, normals, center=shift)  # points and centre together
    np.testing.assert_allclose(moved.l8a, base.l8a, rtol=1e-6, atol=1e-15)
    np.testing.assert_allclose(moved.l8b, base.l8b, rtol=1e-9)
    # Not invariant when only the points move: torques (and G G^T) change with the origin.
    only = da2_criterion(points + shift, normals)
    assert not np.allclose(only.l8b, base.l8b)
    assert (base.l8a > 0).all()
    assert not np.allclose(only.l8a, base.l8a)


def test_zero_tol_rejects_rounding_level_balance() -> None:
    points, normals = box_contacts(0.04)
    normals = normals.copy()
    normals[0, 0] = [1.0, 1e-9, 0.0]  # parallel up to 1e-9: l8b ~ 1e-18
    normals[0, 0] /= np.linalg.norm(normals[0, 0])
    verbatim = da2_criterion(points, normals)
    tolerant = da2_criterion(points, normals, zero_tol=GEOMETRIC_ZERO)
    assert 0 < verbatim.l8b[0] < GEOMETRIC_ZERO
    assert verbatim.passed[0]
    assert not tolerant.passed[0]
    with pytest.raises(DA2LabelError, match="zero_tol"):
        da2_criterion(points, normals, zero_tol=0.5)


def test_empty_input() -> None:
    r = da2_criterion(np.zeros((0, 4, 3)), np.zeros((0, 4, 3)))
    assert r.n == 0
    assert r.passed.dtype == bool


@pytest.mark.parametrize(
    ("points", "normals", "kwargs", "match"),
    [
        (
            np.zeros((2, 3, 3)),
            np.zeros((2, 3, 3)),
            {},
            r"contact_points: expected shape \(N, 4, 3\)",
        ),
        (np.zeros((2, 4, 3)), np.tile(X, (3, 4, 1)), {}, "expected the shape of contact_points"),
        (np.full((1, 4, 3), np.nan), np.tile(X, (1, 4, 1)), {}, "expected finite values"),
        (np.zeros((1, 4, 3)), np.tile(2 * X, (1, 4, 1)), {}, "expected unit vectors"),
        (np.zeros((1, 4, 3)), np.tile(X, (1, 4, 1)), {"normals": "up"}, "normals: expected"),
        (np.zeros((1, 4, 3)), np.tile(X, (1, 4, 1)), {"eps": -1.0}, "eps: expected"),
        (np.zeros((1, 4, 3)), np.tile(X, (1, 4, 1)), {"center": [0, 0]}, "center: expected"),
        ("abc", np.tile(X, (1, 4, 1)), {}, "contact_points: expected a numeric"),
    ],
)
def test_bad_input_refused(points, normals, kwargs, match) -> None:
    with pytest.raises(DA2LabelError, match=match) as info:
        da2_criterion(points, normals, **kwargs)
    assert isinstance(info.value, BaselineError)


def make_set(n: int, normals: bool = True) -> DualGraspSet:
    rng = np.random.default_rng(5)
    points, nrm = random_contacts(rng, n)
    extras = {"contact_normals": nrm, "quality": rng.uniform(size=n)} if normals else {}
    return DualGraspSet(
        grasps=np.tile(np.eye(4), (n, 2, 1, 1)),
        contact_points=points,
        contact_forces=np.zeros((n, 4, 3)),
        loss_values=np.zeros(n),
        passing_indices=np.arange(0, n, 2),
        failed_indices=np.arange(1, n, 2),
        object_file="toy.obj",
        object_scale=1.0,
        extras=extras,
    )


def test_labels_for_file() -> None:
    data = make_set(6)
    r = da2_labels_for_file(data)
    direct = da2_criterion(data.contact_points, data.extras["contact_normals"])
    np.testing.assert_array_equal(r.l8b, direct.l8b)
    np.testing.assert_array_equal(dg16m_passed(data), [True, False] * 3)
    with pytest.raises(DA2LabelError, match="contact_normals"):
        da2_labels_for_file(make_set(4, normals=False))


def test_auc_toy() -> None:
    passed = np.array([True, True, False, False])
    assert roc_auc(np.array([3.0, 4.0, 1.0, 2.0]), passed) == 1.0
    assert roc_auc(np.array([1.0, 2.0, 3.0, 4.0]), passed) == 0.0
    assert roc_auc(np.ones(4), passed) == 0.5
    assert roc_auc(np.array([2.0, 1.0, 1.0, 0.0]), passed) == 0.875  # one tie counts half
    assert roc_auc(np.ones(3), np.ones(3, dtype=bool)) is None


def test_quality_separation_json_ready() -> None:
    q = np.array([0.9, 0.8, 0.1, 0.2, 0.3])
    s = quality_separation(q, np.array([1, 1, 0, 0, 0]))
    assert s["auc"] == 1.0
    assert s["passed"]["count"] == 2
    assert s["failed"]["median"] == pytest.approx(0.2)
    json.dumps(s)
    empty = quality_separation(q, np.zeros(5, dtype=bool))
    assert empty["auc"] is None
    assert empty["passed"]["mean"] is None
    with pytest.raises(DA2LabelError, match="quality: expected finite"):
        quality_separation(np.array([np.nan, 1.0]), np.array([True, False]))
    with pytest.raises(DA2LabelError, match=r"expected shape \(2,\)"):
        quality_separation(np.ones(3), np.array([True, False]))


def test_agreement_and_kappa() -> None:
    ours = np.array([1, 1, 1, 0, 0, 0, 0, 0], dtype=bool)
    da2 = np.array([1, 1, 0, 1, 0, 0, 0, 0], dtype=bool)
    a = agreement(ours, da2)
    assert (a["both_pass"], a["ours_only"], a["da2_only"], a["both_fail"]) == (2, 1, 1, 4)
    assert a["agreement"] == 0.75
    pe = (3 / 8) ** 2 + (5 / 8) ** 2
    assert a["kappa"] == pytest.approx((0.75 - pe) / (1 - pe))
    assert agreement(ours, ours)["kappa"] == pytest.approx(1.0)
    assert agreement(np.ones(3, bool), np.ones(3, bool))["kappa"] is None
    json.dumps(a)


def test_compare_labels() -> None:
    rng = np.random.default_rng(6)
    r = da2_criterion(*random_contacts(rng, 40))
    ours = rng.uniform(size=40) > 0.5
    out = compare_labels(ours, rng.uniform(size=40), r, p=rng.uniform(size=40))
    assert out["agreement"]["n"] == 40
    assert set(out["p"]) >= {"da2_pass", "da2_fail", "ours_pass", "ours_fail"}
    json.dumps(out)


def test_fig4_figure() -> None:
    rng = np.random.default_rng(7)
    q = rng.normal(size=200)
    passed = q > 0
    fig = fig4_figure((q, passed), (rng.normal(size=100), rng.uniform(size=100) > 0.5))
    assert isinstance(fig, Figure)
    assert len(fig.axes) == 2
    assert "AUC = 1.000" in fig.axes[0].get_title()
    one_class = fig4_figure((q, np.ones(200, bool)), (np.ones(5), np.zeros(5, bool)))
    assert "n/a" in one_class.axes[1].get_title()
