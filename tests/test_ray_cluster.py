"""The Ray backend on a multi-node cluster that loses a node mid-run (issue 26).

A cluster on this machine, loopback only: a head node with no CPUs (it only schedules, so every
task runs on a worker node) and :data:`WORKER_NODES` worker nodes of one CPU each, started with
``ray.cluster_utils.Cluster`` (each node its own raylet and object store, as on separate
machines). Each command runs as its own driver process (``dg16m ... --backend ray --address``),
as a user runs it; while it runs one worker node is killed (``Cluster.remove_node``, no grace),
the run must finish on the node that is left (Ray re-runs the lost tasks) and its output must be
byte-identical to a local run of the same command. A killed driver's run is resumed by running
it again. Marked slow (a few minutes on two cores): ``pytest -m slow tests/test_ray_cluster.py``.

Ray resolves ``127.0.0.1`` in an address to the machine's outward IP unless
``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0`` (then a node's own address is the loopback); the tests
set it so that nothing listens beyond loopback. A real cluster needs nothing of the kind
(docs/ray_cluster.md).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from leaderboard_data import tree, valid_submission

from dataset_gen.pipeline.parallel import ParallelError, remove_stale_temporaries, run_resumable
from dg16m_core.atomic import write_bytes_atomic

REPO = Path(__file__).resolve().parents[1]
LOOPBACK = "127.0.0.1"
LOOPBACK_ENV = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"
WORKER_NODES = 2
RUN_TIMEOUT_S = 600.0

GENERATE_OBJECTS = 8
GENERATE = ["generate", "--procedural", str(GENERATE_OBJECTS), "--grasps", "200", "--no-progress"]
BUILD_OBJECTS = 4
BUILD = [
    "benchmark",
    "build",
    "--limit",
    str(BUILD_OBJECTS),
    "--perturbations",
    "1",
    "--no-progress",
]
BOARD_OBJECTS = 4


def driver_env() -> dict[str, str]:
    """The environment of a driver process: this one's, loopback-only Ray, unbuffered output."""
    return {**os.environ, LOOPBACK_ENV: "0", "PYTHONUNBUFFERED": "1"}


def dg16m(args: list[str], *, timeout: float = RUN_TIMEOUT_S) -> subprocess.CompletedProcess[str]:
    """Run ``dg16m ARGS`` as a process of its own; raises on a non-zero exit."""
    result = subprocess.run(
        [sys.executable, "-m", "dg16m_core.cli", *args],
        cwd=REPO,
        env=driver_env(),
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )
    assert result.returncode == 0, (
        f"dg16m {' '.join(args)}: expected exit 0, found {result.returncode}\n"
        f"{result.stdout[-2000:]}\n{result.stderr[-4000:]}"
    )
    return result


def manifest_entries(folder: Path) -> int:
    """Entries in ``folder/manifest.json`` so far (0 before the first; it is written atomically,
    so a read never sees half a file)."""
    path = folder / "manifest.json"
    if not path.is_file():
        return 0
    return len(json.loads(path.read_text(encoding="utf-8"))["entries"])


def retried_tasks(output: str) -> int:
    """Tasks Ray said it re-runs after their node died (the driver prints one line each, e.g.
    "Task _task failed. There are 3 retries remaining, so the task will be retried.")."""
    return sum(
        "retries remaining" in line or "will be retried" in line for line in output.splitlines()
    )


