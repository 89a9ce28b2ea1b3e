"""The HTML site: the board (``GET /``, a page of rows), a submission's page
(``GET /submissions/<id>``) and the page's CSS and script (``GET /assets/<name>``)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import Response
from starlette.routing import Route

from ..page import ASSETS, asset_text, render_index, render_submission
from ..query_checks import NotFoundError, check_id
from ..views import board_view, submission_view
from .answers import answer
from .standings import page_href, page_query, track_query

if TYPE_CHECKING:
    from ..board import Board

ASSET_TYPES = {".css": "text/css; charset=utf-8", ".js": "text/javascript; charset=utf-8"}
"""Content types of the page's assets, by suffix."""


class SiteRoutes:
    """The HTML pages and their assets; pages are rendered in a worker thread."""

    def __init__(self, board: Board):
        self.board = board

    async def index(self, request: Request) -> Response:
        """The board (HTML), a page of rows."""
        page, limit = page_query(request)
        track = track_query(request)

        def render() -> Response:
            view = board_view(self.board, page=page, limit=limit, track=track)
            text = render_index(
                view,
                link=lambda i: f"/submissions/{i}",
                assets="/assets/",
                page_link=page_href("/", limit, track),
            )
            return Response(text, media_type="text/html; charset=utf-8")

        return await run_in_threadpool(render)

    async def submission_page(self, request: Request) -> Response:
        """A scored submission's details (HTML)."""
        sid = check_id(request.path_params["sid"])

        def render() -> Response:
            view = submission_view(self.board, sid)
            text = render_submission(view, board_link="/", assets="/assets/")
            return Response(text, media_type="text/html; charset=utf-8")

        return await run_in_threadpool(render)

    async def asset(self, request: Request) -> Response:
        """The page's CSS or script."""
        return asset_answer(request.path_params["name"])

    def routes(self) -> list[Route]:
        """Its routes, each answering its refusals and board errors."""
        return [
            Route("/", answer(self.index)),
            Route("/submissions/{sid}", answer(self.submission_page)),
            Route("/assets/{name}", answer(self.asset)),
        ]


def asset_answer(name: str) -> Response:
    """The asset ``name`` with its content type.

    Raises:
        NotFoundError: (404) a name that is not one of :data:`~leaderboard.page.ASSETS`.
    """
    if name not in ASSETS:
        raise NotFoundError(f"asset: expected one of {', '.join(ASSETS)}, found {name[:100]!r}")
    return Response(asset_text(name), media_type=ASSET_TYPES[Path(name).suffix])
