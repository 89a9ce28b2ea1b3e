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
``header_timeout_s`` (:mod:`leaderboard.connections`), an upload's body may pause at most
``body_idle_timeout_s`` between chunks and take at most ``upload_timeout_s`` in all (else
408), and on SIGTERM the server stops accepting, finishes what completes within
``shutdown_timeout_s`` and abandons the rest (their temporary files are removed; a killed
server's are removed when the next one starts).

The routes are handlers of a router per resource (:mod:`leaderboard.routes`); this module
wires them (:func:`create_app`) and runs them under uvicorn (:func:`make_server`,
:func:`serve`). The limits are :class:`~leaderboard.limits.ServiceConfig`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from starlette.applications import Starlette
from starlette.middleware import Middleware

from .board import Board, BoardError
from .connections import guarded_connection
from .http_errors import SECURITY_HEADERS
from .limits import MIB, RateLimiter, ServiceConfig
from .routes import (
    SecurityHeaders,
    SiteRoutes,
    StandingsRoutes,
    StatusRoutes,
    UploadRoutes,
    error_response,
)
from .routes.answers import internal_error, no_route
from .routes.site import ASSET_TYPES

__all__ = [
    "ASSET_TYPES",
    "MIB",
    "SECURITY_HEADERS",
    "RateLimiter",
    "SecurityHeaders",
    "ServiceConfig",
    "create_app",
    "error_response",
    "make_server",
    "serve",
]

DEFAULT_CONFIG = ServiceConfig()
"""The service's default limits."""


def create_app(board: Board, config: ServiceConfig = DEFAULT_CONFIG) -> Starlette:
    """The service's ASGI app for ``board``: the routers of :mod:`leaderboard.routes`, the
    security headers on every answer, JSON or HTML errors. Files that killed processes left in
    the board's uploads folder and file store are removed first (:meth:`Board.remove_orphans`)."""
    board.remove_orphans()
    limiter = RateLimiter(board, config.rate_limit, config.rate_window_s)
    routes = [
        *SiteRoutes(board).routes(),
        *StandingsRoutes(board).routes(),
        *StatusRoutes(board).routes(),
        *UploadRoutes(board, config, limiter).routes(),
    ]
    return Starlette(
        routes=routes,
        middleware=[Middleware(SecurityHeaders)],
        exception_handlers={404: no_route, 405: no_route, Exception: internal_error},
    )


def make_server(
    board: Board,
    *,
    host: str = "127.0.0.1",
    port: int = 8000,
    config: ServiceConfig = DEFAULT_CONFIG,
    log_level: str = "warning",
) -> tuple[Any, Any, str]:
    """A uvicorn server for the board, its listening socket and its URL (port 0 picks a free
    port); run it with ``server.run(sockets=[sock])`` (:func:`serve` does).

    uvicorn runs its h11 protocol behind the head deadline, the header size limit (431) and
    the lingering close of :mod:`leaderboard.connections`; on SIGTERM, requests still in
    flight after ``config.shutdown_timeout_s`` are cancelled (uvicorn's
    ``timeout_graceful_shutdown``; an upload's temporary file is removed).

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
            http=guarded_connection(
                header_timeout_s=config.header_timeout_s,
                max_head_bytes=config.max_header_bytes,
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
    config: ServiceConfig = DEFAULT_CONFIG,
    log_level: str = "warning",
    ready: Callable[[str], None] = print,
) -> None:
    """Serve the board with uvicorn (:func:`make_server`) until SIGTERM or SIGINT; ``ready``
    gets the URL once listening."""
    server, sock, url = make_server(board, host=host, port=port, config=config, log_level=log_level)
    ready(url)
    server.run(sockets=[sock])
