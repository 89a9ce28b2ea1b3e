"""The torch grasp-pair classifiers (Dual-PointNetGPD, CGDF) and their shared geometry:
shapes, determinism, hand symmetry, translation / rotation invariance, learning, checkpoints,
input errors."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from baselines.cgdf_classifier import CGDFClassifier, CGDFConfig  # noqa: E402
from baselines.dual_pointnet_gpd import DualPointNetGPD, DualPointNetGPDConfig  # noqa: E402
from baselines.grasp_geometry import (  # noqa: E402
    ClassifierModelError,
    count_parameters,
    grasp_centre_local,
    gripper_template,
    grouped_knn,
    knn,
    load_checkpoint,
    save_checkpoint,
)
from dataset_gen.grasps.gripper import PANDA  # noqa: E402
from dg16m_core.errors import Dg16mError  # noqa: E402

# Small configurations: the tests check properties, not accuracy.
SMALL_GPD = DualPointNetGPDConfig(
    points_per_hand=16, point_widths=(8, 16), hand_widths=(16,), head_widths=(8,)
)
SMALL_CGDF = CGDFConfig(
    n_anchors=32,
    edge_k=8,
    encoder_channels=(8, 8, 8),
    feature_channels=8,
    invariant_channels=4,
    field_candidates=12,
    hand_widths=(16,),
    head_widths=(8,),
)
MODELS = {"gpd": (DualPointNetGPD, SMALL_GPD), "cgdf": (CGDFClassifier, SMALL_CGDF)}


@pytest.fixture(autouse=True)
def _one_thread() -> Any:
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


def build(key: str, **changes: Any) -> torch.nn.Module:
    cls, config = MODELS[key]
    return cls(dataclasses.replace(config, **changes))


def random_rotations(n: int, generator: torch.Generator, dtype: torch.dtype) -> torch.Tensor:
    """(n, 3, 3) random rotations (QR of Gaussian matrices, det +1)."""
    q, r = torch.linalg.qr(torch.randn(n, 3, 3, generator=generator, dtype=torch.float64))
    q = q * torch.sign(torch.diagonal(r, dim1=-2, dim2=-1))[..., None, :]
    q[torch.det(q) < 0, :, 0] *= -1.0
    return q.to(dtype)


def make_object(
    generator: torch.Generator, n_points: int, dtype: torch.dtype = torch.float32
) -> torch.Tensor:
    """(P, 3) points on an ellipsoid (semi-axes 0.15-0.5 m) centred away from the origin."""
    axes = 0.15 + 0.35 * torch.rand(3, generator=generator, dtype=torch.float64)
    direction = torch.randn(n_points, 3, generator=generator, dtype=torch.float64)
    direction = direction / direction.norm(dim=1, keepdim=True)
    centre = torch.tensor([0.4, -0.2, 0.7], dtype=torch.float64)
    return (direction * axes + centre).to(dtype)


def make_poses(generator: torch.Generator, points: torch.Tensor, n: int) -> torch.Tensor:
    """(n, 2, 4, 4) dual grasps whose grasp centres sit near random surface points."""
    dtype = points.dtype
    rot = random_rotations(2 * n, generator, dtype).reshape(n, 2, 3, 3)
    pick = torch.randint(len(points), (n, 2), generator=generator)
    jitter = 0.01 * torch.randn(n, 2, 3, generator=generator, dtype=torch.float64).to(dtype)
    centre = points[pick] + jitter
    local = torch.as_tensor(grasp_centre_local(), dtype=dtype)
    poses = torch.zeros(n, 2, 4, 4, dtype=dtype)
    poses[..., :3, :3] = rot
    poses[..., :3, 3] = centre - rot @ local
    poses[..., 3, 3] = 1.0
    return poses


def rotate_about(
    rotation: torch.Tensor, pivot: torch.Tensor, points: torch.Tensor, poses: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Rotate the object and its grasps together by ``rotation`` about ``pivot``."""
    points = (points - pivot) @ rotation.T + pivot
    moved = poses.clone()
    moved[..., :3, :3] = rotation @ poses[..., :3, :3]
    moved[..., :3, 3] = (poses[..., :3, 3] - pivot) @ rotation.T + pivot
    return points, moved


