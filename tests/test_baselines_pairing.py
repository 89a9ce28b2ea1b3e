"""The pairing baselines (random, farthest, force closure) as predictors, the reference
submissions and their command line."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
import trimesh

from baselines.baseline_commands import register, run_submissions
from baselines.pairing_baselines import (
    PAIRING_STRATEGIES,
    BaselineError,
    PairingBaseline,
    object_from_observation,
)
from baselines.reference_submissions import (
    STRATEGIES,
    ReferenceSubmissionError,
    main,
    parse_strategies,
    reference_baselines,
    write_reference_submissions,
)
from dataset_gen.force_closure import evaluate
from dataset_gen.grasps.pairing import candidate_pairs, dual_contacts, score_pairs
from dataset_gen.objects.grasp_object import is_rigid
from dg16m_env.benchmark.file import write_benchmark
from dg16m_env.benchmark.model import SOURCES
from dg16m_env.benchmark.ref import BenchmarkRef
from dg16m_env.evaluators import load_benchmark_ref
from dg16m_env.subjects.observation import object_observation
from dg16m_env.subjects.submission_reader import validate_submission

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def ref() -> BenchmarkRef:
    return load_benchmark_ref()


@pytest.fixture(scope="module")
def observations(ref: BenchmarkRef) -> list[dict[str, Any]]:
    """Two procedural benchmark objects of different families."""
    objects = ref.benchmark.objects
    second = next(o for o in objects if o.family != objects[0].family)
    return [object_observation(o.load()) for o in (objects[0], second)]


@pytest.fixture(scope="module")
def predictions(
    observations: list[dict[str, Any]],
) -> dict[tuple[str, int], tuple[np.ndarray, np.ndarray]]:
    """(strategy, object) -> the default baseline's prediction."""
    return {
        (s, i): PairingBaseline(s)(obs)  # type: ignore[arg-type]
        for s in PAIRING_STRATEGIES
        for i, obs in enumerate(observations)
    }


def _contacts(baseline: PairingBaseline, obs: dict[str, Any], poses: np.ndarray) -> tuple:
    """The sampled contacts of predicted dual grasps: each hand pose matched to its grasp."""
    grasps = baseline.sample(obs).grasps
    flat = grasps.poses.reshape(grasps.n, -1)
    index = np.array(
        [[np.flatnonzero((flat == h.ravel()).all(axis=1))[0] for h in p] for p in poses]
    )
    return dual_contacts(grasps, index)


@pytest.mark.parametrize("strategy", PAIRING_STRATEGIES)
@pytest.mark.parametrize("which", [0, 1])
def test_predictions_are_k_rigid_finite_dual_grasps(strategy, which, predictions):
    poses, scores = predictions[(strategy, which)]
    assert poses.shape == (10, 2, 4, 4)
    assert scores.shape == (10,)
    assert poses.dtype == np.float64
    assert scores.dtype == np.float64
    assert np.isfinite(poses).all()
    assert np.isfinite(scores).all()
    assert is_rigid(poses).all()
    assert len(np.unique(poses.reshape(10, -1), axis=0)) == 10  # distinct dual grasps
    if strategy != "force_closure":
        assert (scores == 0).all()


@pytest.mark.parametrize("strategy", PAIRING_STRATEGIES)
def test_same_seed_same_bytes_other_seed_other_grasps(strategy, observations, predictions):
    obs = observations[0]
    poses, scores = predictions[(strategy, 0)]
    again_poses, again_scores = PairingBaseline(strategy)(obs)
    assert again_poses.tobytes() == poses.tobytes()
    assert again_scores.tobytes() == scores.tobytes()
    other, _ = PairingBaseline(strategy, seed=1)(obs)
    assert other.tobytes() != poses.tobytes()


