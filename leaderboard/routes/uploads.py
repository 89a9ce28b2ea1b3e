"""A team's submissions, with its token: upload one (``POST /api/submissions``), list them
(``GET /api/submissions``), and one with its error, scoring log and events
(``GET /api/submissions/<id>``).

An upload's checks, in order, each answered without touching the database: the token (401),
the team's rate limit (429 with ``Retry-After``), the query (400), the size (413: a declared
``Content-Length`` over the limit before reading, the streamed body past it while reading), the
file's validation (422 with every problem), a repeat (409); a body that stalls or takes too long
is 408. An accepted upload is stored by content hash and queued (202).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import anyio
from starlette.concurrency import run_in_threadpool
from starlette.requests import ClientDisconnect, Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route

from dg16m_env.subjects.submission import SubmissionInvalid

from ..query_checks import (
    DIGITS,
    BoardError,
    DuplicateError,
    check_evaluators,
    check_file_name,
    check_id,
    check_label,
    check_query,
)
from ..views import submission_view
from .answers import Refused, answer, json_answer, team_of

if TYPE_CHECKING:
    from ..board import Board, Team
    from ..limits import RateLimiter, ServiceConfig

UPLOAD_QUERY = ("filename", "label", "evaluators")
"""The query parameters of an upload."""


class UploadRoutes:
    """A team's uploads and its view of its submissions.

    Args:
        board: the board the submissions go to.
        config: the service's limits (upload size and timeouts, rate limit).
        limiter: the per-team rate limit of uploads.
    """

    def __init__(self, board: Board, config: ServiceConfig, limiter: RateLimiter):
        self.board, self.config, self.limiter = board, config, limiter
        self.max_bytes = min(config.max_upload_bytes, board.limits.max_file_bytes)

    async def own_list(self, request: Request) -> Response:
        """The team's submissions: id, label, status, error."""
        team = await run_in_threadpool(team_of, self.board, request)
        rows = await run_in_threadpool(self.board.submissions, team)
        return JSONResponse(
            {
                "team": team.name,
                "submissions": [
                    {"id": r["id"], "label": r["label"], "status": r["status"], "error": r["error"]}
                    for r in rows
                ],
            }
        )

    async def own_detail(self, request: Request) -> Response:
        """One of the team's submissions with its error, scoring log and events (404 when
        there is none, 403 when it is another team's)."""
        sid = check_id(request.path_params["sid"])
        team = await run_in_threadpool(team_of, self.board, request)
        await run_in_threadpool(self.board.own_submission, team, sid)  # 404 / 403
        return await run_in_threadpool(
            lambda: json_answer(submission_view(self.board, sid, private=True))
        )

    async def upload(self, request: Request) -> Response:
        """Check, store and queue an uploaded submission file (the checks are the module's)."""
        team = await run_in_threadpool(team_of, self.board, request)
        self.admit(team)
        filename, label, evaluators = upload_query(request)
        self.check_declared_size(request.headers.get("content-length"))
        with self.board.file_store.upload() as (handle, tmp):
            size = await self.read_body(request, handle)
            handle.flush()
            if size == 0:
                raise Refused(400, "upload: expected the submission file as the body, found none")
            sid = await self.submit(team, tmp, filename, label, evaluators)
        return JSONResponse(
            {
                "submission": sid,
                "status": "queued",
                "status_url": f"/api/submissions/{sid}",
                "page": f"/submissions/{sid}",
            },
            status_code=202,
        )

    def admit(self, team: Team) -> None:
        """Count the team's upload against its rate limit.

        Raises:
            Refused: (429 with ``Retry-After``) the limit is reached.
        """
        retry = self.limiter.admit(team)
        if retry is not None:
            raise Refused(
                429,
                f"expected at most {self.config.rate_limit} uploads per "
                f"{self.config.rate_window_s:g} s for team {team.name!r}, found the limit "
                "reached (failed uploads count too)",
                headers={"Retry-After": str(int(retry + 0.999))},
            )

    def check_declared_size(self, declared: str | None) -> None:
        """Refuse a ``Content-Length`` that is not a number (400) or over the limit (413), before
        reading the body."""
        if declared is None:
            return
        if not DIGITS.match(declared):
            raise Refused(400, f"Content-Length: expected a number, found {declared[:40]!r}")
        if int(declared) > self.max_bytes:
            raise Refused(
                413,
                f"upload: expected at most {self.max_bytes} bytes, found Content-Length "
                f"{declared} (not read)",
            )

    async def read_body(self, request: Request, handle: Any) -> int:
        """Stream the body into ``handle``; its size. Refused past the size limit (413), when
        it stalls or takes too long (408), or when the client goes (400)."""
        config = self.config
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
                    raise Refused(
                        400, "upload: expected the whole body, found the client gone"
                    ) from None
            if chunk is None:
                whole = time.monotonic() >= deadline
                limit = (
                    f"the whole body within {config.upload_timeout_s:g} s"
                    if whole
                    else f"a part of the body at least every {config.body_idle_timeout_s:g} s"
                )
                raise Refused(
                    408,
                    f"upload: expected {limit}, found {size} bytes and then nothing",
                    headers={"Connection": "close"},
                )
            size += len(chunk)
            if size > self.max_bytes:
                raise Refused(
                    413,
                    f"upload: expected at most {self.max_bytes} bytes, found more (stopped "
                    "reading)",
                    headers={"Connection": "close"},
                )
            handle.write(chunk)

    async def submit(
        self, team: Team, path: Any, filename: str, label: str | None, evaluators: str | None
    ) -> int:
        """Validate, store and queue the received file (in a worker thread); its id.

        Raises:
            Refused: (422) the file is not a valid submission, with its problems; (409) the
                team already submitted it with these evaluators.
        """
        try:
            return await run_in_threadpool(
                self.board.submit,
                team,
                path,
                filename=filename,
                label=label,
                evaluators=evaluators,
            )
        except SubmissionInvalid as exc:
            raise Refused(
                422,
                f"expected a valid submission file, found {len(exc.problems)} problem(s)",
                problems=[{"place": p.place, "message": p.message} for p in exc.problems],
            ) from None
        except DuplicateError as exc:
            raise Refused(409, str(exc), submission=exc.submission_id) from None

    def routes(self) -> list[Route]:
        """Its routes, each answering its refusals and board errors."""
        return [
            Route("/api/submissions", answer(self.upload), methods=["POST"]),
            Route("/api/submissions", answer(self.own_list), methods=["GET"]),
            Route("/api/submissions/{sid}", answer(self.own_detail)),
        ]


def upload_query(request: Request) -> tuple[str, str | None, str | None]:
    """An upload's file name (default ``submission.h5``), label and evaluators
    (comma-separated), checked.

    Raises:
        BoardError: (400) another query key, or a value its check refuses.
    """
    params = request.query_params
    check_query(params, UPLOAD_QUERY, error=BoardError, shown=None, once=False)
    filename = check_file_name(params.get("filename", "submission.h5"))
    label = params.get("label") or None
    if label is not None:
        label = check_label(label)
    evaluators = params.get("evaluators") or None
    if evaluators is not None:
        evaluators = ",".join(check_evaluators(evaluators))
    return filename, label, evaluators