def scene(seed: int = 0, n_points: int = 256, n: int = 12, dtype: Any = torch.float32) -> tuple:
    g = torch.Generator().manual_seed(seed)
    points = make_object(g, n_points, dtype)
    return points, make_poses(g, points, n)


# --------------------------------------------------------------------------------------------
# Geometry helpers
# --------------------------------------------------------------------------------------------


def test_template_is_built_from_the_panda_geometry() -> None:
    template = gripper_template("panda")
    assert template.shape == (22, 3)
    xs = np.unique(np.round(np.abs(template[:, 0]), 6))
    half = PANDA.max_opening / 2.0
    for x in (half, half + PANDA.finger_thickness, PANDA.palm_half_extents[0]):
        assert np.isclose(xs, x).any()
    assert np.isclose(template[:, 1].max(), PANDA.finger_tip)
    # the open Panda hand is symmetric under a half turn about the approach axis
    flipped = template * np.array([-1.0, 1.0, -1.0])
    distances = np.linalg.norm(flipped[:, None] - template[None], axis=-1).min(axis=1)
    assert distances.max() < 1e-12
    assert np.allclose(grasp_centre_local(), [0.0, PANDA.contact_depth, 0.0])


def test_grouped_knn_equals_brute_force_knn() -> None:
    g = torch.Generator().manual_seed(3)
    points = torch.randn(2, 200, 3, generator=g, dtype=torch.float64)
    centres = torch.randn(2, 30, 1, 3, generator=g, dtype=torch.float64) * 1.5
    centres[:, :5] *= 6.0  # far groups: the certificate fails and the fallback runs
    queries = centres + 0.3 * torch.randn(2, 30, 7, 3, generator=g, dtype=torch.float64)
    index, distance = grouped_knn(queries, points, 5, candidates=20)
    expected_index, expected_distance = knn(queries.reshape(2, -1, 3), points, 5)
    assert torch.equal(index.reshape(2, -1, 5), expected_index)
    assert torch.allclose(distance.reshape(2, -1, 5), expected_distance, atol=1e-12)


# --------------------------------------------------------------------------------------------
# Both models
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("cls", [DualPointNetGPD, CGDFClassifier])
def test_default_models_give_shapes(cls: type) -> None:
    points, poses = scene(n_points=512, n=5)
    model = cls().eval()
    assert isinstance(model.name, str)
    assert count_parameters(model) > 1000
    with torch.no_grad():
        out = model(points, poses)
        assert out.shape == (5,)
        assert out.dtype == torch.float32
        batch = model.forward_batch(
            torch.stack([points, points + 1.0]), poses[None].repeat(2, 1, 1, 1, 1)
        )
        assert batch.shape == (2, 5)
        assert torch.allclose(batch[0], out, atol=1e-5)
        assert model.forward_batch(points[None], poses[None, :0]).shape == (1, 0)


@pytest.mark.parametrize("key", sorted(MODELS))
def test_same_seed_same_outputs_and_no_global_rng(key: str) -> None:
    points, poses = scene()
    state = torch.get_rng_state()
    first, second = build(key, seed=7), build(key, seed=7)
    with torch.no_grad():
        a, b = first(points, poses), second(points, poses)
    assert torch.equal(torch.get_rng_state(), state)
    assert torch.equal(a, b)
    with torch.no_grad():
        assert not torch.allclose(build(key, seed=8)(points, poses), a)
    # chunking changes nothing
    with torch.no_grad():
        assert torch.allclose(build(key, seed=7, chunk_size=5)(points, poses), a, atol=1e-6)


@pytest.mark.parametrize("key", sorted(MODELS))
def test_swapping_the_hands_keeps_the_score(key: str) -> None:
    points, poses = scene()
    model = build(key).eval()
    with torch.no_grad():
        assert torch.allclose(model(points, poses), model(points, poses.flip(1)), atol=1e-6)


@pytest.mark.parametrize("key", sorted(MODELS))
def test_translating_object_and_grasps_keeps_the_score(key: str) -> None:
    points, poses = scene()
    shift = torch.tensor([0.7, -0.3, 0.5])
    moved = poses.clone()
    moved[..., :3, 3] += shift
    model = build(key).eval()
    with torch.no_grad():
        assert torch.allclose(model(points, poses), model(points + shift, moved), atol=1e-4)


