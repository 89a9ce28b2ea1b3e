"""The evaluator registry, results, and the ``fce`` / ``gsr`` evaluators on a 3-object benchmark."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dataset_gen.io import package_version
from dg16m_core.errors import Dg16mError
from dg16m_core.hashing import file_sha256
from dg16m_env import evaluators
from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.evaluators import (
    EvaluationResult,
    Evaluator,
    EvaluatorError,
    ResultError,
    load_benchmark_ref,
    make,
    read_results,
    register,
    write_results,
)
from dg16m_env.evaluators.fce import REASONS
from dg16m_env.evaluators.registry import _REGISTRY
from dg16m_env.subjects.submission import Submission

OBJECTS = ("table-1000000", "bench-1000003", "crate-1000006")


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A 3-object benchmark file cut from the shipped one, and its reference."""
    path = tmp_path_factory.mktemp("bench") / "small.h5"
    write_benchmark(path, read_benchmark(EMBEDDED_BENCHMARK).select_objects(list(OBJECTS)))
    return load_benchmark_ref(path)


def _rows(ref, object_id, arm, k):
    bench = ref.benchmark
    rows = bench.object_rows(object_id)
    return rows[bench.arm_rows(arm)[rows]][:k]


def _submission(ref, arm="fc_pass", k=4):
    return Submission(
        poses={i: ref.benchmark.poses[_rows(ref, i, arm, k)] for i in ref.object_ids},
        benchmark=ref.sha256,
    )


def _far(poses, distance=5.0):
    out = np.array(poses, copy=True)
    out[..., :3, 3] += distance
    return out


# ---------------------------------------------------------------------------------------------
# Registry


def test_builtins_are_registered():
    assert {"fce", "gsr"} <= set(evaluators.names())


def test_unknown_name_lists_the_known_ones():
    with pytest.raises(EvaluatorError, match=r"expected one of .*fce.*gsr.*found 'fcee'"):
        make("fcee")


def test_unknown_argument_is_refused(small):
    with pytest.raises(EvaluatorError, match=r"fce: expected arguments among .*found unknown"):
        make("fce", benchmark=small, perturbations=3)


def test_register_a_custom_evaluator_and_refuse_bad_ones():
    try:

        @register("constant_test")
        class Constant(Evaluator):
            version = "7"

            def __init__(self, *, value: float = 0.5) -> None:
                self.value = value

            def evaluate(self, subject):
                return EvaluationResult(
                    "constant_test",
                    self.version,
                    package_version(),
                    {},
                    {},
                    {},
                    {},
                    "x",
                    {"x": self.value},
                )

        assert "constant_test" in evaluators.names()
        assert make("constant_test", value=0.25)(None).score == 0.25
        with pytest.raises(EvaluatorError, match="already registered"):

            @register("constant_test")
            class Other(Evaluator):
                version = "1"

                def evaluate(self, subject):
                    raise AssertionError

    finally:
        _REGISTRY.pop("constant_test", None)
    with pytest.raises(EvaluatorError, match="expected a subclass of Evaluator"):
        register("not_an_evaluator")(dict)
    with pytest.raises(EvaluatorError, match="expected a lower-case identifier"):
        register("Bad Name")

    class NoVersion(Evaluator):
        def evaluate(self, subject):
            raise AssertionError

    with pytest.raises(EvaluatorError, match="non-empty version"):
        register("no_version")(NoVersion)


# ---------------------------------------------------------------------------------------------
# fce


def test_fce_of_the_benchmarks_passing_pairs_is_one(small):
    result = make("fce", benchmark=small).evaluate(_submission(small))
    assert result.score == 1.0
    assert result.details["reasons"] == {"pass": 12}
    assert set(result.per_family) == {"table", "bench", "crate"}
    assert result.per_object["crate-1000006"] == {"grasps": 4, "fce": 1.0, "reasons": {"pass": 4}}


def test_fce_counts_every_failure_with_its_reason(small):
    sub = _submission(small)
    poses = {i: np.array(p, copy=True) for i, p in sub.poses.items()}
    table = poses["table-1000000"]
    table[0] = _far(table[0])  # both hands far away: the jaws close on nothing
    table[1, 1] = table[1, 0]  # both hands at one pose: they overlap
    inside = table[2, 0].copy()
    inside[:3, 3] = 0.0  # a hand at the centre of mass: the open gripper collides
    table[2, 0] = inside
    result = make("fce", benchmark=small).evaluate(Submission(poses=poses))
    reasons = result.per_object["table-1000000"]["reasons"]
    assert reasons["miss"] == 1
    assert reasons["hands_overlap"] == 1
    assert reasons["collision"] + reasons.get("too_wide", 0) == 1
    assert reasons["pass"] == 1
    # Failures stay in the denominator: 1 of 4 on the table, 9 of 12 overall.
    assert result.per_object["table-1000000"]["fce"] == 0.25
    assert result.metrics["fce"]["rate"] == pytest.approx(9 / 12)
    assert result.details["object_mean"]["fce"] == pytest.approx((0.25 + 1 + 1) / 3)
    assert result.metrics["fce"]["rows"] == 12
    assert sum(result.details["reasons"].values()) == 12
    assert set(result.details["reasons"]) <= set(REASONS)