def test_one_sample_serves_every_strategy(observations, predictions):
    obs = observations[1]
    sampled = PairingBaseline("random").sample(obs)
    for strategy in PAIRING_STRATEGIES:
        poses, scores = PairingBaseline(strategy).choose(sampled)  # type: ignore[arg-type]
        expected = predictions[(strategy, 1)]
        assert poses.tobytes() == expected[0].tobytes()
        assert scores.tobytes() == expected[1].tobytes()
    with pytest.raises(BaselineError, match="expected grasps sampled with"):
        PairingBaseline("random", seed=3).choose(sampled)


def test_predictions_are_fresh_grasps_not_benchmark_rows(ref, observations, predictions):
    bench = ref.benchmark
    for i, obs in enumerate(observations):
        stored = bench.poses[bench.object_rows(obs["object_id"])].reshape(-1, 4, 4)
        hands = predictions[("force_closure", i)][0].reshape(-1, 4, 4)
        same = (np.abs(hands[:, None] - stored[None]).max(axis=(2, 3)) < 1e-12).any(axis=1)
        assert not same.any()


@pytest.mark.parametrize("which", [0, 1])
def test_force_closure_picks_pass_force_closure(which, observations, predictions):
    baseline = PairingBaseline("force_closure")
    obs = observations[which]
    poses, scores = predictions[("force_closure", which)]
    points, normals = _contacts(baseline, obs, poses)
    check = evaluate(points, normals, **baseline.force_closure_kwargs())
    assert check.passed.all()
    assert (scores <= 0).all()
    assert (scores >= -baseline.threshold).all()


def test_random_and_farthest_pairs_pass_less_often(observations, predictions):
    kwargs = PairingBaseline("force_closure").force_closure_kwargs()
    for strategy in ("random", "farthest"):
        baseline = PairingBaseline(strategy)  # type: ignore[arg-type]
        passed = [
            evaluate(*_contacts(baseline, obs, predictions[(strategy, i)][0]), **kwargs).passed
            for i, obs in enumerate(observations)
        ]
        assert np.concatenate(passed).mean() < 1.0


def test_force_closure_fills_a_shortfall_with_the_lowest_losses(observations):
    baseline = PairingBaseline("force_closure", n_grasps=12, k=60)
    obs = observations[0]
    sampled = baseline.sample(obs)
    poses, scores = baseline.choose(sampled)
    cands = candidate_pairs(sampled.grasps, min_center_distance=baseline.min_center_distance)
    verdict = score_pairs(sampled.grasps, cands.pairs, **baseline.force_closure_kwargs())
    n_pass = int(verdict.passed.sum())
    assert 0 < n_pass < 60 <= cands.n, "the test needs a shortfall of passing candidates"
    assert poses.shape == (60, 2, 4, 4)
    points, normals = _contacts(baseline, obs, poses)
    exact = evaluate(points, normals, loss_rtol=1e-3, **baseline.force_closure_kwargs())
    assert exact.passed[:n_pass].all()
    assert not exact.passed[n_pass:].any()
    fill = -scores[n_pass:]
    assert (np.diff(fill) >= 0).all()  # lowest losses first
    np.testing.assert_allclose(fill, exact.loss[n_pass:], rtol=2e-3, atol=1e-9)
    # they are the lowest losses among all failing candidates
    failing = np.flatnonzero(~verdict.passed)
    all_points, all_normals = dual_contacts(sampled.grasps, cands.pairs[failing])
    every = evaluate(all_points, all_normals, loss_rtol=1e-3, **baseline.force_closure_kwargs())
    lowest = np.sort(every.loss)[: 60 - n_pass]
    np.testing.assert_allclose(fill, lowest, rtol=2e-3, atol=1e-9)


def test_farthest_pairs_are_farther_apart_than_random(predictions):
    def separation(strategy: str) -> float:
        hands = np.concatenate([predictions[(strategy, i)][0] for i in (0, 1)])
        return float(np.linalg.norm(hands[:, 0, :3, 3] - hands[:, 1, :3, 3], axis=1).mean())

    assert separation("farthest") > separation("random")