def stale_temporaries(folder: Path) -> list[str]:
    """What killed atomic writes left under ``folder`` (``.<name>.tmp-*``)."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob(".*.tmp-*"))


@dataclass
class Killed:
    """A driver run during which something was killed."""

    returncode: int
    output: str
    seconds: float  # the whole run
    killed_after_s: float  # from the start of the run to the kill
    progress_at_kill: int  # what ``progress()`` read just before the kill


def run_and_kill(
    args: list[str],
    progress: Callable[[], int],
    kill_at: int,
    kill: Callable[[subprocess.Popen[str]], bool],
) -> Killed:
    """Run ``dg16m ARGS`` as a driver; once ``progress()`` reaches ``kill_at``, call
    ``kill(driver)`` until it says it killed something; wait for the driver to exit."""
    start = time.perf_counter()
    with subprocess.Popen(
        [sys.executable, "-m", "dg16m_core.cli", *args],
        cwd=REPO,
        env=driver_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    ) as driver:
        killed_after = progress_at_kill = -1
        try:
            while driver.poll() is None and time.perf_counter() - start < RUN_TIMEOUT_S:
                done = progress()
                if killed_after < 0 and done >= kill_at and kill(driver):
                    progress_at_kill = done
                    killed_after = time.perf_counter() - start
                time.sleep(0.05)
            output, _ = driver.communicate(timeout=RUN_TIMEOUT_S)
        finally:
            if driver.poll() is None:
                driver.kill()
    return Killed(
        driver.returncode, output, time.perf_counter() - start, killed_after, progress_at_kill
    )


# --------------------------------------------------------------------------------------------
# The cluster
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def cluster() -> Iterator[Any]:
    """A head (0 CPUs) and :data:`WORKER_NODES` one-CPU worker nodes on loopback."""
    pytest.importorskip("ray")
    from ray._private import ray_constants
    from ray.cluster_utils import Cluster

    saved_env = os.environ.get(LOOPBACK_ENV)
    saved_flag = ray_constants.ENABLE_RAY_CLUSTER
    os.environ[LOOPBACK_ENV] = "0"  # the nodes' processes inherit it
    ray_constants.ENABLE_RAY_CLUSTER = False  # this process resolves loopback as loopback
    began = time.perf_counter()
    head = Cluster(
        initialize_head=True,
        head_node_args={"num_cpus": 0, "node_ip_address": LOOPBACK, "include_dashboard": False},
    )
    try:
        ensure_workers(head)
        print(f"\ncluster: head + {WORKER_NODES} nodes in {time.perf_counter() - began:.1f} s")
        yield head
    finally:
        head.shutdown()
        ray_constants.ENABLE_RAY_CLUSTER = saved_flag
        if saved_env is None:
            os.environ.pop(LOOPBACK_ENV, None)
        else:
            os.environ[LOOPBACK_ENV] = saved_env


def ensure_workers(cluster: Any, count: int = WORKER_NODES) -> None:
    """Add worker nodes until the cluster has ``count`` (a test may have killed one)."""
    while len(cluster.worker_nodes) < count:
        cluster.add_node(num_cpus=1, node_ip_address=LOOPBACK)
    cluster.wait_for_nodes()


RAY_SERVICES = ("ray::IDLE", "ray::DashboardAgent", "ray::RuntimeEnvAgent")
"""Process titles of a node's processes that are not running a task (a Ray worker running a
task is titled ``ray::<function>``)."""


def running_tasks(node: Any) -> list[str]:
    """The titles of ``node``'s worker processes that are running a task now (read from
    ``/proc``: the raylet's children titled ``ray::<function>``)."""
    from ray._private import ray_constants

    raylet = node.all_processes[ray_constants.PROCESS_TYPE_RAYLET][0].process.pid
    titles = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            parent = int((proc / "stat").read_text().rsplit(")", 1)[1].split()[1])
            title = (proc / "cmdline").read_bytes().split(b"\0")[0].decode(errors="replace")
        except (OSError, IndexError, ValueError):
            continue  # the process ended while it was read
        if parent == raylet and title.startswith("ray::") and title not in RAY_SERVICES:
            titles.append(title)
    return titles


def kill_a_busy_worker_node(cluster: Any) -> Callable[[subprocess.Popen[str]], bool]:
    """A ``kill`` for :func:`run_and_kill`: the first worker node that is running a task now,
    killed outright (raylet, object store and workers SIGKILLed); False while none is."""

    def kill(driver: subprocess.Popen[str]) -> bool:
        del driver
        for node in sorted(cluster.worker_nodes, key=lambda n: n.unique_id):
            if running_tasks(node):
                cluster.remove_node(node, allow_graceful=False)
                return True
        return False

    return kill


