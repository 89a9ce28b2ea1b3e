"""``gym.make_vec("dg16m_env/DualGraspLift-v2", num_envs=N)``: N environments stepped in blocks
by ``workers`` processes, this one included, one message per worker per step, behind
Gymnasium's whole ``VectorEnv`` interface.

Gymnasium's ``AsyncVectorEnv`` sends one message per environment per step; a v2 step takes
about 330 us and a round trip through a pipe with its wake-ups 100-150 us, so two workers gained
nothing over one environment (BENCHMARKS.md). Its ``worker`` hook cannot change that: each of
its processes holds one environment. :class:`LiftVectorEnv` splits the environments into
``workers`` blocks: block 0 is stepped in this process while the worker processes step theirs
(one message each way per step), so two workers are two busy processes, not a third that wakes
up to wait; each block's ``info`` comes back as ``(env index, info)`` records and this process
batches them once per step (:func:`batch_infos`, column by column).

It takes ``AsyncVectorEnv``'s constructor keywords (``env_fns``, ``shared_memory``, ``copy``,
``context``, ``daemon``, ``worker``, ``observation_mode``, ``autoreset_mode``,
``max_concurrency``) and has its methods (``reset``, ``step``, ``call``, ``get_attr``,
``set_attr``, ``render``, ``close``), so a caller builds either the same way; three keywords
of its own say how the environments are laid out: ``workers``, ``pin_workers`` and ``spin_s``
(an option, off by default: a waiting process polls its pipe for ``spin_s`` seconds before it
sleeps, which pays where cores are idle and costs where they are shared; measured in
BENCHMARKS.md).

Each block steps its environments with ``SyncVectorEnv``'s loop (:class:`EnvBlock`), so what
the vector env returns is what one ``SyncVectorEnv`` of all the environments returns for the
same seeds and actions (the same observation bytes, rewards, flags and ``info`` entries;
tested): ``reset(seed=s)`` seeds them ``s, s + 1, ...``; ``options["reset_mask"]`` resets some
(after a first reset of every environment); ``autoreset_mode`` is Gymnasium's (``NextStep`` by
default, ``SameStep`` with ``final_obs`` and ``final_info``, or ``Disabled``).

It is the ``vector_entry_point`` of ``DualGraspLift-v2`` (:func:`lift_v2_vector_env`) and
``DualGraspLift-v3`` (:func:`lift_v3_vector_env`):
``gym.make_vec(id, num_envs=8, workers=2)`` passes this class's keywords to it and the others
to every ``gymnasium.make``; ``vectorization_mode="sync"`` or ``"async"`` give Gymnasium's own.

A worker process that fails (a bad keyword argument, an error in a step) sends its traceback;
the vector env closes every worker and raises ``RuntimeError`` with it. An error in block 0
(this process) closes the workers and is raised as it is.
"""

from __future__ import annotations

import contextlib
import copy as copying
import functools
import inspect
import multiprocessing
import os
import time
import traceback
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium
import numpy as np
from gymnasium.spaces import Space
from gymnasium.spaces.utils import is_space_dtype_shape_equiv
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import (
    CloudpickleWrapper,
    batch_differing_spaces,
    batch_space,
    create_shared_memory,
    read_from_shared_memory,
)

from dg16m_env.envs.lift.vector_block import EnvBlock, Record, batch_infos

LIFT_V2 = "dg16m_env/DualGraspLift-v2"
LIFT_V3 = "dg16m_env/DualGraspLift-v3"

# --- worker processes -------------------------------------------------------------------------


def _wait(conn: Any, spin_s: float) -> None:
    """Poll ``conn`` for up to ``spin_s`` seconds before the caller's blocking ``recv``: a
    process that sleeps on a pipe leaves its core idle, and on a virtual machine an idle core
    takes hundreds of microseconds to wake (BENCHMARKS.md)."""
    if spin_s > 0.0:
        end = time.perf_counter() + spin_s
        while not conn.poll() and time.perf_counter() < end:
            pass


def _join(parts: list[Any]) -> Any:
    """Blocks of batched values (arrays, or dictionaries or tuples of them) joined along the
    first axis."""
    if isinstance(parts[0], dict):
        return {key: _join([part[key] for part in parts]) for key in parts[0]}
    if isinstance(parts[0], tuple):
        return tuple(_join(list(column)) for column in zip(*parts, strict=True))
    return np.concatenate(parts)


