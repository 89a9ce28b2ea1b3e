"""Collect demonstrations of a Lift expert (:class:`~dg16m_env.envs.lift.experts.FeedbackLiftExpert`
by default, or :class:`~dg16m_env.envs.lift.recovering_expert.RecoveringLiftExpert`) on
``dg16m_env/DualGraspLift-v2`` (default), ``-v3`` or ``-v1`` into a Farama Minari dataset
(:func:`collect_lift_demos`, ``dg16m demos collect``): the episodes run in worker processes, are
written in index order and the dataset is renamed into place. What the files hold, and how
they are read and replayed, is :mod:`dg16m_env.envs.lift.demo_files`.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import sys
import tempfile
import time
import warnings
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dg16m_core.checks import check_integer
from dg16m_core.distribution import package_version
from dg16m_core.errors import Dg16mError
from dg16m_core.progress import progress_bar
from dg16m_env.envs.lift.demo_files import (
    DATASET_ID,
    DEFAULT_DATASET_ID,
    DEMO_EXPERTS,
    DEMO_OBS_MODES,
    ENV_ID,
    ENV_IDS,
    METADATA_KEY,
    OBJECT_SETS,
    SCHEMA_VERSION,
    LiftDemosError,
    check_dataset_id,
    datasets_root,
    episode_metadata,
    import_minari,
)

FLUSH_EPISODES = 64
"""Finished episodes are written in index order, this many at a time (bounds memory)."""

_RESERVED_KWARGS = ("benchmark", "object_ids", "obs_mode")


# --------------------------------------------------------------------------------------------
# Arguments
# --------------------------------------------------------------------------------------------


def select_objects(object_ids: Sequence[str], objects: str | Sequence[str] = "train") -> list[str]:
    """The object ids an episode is drawn from.

    Args:
        object_ids: the benchmark's object ids, in benchmark order.
        objects: ``"train"`` (default; :func:`~dg16m_env.envs.objects.split_objects`' first
            part, two of every three objects), ``"held-out"`` (every third), ``"all"``, a
            comma-separated string of ids or a sequence of ids.
    """
    from dg16m_env.envs.objects import split_objects

    if isinstance(objects, str):
        if objects == "train":
            return split_objects(list(object_ids))[0]
        if objects == "held-out":
            return split_objects(list(object_ids))[1]
        if objects == "all":
            return list(object_ids)
        objects = [part.strip() for part in objects.split(",") if part.strip()]
    chosen, known = [str(i) for i in objects], set(object_ids)
    unknown = [i for i in chosen if i not in known]
    if unknown or not chosen:
        raise LiftDemosError(
            f"objects: expected one of {OBJECT_SETS} or ids of the benchmark's "
            f"{len(object_ids)} objects (e.g. {object_ids[0]!r}), found "
            f"{unknown[:3] if unknown else 'none'}"
        )
    return chosen


def _benchmark_argument(benchmark: str | os.PathLike[str]) -> str:
    """A short name as given, a file as its absolute path (stored in the env kwargs)."""
    from dg16m_env.benchmark.names import SHIPPED_BENCHMARKS

    if isinstance(benchmark, str) and benchmark in SHIPPED_BENCHMARKS:
        return benchmark
    return str(Path(benchmark).resolve())


def _env_config(
    env_id: str,
    benchmark: str,
    object_ids: list[str],
    obs_mode: str,
    env_kwargs: Mapping[str, Any] | None,
) -> dict[str, Any]:
    """``{"env_id", "kwargs", "max_episode_steps"}`` of the collection env (JSON values)."""
    if env_id not in ENV_IDS:
        raise LiftDemosError(f"env_id: expected one of {ENV_IDS}, found {env_id!r}")
    if obs_mode not in DEMO_OBS_MODES:
        raise LiftDemosError(f"obs_mode: expected one of {DEMO_OBS_MODES}, found {obs_mode!r}")
    extra = dict(env_kwargs or {})
    clash = sorted(set(extra) & set(_RESERVED_KWARGS))
    if clash:
        raise LiftDemosError(
            f"env_kwargs: expected none of {_RESERVED_KWARGS} (they have their own arguments), "
            f"found {clash}"
        )
    kwargs = {"benchmark": benchmark, "object_ids": object_ids, "obs_mode": obs_mode, **extra}
    try:
        json.dumps(kwargs, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise LiftDemosError(
            f"env_kwargs: expected JSON values (they are stored in the dataset), found {exc}"
        ) from None
    steps = extra.get("episode_steps")
    return {
        "env_id": env_id,
        "kwargs": kwargs,
        "max_episode_steps": int(steps) if isinstance(steps, int) else None,
    }


def _make_env(config: Mapping[str, Any]) -> Any:
    from dg16m_env.envs.lift.vector import make_env

    kwargs = dict(config["kwargs"])
    if config["max_episode_steps"] is not None:
        kwargs["max_episode_steps"] = config["max_episode_steps"]
    # without Gymnasium's note that a newer version is registered: the version is the command's
    # choice (--env-id; the default, v2, is the one bc_lift's results name, ENV_ID)
    return make_env(config["env_id"], kwargs)


def _make_expert(config: Mapping[str, Any]) -> Any:
    from dg16m_env.envs.lift.expert_registry import make_lift_expert

    return make_lift_expert(
        config.get("expert", "feedback"),
        lift_height=float(config["kwargs"].get("lift_height", 0.10)),
    )


# --------------------------------------------------------------------------------------------
# One episode
# --------------------------------------------------------------------------------------------


def _stack(values: list[Any]) -> Any:
    """Per-step observations -> one array (T + 1, ...) or a dict of them."""
    if isinstance(values[0], Mapping):
        return {key: np.stack([v[key] for v in values]) for key in values[0]}
    return np.stack(values)


def run_expert_episode(env: Any, expert: Any, seed: int) -> dict[str, Any]:
    """One episode of ``expert`` on ``env`` from ``reset(seed=seed)``.

    Returns:
        ``seed``, ``object_id``, ``observations`` ((T + 1, 117) float32 or a dict of
        (T + 1, n)), ``actions`` ((T, 14) float32), ``rewards`` ((T,) float64),
        ``terminations``, ``truncations`` ((T,) bool), ``infos`` (``success``, ``fail``:
        (T + 1,) bool), ``success`` (bool), ``termination`` (str), ``steps`` (T), ``return``.
    """
    obs, info = env.reset(seed=int(seed))
    observations, actions, rewards = [obs], [], []
    terminations, truncations = [], []
    success, fail = [bool(info["success"])], [bool(info["fail"])]
    terminated = truncated = False
    while not (terminated or truncated):
        action = np.asarray(expert(obs), dtype=np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(obs)
        actions.append(action)
        rewards.append(float(reward))
        terminations.append(bool(terminated))
        truncations.append(bool(truncated))
        success.append(bool(info["success"]))
        fail.append(bool(info["fail"]))
    termination = str(info.get("termination") or "") or "truncated"
    return {
        "seed": int(seed),
        "object_id": str(env.unwrapped.object_id),
        "observations": _stack(observations),
        "actions": np.stack(actions).astype(np.float32),
        "rewards": np.asarray(rewards, dtype=np.float64),
        "terminations": np.asarray(terminations, dtype=bool),
        "truncations": np.asarray(truncations, dtype=bool),
        "infos": {"success": np.asarray(success), "fail": np.asarray(fail)},
        "success": bool(info["success"]),
        "termination": termination,
        "steps": len(actions),
        "return": float(np.sum(rewards)),
    }


_WORKER: dict[str, tuple[Any, Any]] = {}
"""Per process: the env and expert of each collection config (made once per worker)."""


def _episode_task(index: int, config: dict[str, Any], seed0: int) -> dict[str, Any]:
    """Worker task: episode ``index`` (seed ``seed0 + index``) with this process's env."""
    key = json.dumps(config, sort_keys=True)
    if key not in _WORKER:
        _WORKER[key] = (_make_env(config), _make_expert(config))
    env, expert = _WORKER[key]
    return run_expert_episode(env, expert, seed0 + index)


