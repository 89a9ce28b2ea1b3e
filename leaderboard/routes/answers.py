"""What every route shares: refusals (:class:`Refused`), error answers with the security
headers (:func:`error_response`), the wrapper that turns a handler's refusals and board errors
into answers (:func:`answer`), the team of a request's token (:func:`team_of`), the handlers
of unknown routes and unhandled errors, and the middleware that adds the security headers to
every answer (:class:`SecurityHeaders`).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any

from starlette.datastructures import MutableHeaders
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from ..http_errors import SECURITY_HEADERS, error_body, is_api
from ..query_checks import BoardError

if TYPE_CHECKING:
    from ..board import Board, Team

Handler = Callable[[Request], Awaitable[Response]]
"""A route's endpoint: a request in, an answer out."""


class Refused(Exception):  # noqa: N818  (an answer, not an error)
    """A request a handler answers with an error: its status, message, extra headers
    (``headers=``) and extra JSON fields."""

    def __init__(self, status: int, message: str, **extra: Any):
        super().__init__(message)
        self.status, self.message, self.extra = status, message, extra


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
    if is_api(path):
        headers["Cache-Control"] = "no-store"
        return JSONResponse(
            {"error": message, "status": status, **extra}, status_code=status, headers=headers
        )
    body, content_type = error_body(status, message, api=False)
    return Response(body, status_code=status, headers=headers, media_type=content_type)


def json_answer(payload: Any) -> Response:
    """A JSON answer, encoded where it is called (call it in a worker thread for big ones)."""
    return JSONResponse(payload)


def answer(handler: Handler) -> Handler:
    """``handler`` with its :class:`Refused` and :class:`~leaderboard.query_checks.BoardError`
    answered as errors (401s with ``WWW-Authenticate``)."""

    async def wrapped(request: Request) -> Response:
        path = request.url.path
        try:
            response = await handler(request)
        except Refused as exc:
            extra = dict(exc.extra)
            headers = extra.pop("headers", None)
            if exc.status == 401:
                headers = {**(headers or {}), "WWW-Authenticate": 'Bearer realm="dg16m"'}
            response = error_response(path, exc.status, exc.message, headers, **extra)
        except BoardError as exc:
            response = error_response(path, exc.status, str(exc))
        return response

    return wrapped


def team_of(board: Board, request: Request) -> Team:
    """The team whose token the request carries (``Authorization: Bearer <token>``).

    Raises:
        Refused: (401) no header, another scheme, or a token of no team.
    """
    header = request.headers.get("authorization")
    if not header:
        raise Refused(401, "expected an 'Authorization: Bearer <team token>' header, found none")
    scheme, _, token = header.partition(" ")
    if scheme.lower() != "bearer" or not token.strip():
        raise Refused(401, "expected 'Authorization: Bearer <team token>', found another scheme")
    team = board.authenticate(token.strip())
    if team is None:
        raise Refused(401, "expected a team's token, found one that belongs to no team")
    return team


async def no_route(request: Request, exc: Exception) -> Response:
    """The answer to a path no route has (404) or a method it does not take (405)."""
    status = getattr(exc, "status_code", 404)
    return error_response(
        request.url.path,
        status,
        f"{request.method[:20]} {request.url.path[:200]}: expected one of the service's "
        "routes and methods (see leaderboard.app), found none that matches",
    )


async def internal_error(request: Request, exc: Exception) -> Response:
    """A 500 that names no internals (Starlette re-raises the exception after this answer: the
    server logs its traceback)."""
    return error_response(
        request.url.path,
        500,
        "service: expected to answer this request, found an internal error (it is in the "
        "server's log; please report it)",
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
                if is_api(scope["path"]):
                    headers["Cache-Control"] = "no-store"
            await send(message)

        await self.app(scope, receive, send_with_headers)
