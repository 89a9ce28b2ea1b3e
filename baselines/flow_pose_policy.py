"""The learned dual-grasp generator as a ``DualGraspPose-v0`` policy from the point cloud (issue 59).

Reads top to bottom (CleanRL style): the policy, one dataclass of arguments, then the run.

:class:`CloudGraspPolicy` turns a dual-grasp predictor that reads a cloud (the learned
generator, :data:`baselines.flow_predictor.flow_predictor`, by default) into a policy of
``dg16m_env/DualGraspPose-v0`` with pose actions: from the environment's observation alone
(``obs_mode="partial"``: what ``n_cameras`` seeded depth cameras see, object frame; no mesh, no
object id) it proposes the predictor's best dual grasp as the action's two hand poses. The
predictor's random stream is named by a hash of the observed points (the same observation, the
same action).

The script runs ``episodes`` seeded episodes (reset seeds ``seed + i``, the held-out seeds of
``baselines.sb3_pose``) on the benchmark's held-out objects
(:func:`dg16m_env.envs.objects.split_objects`) for each policy of ``policies``:

* ``flow``: the shipped generator and ranker (:data:`baselines.flow_predictor.flow_predictor`);
* ``flow_random``: the same pairs in random order within the force-closure groups (the ranker's
  control);
* ``sampler``: the cloud sampler's hands only, with the same pairing, checks and ranker (the
  generator's ablation);
* ``random_actions``: uniform actions in ``[-1, 1]^(2 x 9)`` (what SAC starts from).

With ``obs_mode="full"`` the environment shows points drawn over the whole surface instead
(the same policies; a control for what the cameras miss). An episode is one benchmark trial
with the benchmark's pose noise (``level="full"``: held through the whole protocol). A policy
that raises (no dual candidate on the cloud) or returns an action outside the space fails its
episode; nothing is left out of the rate. Success rates with Wilson 95% intervals, each
policy's paired difference from the first (the same episodes; a seeded bootstrap over
episodes), the trials' invalid starts (``info["invalid_reason"]``: a hand penetrating the
object, the hands overlapping), the seconds per action and each episode's record go to
``out`` (JSON), the rates to stdout and, with ``plot``, a bar chart.

    .venv/bin/python -m baselines.flow_pose_policy --out runs/flow_pose/procedural.json
"""

from __future__ import annotations

import collections
import hashlib
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from baselines.cloud_inputs import CloudError
from baselines.sb3_common import parse_args, uniform_actions
from dg16m_core.atomic import write_json_atomic
from dg16m_core.progress import progress_bar
from dg16m_env.physics.trial_protocol import InvalidReason

ENV_ID = "dg16m_env/DualGraspPose-v0"
POLICIES = ("flow", "flow_random", "sampler", "random_actions")
"""The policies the script can score (module docstring)."""
INVALID_STARTS = tuple(r.name.lower() for r in InvalidReason if r != InvalidReason.NONE)
"""``info["invalid_reason"]`` of a trial not run because its start was invalid (a hand in the
object, the hands overlapping): the env's names of the trial's invalid reasons."""


