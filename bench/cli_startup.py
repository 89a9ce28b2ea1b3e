"""Start-up time of the ``dg16m`` command line (issue 45), against a bare interpreter start
measured in the same run.

Times, each in a fresh subprocess, best (and median) of ``--runs`` runs after one warm-up:

* ``python -c pass``: the reference, an interpreter that starts and exits (site, the
  virtualenv's ``.pth`` files);
* ``dg16m --help``: every command plugin registered, the help printed;
* ``dg16m --version``.

and prints each time with its ratio to the reference (the machine is shared and noisy; the ratio
travels better than the seconds). ``dg16m`` is the console script next to this interpreter
(``python -m dg16m_core.cli`` where there is none). Target: ``dg16m --help`` within 0.5 s on a
quiet machine.

    .venv/bin/python bench/cli_startup.py               # ~10 s
    .venv/bin/python bench/cli_startup.py --runs 20 --json runs/cli_startup.json
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from dg16m_core.atomic import write_text_atomic

TARGET_HELP_S = 0.5
"""``dg16m --help`` on a quiet machine (s)."""


def dg16m_command() -> list[str]:
    """The ``dg16m`` console script of this interpreter's environment, else ``-m``."""
    script = Path(sys.executable).parent / "dg16m"
    if script.is_file():
        return [str(script)]
    return [sys.executable, "-m", "dg16m_core.cli"]


def time_command(command: list[str], runs: int) -> list[float]:
    """Wall times (s) of ``runs`` runs of ``command`` after one untimed warm-up."""
    env = {**os.environ, "COLUMNS": "100"}
    times = []
    for i in range(runs + 1):
        start = time.perf_counter()
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL, env=env)
        if i:
            times.append(time.perf_counter() - start)
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10, help="timed runs each (default 10)")
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    args = parser.parse_args(argv)
    dg16m = dg16m_command()
    cases = {
        "python -c pass": [sys.executable, "-c", "pass"],
        "dg16m --help": [*dg16m, "--help"],
        "dg16m --version": [*dg16m, "--version"],
    }
    results = {name: time_command(command, args.runs) for name, command in cases.items()}
    reference = min(results["python -c pass"])
    load = [round(x, 2) for x in os.getloadavg()] if hasattr(os, "getloadavg") else None
    where = f"{os.cpu_count()} cores, load average {load} (1, 5, 15 min)"
    print(f"best / median of {args.runs} runs; {where}; dg16m = {' '.join(dg16m)}")
    rows = {}
    for name, times in results.items():
        best, median = min(times), statistics.median(times)
        rows[name] = {"best_s": best, "median_s": median, "ratio": best / reference}
        print(f"  {name:18s} best {best:6.3f} s  median {median:6.3f} s  {best / reference:5.1f}x")
    verdict = "within" if rows["dg16m --help"]["best_s"] <= TARGET_HELP_S else "over"
    print(f"dg16m --help: {verdict} the {TARGET_HELP_S} s target")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(
            args.json, json.dumps({"runs": args.runs, "load": load, "rows": rows}, indent=2)
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
