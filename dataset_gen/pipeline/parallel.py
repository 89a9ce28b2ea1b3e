"""Run one task per object on a local process pool or on Ray, yielding results as they finish.

Both backends call the same top-level function ``task(item, *args)``; the caller records each
result by object id, so the outcome never depends on completion order. Used by the generator
(:mod:`dataset_gen.pipeline.generate`) and the packages built on it (e.g. the simulation benchmark).

Ctrl-C stops a run promptly: the local pool's workers are terminated at once (a task cut short
leaves at most a temporary file, removed by the next run; its object is done again), and an
interrupt that lands where Python ignores exceptions (a weakref callback, a ``__del__``) is
remembered and raised after the task it interrupted (:func:`run_resumable`).
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal, Protocol, TypeVar

from dataset_gen.io import new_manifest, read_manifest, write_manifest
from dg16m_core.errors import Dg16mError
from dg16m_core.stopping import die_with_parent, sigterm_interrupts

Backend = Literal["local", "ray"]
BACKENDS: tuple[str, ...] = ("local", "ray")

Item = TypeVar("Item")
Result = TypeVar("Result")


RAY_MAX_RETRIES = 3
"""Ray re-runs a task whose worker or node died up to this many times (Ray's default, stated
here because the results depend on it: every task is a pure function of its item and writes its
files atomically, so a re-run writes the same bytes). An exception raised by the task itself is
never retried."""


class HasObjectId(Protocol):
    @property
    def object_id(self) -> str: ...


ObjectItem = TypeVar("ObjectItem", bound=HasObjectId)


class ParallelError(Dg16mError, ValueError):
    """Bad backend arguments (worker count, backend name, missing Ray)."""


def check_backend(backend: str, workers: int, error: type[Dg16mError] = ParallelError) -> None:
    """Raise ``error`` unless ``backend`` is known and ``workers >= 1``."""
    if not isinstance(workers, int) or workers < 1:
        raise error(f"--workers: expected an integer >= 1, found {workers!r}")
    if backend not in BACKENDS:
        raise error(f"--backend: expected one of {BACKENDS}, found {backend!r}")


def run_tasks(
    task: Callable[..., Result],
    items: Sequence[Item],
    args: tuple[Any, ...] = (),
    *,
    workers: int = 1,
    backend: Backend = "local",
    address: str | None = None,
) -> Iterator[tuple[Item, Result]]:
    """Yield ``(item, task(item, *args))`` for every item, in completion order.

    Args:
        task: a module-level function (it is pickled to the workers).
        items: the work, one item per task.
        args: extra arguments passed to every call (picklable).
        workers: local processes; 1 runs in this process (``backend="local"``).
        backend: ``"local"`` or ``"ray"``.
        address: Ray address (``"auto"`` or ``host:port``); None starts a local Ray on loopback.
    """
    check_backend(backend, workers)
    if backend == "ray":
        yield from _ray(task, items, args, address)
    elif workers == 1:
        for item in items:
            yield item, task(item, *args)
    else:
        yield from _pool(task, items, args, workers)


def _pool(
    task: Callable[..., Result], items: Sequence[Item], args: tuple[Any, ...], workers: int
) -> Iterator[tuple[Item, Result]]:
    # workers die with this process and leave Ctrl-C to it (it stops them)
    pool = ProcessPoolExecutor(
        max_workers=workers, initializer=die_with_parent, initargs=(os.getpid(),)
    )
    try:
        pending: dict[Future[Result], Item] = {}
        queue = list(items)
        while queue or pending:
            while queue and len(pending) < 2 * workers:
                item = queue.pop(0)
                pending[pool.submit(task, item, *args)] = item
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                yield pending.pop(future), future.result()
    except BaseException:  # Ctrl-C, an error, or the caller stopped reading: stop now
        stop_pool(pool)
        raise
    pool.shutdown(wait=True)


def stop_pool(pool: ProcessPoolExecutor, timeout_s: float = 5.0) -> None:
    """Cancel what has not started and terminate the workers, without waiting for the tasks
    they run (``shutdown(wait=True)`` would let each finish, and write its files, first)."""
    workers = getattr(pool, "_processes", None)  # CPython's worker processes: pid -> Process
    processes = list(workers.values()) if isinstance(workers, dict) else []
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(timeout_s)


@contextmanager
def remembered_interrupts() -> Iterator[Callable[[], bool]]:
    """While inside, Ctrl-C raises ``KeyboardInterrupt`` as usual and is also remembered; the
    callable says whether one came. A loop checks it between tasks, so an interrupt that Python
    swallowed (raised inside a weakref callback or ``__del__``: "Exception ignored in ...")
    still stops the run. Only in the main thread and with Python's own SIGINT handler in place;
    elsewhere nothing changes."""
    previous = signal.getsignal(signal.SIGINT)
    if (
        threading.current_thread() is not threading.main_thread()
        or previous is not signal.default_int_handler
    ):
        yield lambda: False
        return
    seen: list[int] = []

    def handler(signum: int, frame: Any) -> None:
        seen.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)
    try:
        yield lambda: bool(seen)
    finally:
        signal.signal(signal.SIGINT, previous)


RAY_CONNECT_TIMEOUT_S = 10.0
"""How long :func:`check_ray_address` waits for a Ray head's port to answer (s)."""


