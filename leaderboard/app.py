"""The leaderboard service: an ASGI app (Starlette) that teams submit to, served by uvicorn.

Routes (JSON answers carry ``{"error": message}`` on failure, with the HTTP status):

==========================================  ======  ========================================
``/``                                       GET     the board (HTML)
``/submissions/<id>``                       GET     a scored submission's details (HTML)
``/assets/<name>``                          GET     the page's CSS and script
``/api/board``                              GET     the board view (JSON, public results)
``/api/queue``                              GET     queued and running jobs, stale leases
``/api/health``                             GET     ``{"status": "ok", ...}``
``/api/submissions``                        POST    upload a submission file (team token)
``/api/submissions``                        GET     the team's submissions (team token)
``/api/submissions/<id>``                   GET     one of the team's submissions with its
                                                    error, scoring log and events
==========================================  ======  ========================================

A team authenticates with ``Authorization: Bearer <token>``. An upload is the file's bytes as
the request body (``Content-Type: application/octet-stream``) with the query parameters
``filename`` (a plain file name), ``label`` and ``evaluators`` (comma-separated), e.g.::

    curl -H "Authorization: Bearer $TOKEN" --data-binary @mine.h5 \\
        "http://127.0.0.1:8000/api/submissions?filename=mine.h5&evaluators=fce,gsr"

Checks, in order, each answered without touching the database: the token (401), the team's
rate limit (429 with ``Retry-After``; every upload that passes it counts, refused or not), the
query parameters (400), the size (413: a declared ``Content-Length`` over the limit is refused
before reading, and the body is counted while it streams to a temporary file), the file's
validation against the board's benchmark (422 with every problem), a repeat of an earlier
submission (409). An accepted upload is stored by content hash and queued (202); workers score
it (``dg16m leaderboard worker``). The service never runs submitted code.
"""

from __future__ import annotations

import os
import tempfile
import threading
import time
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import MutableHeaders
from starlette.middleware import Middleware
from starlette.requests import ClientDisconnect, Request
from starlette.responses import HTMLResponse, JSONResponse, Response
from starlette.routing import Route
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from dg16m_env.submission import SubmissionInvalid

from .board import (
    Board,
    BoardError,
    DuplicateError,
    NotFoundError,
    Team,
    check_evaluators,
    check_file_name,
    check_label,
)
from .page import ASSETS, asset_text, render_index, render_submission
from .views import board_view, queue_view, submission_view

MIB = 1 << 20
SECURITY_HEADERS = {
    "Content-Security-Policy": (
        "default-src 'none'; style-src 'self'; script-src 'self'; img-src 'self' data:; "
        "base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
    ),
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
}
ASSET_TYPES = {".css": "text/css; charset=utf-8", ".js": "text/javascript; charset=utf-8"}


@dataclass(frozen=True)
class ServiceConfig:
    """Limits of the service.

    Attributes:
        max_upload_bytes: largest upload (bytes); also bounded by the board's file limit.
        rate_limit: uploads a team may make per ``rate_window_s`` (refused and failed ones
            count).
        rate_window_s: the rate limit's sliding window (s).
    """

    max_upload_bytes: int = 64 * MIB
    rate_limit: int = 10
    rate_window_s: float = 3600.0

    def __post_init__(self) -> None:
        if self.max_upload_bytes < 1 or self.rate_limit < 1 or not self.rate_window_s > 0:
            raise BoardError(
                "service: expected a positive upload limit, rate limit and window, found "
                f"{self.max_upload_bytes}, {self.rate_limit}, {self.rate_window_s}"
            )


class RateLimiter:
    """Per-team sliding-window counter of uploads (thread-safe).

    A team's window starts from its submissions stored in the board (so a restart forgets only
    refused uploads), then counts every upload that passed the limiter in this process.
    """

    def __init__(self, board: Board, limit: int, window_s: float):
        self.board, self.limit, self.window_s = board, limit, window_s
        self._times: dict[int, deque[float]] = {}
        self._lock = threading.Lock()

    def admit(self, team: Team) -> float | None:
        """Count an upload; None when admitted, else seconds until the next is allowed."""
        now = time.time()
        with self._lock:
            times = self._times.get(team.id)
            if times is None:
                times = deque(self.board.submission_times(team, now - self.window_s))
                self._times[team.id] = times
            while times and times[0] <= now - self.window_s:
                times.popleft()
            if len(times) >= self.limit:
                return max(1.0, times[0] + self.window_s - now)
            times.append(now)
            return None


class _Refused(Exception):  # noqa: N818  (internal: an answer, not an error)
    def __init__(self, status: int, message: str, **extra: Any):
        super().__init__(message)
        self.status, self.message, self.extra = status, message, extra