def _write(target: Any, first: int, values: Any) -> None:
    """``values`` (a block's batched observations) into rows ``first ..`` of ``target`` (the
    shared observations: arrays, or dictionaries or tuples of them)."""
    if isinstance(target, dict):
        for key in target:
            _write(target[key], first, values[key])
    elif isinstance(target, tuple):
        for part, value in zip(target, values, strict=True):
            _write(part, first, value)
    else:
        target[first : first + len(values)] = values


@dataclass(frozen=True)
class WorkerSetup:
    """What a worker process needs besides its environment functions and pipes."""

    block: int
    """the block index (1 .. workers - 1)"""
    first: int
    """the vector index of the block's first environment"""
    num_envs: int
    """environments of the whole vector env"""
    autoreset_mode: str
    """Gymnasium's autoreset mode, by value"""
    single_observation_space: Space
    """the space observations are batched in (shared memory's layout)"""
    cpu: int | None
    """the CPU to pin the process to, or None"""
    spin_s: float
    """seconds to poll the pipe before sleeping"""


def block_worker(
    setup: WorkerSetup, env_fns: CloudpickleWrapper, pipe: Any, parent_pipe: Any, shared: Any
) -> None:
    """The default ``worker`` of :class:`LiftVectorEnv`: makes the block's environments
    (an :class:`EnvBlock`), answers ``("ok", (observation spaces, action spaces))``, then one
    answer per command: ``("reset", (seeds, options, mask))``, ``("step", actions)``,
    ``("call", (name, args, kwargs))``, ``("set_attr", (name, values))``, ``("close", None)``.
    Observations travel in the answer, or in ``shared`` (the shared memory of
    ``shared_memory=True``, None in the answer). On an error it answers ``("error", (message,
    traceback))`` and stops. A custom ``worker`` takes the same arguments and keeps this
    protocol (start from this function)."""
    parent_pipe.close()
    block: EnvBlock | None = None
    try:
        if setup.cpu is not None:
            os.sched_setaffinity(0, {setup.cpu})
        envs = [make() for make in env_fns.fn]
        block = EnvBlock(envs, AutoresetMode(setup.autoreset_mode), setup.single_observation_space)
        view = (
            None
            if shared is None
            else read_from_shared_memory(setup.single_observation_space, shared, setup.num_envs)
        )

        def obs_out(obs: Any) -> Any:
            if view is None:
                return obs
            _write(view, setup.first, obs)
            return None

        pipe.send(("ok", block.spaces()))
        while True:
            _wait(pipe, setup.spin_s)
            command, payload = pipe.recv()
            if command == "step":
                obs, rewards, terminations, truncations, records = block.step(payload)
                pipe.send(("ok", (obs_out(obs), rewards, terminations, truncations, records)))
            elif command == "reset":
                obs, records = block.reset(*payload)
                pipe.send(("ok", (obs_out(obs), records)))
            elif command == "call":
                pipe.send(("ok", block.call(*payload)))
            elif command == "set_attr":
                pipe.send(("ok", block.set_attr(*payload)))
            elif command == "close":
                block.close()
                pipe.send(("ok", None))
                return
            else:
                raise ValueError(
                    f"command: expected step, reset, call, set_attr or close, found {command!r}"
                )
    except (KeyboardInterrupt, EOFError):
        return
    except Exception as exc:  # reported: the parent raises it with this traceback
        pipe.send(("error", (f"{type(exc).__name__}: {exc}", traceback.format_exc())))


# --- the vector env ---------------------------------------------------------------------------


def _rows(actions: Any, lo: int, hi: int) -> Any:
    """Rows ``lo .. hi`` of batched ``actions`` (an array, or dictionaries or tuples of them)."""
    if isinstance(actions, dict):
        return {key: _rows(value, lo, hi) for key, value in actions.items()}
    if isinstance(actions, tuple):
        return tuple(_rows(value, lo, hi) for value in actions)
    return actions[lo:hi]


