"""A block of environments stepped one after the other in one process (:class:`EnvBlock`:
``SyncVectorEnv``'s loop, each environment's ``info`` kept as a record), and the batching of
records into a vector ``info`` (:func:`batch_infos`: Gymnasium's documented layout, built
column by column). The pieces of :class:`~dg16m_env.envs.lift.vector.LiftVectorEnv`, which
runs a block in this process and one in each worker process; they import Gymnasium only."""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium.spaces import Space
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array, iterate

Record = tuple[int, dict[str, Any]]
"""``(env index, info)``: one environment's ``info`` as ``SyncVectorEnv``'s loop meets it."""


# --- a block: SyncVectorEnv's loop, info as records ------------------------------------------


class EnvBlock:
    """Environments stepped one after the other with ``SyncVectorEnv``'s loop (the same
    observations, rewards, flags and autoreset), each environment's ``info`` returned as a
    :data:`Record` (in the order the loop meets them, indices within the block) for the
    caller to batch (:func:`batch_infos`)."""

    def __init__(
        self,
        envs: list[gymnasium.Env],
        autoreset_mode: AutoresetMode,
        single_observation_space: Space,
    ) -> None:
        self.envs = envs
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        self.space = single_observation_space
        n = len(envs)
        self.action_space = batch_space(envs[0].action_space, n)
        self.env_obs: list[Any] = [None] * n
        self.observations = create_empty_array(single_observation_space, n=n, fn=np.zeros)
        self.rewards = np.zeros(n, dtype=np.float64)
        self.terminations = np.zeros(n, dtype=np.bool_)
        self.truncations = np.zeros(n, dtype=np.bool_)
        self.autoreset = np.zeros(n, dtype=np.bool_)

    def spaces(self) -> tuple[list[Space], list[Space]]:
        """Each environment's observation and action space."""
        return [env.observation_space for env in self.envs], [env.action_space for env in self.envs]

    def reset(
        self, seeds: list[int | None], options: dict[str, Any] | None, mask: np.ndarray | None
    ) -> tuple[Any, list[Record]]:
        """Reset every environment, or those of ``mask`` (``options`` without the mask)."""
        if mask is None:
            mask = np.ones(len(self.envs), dtype=np.bool_)
        self.terminations[mask] = False
        self.truncations[mask] = False
        self.autoreset[mask] = False
        records: list[Record] = []
        for i in np.flatnonzero(mask).tolist():
            self.env_obs[i], info = self.envs[i].reset(seed=seeds[i], options=options)
            records.append((i, info))
        return concatenate(self.space, self.env_obs, self.observations), records

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, list[Record]]:
        """Step every environment with its row of ``actions``, autoreset as configured."""
        records: list[Record] = []
        for i, action in enumerate(iterate(self.action_space, actions)):
            env = self.envs[i]
            if self.autoreset_mode == AutoresetMode.NEXT_STEP and self.autoreset[i]:
                self.env_obs[i], info = env.reset()
                self.rewards[i] = 0.0
                self.terminations[i] = False
                self.truncations[i] = False
            else:
                if self.autoreset_mode == AutoresetMode.DISABLED:
                    assert not self.autoreset[i], f"{self.autoreset=}"
                (
                    self.env_obs[i],
                    self.rewards[i],
                    self.terminations[i],
                    self.truncations[i],
                    info,
                ) = env.step(action)
                ended = self.terminations[i] or self.truncations[i]
                if self.autoreset_mode == AutoresetMode.SAME_STEP and ended:
                    records.append((i, {"final_obs": self.env_obs[i], "final_info": info}))
                    self.env_obs[i], info = env.reset()
            records.append((i, info))
        self.autoreset = np.logical_or(self.terminations, self.truncations)
        obs = concatenate(self.space, self.env_obs, self.observations)
        return obs, self.rewards.copy(), self.terminations.copy(), self.truncations.copy(), records

    def call(self, name: str, args: tuple[Any, ...], kwargs: dict[str, Any]) -> list[Any]:
        """``SyncVectorEnv.call``: each environment's ``name`` called, or read if not callable."""
        results = []
        for env in self.envs:
            function = env.get_wrapper_attr(name)
            results.append(function(*args, **kwargs) if callable(function) else function)
        return results

    def set_attr(self, name: str, values: list[Any]) -> None:
        """Set ``name`` of each environment to its value."""
        for env, value in zip(self.envs, values, strict=True):
            env.set_wrapper_attr(name, value)

    def close(self) -> None:
        """Close every environment."""
        for env in self.envs:
            env.close()


# --- batching the records ---------------------------------------------------------------------

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
            return None  # a subclass: record by record
        else:
            array = np.empty(num_envs, dtype=object)
            for env_num, value in enumerate(column):
                array[env_num] = value
        batched[key], batched["_" + key] = array, ones.copy()
    return batched


def _add_record(batched: dict[str, Any], info: dict[str, Any], env_num: int, n: int) -> None:
    """Add one record to ``batched`` as Gymnasium's ``VectorEnv._add_info`` does (its
    documented ``info`` layout): each key's array typed by its first value (numbers by their
    type, arrays by shape and dtype, anything else in an object array), ``final_obs`` in an
    object array, dictionaries batched inside, and a ``_key`` mask after each key."""
    for key, value in info.items():
        array: Any
        if key == "final_obs":
            array = batched.get(key)
            if array is None:
                array = np.full(n, fill_value=None, dtype=object)
            array[env_num] = value
        elif isinstance(value, dict):
            array = batched.get(key, {})
            _add_record(array, value, env_num, n)
        else:
            if key in batched:
                array = batched[key]
            elif type(value) in _NUMBERS or issubclass(type(value), np.number):
                array = np.zeros(n, dtype=type(value))
            elif isinstance(value, np.ndarray):
                array = np.zeros((n, *value.shape), dtype=value.dtype)
            else:
                array = np.full(n, fill_value=None, dtype=object)
            array[env_num] = value
        mask = batched.get(f"_{key}", np.zeros(n, dtype=np.bool_))
        mask[env_num] = True
        batched[key], batched[f"_{key}"] = array, mask


def batch_infos(records: list[Record], num_envs: int) -> dict[str, Any]:
    """The vector ``info`` of ``num_envs`` environments from ``(env index, info)`` records in
    call order: what ``SyncVectorEnv`` builds record by record (:func:`_add_record`), one
    array per key at once where every environment has one record with the same keys and
    value types (the usual step)."""
    if all(env_num == i for i, (env_num, _) in enumerate(records)):
        batched = _batch_columns([info for _, info in records], num_envs)
        if batched is not None:
            return batched
    infos: dict[str, Any] = {}
    for env_num, info in records:
        _add_record(infos, info, env_num, num_envs)
    return infos