def policy_cloud(observation: Mapping[str, Any]) -> dict[str, Any]:
    """The observed points and normals of a ``DualGraspPose-v0`` observation (flat or shaped),
    the mask applied, as a predictor's observation: ``points`` (P, 3), ``normals`` (P, 3) and an
    ``object_id`` naming its random stream (``"cloud-"`` + 16 hex digits of the points' sha256).

    Raises:
        CloudError: not a mapping with ``points`` and ``normals`` of 3 P values each (and a
            ``mask`` of P values, when given), or no point left after the mask.
    """
    if not isinstance(observation, Mapping):
        raise CloudError(f"observation: expected a dict, found {type(observation).__name__}")
    missing = [key for key in ("points", "normals") if key not in observation]
    if missing:
        raise CloudError(f"observation: expected keys {missing}, found {sorted(observation)}")
    points = np.asarray(observation["points"], dtype=np.float64)
    normals = np.asarray(observation["normals"], dtype=np.float64)
    if points.size % 3 or points.size == 0 or normals.shape != points.shape:
        raise CloudError(
            "observation points/normals: expected two arrays of 3 P values (P > 0), found "
            f"{points.shape} and {normals.shape}"
        )
    points, normals = points.reshape(-1, 3), normals.reshape(-1, 3)
    keep = np.ones(len(points), dtype=bool)
    if "mask" in observation:
        mask = np.asarray(observation["mask"], dtype=np.float64).reshape(-1)
        if mask.shape != (len(points),):
            raise CloudError(
                f"observation mask: expected {len(points)} values, found {mask.shape[0]}"
            )
        keep = mask > 0.5
    if not keep.any():
        raise CloudError("observation: expected at least one observed point, found none")
    points = np.ascontiguousarray(points[keep])
    name = "cloud-" + hashlib.sha256(points.tobytes()).hexdigest()[:16]
    return {"points": points, "normals": normals[keep], "object_id": name}


def _flow_predictor() -> Callable[[dict[str, Any]], tuple[np.ndarray, np.ndarray]]:
    from baselines.flow_predictor import flow_predictor

    return flow_predictor


@dataclass(frozen=True)
class CloudGraspPolicy:
    """A dual-grasp predictor as a ``DualGraspPose-v0`` policy (pose actions).

    ``policy(observation) -> action``: the predictor's best dual grasp for the observation's
    cloud (:func:`policy_cloud`) as a float32 (2, 9) action (per hand the grasp frame's position
    in the object frame, m, and its 6D rotation: closing then approach axis).

    Attributes:
        predictor: ``predictor(observation) -> (poses (k, 2, 4, 4), scores (k,))``, best first
            (default: the shipped learned generator and ranker).
        name: recorded as the subject's name.

    A call raises :class:`~baselines.cloud_inputs.CloudError` for a malformed observation
    (:func:`policy_cloud`) or, from the predictor, when the cloud gives no dual candidate.
    """

    predictor: Callable[[dict[str, Any]], tuple[np.ndarray, np.ndarray]] = field(
        default_factory=_flow_predictor
    )
    name: str = "flow"

    def __call__(self, observation: Mapping[str, Any]) -> np.ndarray:
        from dg16m_env.envs.spaces import action_from_poses

        poses, _ = self.predictor(policy_cloud(observation))
        if len(poses) == 0:
            raise CloudError("predictor: expected at least one dual grasp, found none")
        return action_from_poses(np.asarray(poses[0])).astype(np.float32)


@dataclass
class Args:
    policies: str = "flow,flow_random,sampler,random_actions"
    """comma-separated policies (module docstring)"""
    benchmark: str = "procedural"
    """the benchmark whose held-out objects are grasped: procedural or real"""
    episodes: int = 200
    """episodes per policy"""
    seed: int = 100000
    """first reset seed (baselines.sb3_pose's held-out seeds)"""
    obs_mode: str = "partial"
    """the environment's observation: "partial" (what the depth cameras see) or "full" (points
    drawn over the whole surface: a control for what the cameras miss)"""
    n_cameras: int = 2
    """depth cameras of the environment's partial observation"""
    n_points: int = 4096
    """points of the observation (the predictors close their hands on up to 4,096)"""
    threads: int = 1
    """torch threads of the predictors"""
    out: Path = Path("runs/flow_pose/results.json")
    """the results (JSON)"""
    plot: str = ""
    """a bar chart of the success rates (PNG path; empty: none)"""


