"""The learned check for open hands that start in unseen parts (``baselines.hand_collision``)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from baselines.cloud_grasps import CloudError
from baselines.cloud_predictor import (
    HAND_COLLISION_CHECKPOINT,
    SAFE_BONUS,
    CloudPredictor,
    cgdf_partial_predictor,
    random_partial_predictor,
)
from baselines.da2_labels import roc_auc
from baselines.hand_collision import (
    DEPTH_SCALE,
    GRID,
    hand_features,
    load_hand_collision,
    n_features,
)
from baselines.train_hand_collision import Args, main, object_hands
from dataset_gen.sources.procedural import make_procedural_object
from dg16m_core.parameters import PROTOCOL
from dg16m_env.physics.scene import compile_scene
from dg16m_env.physics.trial_protocol import open_hand_penetration
from dg16m_env.subjects.observation import object_observation

HELD_OUT = ("table", 1000012)  # a benchmark object: never a training object


@pytest.fixture(scope="module")
def table():
    """A benchmark table, its two-camera cloud, views and candidates."""
    obj = make_procedural_object(*HELD_OUT)
    cloud, cands, _rng, views = cgdf_partial_predictor.observed_candidates(object_observation(obj))
    return obj, cloud, cands, views


def test_features_have_the_documented_shape_and_range(table):
    _obj, cloud, cands, views = table
    features = hand_features(cloud, views, cands.poses[:50])
    assert features.shape == (50, 2, n_features())
    assert features.dtype == np.float32
    visibility, occupancy = features[..., : -(GRID**3)], features[..., -(GRID**3) :]
    assert visibility.min() >= -1.0
    assert visibility.max() <= 1.0
    assert set(np.unique(occupancy)) <= {0.0, 1.0}
    assert occupancy.sum(axis=-1).min() > 0  # every hand holds cloud points between its fingers
    # a hand moved 1 m away: all of it in seen-empty space or outside every image, no points
    away = cands.poses[:1].copy()
    away[..., :3, 3] += [0.0, 0.0, 1.0]
    far = hand_features(cloud, views, away)
    assert far[..., -(GRID**3) :].sum() == 0
    assert np.all(np.isin(far[..., : -(GRID**3)], [-1.0, 1.0]))
    with pytest.raises(CloudError, match=r"expected shape \(N, 2, 4, 4\)"):
        hand_features(cloud, views, cands.poses[0])


def test_the_shipped_check_tells_hands_that_start_inside_on_a_held_out_object(table):
    """On a benchmark table (never trained on), the probability ranks the hands that start in
    the object (the evaluator's own test) above those that do not."""
    obj, cloud, cands, views = table
    model = load_hand_collision(str(HAND_COLLISION_CHECKPOINT))
    depth = open_hand_penetration(compile_scene(obj), cands.poses).max(axis=2)
    inside = depth > PROTOCOL.invalid_penetration
    assert 0 < inside.sum() < inside.size
    p = model.probability(hand_features(cloud, views, cands.poses))
    assert p.shape == inside.shape
    assert np.all((p >= 0) & (p <= 1))
    assert roc_auc(p.ravel(), inside.ravel()) > 0.85
    assert model.metadata["kind"] == "hand-collision"
    assert not any(str(o).startswith("table-10") for o in model.metadata["objects"])


def test_the_predictor_ranks_risky_candidates_last(table):
    obj, cloud, cands, views = table
    checked = dataclasses.replace(random_partial_predictor, collision="shipped", k=cands.n)
    risk = checked.start_risk(cloud, views, cands)
    assert risk.shape == (cands.n,)
    assert (risk > checked.max_start_risk).any()
    poses, scores = checked(object_observation(obj))
    assert len(poses) == cands.n
    safe = scores >= SAFE_BONUS
    assert safe.sum() == int((risk <= checked.max_start_risk).sum())
    assert np.all(safe[: safe.sum()])  # every safe candidate before every risky one
    unchecked_poses, _ = dataclasses.replace(checked, collision=None)(object_observation(obj))
    assert not np.array_equal(poses, unchecked_poses)  # same candidates, another order
    with pytest.raises(CloudError, match="collision: expected None with view='full'"):
        CloudPredictor("cgdf", collision="shipped")
    with pytest.raises(CloudError, match=r"max_start_risk: expected a number in \[0, 1\]"):
        CloudPredictor("cgdf", view="partial", max_start_risk=1.5)


def test_training_writes_a_checkpoint_that_loads_and_refuses_other_files(tmp_path: Path):
    _, features, truth = object_hands(("table", 0, 0))  # a training object
    assert features.shape == (len(truth), n_features())
    assert truth.dtype == bool
    out = tmp_path / "hc.pt"
    cache = tmp_path / "features.npz"
    args = Args(objects=3, val_objects=1, epochs=1, workers=1, out=str(out), features=str(cache))
    main(args)
    model = load_hand_collision(str(out))
    assert model.metadata["objects"] == [
        "table-0000000",
        "bench-0000000",
        "crate-0000000",
    ]
    assert model.metadata["epoch"] == 1
    p = model.probability(np.zeros((4, 2, n_features()), dtype=np.float32))
    assert p.shape == (4, 2)
    main(dataclasses.replace(args, out=str(tmp_path / "again.pt")))  # from the features file
    again = torch.load(tmp_path / "again.pt", weights_only=True)
    first = torch.load(out, weights_only=True)
    for name, tensor in first["state_dict"].items():  # same seed, same features: same weights
        assert torch.equal(tensor, again["state_dict"][name])
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(CloudError, match="expected a hand-collision checkpoint"):
        load_hand_collision(str(bad))
    other = tmp_path / "other.pt"
    torch.save({"state_dict": {}, "metadata": {**first["metadata"], "grid": GRID + 1}}, other)
    with pytest.raises(CloudError, match="expected features"):
        load_hand_collision(str(other))
    assert first["metadata"]["depth_scale"] == DEPTH_SCALE