def check_ray_address(address: str, timeout_s: float = RAY_CONNECT_TIMEOUT_S) -> None:
    """Refuse a ``host:port`` where no Ray head answers, within ``timeout_s`` (``ray.init``
    itself retries for minutes); ``"auto"`` and ``ray://`` addresses are left to Ray.

    Raises:
        ParallelError: not ``host:port``, a host that does not resolve, or a port that does not
            accept a connection in time.
    """
    import socket

    if address == "auto" or address.startswith("ray://"):
        return
    host, sep, port_text = address.rpartition(":")
    if not sep or not host or not port_text.isdigit() or not 0 < int(port_text) < 65536:
        raise ParallelError(
            f"--address: expected 'auto' or host:port of a Ray head (e.g. 10.0.0.5:6379), found "
            f"{address!r}"
        )
    try:
        with socket.create_connection((host.strip("[]"), int(port_text)), timeout=timeout_s):
            pass
    except OSError as exc:
        raise ParallelError(
            f"--address {address}: expected a Ray head answering there, found none within "
            f"{timeout_s:g} s ({exc.strerror or exc}); start one with 'ray start --head "
            f"--port {port_text}' or give its address"
        ) from None


def _ray(
    task: Callable[..., Result], items: Sequence[Item], args: tuple[Any, ...], address: str | None
) -> Iterator[tuple[Item, Result]]:
    try:
        import ray
    except ImportError as exc:
        raise ParallelError(
            "--backend ray: expected the ray package (pip install 'dg16m[ray]'), found it missing"
        ) from exc
    started_here = not ray.is_initialized()
    if started_here:
        if address is None:
            ray.init(include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False)
        else:
            check_ray_address(address)
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(max_retries=RAY_MAX_RETRIES)(task)
        refs = {remote.remote(item, *args): item for item in items}
        waiting = list(refs)
        while waiting:
            done, waiting = ray.wait(waiting, num_returns=1)
            for ref in done:
                yield refs[ref], ray.get(ref)
    finally:
        if started_here:
            ray.shutdown()


