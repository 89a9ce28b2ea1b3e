"""The leaderboard service under load and under stalled clients, on loopback, with a same-run
reference.

``dg16m leaderboard serve`` and ``--workers`` ``dg16m leaderboard worker`` processes run on a
board of the shipped benchmark's first ``--objects`` objects, scored with ``fce``. In one run
(the machine is shared and noisy, so every ratio compares numbers taken minutes apart):

* **alone**: one submission uploaded to the idle service and scored (upload to scored), after
  one warm-up submission per worker (not counted: a worker's first job forks its scoring
  process and loads the evaluators);
* **load**: ``--teams`` teams upload ``--per-team`` distinct submissions each, all at once;
  prints uploads/s, the p50/p95 upload latency (each upload is validated on arrival) and the
  drain time (first upload sent to last submission scored), as a ratio to ``alone`` (ideal:
  submissions / workers);
* **stalled**: ``--stalled`` connections that connected and sent nothing or half a request
  head; the latency of ``/api/health`` requests from another client while they are held,
  against the same requests before (target: at most 0.5 s more);
* **sigterm**: the time SIGTERM takes to stop a server holding a stalled upload (target:
  10 s), and whether its temporary file is gone; then a server SIGKILLed with a stalled upload
  and restarted: the upload files left after the restart (target: 0).

    nice -n 19 .venv/bin/python bench/leaderboard_load.py                 # ~2 minutes
    .venv/bin/python bench/leaderboard_load.py --teams 4 --per-team 1 --stalled 20
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import signal
import socket
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import numpy as np

from dg16m_core.atomic import write_json_atomic
from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.evaluators import load_benchmark_ref
from dg16m_env.subjects.submission_writer import write_submission
from leaderboard.board import Board

CLI = [sys.executable, "-m", "dg16m_core.cli", "leaderboard"]
LIMIT_S = 600.0
"""Longest wait for anything (the run fails rather than hang)."""


def _benchmark(path: Path, objects: int) -> Path:
    bench = read_benchmark(EMBEDDED_BENCHMARK)
    write_benchmark(path, bench.select_objects([o.object_id for o in bench.objects][:objects]))
    return path


def _files(folder: Path, benchmark: Path, n: int, k: int) -> list[Path]:
    """``n`` distinct valid submissions (``k`` dual grasps per object, another slice each)."""
    ref = load_benchmark_ref(benchmark)
    bench = ref.benchmark
    out = []
    for i in range(n):
        poses = {}
        for object_id in ref.object_ids:
            rows = bench.object_rows(object_id)
            poses[object_id] = bench.poses[rows[(np.arange(k) + i * k) % rows.size]]
        out.append(write_submission(folder / f"sub-{i:03d}.h5", poses, benchmark=ref.sha256))
    return out


def _serve(db: Path, *args: str) -> tuple[subprocess.Popen[str], str]:
    proc = subprocess.Popen(
        [*CLI, "serve", "--db", str(db), "--port", "0", "--rate-limit", "100000", *args],
        stdout=subprocess.PIPE,
        text=True,
    )
    line = proc.stdout.readline()
    if not line.startswith("serving "):
        proc.kill()
        raise SystemExit(f"the server did not start: {line!r}")
    return proc, line.split(" on ", 1)[1].strip()


def _address(url: str) -> tuple[str, int]:
    host, port = url.split("//", 1)[1].rstrip("/").rsplit(":", 1)
    return host, int(port)


def _upload(url: str, token: str, path: Path) -> tuple[float, int]:
    began = time.perf_counter()
    with httpx.Client(timeout=LIMIT_S) as client:
        answer = client.post(
            f"{url}api/submissions",
            params={"filename": path.name},
            content=path.read_bytes(),
            headers={"Authorization": f"Bearer {token}"},
        )
    if answer.status_code != 202:
        raise SystemExit(f"upload refused: {answer.status_code} {answer.text[:300]}")
    return time.perf_counter() - began, int(answer.json()["submission"])


def _drained(board: Board, n: int) -> float:
    """Wait until ``n`` submissions are scored or failed; the time it happened."""
    deadline = time.monotonic() + LIMIT_S
    while time.monotonic() < deadline:
        counts = board.counts()
        if counts["scored"] + counts["failed"] >= n:
            if counts["failed"]:
                raise SystemExit(f"failed submissions: {counts}")
            return time.perf_counter()
        time.sleep(0.05)
    raise SystemExit(f"not drained within {LIMIT_S} s: {board.counts()}")


def _health_latencies(url: str, n: int) -> list[float]:
    out = []
    with httpx.Client(timeout=30) as client:
        for _ in range(n):
            began = time.perf_counter()
            client.get(f"{url}api/health").raise_for_status()
            out.append(time.perf_counter() - began)
            time.sleep(0.02)
    return out


def _stalled_upload(url: str, token: str, path: Path) -> socket.socket:
    data = path.read_bytes()
    sock = socket.create_connection(_address(url))
    sock.sendall(
        b"POST /api/submissions?filename=stalled.h5 HTTP/1.1\r\nHost: x\r\n"
        + f"Authorization: Bearer {token}\r\nContent-Length: {len(data)}\r\n\r\n".encode()
        + data[: len(data) // 2]
    )
    return sock


def _until(predicate, limit_s: float = 60.0) -> None:
    deadline = time.monotonic() + limit_s
    while not predicate():
        if time.monotonic() > deadline:
            raise SystemExit("a bounded wait ran out")
        time.sleep(0.02)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--teams", type=int, default=8, help="teams uploading at once")
    parser.add_argument("--per-team", type=int, default=2, help="submissions per team")
    parser.add_argument("--workers", type=int, default=2, help="worker processes")
    parser.add_argument("--objects", type=int, default=10, help="benchmark objects")
    parser.add_argument("--k", type=int, default=4, help="dual grasps per object")
    parser.add_argument("--stalled", type=int, default=100, help="stalled connections")
    parser.add_argument("--out", type=Path, default=None, help="write the numbers as JSON")
    args = parser.parse_args()
    numbers: dict[str, float | int] = {}

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        bench = _benchmark(root / "bench.h5", args.objects)
        n = args.teams * args.per_team
        paths = _files(root, bench, n + 1 + args.workers, args.k)
        warmups, paths = paths[n + 1 :], paths[: n + 1]
        db = root / "board.db"
        board = Board(db, benchmark=bench, evaluators=("fce",))
        tokens = [board.add_team(f"team-{i:02d}")[1] for i in range(args.teams)]
        print(
            f"{n} submissions from {args.teams} teams ({args.objects} objects x {args.k} dual "
            f"grasps, {paths[0].stat().st_size / 1024:.0f} KiB each), {args.workers} workers, "
            "fce"
        )

        serve, url = _serve(db)
        workers = [
            subprocess.Popen(
                [*CLI, "worker", "--db", str(db), "--poll", "0.05"], stdout=subprocess.DEVNULL
            )
            for _ in range(args.workers)
        ]
        try:
            time.sleep(3.0)  # let the workers import and start polling (not counted)
            warm = len(warmups)
            for path in warmups:  # claimed at once, one per idle worker (not counted)
                _upload(url, tokens[-1], path)
            _drained(board, warm)
            began = time.perf_counter()
            _upload(url, tokens[0], paths[-1])
            alone_s = _drained(board, warm + 1) - began
            print(f"alone: one submission uploaded and scored in {alone_s:.2f} s")

            jobs = [(tokens[i % args.teams], paths[i]) for i in range(n)]
            began = time.perf_counter()
            with ThreadPoolExecutor(max_workers=n) as pool:
                answers = list(pool.map(lambda job: _upload(url, *job), jobs))
            uploaded_s = time.perf_counter() - began
            drain_s = _drained(board, warm + n + 1) - began
            latencies = np.array([a[0] for a in answers])
            p50, p95 = np.percentile(latencies, [50, 95])
            ratio = drain_s / alone_s
            print(
                f"load: {n} uploads in {uploaded_s:.2f} s ({n / uploaded_s:.1f} uploads/s), "
                f"latency p50 {p50:.2f} s, p95 {p95:.2f} s"
            )
            print(
                f"load: drained in {drain_s:.1f} s = {ratio:.1f} x alone (ideal "
                f"{n / args.workers:.1f} = {n} submissions / {args.workers} workers)"
            )
            assert board.integrity_check() == "ok"
            assert board.counts()["scored"] == warm + n + 1, board.counts()
            numbers.update(
                submissions=n,
                workers=args.workers,
                alone_s=alone_s,
                uploads_per_s=n / uploaded_s,
                upload_p50_s=float(p50),
                upload_p95_s=float(p95),
                drain_s=drain_s,
                drain_ratio=ratio,
            )

            before = _health_latencies(url, 30)
            stalled = []
            for i in range(args.stalled):
                sock = socket.create_connection(_address(url))
                if i % 2:
                    sock.sendall(b"GET /api/health HTTP/1.1\r\nHost: x\r\nX-Slow: ")
                stalled.append(sock)
            during = _health_latencies(url, 30)
            delay = max(during) - float(np.median(before))
            for sock in stalled:
                sock.close()
            print(
                f"stalled: {args.stalled} stalled connections held; /api/health p50 "
                f"{np.median(before) * 1e3:.1f} ms before, {np.median(during) * 1e3:.1f} ms "
                f"during, max during {max(during) * 1e3:.1f} ms: at most {delay:.3f} s more "
                "(target 0.5 s)"
            )
            numbers.update(stalled=args.stalled, stalled_extra_delay_s=delay)
        finally:
            for proc in workers:
                proc.terminate()
            for proc in workers:
                proc.wait(60)
            serve.terminate()
            serve.wait(60)

        uploads = board.uploads
        serve, url = _serve(db)
        sock = _stalled_upload(url, tokens[0], paths[0])
        _until(lambda: any(uploads.glob("upload-*")))
        began = time.perf_counter()
        serve.send_signal(signal.SIGTERM)
        serve.wait(60)
        sigterm_s = time.perf_counter() - began
        sock.close()
        left = len(list(uploads.glob("upload-*")))
        print(
            f"sigterm: a server holding a stalled upload stopped in {sigterm_s:.2f} s "
            f"(target 10 s), {left} upload files left"
        )

        serve, url = _serve(db)
        sock = _stalled_upload(url, tokens[0], paths[0])
        _until(lambda: any(uploads.glob("upload-*")))
        serve.kill()
        serve.wait(60)
        sock.close()
        killed_left = len(list(uploads.glob("upload-*")))
        serve, url = _serve(db)
        orphans = len(list(uploads.glob("upload-*")))
        serve.terminate()
        serve.wait(60)
        print(
            f"restart: SIGKILL left {killed_left} upload file(s); after a restart: {orphans} "
            "(target 0)"
        )
        numbers.update(sigterm_s=sigterm_s, orphans_after_restart=orphans)

    if args.out is not None:
        write_json_atomic(args.out, numbers)


if __name__ == "__main__":
    main()
