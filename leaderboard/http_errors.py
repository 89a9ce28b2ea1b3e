"""What every error answer of the service carries, at both of its levels (the routes,
:mod:`leaderboard.routes`, and the connections, :mod:`leaderboard.connections`): the security
headers and the error body (JSON for ``/api/*``, a small HTML page for the rest).

Imports only the standard library.
"""

from __future__ import annotations

import html
import json

SECURITY_HEADERS = {
    "Content-Security-Policy": (
        "default-src 'none'; style-src 'self'; script-src 'self'; img-src 'self' data:; "
        "base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
    ),
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
}
"""Headers on every answer of the service, errors included."""
REASONS = {400: "Bad Request", 408: "Request Timeout", 431: "Request Header Fields Too Large"}
"""Reason phrases of the errors answered below the app (and the title of an HTML error)."""


def is_api(path: str) -> bool:
    """Whether ``path`` is the JSON API's (``/api/...``): its errors are JSON, not HTML."""
    return path.startswith("/api/")


def error_body(status: int, message: str, *, api: bool) -> tuple[bytes, str]:
    """An error's body and content type: ``{"error", "status"}`` JSON for the API, else a
    small HTML page (escaped; no script, no inline style)."""
    if api:
        body = json.dumps({"error": message, "status": status}).encode("utf-8")
        return body, "application/json"
    title = html.escape(f"{status} {REASONS.get(status, 'Error')}")
    page = (
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>{title}</title><link rel='stylesheet' href='/assets/board.css'></head>"
        f"<body><main><h1>{title}</h1><p>{html.escape(message)}</p>"
        "<p><a href='/'>Back to the board</a></p></main></body></html>"
    )
    return page.encode("utf-8"), "text/html; charset=utf-8"
