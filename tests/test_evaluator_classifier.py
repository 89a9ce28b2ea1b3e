"""The ``classifier`` evaluator on a three-object benchmark cut from the embedded one."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dataset_gen.io import package_version
from dataset_gen.sources.object_source import object_seed
from dg16m_core.hashing import file_sha256
from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.benchmark.ref import BenchmarkRef, load_benchmark_ref
from dg16m_env.evaluators.classifier import ClassifierEvaluator, average_precision
from dg16m_env.evaluators.code_identity import code_sha256
from dg16m_env.evaluators.registry import EvaluatorError, make
from dg16m_env.evaluators.result import EvaluationResult

IDS = ["table-1000000", "bench-1000000", "crate-1000000"]
K = 10


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> BenchmarkRef:
    """Three objects of three families, written to a file and loaded as evaluators do."""
    path = tmp_path_factory.mktemp("bench") / "tiny.h5"
    write_benchmark(path, read_benchmark(EMBEDDED_BENCHMARK).select_objects(IDS))
    return load_benchmark_ref(path)


@pytest.fixture(scope="module")
def evaluator(tiny: BenchmarkRef) -> ClassifierEvaluator:
    ev = make("classifier", benchmark=tiny, n_resamples=200)
    assert isinstance(ev, ClassifierEvaluator)
    return ev


def lookup(tiny: BenchmarkRef, values: np.ndarray) -> Any:
    """A classifier scoring each pose by ``values`` of its benchmark row (matched by bytes)."""
    table = {tiny.benchmark.poses[i].tobytes(): float(values[i]) for i in range(tiny.benchmark.n)}

    def classify(observation: dict[str, Any], poses: np.ndarray) -> np.ndarray:
        assert observation["points"].shape == (2048, 3)
        return np.array([table[p.tobytes()] for p in poses])

    return classify


def constant(observation: dict[str, Any], poses: np.ndarray) -> np.ndarray:
    return np.zeros(len(poses))


def rows_of(tiny: BenchmarkRef, index: int) -> np.ndarray:
    return np.flatnonzero(tiny.benchmark.object_index == index)


def rate(result: EvaluationResult, name: str) -> float:
    return result.metrics[name]["rate"]


def naive_ap(scores: np.ndarray, labels: np.ndarray) -> float:
    order = sorted(range(len(scores)), key=lambda i: (-scores[i], i))
    hits, total = 0, 0.0
    for rank, i in enumerate(order, start=1):
        if labels[i]:
            hits += 1
            total += hits / rank
    return total / hits


def test_tiny_benchmark_has_three_families(tiny: BenchmarkRef) -> None:
    assert tiny.object_ids == IDS
    assert len(set(tiny.families)) == 3
    assert all(rows_of(tiny, i).size > K for i in range(3))
    assert all(tiny.benchmark.label("full")[rows_of(tiny, i)].any() for i in range(3))


def test_average_precision_by_hand() -> None:
    assert average_precision(np.array([3.0, 2.0, 1.0]), np.array([1, 0, 1], bool)) == (
        pytest.approx((1 + 2 / 3) / 2)
    )
    assert average_precision(np.array([1.0, 1.0]), np.array([0, 1], bool)) == 0.5  # stable tie
    assert average_precision(np.zeros(3), np.zeros(3, bool)) is None


def test_oracle_beats_every_other_ranking(tiny: BenchmarkRef, evaluator: ClassifierEvaluator):
    bench = tiny.benchmark
    p = bench.p("full")
    oracle = evaluator.evaluate(lookup(tiny, p))
    best = np.mean([np.sort(p[rows_of(tiny, i)])[::-1][:K] for i in range(3)])
    assert rate(oracle, f"gsr_top{K}_full") == pytest.approx(best)
    assert oracle.headline == f"gsr_top{K}_full"
    assert oracle.score == pytest.approx(best)
    assert rate(oracle, "ap_full") == 1.0
    assert all(oracle.per_object[i]["ap_full"] == 1.0 for i in IDS)
    rng = np.random.default_rng(0)
    others = [constant, lookup(tiny, -p), lookup(tiny, bench.fc_loss)]
    others += [lookup(tiny, rng.random(bench.n)) for _ in range(3)]
    for other in others:
        result = evaluator.evaluate(other)
        assert rate(result, f"gsr_top{K}_full") <= rate(oracle, f"gsr_top{K}_full") + 1e-12
        assert rate(result, "ap_full") <= 1.0


def presented_top(tiny: BenchmarkRef, i: int, seed: int = 0) -> np.ndarray:
    """Benchmark rows of object i's first K candidates in the seeded presented order."""
    rows = rows_of(tiny, i)
    key = f"candidates:{tiny.object_ids[i]}"
    return rows[np.random.default_rng(object_seed(seed, key)).permutation(rows.size)[:K]]


