"""``dg16m demo``: the main job end to end on the embedded procedural objects, in a few minutes.

Each step is an ordinary ``dg16m`` command, run in this process and printed as the line a user
would type, so the demo doubles as a tour of the command line:

1. make a few procedural objects and draw them (``objects make``, ``objects show``);
2. generate DG16M-style dual grasps on them and summarise the dataset (``generate``,
   ``stats``);
3. build and label a small benchmark of the procedural benchmark's first objects in MuJoCo
   (``benchmark build --limit``) and plot it (``benchmark info --plot``);
4. replay one of its trials as pictures (``sim replay``);
5. predict dual grasps with two of the paper's Table III baselines (``baselines submissions``:
   random pairing and force-closure pairing) and score one with ``fce`` and ``gsr``
   (``evaluate``);
6. put both on a local leaderboard, print it and export its page (``leaderboard init``,
   ``team add``, ``submit``, ``show``, ``render``).

The folder it writes (``--out``, default ``runs/demo``) holds ``demo.json``: the steps, their
commands, seconds and outputs. A folder without it that is not empty is refused (nothing a user
made is overwritten); a previous demo's folder is replaced.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dg16m_core.atomic import write_json_atomic
from dg16m_core.cli import add_command
from dg16m_core.errors import Dg16mError

MARKER = "demo.json"
"""The file that marks a folder as a demo's (and records its steps)."""

DEMO_FORMAT = "dg16m-demo"

DEMO_EXAMPLES = """\
  dg16m demo                         # runs/demo, 4 objects, 2 workers (about a minute)
  dg16m demo --out /tmp/tour --objects 2 --workers 1
"""


class DemoError(Dg16mError):
    """The demo cannot start (its folder) or a step failed."""


@dataclass(frozen=True)
class DemoStep:
    """One step of the demo: a ``dg16m`` command line and what it writes.

    Attributes:
        title: what the step shows, in a few words.
        argv: the arguments after ``dg16m``.
        outputs: paths it writes, relative to the demo folder.
        echo: show what the command prints; ``False`` keeps only its ``wrote ...`` lines (a
            report that an earlier step already printed is not printed twice).
    """

    title: str
    argv: tuple[str, ...]
    outputs: tuple[str, ...] = ()
    echo: bool = True

    def command(self) -> str:
        """The command line as a user would type it."""
        return " ".join(["dg16m", *(_quote(a) for a in self.argv)])


def _quote(arg: str) -> str:
    return f"'{arg}'" if not arg or any(c in arg for c in " \"'$*?;&|<>()") else arg


def _args(*parts: str | Path | list[str]) -> tuple[str, ...]:
    """Command-line arguments: a string is split at spaces, a path or a one-item list (a
    value with spaces) is kept whole."""
    out: list[str] = []
    for part in parts:
        if isinstance(part, str):
            out.extend(part.split())
        elif isinstance(part, Path):
            out.append(str(part))
        else:
            out.extend(part)
    return tuple(out)


def demo_steps(out: Path, *, objects: int = 4, workers: int = 2) -> list[DemoStep]:
    """The demo's steps for folder ``out``, ``objects`` objects and ``workers`` processes."""
    w, n = f"--workers {workers}", str(objects)
    return [
        *_dataset_steps(out, n, w),
        *_benchmark_steps(out, n, w),
        *_baseline_steps(out, w),
        *_leaderboard_steps(out, w),
    ]


def _dataset_steps(out: Path, n: str, w: str) -> list[DemoStep]:
    """Steps 1 and 2: objects, their picture, a generated dataset and its statistics."""
    return [
        DemoStep(
            "procedural objects",
            _args("objects make --count", n, "--seed 0 --out", out / "objects"),
            ("objects/",),
        ),
        DemoStep(
            "a picture of them",
            _args("objects show", out / "objects", "--out", out / "objects.png"),
            ("objects.png",),
        ),
        DemoStep(
            "dual grasps with force-closure verdicts (a DG16M-style dataset)",
            _args("generate --procedural", n, "--out", out / "dataset", w),
            ("dataset/grasps/", "dataset/manifest.json"),
        ),
        DemoStep(
            "the dataset's counts and plots",
            _args("stats", out / "dataset", "--out", out / "stats"),
            ("stats/",),
        ),
    ]


