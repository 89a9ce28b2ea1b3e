"""The board's standings as JSON (``GET /api/board``), a page of rows at a time, one table
per track and evaluator (``?track=mesh|cloud``: one track only; tracks are never ranked
together), and the page query (``?page=N&limit=M&track=T``) the HTML board shares."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any
from urllib.parse import urlencode

from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import Response
from starlette.routing import Route

from ..query_checks import check_query, query_number
from ..tracks import check_track
from ..views import PAGE_ROWS, board_view
from .answers import answer, json_answer

if TYPE_CHECKING:
    from ..board import Board


def page_query(request: Request) -> tuple[int, int]:
    """The request's page number and size (``?page=N&limit=M``; defaults 1 and
    :data:`~leaderboard.views.PAGE_ROWS`; bounds are the view's). The query may also name one
    track (:func:`track_query`).

    Raises:
        InvalidParameterError: (422) another key, a repeated one, or not a number.
    """
    params = request.query_params
    check_query(params, {"page", "limit", "track"})
    return query_number(params, "page", 1), query_number(params, "limit", PAGE_ROWS)


def track_query(request: Request) -> str | None:
    """The one track the request asks for (``?track=mesh`` or ``?track=cloud``), or None for
    every track (each ranked apart: tracks are never mixed in one table).

    Raises:
        InvalidParameterError: (422) another name, or the key repeated.
    """
    params = request.query_params
    check_query(params, {"page", "limit", "track"})
    value = params.get("track")
    return None if value is None else check_track(value[:40])


def page_href(path: str, limit: int, track: str | None = None) -> Callable[[int], str]:
    """The link to page ``number`` of ``path`` with page size ``limit`` (left out when it is
    the default) and the one track shown (left out when every track is)."""

    def href(number: int) -> str:
        query: dict[str, Any] = {"page": number}
        if limit != PAGE_ROWS:
            query["limit"] = limit
        if track is not None:
            query["track"] = track
        return f"{path}?{urlencode(query)}"

    return href


class StandingsRoutes:
    """``GET /api/board``: the board view (public results, a page of rows per track and
    evaluator) with links to the previous and next pages."""

    def __init__(self, board: Board):
        self.board = board

    async def api_board(self, request: Request) -> Response:
        """The board view as JSON (built and encoded in a worker thread)."""
        page, limit = page_query(request)
        track = track_query(request)

        def build() -> Response:
            view = board_view(self.board, page=page, limit=limit, track=track)
            href = page_href("/api/board", limit, track)
            number, pages = view["page"]["number"], view["page"]["pages"]
            view["page"]["prev"] = href(number - 1) if number > 1 else None
            view["page"]["next"] = href(number + 1) if number < pages else None
            return json_answer(view)

        return await run_in_threadpool(build)

    def routes(self) -> list[Route]:
        """Its routes, each answering its refusals and board errors."""
        return [Route("/api/board", answer(self.api_board))]