def test_constant_classifier_gets_the_presented_order(
    tiny: BenchmarkRef, evaluator: ClassifierEvaluator
) -> None:
    bench = tiny.benchmark
    result = evaluator.evaluate(constant)
    top = np.concatenate([presented_top(tiny, i) for i in range(3)])
    assert rate(result, f"fce_top{K}") == pytest.approx(bench.fc_passed[top].mean())
    for level in ("full", "gravity"):
        assert rate(result, f"gsr_top{K}_{level}") == pytest.approx(bench.p(level)[top].mean())
        assert rate(result, f"precision_at_{K}_{level}") == pytest.approx(
            bench.label(level)[top].mean()
        )
    for i, object_id in enumerate(IDS):
        entry = result.per_object[object_id]
        assert entry["grasps"] == K
        assert entry["candidates"] == rows_of(tiny, i).size
        assert entry[f"gsr_top{K}_full"] == pytest.approx(bench.p()[presented_top(tiny, i)].mean())
    assert set(result.per_family) == {"table", "bench", "crate"}
    assert result.metrics[f"fce_top{K}"]["rows"] == 3 * K
    assert result.metrics[f"fce_top{K}"]["objects"] == 3


def test_anti_oracle_is_worse_than_random(tiny: BenchmarkRef, evaluator: ClassifierEvaluator):
    bench = tiny.benchmark
    result = evaluator.evaluate(lookup(tiny, -bench.p("full")))
    chance = result.details["chance"]
    assert chance[f"gsr_top{K}_full"] == pytest.approx(
        np.mean([bench.p()[rows_of(tiny, i)].mean() for i in range(3)])
    )
    assert chance[f"fce_top{K}"] == pytest.approx(
        np.mean([bench.fc_passed[rows_of(tiny, i)].mean() for i in range(3)])
    )
    assert rate(result, f"gsr_top{K}_full") < chance[f"gsr_top{K}_full"]
    assert rate(result, f"precision_at_{K}_full") < chance[f"precision_at_{K}_full"]
    assert rate(result, "ap_full") < chance["ap_full"]


def failing_on(tiny: BenchmarkRef, failing: str, how: str) -> Any:
    oracle = lookup(tiny, tiny.benchmark.p("full"))

    def classify(observation: dict[str, Any], poses: np.ndarray) -> Any:
        scores = oracle(observation, poses)
        if observation["object_id"] != failing:
            return scores
        if how == "nan":
            scores[3] = np.nan
            return scores
        if how == "shape":
            return scores[:-1]
        if how == "text":
            return ["a"] * len(poses)
        raise RuntimeError("model exploded")

    return classify