def _error(status: int, message: str, headers: dict[str, str] | None = None, **extra: Any):
    return JSONResponse(
        {"error": message, "status": status, **extra}, status_code=status, headers=headers
    )


def create_app(board: Board, config: ServiceConfig = ServiceConfig()) -> Starlette:
    """The service's ASGI app for ``board``."""
    limiter = RateLimiter(board, config.rate_limit, config.rate_window_s)
    max_bytes = min(config.max_upload_bytes, board.limits.max_file_bytes)
    uploads = board.db.parent / f"{board.db.stem}.uploads"

    def team_of(request: Request) -> Team:
        header = request.headers.get("authorization")
        if not header:
            raise _Refused(
                401, "expected an 'Authorization: Bearer <team token>' header, found none"
            )
        scheme, _, token = header.partition(" ")
        if scheme.lower() != "bearer" or not token.strip():
            raise _Refused(
                401, "expected 'Authorization: Bearer <team token>', found another scheme"
            )
        team = board.authenticate(token.strip())
        if team is None:
            raise _Refused(401, "expected a team's token, found one that belongs to no team")
        return team

    async def index(request: Request) -> Response:
        view = await run_in_threadpool(board_view, board)
        return HTMLResponse(
            render_index(view, link=lambda i: f"/submissions/{i}", assets="/assets/")
        )

    async def submission_page(request: Request) -> Response:
        sid = request.path_params["sid"]
        try:
            view = await run_in_threadpool(submission_view, board, sid)
        except NotFoundError as exc:
            return HTMLResponse(_not_found_page(str(exc)), status_code=404)
        return HTMLResponse(render_submission(view, board_link="/", assets="/assets/"))

    async def asset(request: Request) -> Response:
        name = request.path_params["name"]
        if name not in ASSETS:
            return _error(404, f"asset: expected one of {', '.join(ASSETS)}, found {name[:100]!r}")
        return Response(asset_text(name), media_type=ASSET_TYPES[Path(name).suffix])

    async def api_board(request: Request) -> Response:
        return JSONResponse(await run_in_threadpool(board_view, board))

    async def api_queue(request: Request) -> Response:
        return JSONResponse(await run_in_threadpool(queue_view, board))

    async def api_health(request: Request) -> Response:
        return JSONResponse({"status": "ok", "counts": await run_in_threadpool(board.counts)})

    async def own_list(request: Request) -> Response:
        team = await run_in_threadpool(team_of, request)
        rows = await run_in_threadpool(board.submissions, team)
        return JSONResponse(
            {
                "team": team.name,
                "submissions": [
                    {"id": r["id"], "label": r["label"], "status": r["status"], "error": r["error"]}
                    for r in rows
                ],
            }
        )

    async def own_detail(request: Request) -> Response:
        team = await run_in_threadpool(team_of, request)
        sid = request.path_params["sid"]
        await run_in_threadpool(board.own_submission, team, sid)  # 404 / 403
        return JSONResponse(await run_in_threadpool(submission_view, board, sid, private=True))

    async def upload(request: Request) -> Response:
        team = await run_in_threadpool(team_of, request)
        retry = limiter.admit(team)
        if retry is not None:
            raise _Refused(
                429,
                f"expected at most {config.rate_limit} uploads per {config.rate_window_s:g} s "
                f"for team {team.name!r}, found the limit reached (failed uploads count too)",
                headers={"Retry-After": str(int(retry + 0.999))},
            )
        params = request.query_params
        allowed = {"filename", "label", "evaluators"}
        unknown = sorted(set(params) - allowed)
        if unknown:
            raise _Refused(400, f"query: expected only {sorted(allowed)}, found {unknown}")
        filename = check_file_name(params.get("filename", "submission.h5"))
        label = params.get("label") or None
        if label is not None:
            label = check_label(label)
        evaluators = params.get("evaluators") or None
        if evaluators is not None:
            evaluators = ",".join(check_evaluators(evaluators))
        declared = request.headers.get("content-length")
        if declared is not None:
            if not declared.isdigit():
                raise _Refused(400, f"Content-Length: expected a number, found {declared[:40]!r}")
            if int(declared) > max_bytes:
                raise _Refused(
                    413,
                    f"upload: expected at most {max_bytes} bytes, found Content-Length "
                    f"{declared} (not read)",
                )
        uploads.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix="upload-", suffix=".h5", dir=uploads)
        tmp = Path(tmp_name)
        try:
            size = 0
            with os.fdopen(fd, "wb") as handle:
                try:
                    async for chunk in request.stream():
                        size += len(chunk)
                        if size > max_bytes:
                            raise _Refused(
                                413,
                                f"upload: expected at most {max_bytes} bytes, found more "
                                "(stopped reading)",
                            )
                        handle.write(chunk)
                except ClientDisconnect:
                    raise _Refused(
                        400, "upload: expected the whole body, found the client gone"
                    ) from None
            if size == 0:
                raise _Refused(400, "upload: expected the submission file as the body, found none")
            try:
                sid = await run_in_threadpool(
                    board.submit,
                    team,
                    tmp,
                    filename=filename,
                    label=label,
                    evaluators=evaluators,
                )
            except SubmissionInvalid as exc:
                raise _Refused(
                    422,
                    f"expected a valid submission file, found {len(exc.problems)} problem(s)",
                    problems=[{"place": p.place, "message": p.message} for p in exc.problems],
                ) from None
            except DuplicateError as exc:
                raise _Refused(409, str(exc), submission=exc.submission_id) from None
        finally:
            tmp.unlink(missing_ok=True)
        return JSONResponse(
            {
                "submission": sid,
                "status": "queued",
                "status_url": f"/api/submissions/{sid}",
                "page": f"/submissions/{sid}",
            },
            status_code=202,
        )

    def answer(
        handler: Callable[[Request], Awaitable[Response]],
    ) -> Callable[[Request], Awaitable[Response]]:
        async def wrapped(request: Request) -> Response:
            try:
                response = await handler(request)
            except _Refused as exc:
                headers = exc.extra.pop("headers", None)
                if exc.status == 401:
                    headers = {**(headers or {}), "WWW-Authenticate": 'Bearer realm="dg16m"'}
                response = _error(exc.status, exc.message, headers, **exc.extra)
            except BoardError as exc:
                response = _error(exc.status, str(exc))
            return response

        return wrapped

    routes = [
        Route("/", answer(index)),
        Route("/submissions/{sid:int}", answer(submission_page)),
        Route("/assets/{name}", answer(asset)),
        Route("/api/board", answer(api_board)),
        Route("/api/queue", answer(api_queue)),
        Route("/api/health", answer(api_health)),
        Route("/api/submissions", answer(upload), methods=["POST"]),
        Route("/api/submissions", answer(own_list), methods=["GET"]),
        Route("/api/submissions/{sid:int}", answer(own_detail)),
    ]

    async def no_route(request: Request, exc: Exception) -> Response:
        status = getattr(exc, "status_code", 404)
        return _error(
            status,
            f"{request.method} {request.url.path[:200]}: expected one of the service's routes "
            "(see leaderboard.app), found none that matches",
        )

    return Starlette(
        routes=routes,
        middleware=[Middleware(SecurityHeaders)],
        exception_handlers={404: no_route, 405: no_route},
    )


