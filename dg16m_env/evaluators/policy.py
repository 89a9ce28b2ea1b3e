"""``policy``: success rate of a policy over seeded episodes of a Gymnasium environment.

The subject
-----------
One of:

* a callable ``policy(observation) -> action`` (``observation`` exactly as the environment
  returns it; ``deterministic`` does not apply to it);
* an object with ``predict(observation, deterministic=...) -> (action, state)``, like a
  stable-baselines3 model (detected by the attribute; ``state`` is ignored, each call sees one
  observation).

A callable policy with a ``reset()`` method (a stateful one, e.g. a scripted controller) has it
called at the start of every episode, after the environment's reset.

A ``name`` attribute (str), when present, is recorded in the result's ``subject``.

Protocol
--------
The environment ``gymnasium.make(env_id, max_episode_steps=..., **env_kwargs)`` is made once per
:meth:`PolicyEvaluator.evaluate`; episode ``i`` (0-based) starts with ``reset(seed=seed + i)`` and
runs until ``terminated`` or ``truncated`` (the environment must end its episodes: a registered
time limit or ``max_episode_steps``). Episodes are independent, so the success rate's 95 %
interval is the Wilson score interval (:func:`wilson_interval`) over episodes.

* Success of an episode: ``info["success"]``, else ``info["is_success"]``, of the LAST step's
  ``info`` (the ManiSkill and stable-baselines3 keys). An environment that gives neither at the
  end of an episode is refused (:class:`EvaluatorError`) rather than guessed.
* An episode where the policy raises an ``Exception`` or returns an action outside the action
  space (``action_space.contains``; a Box action is first made an array of the space's dtype, so
  a float64 list is fine for a float32 Box; a Discrete action may be a Python or numpy integer)
  ends there and counts as a failure, never dropped; its reason is counted in
  ``details["failure_reasons"]`` (``"ExcType: message"`` or ``"action outside <space>"``) and
  recorded per episode in ``details["failed_episodes"]``. Its return and length so far count in
  the means. The environment's own errors (``reset`` / ``step`` raising) stop the evaluation
  (:class:`EvaluatorError`).

Metrics: ``success_rate`` (``{"rate", "ci_low", "ci_high", "rows", "episodes", "objects"}``;
``rows`` = ``episodes`` = the number of episodes, ``objects`` the number of distinct object ids
or None), ``mean_return`` and ``mean_length`` (steps) over all episodes. When the reset ``info``
carries ``"object_id"``, ``per_object`` groups the episodes by it (``episodes``, ``successes``,
``success_rate`` with its Wilson interval, ``mean_return``).

Arguments of ``make("policy", ...)``: ``env_id`` (required: a registered Gymnasium id, or
``"module:Name-v0"`` to import the registering module first), ``n_episodes``, ``seed``,
``env_kwargs``, ``max_episode_steps``, ``deterministic``, ``progress``.
"""

from __future__ import annotations

import importlib
import math
import sys
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from statistics import NormalDist
from typing import Any

import numpy as np

from dg16m_core.checks import check_integer
from dg16m_core.progress import progress_bar

from .checkpoint import CheckpointError, CheckpointRequest, ObjectCheckpoint
from .code_identity import code_sha256
from .registry import Evaluator, EvaluatorError, register
from .result import EvaluationResult, code_subject, qualified_type

#: How to list the registered environment ids.
REGISTRY_HINT = 'python -c "import gymnasium; gymnasium.pprint_registry()"'


