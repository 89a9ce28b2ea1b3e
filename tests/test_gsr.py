"""GSR core: many objects' dual grasps, parallel, same results for any worker count."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

from dataset_gen.sources.object_source import ObjectSource, procedural_sources
from dg16m_env.benchmark.file import read_benchmark
from dg16m_env.benchmark.model import Benchmark
from dg16m_env.physics.labels import PerturbationSpec
from dg16m_env.physics.success_probabilities import (
    GraspJob,
    GsrError,
    evaluate_objects,
    jobs_from_mapping,
)
from dg16m_env.physics.trial_protocol import TrialResults


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[GraspJob], Benchmark]:
    from dg16m_env.benchmark.build import build_benchmark
    from dg16m_env.benchmark.model import BenchmarkParameters
    from dg16m_env.benchmark.sources import procedural_benchmark_sources

    out = tmp_path_factory.mktemp("gsr")
    params = BenchmarkParameters(
        n_grasps=50,
        n_passing=4,
        n_failing=3,
        n_random=2,
        n_farthest=2,
        perturbation=PerturbationSpec(n_perturbations=1),
    )
    bench = read_benchmark(
        build_benchmark(procedural_benchmark_sources(2), out, params, progress=False)
    )
    sources = {
        s.object_id: s for s in procedural_sources([(o.family, o.seed) for o in bench.objects])
    }
    poses = {o.object_id: bench.poses[bench.object_rows(o.object_id)] for o in bench.objects}
    return jobs_from_mapping(poses, sources), bench


@pytest.fixture(scope="module")
def jobs(built: tuple[list[GraspJob], Benchmark]) -> list[GraspJob]:
    return built[0]


def test_results_match_the_benchmark_labels_for_any_worker_count(
    built: tuple[list[GraspJob], Benchmark],
) -> None:
    jobs, bench = built
    spec = bench.labels.spec
    one = evaluate_objects(jobs, spec=spec)
    two = evaluate_objects(jobs, spec=spec, workers=2)
    assert list(one.results) == sorted(j.object_id for j in jobs)
    for object_id, result in one.results.items():
        rows = bench.object_rows(object_id)
        # The benchmark's per-row seeds are (spec.seed, object id): the same labels.
        np.testing.assert_array_equal(result.status, bench.labels.status[rows])
        np.testing.assert_array_equal(result.p_success, bench.p()[rows])
        for name in TrialResults.ARRAY_FIELDS:
            np.testing.assert_array_equal(
                getattr(result.nominal, name), getattr(two.results[object_id].nominal, name)
            )
    assert one.success_rate() == pytest.approx(float(bench.p().mean()))
    assert 0.0 <= one.success_rate() <= one.success_rate("gravity") <= 1.0
    assert one.summary()["objects"] == 2


def test_a_broken_object_fails_alone(jobs: list[GraspJob], tmp_path) -> None:
    broken = tmp_path / "broken.obj"
    broken.write_text("v 0 0 0\nf 1 1 1\n")
    bad = GraspJob(ObjectSource("broken", mesh=broken), jobs[0].poses)
    result = evaluate_objects([*jobs, bad], spec=PerturbationSpec(n_perturbations=1))
    assert "broken" in result.errors
    assert set(result.results) == {j.object_id for j in jobs}
    # The broken object's grasps stay in the denominator, as failures.
    won = sum(float(r.p_success.sum()) for r in result.results.values())
    total = sum(len(j.poses) for j in jobs) + len(bad.poses)
    assert result.submitted["broken"] == len(bad.poses)
    assert result.success_rate() == pytest.approx(won / total)
    assert result.success_rate_valid() >= result.success_rate()


def test_duplicate_ids_and_missing_sources_are_rejected(jobs: list[GraspJob]) -> None:
    with pytest.raises(GsrError, match="unique object ids"):
        evaluate_objects([jobs[0], jobs[0]])
    with pytest.raises(GsrError, match="expected a source"):
        jobs_from_mapping({"nope": np.eye(4)[None, None].repeat(2, 1)}, {})


def test_a_job_takes_a_procedural_id_or_a_source() -> None:
    job = GraspJob("table-1000000", np.zeros((0, 2, 4, 4)))
    assert job.source == procedural_sources([("table", 1000000)])[0]
    assert job.object_id == "table-1000000"
    with pytest.raises(GsrError, match="expected an ObjectSource or a procedural object id"):
        GraspJob("chair", np.zeros((0, 2, 4, 4)))
    with pytest.raises(GsrError, match="found int"):
        GraspJob(3, np.zeros((0, 2, 4, 4)))  # type: ignore[arg-type]