def run_resumable(
    task: Callable[..., dict[str, Any]],
    items: Sequence[ObjectItem],
    args: tuple[Any, ...],
    *,
    root: Path,
    kind: str,
    parameters: Mapping[str, Any],
    folders: Sequence[str],
    error: type[Dg16mError],
    workers: int = 1,
    backend: Backend = "local",
    address: str | None = None,
    progress: bool = True,
    desc: str = "objects",
    on_entry: Callable[[str, dict[str, Any]], None] | None = None,
    write_every_s: float = 0.0,
    keep_failed: bool = False,
) -> dict[str, Any]:
    """Run ``task(item, *args)`` for every item not yet finished in ``root``; return the manifest.

    ``root/manifest.json`` (of ``kind``, made with ``parameters``) records one entry per object id
    as each task returns it; an object is finished when its entry is ``ok`` and all its files
    exist, so a rerun after an interruption does only the rest. Temporary files left in
    ``folders`` by killed atomic writes are removed first, and again once every task returned
    (on Ray a task whose node died is retried on another node; its killed attempt may have left
    one).

    ``keep_failed``: a ``failed`` entry counts as finished too (for a task whose failures are
    a function of its inputs and ``parameters``, which the manifest pins: a rerun would fail the
    same way); by default failed objects are tried again.

    ``write_every_s``: the manifest is rewritten after each entry (0, the default) or at most
    this often (s), and always when the run ends or is interrupted: a folder of thousands of
    objects would otherwise spend more time rewriting its manifest than making objects. A run
    killed outright (``kill -9``) then loses the record of at most that many seconds of objects;
    their files are written again, with the same bytes, by the next run.

    Raises:
        Dg16mError: the class passed as ``error``, for a bad worker count or backend, duplicate
            ids, or a ``root`` that holds a manifest of another kind or made with other
            parameters.
    """
    check_backend(backend, workers, error)
    ids = [item.object_id for item in items]
    if len(set(ids)) != len(ids):
        duplicate = next(i for i in ids if ids.count(i) > 1)
        raise error(f"objects: expected unique ids, found {duplicate!r} twice")
    root.mkdir(parents=True, exist_ok=True)
    if (root / "manifest.json").is_file():
        manifest = read_manifest(root)
        if manifest["kind"] != kind or manifest["parameters"] != parameters:
            found = manifest["parameters"]
            differing = sorted(
                k for k in {*parameters, *found} if parameters.get(k) != found.get(k)
            )
            raise error(
                f"{root}: expected a {kind} folder made with the same parameters to resume, found "
                f"kind {manifest['kind']!r} with parameters differing in {differing} "
                "(use another --out)"
            )
    else:
        manifest = new_manifest(kind, dict(parameters))
    remove_stale_temporaries(root, folders)

    def finished(object_id: str) -> bool:
        entry = manifest["entries"].get(object_id)
        if entry and keep_failed and entry["status"] == "failed":
            return True
        return (
            bool(entry)
            and entry["status"] == "ok"
            and all((root / rel).is_file() for rel in entry["files"].values())
        )

    todo = [item for item in items if not finished(item.object_id)]
    bar = None
    if progress:
        from dg16m_core.progress import progress_bar

        bar = progress_bar(
            total=len(items),
            initial=len(items) - len(todo),
            unit="object",
            desc=desc,
            smoothing=0.05,
        )
    written = time.monotonic()
    unwritten = False
    try:
        # SIGTERM stops the run as Ctrl-C does: the pool and budget children stop, finished
        # objects stay recorded (a server with its own SIGTERM handling is not affected)
        with sigterm_interrupts(), remembered_interrupts() as interrupted:
            results = run_tasks(task, todo, args, workers=workers, backend=backend, address=address)
            try:
                for item, entry in results:
                    manifest["entries"][item.object_id] = entry
                    unwritten = True
                    if time.monotonic() - written >= write_every_s:
                        write_manifest(root, manifest)  # sorted keys: bytes independent of order
                        written, unwritten = time.monotonic(), False
                    if on_entry is not None:
                        on_entry(item.object_id, entry)
                    if bar is not None:
                        bar.update(1)
                    if interrupted():  # a Ctrl-C that Python swallowed during the task
                        raise KeyboardInterrupt
            finally:
                results.close()  # stops a pool at once (its workers are terminated)
    finally:
        if unwritten:  # the end of the run, or an interrupt: record what finished
            write_manifest(root, manifest)
        if bar is not None:
            bar.close()
    # Every task of this run has returned. On Ray a worker killed mid-write (its node lost) left
    # its temporary file behind and the task was retried elsewhere: remove what the killed
    # attempts left, so that the folder holds exactly what a run without a loss writes.
    remove_stale_temporaries(root, folders)
    manifest["entries"] = dict(sorted(manifest["entries"].items()))
    return manifest


def remove_stale_temporaries(root: Path, folders: Sequence[str]) -> list[Path]:
    """Remove the ``.<name>.tmp-*`` files that killed atomic writes
    (:mod:`dg16m_core.atomic`) left in ``root/<folder>``; returns what was removed.

    Called by :func:`run_resumable` before its tasks start and after they all returned: no
    write of the run is in progress then.
    """
    removed = []
    for folder in folders:
        if (root / folder).is_dir():
            for stale in sorted((root / folder).glob(".*.tmp-*")):
                stale.unlink(missing_ok=True)
                removed.append(stale)
    return removed
