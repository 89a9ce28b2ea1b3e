"""Digests of what the package makes, to show that a change of layout changed no bytes.

Runs, in a scratch folder, the three things a moved or cut module could change:

1. ``dg16m benchmark build`` of the first procedural object (``--perturbations 1``): the sha256
   of ``benchmark.h5``;
2. ``dg16m evaluate --evaluators fce,gsr`` of a submission made from that benchmark's first
   rows, against it: the sha256 of each result's scores (the JSON without times, dates and
   the package version);
3. one seeded episode of each environment (``DualGraspPose``, ``DualGraspSelect`` with random
   actions; ``DualGraspLift-v0`` driven by the scripted expert with the benchmark's grasp;
   ``DualGraspLift-v1`` and ``-v2`` with random actions and driven by the feedback expert): the
   sha256 of every observation, reward, flag and ``info`` value;
4. ``dg16m objects make --count 3`` (meshes, convex parts, manifest) and ``dg16m generate
   --procedural 20 --workers 2``: the sha256 of every file's content (HDF5 files by their
   datasets and attributes; manifests without their times).

Prints one JSON object (``--out`` writes it too). Run it on two trees and compare::

    .venv/bin/python bench/layout_digest.py --out /tmp/after.json
    git worktree add /tmp/before <commit>
    cp bench/layout_digest.py /tmp/before/bench/
    # the dg16m commands are found through the installed entry points: a tree whose command
    # modules have other names needs its own, first on PYTHONPATH
    mkdir /tmp/before_site && cp -r .venv/lib/python3.*/site-packages/dg16m-*.dist-info /tmp/before_site/
    (edit /tmp/before_site/dg16m-*.dist-info/entry_points.txt to the old tree's [dg16m.commands])
    cd /tmp/before && PYTHONPATH=/tmp/before_site:/tmp/before <repo>/.venv/bin/python \
        bench/layout_digest.py --out /tmp/before.json
    diff /tmp/before.json /tmp/after.json

The command line is run as ``python -c 'from dg16m_core.cli import main; main()'``
(``dataset_gen.cli`` in a tree from before the kernel) so that ``PYTHONPATH`` picks the tree. Same machine, same bytes; across CPUs physics may differ in the
last bits (see DESIGN.md), so compare digests made on one machine. About a minute on 2 cores.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import h5py
import numpy as np

try:
    from dg16m_core.atomic import write_text_atomic
except ImportError:  # a tree from before the kernel package
    from dataset_gen.atomic import write_text_atomic

# Keys of a result that record when, where and with what it ran, not what it measured (``file``:
# the submission's path, in a scratch folder).
VOLATILE_KEYS = {
    "created",
    "package_version",
    "seconds",
    "elapsed",
    "duration",
    "timestamp",
    "file",
}


def dg16m(*args: str) -> None:
    """Run a ``dg16m`` command of the tree on ``PYTHONPATH`` (raises on a non-zero exit)."""
    code = (
        "import sys\n"
        "try:\n    from dg16m_core.cli import main\n"
        "except ImportError:\n    from dataset_gen.cli import main\n"
        "sys.exit(main())"
    )
    subprocess.run([sys.executable, "-c", code, *args], check=True)


def digest(*values: Any) -> str:
    """sha256 of arrays, numbers and dicts of them (a dict: its keys in order, then values)."""
    h = hashlib.sha256()
    for value in values:
        if isinstance(value, dict):
            for key in sorted(value):
                h.update(key.encode())
                h.update(digest(value[key]).encode())
        else:
            h.update(np.ascontiguousarray(np.asarray(value)).tobytes())
    return h.hexdigest()


def scrub(value: Any) -> Any:
    """``value`` without the keys of :data:`VOLATILE_KEYS`, at any depth."""
    if isinstance(value, dict):
        return {k: scrub(v) for k, v in sorted(value.items()) if k not in VOLATILE_KEYS}
    if isinstance(value, list):
        return [scrub(v) for v in value]
    return value


def write_submission(bench_file: Path, path: Path, rows: int = 6) -> None:
    """A submission of the first ``rows`` dual grasps of each object of ``bench_file``."""
    with h5py.File(bench_file, "r") as f:
        poses = f["grasps/poses"][()]
        object_index = f["grasps/object_index"][()]
        ids = [s.decode() if isinstance(s, bytes) else s for s in f["objects/ids"][()]]
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "dg16m-submission"
        f.attrs["schema_version"] = 1
        f.attrs["benchmark"] = hashlib.sha256(bench_file.read_bytes()).hexdigest()
        for o, object_id in enumerate(ids):
            chosen = poses[object_index == o][:rows]
            g = f.create_group(f"objects/{object_id}")
            g["poses"] = chosen
            g["scores"] = np.linspace(1.0, 0.0, len(chosen))


def _expert(kind: str) -> Any:
    """The Lift expert ``kind`` ("scripted" or "feedback") of whichever layout is installed."""
    import importlib

    names = {
        "scripted": (
            "ScriptedLiftPolicy",
            ("dg16m_env.envs.lift.experts", "dg16m_env.envs.lift_expert"),
        ),
        "feedback": (
            "FeedbackLiftExpert",
            ("dg16m_env.envs.lift.experts", "dg16m_env.envs.lift_feedback_expert"),
        ),
    }
    name, modules = names[kind]
    for module in modules:
        try:
            return getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError):
            continue
    raise ImportError(f"expected {name} in one of {modules}, found none")


def episode_digest(env_id: str, seed: int, policy_kind: str | None) -> str:
    """sha256 of one seeded episode of ``env_id``: random actions (``policy_kind`` None) or the
    Lift expert ``policy_kind`` ("scripted", "feedback") on the benchmark's grasp."""
    import gymnasium as gym

    import dg16m_env  # noqa: F401  (registers the environments)

    kwargs = {"target_grasp": "benchmark"} if policy_kind else {}
    env = gym.make(env_id, **kwargs)
    policy = None
    if policy_kind == "scripted":
        policy = _expert("scripted")()
    elif policy_kind == "feedback":
        policy = _expert("feedback")()
    env.action_space.seed(seed)
    obs, info = env.reset(seed=seed)
    h = hashlib.sha256(digest(obs).encode())
    h.update(json.dumps(scrub(info), sort_keys=True, default=str).encode())
    for _ in range(400):
        action = policy(obs) if policy is not None else env.action_space.sample()
        obs, reward, terminated, truncated, info = env.step(action)
        h.update(digest(obs, reward, terminated, truncated).encode())
        h.update(json.dumps(scrub(info), sort_keys=True, default=str).encode())
        if terminated or truncated:
            break
    env.close()
    return h.hexdigest()


