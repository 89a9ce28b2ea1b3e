"""The simulation benchmark: building, resuming, determinism, file schema, the shipped file."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

pytest.importorskip("mujoco")

from dataset_gen.io import read_manifest
from dataset_gen.pipeline.generate import GenerationParameters, generate_dataset
from dataset_gen.sources.object_source import procedural_sources
from dg16m_core.cli import main as cli_main
from dg16m_env.benchmark.build import benchmark_object, build_benchmark
from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.model import (
    FLOAT_SIM,
    SOURCES,
    Benchmark,
    BenchmarkError,
    BenchmarkParameters,
)
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK, SHIPPED_MUJOCO_VERSION
from dg16m_env.benchmark.sources import (
    file_benchmark_sources,
    procedural_benchmark_sources,
    read_split,
    retarget_poses,
)
from dg16m_env.physics.labels import PerturbationSpec
from dg16m_env.physics.trial_protocol import TrialResults, TrialStatus

SMALL = BenchmarkParameters(
    n_grasps=60,
    n_passing=6,
    n_failing=4,
    n_random=4,
    n_farthest=4,
    perturbation=PerturbationSpec(n_perturbations=2),
)


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("bench")
    build_benchmark(procedural_benchmark_sources(2), out, SMALL, progress=False)
    return out


def test_build_writes_labelled_mixed_pairs(built: Path) -> None:
    bench = read_benchmark(built / "benchmark.h5")
    assert [o.object_id for o in bench.objects] == [
        s.object_id for s in procedural_benchmark_sources(2)
    ]
    assert bench.n == len(bench.poses) == len(bench.trials.status)
    for k in range(2):
        rows = bench.object_index == k
        assert 14 <= rows.sum() <= 18
        assert set(bench.source[rows].tolist()) == {0, 1, 2, 3}, "the four arms"
    # Force-closure verdicts agree with the source of candidate pairs; failing candidates are
    # drawn from losses over the release's 0.5.
    assert bench.fc_passed[bench.source == SOURCES.index("fc_pass")].all()
    fc_fail = bench.source == SOURCES.index("fc_fail")
    assert not bench.fc_passed[fc_fail].any()
    assert (bench.fc_loss[fc_fail] > SMALL.failing_min_loss).all()
    # Labels: K + 1 trials per row, the nominal one first; p in steps of 1 / (K + 1).
    assert bench.labels.status.shape == (bench.n, 3)
    np.testing.assert_array_equal(bench.labels.status[:, 0], bench.trials.status)
    np.testing.assert_array_equal(bench.p() * 3, np.round(bench.p() * 3))
    assert (bench.p("gravity") >= bench.p()).all()
    # Every row carries a label; statuses are known codes; simulated rows have finite numbers.
    assert set(bench.trials.status.tolist()) <= {s.value for s in TrialStatus}
    ran = bench.trials.valid
    assert np.isfinite(bench.trials.max_displacement[ran]).all()
    assert (bench.trials.max_penetration[ran] < 1e-3).all()
    assert (bench.trials.status != TrialStatus.UNSTABLE).all()
    assert bench.objects[0].parts, "procedural parts are stored"
    summary = bench.summary()
    assert summary["pairs"] == bench.n
    assert json.dumps(summary)  # JSON-ready


def test_objects_rebuild_from_the_file(built: Path) -> None:
    bench = read_benchmark(built / "benchmark.h5")
    obj = bench.objects[0].load()
    assert obj.object_id == bench.objects[0].object_id
    assert len(obj.parts) == len(bench.objects[0].parts)


def test_rerun_resumes_and_gives_the_same_bytes(built: Path, tmp_path: Path) -> None:
    first = (built / "benchmark.h5").read_bytes()
    manifest = read_manifest(built)
    assert all(e["status"] == "ok" for e in manifest["entries"].values())
    # Resume: drop one object's result, rebuild only that one.
    copy = tmp_path / "copy"
    copy.mkdir()
    for rel in ["manifest.json", "objects"]:
        src = built / rel
        if src.is_dir():
            (copy / rel).mkdir()
            for f in src.iterdir():
                (copy / rel / f.name).write_bytes(f.read_bytes())
        else:
            (copy / rel).write_bytes(src.read_bytes())
    victim = next((copy / "objects").iterdir())
    victim.unlink()
    (copy / "objects" / ".stale.h5.tmp-x").write_bytes(b"partial")
    build_benchmark(procedural_benchmark_sources(2), copy, SMALL, progress=False)
    assert (copy / "benchmark.h5").read_bytes() == first
    assert not list((copy / "objects").glob(".*.tmp-*"))


def test_two_workers_give_the_same_bytes(built: Path, tmp_path: Path) -> None:
    build_benchmark(procedural_benchmark_sources(2), tmp_path, SMALL, workers=2, progress=False)
    assert (tmp_path / "benchmark.h5").read_bytes() == (built / "benchmark.h5").read_bytes()


def test_other_parameters_refuse_to_resume(built: Path) -> None:
    with pytest.raises(BenchmarkError, match="same parameters"):
        build_benchmark(
            procedural_benchmark_sources(2),
            built,
            BenchmarkParameters(n_grasps=60, n_passing=5, n_failing=4, n_random=4),
            progress=False,
        )


def test_write_read_round_trip(built: Path, tmp_path: Path) -> None:
    bench = read_benchmark(built / "benchmark.h5")
    path = tmp_path / "again.h5"
    write_benchmark(path, bench)
    again = read_benchmark(path)
    for name in ("object_index", "poses", "contact_points", "source", "fc_passed", "fc_loss"):
        np.testing.assert_array_equal(getattr(again, name), getattr(bench, name))
    for name in TrialResults.ARRAY_FIELDS:
        np.testing.assert_array_equal(getattr(again.trials, name), getattr(bench.trials, name))
    for name in ("status", "failing_phase", "seeds"):
        np.testing.assert_array_equal(getattr(again.labels, name), getattr(bench.labels, name))
    assert again.labels.spec == SMALL.perturbation
    assert path.read_bytes() == (built / "benchmark.h5").read_bytes()


def _corrupt(src: Path, dst: Path, edit) -> Path:
    dst.write_bytes(src.read_bytes())
    with h5py.File(dst, "r+") as f:
        edit(f)
    return dst


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda f: f.attrs.__setitem__("format", "nope"), "expected format"),
        (lambda f: f.attrs.__setitem__("schema_version", 99), "schema_version"),
        (lambda f: f.__delitem__("sim/status"), "sim/status"),
        (lambda f: f.__delitem__("labels/trial_status"), "labels/trial_status"),
        (lambda f: f["labels/p_success"].__setitem__(0, 0.123), "labels/p_success"),
        (lambda f: f["labels/trial_status"].__setitem__((0, 0), 3), "nominal"),
        (lambda f: f["labels/trial_status"].__setitem__((0, 1), 9), "TrialStatus codes"),
        (lambda f: f["labels/trial_phase"].__setitem__((0, 1), 14), "labels/trial_phase"),
        (lambda f: f["labels/label"].__setitem__(0, not f["labels/label"][0]), "labels/label"),
        (lambda f: f.attrs.__setitem__("schema_version", 1), "found 1: a version 1"),
        (lambda f: f["grasps/object_index"].__setitem__(0, 7), "object_index"),
        (lambda f: f["grasps/poses"].__setitem__((0, 0, 0, 0), np.nan), "finite"),
        (lambda f: f["grasps/source"].__setitem__(0, 42), "source"),
    ],
)
def test_malformed_files_are_rejected(built: Path, tmp_path: Path, edit, message: str) -> None:
    path = _corrupt(built / "benchmark.h5", tmp_path / "bad.h5", edit)
    with pytest.raises(BenchmarkError, match=message):
        read_benchmark(path)


def test_not_hdf5_is_rejected(tmp_path: Path) -> None:
    path = tmp_path / "x.h5"
    path.write_text("hello")
    with pytest.raises(
        BenchmarkError, match="expected an HDF5 file, found a file without the HDF5"
    ):
        read_benchmark(path)


def test_bad_parameters() -> None:
    with pytest.raises(BenchmarkError, match="n_grasps"):
        BenchmarkParameters(n_grasps=1)
    with pytest.raises(BenchmarkError, match="mu"):
        BenchmarkParameters(mu=-1.0)
    with pytest.raises(BenchmarkError, match="limit"):
        procedural_benchmark_sources(0)
    # The scene's friction follows mu.
    assert BenchmarkParameters(mu=0.5).scene.friction == 0.5


def test_split_parsing(tmp_path: Path) -> None:
    assert read_split("a, b,c") == ["a", "b", "c"]
    split = tmp_path / "split.txt"
    split.write_text("# objects\nmug_1\n\nbowl_2  # a comment\n")
    assert read_split(str(split)) == ["mug_1", "bowl_2"]
    with pytest.raises(BenchmarkError, match="expected object ids"):
        read_split(" , ")


def test_retarget_moves_contacts_to_the_panda_depth() -> None:
    pose = np.eye(4)
    moved = retarget_poses(pose[None], "robotiq_2f85")[0]
    # A contact at the 2F-85's depth along +y lands at the Panda's depth after the move.
    from dataset_gen.grasps.gripper import PANDA, ROBOTIQ_2F85

    contact = pose[:3, 3] + ROBOTIQ_2F85.contact_depth * pose[:3, 1]
    np.testing.assert_allclose(moved[:3, 3] + PANDA.contact_depth * moved[:3, 1], contact)


def test_benchmark_from_user_files(tmp_path: Path) -> None:
    """--meshes/--grasps: a generated dataset's files (meshes + DG16M files) as a user's own."""
    sources = procedural_sources([("board", 3)])
    generate_dataset(
        sources,
        tmp_path / "ds",
        GenerationParameters(n_grasps=40, max_passing=5, max_failing=5),
        progress=False,
    )
    items = file_benchmark_sources(tmp_path / "ds" / "meshes", tmp_path / "ds" / "grasps")
    assert [i.object_id for i in items] == [sources[0].object_id]
    bench = benchmark_object(items[0], SMALL)
    assert set(bench.source.tolist()) <= {SOURCES.index("file_pass"), SOURCES.index("file_fail")}
    assert bench.n <= 10
    # The mesh has no parts: it was decomposed (CoACD) and the parts are stored.
    assert bench.objects[0].parts
    assert bench.objects[0].family == ""
    with pytest.raises(BenchmarkError, match="expected grasp file"):
        file_benchmark_sources(tmp_path / "ds" / "meshes", tmp_path / "ds" / "grasps", ["nope"])


def test_cli_build_and_info(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        cli_main(
            [
                "benchmark",
                "build",
                "--out",
                str(tmp_path),
                "--limit",
                "1",
                "--perturbations",
                "2",
                "--no-progress",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "force-closure passing pairs" in out
    assert "benchmark.h5" in out
    assert (
        cli_main(
            [
                "benchmark",
                "info",
                str(tmp_path / "benchmark.h5"),
                "--json",
                "--plot",
                str(tmp_path / "s.png"),
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out.split("\nwrote")[0])
    assert summary["objects"] == 1
    assert summary["trials_per_pair"] == 3, "--perturbations 2: nominal + 2 trials per pair"
    assert "by_family" in summary
    assert (tmp_path / "s.png").stat().st_size > 10_000
    assert cli_main(["benchmark", "build", "--out", str(tmp_path), "--meshes", str(tmp_path)]) == 2
    assert "expected mesh files" in capsys.readouterr().err
    bad = ["benchmark", "build", "--out", str(tmp_path / "x"), "--perturbations", "-1"]
    assert cli_main(bad) == 2
    assert "--perturbations: n_perturbations: expected" in capsys.readouterr().err


CROSS_MACHINE_RTOL = 1e-6
CROSS_MACHINE_ATOL = 1e-9
"""Tolerance for floats recomputed on another machine than the one that wrote the stored file.

