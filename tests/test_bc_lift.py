"""The behaviour-cloning Lift baseline (``baselines/bc_lift.py``) end to end on a two-episode
Minari dataset: it trains, runs a DAgger round, evaluates three policies on two held-out
episodes each and writes the policy, the curve and the results; bad options are refused."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

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


def test_wrong_phases_are_refused(tmp_path: Path, demos: Path) -> None:
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "baselines.bc_lift",
            "--demos",
            str(demos),
            "--dagger-phases",
            "grasp",
            "--out",
            str(tmp_path / "run"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode != 0
    assert "expected 'all' or phases among" in result.stderr