def wilson_interval(successes: int, n: int, level: float = 0.95) -> dict[str, Any]:
    """A success rate with its Wilson score interval (independent trials).

    Args:
        successes: successful trials (0 <= successes <= n).
        n: trials.
        level: confidence level in (0, 1).

    Returns:
        ``{"rate", "ci_low", "ci_high", "rows", "episodes"}`` (rate and bounds None when n = 0).
    """
    successes = check_integer("successes", successes, minimum=0, error=EvaluatorError)
    n = check_integer("n", n, minimum=0, error=EvaluatorError)
    if successes > n:
        raise EvaluatorError(f"successes: expected at most n = {n}, found {successes}")
    if not 0.0 < level < 1.0:
        raise EvaluatorError(f"level: expected a number in (0, 1), found {level!r}")
    if n == 0:
        return {"rate": None, "ci_low": None, "ci_high": None, "rows": 0, "episodes": 0}
    z = NormalDist().inv_cdf(0.5 + level / 2.0)
    rate = successes / n
    denom = 1.0 + z * z / n
    center = (rate + z * z / (2.0 * n)) / denom
    half = z * math.sqrt(rate * (1.0 - rate) / n + z * z / (4.0 * n * n)) / denom
    return {
        "rate": rate,
        "ci_low": 0.0 if successes == 0 else max(0.0, center - half),  # exact at the ends
        "ci_high": 1.0 if successes == n else min(1.0, center + half),
        "rows": n,
        "episodes": n,
    }