def _benchmark_steps(out: Path, n: str, w: str) -> list[DemoStep]:
    """Steps 3 and 4: a small benchmark, its plot, one trial replayed."""
    bench = out / "benchmark" / "benchmark.h5"
    return [
        DemoStep(
            "a small benchmark, labelled in MuJoCo (K = 8 perturbed trials per pair)",
            _args(
                "benchmark build --limit", n, "--out", out / "benchmark", w
            ),  # its progress: the longest step
            ("benchmark/benchmark.h5", "benchmark/manifest.json"),
        ),
        DemoStep(
            # `benchmark build` ends with the same ~70-line report `benchmark info` prints:
            # this step shows only the plot it writes.
            "its plot (its summary is the report printed above)",
            _args("benchmark info", bench, "--plot", out / "benchmark.png"),
            ("benchmark.png",),
            echo=False,
        ),
        DemoStep(
            "one trial replayed as pictures",
            _args("sim replay", bench, "--row 0 --out", out / "replay.png"),
            ("replay.png",),
        ),
    ]


def _baseline_steps(out: Path, w: str) -> list[DemoStep]:
    """Step 5: two baselines' submissions, one of them scored."""
    bench = out / "benchmark" / "benchmark.h5"
    subs = out / "submissions"
    return [
        DemoStep(
            "predictions of two Table III baselines (random and force-closure pairing)",
            _args(
                "baselines submissions --benchmark",
                bench,
                "--out",
                subs,
                "--strategies random,force_closure --k 5",
                w,
                "--no-progress",
            ),
            ("submissions/random.h5", "submissions/force_closure.h5"),
        ),
        DemoStep(
            "force-closure pairing scored: fce (force closure) and gsr (simulated success)",
            _args(
                "evaluate",
                subs / "force_closure.h5",
                "--benchmark",
                bench,
                "--evaluators fce,gsr",
                w,
                "--out",
                out / "scores" / "force_closure.json",
                "--no-progress",
            ),
            ("scores/force_closure.json",),
        ),
    ]


def _leaderboard_steps(out: Path, w: str) -> list[DemoStep]:
    """Step 6: a local leaderboard with both baselines, printed and exported."""
    bench = out / "benchmark" / "benchmark.h5"
    subs = out / "submissions"
    db = out / "leaderboard" / "board.db"
    return [
        DemoStep(
            "a local leaderboard for the benchmark",
            _args(
                "leaderboard init --db",
                db,
                "--benchmark",
                bench,
                "--evaluators fce,gsr",
                "--title",
                ["dg16m demo"],
            ),
            ("leaderboard/board.db",),
        ),
        DemoStep(
            "a team",
            _args("leaderboard team add demo --db", db, "--token-file", db.with_name("demo.token")),
            ("leaderboard/demo.token",),
        ),
        DemoStep(
            "the random baseline submitted and scored",
            _args(
                "leaderboard submit",
                subs / "random.h5",
                "--team demo --label",
                ["random pairing"],
                "--db",
                db,
                w,
            ),
        ),
        DemoStep(
            "the force-closure baseline submitted and scored",
            _args(
                "leaderboard submit",
                subs / "force_closure.h5",
                "--team demo --label",
                ["force-closure pairing"],
                "--db",
                db,
                w,
            ),
        ),
        DemoStep("the board", _args("leaderboard show --db", db)),
        DemoStep(
            "the board's page",
            _args("leaderboard render --db", db, "--out", out / "leaderboard" / "site"),
            ("leaderboard/site/index.html",),
        ),
    ]


NEXT_STEPS = """\
What to run next:
  # grasps on your own meshes (OBJ/STL/PLY in metres)
  dg16m generate --meshes MY_MESHES --out runs/mine --workers 2
  # your predictor (a function observation -> dual grasps), scored on the shipped benchmark
  dg16m evaluate --predictor my_grasps.py:predict --evaluators fce,gsr --out runs/mine.json
  # the paper's Table III on the shipped benchmark
  dg16m reproduce table3 --help
  # this board as a web service (teams upload with tokens)
  dg16m leaderboard serve --db {db} --port 8000
"""


def prepare_folder(out: Path) -> None:
    """Make ``out`` empty for the demo: a missing or empty folder is used, a previous demo's
    (with :data:`MARKER`) is removed first, anything else is refused.

    Raises:
        DemoError: ``out`` is a file, or a non-empty folder the demo did not write.
    """
    if out.exists() and not out.is_dir():
        raise DemoError(f"--out: expected a folder, found a file: {out}")
    if out.is_dir() and any(out.iterdir()):
        if not (out / MARKER).is_file():
            raise DemoError(
                f"--out: expected a missing or empty folder, or one a previous 'dg16m demo' "
                f"wrote (with {MARKER}), found {out} with other files; give another --out"
            )
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)