@pytest.mark.parametrize(
    ("how", "reason"),
    [
        ("nan", "scores: expected finite values, found 1 NaN or infinite of 100"),
        ("shape", "scores: expected shape (100,), found (99,)"),
        ("text", "scores: expected (100,) numbers, found list"),
        ("raise", "RuntimeError: model exploded"),
    ],
)
def test_a_failed_object_counts_as_zero(
    tiny: BenchmarkRef, evaluator: ClassifierEvaluator, how: str, reason: str
) -> None:
    bench = tiny.benchmark
    p = bench.p("full")
    result = evaluator.evaluate(failing_on(tiny, IDS[1], how))
    assert list(result.failures) == [IDS[1]]
    assert result.failures[IDS[1]].startswith(reason)
    good = [np.sort(p[rows_of(tiny, i)])[::-1][:K].sum() for i in (0, 2)]
    assert rate(result, f"gsr_top{K}_full") == pytest.approx(sum(good) / (3 * K))
    assert result.metrics[f"gsr_top{K}_full"]["rows"] == 3 * K
    assert rate(result, "ap_full") == pytest.approx(2 / 3)
    entry = result.per_object[IDS[1]]
    assert entry[f"gsr_top{K}_full"] == 0.0
    assert entry["ap_full"] == 0.0
    assert entry["scored"] is False
    assert result.details["failed_objects"] == 1
    assert result.details["top_k_rows_of_failed_objects"] == K
    assert "could not be scored" in result.format()


def test_keyboard_interrupt_is_not_swallowed(evaluator: ClassifierEvaluator) -> None:
    def interrupted(observation: dict[str, Any], poses: np.ndarray) -> np.ndarray:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        evaluator.evaluate(interrupted)


def test_classifier_gets_fresh_copies(tiny: BenchmarkRef, evaluator: ClassifierEvaluator):
    def vandal(observation: dict[str, Any], poses: np.ndarray) -> np.ndarray:
        observation["points"][:] = np.nan
        scores = poses[:, 0, 0, 3].copy()
        poses[:] = 0.0
        return scores

    before = tiny.benchmark.poses.copy()
    first = evaluator.evaluate(vandal).to_dict()
    np.testing.assert_array_equal(tiny.benchmark.poses, before)
    assert evaluator.evaluate(vandal).to_dict() == first


def test_torch_module_matches_the_equivalent_callable(tiny: BenchmarkRef) -> None:
    torch = pytest.importorskip("torch")

    class Scorer(torch.nn.Module):
        """Score = w . (left hand position) + mean point height."""

        def __init__(self) -> None:
            super().__init__()
            self.w = torch.nn.Parameter(torch.tensor([0.25, -1.0, 0.5]))
            self.drop = torch.nn.Dropout(0.5)  # eval mode must switch it off
            self.name = "scorer"

        def forward(self, points: Any, poses: Any) -> Any:
            assert points.dtype == torch.float32
            assert points.shape == (2048, 3)
            assert poses.dtype == torch.float32
            assert poses.shape[1:] == (2, 4, 4)
            assert len(poses) <= 7
            assert not torch.is_grad_enabled()
            return self.drop(poses[:, 0, :3, 3] @ self.w + points[:, 2].mean())

    def equivalent(observation: dict[str, Any], poses: np.ndarray) -> np.ndarray:
        w = np.array([0.25, -1.0, 0.5], np.float32)
        points = observation["points"]
        return poses.astype(np.float32)[:, 0, :3, 3] @ w + points[:, 2].mean()

    module = Scorer()
    module.train()
    module.drop.eval()  # a mixed state must come back as it was
    ev = make("classifier", benchmark=tiny, n_resamples=200, batch_size=7)
    from_module = ev.evaluate(module)
    from_callable = ev.evaluate(equivalent)
    assert module.training
    assert not module.drop.training
    assert from_module.subject["name"] == "scorer"
    assert from_module.subject["interface"] == "torch.nn.Module"
    assert from_module.metrics == from_callable.metrics
    assert from_module.per_object == from_callable.per_object
    assert not from_module.failures

    class Wrong(torch.nn.Module):
        def forward(self, points: Any, poses: Any) -> Any:
            return poses[:, 0, :3, 3]

    wrong = ev.evaluate(Wrong())
    assert set(wrong.failures) == set(IDS)
    assert "expected shape (7,) for 7 poses, found (7, 3)" in wrong.failures[IDS[0]]
    assert rate(wrong, f"gsr_top{K}_full") == 0.0