@pytest.mark.parametrize("key", sorted(MODELS))
def test_rotating_object_and_grasps_keeps_the_score(key: str) -> None:
    """CGDF by construction; Dual-PointNetGPD too once its gravity feature is off."""
    points, poses = scene(dtype=torch.float64)
    model = build(key, gravity_feature=False).double().eval()
    g = torch.Generator().manual_seed(11)
    pivot = points.mean(dim=0)
    with torch.no_grad():
        reference = model(points, poses)
        for rotation in random_rotations(4, g, torch.float64):
            moved_points, moved_poses = rotate_about(rotation, pivot, points, poses)
            out = model(moved_points, moved_poses)
            assert torch.allclose(out, reference, atol=1e-9), (out - reference).abs().max()
            # not vacuous: rotating the object alone changes the scores
            assert not torch.allclose(model(moved_points, poses), reference, atol=1e-4)


def test_cgdf_rotation_invariance_in_float32() -> None:
    points, poses = scene(seed=5)
    model = CGDFClassifier(dataclasses.replace(SMALL_CGDF, seed=2)).eval()
    g = torch.Generator().manual_seed(12)
    with torch.no_grad():
        reference = model(points, poses)
        for rotation in random_rotations(3, g, torch.float32):
            out = model(*rotate_about(rotation, points.mean(dim=0), points, poses))
            assert torch.allclose(out, reference, atol=1e-4), (out - reference).abs().max()


@pytest.mark.parametrize("key", sorted(MODELS))
def test_gravity_feature_sees_tilts_but_not_turns_about_z(key: str) -> None:
    points, poses = scene(dtype=torch.float64)
    model = build(key, gravity_feature=True).double().eval()
    pivot = points.mean(dim=0)
    c, s = np.cos(0.8), np.sin(0.8)
    about_z = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
    about_x = torch.tensor([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]], dtype=torch.float64)
    with torch.no_grad():
        reference = model(points, poses)
        turned = model(*rotate_about(about_z, pivot, points, poses))
        tilted = model(*rotate_about(about_x, pivot, points, poses))
    assert torch.allclose(turned, reference, atol=1e-9)
    assert not torch.allclose(tilted, reference, atol=1e-6)


@pytest.mark.parametrize("key", sorted(MODELS))
def test_adam_learns_a_geometric_rule(key: str) -> None:
    """4 objects x 16 grasps; label: the two grasp centres lie on opposite sides of the
    centroid. 40 Adam steps must cut the training loss by more than a quarter."""
    g = torch.Generator().manual_seed(21)
    clouds, grasps = [], []
    for _ in range(4):
        points = make_object(g, 128)
        clouds.append(points)
        grasps.append(make_poses(g, points, 16))
    points, poses = torch.stack(clouds), torch.stack(grasps)
    local = torch.as_tensor(grasp_centre_local(), dtype=torch.float32)
    centres = poses[..., :3, 3] + poses[..., :3, :3] @ local - points.mean(dim=1)[:, None, None]
    labels = ((centres[:, :, 0] * centres[:, :, 1]).sum(-1) < 0).float()
    assert 0.2 < float(labels.mean()) < 0.8
    model = build(key, seed=1)
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    losses = []
    for _ in range(40):
        loss = torch.nn.functional.binary_cross_entropy_with_logits(
            model.forward_batch(points, poses), labels
        )
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
    assert np.mean(losses[-5:]) < 0.75 * losses[0], losses


@pytest.mark.parametrize("key", sorted(MODELS))
def test_checkpoint_round_trip(key: str, tmp_path: Path) -> None:
    points, poses = scene()
    model = build(key, seed=4).eval()
    path = tmp_path / "model.pt"
    extra = {"labels": "dg16m", "steps": 3, "history": [0.5, 0.25], "note": None}
    save_checkpoint(path, model, extra)
    assert [p.name for p in tmp_path.iterdir()] == ["model.pt"]  # no temporary left behind
    loaded, loaded_extra = load_checkpoint(path)
    assert type(loaded) is type(model)
    assert loaded.config == model.config
    assert loaded_extra == extra
    same, _ = type(model).from_checkpoint(path)
    with torch.no_grad():
        assert torch.equal(loaded(points, poses), model(points, poses))
        assert torch.equal(same(points, poses), model(points, poses))
    raw = torch.load(path, weights_only=True)
    assert raw["model"] == model.name
    assert raw["config"] == model.config.to_dict()