def test_fewer_pairs_than_k_returns_what_there_is(observations):
    poses, scores = PairingBaseline("farthest", n_grasps=4, k=50)(observations[0])
    assert 1 <= len(poses) <= 4
    assert scores.shape == (len(poses),)


def test_an_object_without_grasps_is_a_clear_error():
    box = trimesh.creation.box(extents=(0.6, 0.5, 0.4))  # wider than the hand everywhere
    obs = {"object_id": "big-box", "mesh_vertices": box.vertices, "mesh_faces": box.faces}
    for strategy in PAIRING_STRATEGIES:
        with pytest.raises(BaselineError, match=r"big-box: expected at least one .* found none"):
            PairingBaseline(strategy, n_grasps=2)(obs)  # type: ignore[arg-type]


def test_bad_arguments_and_observations_say_what_was_expected(observations):
    with pytest.raises(BaselineError, match="strategy: expected one of"):
        PairingBaseline("nearest")  # type: ignore[arg-type]
    with pytest.raises(BaselineError, match="k: expected an integer >= 1, found 0"):
        PairingBaseline("random", k=0)
    with pytest.raises(BaselineError, match="mu: expected a positive finite number"):
        PairingBaseline("random", mu=-0.1)
    with pytest.raises(BaselineError, match="expected keys"):
        object_from_observation({"object_id": "x"})
    bad = dict(observations[0], mesh_faces=observations[0]["mesh_faces"] + 10**6)
    with pytest.raises(BaselineError, match="mesh_faces: expected vertex indices"):
        object_from_observation(bad)
    obj = object_from_observation(observations[0])
    assert np.array_equal(obj.mesh.vertices, observations[0]["mesh_vertices"])  # same frame
    assert np.array_equal(obj.mesh.faces, observations[0]["mesh_faces"])


# --------------------------------------------------------------------------------------------
# Reference submissions
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_ref(ref: BenchmarkRef, tmp_path_factory: pytest.TempPathFactory) -> BenchmarkRef:
    ids = [ref.object_ids[i] for i in (0, 1, 2)]
    path = tmp_path_factory.mktemp("bench") / "b.h5"
    write_benchmark(path, ref.benchmark.select_objects(ids))
    return load_benchmark_ref(path)


