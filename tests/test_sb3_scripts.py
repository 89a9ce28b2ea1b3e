"""The stable-baselines3 baseline scripts run end to end on tiny budgets (slow: minutes)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")


@pytest.mark.slow
@pytest.mark.parametrize(
    ("module", "argv", "policies"),
    [
        (
            "baselines.sb3_select",
            ["--total-timesteps", "512", "--n-envs", "2"],
            {"ppo", "random_candidate"},
        ),
        (
            "baselines.sb3_lift",
            ["--total-timesteps", "512", "--n-envs", "2"],
            {"ppo", "scripted", "random_actions"},
        ),
        (
            "baselines.sb3_pose",
            ["--total-timesteps", "150", "--learning-starts", "50"],
            {"sac", "random_actions"},
        ),
        (
            "baselines.sb3_pose",
            [
                *("--action-mode", "surface", "--algo", "ppo", "--total-timesteps", "64"),
                *("--n-steps", "32", "--batch-size", "32"),
            ],
            {"ppo", "random_actions", "random_pose_actions"},
        ),
    ],
)
def test_script_writes_checkpoint_curve_and_results(tmp_path: Path, module, argv, policies) -> None:
    out = tmp_path / "run"
    subprocess.run(
        [sys.executable, "-m", module, *argv, "--eval-episodes", "3", "--out", str(out)],
        check=True,
        capture_output=True,
        timeout=900,
    )
    results = json.loads((out / "results.json").read_text())
    assert set(results["results"]) == policies
    for result in results["results"].values():
        rate = result["metrics"]["success_rate"]
        assert rate["rows"] == 3
        assert 0.0 <= rate["rate"] <= 1.0
    assert (out / "learning_curve.png").stat().st_size > 10_000
    assert list(out.glob("*.zip"))


@pytest.mark.parametrize(
    "module",
    [
        "baselines.bc_lift",
        "baselines.sb3_lift",
        "baselines.sb3_pose",
        "baselines.sb3_select",
        "baselines.train_classifier",
    ],
)
def test_every_option_is_described_with_its_default(module: str) -> None:
    """--help says what each option means (its field's docstring) and its default, not only its
    own name again."""
    import dataclasses
    import importlib

    from baselines.sb3_common import field_docs

    args = importlib.import_module(module).Args
    docs = field_docs(args)
    assert set(docs) == {f.name for f in dataclasses.fields(args)}
    assert all(docs.values())
    for name, doc in docs.items():
        assert doc != name
    result = subprocess.run(
        [sys.executable, "-m", module, "--help"], capture_output=True, text=True, check=True
    )
    assert "(default: " in result.stdout
    assert "\n  --out OUT             out\n" not in result.stdout
