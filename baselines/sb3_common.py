"""What the baseline training scripts share (the stable-baselines3 ones, ``bc_lift`` and
``residual_lift``): argument parsing from a dataclass, the output folder and the benchmark's
object split, the training environments, training with a learning curve (mean reward per
PPO/SAC rollout) and an atomic checkpoint, the held-out ``policy`` evaluators, the curve's
plot, the results file and the printed summary."""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from matplotlib.figure import Figure

from dataset_gen.io import package_version
from dg16m_core.atomic import atomic_path, write_json_atomic
from dg16m_env.envs.objects import split_objects as split_objects  # its home before issue 40
from dg16m_env.evaluators import EvaluationResult, load_benchmark_ref, make

A = TypeVar("A")


def field_docs(cls: type) -> dict[str, str]:
    """The attribute docstrings of a dataclass (the string under each field, CleanRL style),
    one line each."""
    import ast
    import inspect
    import itertools
    import textwrap

    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    except (OSError, TypeError):  # no source (e.g. defined in a REPL)
        return {}
    body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
    docs: dict[str, str] = {}
    for node, after in itertools.pairwise(body):
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and isinstance(after, ast.Expr)
            and isinstance(after.value, ast.Constant)
            and isinstance(after.value.value, str)
        ):
            docs[node.target.id] = " ".join(after.value.value.split())
    return docs


def parse_args(cls: type[A], description: str, argv: list[str] | None = None) -> A:
    """The dataclass ``cls`` filled from ``--field-name value`` flags (defaults: its own), each
    flag described by its field's docstring and default."""
    parser = argparse.ArgumentParser(description=" ".join(description.split()))
    docs = field_docs(cls)
    for field in dataclasses.fields(cls):  # type: ignore[arg-type]
        flag = "--" + field.name.replace("_", "-")
        kind = _boolean if isinstance(field.default, bool) else type(field.default)
        text = docs.get(field.name, field.name).replace("%", "%%")
        parser.add_argument(
            flag, type=kind, default=field.default, help=f"{text} (default: %(default)s)"
        )
    return cls(**vars(parser.parse_args(argv)))


def output_and_split(out: Path) -> tuple[list[str], list[str]]:
    """Make the output folder ``out``; the procedural benchmark's training and held-out object
    ids (:func:`split_objects`: every third object held out)."""
    out.mkdir(parents=True, exist_ok=True)
    return split_objects(list(load_benchmark_ref().object_ids))


def training_envs(env_id: str, args: Any, env_kwargs: dict[str, Any], **options: Any) -> Any:
    """SB3's ``make_vec_env`` of ``args.n_envs`` environments of ``env_id`` seeded from
    ``args.seed`` (``options``: its other keywords, e.g. ``wrapper_class``)."""
    from stable_baselines3.common.env_util import make_vec_env

    return make_vec_env(
        env_id, n_envs=args.n_envs, seed=args.seed, env_kwargs=env_kwargs, **options
    )


def learn(model: Any, args: Any, curve: Any, checkpoint: str) -> float:
    """Train ``model`` for ``args.total_timesteps`` with the learning-curve callback ``curve``
    and save it to ``args.out / checkpoint`` (:func:`save_model`); the training seconds."""
    started = time.perf_counter()
    model.learn(total_timesteps=args.total_timesteps, callback=curve)
    seconds = time.perf_counter() - started
    save_model(model, args.out / checkpoint)
    return seconds


def policy_evaluator(env_id: str, episodes: int, seed: int, env_kwargs: dict[str, Any]) -> Any:
    """The registered ``policy`` evaluator: ``episodes`` seeded episodes (reset seeds ``seed +
    i``) of ``env_id`` made with ``env_kwargs``, with a progress bar."""
    return make(
        "policy",
        env_id=env_id,
        n_episodes=episodes,
        seed=seed,
        env_kwargs=env_kwargs,
        progress=True,
    )


def _boolean(text: str) -> bool:
    """``true/false``, ``yes/no``, ``1/0`` (argparse's ``type=bool`` would take "false" as
    True)."""
    value = text.strip().lower()
    if value in ("true", "yes", "1"):
        return True
    if value in ("false", "no", "0"):
        return False
    raise argparse.ArgumentTypeError(f"expected true or false, found {text!r}")


