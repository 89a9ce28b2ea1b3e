"""A benchmark of real furniture that carries its meshes, used as a user would: the evaluators
score a submission against it and the environments pass both checkers, with no mesh folder
(``tests/data/real_tiny``: two objects of the real benchmark build, see its ATTRIBUTION.md)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")
gym = pytest.importorskip("gymnasium")

from gymnasium.utils.env_checker import check_env as gym_check_env  # noqa: E402

import dg16m_env  # noqa: E402, F401  (registers the environments)
from dg16m_env.benchmark.file import read_benchmark  # noqa: E402
from dg16m_env.evaluators import load_benchmark_ref, submission_evaluators  # noqa: E402

TINY_REAL = Path(__file__).parent / "data" / "real_tiny" / "benchmark.h5"


def test_the_file_carries_its_meshes_and_hulls() -> None:
    bench = read_benchmark(TINY_REAL)
    assert [o.object_id for o in bench.objects] == ["scopia-littlebank", "blendswap-cc-0-bench"]
    for obj in bench.objects:
        assert obj.has_mesh
        assert obj.parts
        loaded = obj.load()  # no mesh folder
        assert loaded.mesh.is_watertight
        np.testing.assert_allclose(loaded.mass_properties.center_of_mass, obj.center_of_mass)
    assert not (~bench.trials.valid).any()


@pytest.mark.parametrize("env_id", ["dg16m_env/DualGraspPose-v0", "dg16m_env/DualGraspSelect-v0"])
def test_environments_on_real_objects_pass_the_checker(env_id: str) -> None:
    env = gym.make(env_id, benchmark=TINY_REAL)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            gym_check_env(env.unwrapped)
    finally:
        env.close()


def test_evaluators_score_a_submission_on_real_objects(tmp_path: Path) -> None:
    pytest.importorskip("torch")
    from baselines.reference_submissions import write_reference_submissions

    ref = load_benchmark_ref(TINY_REAL)
    paths = write_reference_submissions(
        tmp_path, benchmark=ref, k=2, strategies=["benchmark_fc_pass"], progress=False
    )
    evaluators = submission_evaluators(["fce", "gsr"], ref, n_perturbations=1)
    fce = evaluators["fce"].evaluate(paths["benchmark_fc_pass"])
    gsr = evaluators["gsr"].evaluate(paths["benchmark_fc_pass"])
    # the benchmark's own passing pairs, re-closed on the carried meshes, pass again
    assert fce.metrics["fce"]["rate"] == pytest.approx(1.0)
    assert (fce.metrics["fce"]["rows"], fce.metrics["fce"]["objects"]) == (4, 2)
    assert gsr.metrics["gsr"]["rows"] == 4
    assert 0.0 <= gsr.metrics["gsr"]["rate"] <= 1.0


def test_classifier_evaluator_on_real_objects_needs_no_mesh_folder() -> None:
    pytest.importorskip("torch")
    from baselines.grasp_geometry import load_checkpoint
    from dg16m_env.evaluators import make

    evaluator = make("classifier", benchmark=TINY_REAL, k=5, progress=False)
    checkpoint = Path(__file__).parents[1] / "baselines" / "checkpoints" / "cgdf-dg16m.pt"
    classifier, _ = load_checkpoint(checkpoint)
    result = evaluator.evaluate(classifier)
    assert result.metrics["gsr_top5_full"]["rows"] == 10  # top 5 of each of the 2 objects
    assert 0.0 <= result.metrics["gsr_top5_full"]["rate"] <= 1.0
    assert 0.0 <= result.metrics["ap_full"]["rate"] <= 1.0


def test_meshes_are_stored_as_exact_decimals(tmp_path: Path) -> None:
    """An OBJ file's fixed-point coordinates go to int32 multiples (negative zeros apart) and
    come back bit for bit, so the mesh hashes hold; a file without the scale is refused."""
    import h5py

    from dg16m_env.benchmark.file import write_benchmark
    from dg16m_env.benchmark.model import BenchmarkError

    bench = read_benchmark(TINY_REAL)
    path = tmp_path / "again.h5"
    write_benchmark(path, bench)
    with h5py.File(path, "r") as f:
        assert f["objects/mesh_vertices"].dtype == np.int32
        assert f["objects/mesh_vertices"].attrs["decimals"] == 8
        assert len(f["objects/mesh_negative_zeros"]) > 0  # this file has some "-0.00000000"
    again = read_benchmark(path)
    for a, b in zip(bench.objects, again.objects, strict=True):
        assert a.mesh_vertices is not None
        assert b.mesh_vertices is not None
        assert a.mesh_vertices.tobytes() == b.mesh_vertices.tobytes()
        assert a.mesh_sha256 == b.mesh_sha256
    broken = tmp_path / "broken.h5"
    broken.write_bytes(path.read_bytes())
    with h5py.File(broken, "r+") as f:
        del f["objects/mesh_negative_zeros"]
    with pytest.raises(BenchmarkError, match="mesh bytes were changed"):
        read_benchmark(broken)
    with h5py.File(broken, "r+") as f:
        del f["objects/mesh_vertices"].attrs["decimals"]
    with pytest.raises(BenchmarkError, match="decimals"):
        read_benchmark(broken)


def test_a_mesh_off_any_decimal_grid_stays_float64(tmp_path: Path) -> None:
    import dataclasses

    import h5py

    from dg16m_env.benchmark.file import write_benchmark

    bench = read_benchmark(TINY_REAL)
    obj = bench.objects[0]
    assert obj.mesh_vertices is not None
    moved = obj.mesh_vertices + np.pi * 1e-12  # no longer a short decimal
    objects = [dataclasses.replace(obj, mesh_vertices=moved), *bench.objects[1:]]
    path = tmp_path / "float.h5"
    write_benchmark(path, dataclasses.replace(bench, objects=objects))
    with h5py.File(path, "r") as f:
        assert f["objects/mesh_vertices"].dtype == np.float64
        np.testing.assert_array_equal(f["objects/mesh_vertices"][: len(moved)], moved)
