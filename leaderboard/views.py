"""What the board shows: JSON-ready views of a :class:`~leaderboard.board.Board`.

* :func:`board_view`: per evaluator, the scored submissions ranked by the evaluator's headline
  metric (competition ranking: equal scores share a rank), each with its metrics and
  confidence intervals and its headline per object family; the benchmark; counts by status.
* :func:`submission_view`: one submission: its file's hash and size, its evaluators' full
  results (per object, versions, hashes, seeds). The public view exists for scored
  submissions only; the team's own view (``private=True``) adds the error, the scoring log and
  every state change, for submissions in any state.

The page (:mod:`leaderboard.page`), the service's JSON answers and ``dg16m leaderboard show``
all read these views; their schema is ``format = "dg16m-leaderboard"``, ``version = 1``.
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Mapping
from typing import Any

from .board import Board, NotFoundError
from .worker import iso_time

VIEW_FORMAT = "dg16m-leaderboard"
VIEW_VERSION = 1


def _is_rate(value: Any) -> bool:
    return isinstance(value, Mapping) and "rate" in value


def _rate_only(value: Any) -> Any:
    """A metric without the evaluator-specific extras (rate, CI, rows, objects)."""
    if _is_rate(value):
        return {k: value.get(k) for k in ("rate", "ci_low", "ci_high", "rows", "objects")}
    return value


def board_view(board: Board, *, now: float | None = None) -> dict[str, Any]:
    """The ranked board (see the module docstring)."""
    setting = board.benchmark
    by_evaluator: dict[str, list[sqlite3.Row]] = {}
    for row in board.scored():
        by_evaluator.setdefault(row["evaluator"], []).append(row)
    order = board.evaluators + sorted(set(by_evaluator) - set(board.evaluators))
    sections = []
    for name in order:
        rows, columns, families = [], [], set()
        headline = name  # until a result names it
        previous: tuple[Any, int] | None = None
        for position, row in enumerate(by_evaluator.get(name, []), start=1):
            result = json.loads(row["result"])
            headline = result["headline"]
            rank = previous[1] if previous is not None and previous[0] == row["score"] else position
            previous = (row["score"], rank)
            metrics = {k: _rate_only(v) for k, v in result["metrics"].items()}
            for key in [headline, *metrics]:
                if key not in columns and _is_rate(metrics.get(key)):
                    columns.append(key)
            per_family = {
                family: _rate_only(values.get(headline))
                for family, values in result.get("per_family", {}).items()
            }
            families.update(per_family)
            rows.append(
                {
                    "rank": rank,
                    "submission": row["submission"],
                    "team": row["team"],
                    "label": row["label"],
                    "date": iso_time(row["created_at"]),
                    "evaluator_version": row["evaluator_version"],
                    "metrics": metrics,
                    "per_family": per_family,
                }
            )
        sections.append(
            {
                "name": name,
                "headline": headline,
                "columns": columns or [headline],
                "families": sorted(families),
                "rows": rows,
            }
        )
    return {
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
        "evaluators": sections,
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
