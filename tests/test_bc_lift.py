"""The behaviour-cloning Lift baseline (``baselines/bc_lift.py``) end to end on a two-episode
Minari dataset: it trains, runs a DAgger round, evaluates three policies on two held-out
episodes each and writes the policy, the curve and the results; bad options are refused."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("minari")

from baselines.lift_bc_policy import LiftBCPolicy
from dg16m_env.envs.lift.demos import collect_lift_demos


@pytest.fixture(scope="module")
def demos(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("demos")
    # seed 42 over all objects: ladder-1000002, an episode the expert completes
    collect_lift_demos(root, episodes=2, objects="all", seed=42, progress=False)
    return root / "dg16m" / "lift-expert-v0"


def test_two_episode_smoke_run(tmp_path: Path, demos: Path) -> None:
    out = tmp_path / "run"
    tiny = ["--hidden", "16", "--layers", "1", "--epochs", "1", "--dagger-episodes", "1"]
    subprocess.run(
        [
            sys.executable,
            "-m",
            "baselines.bc_lift",
            "--demos",
            str(demos),
            *tiny,
            "--eval-episodes",
            "2",
            "--out",
            str(out),
        ],
        check=True,
        capture_output=True,
        timeout=600,
    )
    results = json.loads((out / "results.json").read_text())
    assert set(results["results"]) == {"bc_dagger", "expert", "random_actions"}
    for result in results["results"].values():
        assert result["metrics"]["success_rate"]["episodes"] == 2
    assert results["demonstrations"]["episodes"] == 2
    assert [r["round"] for r in results["rounds"]] == [0, 1]
    assert (out / "success_rates.png").stat().st_size > 10_000
    policy = LiftBCPolicy.load(out / "policy.pt")
    assert policy.hidden == 16


def refusal(tmp_path: Path, demos: Path, *options: str) -> str:
    """The error output of a run with ``options`` that must fail."""
    command = [sys.executable, "-m", "baselines.bc_lift", "--demos", str(demos), *options]
    result = subprocess.run(
        [*command, "--out", str(tmp_path / "run")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode != 0
    return result.stderr


def test_wrong_phases_are_refused(tmp_path: Path, demos: Path) -> None:
    assert "expected 'all' or phases among" in refusal(tmp_path, demos, "--dagger-phases", "grasp")


def test_on_path_labels_keep_the_grasp_phases_and_approach_states_on_the_paths() -> None:
    import gymnasium as gym

    from baselines.bc_lift import dagger_rollouts
    from dg16m_env.envs.lift.recovering_expert import RecoveringLiftExpert

    expert = RecoveringLiftExpert()
    env = gym.make("dg16m_env/DualGraspLift-v2")
    try:
        # the expert as its own policy (beta 1): seed 42 is an episode it completes
        rng = np.random.default_rng(0)
        kept, _, rate = dagger_rollouts(
            env, expert, expert, range(42, 43), 1.0, {"lift"}, rng, True
        )
        rng = np.random.default_rng(0)
        grasp_only, _, _ = dagger_rollouts(
            env, expert, expert, range(42, 43), 1.0, {"lift"}, rng, False
        )
    finally:
        env.close()
    assert rate == 1.0
    phases = [expert.phase(state) for state in kept]
    assert set(phases) == {"approach", "lift"}
    for state, phase in zip(kept, phases, strict=True):
        assert phase == "lift" or expert.following_path(state).all()
    assert len(grasp_only) == phases.count("lift") < len(kept)


def test_on_path_labels_need_an_expert_that_says_so(tmp_path: Path, demos: Path) -> None:
    stderr = refusal(tmp_path, demos, "--dagger-on-path", "true")
    assert "found FeedbackLiftExpert" in stderr
