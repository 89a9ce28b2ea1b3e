"""``gym.make_vec("dg16m_env/DualGraspLift-v2", num_envs=N)``: N Lift environments stepped
in blocks by ``workers`` processes, this one included, one message per worker per step.

Gymnasium's ``AsyncVectorEnv`` sends one message per environment per step; a v2 step takes
about 330 us and a round trip through a pipe with its wake-ups 100-150 us, so two workers gained
nothing over one environment (BENCHMARKS.md). :class:`LiftVectorEnv` splits the environments
into ``workers`` blocks: block 0 is stepped in this process while the worker processes step
theirs (one message each way per step), so two workers are two busy processes, not a third
that wakes up to wait; each block's ``info`` comes back as the records its loop would have
batched, and this process batches them once per step (:func:`batch_infos`, column by column).
Measured on the 2-core development VM interleaved with one env (its speed drifts by tens of
percent within seconds), 16 environments with 2 workers against one env, next to the
machine's own ceiling for two processes: BENCHMARKS.md.

Each block is a ``gymnasium.vector.SyncVectorEnv``, so what the vector env returns is what one
``SyncVectorEnv`` of all the environments returns for the same seeds and actions (the same
observation bytes, rewards, flags and ``info`` entries; tested):
the sub-environments are ``gymnasium.make(env_id, **env_kwargs)``; ``reset(seed=s)`` seeds
them ``s, s + 1, ...``; ``options["reset_mask"]`` resets some; ``autoreset_mode`` is
Gymnasium's (``NextStep`` by default, ``SameStep`` with ``final_obs`` and ``final_info``, or
``Disabled``).

It is the ``vector_entry_point`` of ``DualGraspLift-v2``: ``gym.make_vec(id, num_envs=8)`` makes
one (``workers``, ``pin_workers`` and ``autoreset_mode`` go with the env's keyword arguments);
``vectorization_mode="sync"`` or ``"async"`` give Gymnasium's own. ``render_mode`` is refused
(frames would stay in the workers; render with one env).

A worker process that fails (a bad keyword argument, an error in a step) sends its traceback;
the vector env closes every worker and raises ``RuntimeError`` with it. An error in block 0
(this process) closes the workers and is raised as it is.
"""

from __future__ import annotations

import contextlib
import functools
import multiprocessing
import os
import time
import traceback
from typing import Any

import gymnasium
import numpy as np
from gymnasium.vector import AutoresetMode, SyncVectorEnv, VectorEnv
from gymnasium.vector.utils import batch_space

LIFT_V2 = "dg16m_env/DualGraspLift-v2"


class _RecordingSyncVectorEnv(SyncVectorEnv):
    """A block: Gymnasium's ``SyncVectorEnv`` whose ``info`` is the list of what its loop
    would have batched, ``(env index, info)`` in call order, under :data:`RECORDS` (its
    ``_add_info``, which that loop calls, is the only change). The calling process batches
    all the blocks' records at once (:func:`batch_infos`): one batching per step instead of
    one per block and a join, and smaller messages."""

    def _add_info(
        self, vector_infos: dict[str, Any], env_info: dict[str, Any], env_num: int
    ) -> dict[str, Any]:
        vector_infos.setdefault(RECORDS, []).append((env_num, env_info))
        return vector_infos


RECORDS = "records"
"""The key of a block's ``info`` records in a worker's answer."""


def _wait(conn: Any, spin_s: float) -> None:
    """Poll ``conn`` for up to ``spin_s`` seconds before the caller's blocking ``recv``: a
    process that sleeps on a pipe leaves its core idle, and on a virtual machine an idle core
    takes hundreds of microseconds to wake (BENCHMARKS.md)."""
    if spin_s > 0.0:
        end = time.perf_counter() + spin_s
        while not conn.poll() and time.perf_counter() < end:
            pass


