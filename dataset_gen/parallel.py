"""Run one task per object on a local process pool or on Ray, yielding results as they finish.

Both backends call the same top-level function ``task(item, *args)``; the caller records each
result by object id, so the outcome never depends on completion order. Used by the generator
(:mod:`dataset_gen.generate`) and the simulation benchmark (:mod:`dg16m_env.benchmark`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any, Literal, TypeVar

from .errors import Dg16mError

Backend = Literal["local", "ray"]
BACKENDS: tuple[str, ...] = ("local", "ray")

Item = TypeVar("Item")
Result = TypeVar("Result")


class ParallelError(Dg16mError, ValueError):
    """Bad backend arguments (worker count, backend name, missing Ray)."""


def check_backend(backend: str, workers: int) -> None:
    """Raise :class:`ParallelError` unless ``backend`` is known and ``workers >= 1``."""
    if not isinstance(workers, int) or workers < 1:
        raise ParallelError(f"--workers: expected an integer >= 1, found {workers!r}")
    if backend not in BACKENDS:
        raise ParallelError(f"--backend: expected one of {BACKENDS}, found {backend!r}")


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
    with ProcessPoolExecutor(max_workers=workers) as pool:
        pending: dict[Future[Result], Item] = {}
        queue = list(items)
        while queue or pending:
            while queue and len(pending) < 2 * workers:
                item = queue.pop(0)
                pending[pool.submit(task, item, *args)] = item
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                yield pending.pop(future), future.result()


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
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(task)
        refs = {remote.remote(item, *args): item for item in items}
        waiting = list(refs)
        while waiting:
            done, waiting = ray.wait(waiting, num_returns=1)
            for ref in done:
                yield refs[ref], ray.get(ref)
    finally:
        if started_here:
            ray.shutdown()