def test_two_runs_are_identical(tiny: BenchmarkRef) -> None:
    rng = np.random.default_rng(3)
    classify = lookup(tiny, rng.random(tiny.benchmark.n))
    first = make("classifier", benchmark=tiny.path, n_resamples=300).evaluate(classify)
    second = make("classifier", benchmark=tiny.path, n_resamples=300).evaluate(classify)
    assert first.to_dict() == second.to_dict()
    text = json.dumps(first.to_dict(), allow_nan=False, sort_keys=True)
    assert EvaluationResult.from_dict(json.loads(text)).to_dict() == first.to_dict()


def test_result_records_versions_and_inputs(tiny: BenchmarkRef) -> None:
    ev = make(
        "classifier", benchmark=tiny, k=5, levels=("gravity",), n_points=64, observation_seed=2
    )
    result = ev.evaluate(constant)
    assert result.evaluator == "classifier"
    assert result.evaluator_version == "1"
    assert result.package_version == package_version()
    assert result.benchmark["sha256"] == file_sha256(Path(tiny.path))
    assert result.benchmark["objects"] == 3
    assert result.parameters["k"] == 5
    assert result.parameters["levels"] == ["gravity"]
    assert result.parameters["n_points"] == 64
    assert result.parameters["batch_size"] == 4096
    assert result.seeds == {"observation": 2, "resample": 0, "candidates": 0}
    assert result.headline == "gsr_top5_gravity"
    assert set(result.metrics) == {
        "fce_top5",
        "gsr_top5_gravity",
        "precision_at_5_gravity",
        "ap_gravity",
    }
    assert result.subject == {
        "kind": "classifier",
        "name": None,
        "type": "builtins.function",
        "interface": "callable",
        "sha256": code_sha256(constant),
    }


def test_the_stored_order_cannot_be_exploited(tiny: BenchmarkRef) -> None:
    """Stored rows are grouped by arm (fc_pass first); candidates are presented shuffled, so
    scoring by position is no better than a constant."""

    def by_position(observation: dict[str, Any], poses: np.ndarray) -> np.ndarray:
        return -np.arange(len(poses), dtype=np.float64)

    bench = tiny.benchmark
    stored_top = np.concatenate([rows_of(tiny, i)[:K] for i in range(3)])
    for seed in (0, 1):
        ev = make("classifier", benchmark=tiny, n_resamples=100, candidate_seed=seed)
        hidden = ev.evaluate(by_position)
        assert hidden.seeds["candidates"] == seed
        top = np.concatenate([presented_top(tiny, i, seed) for i in range(3)])
        assert rate(hidden, f"fce_top{K}") == pytest.approx(bench.fc_passed[top].mean())
        assert rate(hidden, f"gsr_top{K}_full") < bench.p()[stored_top].mean()
    distinct = lookup(tiny, np.random.default_rng(5).random(tiny.benchmark.n))  # no ties
    one = make("classifier", benchmark=tiny, n_resamples=100, candidate_seed=0)
    other = make("classifier", benchmark=tiny, n_resamples=100, candidate_seed=1)
    assert one.evaluate(distinct).metrics == other.evaluate(distinct).metrics


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"bad_arg": 1}, "found unknown ['bad_arg']"),
        ({"k": 0}, "k: expected an integer >= 1, found 0"),
        ({"levels": ("full", "wind")}, "levels: expected distinct levels"),
        ({"levels": ()}, "levels: expected distinct levels"),
        ({"batch_size": 1.5}, "batch_size: expected an integer >= 1"),
    ],
)
def test_bad_arguments(tiny: BenchmarkRef, kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(EvaluatorError, match="expected") as info:
        make("classifier", benchmark=tiny, **kwargs)
    assert message in str(info.value)


def test_a_subject_that_is_not_a_classifier(evaluator: ClassifierEvaluator) -> None:
    with pytest.raises(EvaluatorError, match=r"expected a callable .* found builtins.int"):
        evaluator.evaluate(3)