def check_args(args: Args) -> list[str]:
    """The policies asked for; ``ValueError`` naming what was expected."""
    names = [name.strip() for name in args.policies.split(",") if name.strip()]
    unknown = [name for name in names if name not in POLICIES]
    if not names or unknown:
        raise ValueError(f"policies: expected names from {POLICIES}, found {args.policies!r}")
    if args.benchmark not in ("procedural", "real"):
        raise ValueError(f"benchmark: expected 'procedural' or 'real', found {args.benchmark!r}")
    if args.obs_mode not in ("partial", "full"):
        raise ValueError(f"obs_mode: expected 'partial' or 'full', found {args.obs_mode!r}")
    for name in ("episodes", "n_cameras", "n_points", "threads"):
        value = getattr(args, name)
        if not isinstance(value, int) or value < 1:
            raise ValueError(f"{name}: expected an integer >= 1, found {value!r}")
    if args.seed < 0:
        raise ValueError(f"seed: expected an integer >= 0, found {args.seed}")
    return names


def make_policy(name: str, args: Args) -> Callable[[Any], np.ndarray]:
    """The policy named ``name`` (:data:`POLICIES`)."""
    from baselines.flow_predictor import FlowPredictor

    if name == "random_actions":
        return uniform_actions((2, 9), args.seed)
    options = {"flow": {}, "flow_random": {"ranker": "random"}, "sampler": {"proposals": "sampler"}}
    return CloudGraspPolicy(FlowPredictor(k=1, threads=args.threads, **options[name]), name)


def run_episode(env: Any, policy: Callable[[Any], np.ndarray], seed: int) -> dict[str, Any]:
    """One episode: its success, the trial's invalid reason, or the policy's failure (its
    :class:`~baselines.cloud_inputs.CloudError`, or an action outside the space; any other
    exception is a bug and propagates)."""
    observation, info = env.reset(seed=seed)
    record: dict[str, Any] = {"seed": seed, "object_id": info.get("object_id")}
    started = time.perf_counter()
    try:
        action = np.asarray(policy(observation), dtype=np.float32)
    except CloudError as error:  # no candidate, or a cloud the predictor refuses: a failure
        return {**record, "success": False, "failure": f"CloudError: {error}", "seconds": None}
    record["seconds"] = round(time.perf_counter() - started, 4)
    if not env.action_space.contains(action):
        return {**record, "success": False, "failure": "action outside the space"}
    _, _, _, _, info = env.step(action)
    return {
        **record,
        "success": bool(info["success"]),
        "failure": None if info["success"] else (info.get("invalid_reason") or "not held"),
    }


def summarise(episodes: list[dict[str, Any]]) -> dict[str, Any]:
    """Success rate with its Wilson 95% interval, failure reasons, seconds per action."""
    from dg16m_env.evaluators.policy import wilson_interval

    successes = sum(e["success"] for e in episodes)
    seconds = [e["seconds"] for e in episodes if e.get("seconds") is not None]
    failures = collections.Counter(e["failure"] for e in episodes if not e["success"])
    reasons = {str(k).split(":")[0]: v for k, v in sorted(failures.items(), key=str)}
    invalid = sum(failures[name] for name in INVALID_STARTS)
    return {
        **wilson_interval(successes, len(episodes)),
        "successes": successes,
        "invalid_starts": invalid / len(episodes),
        "failures": reasons,
        "median_seconds": float(np.median(seconds)) if seconds else None,
        "max_seconds": float(np.max(seconds)) if seconds else None,
    }


def _seen(results: dict[str, Any]) -> str:
    """What the policies saw, for the plot's title."""
    if results["obs_mode"] == "full":
        return "the whole surface"
    return f"{results['n_cameras']} depth cameras"


def paired_difference(
    first: list[dict[str, Any]], other: list[dict[str, Any]], seed: int, resamples: int = 2000
) -> dict[str, float]:
    """``other``'s success rate minus ``first``'s over the same episodes (same seeds, so the same
    objects), with a 95% interval from ``resamples`` seeded bootstrap resamples of episodes."""
    if [e["seed"] for e in first] != [e["seed"] for e in other]:
        raise ValueError("expected episodes of the same seeds, found different ones")
    diff = np.array([o["success"] for o in other], float) - [f["success"] for f in first]
    rows = np.random.default_rng(seed).integers(0, len(diff), (resamples, len(diff)))
    low, high = np.percentile(diff[rows].mean(axis=1), [2.5, 97.5])
    return {"difference": float(diff.mean()), "ci_low": float(low), "ci_high": float(high)}


