"""``gym.make_vec("dg16m_env/DualGraspLift-v2", num_envs=N)``: N Lift environments in worker
processes, each worker stepping its share of them per message.

Gymnasium's ``AsyncVectorEnv`` sends one message per environment per step; a v2 step takes
about 330 us and a round trip through a pipe with its wake-ups 100-150 us, so two workers gained
nothing over one environment (BENCHMARKS.md). :class:`LiftVectorEnv` gives each of ``workers``
processes ``num_envs / workers`` environments and one message per step for all of them.
On the 2-core development VM, 2 workers against 1 measured 0.6-1.5x from run to run, better
with more environments per worker (1.54x with 32); two unsynchronised processes reach 1.9x
there, so the step barrier and the scheduler take the rest (BENCHMARKS.md).

What it returns is what ``gymnasium.vector.SyncVectorEnv`` returns for the same environments,
seeds and actions (the same observation bytes, rewards, flags and ``info`` entries; tested):
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

import multiprocessing
import os
import traceback
from copy import deepcopy
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array

LIFT_V2 = "dg16m_env/DualGraspLift-v2"


class _Block(VectorEnv):
    """A worker's environments: steps them and batches their results itself (observations,
    rewards, flags and Gymnasium's vector ``info`` over the block, ``VectorEnv._add_info``), so
    that the parent only joins the blocks."""

    def __init__(self, envs: list[Any], mode: str) -> None:
        super().__init__()
        self.envs = envs
        self.num_envs = len(envs)
        self.mode = AutoresetMode(mode)
        self.single_observation_space = envs[0].observation_space
        self._obs: list[Any] = [None] * len(envs)
        self._out = create_empty_array(self.single_observation_space, len(envs))
        self._pending = np.zeros(len(envs), dtype=np.bool_)  # NextStep: reset at the next step

    def batch(self) -> Any:
        return deepcopy(concatenate(self.single_observation_space, self._obs, self._out))

    def reset_block(self, items: list[Any]) -> tuple[Any, dict[str, Any]]:
        infos: dict[str, Any] = {}
        for i, item in enumerate(items):  # None: not in the reset mask
            if item is not None:
                self._obs[i], info = self.envs[i].reset(seed=item[0], options=item[1])
                self._pending[i] = False
                infos = self._add_info(infos, info, i)
        return self.batch(), infos

    def step_block(self, actions: np.ndarray) -> tuple[Any, ...]:
        n = self.num_envs
        rewards = np.zeros(n, dtype=np.float64)
        terminations = np.zeros(n, dtype=np.bool_)
        truncations = np.zeros(n, dtype=np.bool_)
        infos: dict[str, Any] = {}
        for i in range(n):
            if self.mode == AutoresetMode.NEXT_STEP and self._pending[i]:
                self._obs[i], info = self.envs[i].reset()
            else:
                if self.mode == AutoresetMode.DISABLED and self._pending[i]:
                    raise RuntimeError(
                        f"step: expected a reset of sub-environment {i} of this worker first "
                        "(autoreset_mode Disabled), found a step after its end"
                    )
                obs, rewards[i], terminations[i], truncations[i], info = self.envs[i].step(
                    actions[i]
                )
                self._obs[i] = obs
                if self.mode == AutoresetMode.SAME_STEP and (terminations[i] or truncations[i]):
                    infos = self._add_info(infos, {"final_obs": obs, "final_info": info}, i)
                    self._obs[i], info = self.envs[i].reset()
            infos = self._add_info(infos, info, i)
        self._pending = terminations | truncations
        return self.batch(), rewards, terminations, truncations, infos


def _serve(
    conn: Any, env_id: str, env_kwargs: dict[str, Any], count: int, cpu: int | None, mode: str
) -> None:
    """A worker: ``count`` environments, one command per message (``reset``, ``step``,
    ``close``); answers ``("ok", result)`` or ``("error", (message, traceback))`` and then
    stops."""
    try:
        if cpu is not None:
            os.sched_setaffinity(0, {cpu})
        import gymnasium

        import dg16m_env  # noqa: F401  registers the environments

        envs = [gymnasium.make(env_id, **env_kwargs) for _ in range(count)]
        first = envs[0]
        conn.send(("ok", (first.observation_space, first.action_space, dict(first.metadata))))
        block = _Block(envs, mode)
        while True:
            command, payload = conn.recv()
            if command == "close":
                for env in envs:
                    env.close()
                conn.send(("ok", None))
                return
            if command == "reset":
                conn.send(("ok", block.reset_block(payload)))
            elif command == "step":
                conn.send(("ok", block.step_block(payload)))
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
        self._terminations = np.zeros(num_envs, dtype=np.bool_)
        self._truncations = np.zeros(num_envs, dtype=np.bool_)

    # ---------------------------------------------------------------------------------------

    def _receive_all(self) -> list[Any]:
        """Every worker's answer, in order; closes everything and raises on an error."""
        answers, errors, details = [], [], []
        for k, conn in enumerate(self._conns):
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

    def _send_blocks(self, command: str, items: Any) -> list[Any]:
        """Send each worker its block of ``items``; the workers' answers, in order."""
        for k, conn in enumerate(self._conns):
            conn.send((command, items[self._blocks[k] : self._blocks[k + 1]]))
        return self._receive_all()

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
        options = dict(options) if options is not None else None
        mask = np.ones(self.num_envs, dtype=np.bool_)
        if options is not None and "reset_mask" in options:
            mask = options.pop("reset_mask")
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
        items = [(s, options) if m else None for s, m in zip(seeds, mask, strict=True)]
        answers = self._send_blocks("reset", items)
        self._terminations[mask] = False
        self._truncations[mask] = False
        observations = _join([a[0] for a in answers])
        infos = _join_infos([a[1] for a in answers], self._sizes)
        return observations, infos

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every sub-environment with its row of ``actions`` (autoreset as configured)."""
        actions = np.asarray(actions)
        if actions.shape[:1] != (self.num_envs,):
            raise ValueError(
                f"actions: expected one row per sub-environment, shape ({self.num_envs}, ...), "
                f"found shape {actions.shape}"
            )
        answers = self._send_blocks("step", actions)
        observations = _join([a[0] for a in answers])
        rewards = np.concatenate([a[1] for a in answers])
        self._terminations = np.concatenate([a[2] for a in answers])
        self._truncations = np.concatenate([a[3] for a in answers])
        infos = _join_infos([a[4] for a in answers], self._sizes)
        return observations, rewards, self._terminations.copy(), self._truncations.copy(), infos

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
