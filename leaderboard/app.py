"""The leaderboard service: an ASGI app (Starlette) that teams submit to, served by uvicorn.

Routes (JSON answers carry ``{"error": message}`` on failure, with the HTTP status):

==========================================  ======  ========================================
``/``                                       GET     the board (HTML, a page of rows)
``/submissions/<id>``                       GET     a scored submission's details (HTML)
``/assets/<name>``                          GET     the page's CSS and script
``/api/board``                              GET     the board view (JSON, public results,
                                                    a page of rows)
``/api/queue``                              GET     submissions per status; with a team's
                                                    token, also its own jobs
``/api/health``                             GET     ``{"status": "ok", ...}``
``/api/submissions``                        POST    upload a submission file (team token)
``/api/submissions``                        GET     the team's submissions (team token)
``/api/submissions/<id>``                   GET     one of the team's submissions with its
                                                    error, scoring log and events
==========================================  ======  ========================================

The board (``/`` and ``/api/board``) comes a page at a time: ``?page=N&limit=M`` (page from
1, 1 <= M <= 500 rows per evaluator, default 50); the view says how many pages there are and
links the previous and next. Ids in paths are positive 64-bit integers; anything else is 404.
Every error is JSON (``/api/*``) or an HTML page (the rest), with the security headers
(:data:`SECURITY_HEADERS`), unhandled exceptions included (a 500 that names no internals;
the traceback goes to the server's log).

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

Slow clients cannot hold the service: a request's line and headers must arrive within
``header_timeout_s`` (:mod:`leaderboard.protocol`), an upload's body may pause at most
``body_idle_timeout_s`` between chunks and take at most ``upload_timeout_s`` in all (else
408), and on SIGTERM the server stops accepting, finishes what completes within
``shutdown_timeout_s`` and abandons the rest (their temporary files are removed; a killed
server's are removed when the next one starts).
"""

from __future__ import annotations

import re
import threading
import time
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

import anyio
from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import MutableHeaders, QueryParams
from starlette.middleware import Middleware
from starlette.requests import ClientDisconnect, Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from dg16m_env.subjects.submission import SubmissionInvalid

from .board import (
    Board,
    BoardError,
    DuplicateError,
    NotFoundError,
    Team,
    check_evaluators,
    check_file_name,
    check_id,
    check_label,
)
from .checks import InvalidParameterError
from .page import ASSETS, asset_text, render_index, render_submission
from .protocol import error_body, guarded_protocol
from .views import PAGE_ROWS, board_view, public_queue_view, submission_view

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
_NUMBER = re.compile(r"^[0-9]{1,19}$")