def run_demo(
    out: Path,
    *,
    objects: int = 4,
    workers: int = 2,
    run: Callable[[Sequence[str]], int] | None = None,
    stream: Any = None,
) -> dict[str, Any]:
    """Run the demo into ``out`` and return its record (also written to ``out/demo.json``).

    Args:
        out: the demo folder (see :func:`prepare_folder`).
        objects: procedural objects (dataset and benchmark), at least 1.
        workers: local processes per step.
        run: runs one ``dg16m`` command line and returns its exit status (default
            :func:`dg16m_core.cli.main`, in this process).
        stream: where progress goes (default ``sys.stdout``).

    Raises:
        DemoError: bad arguments, the folder refused, or a step that failed (named, with its
            command to run again).
    """
    if not isinstance(objects, int) or objects < 1:
        raise DemoError(f"--objects: expected an integer >= 1, found {objects!r}")
    if not isinstance(workers, int) or workers < 1:
        raise DemoError(f"--workers: expected an integer >= 1, found {workers!r}")
    if run is None:
        from dg16m_core.cli import main as run
    stream = stream or sys.stdout
    out = Path(out)
    prepare_folder(out)
    steps = demo_steps(out, objects=objects, workers=workers)
    record: dict[str, Any] = {
        "format": DEMO_FORMAT,
        "objects": objects,
        "workers": workers,
        "steps": [],
        "complete": False,
    }
    write_json_atomic(out / MARKER, record)
    start = time.perf_counter()
    for i, step in enumerate(steps, 1):
        print(f"\n[{i}/{len(steps)}] {step.title}\n$ {step.command()}", file=stream, flush=True)
        t0 = time.perf_counter()
        code = _run_step(run, step, stream)
        seconds = round(time.perf_counter() - t0, 1)
        record["steps"].append(
            {"title": step.title, "command": step.command(), "exit": code, "seconds": seconds}
        )
        write_json_atomic(out / MARKER, record)
        if code != 0:
            raise DemoError(
                f"step {i} ({step.title}) failed with exit status {code}; its command was: "
                f"{step.command()}"
            )
    record["seconds"] = round(time.perf_counter() - start, 1)
    record["complete"] = True
    record["outputs"] = [o for step in steps for o in step.outputs]
    write_json_atomic(out / MARKER, record)
    _summary(out, record, stream)
    return record


def _run_step(run: Callable[[Sequence[str]], int], step: DemoStep, stream: Any) -> int:
    """Run one step; for a step with ``echo=False`` print only its ``wrote ...`` lines (all of
    its output when it fails)."""
    if step.echo:
        return run(list(step.argv))
    captured = io.StringIO()
    with contextlib.redirect_stdout(captured):
        code = run(list(step.argv))
    lines = captured.getvalue().splitlines()
    shown = lines if code != 0 else [line for line in lines if line.startswith("wrote ")]
    for line in shown:
        print(line, file=stream)
    stream.flush()
    return code


def _summary(out: Path, record: dict[str, Any], stream: Any) -> None:
    scores = json.loads((out / "scores" / "force_closure.json").read_text(encoding="utf-8"))
    print(f"\ndemo done in {record['seconds']:.0f} s; everything is in {out}/:", file=stream)
    for relative in record["outputs"]:
        print(f"  {out / relative}", file=stream)
    rates = _rates(scores)
    if rates:
        print("force-closure pairing on the demo benchmark: " + ", ".join(rates), file=stream)
    print(
        f"open {out / 'leaderboard' / 'site' / 'index.html'} in a browser for the board's page",
        file=stream,
    )
    print("\n" + NEXT_STEPS.format(db=out / "leaderboard" / "board.db"), file=stream, end="")


def _rates(scores: dict[str, Any]) -> list[str]:
    """``name rate%`` of each evaluator's headline metric in a ``dg16m evaluate --out`` file."""
    return [
        f"{name} {100 * result['metrics'][result['headline']]['rate']:.1f}%"
        for name, result in scores["results"].items()
    ]


def _handler(args: argparse.Namespace) -> int:
    run_demo(args.out, objects=args.objects, workers=args.workers)
    return 0


def register(subparsers: Any) -> None:
    """Add ``dg16m demo``."""
    demo = add_command(
        subparsers,
        "demo",
        "The main job end to end on a few embedded procedural objects, in a few minutes.",
        DEMO_EXAMPLES,
        description=(
            "Make procedural objects, generate dual grasps with force-closure verdicts, build "
            "and label a small MuJoCo benchmark, replay a trial, predict dual grasps with two "
            "of the paper's baselines, score them (fce, gsr), put them on a local leaderboard "
            "and export its page. Each step is a dg16m command, printed before it runs; "
            "OUT/demo.json records them. A non-empty OUT that no demo wrote is refused."
        ),
    )
    demo.add_argument("--out", type=Path, default=Path("runs/demo"), help="folder (runs/demo)")
    demo.add_argument("--objects", type=int, default=4, help="procedural objects (default 4)")
    demo.add_argument("--workers", type=int, default=2, help="local processes (default 2)")
    demo.set_defaults(handler=_handler)