class SecurityHeaders:
    """ASGI middleware: :data:`SECURITY_HEADERS` on every answer (errors included), and
    ``Cache-Control: no-store`` on the JSON API."""

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = MutableHeaders(scope=message)
                for name, value in SECURITY_HEADERS.items():
                    headers[name] = value
                if scope["path"].startswith("/api/"):
                    headers["Cache-Control"] = "no-store"
            await send(message)

        await self.app(scope, receive, send_with_headers)


def _not_found_page(message: str) -> str:
    from html import escape

    return (
        "<!doctype html><html lang='en'><head><meta charset='utf-8'><title>Not found</title>"
        "<link rel='stylesheet' href='/assets/board.css'></head><body><main>"
        f"<h1>Not found</h1><p>{escape(message)}</p><p><a href='/'>Back to the board</a></p>"
        "</main></body></html>"
    )


def serve(
    board: Board,
    *,
    host: str = "127.0.0.1",
    port: int = 8000,
    config: ServiceConfig = ServiceConfig(),
    log_level: str = "warning",
    ready: Callable[[str], None] = print,
) -> None:
    """Serve the board with uvicorn until interrupted; ``ready`` gets the URL once listening
    (port 0 picks a free port, and the URL says which)."""
    import socket

    import uvicorn

    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise BoardError(
            f"--host/--port: expected a free address, found {host}:{port} ({exc.strerror})"
        ) from None
    bound = sock.getsockname()[1]
    server = uvicorn.Server(
        uvicorn.Config(
            create_app(board, config),
            log_level=log_level,
            timeout_keep_alive=5,
            server_header=False,
        )
    )
    sock.listen(128)  # connections wait in the backlog until uvicorn accepts them
    url = f"http://{host if family == socket.AF_INET else f'[{host}]'}:{bound}/"
    ready(url)
    server.run(sockets=[sock])
