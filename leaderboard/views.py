"""What the board shows: JSON-ready views of a :class:`~leaderboard.board.Board`.

* :func:`board_view`: per track (mesh, cloud: :mod:`leaderboard.tracks`) and evaluator, the
  scored submissions of that track ranked by the evaluator's headline metric (competition
  ranking within the track: equal scores share a rank; a mesh-track and a cloud-track result
  are never ranked together), each with its metrics and confidence intervals, its headline per
  object family and (cloud track) its self-declared provenance; the tracks' headings; the
  benchmark; counts by status. With ``page`` and ``limit``, one page of each section's rows
  (ranks count every row before the page), each section's ``total`` and the view's ``page``
  (number, limit, pages, total: the longest section's rows).
* :func:`submission_view`: one submission: its track and provenance, its file's hash and
  size, its evaluators' full results (per object, versions, hashes, seeds). The public view
  exists for scored
  submissions only; the team's own view (``private=True``) adds the error, the scoring log and
  every state change, for submissions in any state.
* :func:`queue_view`: the queue's jobs with their workers and leases (the operator's view, on
  the command line); :func:`public_queue_view`: counts only, and a team's own jobs when asked
  with its token (what the service shows).

The page (:mod:`leaderboard.page`), the service's JSON answers and ``dg16m leaderboard show``
all read these views; their schema is ``format = "dg16m-leaderboard"``, ``version = 2``
(version 1, before tracks, had one section per evaluator and no ``"tracks"``).
"""

from __future__ import annotations

import json
import math
import sqlite3
from collections.abc import Mapping
from typing import Any

from .board import Board, NotFoundError, Team
from .query_checks import InvalidParameterError
from .tracks import DEFAULT_TRACK, TRACK_INFO, TRACKS, check_track
from .worker import iso_time

VIEW_FORMAT = "dg16m-leaderboard"
VIEW_VERSION = 2
"""2: sections per track (``"track"`` in each, ``"tracks"`` in the view); 1: per evaluator."""
PAGE_ROWS = 50
"""Rows per evaluator on one page of the board (the service's default)."""
MAX_PAGE_ROWS = 500
"""Most rows per evaluator one page may ask for."""


def _is_rate(value: Any) -> bool:
    return isinstance(value, Mapping) and "rate" in value


def _rate_only(value: Any) -> Any:
    """A metric without the evaluator-specific extras (rate, CI, rows, objects)."""
    if _is_rate(value):
        return {k: value.get(k) for k in ("rate", "ci_low", "ci_high", "rows", "objects")}
    return value


def check_page(page: int, limit: int) -> None:
    """Refuse a page number below 1 or a page size outside 1 .. :data:`MAX_PAGE_ROWS`.

    Raises:
        InvalidParameterError: (status 422) saying what was expected.
    """
    if not 1 <= limit <= MAX_PAGE_ROWS:
        raise InvalidParameterError(
            f"limit: expected 1 to {MAX_PAGE_ROWS} rows per page, found {limit}"
        )
    if page < 1:
        raise InvalidParameterError(f"page: expected a page number from 1, found {page}")


def board_view(
    board: Board,
    *,
    now: float | None = None,
    page: int | None = None,
    limit: int = PAGE_ROWS,
    track: str | None = None,
) -> dict[str, Any]:
    """The ranked board (see the module docstring): every row, or page ``page`` (from 1) of
    ``limit`` rows per track and evaluator; every track, or only ``track``.

    Tracks are never mixed: each section is one evaluator's table in one track, ranked within
    it. The mesh track's sections are always there (the board's evaluators); the cloud track's
    when it has a scored result, or when ``track`` asks for it.

    Raises:
        InvalidParameterError: a bad page number or size, or an unknown track; NotFoundError:
            a page past the last.
    """
    setting = board.benchmark
    tracks = list(TRACKS) if track is None else [check_track(track)]
    totals = {name: board.scored_totals(track=name) for name in tracks}
    shown = [t for t in tracks if t == DEFAULT_TRACK or totals[t] or track is not None]
    orders = {t: board.evaluators + sorted(set(totals[t]) - set(board.evaluators)) for t in shown}
    by_section: dict[tuple[str, str], list[sqlite3.Row]] = {}
    paging: dict[str, Any] | None = None
    if page is None:
        for row in board.scored():
            by_section.setdefault((row["track"], row["evaluator"]), []).append(row)
    else:
        check_page(page, limit)
        longest = max((n for t in shown for n in totals[t].values()), default=0)
        pages = max(1, math.ceil(longest / limit))
        if page > pages:
            raise NotFoundError(f"page: expected a page number from 1 to {pages}, found {page}")
        paging = {"number": page, "limit": limit, "pages": pages, "total": longest}
        for t in shown:
            for name in orders[t]:
                rows = board.scored_page(name, (page - 1) * limit, limit, track=t)
                by_section[(t, name)] = rows
    sections = []
    for t in shown:
        for name in orders[t]:
            section = _section(t, name, by_section.get((t, name), []))
            if paging is not None:
                section["total"] = totals[t].get(name, 0)
            sections.append(section)
    view: dict[str, Any] = {
        "format": VIEW_FORMAT,
        "version": VIEW_VERSION,
        "title": board.title,
        "generated_at": iso_time(board.clock() if now is None else now),
        "benchmark": {
            "sha256": setting.sha256,
            "objects": len(setting.object_ids),
            "embedded": setting.embedded,
        },
        "counts": board.counts(),
        "tracks": [
            {
                "name": t,
                "title": TRACK_INFO[t].title,
                "self_declared": TRACK_INFO[t].self_declared,
                "shown": t in shown,
            }
            for t in tracks
        ],
        "evaluators": sections,
    }
    if paging is not None:
        view["page"] = paging
    return view