def _close_workers() -> None:
    while _WORKER:
        env, _ = _WORKER.popitem()[1]
        env.close()


# --------------------------------------------------------------------------------------------
# Collection
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CollectReport:
    """What :func:`collect_lift_demos` wrote."""

    path: Path
    """The dataset folder (``ROOT/<dataset_id>``; Minari's files under ``data/``)."""
    dataset_id: str
    episodes: int
    successes: int
    steps: int
    """Steps (transitions) of all episodes."""
    wall_s: float
    """Wall time of the collection and writing (s)."""
    workers: int

    def format(self) -> str:
        """Two lines: where, and the counts with the Wilson interval and the speed."""
        from dg16m_env.evaluators.policy import wilson_interval

        rate = wilson_interval(self.successes, self.episodes)
        return (
            f"wrote {self.dataset_id} at {self.path}\n"
            f"{self.episodes} episodes, {self.steps} steps, success {self.successes}/"
            f"{self.episodes} = {rate['rate']:.3f} (Wilson 95% {rate['ci_low']:.3f}-"
            f"{rate['ci_high']:.3f}), {self.wall_s:.1f} s ({self.episodes / self.wall_s:.2f} "
            f"episodes/s, {self.workers} worker{'s' if self.workers != 1 else ''})"
        )


@contextlib.contextmanager
def _minari_root(root: Path) -> Iterator[None]:
    """Minari reads its root from ``MINARI_DATASETS_PATH`` on every call: point it at
    ``root`` while inside (not thread-safe: the process environment). Made absolute: Minari
    joins a relative root onto its own paths under it when it adds episodes to a dataset, so
    ``--out runs/demos`` failed on the second batch of episodes (issue 56)."""
    previous = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(Path(root).absolute())
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = previous


