"""The leaderboard service end to end, with a same-run reference.

``--submissions`` whole-benchmark submissions (the shipped benchmark's 300 objects x ``--k``
dual grasps, a different slice of its stored rows each) are uploaded at once to
``dg16m leaderboard serve`` and scored with ``fce`` by ``--workers`` ``dg16m leaderboard worker``
processes. In the same run (the machine is shared and noisy), the **reference** validates and
scores the same files in this process, one after another.

Prints the upload latencies (each includes the file's validation), the wall time until every
submission is scored, and the ratio of that time to the reference's time divided by the number
of workers (the service's overhead over scoring the files directly: 1 is none).

    nice -n 19 .venv/bin/python bench/leaderboard_service.py              # ~3 minutes
    .venv/bin/python bench/leaderboard_service.py --submissions 4 --workers 1
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import numpy as np

from dg16m_core.atomic import write_json_atomic
from dg16m_env.evaluators import load_benchmark_ref, make
from dg16m_env.subjects.submission_reader import validate_submission
from dg16m_env.subjects.submission_writer import write_submission
from leaderboard.board import Board

CLI = [sys.executable, "-m", "dg16m_core.cli", "leaderboard"]


def _files(folder: Path, n: int, k: int) -> list[Path]:
    ref = load_benchmark_ref()
    bench = ref.benchmark
    out = []
    for i in range(n):
        poses = {}
        for object_id in ref.object_ids:
            rows = bench.object_rows(object_id)
            poses[object_id] = bench.poses[rows[(np.arange(k) + i * k) % rows.size]]
        out.append(write_submission(folder / f"sub-{i:02d}.h5", poses, benchmark="embedded"))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--submissions", type=int, default=10)
    parser.add_argument("--k", type=int, default=10, help="dual grasps per object")
    parser.add_argument("--workers", type=int, default=2, help="worker processes")
    parser.add_argument("--out", type=Path, default=None, help="write the numbers as JSON")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        paths = _files(root, args.submissions, args.k)
        size_mb = sum(p.stat().st_size for p in paths) / len(paths) / 2**20
        print(f"{len(paths)} submissions of 300 objects x {args.k} dual grasps, {size_mb:.2f} MiB")

        ref = load_benchmark_ref()
        fce = make("fce", benchmark=ref, progress=False)
        started = time.perf_counter()
        for path in paths:
            assert not validate_submission(path, object_ids=ref.object_ids)
            fce.evaluate(path)
        reference_s = time.perf_counter() - started
        print(f"reference: validated and scored in this process in {reference_s:.1f} s")

        db = root / "board.db"
        board = Board(db, evaluators=("fce",))
        _, token = board.add_team("bench")
        serve = subprocess.Popen(
            [*CLI, "serve", "--db", str(db), "--port", "0", "--rate-limit", "1000"],
            stdout=subprocess.PIPE,
            text=True,
        )
        url = serve.stdout.readline().split(" on ", 1)[1].strip()
        workers = [
            subprocess.Popen(
                [*CLI, "worker", "--db", str(db), "--poll", "0.2", "--idle-exit", "20"],
                stdout=subprocess.DEVNULL,
            )
            for _ in range(args.workers)
        ]
        time.sleep(3.0)  # let the workers import and start polling (not counted)

        def upload(path: Path) -> float:
            began = time.perf_counter()
            with httpx.Client(timeout=600) as client:
                answer = client.post(
                    f"{url}api/submissions",
                    params={"filename": path.name},
                    content=path.read_bytes(),
                    headers={"Authorization": f"Bearer {token}"},
                )
            answer.raise_for_status()
            return time.perf_counter() - began

        started = time.perf_counter()
        with ThreadPoolExecutor(max_workers=len(paths)) as pool:
            latencies = sorted(pool.map(upload, paths))
        while board.counts()["scored"] + board.counts()["failed"] < len(paths):
            if all(proc.poll() is not None for proc in workers):
                raise SystemExit(f"the workers exited before scoring: {board.counts()}")
            time.sleep(0.2)
        service_s = time.perf_counter() - started
        for proc in workers:
            proc.wait(120)
        serve.terminate()
        serve.wait(30)
        assert board.counts()["scored"] == len(paths), board.counts()
        assert board.integrity_check() == "ok"

    ratio = service_s / (reference_s / args.workers)
    print(
        f"uploads: p50 {latencies[len(latencies) // 2]:.2f} s, max {latencies[-1]:.2f} s "
        f"({len(paths)} at once, each validated on arrival)"
    )
    print(f"service: all scored in {service_s:.1f} s with {args.workers} workers")
    print(f"ratio service / (reference / workers) = {ratio:.2f} (1 = no overhead)")
    if args.out is not None:
        write_json_atomic(
            args.out,
            {
                "submissions": len(paths),
                "k": args.k,
                "workers": args.workers,
                "reference_s": reference_s,
                "service_s": service_s,
                "upload_p50_s": latencies[len(latencies) // 2],
                "upload_max_s": latencies[-1],
                "ratio": ratio,
            },
        )


if __name__ == "__main__":
    main()