def kill_the_driver(driver: subprocess.Popen[str]) -> bool:
    """A ``kill`` for :func:`run_and_kill`: the driver, SIGKILL (its Ray tasks die with it)."""
    driver.send_signal(signal.SIGKILL)
    return True


# --------------------------------------------------------------------------------------------
# Stale temporary files (the fix; no Ray needed)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Item:
    object_id: str


def _task_leaving_a_temporary(item: _Item, root: str) -> dict[str, Any]:
    """Write ``files/<id>.bin``; for ``b`` first leave what a write killed half-way leaves (a
    retried attempt on Ray looks the same)."""
    folder = Path(root) / "files"
    if item.object_id == "b":
        folder.mkdir(parents=True, exist_ok=True)
        (folder / ".b.bin.tmp-killed.bin").write_bytes(b"half")
    write_bytes_atomic(folder / f"{item.object_id}.bin", item.object_id.encode())
    return {"status": "ok", "files": {"data": f"files/{item.object_id}.bin"}}


def test_a_finished_run_leaves_no_temporary_of_a_killed_attempt(tmp_path: Path) -> None:
    manifest = run_resumable(
        _task_leaving_a_temporary,
        [_Item("a"), _Item("b")],
        (str(tmp_path),),
        root=tmp_path,
        kind="objects",
        parameters={},
        folders=("files",),
        error=ParallelError,
        progress=False,
    )
    assert sorted(manifest["entries"]) == ["a", "b"]
    assert stale_temporaries(tmp_path) == []
    assert sorted(p.name for p in (tmp_path / "files").iterdir()) == ["a.bin", "b.bin"]
    (tmp_path / "files" / ".a.bin.tmp-x").write_bytes(b"")
    assert [p.name for p in remove_stale_temporaries(tmp_path, ("files", "absent"))] == [
        ".a.bin.tmp-x"
    ]


# --------------------------------------------------------------------------------------------
# On the cluster
# --------------------------------------------------------------------------------------------

_DYING_WRITER = """
import os, sys
from dataclasses import dataclass
from pathlib import Path

from dg16m_core.atomic import atomic_path
from dg16m_core.errors import Dg16mError
from dataset_gen.pipeline.parallel import run_resumable

@dataclass(frozen=True)
class Item:
    object_id: str

def task(item, root, marks):
    out = Path(root) / "files" / f"{item.object_id}.bin"
    first = not (Path(marks) / item.object_id).exists()
    (Path(marks) / item.object_id).touch()
    with atomic_path(out) as tmp:
        tmp.write_bytes(b"half")
        if item.object_id == "b" and first:
            os._exit(1)  # the worker dies in the middle of the write
        tmp.write_bytes(item.object_id.encode() * 1000)
    return {"status": "ok", "files": {"data": f"files/{item.object_id}.bin"}}

root, marks, address = sys.argv[1:]
manifest = run_resumable(
    task, [Item(i) for i in "abcd"], (root, marks), root=Path(root), kind="objects",
    parameters={}, folders=("files",), error=Dg16mError, backend="ray", address=address,
    progress=False,
)
print(sorted(manifest["entries"]))
"""


@pytest.mark.slow
def test_a_worker_killed_mid_write_is_retried_and_leaves_nothing(
    cluster: Any, tmp_path: Path
) -> None:
    """Ray re-runs a task whose worker died (a system failure); the file is written once,
    complete, and the dead attempt's temporary file is gone when the run returns."""
    root, marks = tmp_path / "out", tmp_path / "marks"
    marks.mkdir()
    script = textwrap.dedent(_DYING_WRITER)
    result = subprocess.run(
        [sys.executable, "-c", script, str(root), str(marks), cluster.address],
        cwd=REPO,
        env=driver_env(),
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT_S,
        check=False,
    )
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-4000:]
    assert "['a', 'b', 'c', 'd']" in result.stdout
    assert stale_temporaries(root) == []
    for name in "abcd":
        assert (root / "files" / f"{name}.bin").read_bytes() == name.encode() * 1000


