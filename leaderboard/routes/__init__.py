"""The service's routes, a router per resource; :func:`leaderboard.app.create_app` only wires
them.

* :mod:`~leaderboard.routes.site`: the HTML board, a submission's page, the page's assets;
* :mod:`~leaderboard.routes.standings`: the board as JSON (``/api/board``) and the page query;
* :mod:`~leaderboard.routes.status`: the public queue and the health check;
* :mod:`~leaderboard.routes.uploads`: a team's uploads and its own submissions;
* :mod:`~leaderboard.routes.answers`: what they share (refusals, error answers with the
  security headers, the token check, the handlers of unknown routes and unhandled errors).

Each router is a class built from its dependencies (the board; the limits and the rate limiter
for uploads), whose handlers are its methods and whose ``routes()`` are Starlette routes: a
test builds one router and calls one handler, without the app. The routes import the board's
modules (:mod:`leaderboard.board` and below, :mod:`leaderboard.views`,
:mod:`leaderboard.page`) and Starlette; nothing below imports them.
"""

from __future__ import annotations

from .answers import Refused, SecurityHeaders, answer, error_response, team_of
from .site import SiteRoutes
from .standings import StandingsRoutes
from .status import StatusRoutes
from .uploads import UploadRoutes

__all__ = [
    "Refused",
    "SecurityHeaders",
    "SiteRoutes",
    "StandingsRoutes",
    "StatusRoutes",
    "UploadRoutes",
    "answer",
    "error_response",
    "team_of",
]