def test_fce_refuses_a_submission_for_other_objects(small):
    sub = _submission(small)
    poses = dict(sub.poses)
    poses["ghost-1"] = poses.pop("table-1000000")
    with pytest.raises(EvaluatorError, match=r"1 missing .*table-1000000.*1 unknown .*ghost-1"):
        make("fce", benchmark=small).evaluate(Submission(poses=poses))
    with pytest.raises(EvaluatorError, match="expected a Submission or a submission file"):
        make("fce", benchmark=small).evaluate(42)


# ---------------------------------------------------------------------------------------------
# gsr


def test_gsr_of_the_benchmarks_own_rows_is_their_stored_probability(small):
    """Rows submitted in their stored order get their stored seeds, hence exactly their p."""
    bench = small.benchmark
    sub = Submission(poses={i: bench.poses[bench.object_rows(i)[:5]] for i in small.object_ids})
    result = make("gsr", benchmark=small).evaluate(sub)
    for object_id in small.object_ids:
        stored = bench.p("full")[bench.object_rows(object_id)[:5]]
        assert result.per_object[object_id]["gsr"] == pytest.approx(stored.mean(), abs=1e-12)
        gravity = bench.p("gravity")[bench.object_rows(object_id)[:5]]
        assert result.per_object[object_id]["gsr_gravity"] == pytest.approx(gravity.mean())
    assert result.details["trials"] == 15 * 9
    assert result.seeds == {"perturbation": 0, "resample": 0}


def test_gsr_counts_invalid_and_unsimulatable_grasps_as_failures(small, monkeypatch):
    """The denominator rule: invalid trials and objects that cannot be simulated count as 0,
    and the valid-only rate is reported beside the headline."""
    sub = _submission(small, k=2)
    poses = {i: np.array(p, copy=True) for i, p in sub.poses.items()}
    table = poses["table-1000000"]
    table[0, 0, :3, 3] = 0.0  # an open hand at the centre of mass: the trial is invalid
    import dg16m_env.physics.success_probabilities as success_probabilities

    real = success_probabilities.evaluate_object

    def broken(job, *args, **kwargs):
        if job.object_id == "crate-1000006":
            raise Dg16mError("mesh: expected a watertight mesh, found a broken one")
        return real(job, *args, **kwargs)

    monkeypatch.setattr(success_probabilities, "evaluate_object", broken)
    result = make("gsr", benchmark=small, n_perturbations=1).evaluate(Submission(poses=poses))
    assert result.failures == {
        "crate-1000006": "mesh: expected a watertight mesh, found a broken one"
    }
    per = result.per_object
    assert per["crate-1000006"]["gsr"] == 0.0
    assert per["crate-1000006"]["gsr_valid"] is None  # nothing ran there
    assert result.details["nominal"]["invalid"] == 1
    total = sum(per[i]["gsr"] * per[i]["grasps"] for i in per)
    assert result.metrics["gsr"]["rate"] == pytest.approx(total / 6)
    assert result.metrics["gsr"]["rows"] == 6
    assert result.metrics["gsr_valid"]["rows"] == 3  # the invalid grasp and the crate's two
    assert result.metrics["gsr_valid"]["rate"] >= result.metrics["gsr"]["rate"]


def test_gsr_is_deterministic_and_records_what_reproduces_it(small, tmp_path):
    sub = _submission(small, k=2)
    first = make("gsr", benchmark=small, n_perturbations=1, perturbation_seed=3).evaluate(sub)
    second = make("gsr", benchmark=small, n_perturbations=1, perturbation_seed=3).evaluate(sub)
    assert json.dumps(first.to_dict()) == json.dumps(second.to_dict())
    assert first.benchmark["sha256"] == file_sha256(small.path)
    assert first.package_version == package_version()
    assert first.evaluator_version == "1"
    assert first.parameters["perturbation"]["n_perturbations"] == 1
    assert first.seeds["perturbation"] == 3
    path = write_results(tmp_path / "r.json", {"gsr": first}, {"kind": "submission"})
    back = read_results(path)
    assert back["gsr"].to_dict() == first.to_dict()


def test_read_results_refuses_other_files(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ResultError, match="expected a JSON results file"):
        read_results(bad)
    bad.write_text(json.dumps({"format": "other"}))
    with pytest.raises(ResultError, match="expected format 'dg16m-evaluation'"):
        read_results(bad)
    with pytest.raises(ResultError, match="found missing"):
        EvaluationResult.from_dict({"evaluator": "fce"})


def test_fce_and_gsr_do_not_depend_on_workers(small):
    sub = _submission(small, k=2)
    for name, extra in (("fce", {}), ("gsr", {"n_perturbations": 1})):
        one = make(name, benchmark=small, **extra).evaluate(sub)
        two = make(name, benchmark=small, workers=2, **extra).evaluate(sub)
        assert json.dumps(one.to_dict()) == json.dumps(two.to_dict())


@pytest.mark.slow
def test_fce_and_gsr_on_ray_match_the_local_pool(small):
    pytest.importorskip("ray")
    sub = _submission(small, k=2)
    for name, extra in (("fce", {}), ("gsr", {"n_perturbations": 1})):
        local = make(name, benchmark=small, **extra).evaluate(sub)
        ray = make(name, benchmark=small, backend="ray", **extra).evaluate(sub)
        assert json.dumps(local.to_dict()) == json.dumps(ray.to_dict())
