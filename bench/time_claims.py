"""Measure every "how long does this take" claim of the README, the guide, the quickstart and the
tutorials, and write them as one table (issue 56).

Each claim is a row (:data:`CLAIMS`): an id, the exact command, where it is claimed. The script
runs the cheap commands itself, one at a time, each in a fresh temporary folder (never in the
repository's ``runs/`` or data), and records its wall seconds, the CPU seconds of its processes,
the date, the commit (``+changes`` when the working tree differs from it), and the machine
(cores, CPU model, 1-minute load average at the start). Long commands (``make test``, the
benchmark build, training runs) are not run here: pass their measured wall time with
``--record ID=SECONDS`` (or run one with ``--only ID --run-long``).

The table is written atomically to ``docs/_static/times.json`` (the source of truth) and rendered
to ``docs/times.md`` (a page of the site); rows not rerun keep their values and their own dates.
The prose quotes each row as ``<wall> ... ([ID](times.md), YYYY-MM-DD)``;
``tests/test_time_claims.py`` fails when a time claim in those files is not such a quote, or
differs from the table.

Usage::

    .venv/bin/python bench/time_claims.py --list
    .venv/bin/python bench/time_claims.py                       # every cheap row (~8 min)
    .venv/bin/python bench/time_claims.py --only make-demo --only demos-collect-500
    .venv/bin/python bench/time_claims.py --record make-test=652  # a long one, measured apart
    .venv/bin/python bench/time_claims.py --render               # rewrite times.md only
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
TABLE_JSON = ROOT / "docs" / "_static" / "times.json"
TABLE_MD = ROOT / "docs" / "times.md"
SCHEMA = 1


@dataclass(frozen=True)
class Claim:
    """One command whose duration the docs state.

    Attributes:
        id: the row's name (lower case, digits and ``-``), quoted in the prose.
        command: the shell command, exactly as the docs give it; run from a fresh temporary
            folder (its ``runs/...`` outputs land there).
        claimed_in: the files that quote it (relative to the repository root).
        cheap: run by default (at most a few minutes on 2 cores); else only with ``--record``
            or ``--only ID --run-long``.
        inputs: repository files copied into the temporary folder (same relative path) first.
        approximate: the value is an estimate, shown as "about N min".
        in_root: run from the repository root instead (``make test``, which writes no data).
    """

    id: str
    command: str
    claimed_in: tuple[str, ...]
    cheap: bool
    inputs: tuple[str, ...] = ()
    approximate: bool = False
    in_root: bool = False


TUTORIAL = "docs/tutorials/my_grasps.py"
GUIDE, QUICK, README = "docs/guide.md", "docs/quickstart.md", "README.md"

CLAIMS: tuple[Claim, ...] = (
    Claim("make-demo", "dg16m demo --out runs/demo --workers 2", (README, QUICK), cheap=True),
    Claim(
        "baselines-submissions",
        "dg16m baselines submissions --out runs/refs --workers 2",
        (QUICK, GUIDE),
        cheap=True,
    ),
    Claim(
        "generate-procedural-20",
        "dg16m generate --procedural 20 --workers 1 --out runs/gen20",
        (GUIDE,),
        cheap=True,
    ),
    Claim(
        "evaluate-real-5",
        "dg16m evaluate --predictor baselines.pairing_baselines:force_closure_baseline "
        "--evaluators fce,gsr --benchmark real --limit 5",
        (GUIDE, "docs/tutorials/score_predictor.md"),
        cheap=True,
    ),
    Claim(
        "tutorial-predictor-fce-40",
        f"dg16m evaluate --predictor {TUTORIAL}:predict --evaluators fce --limit 40",
        ("docs/tutorials/score_predictor.md",),
        cheap=True,
        inputs=(TUTORIAL,),
    ),
    Claim(
        "tutorial-predictor-gsr-10",
        f"dg16m evaluate --predictor {TUTORIAL}:predict --evaluators fce,gsr --limit 10",
        ("docs/tutorials/score_predictor.md",),
        cheap=True,
        inputs=(TUTORIAL,),
    ),
    Claim(
        "demos-collect-500",
        "dg16m demos collect --episodes 500 --workers 2 --out runs/demos",
        (GUIDE, "docs/tutorials/demonstrations.md"),
        cheap=True,
    ),
    Claim(
        "generate-benchmark-300",
        "dg16m generate --procedural 300 --split benchmark --out runs/bench_gen --workers 2",
        (GUIDE,),
        cheap=False,
    ),
    Claim("make-test", "make test", (GUIDE,), cheap=False, in_root=True),
    Claim(
        "benchmark-build",
        "dg16m benchmark build --out runs/benchmark --workers 2",
        (GUIDE,),
        cheap=False,
    ),
    Claim(
        "generate-procedural-200",
        "dg16m generate --procedural 200 --split train --out runs/train200 --workers 2",
        (GUIDE,),
        cheap=False,
        approximate=True,
    ),
    Claim(
        "reproduce-table3",
        "dg16m reproduce table3 --out runs/table3 --workers 2",
        (GUIDE,),
        cheap=False,
        approximate=True,
    ),
    Claim(
        "train-hand-collision",
        "python -m baselines.train_hand_collision --features runs/hand_collision_features.npz",
        (GUIDE,),
        cheap=False,
        approximate=True,
    ),
    Claim(
        "sb3-select",
        ".venv/bin/python -m baselines.sb3_select --out runs/sb3_select",
        (GUIDE, "docs/tutorials/train_policy.md"),
        cheap=False,
        approximate=True,
    ),
    Claim(
        "sb3-lift",
        ".venv/bin/python -m baselines.sb3_lift --out runs/sb3_lift",
        ("docs/tutorials/train_policy.md",),
        cheap=False,
        approximate=True,
    ),
    Claim(
        "sb3-pose",
        ".venv/bin/python -m baselines.sb3_pose --out runs/sb3_pose",
        ("docs/tutorials/train_policy.md",),
        cheap=False,
        approximate=True,
    ),
    Claim(
        "residual-lift-400k",
        ".venv/bin/python -m baselines.residual_lift --base-policy runs/bc_lift_1000/policy.pt "
        "--env-id dg16m_env/DualGraspLift-v1 --total-timesteps 400000 --real-eval-episodes 100 "
        "--out runs/residual_lift",
        (GUIDE,),
        cheap=False,
        approximate=True,
    ),
    Claim(
        "residual-lift-1m",
        ".venv/bin/python -m baselines.residual_lift --base-policy runs/bc_lift_1000/policy.pt "
        "--env-id dg16m_env/DualGraspLift-v1 --total-timesteps 1000000 --real-eval-episodes 100 "
        "--out runs/residual_lift",
        (GUIDE,),
        cheap=False,
        approximate=True,
    ),
)
BY_ID = {claim.id: claim for claim in CLAIMS}


def display(seconds: float, approximate: bool = False) -> str:
    """How the prose states ``seconds`` of wall time: ``"53 s"`` under 100 s, else ``"M min S
    s"`` (``"M min"`` on a whole minute); ``"about M min"`` for an estimate."""
    whole = round(seconds)
    if approximate:
        return f"about {round(seconds / 60)} min" if whole >= 90 else f"about {whole} s"
    if whole < 100:
        return f"{whole} s"
    minutes, rest = divmod(whole, 60)
    return f"{minutes} min {rest} s" if rest else f"{minutes} min"