def _serve(
    conn: Any,
    env_id: str,
    env_kwargs: dict[str, Any],
    count: int,
    cpu: int | None,
    mode: str,
    spin_s: float,
) -> None:
    """A worker: a ``SyncVectorEnv`` of ``count`` environments (the block), one command per
    message (``reset``, ``step``, ``close``: its methods' arguments; polled for ``spin_s``
    seconds before it sleeps); answers ``("ok", result)``, with the block's ``info`` as
    records (:class:`_RecordingSyncVectorEnv`), or ``("error", (message, traceback))`` and
    then stops."""
    try:
        if cpu is not None:
            os.sched_setaffinity(0, {cpu})
        import gymnasium

        import dg16m_env  # noqa: F401  registers the environments

        make = functools.partial(gymnasium.make, env_id, **env_kwargs)
        block = _RecordingSyncVectorEnv([make] * count, autoreset_mode=mode)
        conn.send(("ok", "ready"))  # the spaces are block 0's, made in the calling process
        while True:
            _wait(conn, spin_s)
            command, payload = conn.recv()
            if command == "close":
                block.close()
                conn.send(("ok", None))
                return
            if command == "reset":
                obs, info = block.reset(seed=payload[0], options=payload[1])
                conn.send(("ok", (obs, info.get(RECORDS, []))))
            elif command == "step":
                obs, rewards, terminations, truncations, info = block.step(payload)
                answer = (obs, rewards, terminations, truncations, info.get(RECORDS, []))
                conn.send(("ok", answer))
            else:
                raise ValueError(f"command: expected reset, step or close, found {command!r}")
    except (KeyboardInterrupt, EOFError):
        return
    except Exception as exc:  # reported: the parent raises it with this traceback
        conn.send(("error", (f"{type(exc).__name__}: {exc}", traceback.format_exc())))


def _join(parts: list[Any]) -> Any:
    """Blocks of batched values (arrays, or dictionaries of them) joined along the first
    axis."""
    if isinstance(parts[0], dict):
        return {key: _join([part[key] for part in parts]) for key in parts[0]}
    return np.concatenate(parts)


_NUMBERS = (int, float, bool)


def _batch_columns(infos: list[dict[str, Any]], num_envs: int) -> dict[str, Any] | None:
    """The fast case of :func:`batch_infos`: one record per environment, in order, every
    ``info`` with the same keys in the same order and each key's values of one type (arrays
    of one shape and dtype); None otherwise."""
    if len(infos) != num_envs:
        return None
    keys = tuple(infos[0])
    for info in infos:
        if tuple(info) != keys:
            return None
    columns = zip(*[tuple(info.values()) for info in infos], strict=True)
    ones = np.ones(num_envs, dtype=np.bool_)
    batched: dict[str, Any] = {}
    for key, column in zip(keys, columns, strict=True):
        kinds = set(map(type, column))
        if len(kinds) != 1 or key.startswith("_") or key == "final_obs":
            return None
        kind = kinds.pop()
        array: Any
        if issubclass(kind, dict):
            array = _batch_columns(list(column), num_envs)
            if array is None:
                return None
        elif kind in _NUMBERS or issubclass(kind, np.number):
            array = np.array(column, dtype=kind)
        elif kind is np.ndarray:
            if len({(value.shape, value.dtype) for value in column}) != 1:
                return None
            array = np.array(column)
        elif issubclass(kind, np.ndarray):
            return None  # a subclass: Gymnasium's element by element
        else:
            array = np.empty(num_envs, dtype=object)
            for env_num, value in enumerate(column):
                array[env_num] = value
        batched[key], batched["_" + key] = array, ones.copy()
    return batched


def batch_infos(records: list[tuple[int, dict[str, Any]]], num_envs: int) -> dict[str, Any]:
    """The vector ``info`` of ``num_envs`` environments from ``(env index, info)`` records in
    call order: what Gymnasium's ``VectorEnv._add_info`` builds record by record (each key's
    array typed by its first value, a ``_key`` mask after it, dictionaries batched inside),
    one array per key at once where every environment has one record with the same keys and
    value types (the usual step); other records go through ``_add_info`` itself."""
    if all(env_num == i for i, (env_num, _) in enumerate(records)):
        batched = _batch_columns([info for _, info in records], num_envs)
        if batched is not None:
            return batched
    helper = VectorEnv()
    helper.num_envs = num_envs
    infos: dict[str, Any] = {}
    for env_num, info in records:
        infos = helper._add_info(infos, info, env_num)
    return infos


