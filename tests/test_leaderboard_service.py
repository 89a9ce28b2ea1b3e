"""End-to-end tests of the leaderboard service on loopback: ``dg16m leaderboard serve`` and
``dg16m leaderboard worker`` as real processes, requests over HTTP.

Covers the issue's targets: 20 concurrent submissions all stored and scored with a sound
database; a worker killed with SIGKILL mid-scoring whose job another worker finishes, scored
once; refusals (token, another team's submission, path traversal, size, invalid files, rate
limit) each with its status and message and the database unchanged; the page from the running
service in headless Chromium. Every wait is bounded.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import httpx
import numpy as np
import pytest
from browser import console_log, order, page_problems, screenshot, start_browser, wait_for_script
from leaderboard_data import db_dump, small_benchmark, tree, valid_submission

from leaderboard.board import Board
from leaderboard.tokens import new_token

CLI = [sys.executable, "-m", "dg16m_core.cli", "leaderboard"]
RATE_LIMIT = 25
MAX_UPLOAD = 60_000  # bytes; a 3-object submission is ~10-20 kB
START_TIMEOUT_S = 60.0
SCORE_TIMEOUT_S = 180.0


@dataclass
class Service:
    url: str
    db: Path
    bench: Path
    files: Path
    tokens: dict[str, str]
    process: subprocess.Popen[str]
    workers: list[subprocess.Popen[str]] = field(default_factory=list)

    def client(self, team: str | None = None) -> httpx.Client:
        headers = {} if team is None else {"Authorization": f"Bearer {self.tokens[team]}"}
        return httpx.Client(base_url=self.url, headers=headers, timeout=30.0)

    def wait_workers(self, timeout_s: float = 60.0) -> None:
        """Until every worker started so far has exited (they run with --idle-exit)."""
        for proc in self.workers:
            proc.wait(timeout_s)

    def worker(self, *args: str) -> subprocess.Popen[str]:
        proc = subprocess.Popen(
            [*CLI, "worker", "--db", str(self.db), "--poll", "0.2", *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.workers.append(proc)
        return proc


def _first_line(proc: subprocess.Popen[str], timeout_s: float) -> str:
    """The process's first line of output, read with a deadline."""
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.append(proc.stdout.readline()), daemon=True)
    reader.start()
    reader.join(timeout_s)
    if not lines or not lines[0]:
        proc.kill()
        raise AssertionError(f"no output within {timeout_s} s: {proc.communicate()[0]!r}")
    return lines[0]


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Service]:
    root = tmp_path_factory.mktemp("service")
    bench = small_benchmark(root / "bench3.h5")
    db = root / "board.db"
    board = Board(db, benchmark=bench, evaluators=("fce",))
    tokens = {name: board.add_team(name)[1] for name in ("many", "alice", "bob", "burst", "kill")}
    proc = subprocess.Popen(
        [
            *CLI,
            "serve",
            "--db",
            str(db),
            "--port",
            "0",
            "--rate-limit",
            str(RATE_LIMIT),
            "--max-upload-mb",
            str(MAX_UPLOAD / (1 << 20)),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    line = _first_line(proc, START_TIMEOUT_S)
    assert line.startswith("serving "), line
    url = line.split(" on ", 1)[1].strip()
    files = root / "files"
    files.mkdir()
    service = Service(url, db, bench, files, tokens, proc)
    yield service
    for p in [*service.workers, proc]:
        if p.poll() is None:
            p.terminate()
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def _wait_all_scored(service: Service, ids: list[int], timeout_s: float) -> Board:
    board = Board(service.db, create=False)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        states = {board.submission_row(i)["status"] for i in ids}
        if states <= {"scored", "failed"}:
            return board
        time.sleep(0.3)
    raise AssertionError(f"not scored within {timeout_s} s: {board.counts()}")


@pytest.fixture(scope="module")
def twenty(service: Service) -> list[int]:
    """20 submissions uploaded at once by one team, then scored by two workers."""
    paths = [
        valid_submission(service.files / f"many-{i:02d}.h5", service.bench, k=2, offset=i)
        for i in range(20)
    ]

    def upload(path: Path) -> httpx.Response:
        with service.client("many") as client:
            return client.post(
                "/api/submissions",
                params={"filename": path.name, "label": f"run {path.stem}"},
                content=path.read_bytes(),
            )

    with ThreadPoolExecutor(max_workers=20) as pool:
        answers = list(pool.map(upload, paths))
    assert [a.status_code for a in answers] == [202] * 20, [a.text for a in answers]
    ids = [a.json()["submission"] for a in answers]
    for _ in range(2):
        service.worker("--idle-exit", "3")
    _wait_all_scored(service, ids, SCORE_TIMEOUT_S)
    return ids


def test_twenty_concurrent_submissions_are_all_stored_and_scored(
    service: Service, twenty: list[int]
) -> None:
    assert len(set(twenty)) == 20
    with service.client("many") as client:
        mine = client.get("/api/submissions").json()["submissions"]
    assert len(mine) == 20
    assert {s["status"] for s in mine} == {"scored"}
    board = Board(service.db, create=False)
    assert board.integrity_check() == "ok"
    with board.read() as conn:
        assert conn.execute("SELECT count(*) FROM results").fetchone()[0] >= 20
        rows = conn.execute(
            "SELECT count(*) FROM results r JOIN submissions s ON s.id = r.submission_id "
            "JOIN teams t ON t.id = s.team_id WHERE t.name = 'many'"
        ).fetchone()[0]
    assert rows == 20  # one fce result each, none twice
    files = tree(board.files)
    assert len(files) == 20  # distinct contents, stored once each
    with service.client() as client:
        fce = client.get("/api/board").json()["evaluators"][0]
    assert fce["name"] == "fce"
    assert {r["submission"] for r in fce["rows"]} >= set(twenty)


def test_worker_killed_mid_scoring_is_replaced_and_scored_once(service: Service) -> None:
    service.wait_workers()  # the victim must be the only worker that can claim the job
    path = valid_submission(service.files / "slow.h5", service.bench, k=12, offset=3)
    with service.client("kill") as client:
        answer = client.post(
            "/api/submissions",
            params={"filename": "slow.h5", "evaluators": "gsr"},
            content=path.read_bytes(),
        )
        assert answer.status_code == 202, answer.text
        sid = answer.json()["submission"]
        victim = service.worker("--lease", "2")
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            job = client.get(f"/api/submissions/{sid}").json()
            if job["status"] == "running":
                break
            time.sleep(0.1)
        assert job["status"] == "running", job
        assert job["events"][-1]["worker"].endswith(f":{victim.pid}")
        time.sleep(0.5)
        victim.send_signal(signal.SIGKILL)
        victim.wait(10)
        board = Board(service.db, create=False)
        assert board.submission_row(sid)["status"] == "running"  # killed mid-scoring
        assert board.results(sid) == {}
        with client.stream("GET", "/api/queue") as response:
            assert response.status_code == 200
        # a long lease: a loaded machine must not make the rescuer lose the job too
        rescuer = service.worker("--lease", "10", "--idle-exit", "5")
        _wait_all_scored(service, [sid], SCORE_TIMEOUT_S)
        rescuer.wait(60)
        view = client.get(f"/api/submissions/{sid}").json()
    assert view["status"] == "scored", view
    assert view["attempts"] == 2
    assert list(view["results"]) == ["gsr"]
    assert board.results(sid)["gsr"]["subject"]["sha256"] == view["file_sha256"]
    messages = [e["message"] for e in view["events"]]
    assert any("re-queued: the lease of worker" in m for m in messages), messages
    assert [e["state"] for e in view["events"]] == [
        "queued",
        "running",
        "queued",
        "running",
        "scored",
    ]
    with board.read() as conn:
        count = conn.execute(
            "SELECT count(*) FROM results WHERE submission_id = ?", (sid,)
        ).fetchone()[0]
    assert count == 1
    assert board.integrity_check() == "ok"


def _edited(source: Path, target: Path, edit: Any) -> Path:
    target.write_bytes(source.read_bytes())
    with h5py.File(target, "r+") as f:
        edit(f)
    return target


def test_refusals_leave_the_database_unchanged(service: Service) -> None:
    good = valid_submission(service.files / "alice.h5", service.bench, k=2, offset=7)
    with service.client("alice") as alice:
        answer = alice.post(
            "/api/submissions", params={"filename": "alice.h5"}, content=good.read_bytes()
        )
        assert answer.status_code == 202, answer.text
        sid = answer.json()["submission"]
    ids = list(Board(service.db, create=False).benchmark.object_ids)

    def nan(f: h5py.File) -> None:
        poses = f[f"objects/{ids[0]}/poses"]
        data = poses[...]
        data[1, 0, 0, 3] = np.nan
        poses[...] = data

    invalid = {
        "text.h5": (lambda p: p.write_text("not hdf5"), "file"),
        "nan.h5": (lambda p: _edited(good, p, nan), f"objects/{ids[0]}/poses[1]"),
        "extra.h5": (
            lambda p: _edited(
                good,
                p,
                lambda f: (
                    f["objects"]
                    .create_group("chair-9")
                    .create_dataset("poses", data=f[f"objects/{ids[0]}/poses"][...])
                ),
            ),
            "objects",
        ),
        "other-benchmark.h5": (
            lambda p: _edited(good, p, lambda f: f.attrs.__setitem__("benchmark", "cd" * 32)),
            "attrs/benchmark",
        ),
        "truncated.h5": (
            lambda p: p.write_bytes(good.read_bytes()[: good.stat().st_size // 2]),
            "file",
        ),
    }
    for name, (build, _) in invalid.items():
        build(service.files / name)

    before_db = db_dump(service.db)
    store = Board(service.db, create=False).files
    before_files = tree(store)
    wrong = new_token()
    with service.client() as anon, service.client("alice") as alice, service.client("bob") as bob:
        cases: list[tuple[str, httpx.Response, int, str]] = [
            ("no token", anon.post("/api/submissions", content=b"x"), 401, "found none"),
            (
                "wrong token",
                anon.post(
                    "/api/submissions",
                    content=good.read_bytes(),
                    headers={"Authorization": f"Bearer {wrong}"},
                ),
                401,
                "belongs to no team",
            ),
            (
                "basic auth",
                anon.get("/api/submissions", headers={"Authorization": "Basic YTpi"}),
                401,
                "another scheme",
            ),
            ("no token, list", anon.get(f"/api/submissions/{sid}"), 401, "found none"),
            ("another team's", bob.get(f"/api/submissions/{sid}"), 403, "another team's"),
            ("no such", bob.get("/api/submissions/99999"), 404, "#99999"),
        ]
        for filename in ("../../etc/passwd", "..", "a/b.h5", "..\\x.h5", ".h5", "x\x00.h5"):
            cases.append(
                (
                    f"file name {filename!r}",
                    alice.post(
                        "/api/submissions",
                        params={"filename": filename},
                        content=good.read_bytes(),
                    ),
                    400,
                    "expected a plain name",
                )
            )
        cases += [
            (
                "unknown parameter",
                alice.post("/api/submissions", params={"path": "/etc"}, content=b"x"),
                400,
                "found ['path']",
            ),
            (
                "unknown evaluator",
                alice.post("/api/submissions", params={"evaluators": "fce,rm"}, content=b"x"),
                400,
                "found 'rm'",
            ),
            (
                "declared too large",
                alice.post("/api/submissions", content=b"\0" * (MAX_UPLOAD + 1)),
                413,
                "Content-Length",
            ),
            (
                "streamed too large",
                alice.post(
                    "/api/submissions",
                    content=(b"\0" * 8192 for _ in range(MAX_UPLOAD // 8192 + 2)),
                ),
                413,
                "stopped reading",
            ),
            ("empty", alice.post("/api/submissions", content=b""), 400, "found none"),
        ]
        for name, (_, place) in invalid.items():
            answer = alice.post(
                "/api/submissions",
                params={"filename": name},
                content=(service.files / name).read_bytes(),
            )
            cases.append((f"invalid {name}", answer, 422, "expected a valid submission file"))
            assert any(p["place"].startswith(place) for p in answer.json()["problems"]), (
                name,
                answer.json(),
            )
        cases.append(
            (
                "repeat",
                alice.post(
                    "/api/submissions", params={"filename": "alice.h5"}, content=good.read_bytes()
                ),
                409,
                f"already submitted as #{sid}",
            )
        )
        cases += [
            ("asset traversal", anon.get("/assets/..%2Fboard.db"), 404, ""),
            ("unknown asset", anon.get("/assets/board.db"), 404, "expected one of"),
            ("unscored page", anon.get(f"/submissions/{sid}"), 404, ""),
        ]
    for name, response, status, message in cases:
        assert response.status_code == status, (name, response.status_code, response.text)
        if message:
            assert message in response.text, (name, response.text)
        if status == 401:
            assert response.headers["www-authenticate"].startswith("Bearer")
        if response.headers.get("content-type", "").startswith("application/json"):
            assert response.json()["error"]
        assert "default-src 'none'" in response.headers["content-security-policy"]
    assert db_dump(service.db) == before_db
    assert tree(store) == before_files
    uploads = service.db.parent / f"{service.db.stem}.uploads"
    assert tree(uploads) == {}  # every temporary upload was removed


def test_bursts_over_the_rate_limit_are_refused(service: Service) -> None:
    before = db_dump(service.db)
    with service.client("burst") as client:
        codes = [client.post("/api/submissions", content=b"").status_code for _ in range(30)]
        last = client.post("/api/submissions", content=b"")
    assert codes[:RATE_LIMIT] == [400] * RATE_LIMIT  # refused uploads count too
    assert codes[RATE_LIMIT:] == [429] * (30 - RATE_LIMIT)
    assert last.status_code == 429
    assert int(last.headers["retry-after"]) >= 1
    assert "failed uploads count too" in last.json()["error"]
    assert db_dump(service.db) == before
    with service.client("bob") as other:  # another team is not limited by it
        assert other.post("/api/submissions", content=b"").status_code == 400


def test_page_from_the_running_service(service: Service, twenty: list[int], tmp_path: Path) -> None:
    from selenium.webdriver.common.by import By

    driver = start_browser()
    try:
        console_log(driver)
        driver.get(service.url)
        wait_for_script(driver)
        assert page_problems(driver) == []
        shown = order(driver, "table-fce")
        with service.client() as client:
            rows = client.get("/api/board").json()["evaluators"][0]["rows"]
        assert shown == [r["submission"] for r in rows]
        assert set(twenty) <= set(shown)
        with service.client() as client:
            client_families = client.get("/api/board").json()["evaluators"][0]["families"]
        families = len(client_families)
        bars = driver.find_elements(By.CSS_SELECTOR, "#chart-fce rect.bar")
        assert len(bars) == min(5, len(rows)) * families  # the top 5, every family scored
        screenshot(driver, tmp_path, "leaderboard_service.png")
        team = driver.find_element(By.CSS_SELECTOR, "#table-fce thead th:nth-child(2)")
        team.click()
        teams = [r["team"] for r in rows]
        by_team = [r["submission"] for _, r in sorted(enumerate(rows), key=lambda p: p[1]["team"])]
        assert order(driver, "table-fce") == by_team or sorted(teams) == teams
        submission = driver.find_element(By.CSS_SELECTOR, "#table-fce thead th:nth-child(3)")
        submission.click()
        reordered = order(driver, "table-fce")
        assert sorted(reordered) == sorted(shown)
        assert reordered != shown or len(set(shown)) == 1
        driver.get(f"{service.url}submissions/{twenty[0]}")
        wait_for_script(driver)
        assert page_problems(driver) == []
        objects = driver.find_elements(By.CSS_SELECTOR, "#objects-fce tbody tr[data-object]")
        assert len(objects) == len(Board(service.db, create=False).benchmark.object_ids)
        screenshot(driver, tmp_path, "leaderboard_service_submission.png")
    finally:
        driver.quit()


def test_json_answers_and_headers(service: Service) -> None:
    with service.client() as client:
        health = client.get("/api/health")
        assert health.status_code == 200
        assert health.json()["status"] == "ok"
        assert health.headers["cache-control"] == "no-store"
        queue = client.get("/api/queue").json()
        assert set(queue) == {"generated_at", "counts"}  # public: counts only (issue 26)
        css = client.get("/assets/board.css")
        assert css.headers["content-type"].startswith("text/css")
        assert client.get("/nowhere").status_code == 404
    assert json.loads(json.dumps(queue)) == queue
    assert os.path.exists(service.db)


def test_command_line_submits_to_the_service(
    service: Service, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from dg16m_core.cli import main

    token_file = tmp_path / "bob.token"
    token_file.write_text(service.tokens["bob"] + "\n")
    path = valid_submission(tmp_path / "bob-cli.h5", service.bench, k=1, offset=13, method="cli")
    remote = ["--url", service.url, "--token-file", str(token_file)]
    service.worker("--idle-exit", "5")
    code = main(["leaderboard", "submit", str(path), *remote, "--wait", "120"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "queued on" in out
    assert "cli (bob): scored" in out
    bad = tmp_path / "bad.h5"
    bad.write_text("not hdf5")
    code = main(["leaderboard", "submit", str(bad), *remote])
    err = capsys.readouterr().err
    assert code == 2
    assert "HTTP 422" in err
    assert "file: expected an HDF5 file" in err or "HDF5 signature" in err