def test_checkpoint_of_another_model_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "gpd.pt"
    save_checkpoint(path, build("gpd"), {})
    with pytest.raises(ClassifierModelError, match="expected a 'cgdf_classifier' checkpoint"):
        CGDFClassifier.from_checkpoint(path)
    with pytest.raises(ClassifierModelError, match="found one of model 'dual_pointnet_gpd'"):
        load_checkpoint(path, expected="cgdf_classifier")


class _Payload:
    """An arbitrary object: a weights-only load must refuse to rebuild it."""


def test_unsafe_or_foreign_files_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ClassifierModelError, match="expected a checkpoint file, found none"):
        load_checkpoint(tmp_path / "missing.pt")
    pickled = tmp_path / "pickled.pt"
    torch.save({"format": "dg16m-classifier", "payload": _Payload()}, pickled)
    with pytest.raises(ClassifierModelError, match="unreadable"):
        load_checkpoint(pickled)
    other = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(3)}, other)
    with pytest.raises(ClassifierModelError, match="expected format 'dg16m-classifier'"):
        load_checkpoint(other)
    with pytest.raises(ClassifierModelError, match="expected str, int, float"):
        save_checkpoint(tmp_path / "bad.pt", build("gpd"), {"object": _Payload()})
    assert not (tmp_path / "bad.pt").exists()


def test_config_round_trip_and_validation() -> None:
    for config in (SMALL_GPD, SMALL_CGDF):
        assert type(config).from_dict(config.to_dict()) == config
    with pytest.raises(ClassifierModelError, match="expected keys among"):
        CGDFConfig.from_dict({"n_anchors": 8, "widths": 3})
    with pytest.raises(ClassifierModelError, match="points_per_hand: expected an int >= 1"):
        DualPointNetGPDConfig(points_per_hand=0)
    with pytest.raises(ClassifierModelError, match="crop: expected 'centre' or 'template'"):
        DualPointNetGPDConfig(crop="box")  # type: ignore[arg-type]


def test_template_crop_mode_runs() -> None:
    points, poses = scene()
    model = build("gpd", crop="template").eval()
    with torch.no_grad():
        out = model(points, poses)
    assert out.shape == (12,)
    assert torch.allclose(out, model(points, poses.flip(1)), atol=1e-6)


@pytest.mark.parametrize("key", sorted(MODELS))
@pytest.mark.parametrize(
    ("points_shape", "poses_shape", "message"),
    [
        ((64, 4), (3, 2, 4, 4), r"points: expected shape \(P, 3\) with P >= 1, found \(64, 4\)"),
        ((0, 3), (3, 2, 4, 4), r"points: expected shape \(P, 3\) with P >= 1, found \(0, 3\)"),
        ((64, 3), (3, 4, 4), r"poses: expected shape \(n, 2, 4, 4\), found \(3, 4, 4\)"),
        ((64, 3), (3, 2, 4, 3), r"poses: expected shape \(n, 2, 4, 4\), found \(3, 2, 4, 3\)"),
    ],
)
def test_wrong_shapes_are_refused(
    key: str, points_shape: tuple, poses_shape: tuple, message: str
) -> None:
    model = build(key)
    with pytest.raises(ClassifierModelError, match=message) as info:
        model(torch.zeros(points_shape), torch.zeros(poses_shape))
    assert isinstance(info.value, Dg16mError)


@pytest.mark.parametrize("key", sorted(MODELS))
def test_batch_mismatch_and_nan_are_refused(key: str) -> None:
    points, poses = scene()
    model = build(key)
    with pytest.raises(ClassifierModelError, match=r"expected shape \(B, P, 3\)"):
        model.forward_batch(points, poses)
    with pytest.raises(ClassifierModelError, match="expected B = 2 objects"):
        model.forward_batch(torch.stack([points, points]), poses[None])
    bad = points.clone()
    bad[0, 0] = float("nan")
    with pytest.raises(ClassifierModelError, match="points: expected finite values"):
        model(bad, poses)
