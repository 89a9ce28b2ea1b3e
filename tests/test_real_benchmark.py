"""The real-object benchmark: its split, the build with admission rules, time budgets and
replacements, benchmark files that carry their meshes (and refuse changed ones), short
benchmark names, and ``dg16m reproduce --mesh-root``."""

from __future__ import annotations

import functools
import hashlib
import json
import os
import pickle
import signal
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
import trimesh

from dataset_gen.objects.decomposition import DecompositionParameters, object_parts
from dg16m_core.budget import (
    RLIMIT_MARGIN_S,
    WALL_FACTOR,
    StageCrashError,
    StageTimeoutError,
    run_with_budget,
)
from dg16m_core.cli import main as cli_main
from dg16m_core.errors import MeshError
from dg16m_env.benchmark.build import BuildLimits, build_benchmark
from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.model import SOURCES, BenchmarkError, BenchmarkParameters
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK, benchmark_file
from dg16m_env.benchmark.real import (
    REAL_SPLIT_FILE,
    build_real_benchmark,
    check_split,
    chosen_ids,
    make_split,
    read_split,
    real_sources,
    rejections,
    revise_split,
    ship_real_benchmark,
    with_membership,
)
from dg16m_env.benchmark.sources import mesh_benchmark_sources
from dg16m_env.physics.labels import PerturbationSpec

TINY = BenchmarkParameters(
    n_grasps=40,
    n_passing=3,
    n_failing=2,
    n_random=2,
    n_farthest=2,
    perturbation=PerturbationSpec(n_perturbations=1),
)


