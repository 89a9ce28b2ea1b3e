"""``gym.make_vec("dg16m_env/DualGraspLift-v2", num_envs=N)``: N Lift environments in worker
processes, each worker stepping its share of them per message.

Gymnasium's ``AsyncVectorEnv`` sends one message per environment per step; a v2 step takes
about 330 us and a round trip through a pipe with its wake-ups 100-150 us, so two workers gained
nothing over one environment (BENCHMARKS.md). :class:`LiftVectorEnv` gives each of ``workers``
processes ``num_envs / workers`` environments and one message per step for all of them.
On the 2-core development VM, 2 workers against 1 measured 0.6-1.5x from run to run, better
with more environments per worker (1.54x with 32); two unsynchronised processes reach 1.9x
there, so the step barrier and the scheduler take the rest (BENCHMARKS.md).

Each worker's block is a ``gymnasium.vector.SyncVectorEnv``; the parent joins the blocks'
batches, so what it returns is what one ``SyncVectorEnv`` of all the environments returns for
the same seeds and actions (the same observation bytes, rewards, flags and ``info`` entries;
tested):
the sub-environments are ``gymnasium.make(env_id, **env_kwargs)``; ``reset(seed=s)`` seeds
them ``s, s + 1, ...``; ``options["reset_mask"]`` resets some; ``autoreset_mode`` is
Gymnasium's (``NextStep`` by default, ``SameStep`` with ``final_obs`` and ``final_info``, or
``Disabled``).

It is the ``vector_entry_point`` of ``DualGraspLift-v2``: ``gym.make_vec(id, num_envs=8)`` makes
one (``workers``, ``pin_workers`` and ``autoreset_mode`` go with the env's keyword arguments);
``vectorization_mode="sync"`` or ``"async"`` give Gymnasium's own. ``render_mode`` is refused
(frames stay in the workers; render with one env).

A worker that fails (a bad keyword argument, an error in a step) sends its traceback; the vector
env closes every worker and raises ``RuntimeError`` with it.
"""

from __future__ import annotations

import functools
import multiprocessing
import os
import traceback
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

LIFT_V2 = "dg16m_env/DualGraspLift-v2"


def _serve(
    conn: Any, env_id: str, env_kwargs: dict[str, Any], count: int, cpu: int | None, mode: str
) -> None:
    """A worker: a ``SyncVectorEnv`` of ``count`` environments (the block), one command per
    message (``reset``, ``step``, ``close``: its methods' arguments); answers ``("ok",
    result)`` or ``("error", (message, traceback))`` and then stops."""
    try:
        if cpu is not None:
            os.sched_setaffinity(0, {cpu})
        import gymnasium

        import dg16m_env  # noqa: F401  registers the environments

        make = functools.partial(gymnasium.make, env_id, **env_kwargs)
        block = gymnasium.vector.SyncVectorEnv([make] * count, autoreset_mode=mode)
        first = block.envs[0]
        conn.send(("ok", (first.observation_space, first.action_space, dict(first.metadata))))
        while True:
            command, payload = conn.recv()
            if command == "close":
                block.close()
                conn.send(("ok", None))
                return
            if command == "reset":
                conn.send(("ok", block.reset(seed=payload[0], options=payload[1])))
            elif command == "step":
                conn.send(("ok", block.step(payload)))
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


def _join_infos(parts: list[dict[str, Any]], sizes: list[int]) -> dict[str, Any]:
    """Blocks of Gymnasium vector ``info`` joined into the ``info`` of all the environments:
    what ``VectorEnv._add_info`` gives env by env (a key first seen in a later block comes
    after the earlier blocks' keys; where a block lacks a key, its values are zeros, or None
    in object arrays, and its mask ``False``)."""
    keys: dict[str, None] = {}
    for part in parts:
        keys.update(dict.fromkeys(part))
    joined: dict[str, Any] = {}
    for key in keys:
        values = [part.get(key) for part in parts]
        if all(isinstance(v, np.ndarray) and v.dtype == values[0].dtype for v in values):
            joined[key] = np.concatenate(values)  # the usual case: every block has the key
            continue
        if any(isinstance(v, dict) for v in values):
            joined[key] = _join_infos([v if v is not None else {} for v in values], sizes)
            continue
        first = next(v for v in values if v is not None)
        blocks = []
        for value, size in zip(values, sizes, strict=True):
            if value is None:
                shape = (size, *first.shape[1:])
                value = (
                    np.full(shape, None, dtype=object)
                    if first.dtype == object
                    else np.zeros(shape, dtype=first.dtype)
                )
            blocks.append(value.astype(first.dtype, copy=False))
        joined[key] = np.concatenate(blocks)
    return joined