def _section(track: str, name: str, found: list[sqlite3.Row]) -> dict[str, Any]:
    """One evaluator's table in one track: its rows (ranked within the track), its columns
    (the headline first) and the object families its rows report."""
    rows, columns, families = [], [], set()
    headline = name  # until a result names it
    for row in found:
        result = json.loads(row["result"])
        headline = result["headline"]
        metrics = {k: _rate_only(v) for k, v in result["metrics"].items()}
        for key in [headline, *metrics]:
            if key not in columns and _is_rate(metrics.get(key)):
                columns.append(key)
        per_family = {
            family: _rate_only(values.get(headline))
            for family, values in result.get("per_family", {}).items()
        }
        families.update(per_family)
        entry = {
            "rank": row["rank"],
            "submission": row["submission"],
            "team": row["team"],
            "label": row["label"],
            "date": iso_time(row["created_at"]),
            "evaluator_version": row["evaluator_version"],
            "metrics": metrics,
            "per_family": per_family,
        }
        if row["provenance"] is not None:
            entry["provenance"] = json.loads(row["provenance"])
        rows.append(entry)
    return {
        "track": track,
        "name": name,
        "headline": headline,
        "columns": columns or [headline],
        "families": sorted(families),
        "rows": rows,
    }


def submission_view(board: Board, submission_id: int, *, private: bool = False) -> dict[str, Any]:
    """One submission (see the module docstring).

    Raises:
        NotFoundError: no such submission, or (public view) one not scored.
    """
    row = board.submission_row(submission_id)
    if not private and row["status"] != "scored":
        raise NotFoundError(
            f"submission: expected a scored submission, found #{submission_id} {row['status']} "
            "(only its team sees it before it is scored)"
        )
    view: dict[str, Any] = {
        "id": row["id"],
        "team": row["team"],
        "label": row["label"],
        "filename": row["filename"],
        "date": iso_time(row["created_at"]),
        "status": row["status"],
        "file_sha256": row["file_sha256"],
        "size": row["size"],
        "evaluators": json.loads(row["evaluators"]),
        "track": row["track"],
        "provenance": None if row["provenance"] is None else json.loads(row["provenance"]),
        "benchmark": board.benchmark.sha256,
        "results": board.results(submission_id),
    }
    if private:
        view.update(
            {
                "private": True,
                "error": row["error"],
                "log": row["log"],
                "attempts": row["attempts"],
                "lease_expires_at": None
                if row["lease_expires_at"] is None
                else iso_time(row["lease_expires_at"]),
                "events": [
                    {
                        "at": iso_time(e["at"]),
                        "state": e["state"],
                        "worker": e["worker"],
                        "message": e["message"],
                    }
                    for e in board.events(submission_id)
                ],
            }
        )
    return view


def queue_view(board: Board) -> dict[str, Any]:
    """Jobs not done, each with its state, attempts, worker and lease deadline; a running job
    whose lease passed is marked ``stale`` (its worker stopped renewing: it is re-queued by the
    next claim)."""
    now = board.clock()
    jobs = []
    for row in board.queue():
        expires = row["lease_expires_at"]
        jobs.append(
            {
                "submission": row["submission_id"],
                "team": row["team"],
                "label": row["label"],
                "state": row["state"],
                "attempts": row["attempts"],
                "worker": row["worker"],
                "queued_at": iso_time(row["queued_at"]),
                "lease_expires_at": None if expires is None else iso_time(expires),
                "stale": row["state"] == "running" and expires is not None and expires < now,
            }
        )
    return {"generated_at": iso_time(now), "counts": board.counts(), "jobs": jobs}


def public_queue_view(board: Board, team: Team | None = None) -> dict[str, Any]:
    """What the service shows of the queue: submissions per status (queued, running, scored,
    failed) and, for a team that shows its token, its own jobs (state, attempts, stale); never
    another team's labels or names, nor which worker holds a job."""
    counts = board.counts()
    view: dict[str, Any] = {
        "generated_at": iso_time(board.clock()),
        "counts": {k: counts[k] for k in ("queued", "running", "scored", "failed")},
    }
    if team is not None:
        now = board.clock()
        view["team"] = team.name
        view["jobs"] = [
            {
                "submission": row["submission_id"],
                "label": row["label"],
                "state": row["state"],
                "attempts": row["attempts"],
                "queued_at": iso_time(row["queued_at"]),
                "stale": row["state"] == "running"
                and row["lease_expires_at"] is not None
                and row["lease_expires_at"] < now,
            }
            for row in board.queue(team)
        ]
    return view
