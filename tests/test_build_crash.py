"""Every mesh ends with a verdict (issue 55): a child that crashes in CoACD is that object's
rejection while the folder's other objects are built; CoACD is tried once more with its next
seed; a resumed build keeps a rejection whose inputs and settings are unchanged
(``--retry-rejected`` redoes it); ``--stage-budget`` sets the CPU budgets; a killed child leaves
no semaphore behind; ``objects decompose`` stops on Ctrl-C inside CoACD."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import pytest
import trimesh

pytest.importorskip("mujoco")

from test_build_stopping import default_sigint

from dataset_gen.io import new_manifest, read_manifest, write_manifest
from dg16m_core.cli import EXIT_INTERRUPTED
from dg16m_core.cli import main as cli_main
from dg16m_env.benchmark import build
from dg16m_env.benchmark.build import BuildLimits
from dg16m_env.benchmark.model import BenchmarkError
from dg16m_env.benchmark.sources import mesh_benchmark_sources
from dg16m_env.benchmark.verdicts import input_digest, kept_rejections

STOP_WITHIN_S = 5.0


def crash_in_decompose(
    item: Any,
    params: Any,
    simulator: Any,
    min_passing: int,
    decompose_fallback: bool = False,
    *,
    on_stage: Any,
) -> Any:
    """The build's child work, except that objects named ``crash*`` kill their child with
    SIGSEGV on entering the decomposition (as CoACD did on a thin vase); ``*_once`` only with
    the build's own settings, not with the fallback's. Each call is logged in ``calls.txt``
    beside the mesh. Module level: the spawned child imports it by name."""
    with open(Path(item.source.mesh).parent / "calls.txt", "a", encoding="utf-8") as log:
        log.write(f"{item.object_id} {int(decompose_fallback)}\n")
    if item.object_id.startswith("crash") and not (
        item.object_id.endswith("_once") and decompose_fallback
    ):
        on_stage("load")
        on_stage("decompose")
        os.kill(os.getpid(), signal.SIGSEGV)
    return build._budgeted_object(
        item, params, simulator, min_passing, decompose_fallback, on_stage=on_stage
    )


def _calls(folder: Path) -> list[str]:
    path = folder / "calls.txt"
    return path.read_text(encoding="utf-8").splitlines() if path.is_file() else []


@pytest.fixture
def crashing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A folder of ``a_box`` (built) and ``crash_me`` (its child segfaults in CoACD, also with
    the fallback), built by children that run :func:`crash_in_decompose`."""
    monkeypatch.setenv("DG16M_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(build, "_budgeted_object", crash_in_decompose)
    folder = tmp_path / "meshes"
    folder.mkdir()
    trimesh.creation.box((0.1, 0.04, 0.3)).export(folder / "a_box.obj")
    trimesh.creation.box((0.1, 0.05, 0.2)).export(folder / "crash_me.obj")
    return folder


def _build(folder: Path, out: Path, *extra: str) -> list[str]:
    return [
        *("benchmark", "build", "--meshes", str(folder), "--out", str(out)),
        *("--mesh-settings", "plain", "--perturbations", "0", "--no-progress", *extra),
    ]


def test_a_crash_in_coacd_is_a_verdict_the_others_are_built_and_a_resume_keeps_it(
    crashing: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    assert cli_main(_build(crashing, out)) == 1  # a rejection: exit 1, the others built
    printed = capsys.readouterr().out
    assert "1 objects failed and are left out of the benchmark:" in printed
    assert (
        "  failed crash_me: rejected at stage decompose: its convex decomposition (CoACD) "
        "crashed with signal 11 (SIGSEGV, segmentation fault) after "
    ) in printed
    assert "Traceback" not in printed
    entries = read_manifest(out)["entries"]
    assert entries["a_box"]["status"] == "ok"
    assert (out / "benchmark.h5").is_file()
    entry = entries["crash_me"]
    assert (entry["status"], entry["rejected"], entry["stage"]) == (
        "failed",
        "crashed",
        "decompose",
    )
    assert entry["signal"] == signal.SIGSEGV
    assert "exit_code" not in entry
    assert entry["cpu_seconds"] >= 0.0
    # the fallback (CoACD's next seed) was tried once, within the budget, and crashed too
    assert entry["decompose_fallback"] == {
        "tried": True,
        "worked": False,
        "settings": build.FALLBACK_WORDS,
        "outcome": "it crashed too",
    }
    assert "tried again with CoACD's next seed" in entry["verdict"]
    assert "dg16m objects repair" in entry["verdict"]
    assert _calls(crashing).count("crash_me 0") == 1
    assert _calls(crashing).count("crash_me 1") == 1
    # A resume keeps the verdict (same mesh bytes, same settings) and says so.
    assert cli_main(_build(crashing, out)) == 1
    printed = capsys.readouterr().out
    assert "kept the verdict of 1 objects from the earlier run" in printed
    assert "--retry-rejected to redo them" in printed
    assert "failed crash_me: rejected at stage decompose" in printed
    assert _calls(crashing).count("crash_me 0") == 1, "redone on resume"
    assert read_manifest(out)["entries"]["crash_me"] == entry
    # --retry-rejected redoes it.
    assert cli_main(_build(crashing, out, "--retry-rejected")) == 1
    assert "kept the verdict" not in capsys.readouterr().out
    assert _calls(crashing).count("crash_me 0") == 2


@pytest.mark.slow
def test_the_decomposition_fallback_admits_an_object_coacd_crashed_on_once(
    crashing: Path, tmp_path: Path
) -> None:
    (crashing / "crash_me.obj").unlink()
    trimesh.creation.box((0.08, 0.05, 0.2)).export(crashing / "crash_once.obj")
    out = tmp_path / "out"
    assert cli_main(_build(crashing, out)) == 0
    entry = read_manifest(out)["entries"]["crash_once"]
    assert entry["status"] == "ok"
    assert entry["decompose_fallback"] == {
        "tried": True,
        "worked": True,
        "settings": build.FALLBACK_WORDS,
        "outcome": "it decomposed the mesh",
    }
    assert build.fallback_decomposition(build.BenchmarkParameters()).seed == 1


def test_kept_rejections_need_the_same_inputs_settings_and_a_load_free_verdict(
    tmp_path: Path,
) -> None:
    folder = tmp_path / "meshes"
    folder.mkdir()
    for name in ("budget", "wall", "old", "ok", "changed"):
        trimesh.creation.box((0.1, 0.05, 0.2)).export(folder / f"{name}.obj")
    items = mesh_benchmark_sources(folder)
    digest = {item.object_id: input_digest(item) for item in items}
    rejected = {"status": "failed", "files": {}, "error": "x", "rejected": "time budget"}
    manifest = new_manifest("benchmark", {"seed": 0})
    manifest["entries"] = {
        "budget": {**rejected, "limit": "cpu", "input_sha256": digest["budget"]},
        "wall": {**rejected, "limit": "wall", "input_sha256": digest["wall"]},  # load: redone
        "old": rejected,  # written before the digest: redone once
        "ok": {"status": "ok", "files": {}},
        "changed": {**rejected, "limit": "cpu", "input_sha256": digest["changed"]},
    }
    out = tmp_path / "out"
    out.mkdir()
    write_manifest(out, manifest)
    trimesh.creation.box((0.1, 0.05, 0.3)).export(folder / "changed.obj")
    assert set(kept_rejections(out, items, {"seed": 0})) == {"budget"}
    assert kept_rejections(out, items, {"seed": 1}) == {}  # other settings: refused anyway
    assert kept_rejections(tmp_path / "nothing", items, {"seed": 0}) == {}


def test_stage_budgets_from_the_command_line(tmp_path: Path) -> None:
    limits = BuildLimits(decompose_s=180.0).with_stage_budgets(
        ["decompose=600", "label=30", "sample=2.5", "label=40"]
    )
    assert (limits.decompose_s, limits.sample_s, limits.label_s) == (600.0, 2.5, 40.0)
    assert limits.budgets() == {"screen": 2.5, "decompose": 600.0, "sample": 2.5, "label": 40.0}
    with pytest.raises(
        BenchmarkError, match=r"expected one of decompose, sample, label .*found 'screen'"
    ):
        BuildLimits().with_stage_budgets(["screen=5"])
    with pytest.raises(BenchmarkError, match="expected STAGE=SECONDS"):
        BuildLimits().with_stage_budgets(["600"])
    with pytest.raises(BenchmarkError, match="expected CPU seconds > 0, found '-1'"):
        BuildLimits().with_stage_budgets(["label=-1"])
    code = cli_main(
        [
            *("benchmark", "build", "--meshes", str(tmp_path), "--out", str(tmp_path / "o")),
            "--stage-budget",
            "trials=5",
        ]
    )
    assert code == 2


_LEAK_SCRIPT = textwrap.dedent(
    """
    import multiprocessing, sys, time
    sys.path.insert(0, {tests!r})
    from dg16m_core.budget import StageTimeoutError, run_with_budget
    from test_build_crash import holds_a_semaphore

    if __name__ == "__main__":
        # Python 3.14's default on Linux (and macOS's spawn): semaphores are named and
        # registered with the resource tracker
        multiprocessing.set_start_method("forkserver", force=True)
        try:
            run_with_budget(holds_a_semaphore, (), {{"hold": 0.5}}, poll_s=0.1)
        except StageTimeoutError as exc:
            print("stopped", exc.limit)
    """
)


def holds_a_semaphore(*, on_stage: Any) -> None:
    """A child that makes a multiprocessing lock (as tqdm does for its bars) and then spins
    past its budget, so that it is killed holding it."""
    import multiprocessing

    on_stage("hold")
    lock = multiprocessing.RLock()
    while lock:
        pass


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="forkserver, /proc (Linux)")
def test_a_child_killed_at_its_budget_leaks_no_semaphore(tmp_path: Path) -> None:
    script = tmp_path / "leak.py"
    script.write_text(_LEAK_SCRIPT.format(tests=str(Path(__file__).parent)), encoding="utf-8")
    done = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert "stopped cpu" in done.stdout
    assert "leaked semaphore" not in done.stderr, done.stderr


def thin_vase() -> trimesh.Trimesh:
    from test_build_stopping import thin_vase as vase

    return vase()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc (Linux)")
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["sigint", "sigterm"])
def test_objects_decompose_stops_inside_coacd(signum: int, tmp_path: Path) -> None:
    thin_vase().export(tmp_path / "vase.obj")
    command = [
        str(Path(sys.executable).parent / "dg16m"),
        *("objects", "decompose", str(tmp_path / "vase.obj"), "--no-cache"),
    ]
    process = subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=os.environ,
        preexec_fn=default_sigint,
    )
    try:
        time.sleep(6.0)  # the child is in CoACD now (the vase takes it tens of seconds)
        assert process.poll() is None, process.communicate()
        process.send_signal(signum)
        sent = time.monotonic()
        stdout, stderr = process.communicate(timeout=60)
        took = time.monotonic() - sent
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert took < STOP_WITHIN_S, stderr
    assert process.returncode == EXIT_INTERRUPTED, stdout + stderr
    assert "Traceback" not in stderr
    assert "leaked semaphore" not in stderr
