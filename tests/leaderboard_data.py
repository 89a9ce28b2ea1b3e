"""Data for the leaderboard tests: a 3-object benchmark cut from the shipped one, and valid
submission files for it (imported as ``leaderboard_data``: pytest puts ``tests/`` on the path)."""

from __future__ import annotations

import contextlib
import json
import sqlite3
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from dg16m_env.benchmark.file import read_benchmark, write_benchmark
from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
from dg16m_env.evaluators import load_benchmark_ref
from dg16m_env.subjects.submission_writer import write_submission

OBJECTS = 3


def small_benchmark(path: Path) -> Path:
    """The shipped benchmark's first :data:`OBJECTS` objects, written to ``path``."""
    bench = read_benchmark(EMBEDDED_BENCHMARK)
    ids = [o.object_id for o in bench.objects][:OBJECTS]
    write_benchmark(path, bench.select_objects(ids))
    return path


def valid_submission(
    path: Path, benchmark: Path, *, k: int = 3, offset: int = 0, method: str | None = None
) -> Path:
    """A valid submission: each object's stored dual grasps ``offset .. offset + k`` (cycled)."""
    ref = load_benchmark_ref(benchmark)
    bench = ref.benchmark
    poses = {}
    for object_id in ref.object_ids:
        rows = bench.object_rows(object_id)
        take = rows[(np.arange(k) + offset) % rows.size]
        poses[object_id] = bench.poses[take]
    metadata = {"method": method} if method else None
    return write_submission(path, poses, benchmark=ref.sha256, metadata=metadata)


def db_dump(db: Path) -> list[str]:
    """Every row of a board's database as SQL (to check that a refusal changed nothing)."""
    conn = sqlite3.connect(db)
    try:
        return list(conn.iterdump())
    finally:
        conn.close()


def tree(folder: Path) -> dict[str, bytes]:
    """Relative path -> bytes of every file under ``folder``."""
    if not folder.exists():
        return {}
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def set_benchmark(db: Path, *, sha256: str, object_ids: list[str], path: str | None) -> None:
    """Point a board at another benchmark identity (the bad-submission corpus is made for
    fixed ids and a fixed sha256)."""
    conn = sqlite3.connect(db)
    try:
        value = {"path": path, "sha256": sha256, "object_ids": object_ids, "mesh_root": None}
        conn.execute("UPDATE settings SET value = ? WHERE key = 'benchmark'", (json.dumps(value),))
        conn.commit()
    finally:
        conn.close()


class FakeResult:
    """What ``Board.finish`` stores of a result: a stand-in for an evaluator's
    :class:`~dg16m_env.evaluators.EvaluationResult` with an ``fce`` headline of ``score``."""

    evaluator_version = "1"

    def __init__(self, score: float):
        self.score = score

    def to_dict(self) -> dict[str, Any]:
        rate = {"rate": self.score, "ci_low": self.score, "ci_high": self.score, "rows": 1}
        return {"headline": "fce", "metrics": {"fce": rate}, "per_family": {}}


def scored_rows(board: Any, team_name: str, n: int, *, ties: int = 40) -> list[int]:
    """``n`` scored fce results of ``team_name`` (scores ``(i % ties) / ties``) recorded without
    files or evaluators (the queue's records only); returns their submission ids."""
    from leaderboard.queue import NewSubmission

    team = board.team(team_name)
    ids = []
    for i in range(n):
        new = NewSubmission(team.id, team.name, f"{i:064x}", 1, f"f{i}.h5", f"run {i}", ["fce"])
        sid = board.jobs.enqueue(new)
        claim = board.claim("w", 60.0, submission_id=sid)
        assert board.finish(claim, {"fce": FakeResult((i % ties) / ties)}, "log")
        ids.append(sid)
    return ids


@contextlib.contextmanager
def running_service(board: Any, config: Any) -> Iterator[tuple[str, tuple[str, int]]]:
    """The service for ``board`` (a ``leaderboard.app.ServiceConfig``) on loopback in a thread;
    yields its URL and (host, port); stopped and joined (bounded) on exit."""
    from leaderboard.app import make_server

    server, sock, url = make_server(board, port=0, config=config)
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    for _ in range(200):
        if server.started:
            break
        time.sleep(0.05)
    assert server.started
    try:
        yield url, sock.getsockname()[:2]
    finally:
        server.should_exit = True
        thread.join(30)
        sock.close()