@pytest.fixture(scope="module")
def local_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``dg16m generate`` on the local backend (one process): the reference bytes."""
    out = tmp_path_factory.mktemp("local") / "dataset"
    began = time.perf_counter()
    dg16m([*GENERATE, "--out", str(out)])
    print(f"\ngenerate local: {time.perf_counter() - began:.1f} s")
    return out


@pytest.mark.slow
def test_generate_survives_a_killed_worker_node(
    cluster: Any, local_dataset: Path, tmp_path: Path
) -> None:
    ensure_workers(cluster)
    out = tmp_path / "ray"
    run = run_and_kill(
        [*GENERATE, "--out", str(out), "--backend", "ray", "--address", cluster.address],
        lambda: manifest_entries(out),
        2,
        kill_a_busy_worker_node(cluster),
    )
    print(
        f"\ngenerate ray, {WORKER_NODES} nodes, one killed after {run.progress_at_kill} of "
        f"{GENERATE_OBJECTS} objects ({run.killed_after_s:.1f} s): {run.seconds:.1f} s, "
        f"{retried_tasks(run.output)} task(s) retried"
    )
    assert run.returncode == 0, run.output[-4000:]
    assert 0 <= run.progress_at_kill < GENERATE_OBJECTS - 1, "the kill came too late"
    assert retried_tasks(run.output) >= 1, f"expected a lost task retried, found {run.output}"
    assert len(cluster.worker_nodes) == WORKER_NODES - 1
    assert tree(out) == tree(local_dataset)


@pytest.mark.slow
def test_a_killed_driver_resumes_on_the_cluster(
    cluster: Any, local_dataset: Path, tmp_path: Path
) -> None:
    """The driver killed mid-run (its tasks die with it); the same command again finishes only
    the rest and the folder is byte-identical to the local run's."""
    ensure_workers(cluster)
    out = tmp_path / "ray"
    args = [*GENERATE, "--out", str(out), "--backend", "ray", "--address", cluster.address]
    run = run_and_kill(args, lambda: manifest_entries(out), 2, kill_the_driver)
    assert run.returncode == -signal.SIGKILL
    done = manifest_entries(out)
    assert 2 <= done < GENERATE_OBJECTS
    began = time.perf_counter()
    dg16m(args)
    print(
        f"\ngenerate ray, driver killed after {run.progress_at_kill} objects "
        f"({run.killed_after_s:.1f} s); rerun of the other {GENERATE_OBJECTS - done}: "
        f"{time.perf_counter() - began:.1f} s"
    )
    assert tree(out) == tree(local_dataset)


@pytest.mark.slow
def test_benchmark_build_survives_a_killed_worker_node(cluster: Any, tmp_path: Path) -> None:
    ensure_workers(cluster)
    local = tmp_path / "local"
    began = time.perf_counter()
    dg16m([*BUILD, "--out", str(local)])
    local_s = time.perf_counter() - began
    out = tmp_path / "ray"
    run = run_and_kill(
        [*BUILD, "--out", str(out), "--backend", "ray", "--address", cluster.address],
        lambda: manifest_entries(out),
        1,
        kill_a_busy_worker_node(cluster),
    )
    print(
        f"\nbenchmark build local: {local_s:.1f} s; ray, {WORKER_NODES} nodes, one killed after "
        f"{run.progress_at_kill} of {BUILD_OBJECTS} objects ({run.killed_after_s:.1f} s): "
        f"{run.seconds:.1f} s, {retried_tasks(run.output)} task(s) retried"
    )
    assert run.returncode == 0, run.output[-4000:]
    assert 0 <= run.progress_at_kill < BUILD_OBJECTS - 1, "the kill came too late"
    assert retried_tasks(run.output) >= 1, f"expected a lost task retried, found {run.output}"
    assert (out / "benchmark.h5").is_file()
    assert tree(out) == tree(local)