def _buffer(episode: Mapping[str, Any]) -> Any:
    from minari.data_collector import EpisodeBuffer

    return EpisodeBuffer(
        seed=episode["seed"],
        observations=episode["observations"],
        actions=episode["actions"],
        rewards=episode["rewards"],
        terminations=episode["terminations"],
        truncations=episode["truncations"],
        infos=episode["infos"],
    )


def _requirements() -> list[str]:
    """pip-style pins to remake the env (Minari's ``requirements``)."""
    import mujoco

    return [f"dg16m=={package_version()}", f"mujoco=={mujoco.__version__}"]


def _episode_attrs(episode: Mapping[str, Any], expert: str) -> dict[str, Any]:
    return {
        "object_id": episode["object_id"],
        "expert": expert,
        "success": bool(episode["success"]),
        "termination": episode["termination"],
        "steps": int(episode["steps"]),
        "return": float(episode["return"]),
        "schema_version": SCHEMA_VERSION,
    }


class _Writer:
    """Writes finished episodes in index order into a new Minari dataset (in Minari's root
    ``tmp_root``)."""

    def __init__(self, tmp_root: Path, dataset_id: str, env: Any, description: str) -> None:
        self.tmp_root, self.dataset_id, self.env = tmp_root, dataset_id, env
        self.description = description
        self.dataset: Any = None
        self.written = 0

    def write(self, episodes: list[dict[str, Any]], expert: str) -> None:
        minari = import_minari()
        buffers = [_buffer(e) for e in episodes]
        with _minari_root(self.tmp_root):
            if self.dataset is None:
                with warnings.catch_warnings():  # no e-mail or permalink to give
                    warnings.filterwarnings("ignore", message=r"`(author_email|code_permalink)`")
                    self.dataset = minari.create_dataset_from_buffers(
                        dataset_id=self.dataset_id,
                        buffer=buffers,
                        env=self.env,
                        eval_env=self.env.spec,
                        algorithm_name=expert,
                        author="dg16m",
                        description=self.description,
                        data_format="hdf5",
                        requirements=_requirements(),
                    )
            else:
                self.dataset.update_dataset_from_buffer(buffers)
        indices = range(self.written, self.written + len(episodes))
        self.dataset.storage.update_episode_metadata(
            [_episode_attrs(e, expert) for e in episodes], indices
        )
        self.written += len(episodes)