def _check_count(name: str, value: Any, at_most: int | None = None) -> int:
    """``value`` as an integer >= 1 (and at most ``at_most``), else ValueError."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{name}: expected an integer >= 1, found {value!r}")
    if at_most is not None and value > at_most:
        raise ValueError(f"{name}: expected at most {at_most}, found {value}")
    return int(value)


class LiftVectorEnv(VectorEnv):
    """Environments stepped in blocks by ``workers`` processes, this one included (module
    docstring); Gymnasium's ``AsyncVectorEnv`` interface and constructor keywords.

    Args:
        env_fns: functions that make the environments (one each; pickled with cloudpickle for
            the worker processes, as ``AsyncVectorEnv``'s).
        shared_memory: the worker processes write their observations to shared memory
            instead of sending them (as ``AsyncVectorEnv``'s).
        copy: ``reset`` and ``step`` return a copy of the shared observations (with
            ``shared_memory``; without, each call's observations are a new array anyway).
        context: the ``multiprocessing`` start method (default: Python's; with ``"spawn"`` or
            ``"forkserver"`` a script needs the ``if __name__ == "__main__":`` guard). Workers
            that render (``render_mode="rgb_array"``) after this process has drawn with OpenGL
            need ``"spawn"`` or ``"forkserver"``: a process forked from one that holds an EGL
            context can hang in its first frame.
        daemon: worker processes are daemons (they end with this process).
        worker: the function each worker process runs (default :func:`block_worker`, whose
            arguments and protocol a custom one keeps).
        observation_mode: ``"same"``, ``"different"`` or ``(observation_space,
            single_observation_space)``, as ``AsyncVectorEnv``'s.
        autoreset_mode: Gymnasium's (``"NextStep"``, ``"SameStep"`` or ``"Disabled"``).
        max_concurrency: processes that step environments at once: caps the default of
            ``workers`` (None: no cap).
        workers: processes that step environments, this one included (1 .. the number of
            environments; default: the CPUs this process may use, at most the environments).
            Block 0 is stepped here, blocks ``1 .. workers - 1`` in worker processes; where the
            environments do not divide evenly the first blocks are the larger (a worker's
            block also pays for its messages). ``workers=1`` steps everything here.
        pin_workers: pin worker process ``k`` to the ``k``-th CPU this process may use (this
            process is left as it is).
        spin_s: seconds a worker process polls for its next command, and this process for
            the workers' answers, before sleeping (default 0: sleep at once, as
            ``AsyncVectorEnv``). On a virtual machine a sleeping core takes hundreds of
            microseconds to wake, most of a small block's step: where every worker has an
            idle core of its own, ``spin_s=0.001`` gained up to a quarter of the steps per
            second with 16 environments on the 2-core VM. The cost: each worker keeps its core
            busy for up to ``spin_s`` while this process computes between steps (a policy),
            and where other busy processes share the cores the polling takes their time (a
            quarter of the steps per second lost, measured; BENCHMARKS.md).
    """

    def __init__(
        self,
        env_fns: Sequence[Callable[[], gymnasium.Env]],
        shared_memory: bool = True,
        copy: bool = True,
        context: str | None = None,
        daemon: bool = True,
        worker: Callable[..., None] | None = None,
        observation_mode: str | tuple[Space, Space] = "same",
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        max_concurrency: int | None = None,
        *,
        workers: int | None = None,
        pin_workers: bool = False,
        spin_s: float = 0.0,
    ) -> None:
        super().__init__()
        self._conns: list[Any] = []
        self._processes: list[Any] = []
        self._block: EnvBlock | None = None
        self._shared: Any = None  # the observations' shared memory (``shared_memory``)
        self.env_fns = list(env_fns)
        if not self.env_fns:
            raise ValueError("env_fns: expected at least one environment function, found none")
        self.shared_memory, self.copy, self.context = bool(shared_memory), bool(copy), context
        self.daemon, self.worker, self.observation_mode = daemon, worker, observation_mode
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        self.num_envs = num_envs = len(self.env_fns)
        cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else [0]
        cap = num_envs
        if max_concurrency is not None:
            cap = min(cap, _check_count("max_concurrency", max_concurrency))
        self.max_concurrency = max_concurrency
        self.workers = _check_count(
            "workers", min(cap, len(cpus)) if workers is None else workers, cap
        )
        if (
            isinstance(spin_s, bool)
            or not isinstance(spin_s, int | float)
            or not 0 <= spin_s < np.inf
        ):
            raise ValueError(f"spin_s: expected finite seconds >= 0, found {spin_s!r}")
        self.spin_s = float(spin_s)
        counts = [
            num_envs // self.workers + (1 if k < num_envs % self.workers else 0)
            for k in range(self.workers)
        ]
        # the larger blocks here: a worker's block also pays for its message both ways
        self._blocks = [int(b) for b in np.cumsum([0, *counts])]
        self._reset_once = np.zeros(num_envs, dtype=np.bool_)
        self._block_obs: list[Any] = [None] * self.workers  # each block's last observations
        envs = [self.env_fns[0]()]  # block 0's first: the spaces, before the workers start
        try:
            self._set_spaces(envs[0])
            self._start_workers(counts, cpus if pin_workers else None)
            # the rest of block 0 while the workers make theirs
            envs += [make() for make in self.env_fns[1 : counts[0]]]
            self._block = EnvBlock(envs, self.autoreset_mode, self.single_observation_space)
            self._check_spaces([self._block.spaces(), *self._receive_all()])
        except BaseException:
            if self._block is None:
                for env in envs:
                    env.close()
            self.close()
            raise

    def _set_spaces(self, env: gymnasium.Env) -> None:
        """The metadata and spaces from the first environment (``observation_mode``'s
        batched space of ``"different"`` waits for every environment's)."""
        self.metadata = dict(env.metadata)
        self.metadata["autoreset_mode"] = self.autoreset_mode
        self.render_mode = env.render_mode
        self.single_action_space = env.action_space
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        mode = self.observation_mode
        if isinstance(mode, tuple) and len(mode) == 2:
            if not all(isinstance(space, Space) for space in mode):
                raise TypeError(f"observation_mode: expected two spaces, found {mode!r}")
            self.observation_space, self.single_observation_space = mode
        elif mode in ("same", "different"):
            self.single_observation_space = env.observation_space
            self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        else:
            raise ValueError(
                f"observation_mode: expected 'same', 'different' or (observation_space, "
                f"single_observation_space), found {mode!r}"
            )
        if self.shared_memory:
            ctx = multiprocessing.get_context(self.context)
            self._shared = create_shared_memory(self.single_observation_space, self.num_envs, ctx)
            self.observations = read_from_shared_memory(
                self.single_observation_space, self._shared, self.num_envs
            )

    def _start_workers(self, counts: list[int], cpus: list[int] | None) -> None:
        """Start worker processes ``1 .. workers - 1``, each with its block's functions."""
        ctx = multiprocessing.get_context(self.context)
        for k in range(1, self.workers):
            parent, child = ctx.Pipe()
            setup = WorkerSetup(
                block=k,
                first=self._blocks[k],
                num_envs=self.num_envs,
                autoreset_mode=self.autoreset_mode.value,
                single_observation_space=self.single_observation_space,
                cpu=None if cpus is None else cpus[k % len(cpus)],
                spin_s=self.spin_s,
            )
            fns = CloudpickleWrapper(self.env_fns[self._blocks[k] : self._blocks[k + 1]])
            process = ctx.Process(
                target=self.worker or block_worker,
                args=(setup, fns, child, parent, self._shared),
                name=f"{type(self).__name__}-{k}",
                daemon=self.daemon,
            )
            process.start()
            child.close()
            self._conns.append(parent)
            self._processes.append(process)

    def _check_spaces(self, spaces: list[tuple[list[Space], list[Space]]]) -> None:
        """Every environment's spaces against the first's, as ``observation_mode`` asks."""
        observation_spaces = [space for block in spaces for space in block[0]]
        action_spaces = [space for block in spaces for space in block[1]]
        same = self.observation_mode == "same"
        for i, (obs, action) in enumerate(zip(observation_spaces, action_spaces, strict=True)):
            if not (
                obs == self.single_observation_space
                if same
                else is_space_dtype_shape_equiv(obs, self.single_observation_space)
            ):
                kind = "equal to" if same else "of the shape and dtype of"
                raise RuntimeError(
                    f"environment {i}'s observation space: expected one {kind} "
                    f"{self.single_observation_space} (observation_mode={self.observation_mode!r}), "
                    f"found {obs}"
                )
            if action != self.single_action_space:
                raise RuntimeError(
                    f"environment {i}'s action space: expected {self.single_action_space}, "
                    f"found {action}"
                )
        if self.observation_mode == "different":
            self.observation_space = batch_differing_spaces(observation_spaces)

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
                f"{type(self).__name__}: "
                + "; ".join(errors)
                + "\n\n"
                + (details[0] or "").rstrip()
            )
        return answers

    def _here(self, method: Any, *args: Any) -> Any:
        """Block 0's ``method(*args)``; on an error, the worker processes (already sent their
        share) are closed before it is raised."""
        try:
            return method(*args)
        except BaseException:
            self.close()
            raise

    def _observations(self, k: int, obs: Any) -> None:
        """Keep block ``k``'s observations (into the shared memory for block 0)."""
        if self._shared is None:
            self._block_obs[k] = obs
        elif k == 0:
            _write(self.observations, 0, obs)

    def _batched_observations(self) -> Any:
        """Every block's last observations, batched."""
        if self._shared is None:
            self.observations = _join(self._block_obs)
            return self.observations
        return copying.deepcopy(self.observations) if self.copy else self.observations

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Reset every sub-environment (or those of ``options["reset_mask"]``, once every one
        has been reset), seeds as ``SyncVectorEnv``'s: ``None``, an int ``s`` (``s, s + 1,
        ...``) or one per env."""
        n = self.num_envs
        if seed is None:
            seeds: list[int | None] = [None] * n
        elif isinstance(seed, int):
            seeds = [seed + i for i in range(n)]
        else:
            seeds = list(seed)
        if len(seeds) != n:
            raise ValueError(
                f"seed: expected {n} seeds (one per sub-environment), found {len(seeds)}"
            )
        mask = None
        if options is not None and "reset_mask" in options:
            options = dict(options)
            mask = options.pop("reset_mask")
            if not (
                isinstance(mask, np.ndarray)
                and mask.shape == (n,)
                and mask.dtype == np.bool_
                and mask.any()
            ):
                raise ValueError(
                    f"options['reset_mask']: expected a bool array of shape ({n},) with a True "
                    f"value, found {mask!r}"
                )
            never = np.flatnonzero(~(mask | self._reset_once)).tolist()
            if never:
                raise ValueError(
                    f"options['reset_mask']: expected every environment reset once before a "
                    f"partial reset, found environments {never} never reset"
                )
        shares = []
        for k in range(self.workers):  # a block none of whose envs resets keeps all
            lo, hi = self._blocks[k], self._blocks[k + 1]
            if mask is None or mask[lo:hi].any():
                shares.append((k, (seeds[lo:hi], options, None if mask is None else mask[lo:hi])))
        for k, payload in shares:
            if k > 0:
                self._conns[k - 1].send(("reset", payload))
        answers = []
        if shares[0][0] == 0:
            assert self._block is not None
            answers.append(self._here(self._block.reset, *shares[0][1]))
        answers += self._receive_all([k for k, _ in shares if k > 0])
        records: list[Record] = []
        for (k, _), (obs, block_records) in zip(shares, answers, strict=True):
            self._observations(k, obs)
            records += [(self._blocks[k] + i, info) for i, info in block_records]
        self._reset_once |= True if mask is None else mask
        return self._batched_observations(), batch_infos(records, n)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every sub-environment with its row of ``actions`` (autoreset as configured)."""
        if not isinstance(actions, dict | tuple):
            actions = np.asarray(actions)
            if actions.shape[:1] != (self.num_envs,):
                raise ValueError(
                    f"actions: expected one row per sub-environment, shape ({self.num_envs}, "
                    f"...), found shape {actions.shape}"
                )
        blocks = self._blocks
        for k, conn in enumerate(self._conns, start=1):
            conn.send(("step", _rows(actions, blocks[k], blocks[k + 1])))
        assert self._block is not None
        answers = [self._here(self._block.step, _rows(actions, 0, blocks[1]))]
        answers += self._receive_all()
        for k, answer in enumerate(answers):
            self._observations(k, answer[0])
        records = [
            (blocks[k] + i, env_info)
            for k, answer in enumerate(answers)
            for i, env_info in answer[4]
        ]
        return (
            self._batched_observations(),
            np.concatenate([answer[1] for answer in answers]),
            np.concatenate([answer[2] for answer in answers]),
            np.concatenate([answer[3] for answer in answers]),
            batch_infos(records, self.num_envs),
        )

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """Each sub-environment's ``name`` called with the arguments (read where it is not
        callable), as ``SyncVectorEnv.call``: a tuple, one result per environment."""
        for conn in self._conns:
            conn.send(("call", (name, args, kwargs)))
        assert self._block is not None
        results = self._here(self._block.call, name, args, kwargs)
        for answer in self._receive_all():
            results += answer
        return tuple(results)

    def get_attr(self, name: str) -> tuple[Any, ...]:
        """Each sub-environment's attribute ``name``."""
        return self.call(name)

    def set_attr(self, name: str, values: list[Any] | tuple[Any, ...] | Any) -> None:
        """Set attribute ``name`` of the sub-environments: one value each (a list or tuple) or
        the same value for all."""
        if not isinstance(values, list | tuple):
            values = [values] * self.num_envs
        if len(values) != self.num_envs:
            raise ValueError(
                f"values: expected {self.num_envs} (one per sub-environment), found {len(values)}"
            )
        blocks = self._blocks
        for k, conn in enumerate(self._conns, start=1):
            conn.send(("set_attr", (name, list(values[blocks[k] : blocks[k + 1]]))))
        assert self._block is not None
        self._here(self._block.set_attr, name, list(values[: blocks[1]]))
        self._receive_all()

    def render(self) -> tuple[Any, ...] | None:
        """Each sub-environment's frame (``render_mode`` of the environments)."""
        return self.call("render")

    @property
    def np_random_seed(self) -> tuple[int, ...]:
        """Each sub-environment's ``np_random_seed``."""
        return self.get_attr("np_random_seed")

    @property
    def np_random(self) -> tuple[np.random.Generator, ...]:
        """Each sub-environment's random generator (copies from the worker processes)."""
        return self.get_attr("np_random")

    def close_extras(self, **kwargs: Any) -> None:
        """Ask every worker to close its environments, close block 0's, then end the
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

    def __del__(self) -> None:
        """Close the worker processes of a vector env left open."""
        if not getattr(self, "closed", True) and getattr(self, "_processes", None):
            with contextlib.suppress(Exception):
                self.close()


VECTOR_KEYWORDS = tuple(
    name for name in inspect.signature(LiftVectorEnv).parameters if name != "env_fns"
)
"""The keywords of :class:`LiftVectorEnv` that :func:`lift_v2_vector_env` passes to it (the
others go to every ``gymnasium.make``)."""


def make_env(env_id: str, kwargs: dict[str, Any]) -> gymnasium.Env:
    """``gymnasium.make(env_id, **kwargs)``: an environment function by reference (its module
    imports :mod:`dg16m_env`, which registers the ids, wherever it is unpickled). Gymnasium's
    note that a newer version is registered is left out: ``gym.make_vec`` has made it once for
    the caller, and each process would repeat it (the demonstrations, whose version is the
    command's choice, make their environments here too)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*is out of date.*", category=DeprecationWarning)
        return gymnasium.make(env_id, **kwargs)


def lift_v2_vector_env(num_envs: int = 1, **kwargs: Any) -> LiftVectorEnv:
    """The ``vector_entry_point`` of ``DualGraspLift-v2`` (``gym.make_vec``): ``num_envs``
    environments, :data:`VECTOR_KEYWORDS` to :class:`LiftVectorEnv`, the rest to
    ``gymnasium.make``."""
    _check_count("num_envs", num_envs)
    vector = {name: kwargs.pop(name) for name in VECTOR_KEYWORDS if name in kwargs}
    make = functools.partial(make_env, LIFT_V2, kwargs)
    return LiftVectorEnv([make] * num_envs, **vector)


def lift_v3_vector_env(num_envs: int = 1, **kwargs: Any) -> LiftVectorEnv:
    """The ``vector_entry_point`` of ``DualGraspLift-v3``: as :func:`lift_v2_vector_env`."""
    _check_count("num_envs", num_envs)
    vector = {name: kwargs.pop(name) for name in VECTOR_KEYWORDS if name in kwargs}
    make = functools.partial(make_env, LIFT_V3, kwargs)
    return LiftVectorEnv([make] * num_envs, **vector)
