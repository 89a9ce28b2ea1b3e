"""``dg16m evaluate --classifier / --policy --out R.json``: the classifier and policy evaluators
checkpoint each finished object (episode) beside the results; an interrupt keeps them and
``--resume`` scores only the rest, with the same bytes as an uninterrupted run. Code subjects are
told apart by the sha256 of their module's source and their torch weights
(:func:`dg16m_env.evaluators.code_identity.code_sha256`)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from checkpoint_stops import ctrl_c, sigterm, stop_after

from dg16m_core.cli import main
from dg16m_env.evaluators import read_results
from dg16m_env.evaluators.checkpoint import ObjectCheckpoint, checkpoint_folder
from dg16m_env.evaluators.code_identity import code_sha256

OBJECTS = ["table-1000000", "crate-1000006", "bench-1000012"]

CLASSIFIER = '''
import numpy as np

def score(observation, poses):
    """Prefer grasps whose two hands are far apart; refuses the crates (a failing object)."""
    if observation["object_id"].startswith("crate"):
        raise ValueError("no crates")
    return np.linalg.norm(poses[:, 0, :3, 3] - poses[:, 1, :3, 3], axis=1)
'''

POLICY = '''
class Cycling:
    """A stateful policy: candidate 0, 1, 2, 0, ... from its reset()."""

    def __init__(self):
        self.t = 0

    def reset(self):
        self.t = 0

    def __call__(self, observation):
        self.t += 1
        return self.t % 3
'''


def _write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def code(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("code")
    _write(folder, "my_classifier.py", CLASSIFIER)
    _write(folder, "my_policy.py", POLICY)
    return folder


def _classifier_argv(code: Path, out: Path) -> list[str]:
    target = f"{code / 'my_classifier.py'}:score"
    objects = ",".join(OBJECTS)
    return ["evaluate", "--classifier", target, "--objects", objects, "--out", str(out)]


def _policy_argv(code: Path, out: Path) -> list[str]:
    return [
        "evaluate",
        "--policy",
        f"{code / 'my_policy.py'}:Cycling",
        "--env-id",
        "dg16m_env/DualGraspSelect-v0",
        "--episodes",
        "5",
        "--out",
        str(out),
    ]


ARGVS = {"classifier": _classifier_argv, "policy": _policy_argv}


@pytest.mark.parametrize("stop", [ctrl_c, sigterm], ids=["ctrl-c", "sigterm"])
@pytest.mark.parametrize("kind", ["classifier", "policy"])
def test_an_interrupted_code_evaluation_resumes_with_the_same_bytes(
    code, tmp_path, capsys, monkeypatch, kind, stop
):
    whole = tmp_path / "whole.json"
    assert main([*ARGVS[kind](code, whole), "--no-progress"]) == 0
    assert not checkpoint_folder(whole, kind).exists()
    out = tmp_path / "r.json"
    argv = [*ARGVS[kind](code, out), "--no-progress"]
    folder = checkpoint_folder(out, kind)
    capsys.readouterr()
    with monkeypatch.context() as patch:
        stop_after(patch, 2, stop)
        assert main(argv) == 130
    err = capsys.readouterr().err
    assert f"interrupted during {kind}" in err
    units = "episodes" if kind == "policy" else "objects"
    assert f"kept 2 finished {kind} {units} in {folder}" in err
    assert "rerun with --resume" in err
    assert len(list(folder.glob("*.npz"))) == 2
    run = json.loads((folder / "run.json").read_text())
    assert run["subject"] == json.loads(whole.read_text())["subject"]["sha256"]
    saved = []
    with monkeypatch.context() as patch:
        original = ObjectCheckpoint.save
        patch.setattr(
            ObjectCheckpoint,
            "save",
            lambda self, *a, **k: (saved.append(a[0]), original(self, *a, **k)),
        )
        assert main([*argv, "--resume"]) == 0
    assert f"{kind}: resuming: 2 of " in capsys.readouterr().err
    total = {"classifier": len(OBJECTS), "policy": 5}[kind]
    assert saved == list(range(2, total))  # only the ones not yet done
    assert not folder.exists()
    assert out.read_bytes() == whole.read_bytes()
    # a finished result is kept as it is by a further --resume
    assert main([*argv, "--resume"]) == 0
    assert f"{kind}: kept from {out}" in capsys.readouterr().out
    assert out.read_bytes() == whole.read_bytes()


def test_the_classifier_result_keeps_its_failures_in_benchmark_order(code, tmp_path):
    out = tmp_path / "r.json"
    assert main([*_classifier_argv(code, out), "--no-progress"]) == 0
    result = read_results(out)["classifier"]
    assert list(result.failures) == ["crate-1000006"]
    assert result.failures["crate-1000006"] == "ValueError: no crates"
    assert result.subject["sha256"] == json.loads(out.read_text())["subject"]["sha256"]


def test_a_checkpoint_of_other_code_is_refused(code, tmp_path, capsys, monkeypatch):
    folder = tmp_path / "code"
    folder.mkdir()
    _write(folder, "my_classifier.py", CLASSIFIER)
    out = tmp_path / "r.json"
    argv = [*_classifier_argv(folder, out), "--no-progress"]
    with monkeypatch.context() as patch:
        stop_after(patch, 1, ctrl_c)
        assert main(argv) == 130
    capsys.readouterr()
    _write(folder, "my_classifier.py", CLASSIFIER.replace("axis=1)", "axis=1) * 2"))
    assert main([*argv, "--resume"]) == 2
    err = capsys.readouterr().err
    assert "expected the checkpoint" in err
    assert "another subject" in err
    assert len(list(checkpoint_folder(out, "classifier").glob("*.npz"))) == 1  # left as it was


def _double(x: float) -> float:
    return 2 * x


def test_code_sha256_sees_the_source_and_a_declared_identity(tmp_path) -> None:
    first = code_sha256(_double)
    assert first == code_sha256(_double)
    assert len(first) == 64
    assert code_sha256(np.mean) != first  # another module's source

    class Declared:
        code_identity = "weights sha256 abc"

        def __call__(self, observation):
            return 0

    subject = Declared()
    with_abc = code_sha256(subject)
    Declared.code_identity = "weights sha256 abd"
    assert code_sha256(subject) != with_abc


def test_code_sha256_changes_with_torch_weights() -> None:
    torch = pytest.importorskip("torch")
    torch.manual_seed(0)
    net = torch.nn.Linear(3, 1)
    before = code_sha256(net)
    assert before == code_sha256(net)
    with torch.no_grad():
        net.weight[0, 0] += 1e-6
    assert code_sha256(net) != before

    class Model:  # a stable-baselines3-like model: weights in .policy
        def __init__(self, policy):
            self.policy = policy

        def predict(self, observation, deterministic=True):
            return 0, None

    assert code_sha256(Model(net)) != code_sha256(Model(torch.nn.Linear(3, 1)))