# -------------------------------------------------------------------------------------------
# The table
# -------------------------------------------------------------------------------------------


def read_table(path: Path = TABLE_JSON) -> dict[str, dict[str, Any]]:
    """The rows of the table at ``path`` by id (empty when there is no file yet)."""
    if not path.exists():
        return {}
    payload = json.loads(path.read_text())
    if payload.get("schema") != SCHEMA:
        raise SystemExit(f"{path}: expected schema {SCHEMA}, found {payload.get('schema')!r}")
    return {row["id"]: row for row in payload["rows"]}


def write_table(rows: dict[str, dict[str, Any]], json_path: Path, md_path: Path) -> None:
    """Write ``rows`` (in :data:`CLAIMS` order) to ``json_path`` and render ``md_path``, each
    atomically."""
    from dg16m_core.atomic import write_text_atomic

    unknown = sorted(set(rows) - set(BY_ID))
    if unknown:
        raise SystemExit(f"expected rows of {sorted(BY_ID)}, found unknown ids {unknown}")
    ordered = [rows[claim.id] for claim in CLAIMS if claim.id in rows]
    payload = {"schema": SCHEMA, "written_by": "bench/time_claims.py", "rows": ordered}
    write_text_atomic(json_path, json.dumps(payload, indent=1) + "\n")
    write_text_atomic(md_path, render(ordered))