class LiftVectorEnv(VectorEnv):
    """``num_envs`` environments of ``env_id`` stepped by ``workers`` processes, this one
    included (module docstring).

    Args:
        num_envs: sub-environments (>= 1).
        workers: processes that step environments, this one included (1 .. ``num_envs``;
            default: the CPUs this process may use, at most ``num_envs``). Block 0 is stepped
            here, blocks ``1 .. workers - 1`` in worker processes; where ``num_envs`` does
            not divide evenly the first blocks are the larger (a worker's block also pays
            for its messages). ``workers=1`` steps everything here, as ``SyncVectorEnv``.
        pin_workers: pin worker process ``k`` to the ``k``-th CPU this process may use (this
            process is left as it is).
        spin_s: seconds a worker process polls for its next command, and this process for
            the workers' answers, before sleeping (default 0.001 where ``workers`` is at
            most the CPUs this process may use, else 0): on a virtual machine a sleeping core
            takes hundreds of microseconds to wake, which is most of a small block's step
            (BENCHMARKS.md). The cost: while this process computes between steps (a policy),
            each worker keeps its core busy for up to ``spin_s``, and where other busy
            processes share the cores the polling takes their time; 0 sleeps at once.
        autoreset_mode: Gymnasium's (``"NextStep"``, ``"SameStep"`` or ``"Disabled"``).
        env_id: the environment (default ``dg16m_env/DualGraspLift-v2``).
        context: the ``multiprocessing`` start method (default: Python's, as Gymnasium's
            ``AsyncVectorEnv``; with ``"spawn"`` or ``"forkserver"`` a script needs the
            ``if __name__ == "__main__":`` guard).
        env_kwargs: ``gymnasium.make`` keyword arguments of every sub-environment.
    """

    def __init__(
        self,
        num_envs: int = 1,
        *,
        workers: int | None = None,
        pin_workers: bool = False,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        env_id: str = LIFT_V2,
        context: str | None = None,
        spin_s: float | None = None,
        **env_kwargs: Any,
    ) -> None:
        super().__init__()
        self._conns: list[Any] = []
        self._processes: list[Any] = []
        self._block: _RecordingSyncVectorEnv | None = None
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs: expected an integer >= 1, found {num_envs!r}")
        cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else [0]
        if workers is None:
            workers = min(num_envs, len(cpus))
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise ValueError(f"workers: expected an integer >= 1, found {workers!r}")
        if workers > num_envs:
            raise ValueError(f"workers: expected at most num_envs = {num_envs}, found {workers}")
        if env_kwargs.get("render_mode") is not None:
            raise ValueError(
                f"render_mode: expected None (frames would stay in the worker processes; "
                f"render one env, or use vectorization_mode='sync'), found "
                f"{env_kwargs['render_mode']!r}"
            )
        if spin_s is None:
            spin_s = 0.001 if workers <= len(cpus) else 0.0
        if (
            isinstance(spin_s, bool)
            or not isinstance(spin_s, int | float)
            or not 0.0 <= spin_s < float("inf")
        ):
            raise ValueError(f"spin_s: expected finite seconds >= 0, found {spin_s!r}")
        self.spin_s = float(spin_s)
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        self.num_envs = num_envs
        self.workers = workers
        self.env_id = env_id
        self.render_mode = None
        counts = [
            num_envs // workers + (1 if k < num_envs % workers else 0) for k in range(workers)
        ]
        # the larger blocks here: a worker's block also pays for its message both ways
        self._blocks = [int(b) for b in np.cumsum([0, *counts])]
        ctx = multiprocessing.get_context(context)
        for k in range(1, workers):
            parent, child = ctx.Pipe()
            cpu = cpus[k % len(cpus)] if pin_workers else None
            process = ctx.Process(
                target=_serve,
                args=(
                    child,
                    env_id,
                    dict(env_kwargs),
                    counts[k],
                    cpu,
                    self.autoreset_mode.value,
                    self.spin_s,
                ),
                name=f"LiftVectorEnv-{k}",
                daemon=True,
            )
            process.start()
            child.close()
            self._conns.append(parent)
            self._processes.append(process)
        try:  # block 0 is made while the workers make theirs
            make = functools.partial(gymnasium.make, env_id, **env_kwargs)
            self._block = _RecordingSyncVectorEnv(
                [make] * counts[0], autoreset_mode=self.autoreset_mode
            )
        except BaseException:
            self.close()
            raise
        self._receive_all()
        self.single_observation_space = self._block.single_observation_space
        self.single_action_space = self._block.single_action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.metadata = dict(self._block.envs[0].metadata)
        self.metadata["autoreset_mode"] = self.autoreset_mode
        self._block_obs: list[Any] = [None] * workers  # each block's last observations

    # ---------------------------------------------------------------------------------------

    def _receive_all(self, blocks: list[int] | None = None) -> list[Any]:
        """The answers of the worker processes of ``blocks`` (default all: ``1 ..
        workers - 1``), in order; closes everything and raises on an error."""
        answers, errors, details = [], [], []
        for k in range(1, self.workers) if blocks is None else blocks:
            conn = self._conns[k - 1]
            _wait(conn, self.spin_s)
            try:
                status, value = conn.recv()
            except EOFError:
                status, value = "error", ("the worker process ended without an answer", "")
            if status == "error":
                errors.append(f"worker {k}: {value[0]}")
                details.append(value[1])
            answers.append(value)
        if errors:
            self.close()
            raise RuntimeError(
                "LiftVectorEnv: " + "; ".join(errors) + "\n\n" + (details[0] or "").rstrip()
            )
        return answers

    def _here(self, method: Any, *args: Any, **kwargs: Any) -> Any:
        """Block 0's ``method(*args, **kwargs)``; on an error, the worker processes (already
        sent their share) are closed before it is raised."""
        try:
            return method(*args, **kwargs)
        except BaseException:
            self.close()
            raise

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Reset every sub-environment (or those of ``options["reset_mask"]``), seeds as
        ``SyncVectorEnv``'s: ``None``, an int ``s`` (``s, s + 1, ...``) or one per env."""
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, int):
            seeds = [seed + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
        if len(seeds) != self.num_envs:
            raise ValueError(
                f"seed: expected {self.num_envs} seeds (one per sub-environment), found "
                f"{len(seeds)}"
            )
        mask = np.ones(self.num_envs, dtype=np.bool_)
        masked = options is not None and "reset_mask" in options
        if masked:
            assert options is not None
            mask = options["reset_mask"]
            if not (
                isinstance(mask, np.ndarray)
                and mask.shape == (self.num_envs,)
                and mask.dtype == np.bool_
                and mask.any()
            ):
                raise ValueError(
                    f"options['reset_mask']: expected a bool array of shape ({self.num_envs},) "
                    f"with a True value, found {mask!r}"
                )
        shares = []
        for k in range(self.workers):  # a block none of whose envs resets keeps all
            lo, hi = self._blocks[k], self._blocks[k + 1]
            if mask[lo:hi].any():
                block_options = {**options, "reset_mask": mask[lo:hi]} if masked else options
                shares.append((k, (seeds[lo:hi], block_options)))
        for k, payload in shares:
            if k > 0:
                self._conns[k - 1].send(("reset", payload))
        answers = []
        if shares[0][0] == 0:
            seeds_here, options_here = shares[0][1]
            obs, info = self._here(self._block.reset, seed=seeds_here, options=options_here)
            answers.append((obs, info.get(RECORDS, [])))
        answers += self._receive_all([k for k, _ in shares if k > 0])
        records: list[tuple[int, dict[str, Any]]] = []
        for (k, _), (obs, block_records) in zip(shares, answers, strict=True):
            self._block_obs[k] = obs
            records += [(self._blocks[k] + i, info) for i, info in block_records]
        return _join(self._block_obs), batch_infos(records, self.num_envs)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every sub-environment with its row of ``actions`` (autoreset as configured)."""
        actions = np.asarray(actions)
        if actions.shape[:1] != (self.num_envs,):
            raise ValueError(
                f"actions: expected one row per sub-environment, shape ({self.num_envs}, ...), "
                f"found shape {actions.shape}"
            )
        blocks = self._blocks
        for k, conn in enumerate(self._conns, start=1):
            conn.send(("step", actions[blocks[k] : blocks[k + 1]]))
        obs, rewards, terminations, truncations, info = self._here(
            self._block.step, actions[: blocks[1]]
        )
        answers = [(obs, rewards, terminations, truncations, info.get(RECORDS, []))]
        answers += self._receive_all()
        self._block_obs = [answer[0] for answer in answers]
        records = [
            (blocks[k] + i, env_info)
            for k, answer in enumerate(answers)
            for i, env_info in answer[4]
        ]
        return (
            _join(self._block_obs),
            np.concatenate([answer[1] for answer in answers]),
            np.concatenate([answer[2] for answer in answers]),
            np.concatenate([answer[3] for answer in answers]),
            batch_infos(records, self.num_envs),
        )

    def close_extras(self, **kwargs: Any) -> None:
        """Close block 0's environments, ask every worker to close its own, then end the
        processes."""
        for conn, process in zip(self._conns, self._processes, strict=True):
            if process.is_alive():
                with contextlib.suppress(BrokenPipeError, ConnectionResetError):
                    conn.send(("close", None))
        if self._block is not None:
            self._block.close()
            self._block = None
        for conn, process in zip(self._conns, self._processes, strict=True):
            with contextlib.suppress(EOFError, ConnectionResetError):
                while conn.poll(10.0):  # unanswered commands first, then the close
                    if conn.recv()[1] is None:
                        break
            process.join(timeout=5.0)
            if process.is_alive():
                process.terminate()
                process.join(timeout=5.0)
            conn.close()
        self._conns, self._processes = [], []


def lift_v2_vector_env(num_envs: int = 1, **kwargs: Any) -> LiftVectorEnv:
    """The ``vector_entry_point`` of ``DualGraspLift-v2`` (``gym.make_vec``)."""
    return LiftVectorEnv(num_envs, env_id=LIFT_V2, **kwargs)