def plot_rates(results: dict[str, Any], path: Path) -> None:
    """Bars of each policy's success rate with Wilson 95% intervals."""
    from dg16m_core.figures import new_figure, save_png

    rows = results["rates"]
    fig = new_figure(5.5, 3.0)
    ax = fig.add_subplot(1, 1, 1)
    for i, row in enumerate(rows):
        err = [[row["rate"] - row["ci_low"]], [row["ci_high"] - row["rate"]]]
        ax.bar(i, row["rate"], 0.6, color=f"C{i}")
        ax.errorbar(i, row["rate"], yerr=err, color="black", capsize=3, lw=1)
        ax.text(i, row["ci_high"] + 0.02, f"{row['rate']:.1%}", ha="center", fontsize=8)
    ax.set_xticks(range(len(rows)), [row["policy"] for row in rows])
    ax.set_ylim(0.0, 1.0)
    ax.set_ylabel("success (Wilson 95%)")
    ax.set_title(
        f"DualGraspPose-v0 from {_seen(results)}, "
        f"{results['benchmark']} held-out, {results['episodes']} episodes",
        fontsize=9,
    )
    fig.tight_layout()
    save_png(fig, path, dpi=120)


def main(args: Args | None = None) -> dict[str, Any]:
    args = args or parse_args(Args, __doc__.split("\n\n")[0])
    names = check_args(args)
    import gymnasium as gym

    from dg16m_env.envs.objects import split_objects
    from dg16m_env.evaluators import load_benchmark_ref

    ref = load_benchmark_ref(None if args.benchmark == "procedural" else args.benchmark)
    held_out = split_objects(list(ref.object_ids))[1]
    env = gym.make(
        ENV_ID,
        benchmark=ref,
        object_ids=held_out,
        obs_mode=args.obs_mode,
        n_cameras=args.n_cameras,
        n_points=args.n_points,
        fc_info=False,
    )
    started = time.monotonic()
    rows: list[dict[str, Any]] = []
    for name in names:
        policy = make_policy(name, args)
        seeds = range(args.seed, args.seed + args.episodes)
        episodes = [run_episode(env, policy, seed) for seed in progress_bar(seeds, desc=name)]
        row = {"policy": name, **summarise(episodes), "episodes": episodes}
        if rows:
            paired = paired_difference(rows[0]["episodes"], episodes, args.seed)
            row["paired_vs_first"] = {"policy": rows[0]["policy"], **paired}
        rows.append(row)
        print(
            f"{name}: {row['successes']}/{args.episodes} = {row['rate']:.1%} "
            f"[{row['ci_low']:.1%}, {row['ci_high']:.1%}]; invalid starts "
            f"{row['invalid_starts']:.1%}; failures {row['failures']}"
            + (
                f"; minus {rows[0]['policy']} {row['paired_vs_first']['difference']:+.1%} "
                f"[{row['paired_vs_first']['ci_low']:+.1%}, "
                f"{row['paired_vs_first']['ci_high']:+.1%}]"
                if "paired_vs_first" in row
                else ""
            )
        )
    env.close()
    results: dict[str, Any] = {
        "env_id": ENV_ID,
        "benchmark": args.benchmark,
        "episodes": args.episodes,
        "first_seed": args.seed,
        "obs_mode": args.obs_mode,
        "n_cameras": args.n_cameras,
        "n_points": args.n_points,
        "objects": len({e["object_id"] for e in rows[0]["episodes"]}),
        "seconds": round(time.monotonic() - started, 1),
        "rates": rows,
    }
    write_json_atomic(args.out, results)
    if args.plot:
        plot_rates(results, Path(args.plot))
    return results


if __name__ == "__main__":
    main()
