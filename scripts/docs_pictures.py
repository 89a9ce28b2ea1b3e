"""Render the documentation site's pictures of trials into ``docs/_static/pictures/``.

Reproducible: every picture is a fixed row of the benchmark shipped with dg16m (its trials are
deterministic) or a seeded episode, rendered offscreen (``MUJOCO_GL=egl``, or ``osmesa``).
The benchmark trials go through the ordinary command, ``dg16m sim replay``; the lift episodes
run ``DualGraspLift-v0`` with its scripted policy (``lift_episode.gif``) and
``DualGraspLift-v2`` with the feedback expert that ``dg16m demos collect`` records
(``lift_v2_episode.gif``; the script checks that the same seed on ``DualGraspLift-v3`` gives
the same observations, so the picture shows v3 too), with ``render_mode="rgb_array"``. Each
file is kept small (the docs are committed): the script fails when one is over ``--max-kb``.

Usage::

    MUJOCO_GL=egl .venv/bin/python scripts/docs_pictures.py            # all pictures
    MUJOCO_GL=egl .venv/bin/python scripts/docs_pictures.py --only pose_trial.gif
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "_static" / "pictures"


@dataclass(frozen=True)
class Replay:
    """A ``dg16m sim replay`` of one row (nominal trial) of the shipped benchmark."""

    name: str
    row: int
    frames: int
    size: str = "320x240"
    fps: int = 8

    def arguments(self, out: Path) -> list[str]:
        """The command line that writes this picture to ``out``."""
        command = [str(_dg16m()), "sim", "replay", "--row", str(self.row), "--out", str(out)]
        command += ["--frames", str(self.frames), "--size", self.size]
        if out.suffix == ".gif":
            command += ["--fps", str(self.fps)]
        return command


# Rows of dg16m_env/data/benchmark.h5: 0 is a force-closure pass that holds through every
# disturbance (p = 1); 61 a random pair that fails (p = 0).
REPLAYS = (
    Replay("pose_trial.gif", row=0, frames=20, size="400x300"),
    Replay("select_trial.png", row=61, frames=4),
    Replay("trial_strip.png", row=0, frames=3),  # 4 frames: one row of the strip
)

LIFT_NAME = "lift_episode.gif"
LIFT_OBJECT = "tub-1000013"  # an object the scripted policy lifts (tests/test_env_lift.py)
LIFT_SEED = 0
LIFT_SIZE = (400, 300)
LIFT_EVERY = 5  # keep one control step in five (20 Hz -> 4 frames per second of episode)

LIFT_V2_NAME = "lift_v2_episode.gif"
LIFT_V2_IDS = ("dg16m_env/DualGraspLift-v2", "dg16m_env/DualGraspLift-v3")  # drawn, checked


def _dg16m() -> Path:
    """The ``dg16m`` console script next to this interpreter (else the one on PATH)."""
    beside = Path(sys.executable).with_name("dg16m")
    if beside.exists():
        return beside
    found = shutil.which("dg16m")
    if found is None:
        raise SystemExit("dg16m is not installed: pip install -e '.[sim]'")
    return Path(found)


def render_replay(replay: Replay, out: Path) -> None:
    """Write ``replay`` to ``out`` with ``dg16m sim replay``."""
    command = replay.arguments(out)
    print("$ dg16m", " ".join(command[1:]).replace(str(ROOT) + os.sep, ""), flush=True)
    subprocess.run(command, check=True)


def render_lift(out: Path) -> None:
    """Write a seeded episode of ``DualGraspLift-v0`` (scripted policy, benchmark target) as a
    GIF to ``out``."""
    from dg16m_env.envs.lift.experts import ScriptedLiftPolicy

    frames, _ = _lift_episode("dg16m_env/DualGraspLift-v0", ScriptedLiftPolicy(), draw=True)
    _save_gif(frames, out)


def render_lift_v2(out: Path) -> None:
    """Write a seeded episode of ``DualGraspLift-v2`` driven by
    :class:`~dg16m_env.envs.lift.experts.FeedbackLiftExpert` (the demonstrations' expert) as a
    GIF to ``out``, after checking that ``DualGraspLift-v3`` with the same seed and object
    gives the same observations and the same ending (v3 differs only in when success is
    credited), so that one picture stands for both pages."""
    import numpy as np

    from dg16m_env.envs.lift.experts import FeedbackLiftExpert

    drawn_id, checked_id = LIFT_V2_IDS
    frames, drawn = _lift_episode(drawn_id, FeedbackLiftExpert(), draw=True)
    _, checked = _lift_episode(checked_id, FeedbackLiftExpert(), draw=False)
    same = drawn[0] == checked[0] and np.array_equal(drawn[1], checked[1])
    if not same:
        raise SystemExit(
            f"{LIFT_V2_NAME}: expected {checked_id} to repeat the {drawn_id} episode "
            f"(termination {drawn[0]!r}, {len(drawn[1]) - 1} steps), found termination "
            f"{checked[0]!r} after {len(checked[1]) - 1} steps or other observations: draw "
            "one picture per version"
        )
    print(f"{checked_id}: the same observations and ending as {drawn_id}")
    _save_gif(frames, out)


def _lift_episode(env_id: str, policy: Any, draw: bool) -> tuple[list[Any], tuple[str, Any]]:
    """Run one episode of ``env_id`` (benchmark target on ``LIFT_OBJECT``, reset seed
    ``LIFT_SEED``) with ``policy``; return its frames (one control step in ``LIFT_EVERY`` and
    the last; none unless ``draw``) and (its termination, its observations stacked)."""
    import gymnasium as gym
    import numpy as np

    import dg16m_env  # noqa: F401  (registers the environments)

    width, height = LIFT_SIZE
    render = {"render_mode": "rgb_array", "width": width, "height": height} if draw else {}
    with warnings.catch_warnings():  # an older version's "out of date" warning: drawn on purpose
        warnings.simplefilter("ignore", DeprecationWarning)
        env = gym.make(env_id, target_grasp="benchmark", **render)
    obs, _ = env.reset(seed=LIFT_SEED, options={"object_id": LIFT_OBJECT})
    frames = [env.render()] if draw else []
    observations = [obs]
    step = 0
    info: dict[str, object] = {}
    while True:
        obs, _, terminated, truncated, info = env.step(policy(obs))
        observations.append(obs)
        step += 1
        if draw and (step % LIFT_EVERY == 0 or terminated or truncated):
            frames.append(env.render())
        if terminated or truncated:
            break
    env.close()
    print(f"{env_id}: {LIFT_OBJECT}, seed {LIFT_SEED}, {step} steps, {info['termination']!r}")
    return frames, (str(info["termination"]), np.stack(observations))


def _save_gif(frames: list[Any], out: Path) -> None:
    """Write ``frames`` (RGB arrays) as a looping GIF (4 frames per second, 128 colours) that
    lingers on its last frame."""
    import numpy as np
    from PIL import Image

    images = [Image.fromarray(np.asarray(frame)).quantize(colors=128) for frame in frames]
    images += [images[-1]] * 5  # linger on the last frame
    images[0].save(
        out, save_all=True, append_images=images[1:], duration=250, loop=0, optimize=True
    )


def main(argv: list[str] | None = None) -> int:
    """Render the pictures; exit status 1 when one is over the size limit."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=OUT, help="folder (default: %(default)s)")
    parser.add_argument("--only", action="append", help="render only this file name")
    parser.add_argument("--max-kb", type=int, default=300, help="size limit per file (KB)")
    args = parser.parse_args(argv)
    os.environ.setdefault("MUJOCO_GL", "egl")
    args.out.mkdir(parents=True, exist_ok=True)

    jobs: dict[str, Callable[[Path], None]] = {
        replay.name: (lambda out, replay=replay: render_replay(replay, out)) for replay in REPLAYS
    }
    jobs[LIFT_NAME] = render_lift
    jobs[LIFT_V2_NAME] = render_lift_v2
    unknown = set(args.only or ()) - set(jobs)
    if unknown:
        parser.error(f"--only: expected one of {sorted(jobs)}, found {sorted(unknown)}")
    status = 0
    for name, job in jobs.items():
        if args.only and name not in args.only:
            continue
        path = args.out / name
        job(path)
        size_kb = path.stat().st_size / 1024
        over = size_kb > args.max_kb
        status |= over
        print(
            f"wrote {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}"
            f" ({size_kb:.0f} KB){'  OVER THE LIMIT' if over else ''}"
        )
    total = sum(p.stat().st_size for p in args.out.iterdir() if p.is_file()) / 1024
    print(f"{args.out}: {total:.0f} KB in all")
    return int(status)


if __name__ == "__main__":
    raise SystemExit(main())
