"""A small client of the leaderboard service (standard library only): upload a submission with a
team token, read its status. ``dg16m leaderboard submit --url`` uses it."""

from __future__ import annotations

import json
import os
import time
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .board import BoardError


class ServiceError(BoardError):
    """The service refused a request; :attr:`status` is its HTTP status, :attr:`answer` its
    JSON answer (with ``error``, and ``problems`` for an invalid file)."""

    def __init__(self, status: int, answer: dict[str, Any]):
        message = str(answer.get("error", f"HTTP {status}"))
        problems = answer.get("problems") or []
        lines = [f"{p.get('place')}: {p.get('message')}" for p in problems[:20]]
        super().__init__("\n  ".join([f"HTTP {status}: {message}", *lines]))
        self.status = status
        self.answer = answer


def _request(request: urllib.request.Request, timeout: float) -> dict[str, Any]:
    try:
        with urllib.request.urlopen(request, timeout=timeout) as response:
            return json.loads(response.read().decode("utf-8"))
    except urllib.error.HTTPError as exc:
        body = exc.read().decode("utf-8", "replace")
        try:
            answer = json.loads(body)
        except ValueError:
            answer = {"error": body[:500]}
        raise ServiceError(exc.code, answer if isinstance(answer, dict) else {}) from None
    except urllib.error.URLError as exc:
        raise BoardError(
            f"{request.full_url}: expected a leaderboard service, found none ({exc.reason})"
        ) from None


def _check_url(url: str) -> str:
    parts = urllib.parse.urlsplit(url)
    if parts.scheme not in ("http", "https") or not parts.netloc:
        raise BoardError(f"--url: expected http(s)://host:port, found {url!r}")
    return url.rstrip("/")


def upload(
    url: str,
    token: str,
    path: str | os.PathLike[str],
    *,
    label: str | None = None,
    evaluators: str | None = None,
    timeout: float = 300.0,
) -> dict[str, Any]:
    """Upload a submission file; returns the service's answer (``submission``, ``status``).

    Raises:
        ServiceError: refused (401 token, 409 repeat, 413 size, 422 invalid, 429 rate, ...).
        BoardError: no service at ``url``.
    """
    base = _check_url(url)
    if not Path(path).is_file():
        raise BoardError(f"{path}: expected a submission file, found nothing there")
    query = {"filename": Path(path).name}
    if label:
        query["label"] = label
    if evaluators:
        query["evaluators"] = evaluators
    request = urllib.request.Request(
        f"{base}/api/submissions?{urllib.parse.urlencode(query)}",
        data=Path(path).read_bytes(),
        method="POST",
        headers={
            "Authorization": f"Bearer {token}",
            "Content-Type": "application/octet-stream",
        },
    )
    return _request(request, timeout)


def status(url: str, token: str, submission_id: int, *, timeout: float = 30.0) -> dict[str, Any]:
    """The team's view of one of its submissions (status, results, error, log, events)."""
    request = urllib.request.Request(
        f"{_check_url(url)}/api/submissions/{int(submission_id)}",
        headers={"Authorization": f"Bearer {token}"},
    )
    return _request(request, timeout)


def wait(
    url: str,
    token: str,
    submission_id: int,
    *,
    timeout_s: float,
    poll_s: float = 2.0,
    on_update: Callable[[dict[str, Any], float], None] | None = None,
) -> dict[str, Any]:
    """Poll until the submission is scored or failed, or ``timeout_s`` passed (then the last
    answer, still queued or running); ``on_update(answer, seconds waited)`` after each poll."""
    start = time.monotonic()
    deadline = start + timeout_s
    while True:
        answer = status(url, token, submission_id)
        if on_update is not None:
            on_update(answer, time.monotonic() - start)
        if answer.get("status") in ("scored", "failed") or time.monotonic() >= deadline:
            return answer
        time.sleep(poll_s)
