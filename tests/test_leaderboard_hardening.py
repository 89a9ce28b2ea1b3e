"""The leaderboard service under hostile use (issue 26): ids past SQLite's integers, errors
with their security headers (unhandled ones too), stalled and oversized requests, SIGTERM with
a stalled upload, files left by killed processes, the public queue, pages of the board, and a
worker that lost its lease. Loopback only; every wait is bounded; no timing assertions."""

from __future__ import annotations

import contextlib
import fcntl
import signal
import socket
import subprocess
import sys
import threading
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import pytest
from leaderboard_data import running_service, scored_rows, small_benchmark, tree, valid_submission
from starlette.exceptions import StarletteDeprecationWarning

from leaderboard.app import SECURITY_HEADERS, ServiceConfig, create_app
from leaderboard.board import Board, NotFoundError
from leaderboard.query_checks import MAX_ID, check_id
from leaderboard.worker import Scorer, WorkerOptions, score_claim

with warnings.catch_warnings():  # starlette asks for httpx2, which is not installed
    warnings.simplefilter("ignore", StarletteDeprecationWarning)
    from starlette.testclient import TestClient

CLI = [sys.executable, "-m", "dg16m_core.cli", "leaderboard"]
CSP = SECURITY_HEADERS["Content-Security-Policy"]


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return small_benchmark(tmp_path_factory.mktemp("bench") / "bench3.h5")


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory, bench: Path) -> Path:
    return valid_submission(tmp_path_factory.mktemp("subs") / "good.h5", bench, k=2)


@dataclass
class App:
    board: Board
    token: str
    other: str
    client: TestClient


def make_app(tmp_path: Path, bench: Path, **config: Any) -> App:
    board = Board(tmp_path / "board.db", benchmark=bench, evaluators=("fce",))
    _, token = board.add_team("lab-a")
    _, other = board.add_team("lab-b")
    app = create_app(board, ServiceConfig(rate_limit=1000, **config))
    return App(board, token, other, TestClient(app, raise_server_exceptions=False))


def assert_error(response: httpx.Response, status: int, *, api: bool) -> None:
    assert response.status_code == status, (response.status_code, response.text[:500])
    assert response.headers["content-security-policy"] == CSP
    assert response.headers["x-content-type-options"] == "nosniff"
    kind = response.headers["content-type"]
    if api:
        assert kind.startswith("application/json"), kind
        body = response.json()
        assert body["status"] == status
        assert "expected" in body["error"]
        assert response.headers["cache-control"] == "no-store"
    else:
        assert kind.startswith("text/html"), kind
        assert "<h1>" in response.text


# --------------------------------------------------------------------------------------------
# Ids, errors and their headers
# --------------------------------------------------------------------------------------------


def test_check_id_bounds() -> None:
    assert check_id(1) == 1
    assert check_id("42") == 42
    assert check_id(str(MAX_ID)) == MAX_ID
    for bad in (0, -1, MAX_ID + 1, 2**64, "0", "", "1e3", "+5", " 7", "٣", True, 1.0, None):
        with pytest.raises(NotFoundError, match="expected an id from 1 to"):
            check_id(bad)


def test_ids_past_sqlite_integers_are_404_not_500(tmp_path: Path, bench: Path) -> None:
    app = make_app(tmp_path, bench)
    with pytest.raises(NotFoundError, match="expected an id"):
        app.board.submission_row(2**64)  # was OverflowError
    with pytest.raises(NotFoundError, match="expected an id"):
        app.board.results(99999999999999999999)
    auth = {"Authorization": f"Bearer {app.token}"}
    for sid in ("99999999999999999999", str(2**64), str(MAX_ID + 1), "0", "-1", "abc", "1.5"):
        assert_error(app.client.get(f"/submissions/{sid}"), 404, api=False)
        answer = app.client.get(f"/api/submissions/{sid}", headers=auth)
        assert_error(answer, 404, api=True)
        assert "expected an id from 1 to" in answer.json()["error"]
    assert_error(app.client.get(f"/api/submissions/{MAX_ID}", headers=auth), 404, api=True)


