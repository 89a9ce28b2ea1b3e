"""``dg16m demos``: demonstrations of the Lift expert in Farama's Minari format.

``collect`` runs :class:`~dg16m_env.envs.lift.experts.FeedbackLiftExpert` on
``dg16m_env/DualGraspLift-v2`` (or ``-v1``: ``--env-id``) and writes a Minari dataset;
``replay`` re-runs recorded episodes and checks them step for step; ``info`` summarises a
dataset. The logic lives in :mod:`dg16m_env.envs.lift.demos` (collecting) and
:mod:`dg16m_env.envs.lift.demo_files` (reading, replaying); this module parses and prints.
Building the parser imports no MuJoCo, Minari or h5py: the handlers import them when they run.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from dg16m_core.arguments import add_progress_argument, add_seed_argument
from dg16m_core.cli import add_command
from dg16m_core.errors import Dg16mError
from dg16m_env.envs.lift.demo_files import (
    DEFAULT_DATASET_ID,
    DEMO_EXPERTS,
    DEMO_OBS_MODES,
    ENV_ID,
    ENV_IDS,
    OBJECT_SETS,
)


class DemosCommandError(Dg16mError, ValueError):
    """Bad ``dg16m demos`` arguments (an episode list that is not one)."""


DEMOS_EXAMPLES = (
    "  dg16m demos collect --episodes 500 --workers 2 --out runs/demos\n"
    "  dg16m demos info runs/demos/dg16m/lift-expert-v0\n"
    "  dg16m demos replay runs/demos/dg16m/lift-expert-v0 --episodes 0,1,2\n"
)

COLLECT_EXAMPLES = (
    "  # 500 episodes on the training objects of the procedural benchmark, 2 processes\n"
    "  dg16m demos collect --episodes 500 --workers 2 --out runs/demos\n"
    "  # then in Python: MINARI_DATASETS_PATH=runs/demos, minari.load_dataset('dg16m/lift-expert-v0')\n"
    "  # a quick try: 3 short episodes as named parts, another id\n"
    "  dg16m demos collect --episodes 3 --episode-steps 40 --obs-mode state_dict \\\n"
    "      --dataset-id dg16m/lift-try-v0 --out runs/demos\n"
    "  # the held-out objects, seeds 10000.., replacing an earlier dataset of that id\n"
    "  dg16m demos collect --episodes 200 --objects held-out --seed 10000 \\\n"
    "      --dataset-id dg16m/lift-expert-heldout-v0 --out runs/demos --force\n"
    "  # two given objects of the real benchmark, into Minari's own root (~/.minari/datasets)\n"
    "  dg16m demos collect --episodes 20 --benchmark real --objects ID1,ID2 \\\n"
    "      --dataset-id dg16m/lift-real-v0\n"
)

REPLAY_EXAMPLES = (
    "  dg16m demos replay runs/demos/dg16m/lift-expert-v0              # episode 0\n"
    "  dg16m demos replay runs/demos/dg16m/lift-expert-v0 --episodes 3,17\n"
    "  dg16m demos replay runs/demos/dg16m/lift-expert-v0 --all\n"
    "  MINARI_DATASETS_PATH=runs/demos dg16m demos replay dg16m/lift-expert-v0\n"
)

INFO_EXAMPLES = (
    "  dg16m demos info runs/demos/dg16m/lift-expert-v0\n"
    "  MINARI_DATASETS_PATH=runs/demos dg16m demos info dg16m/lift-expert-v0 --json\n"
)

DATASET_HELP = (
    "a dataset folder (ROOT/ID, e.g. runs/demos/dg16m/lift-expert-v0) or a dataset id under "
    "Minari's root (MINARI_DATASETS_PATH, default ~/.minari/datasets)"
)


def register(subparsers: Any) -> None:
    """Add ``dg16m demos`` (``collect``, ``replay``, ``info``)."""
    demos = add_command(
        subparsers,
        "demos",
        "Demonstrations of the Lift expert as a Minari dataset: collect, replay, info.",
        DEMOS_EXAMPLES,
        description="Demonstrations of FeedbackLiftExpert on dg16m_env/DualGraspLift-v2 (or -v1) in "
        "Farama's Minari format (needs the demos extra: pip install -e '.[demos]'). Generated "
        "by command, never shipped nor downloaded.",
    )
    actions = demos.add_subparsers(dest="action", metavar="ACTION", required=True)
    collect = add_command(
        actions,
        "collect",
        "Run the expert and write its episodes (all of them) as a Minari dataset.",
        COLLECT_EXAMPLES,
        description="Run FeedbackLiftExpert on a DualGraspLift env for N episodes and write them as the "
        "Minari dataset ROOT/ID (HDF5). Episode i resets with seed S + i and the env draws its "
        "object from the chosen objects with that seed, so the data are the same bytes for any "
        "--workers. Every episode is kept, failed ones too; each records its seed, object, "
        "success, termination and steps, the dataset its env id and kwargs, expert, seeds, "
        "benchmark (and sha256), versions and success rate. Written atomically (built in a "
        "hidden folder beside the target, then renamed); an existing dataset is refused "
        "unless --force. Prints the success rate (Wilson 95%% interval) and the speed.",
    )
    _collect_arguments(collect)
    replay = add_command(
        actions,
        "replay",
        "Re-run recorded episodes from their seeds and actions; check every step.",
        REPLAY_EXAMPLES,
        description="Remake the env from the dataset (Minari's stored env spec), reset it with "
        "each episode's recorded seed, apply the recorded actions, and check that the "
        "observations, rewards, terminations and truncations are the same bytes as recorded "
        "(on the machine and build that collected them). Prints one line per episode: "
        "identical, or the first step that differs and what differed. Exit status 1 when any "
        "episode differs.",
    )
    replay.add_argument("dataset", metavar="DATASET", help=DATASET_HELP)
    which = replay.add_mutually_exclusive_group()
    which.add_argument(
        "--episodes",
        default="0",
        metavar="K,K",
        help="episode indices, comma-separated (default: 0)",
    )
    which.add_argument("--all", action="store_true", help="every episode")
    replay.set_defaults(handler=_replay)
    info = add_command(
        actions,
        "info",
        "Counts of a dataset: episodes, steps, success rate (Wilson 95%%), objects.",
        INFO_EXAMPLES,
        description="Summarise a demonstrations dataset: episodes and steps (per episode "
        "min / median / mean / max), the success rate with its Wilson 95%% interval, the "
        "terminations, the objects (distinct ids, the most frequent) and how it was collected.",
    )
    info.add_argument("dataset", metavar="DATASET", help=DATASET_HELP)
    info.add_argument("--json", action="store_true", help="print JSON instead of text")
    info.set_defaults(handler=_info)


def _collect_arguments(collect: argparse.ArgumentParser) -> None:
    collect.add_argument(
        "--episodes", type=int, required=True, metavar="N", help="episodes to collect"
    )
    collect.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="ROOT",
        help="Minari root folder; the dataset goes to ROOT/ID (default: MINARI_DATASETS_PATH, "
        "else ~/.minari/datasets)",
    )
    collect.add_argument(
        "--dataset-id",
        default=DEFAULT_DATASET_ID,
        metavar="ID",
        help=f"(namespace/)name-vN (default: {DEFAULT_DATASET_ID})",
    )
    collect.add_argument(
        "--env-id",
        choices=ENV_IDS,
        default=ENV_ID,
        help=f"the environment (default: {ENV_ID})",
    )
    collect.add_argument(
        "--benchmark",
        default="procedural",
        metavar="B",
        help="procedural (default), real, or a benchmark file",
    )
    collect.add_argument(
        "--objects",
        default="train",
        metavar="SET",
        help=f"{' | '.join(OBJECT_SETS)} | ID,ID,...: the objects episodes are drawn from; "
        "train and held-out split the benchmark's objects as every learning baseline does "
        "(every third object held out; default: train)",
    )
    add_seed_argument(collect, "seed of episode 0 (default: 0)", metavar="S")
    collect.add_argument(
        "--workers", type=int, default=1, metavar="W", help="processes (default: 1)"
    )
    collect.add_argument(
        "--obs-mode",
        choices=DEMO_OBS_MODES,
        default="state",
        help="the env's observation mode (default: state, the flat 117-number vector)",
    )
    collect.add_argument(
        "--episode-steps",
        type=int,
        default=None,
        metavar="T",
        help="the env's episode length (default: the env's, 200 steps = 10 s)",
    )
    collect.add_argument(
        "--expert",
        choices=DEMO_EXPERTS,
        default="feedback",
        help="the expert: feedback (FeedbackLiftExpert, default) or recovering "
        "(RecoveringLiftExpert: resumes from where the hands are, holds their relative pose "
        "while lifting, regrasps)",
    )
    collect.add_argument("--force", action="store_true", help="replace an existing dataset")
    add_progress_argument(collect)
    collect.set_defaults(handler=_collect)


# --------------------------------------------------------------------------------------------
# Handlers
# --------------------------------------------------------------------------------------------


def _collect(args: argparse.Namespace) -> int:
    from dg16m_env.envs.lift.demo_files import datasets_root
    from dg16m_env.envs.lift.demos import collect_lift_demos

    env_kwargs = {} if args.episode_steps is None else {"episode_steps": args.episode_steps}
    report = collect_lift_demos(
        args.out,
        episodes=args.episodes,
        dataset_id=args.dataset_id,
        env_id=args.env_id,
        benchmark=args.benchmark,
        objects=args.objects,
        seed=args.seed,
        workers=args.workers,
        obs_mode=args.obs_mode,
        env_kwargs=env_kwargs,
        expert=args.expert,
        force=args.force,
        progress=not args.no_progress,
    )
    print(report.format())
    root = datasets_root(args.out)
    print(
        f'load it: MINARI_DATASETS_PATH={root} python -c "import minari; '
        f"print(minari.load_dataset('{report.dataset_id}'))\""
    )
    return 0


def _episode_list(text: str) -> list[int]:
    try:
        indices = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise DemosCommandError(
            f"--episodes: expected comma-separated indices like 0,3,17, found {text!r}"
        ) from None
    if not indices:
        raise DemosCommandError(f"--episodes: expected at least one index, found {text!r}")
    return indices


def _replay(args: argparse.Namespace) -> int:
    from dg16m_env.envs.lift.demo_files import demos_metadata, open_lift_demos, replay_lift_demo

    dataset = open_lift_demos(args.dataset)
    demos_metadata(dataset)  # refuse another dataset before making an env
    total = dataset.storage.total_episodes
    indices = list(range(total)) if args.all else _episode_list(args.episodes)
    bad = [i for i in indices if not 0 <= i < total]
    if bad:
        raise DemosCommandError(f"--episodes: expected indices in [0, {total}), found {bad[:5]}")
    env = dataset.recover_environment()
    mismatches = 0
    try:
        for index in indices:
            report = replay_lift_demo(dataset, index, env=env)
            mismatches += not report.identical
            print(report.format(), flush=True)
    finally:
        env.close()
    n = len(indices)
    verdict = "identical" if mismatches == 0 else f"{mismatches} differ"
    print(f"replayed {n} episode{'s' if n != 1 else ''}: {verdict}")
    return 1 if mismatches else 0


def _info(args: argparse.Namespace) -> int:
    from dg16m_env.envs.lift.demo_files import open_lift_demos, summarize_lift_demos

    dataset = open_lift_demos(args.dataset)
    summary = summarize_lift_demos(dataset)
    summary["path"] = str(dataset.storage.data_path.parent)
    if args.json:
        print(json.dumps(summary, indent=2, allow_nan=False))
        return 0
    sys.stdout.write(format_summary(summary))
    return 0


def format_summary(summary: dict[str, Any]) -> str:
    """The text ``dg16m demos info`` prints for
    :func:`~dg16m_env.envs.lift.demo_files.summarize_lift_demos`."""
    meta, steps, rate = summary["metadata"], summary["steps"], summary["success_rate"]
    objects = summary["objects"]
    n = summary["episodes"]
    success_steps = steps["mean_success"]
    lines = [
        f"dataset     {summary['dataset_id']} ({summary.get('path', '')})",
        f"episodes    {n}, {steps['total']} steps (per episode min {steps['min']}, median "
        f"{steps['median']:g}, mean {steps['mean']:.1f}, max {steps['max']}; successful mean "
        f"{'-' if success_steps is None else f'{success_steps:.1f}'})",
        f"success     {summary['successes']}/{n} = {rate['rate']:.3f} (Wilson 95% "
        f"{rate['ci_low']:.3f}-{rate['ci_high']:.3f})",
        "ended       "
        + ", ".join(f"{name} {count}" for name, count in summary["terminations"].items()),
        f"objects     {objects['distinct']} distinct of {objects['of']} ({objects['selection']}); "
        "most frequent: " + ", ".join(f"{k} {s}/{e}" for k, e, s in objects["most_frequent"]),
        f"collected   {meta['expert']['name']} on {meta['env_id']}, benchmark "
        f"{meta['benchmark']} (sha256 {meta['benchmark_sha256'][:12]}), obs {meta['obs_mode']}, "
        f"seeds {meta['seeds']['first']}-{meta['seeds']['last']}",
        f"built with  dg16m {meta['package_version']}, MuJoCo {meta['mujoco_version']}, "
        f"{meta['workers']} worker(s), {meta['collect_wall_s']:.1f} s",
    ]
    return "\n".join(lines) + "\n"
