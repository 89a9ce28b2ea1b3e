"""The leaderboard service's routers one by one (no app): each handler called with its
dependencies, the one query checker, the refusal wrapper, the connection guard on a kept-alive
connection, and the old module paths (issue 53)."""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import json
import socket
import sys
from pathlib import Path
from typing import Any

import pytest
from leaderboard_data import running_service, small_benchmark
from starlette.datastructures import QueryParams
from starlette.requests import Request

from leaderboard.board import Board
from leaderboard.limits import RateLimiter, ServiceConfig
from leaderboard.query_checks import BoardError, InvalidParameterError, check_query, query_number
from leaderboard.routes import Refused, SiteRoutes, StatusRoutes, UploadRoutes, answer
from leaderboard.routes.standings import StandingsRoutes, page_query
from leaderboard.routes.uploads import upload_query


@pytest.fixture(scope="module")
def board(tmp_path_factory: pytest.TempPathFactory) -> Board:
    root = tmp_path_factory.mktemp("routes")
    bench = small_benchmark(root / "bench3.h5")
    board = Board(root / "board.db", benchmark=bench, evaluators=("fce",))
    board.add_team("lab-a")
    return board


def request(
    path: str, query: str = "", headers: dict[str, str] | None = None, **params: str
) -> Request:
    return Request(
        {
            "type": "http",
            "method": "GET",
            "path": path,
            "query_string": query.encode(),
            "headers": [(k.lower().encode(), v.encode()) for k, v in (headers or {}).items()],
            "path_params": params,
        }
    )


def run(handler: Any, *args: Any) -> Any:
    return asyncio.run(handler(*args))


def test_one_query_checker_for_pages_and_uploads() -> None:
    check_query(QueryParams("page=2&limit=5"), {"page", "limit"})
    with pytest.raises(InvalidParameterError, match=r"expected only \['limit', 'page'\]") as info:
        check_query(QueryParams("pages=2"), {"page", "limit"})
    assert info.value.status == 422
    with pytest.raises(InvalidParameterError, match="expected 'page' once"):
        check_query(QueryParams("page=1&page=2"), {"page", "limit"})
    many = "&".join(f"k{i:02d}=1" for i in range(12))
    with pytest.raises(InvalidParameterError) as info:
        check_query(QueryParams(many), set())
    assert "k09" in str(info.value)
    assert "k10" not in str(info.value)
    with pytest.raises(BoardError) as info:  # an upload's: 400, every key named, repeats taken
        check_query(QueryParams(many), {"label"}, error=BoardError, shown=None, once=False)
    assert info.value.status == 400
    assert "k11" in str(info.value)
    check_query(QueryParams("label=a&label=b"), {"label"}, error=BoardError, once=False)
    assert query_number(QueryParams(""), "page", 7) == 7
    assert query_number(QueryParams("page=12"), "page", 7) == 12
    for bad in ("-1", "x", "1e3", "9" * 20):
        with pytest.raises(InvalidParameterError, match="page: expected a positive integer"):
            query_number(QueryParams(f"page={bad}"), "page", 1)


def test_page_and_upload_queries() -> None:
    assert page_query(request("/api/board", "page=3&limit=20")) == (3, 20)
    assert page_query(request("/")) == (1, 50)
    with pytest.raises(InvalidParameterError):
        page_query(request("/", "other=1"))
    assert upload_query(request("/api/submissions", "filename=a.h5&label=x&evaluators=fce")) == (
        "a.h5",
        "x",
        "fce",
    )
    assert upload_query(request("/api/submissions")) == ("submission.h5", None, None)
    with pytest.raises(BoardError, match="file name: expected a plain name"):
        upload_query(request("/api/submissions", "filename=../x.h5"))


def test_status_and_standings_handlers_alone(board: Board) -> None:
    health = run(StatusRoutes(board).api_health, request("/api/health"))
    assert health.status_code == 200
    assert json.loads(health.body) == {"status": "ok", "counts": board.counts()}
    queue = run(StatusRoutes(board).api_queue, request("/api/queue"))
    assert set(json.loads(queue.body)) == {"generated_at", "counts"}
    with pytest.raises(Refused) as info:
        run(StatusRoutes(board).api_queue, request("/api/queue", headers={"Authorization": "x"}))
    assert info.value.status == 401
    view = json.loads(run(StandingsRoutes(board).api_board, request("/api/board")).body)
    assert view["page"]["prev"] is None
    assert view["page"]["number"] == 1