def test_errors_are_json_for_the_api_and_html_for_pages(tmp_path: Path, bench: Path) -> None:
    app = make_app(tmp_path, bench)
    assert_error(app.client.get("/nowhere"), 404, api=False)
    assert_error(app.client.get("/api/nowhere"), 404, api=True)
    assert_error(app.client.post("/api/board"), 405, api=True)
    assert_error(app.client.delete("/"), 405, api=False)
    assert_error(app.client.get("/assets/board.db"), 404, api=False)
    assert_error(app.client.get("/api/submissions"), 401, api=True)


def test_unhandled_exceptions_are_500s_with_headers_and_no_traceback(
    tmp_path: Path, bench: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    app = make_app(tmp_path, bench)

    def broken(*args: Any, **kwargs: Any) -> Any:
        raise RuntimeError("secret-internal-detail")

    monkeypatch.setattr(app.board, "counts", broken)
    for path, api in (("/api/health", True), ("/", False), ("/api/board", True)):
        answer = app.client.get(path)
        assert_error(answer, 500, api=api)
        assert "secret-internal-detail" not in answer.text
        assert "Traceback" not in answer.text
        assert "RuntimeError" not in answer.text


# --------------------------------------------------------------------------------------------
# The public queue, pages of the board
# --------------------------------------------------------------------------------------------


def test_public_queue_shows_counts_only(tmp_path: Path, bench: Path, good: Path) -> None:
    app = make_app(tmp_path, bench)
    team = app.board.team("lab-a")
    sid = app.board.submit(team, good, label="secret-label-x")
    app.board.claim("host-secret:4242", 60.0)
    public = app.client.get("/api/queue")
    assert public.status_code == 200
    assert set(public.json()) == {"generated_at", "counts"}
    assert public.json()["counts"] == {"queued": 0, "running": 1, "scored": 0, "failed": 0}
    for secret in ("secret-label-x", "lab-a", "host-secret", "4242"):
        assert secret not in public.text
    own = app.client.get("/api/queue", headers={"Authorization": f"Bearer {app.token}"}).json()
    assert [j["submission"] for j in own["jobs"]] == [sid]
    assert own["jobs"][0]["label"] == "secret-label-x"
    assert "host-secret" not in str(own)
    other = app.client.get("/api/queue", headers={"Authorization": f"Bearer {app.other}"})
    assert other.json()["jobs"] == []
    wrong = app.client.get("/api/queue", headers={"Authorization": "Bearer nope"})
    assert_error(wrong, 401, api=True)


def test_board_comes_in_bounded_pages(tmp_path: Path, bench: Path) -> None:
    app = make_app(tmp_path, bench)
    scored_rows(app.board, "lab-a", 120)
    whole = app.client.get("/api/board").json()
    (fce,) = whole["evaluators"]
    assert len(fce["rows"]) == 50
    assert fce["total"] == 120
    assert whole["page"] == {
        "number": 1,
        "limit": 50,
        "pages": 3,
        "total": 120,
        "prev": None,
        "next": "/api/board?page=2",
    }
    ranks = []
    for page in (1, 2, 3):
        view = app.client.get("/api/board", params={"page": page}).json()
        ranks += [r["rank"] for r in view["evaluators"][0]["rows"]]
    assert len(ranks) == 120
    assert ranks == sorted(ranks)
    assert ranks[:3] == [1, 1, 1]  # 3 results of each score: competition ranking
    assert ranks[-1] == 118
    small = app.client.get("/api/board", params={"page": 4, "limit": 30}).json()
    assert small["page"]["prev"] == "/api/board?page=3&limit=30"
    assert small["page"]["next"] is None
    assert len(small["evaluators"][0]["rows"]) == 30
    html = app.client.get("/", params={"page": 2})
    assert html.status_code == 200
    assert 'rel="prev" href="/?page=1"' in html.text
    assert 'rel="next" href="/?page=3"' in html.text
    assert html.text.count("<tr data-submission") <= 50 or "data-submission" not in html.text
    for params, status in (
        ({"page": "0"}, 422),
        ({"page": "-1"}, 422),
        ({"page": "x"}, 422),
        ({"page": "9" * 30}, 422),
        ({"limit": "0"}, 422),
        ({"limit": "501"}, 422),
        ({"other": "1"}, 422),
        ({"page": "4"}, 404),
    ):
        assert_error(app.client.get("/api/board", params=params), status, api=True)
        assert_error(app.client.get("/", params=params), status, api=False)


def test_pages_are_rendered_off_the_event_loop(
    tmp_path: Path, bench: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import asyncio

    import leaderboard.routes.site

    app = make_app(tmp_path, bench)
    (sid,) = scored_rows(app.board, "lab-a", 1)
    on_loop: list[bool] = []

    def watched(render: Any) -> Any:
        def wrapper(*args: Any, **kwargs: Any) -> str:
            try:
                asyncio.get_running_loop()
                on_loop.append(True)
            except RuntimeError:  # no loop in this thread: a worker thread
                on_loop.append(False)
            return render(*args, **kwargs)

        return wrapper

    for name in ("render_index", "render_submission"):
        module = leaderboard.routes.site
        monkeypatch.setattr(module, name, watched(getattr(module, name)))
    assert app.client.get("/").status_code == 200
    assert app.client.get(f"/submissions/{sid}").status_code == 200
    assert on_loop == [False, False]


# --------------------------------------------------------------------------------------------
# Files killed processes left
# --------------------------------------------------------------------------------------------


def test_orphaned_files_are_removed_at_start_and_files_in_use_kept(
    tmp_path: Path, bench: Path, good: Path
) -> None:
    board = Board(tmp_path / "board.db", benchmark=bench, evaluators=("fce",))
    team, _ = board.add_team("lab-a")
    sid = board.submit(team, good)
    kept = board.file_path(board.submission_row(sid)["file_sha256"])
    board.uploads.mkdir()
    orphans = [
        board.uploads / "upload-killed1.h5",
        board.uploads / "upload-killed2.h5",
        kept.parent / f".{kept.name}.tmp-abc.h5",
        board.files / "ab" / f"{'ab' * 32}.h5",  # stored, but its submission never recorded
    ]
    for path in orphans:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"partial")
    in_use = board.uploads / "upload-streaming.h5"
    in_use.write_bytes(b"still arriving")
    other = board.uploads / "notes.txt"
    other.write_text("not ours")
    with open(in_use, "rb") as handle:
        fcntl.flock(handle.fileno(), fcntl.LOCK_SH)  # as a live upload holds it
        create_app(board, ServiceConfig())
        assert in_use.exists()
    assert [p for p in orphans if p.exists()] == []
    assert kept.read_bytes() == good.read_bytes()  # referenced: kept
    assert other.exists()
    assert board.remove_orphans() == [in_use]  # its writer is gone now
    pending = "cd" * 32  # stored by a submitter that has not recorded its submission yet
    with board.file_store.kept(good, pending, good.stat().st_size) as path:
        assert board.remove_orphans() == []
        assert path.read_bytes() == good.read_bytes()
    assert board.remove_orphans() == [path]  # never recorded: an orphan once let go


def test_submit_hashes_the_file_once(
    tmp_path: Path, bench: Path, good: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import dg16m_core.hashing
    import dg16m_env.subjects.submission_reader

    calls: list[str] = []
    real = dg16m_core.hashing.file_sha256

    def counted(path: Any) -> str:
        calls.append(str(path))
        return real(path)

    monkeypatch.setattr(dg16m_env.subjects.submission_reader, "file_sha256", counted)
    for module in ("leaderboard.board", "leaderboard.files"):
        monkeypatch.setattr(f"{module}.file_sha256", counted, raising=False)
    board = Board(tmp_path / "board.db", benchmark=bench, evaluators=("fce",))
    team, _ = board.add_team("lab-a")
    sid = board.submit(team, good)
    assert calls == [str(good)]
    stored = board.file_path(board.submission_row(sid)["file_sha256"])
    assert real(stored) == real(good)


# --------------------------------------------------------------------------------------------
# A worker that lost its lease
# --------------------------------------------------------------------------------------------


class SlowEvaluator:
    """Stands in for an evaluator that takes long: marks its start, sleeps (at most 20 s),
    then marks its end."""

    version = "1"

    def __init__(self, marks: Path):
        self.marks = marks

    def evaluate(self, path: Any) -> Any:
        (self.marks / "started").write_text("")
        for _ in range(200):
            time.sleep(0.1)
        (self.marks / "finished").write_text("")
        raise AssertionError("scored to the end after its lease was lost")


class Clock:
    def __init__(self, now: float = 1.8e9):
        self.now = now

    def __call__(self) -> float:
        return self.now


def test_worker_that_lost_its_lease_stops_scoring(
    tmp_path: Path, bench: Path, good: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import dg16m_env.evaluators

    marks = tmp_path / "marks"
    marks.mkdir()
    monkeypatch.setattr(
        dg16m_env.evaluators,
        "submission_evaluators",
        lambda names, ref, **kwargs: {"fce": SlowEvaluator(marks)},
    )
    clock = Clock()
    board = Board(tmp_path / "board.db", benchmark=bench, evaluators=("fce",), clock=clock)
    team, _ = board.add_team("lab-a")
    sid = board.submit(team, good)
    claim = board.claim("w1", 0.6)
    outcome: list[str] = []
    scorer = threading.Thread(
        target=lambda: outcome.append(score_claim(board, claim, WorkerOptions(lease_s=0.6)))
    )
    scorer.start()
    for _ in range(300):
        if (marks / "started").exists():
            break
        time.sleep(0.05)
    assert (marks / "started").exists()
    clock.now += 10  # w1's lease lapses (it was paused) and w2 takes the job
    thief = board.claim("w2", 60.0)
    assert thief is not None
    assert thief.submission_id == sid
    scorer.join(60)
    assert outcome == ["lost"]
    assert not (marks / "finished").exists()  # stopped mid-scoring, not at the end
    assert board.submission_row(sid)["worker"] == "w2"
    assert board.results(sid) == {}


def test_scoring_process_is_reused_and_ends_when_closed(
    tmp_path: Path, bench: Path, good: Path
) -> None:
    board = Board(tmp_path / "board.db", benchmark=bench, evaluators=("fce",))
    team, _ = board.add_team("lab-a")
    first = board.submit(team, good)
    second = board.submit(team, good, evaluators="fce,gsr", label="again")
    scorer = Scorer(board, WorkerOptions())
    pids = []
    for sid in (first, second):
        claim = board.claim("w", 60.0, submission_id=sid)
        assert score_claim(board, claim, WorkerOptions(), scorer) == "scored"
        pids.append(scorer._proc.pid if scorer._proc is not None else None)
    assert pids[0] == pids[1] is not None  # one process, job after job
    assert scorer.close() == 0  # it ended by itself when its pipe closed (not killed)
    assert scorer.close() is None


# --------------------------------------------------------------------------------------------
# A real server on loopback: stalled and oversized requests
# --------------------------------------------------------------------------------------------


@contextlib.contextmanager
def running(board: Board, config: ServiceConfig) -> Iterator[str]:
    """The service for ``board`` on loopback in a thread; yields its URL."""
    with running_service(board, config) as (url, _):
        yield url


def _address(url: str) -> tuple[str, int]:
    host, port = url.split("//", 1)[1].rstrip("/").rsplit(":", 1)
    return host, int(port)


def _read_all(sock: socket.socket, limit_s: float = 20.0) -> bytes:
    """Everything the server sends until it closes (bounded by ``limit_s``)."""
    sock.settimeout(limit_s)
    data = b""
    with contextlib.suppress(ConnectionResetError):
        while chunk := sock.recv(65536):
            data += chunk
    return data


def test_stalled_heads_are_closed_and_others_served(tmp_path: Path, bench: Path) -> None:
    board = Board(tmp_path / "board.db", benchmark=bench, evaluators=("fce",))
    with running(board, ServiceConfig(header_timeout_s=1.0)) as url:
        silent = socket.create_connection(_address(url))
        partial = socket.create_connection(_address(url))
        partial.sendall(b"GET /api/health HTTP/1.1\r\nHost: x\r\nX-Slow: ")
        stalled = [socket.create_connection(_address(url)) for _ in range(20)]
        assert httpx.get(f"{url}api/health", timeout=10).status_code == 200
        assert _read_all(silent) == b""  # closed by the server, not held
        answer = _read_all(partial)
        assert answer.startswith(b"HTTP/1.1 408 "), answer[:200]
        assert f"content-security-policy: {CSP}".encode() in answer
        assert b'"status": 408' in answer
        for sock in [silent, partial, *stalled]:
            sock.close()


def test_oversized_head_gets_431_not_a_reset(tmp_path: Path, bench: Path) -> None:
    board = Board(tmp_path / "board.db", benchmark=bench, evaluators=("fce",))
    with running(board, ServiceConfig()) as url:
        for path, kind in (("/api/health", b"application/json"), ("/", b"text/html")):
            answer = httpx.get(f"{url}{path.lstrip('/')}", headers={"X-Big": "a" * (1 << 20)})
            assert answer.status_code == 431
            assert answer.headers["content-security-policy"] == CSP
            assert answer.headers["content-type"].encode().startswith(kind)
            assert "expected a request line and headers of at most" in answer.text
        assert httpx.get(f"{url}api/health").status_code == 200


def test_stalled_upload_body_gets_408(tmp_path: Path, bench: Path) -> None:
    board = Board(tmp_path / "board.db", benchmark=bench, evaluators=("fce",))
    _, token = board.add_team("lab-a")
    with running(board, ServiceConfig(body_idle_timeout_s=0.5)) as url:
        sock = socket.create_connection(_address(url))
        sock.sendall(
            b"POST /api/submissions?filename=x.h5 HTTP/1.1\r\nHost: x\r\n"
            + f"Authorization: Bearer {token}\r\n".encode()
            + b"Content-Length: 5000\r\n\r\n"
            + b"\x89HDF" * 100
        )
        answer = _read_all(sock)
        sock.close()
    assert answer.startswith(b"HTTP/1.1 408 "), answer[:300]
    assert b"found 400 bytes and then nothing" in answer
    assert f"content-security-policy: {CSP}".encode() in answer
    assert tree(board.uploads) == {}


# --------------------------------------------------------------------------------------------
# The command: SIGTERM with a stalled upload, SIGKILL and restart
# --------------------------------------------------------------------------------------------


def _start(db: Path, *args: str) -> tuple[subprocess.Popen[str], str]:
    proc = subprocess.Popen(
        [*CLI, "serve", "--db", str(db), "--port", "0", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.append(proc.stdout.readline()), daemon=True)
    reader.start()
    reader.join(60)
    if not lines or not lines[0].startswith("serving "):
        proc.kill()
        raise AssertionError(f"no server: {lines} {proc.communicate()[0]!r}")
    return proc, lines[0].split(" on ", 1)[1].strip()


def _stalled_upload(url: str, token: str, good: Path) -> socket.socket:
    """An upload that sends half its body and then nothing (a live connection)."""
    data = good.read_bytes()
    sock = socket.create_connection(_address(url))
    sock.sendall(
        b"POST /api/submissions?filename=good.h5 HTTP/1.1\r\nHost: x\r\n"
        + f"Authorization: Bearer {token}\r\nContent-Length: {len(data)}\r\n\r\n".encode()
        + data[: len(data) // 2]
    )
    return sock


def _wait_for(predicate: Any, limit_s: float = 30.0) -> bool:
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.05)
    return False


def test_sigterm_with_a_stalled_upload_exits_and_kill_leaves_no_orphan(
    tmp_path: Path, bench: Path, good: Path
) -> None:
    db = tmp_path / "board.db"
    board = Board(db, benchmark=bench, evaluators=("fce",))
    _, token = board.add_team("lab-a")
    uploads = board.uploads

    proc, url = _start(db, "--shutdown-timeout", "2")
    sock = _stalled_upload(url, token, good)
    assert _wait_for(lambda: len(tree(uploads)) == 1)  # the body is streaming in
    proc.send_signal(signal.SIGTERM)
    try:
        code = proc.wait(30)  # bounded; the bench measures how long it takes
    except subprocess.TimeoutExpired:
        proc.kill()
        raise AssertionError("SIGTERM did not stop the server with a stalled upload") from None
    sock.close()
    assert code in (0, -signal.SIGTERM), proc.communicate()[0]  # uvicorn re-raises it
    assert tree(uploads) == {}  # abandoned, and its temporary file removed

    proc, url = _start(db)
    sock = _stalled_upload(url, token, good)
    assert _wait_for(lambda: len(tree(uploads)) == 1)
    proc.kill()
    proc.wait(30)
    sock.close()
    assert len(tree(uploads)) == 1  # what a killed server leaves
    proc, url = _start(db)
    try:
        assert tree(uploads) == {}  # removed when the next one started
        assert httpx.get(f"{url}api/health").status_code == 200
    finally:
        proc.terminate()
        proc.wait(30)
    assert Board(db, create=False).counts()["submissions"] == 0