class _PolicyError(Exception):
    """The policy's output for one step cannot be used (the episode is a failure)."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason


@dataclass(frozen=True)
class Episode:
    """One episode's outcome.

    Attributes:
        success: the episode succeeded (False for a failed episode).
        ret: sum of the rewards (until the end or the failure).
        length: steps taken.
        object_id: the reset info's ``"object_id"`` (None when absent).
        reason: why the policy failed (None when it did not).
        detail: the full message of the failure.
    """

    success: bool
    ret: float
    length: int
    object_id: str | None = None
    reason: str | None = None
    detail: str | None = None


def _scalar(value: Any) -> Any:
    """A one-element value (Python, numpy, torch, list) as a Python scalar.

    Raises:
        ValueError: more or fewer than one element.
    """
    if isinstance(value, (bool, int, float)):
        return value
    if hasattr(value, "numel") and hasattr(value, "item"):  # a torch tensor, on any device
        if value.numel() != 1:
            raise ValueError(f"expected one value, found shape {tuple(value.shape)}")
        return value.item()
    array = np.asarray(value)
    if array.size != 1:
        raise ValueError(f"expected one value, found shape {array.shape}")
    return array.reshape(()).item()


def _describe(value: Any) -> str:
    text = repr(value)
    return f"{type(value).__name__} {text[:80]}{'...' if len(text) > 80 else ''}"


def _checked_action(space: Any, action: Any) -> Any:
    """``action`` made ready for ``env.step``.

    Raises:
        _PolicyError: the action is not an element of ``space``.
    """
    from gymnasium import spaces

    reason = f"action outside {space}"
    detail = f"action: expected an element of {space}, found {_describe(action)}"
    if isinstance(space, spaces.Box):
        try:
            array = np.asarray(action)
        except Exception:
            raise _PolicyError(reason, detail) from None
        kinds = "iu" if np.issubdtype(space.dtype, np.integer) else "iuf"
        if array.dtype.kind not in kinds or array.shape != space.shape:
            raise _PolicyError(reason, detail)
        with np.errstate(over="ignore", invalid="ignore"):
            cast = array.astype(space.dtype)  # float64 -> float32 rounding is accepted
            inside = bool(np.all(array >= space.low) and np.all(array <= space.high))
        if not inside or not space.contains(cast):
            raise _PolicyError(reason, detail)
        return cast
    try:
        ok = bool(space.contains(action))
    except Exception:
        ok = False
    if not ok:
        raise _PolicyError(reason, detail)
    return action


@register("policy")
class PolicyEvaluator(Evaluator):
    """Success rate of a policy over seeded episodes (see the module docstring)."""

    version = "1"
    subject_kind = "policy"

    def __init__(
        self,
        *,
        env_id: str | None = None,
        n_episodes: int = 100,
        seed: int = 0,
        env_kwargs: Mapping[str, Any] | None = None,
        max_episode_steps: int | None = None,
        deterministic: bool = True,
        progress: bool = False,
    ) -> None:
        self.n_episodes = check_integer("n_episodes", n_episodes, minimum=1, error=EvaluatorError)
        self.seed = check_integer("seed", seed, minimum=0, error=EvaluatorError)
        self.max_episode_steps = (
            None
            if max_episode_steps is None
            else check_integer(
                "max_episode_steps", max_episode_steps, minimum=1, error=EvaluatorError
            )
        )
        if env_kwargs is not None and (
            not isinstance(env_kwargs, Mapping) or not all(isinstance(k, str) for k in env_kwargs)
        ):
            raise EvaluatorError(
                f"env_kwargs: expected a mapping with str keys, found {_describe(env_kwargs)}"
            )
        self.env_kwargs = dict(env_kwargs or {})
        if not isinstance(deterministic, (bool, np.bool_)):
            raise EvaluatorError(f"deterministic: expected a bool, found {deterministic!r}")
        self.deterministic = bool(deterministic)
        self.progress = bool(progress)
        self.env_id = env_id if isinstance(env_id, str) else ""
        self.spec = self._find_spec(env_id)

    @staticmethod
    def _find_spec(env_id: Any) -> Any:
        """The Gymnasium spec of ``env_id`` (importing ``module`` of ``"module:Name-v0"``).

        Raises:
            EvaluatorError: gymnasium missing, or an unknown id.
        """
        try:
            import gymnasium
        except ImportError as exc:
            raise EvaluatorError(
                f"policy: expected gymnasium installed (pip install 'dg16m[sim]'), found {exc}"
            ) from None
        if not isinstance(env_id, str) or not env_id:
            raise EvaluatorError(
                f"env_id: expected a registered Gymnasium id (list them with {REGISTRY_HINT}), "
                f"found {env_id!r}"
            )
        module, _, name = env_id.rpartition(":")
        try:
            if module:
                importlib.import_module(module)
            return gymnasium.spec(name)
        except (gymnasium.error.Error, ImportError) as exc:
            raise EvaluatorError(
                f"env_id: expected a registered Gymnasium id (list them with {REGISTRY_HINT}; "
                f"'module:Name-v0' imports module first), found {env_id!r}: {exc}"
            ) from None

    def _env_record(self) -> dict[str, Any]:
        import gymnasium

        entry = self.spec.entry_point
        if callable(entry):
            entry = f"{getattr(entry, '__module__', '?')}:{getattr(entry, '__qualname__', entry)}"
        return {
            "id": self.spec.id,
            "entry_point": str(entry),
            "version": self.spec.version,
            "max_episode_steps": (
                self.max_episode_steps
                if self.max_episode_steps is not None
                else self.spec.max_episode_steps
            ),
            "gymnasium": gymnasium.__version__,
        }

    def _actor(self, subject: Any) -> tuple[Callable[[Any], Any], str]:
        predict = getattr(subject, "predict", None)
        if callable(predict):

            def act(observation: Any) -> Any:
                out = predict(observation, deterministic=self.deterministic)
                if not (isinstance(out, tuple) and len(out) == 2):
                    raise _PolicyError(
                        "predict: expected (action, state)",
                        f"predict: expected (action, state), found {_describe(out)}",
                    )
                return out[0]

            return act, "predict"
        if callable(subject):
            return subject, "callable"
        raise EvaluatorError(
            "policy: expected a callable policy(observation) -> action or an object with "
            f".predict(observation, deterministic=...), found {qualified_type(subject)}"
        )

    def _make_env(self) -> Any:
        import gymnasium

        try:
            return gymnasium.make(
                self.env_id, max_episode_steps=self.max_episode_steps, **self.env_kwargs
            )
        except Exception as exc:
            raise EvaluatorError(
                f"env {self.env_id}: expected gymnasium.make to succeed with env_kwargs "
                f"{sorted(self.env_kwargs)}, found {type(exc).__name__}: {exc}"
            ) from exc

    def _success(self, info: Any, episode: int) -> bool:
        keys = sorted(map(str, info)) if isinstance(info, Mapping) else []
        for key in ("success", "is_success"):
            if isinstance(info, Mapping) and key in info:
                try:
                    return bool(_scalar(info[key]))
                except ValueError as exc:
                    raise EvaluatorError(
                        f"env {self.env_id}: expected info[{key!r}] to be one bool at the end "
                        f"of episode {episode}, found {exc}"
                    ) from None
        raise EvaluatorError(
            f"env {self.env_id}: expected info['success'] or info['is_success'] at the end of an "
            f"episode, found keys {keys}"
        )

    def _episode(
        self, env: Any, act: Callable[[Any], Any], i: int, reset: Callable[[], Any] | None
    ) -> Episode:
        """Run episode ``i`` (reset with ``seed + i``; then the policy's own ``reset()``)."""
        try:
            observation, info = env.reset(seed=self.seed + i)
        except Exception as exc:
            raise EvaluatorError(
                f"env {self.env_id}: expected reset(seed={self.seed + i}) to succeed, found "
                f"{type(exc).__name__}: {exc}"
            ) from exc
        object_id = info.get("object_id") if isinstance(info, Mapping) else None
        object_id = None if object_id is None else str(object_id)
        ret, length = 0.0, 0
        if reset is not None:  # a stateful policy (e.g. a scripted one) starts afresh
            reset()
        while True:
            try:
                action = _checked_action(env.action_space, act(observation))
            except _PolicyError as exc:
                return Episode(False, ret, length, object_id, exc.reason, str(exc))
            except Exception as exc:  # the policy's own error fails only this episode
                reason = f"{type(exc).__name__}: {exc}"
                return Episode(False, ret, length, object_id, reason, reason)
            try:
                observation, reward, terminated, truncated, info = env.step(action)
                ret += float(_scalar(reward))
                done = bool(_scalar(terminated)) or bool(_scalar(truncated))
            except Exception as exc:
                raise EvaluatorError(
                    f"env {self.env_id}: expected step to succeed in episode {i} (seed "
                    f"{self.seed + i}, step {length}), found {type(exc).__name__}: {exc}"
                ) from exc
            length += 1
            if done:
                return Episode(self._success(info, i), ret, length, object_id)

    def run_parameters(self) -> dict[str, Any]:
        """Every argument that can change a score (a result's ``parameters``)."""
        return {
            "env_id": self.env_id,
            "n_episodes": self.n_episodes,
            "env_kwargs": self.env_kwargs,
            "max_episode_steps": self.max_episode_steps,
            "deterministic": self.deterministic,
            "env": self._env_record(),
        }

    def planned(self) -> dict[str, Any]:
        """See :meth:`Evaluator.planned`."""
        from dg16m_core.json_values import json_ready

        return json_ready(
            {
                **self.identity(),
                "benchmark": {},
                "parameters": self.run_parameters(),
                "seeds": {"reset": self.seed},
            }
        )

    def run_episodes(self, subject: Any, store: ObjectCheckpoint | None = None) -> list[Episode]:
        """Every episode's outcome, in order (see the module docstring); the episodes ``store``
        kept are not run again, and each finished one is recorded there."""
        act, _ = self._actor(subject)
        reset = getattr(subject, "reset", None)
        reset = (
            reset if callable(reset) and not callable(getattr(subject, "predict", None)) else None
        )
        done = _kept_episodes(store, self.n_episodes)
        todo = [i for i in range(self.n_episodes) if i not in done]
        env = self._make_env()
        try:
            for i in progress_bar(todo, desc="policy", enabled=self.progress):
                done[i] = self._episode(env, act, i, reset)
                if store is not None:
                    store.save(i, _episode_name(i), _episode_arrays(done[i]))
        finally:
            env.close()
        return [done[i] for i in range(self.n_episodes)]

    def evaluate(
        self, subject: Any, *, checkpoint: CheckpointRequest | None = None
    ) -> EvaluationResult:
        """Score ``subject`` (a policy, see the module docstring). With ``checkpoint``, each
        episode's outcome is recorded in its folder as it ends, and a resumed run
        (``checkpoint.resume``) runs only the episodes not recorded there. Episode ``i`` starts
        from ``reset(seed=seed + i)`` whichever run plays it, so the result is the same as
        without for a policy whose actions depend only on what it observed since its
        ``reset()`` (``deterministic=True`` for a ``predict`` model); the subject is told apart
        by :func:`~dg16m_env.evaluators.code_identity.code_sha256`.

        Raises:
            EvaluatorError: not a policy, the environment cannot be made, fails, or gives no
                success key at the end of an episode.
            CheckpointError: resuming a checkpoint of another run (policy, environment,
                parameters, seeds or versions).
        """
        _, interface = self._actor(subject)
        sha256 = code_sha256(subject)
        store = None
        if checkpoint is not None:
            store = ObjectCheckpoint(checkpoint, {**self.planned(), "subject": sha256})
        episodes = self.run_episodes(subject, store)
        n = len(episodes)
        successes = sum(e.success for e in episodes)
        returns = np.array([e.ret for e in episodes])
        lengths = np.array([e.length for e in episodes])
        object_ids = sorted({e.object_id for e in episodes if e.object_id is not None})
        success_rate = wilson_interval(successes, n)
        success_rate["objects"] = len(object_ids) if object_ids else None
        per_object: dict[str, dict[str, Any]] = {}
        if object_ids:
            groups: dict[str, list[Episode]] = {}
            for e in episodes:
                groups.setdefault(e.object_id or "(none)", []).append(e)
            for object_id, mine in groups.items():
                wins = sum(e.success for e in mine)
                per_object[object_id] = {
                    "episodes": len(mine),
                    "successes": wins,
                    "success_rate": wilson_interval(wins, len(mine)),
                    "mean_return": float(np.mean([e.ret for e in mine])),
                }
        failed = {str(i): e.detail for i, e in enumerate(episodes) if e.reason is not None}
        reasons = Counter(e.reason for e in episodes if e.reason is not None)
        result = self.result(
            benchmark={},
            subject=code_subject("policy", subject, interface, sha256),
            parameters=self.run_parameters(),
            seeds={"reset": self.seed},
            headline="success_rate",
            metrics={
                "success_rate": success_rate,
                "mean_return": float(returns.mean()),
                "mean_length": float(lengths.mean()),
            },
            per_object=per_object,
            details={
                "episodes": n,
                "successes": int(successes),
                "failed_episodes_count": len(failed),
                "failure_reasons": dict(sorted(reasons.items())),
                "failed_episodes": failed,
                "return_std": float(returns.std()),
                "return_min": float(returns.min()),
                "return_max": float(returns.max()),
                "length_min": int(lengths.min()),
                "length_max": int(lengths.max()),
            },
        )
        if store is not None:
            store.finish()
        return result


def _episode_name(i: int) -> str:
    """The name a checkpoint records episode ``i`` under (its "object id")."""
    return f"episode {i}"


def _episode_arrays(episode: Episode) -> dict[str, np.ndarray]:
    """What a checkpoint records of an episode (absent optional fields are left out)."""
    arrays = {
        "success": np.array(episode.success, dtype=bool),
        "ret": np.array(episode.ret, dtype=np.float64),
        "length": np.array(episode.length, dtype=np.int64),
    }
    for name in ("object_id", "reason", "detail"):
        value = getattr(episode, name)
        if value is not None:
            arrays[name] = np.array(value, dtype=str)
    return arrays


def _kept_episodes(store: ObjectCheckpoint | None, n_episodes: int) -> dict[int, Episode]:
    """The episodes a resumed checkpoint holds, by index.

    Raises:
        CheckpointError: an entry that is not an episode's record.
    """
    if store is None:
        return {}
    names = [_episode_name(i) for i in range(n_episodes)]
    position = {name: i for i, name in enumerate(names)}
    done: dict[int, Episode] = {}
    for name, entry in store.kept(names).items():
        arrays = entry["arrays"]
        try:
            done[position[name]] = Episode(
                success=bool(arrays["success"]),
                ret=float(arrays["ret"]),
                length=int(arrays["length"]),
                **{
                    field: str(arrays[field])
                    for field in ("object_id", "reason", "detail")
                    if field in arrays
                },
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise CheckpointError(
                f"policy checkpoint of {name}: expected its outcome (success, ret, length), "
                f"found {type(exc).__name__}: {exc}; remove the checkpoint folder or run "
                "without --resume"
            ) from None
    if done:
        print(
            f"policy: resuming: {len(done)} of {n_episodes} episodes kept from {store.folder}",
            file=sys.stderr,
        )
    return done