@dataclass(frozen=True)
class ServiceConfig:
    """Limits of the service.

    Attributes:
        max_upload_bytes: largest upload (bytes); also bounded by the board's file limit.
        rate_limit: uploads a team may make per ``rate_window_s`` (refused and failed ones
            count).
        rate_window_s: the rate limit's sliding window (s).
        header_timeout_s: time for a request's line and headers to arrive (s).
        max_header_bytes: largest request line and headers (bytes; more: 431).
        body_idle_timeout_s: longest pause between two chunks of an upload's body (s).
        upload_timeout_s: longest time to receive an upload's body (s).
        shutdown_timeout_s: on SIGTERM, time given to requests in flight before they are
            abandoned (s).
    """

    max_upload_bytes: int = 64 * MIB
    rate_limit: int = 10
    rate_window_s: float = 3600.0
    header_timeout_s: float = 10.0
    max_header_bytes: int = 32 * 1024
    body_idle_timeout_s: float = 30.0
    upload_timeout_s: float = 600.0
    shutdown_timeout_s: float = 5.0

    def __post_init__(self) -> None:
        if self.max_upload_bytes < 1 or self.rate_limit < 1 or not self.rate_window_s > 0:
            raise BoardError(
                "service: expected a positive upload limit, rate limit and window, found "
                f"{self.max_upload_bytes}, {self.rate_limit}, {self.rate_window_s}"
            )
        timeouts = (
            self.header_timeout_s,
            self.body_idle_timeout_s,
            self.upload_timeout_s,
            self.shutdown_timeout_s,
        )
        if not all(t > 0 for t in timeouts) or self.max_header_bytes < 1024:
            raise BoardError(
                "service: expected positive timeouts and a header limit of at least 1024 "
                f"bytes, found timeouts {timeouts} and {self.max_header_bytes} bytes"
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


def _is_api(path: str) -> bool:
    return path.startswith("/api/")


def error_response(
    path: str,
    status: int,
    message: str,
    headers: dict[str, str] | None = None,
    **extra: Any,
) -> Response:
    """An error answer: ``{"error", "status", ...}`` JSON for ``/api/*``, an HTML page for the
    rest; always with :data:`SECURITY_HEADERS` (the server's own 500 handler sits outside the
    middleware that adds them)."""
    headers = {**SECURITY_HEADERS, **(headers or {})}
    if _is_api(path):
        headers["Cache-Control"] = "no-store"
        return JSONResponse(
            {"error": message, "status": status, **extra}, status_code=status, headers=headers
        )
    body, content_type = error_body(status, message, api=False)
    return Response(body, status_code=status, headers=headers, media_type=content_type)


def _json(payload: Any) -> Response:
    """A JSON answer, encoded where it is called (call it in a worker thread for big ones)."""
    return JSONResponse(payload)


def _query(params: QueryParams, allowed: set[str]) -> None:
    unknown = sorted(set(params) - allowed)
    if unknown:
        raise InvalidParameterError(
            f"query: expected only {sorted(allowed)}, found {[k[:40] for k in unknown[:10]]}"
        )
    for key in allowed:
        if len(params.getlist(key)) > 1:
            raise InvalidParameterError(f"query: expected {key!r} once, found it repeated")


def _number(params: QueryParams, key: str, default: int) -> int:
    value = params.get(key)
    if value is None:
        return default
    if not _NUMBER.match(value):
        raise InvalidParameterError(
            f"{key}: expected a positive integer, found {value[:40]!r}"
            + ("..." if len(value) > 40 else "")
        )
    return int(value)


def create_app(board: Board, config: ServiceConfig = ServiceConfig()) -> Starlette:
    """The service's ASGI app for ``board``. Files that killed processes left in the board's
    uploads folder and file store are removed first (:meth:`Board.remove_orphans`)."""
    board.remove_orphans()
    limiter = RateLimiter(board, config.rate_limit, config.rate_window_s)
    max_bytes = min(config.max_upload_bytes, board.limits.max_file_bytes)

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

    def board_page(request: Request) -> tuple[int, int]:
        params = request.query_params
        _query(params, {"page", "limit"})
        return _number(params, "page", 1), _number(params, "limit", PAGE_ROWS)

    def page_href(path: str, limit: int) -> Callable[[int], str]:
        def href(number: int) -> str:
            query = {"page": number} if limit == PAGE_ROWS else {"page": number, "limit": limit}
            return f"{path}?{urlencode(query)}"

        return href

    async def index(request: Request) -> Response:
        page, limit = board_page(request)

        def render() -> Response:
            view = board_view(board, page=page, limit=limit)
            text = render_index(
                view,
                link=lambda i: f"/submissions/{i}",
                assets="/assets/",
                page_link=page_href("/", limit),
            )
            return Response(text, media_type="text/html; charset=utf-8")

        return await run_in_threadpool(render)

    async def submission_page(request: Request) -> Response:
        sid = check_id(request.path_params["sid"])

        def render() -> Response:
            view = submission_view(board, sid)
            text = render_submission(view, board_link="/", assets="/assets/")
            return Response(text, media_type="text/html; charset=utf-8")

        return await run_in_threadpool(render)

    async def asset(request: Request) -> Response:
        name = request.path_params["name"]
        if name not in ASSETS:
            raise NotFoundError(f"asset: expected one of {', '.join(ASSETS)}, found {name[:100]!r}")
        return Response(asset_text(name), media_type=ASSET_TYPES[Path(name).suffix])

    async def api_board(request: Request) -> Response:
        page, limit = board_page(request)

        def build() -> Response:
            view = board_view(board, page=page, limit=limit)
            href = page_href("/api/board", limit)
            number, pages = view["page"]["number"], view["page"]["pages"]
            view["page"]["prev"] = href(number - 1) if number > 1 else None
            view["page"]["next"] = href(number + 1) if number < pages else None
            return _json(view)

        return await run_in_threadpool(build)

    async def api_queue(request: Request) -> Response:
        _query(request.query_params, set())
        team = None
        if request.headers.get("authorization"):
            team = await run_in_threadpool(team_of, request)
        return await run_in_threadpool(lambda: _json(public_queue_view(board, team)))

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
        sid = check_id(request.path_params["sid"])
        team = await run_in_threadpool(team_of, request)
        await run_in_threadpool(board.own_submission, team, sid)  # 404 / 403
        return await run_in_threadpool(lambda: _json(submission_view(board, sid, private=True)))

    async def read_body(request: Request, handle: Any) -> int:
        """Stream the body into ``handle``; its size. Refused past the size limit (413), when
        it stalls or takes too long (408), or when the client goes (400)."""
        deadline = time.monotonic() + config.upload_timeout_s
        chunks = request.stream().__aiter__()
        size = 0
        while True:
            wait = min(config.body_idle_timeout_s, deadline - time.monotonic())
            chunk: bytes | None = None
            with anyio.move_on_after(max(wait, 0.0)):
                try:
                    chunk = await chunks.__anext__()
                except StopAsyncIteration:
                    return size
                except ClientDisconnect:
                    raise _Refused(
                        400, "upload: expected the whole body, found the client gone"
                    ) from None
            if chunk is None:
                whole = time.monotonic() >= deadline
                limit = (
                    f"the whole body within {config.upload_timeout_s:g} s"
                    if whole
                    else f"a part of the body at least every {config.body_idle_timeout_s:g} s"
                )
                raise _Refused(
                    408,
                    f"upload: expected {limit}, found {size} bytes and then nothing",
                    headers={"Connection": "close"},
                )
            size += len(chunk)
            if size > max_bytes:
                raise _Refused(
                    413,
                    f"upload: expected at most {max_bytes} bytes, found more (stopped reading)",
                    headers={"Connection": "close"},
                )
            handle.write(chunk)

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
            raise _Refused(
                400, f"query: expected only {sorted(allowed)}, found {[k[:40] for k in unknown]}"
            )
        filename = check_file_name(params.get("filename", "submission.h5"))
        label = params.get("label") or None
        if label is not None:
            label = check_label(label)
        evaluators = params.get("evaluators") or None
        if evaluators is not None:
            evaluators = ",".join(check_evaluators(evaluators))
        declared = request.headers.get("content-length")
        if declared is not None:
            if not _NUMBER.match(declared):
                raise _Refused(400, f"Content-Length: expected a number, found {declared[:40]!r}")
            if int(declared) > max_bytes:
                raise _Refused(
                    413,
                    f"upload: expected at most {max_bytes} bytes, found Content-Length "
                    f"{declared} (not read)",
                )
        with board.file_store.upload() as (handle, tmp):
            size = await read_body(request, handle)
            handle.flush()
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
            path = request.url.path
            try:
                response = await handler(request)
            except _Refused as exc:
                headers = exc.extra.pop("headers", None)
                if exc.status == 401:
                    headers = {**(headers or {}), "WWW-Authenticate": 'Bearer realm="dg16m"'}
                response = error_response(path, exc.status, exc.message, headers, **exc.extra)
            except BoardError as exc:
                response = error_response(path, exc.status, str(exc))
            return response

        return wrapped

    routes = [
        Route("/", answer(index)),
        Route("/submissions/{sid}", answer(submission_page)),
        Route("/assets/{name}", answer(asset)),
        Route("/api/board", answer(api_board)),
        Route("/api/queue", answer(api_queue)),
        Route("/api/health", answer(api_health)),
        Route("/api/submissions", answer(upload), methods=["POST"]),
        Route("/api/submissions", answer(own_list), methods=["GET"]),
        Route("/api/submissions/{sid}", answer(own_detail)),
    ]

    async def no_route(request: Request, exc: Exception) -> Response:
        status = getattr(exc, "status_code", 404)
        return error_response(
            request.url.path,
            status,
            f"{request.method[:20]} {request.url.path[:200]}: expected one of the service's "
            "routes and methods (see leaderboard.app), found none that matches",
        )

    async def internal_error(request: Request, exc: Exception) -> Response:
        # Starlette re-raises the exception after this answer: the server logs its traceback.
        return error_response(
            request.url.path,
            500,
            "service: expected to answer this request, found an internal error (it is in the "
            "server's log; please report it)",
        )

    return Starlette(
        routes=routes,
        middleware=[Middleware(SecurityHeaders)],
        exception_handlers={404: no_route, 405: no_route, Exception: internal_error},
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
                if _is_api(scope["path"]):
                    headers["Cache-Control"] = "no-store"
            await send(message)

        await self.app(scope, receive, send_with_headers)


def make_server(
    board: Board,
    *,
    host: str = "127.0.0.1",
    port: int = 8000,
    config: ServiceConfig = ServiceConfig(),
    log_level: str = "warning",
) -> tuple[Any, Any, str]:
    """A uvicorn server for the board, its listening socket and its URL (port 0 picks a free
    port); run it with ``server.run(sockets=[sock])`` (:func:`serve` does).

    uvicorn runs its h11 protocol with the head deadline, the header size limit (431) and the
    lingering close of :mod:`leaderboard.protocol`; on SIGTERM, requests still in flight after
    ``config.shutdown_timeout_s`` are cancelled (an upload's temporary file is removed).

    Raises:
        BoardError: the address is taken or cannot be bound.
    """
    import math
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
            http=guarded_protocol(
                header_timeout_s=config.header_timeout_s,
                body_grace_s=0.8 * config.shutdown_timeout_s,
                security_headers=SECURITY_HEADERS,
            ),
            log_level=log_level,
            timeout_keep_alive=5,
            timeout_graceful_shutdown=max(1, math.ceil(config.shutdown_timeout_s)),
            h11_max_incomplete_event_size=config.max_header_bytes,
            server_header=False,
        )
    )
    sock.listen(1024)  # connections wait in the backlog until uvicorn accepts them
    url = f"http://{host if family == socket.AF_INET else f'[{host}]'}:{bound}/"
    return server, sock, url


def serve(
    board: Board,
    *,
    host: str = "127.0.0.1",
    port: int = 8000,
    config: ServiceConfig = ServiceConfig(),
    log_level: str = "warning",
    ready: Callable[[str], None] = print,
) -> None:
    """Serve the board with uvicorn (:func:`make_server`) until SIGTERM or SIGINT; ``ready``
    gets the URL once listening."""
    server, sock, url = make_server(board, host=host, port=port, config=config, log_level=log_level)
    ready(url)
    server.run(sockets=[sock])