def _cells(cells: list[str]) -> str:
    """One Markdown table row."""
    return "| " + " | ".join(cell.replace("|", "\\|") for cell in cells) + " |"


def render(rows: list[dict[str, Any]]) -> str:
    """The Markdown page of the table (``docs/times.md``)."""
    lines = [
        "# Measured times",
        "",
        "Every duration that the README, the guide, the quickstart and the tutorials state comes "
        "from this table. It is written by `bench/time_claims.py` (from "
        "`docs/_static/times.json`; do not edit it by hand), which runs the cheap commands "
        "itself, one at a time, each in a fresh temporary folder, and takes the long ones "
        "(`make test`, the benchmark build, training runs) from a separate measurement "
        "(`--record ID=SECONDS`). Each row keeps its own date: a row that was not rerun "
        "keeps the value, commit and machine it was measured with. `tests/test_time_claims.py` "
        "fails when the prose states a time that is not here.",
        "",
        "*wall*: wall-clock time of the command; *CPU*: CPU seconds of its processes (user + "
        "system; blank when not measured here); *load*: the machine's 1-minute load average "
        'when the command started (a shared machine runs slower); *commit*: "+changes" when the '
        "working tree had uncommitted changes.",
        "",
        "## The times",
        "",
        "| id | wall | CPU | date | load | claimed in |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        cpu = "" if row.get("cpu_seconds") is None else f"{row['cpu_seconds']:.0f} s"
        load = "" if row.get("load_at_start") is None else f"{row['load_at_start']:.2f}"
        value = display(row["wall_seconds"], row.get("approximate", False))
        where = ", ".join(f"`{path}`" for path in row["claimed_in"])
        lines.append(_cells([f"`{row['id']}`", value, cpu, row["date"], load, where]))
    lines += [
        "",
        "## Commands and where each value comes from",
        "",
        "| id | command | commit | machine | how |",
        "|---|---|---|---|---|",
    ]
    for row in rows:
        cells = [f"`{row['id']}`", f"`{row['command']}`", row.get("commit") or ""]
        lines.append(_cells([*cells, row.get("machine") or "", row["how"]]))
    return "\n".join(lines) + "\n"


# -------------------------------------------------------------------------------------------
# Measuring
# -------------------------------------------------------------------------------------------


def commit() -> str:
    """The checked-out commit (short), with ``+changes`` when tracked files differ from it."""
    head = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
    ).stdout.strip()
    changed = subprocess.run(
        ["git", "status", "--porcelain", "--untracked-files=no"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    ).stdout.strip()
    return f"{head}+changes" if changed else head


def machine() -> str:
    """Cores and CPU model of this machine, e.g. ``"2 cores, Intel Xeon ..."``."""
    model = platform.processor() or platform.machine()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    return f"{os.cpu_count()} cores, {model}"


def _children_cpu() -> float:
    """CPU seconds (user + system) of the waited-for child processes so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def measure(claim: Claim, log: Path | None = None) -> dict[str, Any]:
    """Run ``claim.command`` once in a fresh temporary folder (where ``.venv`` links to this
    interpreter's environment); its row (raises ``SystemExit`` naming the command and its
    output's end when it fails)."""
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env.setdefault("MUJOCO_GL", "egl")
    folder = Path(tempfile.mkdtemp(prefix=f"dg16m-times-{claim.id}-"))
    try:
        for name in claim.inputs:
            (folder / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, folder / name)
        (folder / ".venv").symlink_to(Path(sys.prefix), target_is_directory=True)
        load = os.getloadavg()[0]
        cpu0, start = _children_cpu(), time.perf_counter()
        done = subprocess.run(
            claim.command,
            shell=True,
            cwd=ROOT if claim.in_root else folder,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        wall, cpu = time.perf_counter() - start, _children_cpu() - cpu0
        if log is not None:
            with log.open("a") as handle:
                handle.write(f"$ {claim.command}\n{done.stdout}\n")
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    if done.returncode != 0:
        tail = "\n".join(done.stdout.splitlines()[-20:])
        raise SystemExit(
            f"{claim.id}: expected exit status 0, found {done.returncode} from "
            f"{claim.command!r}:\n{tail}"
        )
    where = "the repository root" if claim.in_root else "a temporary folder"
    return _row(claim, wall, cpu, load, f"run by bench/time_claims.py in {where}")


def _row(
    claim: Claim, wall: float, cpu: float | None, load: float | None, how: str
) -> dict[str, Any]:
    """A table row for ``claim`` measured now on this machine."""
    return {
        "id": claim.id,
        "command": claim.command,
        "wall_seconds": round(wall, 1),
        "cpu_seconds": None if cpu is None else round(cpu, 1),
        "approximate": claim.approximate,
        "date": dt.datetime.now(dt.timezone.utc).date().isoformat(),
        "commit": commit(),
        "machine": machine(),
        "load_at_start": None if load is None else round(load, 2),
        "claimed_in": list(claim.claimed_in),
        "how": how,
    }


def _recorded(text: str) -> tuple[Claim, float]:
    """``ID=SECONDS`` of ``--record``."""
    name, _, value = text.partition("=")
    if name not in BY_ID:
        raise argparse.ArgumentTypeError(
            f"expected ID=SECONDS with an id of --list, found {text!r}"
        )
    try:
        seconds = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected ID=SECONDS with SECONDS a number, found {text!r}"
        ) from None
    if not seconds > 0:
        raise argparse.ArgumentTypeError(f"expected SECONDS > 0, found {text!r}")
    return BY_ID[name], seconds


def main(argv: list[str] | None = None) -> int:
    """Run the selected rows, merge them into the table and write it; exit status 0."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--list", action="store_true", help="list the rows and exit")
    parser.add_argument("--only", action="append", default=[], help="run only this row")
    parser.add_argument("--run-long", action="store_true", help="--only may name a long row")
    parser.add_argument(
        "--record", action="append", default=[], type=_recorded, help="ID=SECONDS measured apart"
    )
    parser.add_argument("--render", action="store_true", help="only rewrite docs/times.md")
    parser.add_argument("--json", type=Path, default=TABLE_JSON, help="(default: %(default)s)")
    parser.add_argument("--md", type=Path, default=TABLE_MD, help="(default: %(default)s)")
    parser.add_argument("--log", type=Path, help="append the commands' output to this file")
    args = parser.parse_args(argv)
    rows = read_table(args.json)
    before = {row_id: dict(row) for row_id, row in rows.items()}
    if args.list:
        for claim in CLAIMS:
            row = rows.get(claim.id)
            value = f"{display(row['wall_seconds'])} on {row['date']}" if row else "not measured"
            kind = "cheap" if claim.cheap else "long "
            print(f"{claim.id:28} {kind} {value:26} {claim.command}")
        return 0
    unknown = sorted(set(args.only) - set(BY_ID))
    if unknown:
        parser.error(f"--only: expected ids of --list, found {unknown}")
    long_ones = [name for name in args.only if not BY_ID[name].cheap]
    if long_ones and not args.run_long:
        parser.error(f"--only: {long_ones} take long; add --run-long or pass --record ID=SECONDS")
    selected = [] if args.render or args.record else args.only or [c.id for c in CLAIMS if c.cheap]
    for claim, seconds in args.record:
        rows[claim.id] = _row(claim, seconds, None, None, "measured apart, passed with --record")
    for name in selected:
        claim = BY_ID[name]
        print(f"{claim.id}: $ {claim.command}", flush=True)
        rows[claim.id] = measure(claim, args.log)
        row = rows[claim.id]
        print(
            f"{claim.id}: {display(row['wall_seconds'])} wall, {row['cpu_seconds']:.0f} s CPU,"
            f" load {row['load_at_start']:.2f} at the start",
            flush=True,
        )
        write_table(rows, args.json, args.md)  # keep each finished row
    write_table(rows, args.json, args.md)
    print(f"wrote {args.json} and {args.md} ({len(rows)} rows)")
    for row_id, row in sorted(rows.items()):
        old = before.get(row_id)
        if old is None or (old["wall_seconds"], old["date"]) != (row["wall_seconds"], row["date"]):
            value = display(row["wall_seconds"], row.get("approximate", False))
            print(
                f"{row_id}: now {value} on {row['date']}: quote it so in "
                f"{', '.join(row['claimed_in'])} (tests/test_time_claims.py checks)"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
