"""The paper's Table III ordering on a slice of the benchmark: random < farthest < force-closure
pairing, on FCE and on GSR (20 objects, 5 dual grasps each, 2 perturbed trials)."""

from __future__ import annotations

from baselines.reference_submissions import write_reference_submissions
from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.evaluators import load_benchmark_ref, make


def test_pairing_baselines_order_as_in_table_iii(tmp_path):
    bench = read_benchmark(EMBEDDED_BENCHMARK)
    ids = [o.object_id for o in bench.objects[::15]]  # 20 objects, 2 of each family
    write_benchmark(tmp_path / "b.h5", bench.select_objects(ids))
    ref = load_benchmark_ref(tmp_path / "b.h5")
    strategies = ("random", "farthest", "force_closure")
    paths = write_reference_submissions(
        tmp_path / "refs", benchmark=ref, k=5, workers=2, strategies=strategies, progress=False
    )
    scores = {}
    for name in strategies:
        fce = make("fce", benchmark=ref, workers=2).evaluate(paths[name]).score
        gsr = make("gsr", benchmark=ref, workers=2, n_perturbations=2).evaluate(paths[name])
        scores[name] = (fce, gsr.score, gsr.metrics["gsr_gravity"]["rate"])
    for metric in range(3):
        values = [scores[name][metric] for name in strategies]
        assert values == sorted(values), (metric, scores)
        assert values[0] < values[2]