def reward_curve_callback() -> Any:
    """An SB3 callback recording ``(timesteps, mean reward of the last 1,000 or more steps)``
    in ``.points`` (the rest at the end of training)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class RewardCurve(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.points: list[tuple[int, float]] = []
            self.rewards: list[float] = []

        def _flush(self) -> None:
            if self.rewards:
                self.points.append((self.num_timesteps, float(np.mean(self.rewards))))
                self.rewards = []

        def _on_step(self) -> bool:
            self.rewards.extend(float(r) for r in np.atleast_1d(self.locals["rewards"]))
            if len(self.rewards) >= 1000:
                self._flush()
            return True

        def _on_training_end(self) -> None:
            self._flush()

    return RewardCurve()


def plot_curve(
    path: Path,
    points: list[tuple[int, float]],
    results: dict[str, EvaluationResult],
    *,
    title: str,
    ylabel: str,
    train_label: str,
) -> None:
    """The learning curve with each evaluated policy's success rate and Wilson interval."""
    fig = Figure(figsize=(6.4, 4.2))
    ax = fig.add_subplot()
    if points:
        steps, rewards = np.array(points).T
        ax.plot(steps, rewards, color="C0", label=train_label)
    ax.set_xlabel("training steps")
    ax.set_ylabel(ylabel)
    twin = ax.twinx() if ylabel != "success rate" else ax
    for k, (name, result) in enumerate(results.items()):
        rate = result.metrics["success_rate"]
        color = f"C{k + 1}"
        twin.axhline(rate["rate"], color=color, label=f"{name}: {rate['rate']:.2f} (eval)")
        twin.axhspan(rate["ci_low"], rate["ci_high"], color=color, alpha=0.15)
    twin.set_ylim(0, 1)
    if twin is not ax:
        twin.set_ylabel("evaluated success rate (Wilson 95% CI)")
        twin.legend(fontsize=7, loc="lower right")
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title(title)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)


def report(
    args: Any,
    results: dict[str, EvaluationResult],
    curve: Any,
    *,
    env_id: str,
    title: str,
    ylabel: str,
    train_label: str,
    **facts: Any,
) -> None:
    """Write ``args.out/learning_curve.png`` and ``args.out/results.json``, print each
    policy's success rate."""
    plot_curve(
        args.out / "learning_curve.png",
        curve.points,
        results,
        title=title,
        ylabel=ylabel,
        train_label=train_label,
    )
    write_run(
        args.out / "results.json",
        args,
        results,
        env_id=env_id,
        learning_curve=curve.points,
        **facts,
    )
    print_results(results, args.out)


def print_results(results: dict[str, EvaluationResult], out: Path) -> None:
    """Each policy's success rate (one line each), then the output folder."""
    for name, result in results.items():
        print(f"{name:<17} {result.format().splitlines()[1].strip()}")
    print(f"wrote {out}")


def save_model(model: Any, path: Path) -> None:
    """Save an SB3 model to ``path`` (a ``.zip``) atomically: an interrupted save leaves the
    previous checkpoint, never half a file."""
    with atomic_path(path) as tmp:
        model.save(tmp)


def write_run(path: Path, args: Any, results: dict[str, EvaluationResult], **extra: Any) -> None:
    """The run's arguments, package version, extra facts and every evaluation result (JSON)."""
    write_json_atomic(
        path,
        {
            "args": {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()},
            "package_version": package_version(),
            **extra,
            "results": {name: r.to_dict() for name, r in results.items()},
        },
    )


def uniform_actions(shape: tuple[int, ...], seed: int) -> Any:
    """A policy drawing each action uniformly from ``[-1, 1]^shape`` (float32)."""
    rng = np.random.default_rng(seed)

    def act(observation: Any) -> np.ndarray:
        return rng.uniform(-1.0, 1.0, size=shape).astype(np.float32)

    return act


def lift_held_out_evaluators(
    env_id: str, test_ids: list[str], episodes: int, real_episodes: int, seed: int
) -> tuple[Any, Any]:
    """The registered ``policy`` evaluators of a Lift baseline: ``episodes`` seeded episodes
    (reset seeds ``seed + i``) on the procedural benchmark's held-out objects ``test_ids``, and
    ``real_episodes`` on the real benchmark's held-out objects with the same seeds (None when
    ``real_episodes`` is 0)."""
    evaluator = policy_evaluator(env_id, episodes, seed, {"object_ids": test_ids})
    if not real_episodes:
        return evaluator, None
    real = load_benchmark_ref("real", lazy=True)
    real_ids = split_objects(list(real.object_ids))[1]
    kwargs = {"benchmark": "real", "object_ids": real_ids}
    return evaluator, policy_evaluator(env_id, real_episodes, seed, kwargs)