@pytest.fixture(scope="module")
def written(small_ref: BenchmarkRef, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("refs")
    return write_reference_submissions(out, benchmark=small_ref, k=10, progress=False)


def test_reference_submissions_are_four_valid_files(small_ref, written):
    assert list(written) == list(STRATEGIES)
    assert [p.name for p in written.values()] == [f"{s}.h5" for s in STRATEGIES]
    bench = small_ref.benchmark
    for name, path in written.items():
        assert (
            validate_submission(
                path,
                object_ids=small_ref.object_ids,
                benchmark_sha256=small_ref.sha256,
                embedded=False,
            )
            == []
        )
        with h5py.File(path, "r") as f:
            assert f.attrs["benchmark"] == small_ref.sha256
            meta = json.loads(f.attrs["metadata"])
            assert sorted(f["objects"]) == sorted(small_ref.object_ids)
            for object_id in small_ref.object_ids:
                poses = f[f"objects/{object_id}/poses"][()]
                scores = f[f"objects/{object_id}/scores"][()]
                rows = bench.object_rows(object_id)
                n_pass = int((bench.source[rows] == SOURCES.index("fc_pass")).sum())
                k = min(10, n_pass) if name == "benchmark_fc_pass" else 10
                assert poses.shape == (k, 2, 4, 4)
                assert scores.shape == (k,)
        assert meta["baseline"] == name
        assert meta["k"] == 10
        assert meta["seed"] == 0
        assert meta["created_by"].startswith("dg16m ")


def test_reference_files_hold_the_predictors_and_the_stored_rows(small_ref, written):
    bench = small_ref.benchmark
    object_id = small_ref.object_ids[1]
    observation = object_observation(bench.objects[1].load())
    for baseline in reference_baselines(small_ref, k=10):
        poses, scores = baseline(observation)
        with h5py.File(written[baseline.name], "r") as f:
            assert f[f"objects/{object_id}/poses"][()].tobytes() == poses.tobytes()
            assert f[f"objects/{object_id}/scores"][()].tobytes() == scores.tobytes()
    rows = bench.object_rows(object_id)
    rows = rows[bench.source[rows] == SOURCES.index("fc_pass")][:10]
    with h5py.File(written["benchmark_fc_pass"], "r") as f:
        assert np.array_equal(f[f"objects/{object_id}/poses"][()], bench.poses[rows])
        assert np.array_equal(f[f"objects/{object_id}/scores"][()], -bench.fc_loss[rows])


def test_reference_submissions_do_not_depend_on_workers(small_ref, written, tmp_path):
    again = write_reference_submissions(
        tmp_path, benchmark=small_ref, workers=2, strategies=["random"], progress=False
    )
    with h5py.File(again["random"], "r") as a, h5py.File(written["random"], "r") as b:
        for object_id in small_ref.object_ids:
            key = f"objects/{object_id}/poses"
            assert a[key][()].tobytes() == b[key][()].tobytes()


def test_a_baseline_that_fails_on_an_object_is_not_written(small_ref, tmp_path):
    bench = small_ref.benchmark.select_objects(small_ref.object_ids)
    first = bench.object_rows(small_ref.object_ids[0])
    bench.source = bench.source.copy()
    bench.source[first] = SOURCES.index("random")  # no stored passing rows on object 0
    broken = BenchmarkRef(path=tmp_path / "x.h5", sha256="0" * 64, embedded=False, benchmark=bench)
    with pytest.raises(ReferenceSubmissionError, match="benchmark_fc_pass: expected") as info:
        write_reference_submissions(
            tmp_path / "out", benchmark=broken, strategies=["benchmark_fc_pass"], progress=False
        )
    assert info.value.written == {}
    assert list(info.value.failures["benchmark_fc_pass"]) == [small_ref.object_ids[0]]
    assert not (tmp_path / "out" / "benchmark_fc_pass.h5").exists()


def test_strategy_names_are_checked():
    assert parse_strategies("random, farthest") == ("random", "farthest")
    for text, message in (
        ("", "found none"),
        ("best", "found \\['best'\\]"),
        ("random,random", "each name once"),
    ):
        with pytest.raises(BaselineError, match=message):
            parse_strategies(text)


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="dg16m")
    register(parser.add_subparsers(dest="command"))
    return parser


def test_command_parses_and_has_help_with_examples(capsys):
    args = _parser().parse_args(
        ["baselines", "submissions", "--out", "x", "--k", "5", "--strategies", "random"]
    )
    assert args.handler is run_submissions
    assert (args.out, args.k, args.seed, args.workers) == (Path("x"), 5, 0, 1)
    assert args.benchmark is None
    assert args.strategies == "random"
    with pytest.raises(SystemExit) as exit_:
        _parser().parse_args(["baselines", "submissions", "--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    assert "examples:" in text
    assert "dg16m baselines submissions --out" in text


def test_command_handler_writes_the_files(small_ref, tmp_path, capsys):
    args = _parser().parse_args(
        [
            "baselines",
            "submissions",
            "--out",
            str(tmp_path),
            "--benchmark",
            str(small_ref.path),
            "--strategies",
            "benchmark_fc_pass",
            "--no-progress",
        ]
    )
    assert args.handler(args) == 0
    assert (tmp_path / "benchmark_fc_pass.h5").is_file()
    assert "wrote" in capsys.readouterr().out
    assert main(["--out", str(tmp_path), "--strategies", "nope"]) == 2


def test_module_runs_as_a_script():
    result = subprocess.run(
        [sys.executable, "-m", "baselines.reference_submissions", "--help"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert "--strategies" in result.stdout