MuJoCo's (and numpy's) floating-point results can differ across CPUs in the last bits (11
of 100 rows of ``max_rotation_deg`` for table-1000000 differed by 7e-15 on another machine,
reported in issue 10; on an Intel Xeon all 30,000 shipped rows reproduced bit for bit:
BENCHMARKS.md, bench/reproduce_benchmark.py).
For a trial without contact chaos, as the one rebuilt here, such differences stay at rounding
level, far below 1e-6 relative; labels, statuses, phases, sources and poses must still be exact.
On the same machine every comparison is exact (see the worker, batch-size and resume tests).
A chaotic trial can move by up to ~1 mm after a contact event (BENCHMARKS.md): such objects are
not compared with this tolerance."""

EXACT_ROW_FIELDS = ("poses", "contact_points", "contact_normals", "source", "fc_passed")
"""Benchmark rows a rebuild must reproduce exactly on any machine: sampling and pairing are
seeded integer choices, and poses and contacts are stored from the same arithmetic."""

EXACT_TRIAL_FIELDS = (
    "status",
    "failing_phase",
    "invalid_reason",
    "contacts_after_close",
    "contacts_final",
    "ejected",
)
"""Trial results compared exactly across machines (labels and their discrete facts)."""


def assert_rebuilt(rebuilt: Benchmark, shipped: Benchmark, rows: np.ndarray) -> None:
    """``rebuilt`` (this machine) reproduces ``shipped`` rows ``rows`` (maybe another machine):
    discrete fields exactly, floats within the cross-machine tolerance."""
    for name in EXACT_ROW_FIELDS:
        np.testing.assert_array_equal(getattr(rebuilt, name), getattr(shipped, name)[rows], name)
    np.testing.assert_allclose(
        rebuilt.fc_loss, shipped.fc_loss[rows], rtol=CROSS_MACHINE_RTOL, atol=CROSS_MACHINE_ATOL
    )
    assert set(EXACT_TRIAL_FIELDS) | set(FLOAT_SIM) == set(TrialResults.ARRAY_FIELDS)
    for name in EXACT_TRIAL_FIELDS:
        np.testing.assert_array_equal(
            getattr(rebuilt.trials, name), getattr(shipped.trials, name)[rows], name
        )
    for name in ("status", "failing_phase", "seeds"):
        np.testing.assert_array_equal(
            getattr(rebuilt.labels, name), getattr(shipped.labels, name)[rows], name
        )
    for name in FLOAT_SIM:
        np.testing.assert_allclose(
            getattr(rebuilt.trials, name),
            getattr(shipped.trials, name)[rows],
            rtol=CROSS_MACHINE_RTOL,
            atol=CROSS_MACHINE_ATOL,
            err_msg=name,
        )


def test_installed_mujoco_is_the_release_that_simulated_the_shipped_files() -> None:
    """The shipped files' stored trials reproduce with one MuJoCo release only (4.0.1 flips
    labels: BENCHMARKS.md); the install pins it, and a new build records its own."""
    import mujoco

    pyproject = (Path(__file__).resolve().parents[1] / "pyproject.toml").read_text()
    assert f'"mujoco=={SHIPPED_MUJOCO_VERSION}"' in pyproject, "the sim extra pins that release"
    assert mujoco.__version__ == SHIPPED_MUJOCO_VERSION, (
        f"expected MuJoCo {SHIPPED_MUJOCO_VERSION} (the shipped benchmarks were simulated with "
        f"it; reinstall with `make setup`), found {mujoco.__version__}"
    )


def test_a_build_records_its_mujoco_version(built: Path) -> None:
    import mujoco

    assert read_benchmark(built / "benchmark.h5").metadata["mujoco"] == mujoco.__version__


@pytest.mark.skipif(not EMBEDDED_BENCHMARK.is_file(), reason="no shipped benchmark file")
def test_shipped_benchmark_is_reproduced_by_a_rebuild() -> None:
    """The shipped file was built on another machine: labels, statuses, phases, sources and poses
    exactly, floats within :data:`CROSS_MACHINE_RTOL` / :data:`CROSS_MACHINE_ATOL`."""
    shipped = read_benchmark(EMBEDDED_BENCHMARK)
    assert len(shipped.objects) == 300
    assert shipped.metadata["parameters"] == json.loads(
        json.dumps(BenchmarkParameters().to_dict())
    ), "the shipped file was built with the default parameters"
    assert shipped.parameters() == BenchmarkParameters()
    item = procedural_benchmark_sources(1)[0]
    rebuilt = benchmark_object(item, BenchmarkParameters())
    assert_rebuilt(rebuilt, shipped, shipped.object_rows(item.object_id))
    summary = shipped.summary(n_resamples=200)
    assert set(summary["by_arm"]) == {"fc_pass", "fc_fail", "random", "farthest"}
    gsr = {arm: row["full"]["gsr"]["rate"] for arm, row in summary["by_arm"].items()}
    assert gsr["fc_pass"] > gsr["random"]
    assert gsr["fc_pass"] > gsr["fc_fail"]
    assert summary["nominal_trials"]["unstable"] == 0
    assert summary["nominal_trials"]["ejected"] == 0
    # Penetration while held: under 1 mm for all but transient spikes when a slipping object
    # re-seats on a finger edge (measured in v2: 10 of 29,980 nominal trials; the deepest, 13.8
    # mm, in a trial that then failed; BENCHMARKS.md). No success rests on a deep penetration.
    depth = shipped.trials.max_penetration[shipped.trials.valid]
    assert np.mean(depth > 1e-3) < 1e-3
    assert shipped.trials.max_penetration[shipped.trials.success].max() < 5e-3
    # Every trial of a pair counts: statuses are known codes, no trial is unstable.
    assert set(np.unique(shipped.labels.status).tolist()) <= {0, 1, 2}


# --------------------------------------------------------------------------------------------
# One source of parameters, one constructor from metadata, one pair chooser
# --------------------------------------------------------------------------------------------


def test_defaults_are_the_papers() -> None:
    from dg16m_core.parameters import PAPER
    from dg16m_env.physics.scene import SceneParameters
    from dg16m_env.physics.success_probabilities import GraspJob
    from dg16m_env.physics.trial_protocol import TrialProtocol

    params = BenchmarkParameters()
    assert (params.mu, params.mass, params.f_high, params.threshold) == (
        PAPER.mu,
        PAPER.mass,
        PAPER.f_high,
        PAPER.threshold,
    )
    assert params.min_center_distance == PAPER.min_center_distance
    assert SceneParameters().friction == params.scene.friction == PAPER.mu
    assert SceneParameters().squeeze_force == PAPER.f_high
    assert TrialProtocol().gravity == PAPER.gravity
    assert GraspJob.__dataclass_fields__["mass"].default == PAPER.mass


def test_parameters_round_trip_through_metadata() -> None:
    params = BenchmarkParameters(seed=3, n_grasps=50, mu=0.5)
    stored = json.loads(json.dumps(params.to_dict()))  # what a file holds
    assert BenchmarkParameters.from_dict(stored) == params
    assert BenchmarkParameters.from_dict({}) == BenchmarkParameters()
    with pytest.raises(BenchmarkError, match=r"found unknown \['nope'\]"):
        BenchmarkParameters.from_dict({**stored, "nope": 1})
    with pytest.raises(BenchmarkError, match="scene parameters: expected keys among"):
        BenchmarkParameters.from_dict({**stored, "scene": {**stored["scene"], "frictoin": 1}})
    with pytest.raises(BenchmarkError, match="protocol: expected keys among"):
        BenchmarkParameters.from_dict({"protocol": {"gravity_s": 1.0}})
    with pytest.raises(BenchmarkError, match="timestep: expected a positive finite number"):
        BenchmarkParameters.from_dict({"scene": {"timestep": -1}})


def test_benchmark_parameters_come_from_its_metadata(built: Path) -> None:
    bench = read_benchmark(built / "benchmark.h5")
    assert bench.parameters() == SMALL
    assert bench.trials.protocol == SMALL.protocol


def _grasp_set(n_pass: int, n_fail: int):
    from dataset_gen.io import DualGraspSet

    n = n_pass + n_fail
    return DualGraspSet(
        grasps=np.tile(np.eye(4), (n, 2, 1, 1)),
        contact_points=np.zeros((n, 4, 3)),
        contact_forces=np.zeros((n, 4, 3)),
        loss_values=np.r_[np.zeros(n_pass), np.ones(n_fail)],
        passing_indices=np.arange(n_pass),
        failed_indices=np.arange(n_pass, n),
        object_file="x.obj",
        object_scale=1.0,
    )


def test_choose_file_pairs() -> None:
    from dg16m_env.benchmark.arms import choose_file_pairs

    data = _grasp_set(3, 20)
    # The benchmark's rule: a passing shortfall is filled with failing pairs.
    take_pass, take_fail = choose_file_pairs(data, 5, 4, np.random.default_rng(0))
    assert take_pass.tolist() == [0, 1, 2]
    assert take_fail.size == 6
    assert (np.diff(take_fail) > 0).all()
    assert set(take_fail.tolist()) <= set(range(3, 23))
    # `sim run --limit K`: at most K of each, no filling; None takes all.
    take_pass, take_fail = choose_file_pairs(data, 5, 4, np.random.default_rng(0), fill=False)
    assert (take_pass.size, take_fail.size) == (3, 4)
    take_pass, take_fail = choose_file_pairs(data, None, None, np.random.default_rng(0))
    assert (take_pass.size, take_fail.size) == (3, 20)
    # Seeded: the same stream gives the same pairs.
    again = choose_file_pairs(data, 2, 4, np.random.default_rng(7))
    np.testing.assert_array_equal(
        again[1], choose_file_pairs(data, 2, 4, np.random.default_rng(7))[1]
    )


def test_records_print_short(built: Path) -> None:
    bench = read_benchmark(built / "benchmark.h5")
    for thing in (bench, bench.objects[0], bench.trials):
        text = repr(thing)
        assert len(text) < 200, text
        assert "array(" not in text
    assert repr(bench.objects[0]).startswith(f"BenchmarkObject({bench.objects[0].object_id!r}")
    assert f"{bench.n} dual grasps" in repr(bench)


def test_summary_plot_does_not_touch_the_matplotlib_backend(
    built: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import matplotlib

    from dg16m_env.benchmark.report_plot import plot_summary

    def refuse(*args, **kwargs):
        raise AssertionError("library code called matplotlib.use")

    monkeypatch.setattr(matplotlib, "use", refuse)
    plot_summary(read_benchmark(built / "benchmark.h5"), tmp_path / "s.png")
    assert (tmp_path / "s.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