def collect_lift_demos(
    root: str | os.PathLike[str] | None = None,
    *,
    episodes: int,
    dataset_id: str = DEFAULT_DATASET_ID,
    env_id: str = ENV_ID,
    benchmark: str | os.PathLike[str] = "procedural",
    objects: str | Sequence[str] = "train",
    seed: int = 0,
    workers: int = 1,
    obs_mode: str = "state",
    env_kwargs: Mapping[str, Any] | None = None,
    expert: str = "feedback",
    force: bool = False,
    progress: bool = True,
) -> CollectReport:
    """Run a Lift expert (default :class:`~dg16m_env.envs.lift.experts.FeedbackLiftExpert`)
    for ``episodes`` episodes and write them as the Minari dataset ``dataset_id`` under
    ``root``.

    Args:
        root: Minari root folder (default :func:`datasets_root`: ``$MINARI_DATASETS_PATH`` or
            ``~/.minari/datasets``); the dataset goes to ``root/<dataset_id>``.
        episodes: how many (>= 1); episode ``i`` resets with seed ``seed + i``.
        dataset_id: ``(namespace/)name-vN``.
        env_id: one of :data:`ENV_IDS` (default :data:`ENV_ID`, v2).
        benchmark: ``"procedural"`` (default), ``"real"`` or a benchmark file.
        objects: ``"train"`` (default), ``"held-out"``, ``"all"`` or object ids
            (:func:`select_objects`).
        seed: the first episode's seed (>= 0).
        workers: processes (>= 1), each with its own env; the data do not depend on it.
        obs_mode: ``"state"`` (default) or ``"state_dict"``.
        env_kwargs: more ``gym.make`` keyword arguments (JSON values, stored), e.g.
            ``{"episode_steps": 50}`` (then also the ``TimeLimit``), ``{"reward_mode":
            "sparse"}``; ``lift_height`` is passed to the expert as well.
        expert: ``"feedback"`` (default) or ``"recovering"``
            (:data:`~dg16m_env.envs.lift.expert_registry.LIFT_EXPERTS`); the dataset records its class.
        force: replace an existing dataset of that id.
        progress: a progress bar on stderr (:func:`dg16m_core.progress.progress_bar`).

    Raises:
        LiftDemosError: bad arguments, the dataset exists (without ``force``), no minari.
    """
    minari = import_minari()

    from dataset_gen.pipeline.parallel import run_tasks
    from dg16m_env.benchmark.ref import load_benchmark_ref

    episodes = check_integer("episodes", episodes, minimum=1, error=LiftDemosError)
    seed = check_integer("seed", seed, minimum=0, error=LiftDemosError)
    workers = check_integer("workers", workers, minimum=1, error=LiftDemosError)
    dataset_id = check_dataset_id(dataset_id)
    root = datasets_root(root)
    target = root / dataset_id
    if target.exists() and not force:
        raise LiftDemosError(
            f"{target}: expected no dataset there (use force / --force to replace it), found one"
        )
    bench = _benchmark_argument(benchmark)
    ref = load_benchmark_ref(bench, (env_kwargs or {}).get("mesh_root"), lazy=True)
    object_ids = select_objects(ref.object_ids, objects)
    config = _env_config(env_id, bench, object_ids, obs_mode, env_kwargs)
    if expert not in DEMO_EXPERTS:
        raise LiftDemosError(f"expert: expected one of {DEMO_EXPERTS}, found {expert!r}")
    config["expert"] = expert
    try:  # checks the kwargs before any worker starts; gives the spaces
        env = _make_env(config)
    except Dg16mError:
        raise
    except (TypeError, ValueError) as exc:  # the env's own checks of its kwargs
        raise LiftDemosError(f"{env_id}: {exc}") from None
    expert = type(_make_expert(config)).__name__
    start = time.perf_counter()
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp_root = Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-", dir=target.parent))
    successes = steps = done = 0
    try:
        writer = _Writer(
            tmp_root,
            dataset_id,
            env,
            f"{expert} on {env_id} ({bench} benchmark, {len(object_ids)} objects: "
            f"{objects if isinstance(objects, str) else 'listed'}), all episodes kept.",
        )
        finished: dict[int, dict[str, Any]] = {}
        bar = progress_bar(total=episodes, desc="lift demos", unit="ep", enabled=progress)
        with bar:
            for index, episode in run_tasks(
                _episode_task, list(range(episodes)), (config, seed), workers=workers
            ):
                finished[index] = episode
                successes += episode["success"]
                steps += episode["steps"]
                bar.update(1)
                done += 1
                bar.set_postfix(success=f"{successes / done:.2f}")
                ready = _ready(finished, writer.written)
                if len(ready) >= FLUSH_EPISODES or writer.written + len(ready) == episodes:
                    writer.write([finished.pop(i) for i in ready], expert)
        wall = time.perf_counter() - start
        _finish_metadata(writer.dataset, config, ref, objects, seed, episodes, workers, wall)
        _move_into_place(tmp_root / dataset_id, target, tmp_root)
        _ensure_namespaces(minari, root, dataset_id)
    finally:
        env.close()
        if workers == 1:
            _close_workers()
        shutil.rmtree(tmp_root, ignore_errors=True)
    wall = time.perf_counter() - start
    return CollectReport(target, dataset_id, episodes, successes, steps, wall, workers)