@pytest.fixture(autouse=True)
def coarse_parts(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Quick CoACD settings and a private cache (the faithful settings are tested elsewhere)."""
    from dg16m_env.benchmark import build as benchmark_build

    monkeypatch.setenv("DG16M_CACHE_DIR", str(tmp_path / "cache"))
    coarse = functools.partial(object_parts, params=DecompositionParameters(threshold=0.05))
    monkeypatch.setattr(benchmark_build, "object_parts", coarse)


def _plank(folder: Path, name: str, size: tuple[float, float, float] = (0.5, 0.05, 0.3)) -> Path:
    path = folder / f"{name}.obj"
    path.write_text(trimesh.creation.box(size).export(file_type="obj"), encoding="utf-8")
    return path


def _import_folder(
    folder: Path, objects: dict[str, tuple[str, tuple[float, float, float]]]
) -> Path:
    """An import folder as 'dg16m objects import-sweethome3d' writes it: meshes + manifest."""
    folder.mkdir(parents=True, exist_ok=True)
    entries = {}
    for object_id, (category, size) in objects.items():
        path = _plank(folder, object_id, size)
        entries[object_id] = {
            "status": "ok",
            "files": {"mesh": path.name},
            "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
            "source": {
                "object_id": object_id,
                "category": category,
                "library": "Scopia",
                "name": object_id.replace("-", " "),
                "model": f"scopia/{object_id}.obj",
                "creator": "Scopia",
                "licence": "CC-BY-3.0",
                "licence_files": [],
            },
            "modified": "a test box",
        }
    manifest = {
        "format": "dg16m-manifest",
        "schema_version": 1,
        "kind": "sweethome3d-import",
        "created_by": "test",
        "parameters": {},
        "entries": entries,
    }
    (folder / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    return folder


# --------------------------------------------------------------------------------------------
# The split
# --------------------------------------------------------------------------------------------


def _entries(counts: dict[str, int]) -> dict[str, Any]:
    out = {}
    for category, n in counts.items():
        for i in range(n):
            object_id = f"{category.lower()}-{i:02d}"
            out[object_id] = {
                "status": "ok",
                "sha256": f"{i:064x}",
                "source": {"object_id": object_id, "category": category},
            }
    out["broken"] = {"status": "failed", "error": "no volume", "source": {"category": "A"}}
    return out


def test_split_is_stratified_disjoint_and_seeded() -> None:
    entries = _entries({"A": 20, "B": 10, "C": 10})
    split = make_split(entries, size=10, seed=0)
    quotas = {c: v["quota"] for c, v in split["categories"].items()}
    assert quotas == {"A": 5, "B": 3, "C": 2} or quotas == {"A": 5, "B": 2, "C": 3}
    assert sum(quotas.values()) == 10
    assert len(split["benchmark"]) == 10
    assert not set(split["benchmark"]) & set(split["train"])
    assert len(split["benchmark"]) + len(split["train"]) == 40
    assert split["import_failed"] == {"broken": "no volume"}
    assert make_split(entries, size=10, seed=0) == split
    assert make_split(entries, size=10, seed=1)["benchmark"] != split["benchmark"]
    # a rejected object is replaced by the next of its category's order
    first_a = split["categories"]["A"]["order"][0]
    split["rejected"] = {first_a: {"stage": "screen", "reason": "too few passing pairs"}}
    replaced = with_membership(split)
    assert first_a not in replaced["benchmark"]
    assert first_a not in replaced["train"]
    assert split["categories"]["A"]["order"][5] in replaced["benchmark"]
    assert len(replaced["benchmark"]) == 10
    with pytest.raises(BenchmarkError, match="expected at least 50 imported objects, found 40"):
        make_split(entries, size=50)


def test_a_revised_import_keeps_the_orders_and_records_the_revision() -> None:
    entries = _entries({"A": 20, "B": 10})
    split = make_split(entries, size=10, seed=0)
    first_a = split["categories"]["A"]["order"][0]
    split["rejected"] = {first_a: {"stage": "screen", "reason": "too few passing pairs"}}
    split = with_membership(split)
    revised_entries = dict(entries)
    gone = split["categories"]["B"]["order"][0]  # its repair is now refused
    revised_entries[gone] = {"status": "failed", "error": "a fragment", "source": {}}
    changed = split["categories"]["A"]["order"][1]  # re-imported with other bytes
    revised_entries[changed] = {**entries[changed], "sha256": "f" * 64}
    for i in range(10):  # a new category of 10 objects
        revised_entries[f"l-{i:02d}"] = {
            "status": "ok",
            "sha256": f"{i:064x}",
            "source": {"object_id": f"l-{i:02d}", "category": "Lights"},
        }
    revised = revise_split(split, revised_entries, note="filter v2")
    for c in ("A", "B"):  # every order is a prefix of its revision
        old = split["categories"][c]["order"]
        assert revised["categories"][c]["order"][: len(old)] == old
    assert sorted(revised["categories"]["Lights"]["order"]) == [f"l-{i:02d}" for i in range(10)]
    assert revised["rejected"][gone]["stage"] == "import"
    assert revised["rejected"][gone]["error"] == "a fragment"
    assert revised["rejected"][first_a] == split["rejected"][first_a]
    assert revised["sha256"][changed] == "f" * 64
    assert {c: v["quota"] for c, v in revised["categories"].items()} == {
        "A": 5,
        "B": 2,
        "Lights": 3,
    }
    assert len(revised["benchmark"]) == 10
    assert gone not in revised["benchmark"] + revised["train"]
    assert revised["revisions"] == [
        {
            "revision": 1,
            "note": "filter v2",
            "added": [f"l-{i:02d}" for i in range(10)],
            "removed": [gone],
            "changed_sha256": [changed],
        }
    ]
    assert revise_split(split, revised_entries, note="filter v2") == revised  # seeded
    again = revise_split(revised, revised_entries, note="nothing new")
    assert again["revisions"][-1]["added"] == again["revisions"][-1]["removed"] == []
    assert again["categories"] == revised["categories"]


def test_split_check_refuses_overlap_and_other_files() -> None:
    split = make_split(_entries({"A": 6}), size=3)
    bad = {**split, "train": [*split["train"], split["benchmark"][0]]}
    with pytest.raises(BenchmarkError, match="expected disjoint benchmark and train ids"):
        check_split(bad)
    with pytest.raises(BenchmarkError, match="expected format 'dg16m-real-split'"):
        check_split({"format": "other"})


@pytest.mark.skipif(not REAL_SPLIT_FILE.is_file(), reason="no real split shipped")
def test_shipped_split_has_300_benchmark_ids_disjoint_from_training() -> None:
    split = read_split()
    assert len(split["benchmark"]) == 300
    assert len(set(split["benchmark"])) == 300
    assert not set(split["benchmark"]) & set(split["train"])
    assert set(split["benchmark"]) | set(split["train"]) <= set(split["sha256"])
    assert sum(c["quota"] for c in split["categories"].values()) == 300
    assert chosen_ids(split) == split["benchmark"]


# --------------------------------------------------------------------------------------------
# Time budgets
# --------------------------------------------------------------------------------------------


def _staged(seconds: float, fail: str = "", *, on_stage: Any) -> str:
    on_stage("quick")
    on_stage("slow")
    end = time.process_time() + seconds
    while time.process_time() < end:  # burn CPU: the budgets are CPU seconds
        pass
    if fail == "error":
        raise MeshError("a broken mesh")
    if fail == "crash":
        raise KeyError("a bug")
    if fail == "segv":  # compiled code crashing: no answer, a signal
        os.kill(os.getpid(), signal.SIGSEGV)
    if fail == "exit":
        os._exit(3)
    return "done"


def _sleeper(*, on_stage: Any) -> str:
    on_stage("waiting")
    time.sleep(60)
    return "woke"


def test_budget_stops_a_stage_that_runs_past_it() -> None:
    start = time.monotonic()
    with pytest.raises(
        StageTimeoutError, match="'slow' to finish within its budget of 1 CPU s, found it still"
    ) as e:
        run_with_budget(_staged, (60.0,), {"slow": 1.0})
    assert (e.value.stage, e.value.limit) == ("slow", "cpu")
    assert e.value.cpu_seconds >= 1.0  # the CPU seconds it had used
    assert time.monotonic() - start < 30  # killed, not waited for
    with pytest.raises(StageTimeoutError, match="wall-time safety net") as e:
        run_with_budget(_sleeper, (), {"waiting": 0.2})  # no CPU spent: the wall net stops it
    assert (e.value.stage, e.value.limit) == ("waiting", "wall")
    assert e.value.wall_s == pytest.approx(WALL_FACTOR * 0.2)
    assert e.value.cpu_seconds < 0.2
    # a stage that ends past its budget before the first poll is past it all the same
    with pytest.raises(StageTimeoutError, match="'slow' to finish within its budget") as e:
        run_with_budget(_staged, (0.5,), {"slow": 0.05}, poll_s=120.0)
    assert e.value.stage == "slow"
    done = run_with_budget(_staged, (0.0,), {"slow": 30.0})
    assert done.value == "done"
    assert set(done.times) == {"start", "quick", "slow"}
    with pytest.raises(MeshError, match="a broken mesh"):
        run_with_budget(_staged, (0.0, "error"), {})
    with pytest.raises(RuntimeError, match="KeyError: 'a bug'"):
        run_with_budget(_staged, (0.0, "crash"), {})


def test_budget_reports_a_crashed_child_and_the_kernels_cpu_limit() -> None:
    # a child killed by a signal, or ending without an answer, is a StageCrashError (a verdict
    # for the caller), not a RuntimeError
    with pytest.raises(StageCrashError, match=r"signal 11 \(SIGSEGV, segmentation fault\)") as e:
        run_with_budget(_staged, (0.3, "segv"), {"slow": 30.0})
    assert (e.value.stage, e.value.signal, e.value.exit_code) == ("slow", signal.SIGSEGV, None)
    assert e.value.cpu_seconds >= 0.3
    assert set(e.value.stage_times) == {"start", "quick", "slow"}
    again = pickle.loads(pickle.dumps(e.value))
    assert (again.stage, again.signal, again.cpu_seconds) == ("slow", 11, e.value.cpu_seconds)
    with pytest.raises(StageCrashError, match="exit status 3 and no answer") as e:
        run_with_budget(_staged, (0.0, "exit"), {})
    assert (e.value.signal, e.value.exit_code) == (None, 3)
    # the parent looks only every 120 s: the child's RLIMIT_CPU (budget + margin) stops it with
    # SIGXCPU, reported as its CPU budget, not as a crash
    with pytest.raises(StageTimeoutError) as e:
        run_with_budget(_staged, (60.0,), {"slow": 0.5}, poll_s=120.0)
    assert (e.value.stage, e.value.limit) == ("slow", "cpu")
    assert e.value.cpu_seconds == pytest.approx(0.5 + RLIMIT_MARGIN_S, abs=1.0)


# --------------------------------------------------------------------------------------------
# Files that carry their meshes
# --------------------------------------------------------------------------------------------


@pytest.fixture
def plank_build(tmp_path: Path) -> tuple[Path, Path]:
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    _plank(meshes, "plank")
    path = build_benchmark(mesh_benchmark_sources(meshes), tmp_path / "bench", TINY, progress=False)
    return path, meshes


def test_a_mesh_benchmark_carries_its_mesh_and_refuses_a_changed_one(
    plank_build: tuple[Path, Path],
) -> None:
    path, meshes = plank_build
    bench = read_benchmark(path)
    obj = bench.objects[0]
    assert obj.has_mesh
    carried = obj.load()  # no mesh folder needed
    from dataset_gen.objects.grasp_object import load_object

    from_folder = load_object(meshes / "plank.obj")
    np.testing.assert_array_equal(carried.mesh.vertices, from_folder.mesh.vertices)
    np.testing.assert_array_equal(carried.mesh.faces, from_folder.mesh.faces)
    # the hulls are stored as arrays, exactly (labels never depend on a re-run of CoACD)
    with h5py.File(path, "r") as f:
        assert f["objects/parts"][0] == b"[]"
        assert int(f["objects/hull_objects"][0]) == len(obj.parts)
    direct = object_parts(carried, params=DecompositionParameters(threshold=0.05))
    assert len(direct) == len(obj.parts)
    for a, b in zip(direct, obj.parts, strict=True):
        np.testing.assert_array_equal(a.vertices, b.vertices)
    copy = path.with_name("copy.h5")
    write_benchmark(copy, bench)
    assert copy.read_bytes() == path.read_bytes()
    # the object is the mesh the file carries: a changed file on disk does not relabel it
    changed = trimesh.creation.box((0.5, 0.06, 0.3)).export(file_type="obj")
    (meshes / "plank.obj").write_text(changed, encoding="utf-8")
    np.testing.assert_array_equal(obj.load(meshes).mesh.vertices, carried.mesh.vertices)
    # and so is a file whose carried mesh was edited
    with h5py.File(path, "r+") as f:
        vertices = f["objects/mesh_vertices"][()]
        vertices[0, 0] += 1e-3
        f["objects/mesh_vertices"][...] = vertices
    with pytest.raises(BenchmarkError, match="the mesh bytes were changed"):
        read_benchmark(path)


def test_admission_rule_rejects_an_object_without_enough_passing_pairs(tmp_path: Path) -> None:
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    _plank(meshes, "plank")
    _plank(meshes, "cube", (0.3, 0.3, 0.3))  # wider than the Panda hand opens
    limits = BuildLimits(min_passing=TINY.n_passing)
    out = tmp_path / "bench"
    path = build_benchmark(mesh_benchmark_sources(meshes), out, TINY, limits=limits, progress=False)
    manifest = json.loads((out / "manifest.json").read_text())
    cube = manifest["entries"]["cube"]
    assert cube["status"] == "failed"
    assert (cube["rejected"], cube["stage"]) == ("too few passing pairs", "screen")
    assert manifest["parameters"]["limits"]["min_passing"] == TINY.n_passing
    plank = manifest["entries"]["plank"]
    assert plank["arms"]["fc_pass"] == TINY.n_passing
    assert [o.object_id for o in read_benchmark(path).objects] == ["plank"]
    with pytest.raises(BenchmarkError, match="min_passing"):
        BuildLimits(min_passing=-1)


def test_real_build_replaces_rejected_objects_and_checks_hashes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    meshes = _import_folder(
        tmp_path / "import",
        {
            "a-cube": ("A", (0.3, 0.3, 0.3)),
            "a-plank": ("A", (0.5, 0.05, 0.3)),
            "b-plank": ("B", (0.4, 0.06, 0.3)),
        },
    )
    from dg16m_env.benchmark.real import import_entries

    split = make_split(import_entries(meshes), size=2, seed=0)
    # put the cube first in category A, so that it must be replaced
    split["categories"]["A"]["order"] = ["a-cube", "a-plank"]
    split = with_membership(split)
    assert split["benchmark"] == ["a-cube", "b-plank"]
    limits = BuildLimits(min_passing=TINY.n_passing)
    path, final = build_real_benchmark(
        meshes, tmp_path / "out", split=split, params=TINY, limits=limits, progress=False
    )
    assert final["benchmark"] == ["a-plank", "b-plank"]
    assert final["rejected"]["a-cube"]["stage"] == "screen"
    assert final["train"] == []
    # resumed from the same split, the folder's rejection stands: the cube is not built again
    import dg16m_env.benchmark.real as real_benchmark

    asked: list[str] = []

    def spy(sources, *args, **kwargs):
        asked.extend(s.object_id for s in sources)
        return build_objects(sources, *args, **kwargs)

    build_objects = real_benchmark.build_objects
    monkeypatch.setattr(real_benchmark, "build_objects", spy)
    _, resumed = build_real_benchmark(
        meshes, tmp_path / "out", split=split, params=TINY, limits=limits, progress=False
    )
    monkeypatch.undo()
    assert asked == ["a-plank", "b-plank"]
    assert resumed["benchmark"] == final["benchmark"]
    assert resumed["rejected"]["a-cube"] == final["rejected"]["a-cube"]
    bench = read_benchmark(path)
    assert [o.object_id for o in bench.objects] == ["a-plank", "b-plank"]
    assert all(o.has_mesh for o in bench.objects)
    assert set(np.unique(bench.source)) <= {SOURCES.index(a) for a in SOURCES}
    written = json.loads((tmp_path / "out" / "real_split.json").read_text())
    assert written["benchmark"] == ["a-plank", "b-plank"]
    attribution = (tmp_path / "out" / "ATTRIBUTION.md").read_text()
    assert "| a-plank | a plank (`scopia/a-plank.obj`) | Scopia |" in attribution
    assert "| b-plank |" in attribution
    assert "a-cube" not in attribution
    assert "CC-BY-3.0" in attribution
    assert "carries these 2 meshes" in attribution
    # shipping checks the build before it copies anything
    data = tmp_path / "data"
    with pytest.raises(BenchmarkError, match="expected 300 benchmark objects in the file"):
        ship_real_benchmark(tmp_path / "out", to=data)
    assert not data.exists()
    shipped = ship_real_benchmark(tmp_path / "out", to=data, size=2)
    assert [p.name for p in shipped] == ["benchmark_real.h5", "real_split.json", "ATTRIBUTION.md"]
    assert (data / "benchmark_real.h5").read_bytes() == path.read_bytes()
    (tmp_path / "out" / "ATTRIBUTION.md").write_text(attribution.replace("| b-plank |", "| x |"))
    with pytest.raises(BenchmarkError, match="expected a row for every benchmark object"):
        ship_real_benchmark(tmp_path / "out", to=tmp_path / "data2", size=2)
    # a mesh changed after the split was made is an error
    _plank(meshes, "b-plank", (0.4, 0.07, 0.3))
    with pytest.raises(BenchmarkError, match="the mesh changed since the split was made"):
        real_sources(meshes, ["b-plank"], split)
    # meshes not imported yet (a partial import) are all named, with the command that makes them
    with pytest.raises(
        BenchmarkError,
        match=r"found none for 2 \(x-one, x-two\); import them: "
        r"dg16m objects import-sweethome3d --out .* --ids x-one,x-two$",
    ):
        real_sources(meshes, ["b-plank", "x-one", "x-two"], split)
    # ... until the split is revised with the new bytes: the object is then built again, not
    # reused from the build folder
    manifest_path = meshes / "manifest.json"
    imported = json.loads(manifest_path.read_text())
    new_sha = hashlib.sha256((meshes / "b-plank.obj").read_bytes()).hexdigest()
    imported["entries"]["b-plank"]["sha256"] = new_sha
    manifest_path.write_text(json.dumps(imported))
    from dg16m_env.benchmark.real import import_entries as entries_of

    revised = revise_split(final, entries_of(meshes), note="b-plank re-imported")
    assert revised["revisions"][-1]["changed_sha256"] == ["b-plank"]
    path, _ = build_real_benchmark(
        meshes, tmp_path / "out", split=revised, params=TINY, limits=limits, progress=False
    )
    rebuilt = {o.object_id: o for o in read_benchmark(path).objects}
    assert rebuilt["b-plank"].load().mesh.extents[1] == pytest.approx(0.07)
    assert json.loads((tmp_path / "out" / "sources.json").read_text())["b-plank"] == new_sha


# --------------------------------------------------------------------------------------------
# Benchmarks by name
# --------------------------------------------------------------------------------------------


def test_benchmarks_by_short_name(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from dg16m_env.benchmark import names as benchmark_names

    assert benchmark_file(None) == EMBEDDED_BENCHMARK
    assert benchmark_file("procedural") == EMBEDDED_BENCHMARK
    assert benchmark_file(str(tmp_path / "x.h5")) == tmp_path / "x.h5"
    if benchmark_names.REAL_BENCHMARK.is_file():
        assert benchmark_file("real") == benchmark_names.REAL_BENCHMARK
    # an installation without the file says so, from Python and from the command line
    missing = {"procedural": EMBEDDED_BENCHMARK, "real": tmp_path / "absent" / "benchmark_real.h5"}
    monkeypatch.setattr(benchmark_names, "SHIPPED_BENCHMARKS", missing)
    with pytest.raises(BenchmarkError, match="installation lacks it"):
        benchmark_file("real")
    with pytest.raises(SystemExit) as exit_info:  # argparse refuses the argument
        cli_main(["benchmark", "info", "real"])
    assert exit_info.value.code == 2
    assert "installation lacks it" in capsys.readouterr().err


def test_reproduce_passes_the_mesh_root_on(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("torch")
    from baselines import reproduce

    seen: dict[str, Any] = {}

    def table2(out: Path, **kwargs: Any) -> dict[str, Any]:
        seen.update(kwargs)
        (Path(out) / "table2.md").parent.mkdir(parents=True, exist_ok=True)
        (Path(out) / "table2.md").write_text("table", encoding="utf-8")
        return {}

    monkeypatch.setattr(reproduce, "table2", table2)
    args = ["reproduce", "table2", "--out", str(tmp_path / "t2"), "--mesh-root", str(tmp_path)]
    assert cli_main(args) == 0
    assert seen["mesh_root"] == tmp_path


def test_decomposition_settings_are_recorded_and_read_back() -> None:
    from dg16m_env.benchmark.real import REAL_PARAMETERS

    data = json.loads(json.dumps(REAL_PARAMETERS.to_dict()))
    assert data["decomposition"]["mcts_iterations"] == 60
    assert BenchmarkParameters.from_dict(data) == REAL_PARAMETERS
    assert "decomposition" not in BenchmarkParameters().to_dict()  # older files keep their bytes
    with pytest.raises(BenchmarkError, match="decomposition"):
        BenchmarkParameters.from_dict({"decomposition": {"threshold": 0.01, "bogus": 1}})


def test_grid_hulls_are_what_is_simulated_and_stored(tmp_path: Path) -> None:
    from dataclasses import replace

    meshes = tmp_path / "meshes"
    meshes.mkdir()
    _plank(meshes, "plank")
    grid = 5e-5
    params = replace(TINY, hull_grid=grid)
    path = build_benchmark(mesh_benchmark_sources(meshes), tmp_path / "b", params, progress=False)
    with h5py.File(path, "r") as f:
        stored = f["objects/hull_vertices"]
        assert stored.dtype == np.int32
        assert stored.attrs["grid_m"] == grid
    bench = read_benchmark(path)
    assert bench.metadata["parameters"]["hull_grid"] == grid
    for part in bench.objects[0].parts:
        assert part.vertices is not None
        np.testing.assert_array_equal(part.vertices, np.round(part.vertices / grid) * grid)
    # the parts read back are the parts simulated: writing them again gives the same bytes
    again = tmp_path / "again.h5"
    write_benchmark(again, bench)
    assert again.read_bytes() == Path(path).read_bytes()
    with h5py.File(path, "r+") as f:  # a grid attribute removed is refused, not guessed
        del f["objects/hull_vertices"].attrs["grid_m"]
    with pytest.raises(BenchmarkError, match="grid_m"):
        read_benchmark(path)
    with pytest.raises(BenchmarkError, match="hull_grid"):
        BenchmarkParameters(hull_grid=-1.0)


def test_split_and_build_commands(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    meshes = _import_folder(
        tmp_path / "import",
        {"a-plank": ("A", (0.5, 0.05, 0.3)), "b-plank": ("B", (0.4, 0.06, 0.3))},
    )
    split = tmp_path / "split.json"
    args = ["benchmark", "split-real", "--meshes", str(meshes), "--out", str(split), "--size", "2"]
    assert cli_main(args) == 0
    assert "2 benchmark and 0 training objects" in capsys.readouterr().out
    assert read_split(split)["benchmark"] == ["a-plank", "b-plank"]
    assert (
        cli_main(["benchmark", "split-real", "--meshes", str(tmp_path), "--out", str(split)]) == 2
    )
    assert (
        "expected a folder written by 'dg16m objects import-sweethome3d'" in capsys.readouterr().err
    )


def test_a_category_that_runs_out_leaves_its_places_to_others() -> None:
    split = make_split(_entries({"A": 4, "B": 4, "C": 8}), size=8, seed=0)
    quotas = {c: v["quota"] for c, v in split["categories"].items()}
    assert quotas == {"A": 2, "B": 2, "C": 4}
    order_a = split["categories"]["A"]["order"]
    split["rejected"] = {i: {"stage": "screen"} for i in order_a[:3]}  # one A left
    chosen = chosen_ids(split)
    assert len(chosen) == 8
    assert [i for i in chosen if i.startswith("a-")] == [order_a[3]]
    assert sum(i.startswith("c-") for i in chosen) == 5  # C has the most left
    split["rejected"] = {
        i: {"stage": "screen"} for i in [*order_a, *split["categories"]["B"]["order"]]
    }
    assert len(chosen_ids(split)) == 8  # all from C
    split["rejected"].update(
        {i: {"stage": "screen"} for i in split["categories"]["C"]["order"][:2]}
    )
    assert len(chosen_ids(split)) == 6  # fewer objects left than places: all of them


def test_a_stage_past_its_budget_is_recorded_with_its_stage(tmp_path: Path) -> None:
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    _plank(meshes, "plank")
    limits = BuildLimits(min_passing=TINY.n_passing, label_s=1e-3)  # no trials fit in 1 ms
    out = tmp_path / "bench"
    with pytest.raises(BenchmarkError, match="found all failed: plank: expected stage 'label'"):
        build_benchmark(mesh_benchmark_sources(meshes), out, TINY, limits=limits, progress=False)
    entry = json.loads((out / "manifest.json").read_text())["entries"]["plank"]
    assert (entry["status"], entry["rejected"], entry["stage"]) == (
        "failed",
        "time budget",
        "label",
    )
    assert entry["error"].startswith("plank: expected stage 'label' to finish within its budget")
    assert {"screen", "decompose", "sample", "label"} <= set(entry["stage_seconds"])


def test_the_grid_leaves_out_the_slivers_it_flattens() -> None:
    from dataset_gen.objects.grasp_object import ConvexPart
    from dg16m_env.benchmark.build import grid_parts

    box = np.array([[x, y, z] for x in (0, 0.1) for y in (0, 0.1) for z in (0, 0.1)])
    sliver = box * [1e-5, 1, 1] + [0.2, 0, 0]  # 0.01 mm thick: one plane on a 0.05 mm grid
    parts = [ConvexPart("mesh", np.eye(4), (), v) for v in (box, sliver)]
    kept = grid_parts(parts, 5e-5, np.vstack([box, sliver]))
    assert len(kept) == 1
    np.testing.assert_array_equal(kept[0].vertices, np.round(box / 5e-5) * 5e-5)
    with pytest.raises(BenchmarkError, match="all 1 flattened"):
        grid_parts(parts[1:], 5e-5, sliver)


def test_a_built_object_with_coarse_hulls_is_rejected_and_replaced() -> None:
    """The per-object target (hull-to-mesh p95 <= 2 mm) is an admission rule: a built object
    over it is rejected at the decomposition stage, like a failed one, and others stay."""
    entries = {
        "a": {"status": "ok", "hull_deviation_mm": {"p95": 0.8}},
        "b": {"status": "ok", "hull_deviation_mm": {"p95": 2.23}},
        "c": {"status": "failed", "stage": "screen", "rejected": "too few passing pairs"},
    }
    found = rejections(entries, ["a", "b", "c", "d"])
    assert set(found) == {"b", "c"}
    assert found["b"]["stage"] == "decompose"
    assert found["b"]["reason"] == "hull deviation"
    assert "expected hull-to-mesh p95 <= 2 mm, found 2.23 mm" in found["b"]["error"]
    assert found["c"] == {"stage": "screen", "reason": "too few passing pairs", "error": ""}