def test_site_and_upload_handlers_alone(board: Board) -> None:
    css = run(SiteRoutes(board).asset, request("/assets/board.css", name="board.css"))
    assert css.status_code == 200
    assert css.headers["content-type"].startswith("text/css")
    with pytest.raises(BoardError) as info:
        run(SiteRoutes(board).asset, request("/assets/x", name="board.db"))
    assert info.value.status == 404
    config = ServiceConfig(max_upload_bytes=1000, rate_limit=1)
    uploads = UploadRoutes(board, config, RateLimiter(board, config.rate_limit, 60.0))
    uploads.check_declared_size(None)
    uploads.check_declared_size("1000")
    for declared, status in (("1001", 413), ("abc", 400), ("-1", 400)):
        with pytest.raises(Refused) as refused:
            uploads.check_declared_size(declared)
        assert refused.value.status == status
    team = board.team("lab-a")
    uploads.admit(team)
    with pytest.raises(Refused) as refused:
        uploads.admit(team)
    assert refused.value.status == 429
    assert "Retry-After" in refused.value.extra["headers"]


def test_answer_turns_refusals_and_board_errors_into_error_answers() -> None:
    async def refuses(request: Request) -> Any:
        raise Refused(401, "expected a token, found none", headers={"X-A": "1"})

    async def fails(request: Request) -> Any:
        raise InvalidParameterError("page: expected 1, found 2")

    wrapped = run(answer(refuses), request("/api/x"))
    assert wrapped.status_code == 401
    assert wrapped.headers["www-authenticate"] == 'Bearer realm="dg16m"'
    assert wrapped.headers["x-a"] == "1"
    assert json.loads(wrapped.body) == {"error": "expected a token, found none", "status": 401}
    page = run(answer(fails), request("/"))
    assert page.status_code == 422
    assert page.headers["content-type"].startswith("text/html")
    assert run(answer(refuses), request("/api/x")).headers["x-a"] == "1"  # refusal unchanged


def _exchange(sock: socket.socket, data: bytes, answers: int) -> bytes:
    sock.sendall(data)
    received = b""
    while received.count(b"HTTP/1.1 ") < answers or not received.endswith(b"}"):
        chunk = sock.recv(65536)
        if not chunk:
            break
        received += chunk
    return received


def test_kept_alive_connection_serves_pipelined_requests_then_its_head_deadline(
    board: Board,
) -> None:
    with running_service(board, ServiceConfig(header_timeout_s=1.0)) as (_, address):
        sock = socket.create_connection(address, timeout=20)
        head = b"GET /api/health HTTP/1.1\r\nHost: x\r\n\r\n"
        first = _exchange(sock, head * 2, 2)
        assert first.count(b"HTTP/1.1 200 OK") == 2, first[:300]
        again = _exchange(sock, head, 1)  # the deadline restarted after each answer
        assert again.startswith(b"HTTP/1.1 200 OK")
        sock.sendall(b"GET /api/health HTTP/1.1\r\nHost: x\r\n")  # then a head that stalls
        rest = b""
        with contextlib.suppress(ConnectionResetError):
            while chunk := sock.recv(65536):
                rest += chunk
        sock.close()
    assert rest.startswith(b"HTTP/1.1 408 "), rest[:200]
    assert b"content-security-policy: " in rest


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("leaderboard.checks", "leaderboard.query_checks"),
        ("leaderboard.protocol", "leaderboard.connections"),
    ],
)
def test_old_module_paths_import_and_warn(old: str, new: str, tmp_path: Path) -> None:
    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match=f"{old} moved to {new}"):
        module = importlib.import_module(old)
    assert module is importlib.import_module(new)
    sys.modules.pop(old, None)
    if old == "leaderboard.checks":
        assert module.check_id("5") == 5
    else:
        assert module.error_body(400, "x", api=True)[1] == "application/json"