def _ready(finished: Mapping[int, Any], written: int) -> list[int]:
    """The finished indices that continue the written ones without a gap."""
    ready, index = [], written
    while index in finished:
        ready.append(index)
        index += 1
    return ready


def _finish_metadata(
    dataset: Any,
    config: Mapping[str, Any],
    ref: Any,
    objects: str | Sequence[str],
    seed: int,
    episodes: int,
    workers: int,
    wall_s: float,
) -> None:
    import mujoco

    from dg16m_env.evaluators.policy import wilson_interval

    rows = episode_metadata(dataset)
    successes = sum(bool(r["success"]) for r in rows)
    steps = [int(r["steps"]) for r in rows]
    expert = _make_expert(config)
    ours = {
        "schema_version": SCHEMA_VERSION,
        "env_id": config["env_id"],
        "env_kwargs": config["kwargs"],
        "max_episode_steps": config["max_episode_steps"],
        "expert": {
            "name": type(expert).__name__,
            "module": type(expert).__module__,
            "lift_height": expert.lift_height,
            "lift_margin": expert.lift_margin,
        },
        "seeds": {"first": seed, "last": seed + episodes - 1, "rule": "episode i: seed + i"},
        "benchmark": config["kwargs"]["benchmark"],
        "benchmark_sha256": ref.sha256,
        "objects": objects if isinstance(objects, str) else "listed",
        "n_objects": len(config["kwargs"]["object_ids"]),
        "split_rule": "train/held-out: every third benchmark object held out (split_objects)",
        "obs_mode": config["kwargs"]["obs_mode"],
        "package_version": package_version(),
        "mujoco_version": mujoco.__version__,
        "python": sys.version.split()[0],
        "episodes": len(rows),
        "steps": int(sum(steps)),
        "successes": successes,
        "success_rate": wilson_interval(successes, len(rows)),
        "terminations": dict(sorted(Counter(r["termination"] for r in rows).items())),
        "workers": workers,
        "collect_wall_s": round(wall_s, 3),
    }
    dataset.storage.update_metadata({METADATA_KEY: ours})


def _move_into_place(built: Path, target: Path, tmp_root: Path) -> None:
    """Rename the built dataset folder onto ``target``; an existing one is moved into
    ``tmp_root`` first (removed with it)."""
    if target.exists():
        os.replace(target, tmp_root / ".replaced")
    os.replace(built, target)


def _ensure_namespaces(minari: Any, root: Path, dataset_id: str) -> None:
    """Minari's namespace files (``namespace_metadata.json``) for the id's namespace."""
    namespace = DATASET_ID.fullmatch(dataset_id).group("namespace")  # type: ignore[union-attr]
    if namespace is None:
        return
    from minari.namespace import create_namespace, list_local_namespaces

    with _minari_root(root):
        if namespace not in list_local_namespaces():
            create_namespace(namespace, description="dg16m demonstrations (dg16m demos collect)")
