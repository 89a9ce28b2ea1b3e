"""Every command that runs CoACD stops on Ctrl-C and SIGTERM within seconds (issue 55, item 3):
``dg16m generate --meshes`` with one worker and ``dg16m sim run --mesh`` run CoACD in a child
process (:func:`dataset_gen.objects.decomposition.convex_decomposition` with ``stoppable``), which
gives the same parts as CoACD run in-process; a cache hit starts no child; a crash of CoACD's
child is the object's verdict."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh
from test_build_stopping import STOP_WITHIN_S, _alive, _descendants, default_sigint, thin_vase

from dataset_gen.io import read_manifest
from dataset_gen.objects import decomposition as dec
from dg16m_core.budget import process_cpu_seconds
from dg16m_core.cli import EXIT_INTERRUPTED
from dg16m_core.cli import main as cli_main

PARAMS = dec.DecompositionParameters(threshold=0.05)
"""A coarse threshold: the L-shape below decomposes in a fraction of a second."""


def l_shape() -> trimesh.Trimesh:
    """A watertight L-shaped block (10 x 10 x 5 cm, arms 3 cm wide): not convex, 32 faces."""
    arm = trimesh.creation.box((0.1, 0.03, 0.05))
    arm.apply_translation((0.05, 0.015, 0.0))
    other = trimesh.creation.box((0.03, 0.1, 0.05))
    other.apply_translation((0.015, 0.05, 0.0))
    mesh = arm.union(other)
    assert mesh.is_watertight
    return mesh


def _refuse(*args: Any, **kwargs: Any) -> Any:
    raise AssertionError("expected CoACD not to run in this process")


def test_parts_from_the_child_are_those_computed_here_and_a_cache_hit_starts_no_child(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    mesh = l_shape()
    here = dec.convex_decomposition(mesh, params=PARAMS, use_cache=False)
    assert len(here) >= 2, "expected a non-convex mesh"
    with monkeypatch.context() as patch:
        patch.setattr(dec, "_compute", _refuse)  # the child imports the module afresh
        stats: dict[str, Any] = {}
        child = dec.convex_decomposition(
            mesh, params=PARAMS, cache_dir=tmp_path, name="l", stats=stats, stoppable=True
        )
    assert stats["cache_hit"] is False
    assert len(child) == len(here)
    for a, b in zip(here, child, strict=True):
        assert (a.kind, b.kind) == ("mesh", "mesh")
        assert np.array_equal(a.vertices, b.vertices)
        assert np.array_equal(a.pose, b.pose)
    with monkeypatch.context() as patch:  # the parts come from the cache: no child, no CoACD
        patch.setattr(dec, "_compute_stoppable", _refuse)
        patch.setattr(dec, "_compute", _refuse)
        again = dec.convex_decomposition(
            mesh, params=PARAMS, cache_dir=tmp_path, stats=stats, stoppable=True
        )
    assert stats["cache_hit"] is True
    assert all(np.array_equal(a.vertices, b.vertices) for a, b in zip(here, again, strict=True))


def test_a_pool_worker_runs_coacd_itself() -> None:
    """Its parent stops it by ending it, so a child of its own would only cost a second."""
    assert not dec._is_a_worker()
    with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as pool:
        assert pool.submit(dec._is_a_worker).result(timeout=120)


def segfault_for_crash_meshes(
    vertices: np.ndarray,
    faces: np.ndarray,
    params: dec.DecompositionParameters,
    label: str,
    preprocess_mode: str,
    *,
    on_stage: Any,
) -> Any:
    """CoACD's child, except that it kills itself with SIGSEGV (as CoACD did on a thin vase)
    for objects named ``crash*``. Module level: the spawned child imports it by name."""
    on_stage("decompose")
    if label.startswith("crash"):
        os.kill(os.getpid(), signal.SIGSEGV)
    return dec._compute(vertices, faces, params, label, preprocess_mode)


def test_a_crash_of_coacd_fails_its_object_and_generate_goes_on(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("DG16M_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(dec, "_compute_in_child", segfault_for_crash_meshes)
    folder = tmp_path / "meshes"
    folder.mkdir()
    l_shape().export(folder / "a_block.obj")
    l_shape().apply_scale(1.2).export(folder / "crash_me.obj")  # not the cached one
    out = tmp_path / "out"
    argv = ["generate", "--meshes", str(folder), "--out", str(out), "--grasps", "40"]
    assert cli_main([*argv, "--no-progress"]) == 1  # one object failed
    entries = read_manifest(out)["entries"]
    assert entries["a_block"]["status"] == "ok"
    assert entries["crash_me"]["status"] == "failed"
    assert entries["crash_me"]["error"].startswith(
        "crash_me: the convex decomposition (CoACD) crashed (expected stage 'decompose' to end "
        "with an answer from its worker process, found it killed by signal 11 (SIGSEGV"
    )
    assert entries["crash_me"]["error"].endswith(dec.CRASH_ADVICE)
    assert "Traceback" not in capsys.readouterr().err


@pytest.fixture(scope="module")
def vase_and_grasps(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A folder holding the thin vase (tens of seconds of CoACD) and a DG16M file (of a box)
    for ``sim run`` to read its scale and poses from."""
    root = tmp_path_factory.mktemp("coacd_stopping")
    (root / "vase").mkdir()
    thin_vase().export(root / "vase" / "vase.obj")
    (root / "box").mkdir()
    trimesh.creation.box((0.1, 0.04, 0.3)).export(root / "box" / "box.obj")
    command = [str(Path(sys.executable).parent / "dg16m"), "generate", "--meshes"]
    command += [str(root / "box"), "--out", str(root / "dataset"), "--grasps", "40"]
    env = {**os.environ, "DG16M_CACHE_DIR": str(root / "cache")}
    done = subprocess.run(
        [*command, "--no-progress"], capture_output=True, text=True, env=env, timeout=240
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return root / "vase", root / "dataset" / "grasps" / "box.h5"


def _stop_inside_coacd(command: list[str], signum: int, cache: Path) -> tuple[int, str, float]:
    """Run ``command``, send ``signum`` once a child of it has used 2 CPU s (it is in CoACD:
    its imports take about 1 s), and return its exit status, output and the seconds it took
    to end; check that none of its processes outlived it."""
    env = {**os.environ, "DG16M_CACHE_DIR": str(cache)}
    process = subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
        preexec_fn=default_sigint,
    )
    try:
        started = time.monotonic()
        while True:
            assert process.poll() is None, process.communicate()[0]
            assert time.monotonic() - started < 120, "expected CoACD's child within 2 minutes"
            below = _descendants(process.pid)
            if any((process_cpu_seconds(pid) or 0.0) >= 2.0 for pid in below):
                break
            time.sleep(0.2)
        process.send_signal(signum)
        sent = time.monotonic()
        output = process.communicate(timeout=60)[0]
        took = time.monotonic() - sent
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    deadline = time.monotonic() + STOP_WITHIN_S
    while any(_alive(pid) for pid in below) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [pid for pid in below if _alive(pid)], "a child outlived the command"
    return process.returncode, output, took


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc (Linux)")
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["sigint", "sigterm"])
@pytest.mark.parametrize("command", ["generate", "sim"])
def test_a_signal_stops_generate_and_sim_inside_coacd(
    command: str, signum: int, vase_and_grasps: tuple[Path, Path], tmp_path: Path
) -> None:
    vase, grasps = vase_and_grasps
    dg16m = str(Path(sys.executable).parent / "dg16m")
    if command == "generate":
        argv = [dg16m, "generate", "--meshes", str(vase), "--out", str(tmp_path / "out")]
        argv += ["--workers", "1", "--no-progress"]
    else:
        argv = [dg16m, "sim", "run", str(grasps), "--mesh", str(vase / "vase.obj")]
        argv += ["--limit", "2", "--perturbations", "0"]
    code, output, took = _stop_inside_coacd(argv, signum, tmp_path / "cache")
    assert took < STOP_WITHIN_S, output
    assert code == EXIT_INTERRUPTED, output
    assert f"dg16m {command}: interrupted" in output
    assert "Traceback" not in output
    assert "leaked semaphore" not in output
    if command == "generate":  # nothing finished, nothing half-written
        assert not list((tmp_path / "out").rglob("*.h5"))
        assert not list((tmp_path / "out").rglob(".*.tmp-*"))