class LiftVectorEnv(VectorEnv):
    """``num_envs`` environments of ``env_id`` in ``workers`` processes (module docstring).

    Args:
        num_envs: sub-environments (>= 1).
        workers: processes (1 .. ``num_envs``; default: the CPUs this process may use, at most
            ``num_envs``); worker ``k`` holds a contiguous block of the sub-environments.
        pin_workers: pin worker ``k`` to the ``k``-th CPU this process may use (on a machine
            whose scheduler keeps two busy processes on one core, this decides the speed-up).
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
        **env_kwargs: Any,
    ) -> None:
        super().__init__()
        self._conns: list[Any] = []
        self._processes: list[Any] = []
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
                f"render_mode: expected None (frames stay in the worker processes; render one "
                f"env, or use vectorization_mode='sync'), found {env_kwargs['render_mode']!r}"
            )
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        self.num_envs = num_envs
        self.workers = workers
        self.env_id = env_id
        self.render_mode = None
        counts = [
            num_envs // workers + (1 if k < num_envs % workers else 0) for k in range(workers)
        ]
        self._blocks = np.cumsum([0, *counts])
        self._sizes = counts
        ctx = multiprocessing.get_context(context)
        for k, count in enumerate(counts):
            parent, child = ctx.Pipe()
            cpu = cpus[k % len(cpus)] if pin_workers else None
            process = ctx.Process(
                target=_serve,
                args=(child, env_id, dict(env_kwargs), count, cpu, self.autoreset_mode.value),
                name=f"LiftVectorEnv-{k}",
                daemon=True,
            )
            process.start()
            child.close()
            self._conns.append(parent)
            self._processes.append(process)
        ready = self._receive_all()
        observation_space, action_space, metadata = ready[0]
        self.single_observation_space = observation_space
        self.single_action_space = action_space
        self.observation_space = batch_space(observation_space, num_envs)
        self.action_space = batch_space(action_space, num_envs)
        self.metadata = dict(metadata)
        self.metadata["autoreset_mode"] = self.autoreset_mode
        self._block_obs: list[Any] = [None] * workers  # each block's last observations

    # ---------------------------------------------------------------------------------------

    def _receive_all(self, workers: list[int] | None = None) -> list[Any]:
        """The answers of ``workers`` (default all), in order; closes everything and raises on
        an error."""
        answers, errors, details = [], [], []
        for k in range(len(self._conns)) if workers is None else workers:
            conn = self._conns[k]
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
        if options is not None and "reset_mask" in options:
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
        masked = options is not None and "reset_mask" in options
        block_infos: list[dict[str, Any]] = [{} for _ in self._conns]
        sent = []
        for k, conn in enumerate(self._conns):  # a block none of whose envs resets keeps all
            lo, hi = self._blocks[k], self._blocks[k + 1]
            if not mask[lo:hi].any():
                continue
            block_options = options
            if masked:
                block_options = {**options, "reset_mask": mask[lo:hi]}
            conn.send(("reset", (seeds[lo:hi], block_options)))
            sent.append(k)
        for k, (obs, info) in zip(sent, self._receive_all(sent), strict=True):
            self._block_obs[k], block_infos[k] = obs, info
        return _join(self._block_obs), _join_infos(block_infos, self._sizes)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every sub-environment with its row of ``actions`` (autoreset as configured)."""
        actions = np.asarray(actions)
        if actions.shape[:1] != (self.num_envs,):
            raise ValueError(
                f"actions: expected one row per sub-environment, shape ({self.num_envs}, ...), "
                f"found shape {actions.shape}"
            )
        for k, conn in enumerate(self._conns):
            conn.send(("step", actions[self._blocks[k] : self._blocks[k + 1]]))
        answers = self._receive_all()
        self._block_obs = [a[0] for a in answers]
        return (
            _join(self._block_obs),
            np.concatenate([a[1] for a in answers]),
            np.concatenate([a[2] for a in answers]),
            np.concatenate([a[3] for a in answers]),
            _join_infos([a[4] for a in answers], self._sizes),
        )

    def close_extras(self, **kwargs: Any) -> None:
        """Ask every worker to close its environments, then end the processes."""
        for conn, process in zip(self._conns, self._processes, strict=True):
            if process.is_alive():
                try:
                    conn.send(("close", None))
                    if conn.poll(10.0):
                        conn.recv()
                except (BrokenPipeError, EOFError, ConnectionResetError):
                    pass
            process.join(timeout=5.0)
            if process.is_alive():
                process.terminate()
                process.join(timeout=5.0)
            conn.close()
        self._conns, self._processes = [], []


def lift_v2_vector_env(num_envs: int = 1, **kwargs: Any) -> LiftVectorEnv:
    """The ``vector_entry_point`` of ``DualGraspLift-v2`` (``gym.make_vec``)."""
    return LiftVectorEnv(num_envs, env_id=LIFT_V2, **kwargs)