def _board(folder: Path, bench: Path, submission: Path) -> Path:
    """A board with one team and ``submission`` queued (through the command line)."""
    db = folder / "board.db"
    folder.mkdir(parents=True)
    dg16m(["leaderboard", "init", "--db", str(db), "--benchmark", str(bench)])
    dg16m(["leaderboard", "team", "add", "lab-a", "--db", str(db)])
    submit = ["leaderboard", "submit", str(submission), "--team", "lab-a", "--queue-only"]
    dg16m([*submit, "--label", "sub", "--db", str(db)])
    return db


def _board_view(db: Path) -> dict[str, Any]:
    """``dg16m leaderboard show --json`` without its clock readings (the page's time, each
    row's date)."""
    view = json.loads(dg16m(["leaderboard", "show", "--db", str(db), "--json"]).stdout)
    view.pop("generated_at", None)
    for evaluator in view["evaluators"]:
        for row in evaluator["rows"]:
            row.pop("date", None)
    return view


@pytest.mark.slow
def test_leaderboard_worker_survives_a_killed_worker_node(cluster: Any, tmp_path: Path) -> None:
    """``dg16m leaderboard worker --backend ray`` scores a job (fce, gsr) while a node dies; the
    board shows what a local worker's board shows."""
    from dg16m_env.benchmark.file import read_benchmark, write_benchmark
    from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK

    ensure_workers(cluster)
    shipped = read_benchmark(EMBEDDED_BENCHMARK)
    bench = tmp_path / "bench.h5"
    ids = [o.object_id for o in shipped.objects][:BOARD_OBJECTS]
    write_benchmark(bench, shipped.select_objects(ids))
    submission = valid_submission(tmp_path / "sub.h5", bench, k=10)
    worker = ["leaderboard", "worker", "--max-jobs", "1", "--idle-exit", "5"]

    local = _board(tmp_path / "local", bench, submission)
    began = time.perf_counter()
    dg16m([*worker, "--db", str(local)])
    local_s = time.perf_counter() - began

    remote = _board(tmp_path / "ray", bench, submission)
    claimed: list[float] = []
    lines: list[str] = []
    start = time.perf_counter()
    on_ray = ["--db", str(remote), "--backend", "ray", "--address", cluster.address]
    with subprocess.Popen(
        [sys.executable, "-m", "dg16m_core.cli", *worker, *on_ray],
        cwd=REPO,
        env=driver_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    ) as driver:
        assert driver.stdout is not None
        kill = kill_a_busy_worker_node(cluster)
        for line in driver.stdout:  # "#1: claimed (attempt 1)", later "#1: scored"
            lines.append(line)
            if "claimed" in line and not claimed:
                claimed.append(time.perf_counter() - start)
                while not kill(driver) and time.perf_counter() - start < RUN_TIMEOUT_S:
                    time.sleep(0.05)  # until an evaluator's task runs on a node
                claimed.append(time.perf_counter() - start)
        driver.wait(timeout=RUN_TIMEOUT_S)
    seconds = time.perf_counter() - start
    text = "".join(lines)
    print(
        f"\nleaderboard worker local: {local_s:.1f} s; ray, {WORKER_NODES} nodes, one killed "
        f"{claimed[-1] - claimed[0]:.1f} s after the claim: {seconds:.1f} s, "
        f"{retried_tasks(text)} task(s) retried"
    )
    assert driver.returncode == 0, text[-4000:]
    assert len(claimed) == 2, f"expected the job to be claimed, found {text[-2000:]}"
    assert retried_tasks(text) >= 1, f"expected a lost task retried, found {text[-4000:]}"
    assert "#1: scored" in text
    assert text.index("#1: scored") > text.index("claimed")
    assert _board_view(remote) == _board_view(local)