def h5_digest(path: Path) -> str:
    """sha256 of an HDF5 file's datasets and attributes (names in order), not its bytes."""
    h = hashlib.sha256()

    def visit(name: str, item: Any) -> None:
        h.update(name.encode())
        for key in sorted(item.attrs):
            h.update(key.encode())
            h.update(repr(item.attrs[key]).encode())
        if isinstance(item, h5py.Dataset):
            h.update(digest(item[()]).encode())

    with h5py.File(path, "r") as f:
        visit("/", f)
        f.visititems(visit)
    return h.hexdigest()


def folder_digest(folder: Path) -> dict[str, str]:
    """Relative path -> sha256 of every file under ``folder`` (HDF5 by content, JSON without
    the keys of :data:`VOLATILE_KEYS`)."""
    out = {}
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        rel = str(path.relative_to(folder))
        if path.suffix == ".h5":
            out[rel] = h5_digest(path)
        elif path.suffix == ".json":
            text = json.dumps(scrub(json.loads(path.read_text())), sort_keys=True)
            out[rel] = hashlib.sha256(text.encode()).hexdigest()
        else:
            out[rel] = hashlib.sha256(path.read_bytes()).hexdigest()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="also write the digests here (JSON)")
    parser.add_argument("--work", type=Path, help="scratch folder (default: a temporary one)")
    args = parser.parse_args()
    os.environ.setdefault("MUJOCO_GL", "egl")
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        build = work / "build"
        dg16m("benchmark", "build", "--out", str(build), "--limit", "1", "--perturbations", "1")
        bench_file = build / "benchmark.h5"
        sub = work / "submission.h5"
        write_submission(bench_file, sub)
        scores = work / "scores.json"
        dg16m(
            "evaluate",
            str(sub),
            "--benchmark",
            str(bench_file),
            "--evaluators",
            "fce,gsr",
            "--perturbations",
            "1",
            "--out",
            str(scores),
            "--no-progress",
        )
        results = json.loads(scores.read_text())
        out: dict[str, Any] = {
            "benchmark.h5": hashlib.sha256(bench_file.read_bytes()).hexdigest(),
            "scores": hashlib.sha256(
                json.dumps(scrub(results), sort_keys=True).encode()
            ).hexdigest(),
            "episodes": {
                "DualGraspPose-v0": episode_digest("dg16m_env/DualGraspPose-v0", 3, None),
                "DualGraspSelect-v0": episode_digest("dg16m_env/DualGraspSelect-v0", 3, None),
                "DualGraspLift-v0": episode_digest("dg16m_env/DualGraspLift-v0", 3, "scripted"),
                "DualGraspLift-v1": episode_digest("dg16m_env/DualGraspLift-v1", 3, None),
                "DualGraspLift-v1 feedback": episode_digest(
                    "dg16m_env/DualGraspLift-v1", 4, "feedback"
                ),
                "DualGraspLift-v2": episode_digest("dg16m_env/DualGraspLift-v2", 3, None),
                "DualGraspLift-v2 feedback": episode_digest(
                    "dg16m_env/DualGraspLift-v2", 4, "feedback"
                ),
            },
        }
        objects = work / "objects"
        dg16m("objects", "make", "--count", "3", "--out", str(objects))
        out["objects make"] = folder_digest(objects)
        generated = work / "generated"
        dg16m(
            "generate",
            "--procedural",
            "20",
            "--workers",
            "2",
            "--out",
            str(generated),
            "--no-progress",
        )
        out["generate"] = folder_digest(generated)
    text = json.dumps(out, indent=2)
    print(text)
    if args.out:
        write_text_atomic(args.out, text + "\n")


if __name__ == "__main__":
    main()
