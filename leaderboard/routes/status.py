"""The service's state: the queue (``GET /api/queue``: counts per status; with a team's
token, also its own jobs) and its health (``GET /api/health``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route

from ..query_checks import check_query
from ..views import public_queue_view
from .answers import answer, json_answer, team_of

if TYPE_CHECKING:
    from ..board import Board


class StatusRoutes:
    """The public queue and the health check."""

    def __init__(self, board: Board):
        self.board = board

    async def api_queue(self, request: Request) -> Response:
        """Submissions per status; with a team's token, also the team's own jobs."""
        check_query(request.query_params, set())
        team = None
        if request.headers.get("authorization"):
            team = await run_in_threadpool(team_of, self.board, request)
        return await run_in_threadpool(lambda: json_answer(public_queue_view(self.board, team)))

    async def api_health(self, request: Request) -> Response:
        """``{"status": "ok", "counts": ...}``."""
        counts = await run_in_threadpool(self.board.counts)
        return JSONResponse({"status": "ok", "counts": counts})

    def routes(self) -> list[Route]:
        """Its routes, each answering its refusals and board errors."""
        return [
            Route("/api/queue", answer(self.api_queue)),
            Route("/api/health", answer(self.api_health)),
        ]
