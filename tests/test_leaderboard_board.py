"""Tests of the leaderboard store (leaderboard.board, .schema, .tokens, .worker, .views): schema
migrations, teams and tokens, submissions stored by content hash, the queue's leases (with a
fake clock), scoring by a worker, the views, and the bad-submission corpus refused with nothing
changed."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path
from typing import Any

import pytest
from leaderboard_data import db_dump, set_benchmark, small_benchmark, tree, valid_submission
from test_submission import CORPUS, IDS, SHA

from dg16m_core.hashing import file_sha256
from dg16m_env.subjects.submission import SubmissionInvalid
from leaderboard.board import (
    Board,
    BoardError,
    DuplicateError,
    ForbiddenError,
    NotFoundError,
)
from leaderboard.schema import MIGRATIONS, SCHEMA_VERSION, SchemaError, migrate, schema_version
from leaderboard.tokens import find_token, new_token, token_sha256
from leaderboard.views import board_view, queue_view, submission_view
from leaderboard.worker import WorkerOptions, run_worker, score_claim


class Clock:
    """A settable clock (s since the epoch)."""

    def __init__(self, now: float = 1.8e9):
        self.now = now

    def __call__(self) -> float:
        return self.now


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return small_benchmark(tmp_path_factory.mktemp("bench") / "bench3.h5")


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory, bench: Path) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("subs")
    return {
        "a": valid_submission(folder / "a.h5", bench, k=2, method="pairs A"),
        "b": valid_submission(folder / "b.h5", bench, k=2, offset=5),
        "c": valid_submission(folder / "c.h5", bench, k=1, offset=9),
    }


def make_board(tmp_path: Path, bench: Path, **kwargs: Any) -> Board:
    return Board(tmp_path / "board.db", benchmark=bench, evaluators=("fce",), **kwargs)


# --------------------------------------------------------------------------------------------
# Schema and migrations
# --------------------------------------------------------------------------------------------


def test_new_board_has_latest_schema_in_wal_mode(tmp_path: Path, bench: Path) -> None:
    board = make_board(tmp_path, bench)
    conn = sqlite3.connect(board.db)
    assert schema_version(conn) == SCHEMA_VERSION == len(MIGRATIONS)
    assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    assert {"settings", "teams", "submissions", "results", "jobs", "events"} <= tables
    assert board.benchmark.sha256 == file_sha256(bench)
    assert board.benchmark.object_ids == tuple(json.loads(json.dumps(board.benchmark.object_ids)))
    assert board.integrity_check() == "ok"
    # opening it again changes nothing
    before = db_dump(board.db)
    Board(board.db, create=False)
    assert db_dump(board.db) == before


def test_migration_from_schema_1_keeps_data_and_queues_unscored(
    tmp_path: Path, bench: Path
) -> None:
    db = tmp_path / "old.db"
    conn = sqlite3.connect(db, isolation_level=None)
    assert migrate(conn, target=1) == [1]
    conn.execute(
        "INSERT INTO settings VALUES ('benchmark', ?), ('evaluators', '[\"fce\"]'), "
        "('title', '\"old board\"'), ('created_at', '1.0')",
        (
            json.dumps(
                {
                    "path": str(bench),
                    "sha256": file_sha256(bench),
                    "object_ids": [],
                    "mesh_root": None,
                }
            ),
        ),
    )
    conn.execute("INSERT INTO teams VALUES (1, 'old team', ?, 1.0)", (token_sha256("x"),))
    for sid, status in ((1, "scored"), (2, "queued"), (3, "running"), (4, "failed")):
        conn.execute(
            "INSERT INTO submissions (id, team_id, file_sha256, size, filename, label, "
            "evaluators, created_at, status) VALUES (?, 1, ?, 10, 'f.h5', 'old', '[\"fce\"]', "
            "?, ?)",
            (sid, "ab" * 32, float(sid), status),
        )
    conn.execute(
        "INSERT INTO results VALUES (1, 'fce', '1', 0.5, '{}', 2.0)",
    )
    conn.close()

    board = Board(db, create=False)
    conn = sqlite3.connect(db)
    assert schema_version(conn) == SCHEMA_VERSION == 3
    tracks = conn.execute("SELECT DISTINCT track, provenance FROM submissions").fetchall()
    assert tracks == [("mesh", None)]  # every submission before tracks is mesh-track
    jobs = dict(conn.execute("SELECT submission_id, state FROM jobs").fetchall())
    assert jobs == {1: "done", 2: "queued", 3: "queued", 4: "done"}
    status = dict(conn.execute("SELECT id, status FROM submissions").fetchall())
    assert status == {1: "scored", 2: "queued", 3: "queued", 4: "failed"}
    assert conn.execute("SELECT count(*) FROM events").fetchone()[0] == 4
    assert conn.execute("SELECT score FROM results").fetchone()[0] == 0.5
    assert board.title == "old board"
    assert [t.name for t in board.teams()] == ["old team"]
    claim = board.claim("w", 10.0)
    assert claim is not None
    assert claim.submission_id == 2
    assert board.integrity_check() == "ok"


def test_newer_or_foreign_database_is_refused(tmp_path: Path, bench: Path) -> None:
    board = make_board(tmp_path, bench)
    conn = sqlite3.connect(board.db, isolation_level=None)
    conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    conn.close()
    with pytest.raises(SchemaError, match="newer dg16m"):
        Board(board.db)
    other = tmp_path / "other.db"
    conn = sqlite3.connect(other, isolation_level=None)
    conn.execute("CREATE TABLE notes (x)")
    conn.close()
    with pytest.raises(SchemaError, match="another SQLite database"):
        Board(other)
    assert sqlite3.connect(other).execute("SELECT name FROM sqlite_master").fetchall() == [
        ("notes",)
    ]


def test_missing_board_is_refused_without_create(tmp_path: Path) -> None:
    with pytest.raises(NotFoundError, match="found nothing at"):
        Board(tmp_path / "none.db", create=False)
    assert not (tmp_path / "none.db").exists()


# --------------------------------------------------------------------------------------------
# Teams and tokens
# --------------------------------------------------------------------------------------------


def test_tokens_are_stored_hashed_and_matched_exactly(tmp_path: Path, bench: Path) -> None:
    board = make_board(tmp_path, bench)
    team, token = board.add_team("lab-a")
    _, other = board.add_team("Lab B.2")
    assert token != other
    assert token.startswith("dg16m_")
    raw = b"".join(p.read_bytes() for p in tmp_path.glob("board.db*"))
    assert token.encode() not in raw
    assert token_sha256(token).encode() in raw
    assert board.authenticate(token) == team
    assert board.authenticate(other).name == "Lab B.2"
    changed = other[:-1] + ("A" if other[-1] != "A" else "B")  # one character off
    for wrong in ("", token[:-1], token + "x", token.upper(), changed, "dg16m_"):
        assert board.authenticate(wrong) is None
    rotated = board.rotate_token("lab-a")
    assert board.authenticate(token) is None
    assert board.authenticate(rotated) == team
    with pytest.raises(BoardError, match="already taken"):
        board.add_team("lab-a")
    for bad in ("", " lab", "-x", "a/b", "x" * 65, "tab\tname", "<script>"):
        with pytest.raises(BoardError, match="expected 1-64 letters"):
            board.add_team(bad)
    with pytest.raises(NotFoundError, match=r"lab-a, Lab B\.2"):
        board.team("nobody")


def test_find_token_scans_every_entry() -> None:
    tokens = [new_token() for _ in range(5)]
    stored = [(token_sha256(t), i) for i, t in enumerate(tokens)]
    assert [find_token(t, stored) for t in tokens] == [0, 1, 2, 3, 4]
    # a malformed token never matches, even one whose hash is stored
    assert find_token("short", [(token_sha256("short"), 9)]) is None


# --------------------------------------------------------------------------------------------
# Submissions
# --------------------------------------------------------------------------------------------


def test_submit_stores_by_content_and_refuses_repeats(
    tmp_path: Path, bench: Path, files: dict[str, Path]
) -> None:
    board = make_board(tmp_path, bench)
    team, _ = board.add_team("lab-a")
    sid = board.submit(team, files["a"])
    row = board.submission_row(sid)
    assert row["label"] == "pairs A"  # from the file's metadata
    assert row["status"] == "queued"
    assert row["job_state"] == "queued"
    stored = board.file_path(row["file_sha256"])
    assert stored.read_bytes() == files["a"].read_bytes()
    assert stored.parent.parent == board.files
    assert stored.name == f"{row['file_sha256']}.h5"
    before = db_dump(board.db)
    with pytest.raises(DuplicateError, match=f"already submitted as #{sid}") as info:
        board.submit(team, files["a"])
    assert info.value.submission_id == sid
    assert info.value.status == 409
    assert db_dump(board.db) == before
    # the same file with other evaluators is another submission; the file is stored once
    sid2 = board.submit(team, files["a"], evaluators="fce,gsr", label="with gsr")
    assert board.submission_row(sid2)["file_sha256"] == row["file_sha256"]
    assert len(tree(board.files)) == 1
    assert board.submission_row(sid2)["label"] == "with gsr"
    assert board.submit(team, files["b"]) > sid2
    assert board.submission_row(sid2 + 1)["label"] == "b"  # the file name's stem


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"filename": "../evil.h5"}, "plain name"),
        ({"filename": "a/b.h5"}, "plain name"),
        ({"filename": ".hidden.h5"}, "plain name"),
        ({"filename": "x..h5"}, "plain name"),
        ({"label": "x" * 81}, "1-80 printable"),
        ({"label": "bell\x07"}, "1-80 printable"),
        ({"evaluators": "fce,nope"}, "found 'nope'"),
        ({"evaluators": "classifier"}, "scores a classifier"),
        ({"evaluators": ""}, "at least one"),
    ],
)
def test_submit_refuses_bad_arguments(
    tmp_path: Path, bench: Path, files: dict[str, Path], kwargs: dict[str, Any], message: str
) -> None:
    board = make_board(tmp_path, bench)
    team, _ = board.add_team("lab-a")
    before = db_dump(board.db)
    with pytest.raises(BoardError, match=message):
        board.submit(team, files["a"], **kwargs)
    assert db_dump(board.db) == before
    assert tree(board.files) == {}


@pytest.mark.parametrize("kind", sorted(CORPUS))
def test_bad_submission_corpus_is_refused_and_nothing_changes(
    tmp_path: Path, bench: Path, kind: str
) -> None:
    bad = CORPUS[kind]
    kwargs = dict(bad.kwargs)
    board = make_board(tmp_path, bench, limits=kwargs.pop("limits", None))
    embedded = kwargs.pop("embedded", True)
    assert not kwargs, f"corpus entry {kind} has arguments the board cannot mirror: {kwargs}"
    set_benchmark(board.db, sha256=SHA, object_ids=list(IDS), path=None if embedded else str(bench))
    team, _ = board.add_team("lab-a")
    upload = tmp_path / "upload"
    upload.mkdir()
    path = upload / "sub.h5"
    bad.build(path)
    before_db, before_files = db_dump(board.db), tree(upload)
    with pytest.raises(SubmissionInvalid) as info:
        board.submit(team, path)
    assert any(bad.place in p.place and bad.message in p.message for p in info.value.problems)
    assert db_dump(board.db) == before_db
    assert tree(upload) == before_files
    assert tree(board.files) == {}


# --------------------------------------------------------------------------------------------
# The queue: claims, leases, re-queues
# --------------------------------------------------------------------------------------------


def test_leases_requeue_a_dead_workers_job_and_score_it_once(
    tmp_path: Path, bench: Path, files: dict[str, Path]
) -> None:
    clock = Clock()
    board = make_board(tmp_path, bench, clock=clock)
    team, _ = board.add_team("lab-a")
    first = board.submit(team, files["a"])
    clock.now += 1
    second = board.submit(team, files["b"])
    a = board.claim("w1", 10.0)
    b = board.claim("w2", 10.0)
    assert (a.submission_id, b.submission_id) == (first, second)
    assert board.claim("w3", 10.0) is None
    clock.now += 5
    assert board.renew(b, 10.0)  # w2 is alive: its lease now ends at +15
    clock.now += 6  # w1's lease (ended at +10) has passed; w2's has not
    view = queue_view(board)
    assert [j["stale"] for j in view["jobs"]] == [True, False]
    again = board.claim("w3", 10.0)
    assert again.submission_id == first
    assert again.attempt == 2
    assert board.submission_row(first)["worker"] == "w3"
    messages = [e["message"] for e in board.events(first)]
    assert any("re-queued: the lease of worker w1 expired" in m for m in messages)
    # w1 comes back: its results and failure are refused, nothing is stored
    assert not board.finish(a, {}, "late")
    assert not board.fail(a, "late", "late")
    assert not board.renew(a, 10.0)
    assert board.submission_row(first)["status"] == "running"
    assert board.finish(again, {}, "log of w3")
    assert not board.finish(again, {}, "twice")
    row = board.submission_row(first)
    assert row["status"] == "scored"
    assert row["log"] == "log of w3"
    assert [e["state"] for e in board.events(first)] == [
        "queued",
        "running",
        "queued",
        "running",
        "scored",
    ]


def test_a_job_that_keeps_losing_its_worker_fails_visibly(
    tmp_path: Path, bench: Path, files: dict[str, Path]
) -> None:
    clock = Clock()
    board = make_board(tmp_path, bench, clock=clock, max_attempts=2)
    team, _ = board.add_team("lab-a")
    sid = board.submit(team, files["a"])
    for _ in range(2):
        assert board.claim("doomed", 5.0) is not None
        clock.now += 6
    assert board.requeue_stale() == [sid]
    row = board.submission_row(sid)
    assert row["status"] == "failed"
    assert "did not finish in 2 attempts" in row["error"]
    assert board.claim("w", 5.0) is None
    assert board.counts()["failed"] == 1


def test_claim_validates_the_lease(tmp_path: Path, bench: Path) -> None:
    board = make_board(tmp_path, bench)
    for lease in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(BoardError, match="lease_s"):
            board.claim("w", lease)


# --------------------------------------------------------------------------------------------
# Workers and views
# --------------------------------------------------------------------------------------------


def test_worker_scores_and_views_rank(tmp_path: Path, bench: Path, files: dict[str, Path]) -> None:
    board = make_board(tmp_path, bench)
    team_a, _ = board.add_team("lab-a")
    team_b, _ = board.add_team("lab-b")
    ids = [
        board.submit(team_a, files["a"]),
        board.submit(team_b, files["b"]),
        board.submit(team_b, files["c"]),
    ]
    reports: list[str] = []
    done = run_worker(board, WorkerOptions(idle_exit_s=0.01, poll_s=0.01), report=reports.append)
    assert done == 3
    assert all(board.submission_row(i)["status"] == "scored" for i in ids)
    view = board_view(board)
    (fce,) = view["evaluators"]
    assert fce["name"] == "fce"
    assert fce["headline"] == "fce"
    assert fce["columns"] == ["fce"]
    scores = [r["metrics"]["fce"]["rate"] for r in fce["rows"]]
    assert scores == sorted(scores, reverse=True)
    assert len(scores) == 3
    ranks = [r["rank"] for r in fce["rows"]]
    for k in range(1, 3):  # competition ranking: equal scores share a rank
        expected = ranks[k - 1] if scores[k] == scores[k - 1] else k + 1
        assert ranks[k] == expected
    assert set(fce["families"]) == set(fce["rows"][0]["per_family"])
    assert view["counts"] == {
        "teams": 2,
        "submissions": 3,
        "queued": 0,
        "running": 0,
        "scored": 3,
        "failed": 0,
    }
    public = submission_view(board, ids[0])
    assert "private" not in public
    assert "log" not in public
    result = public["results"]["fce"]
    assert result["benchmark"]["sha256"] == file_sha256(bench)
    assert result["subject"]["sha256"] == file_sha256(files["a"])
    assert set(result["per_object"]) == set(board.benchmark.object_ids)
    private = submission_view(board, ids[0], private=True)
    assert "fce v1: scoring" in private["log"]
    assert private["events"][-1]["state"] == "scored"
    # a team sees only its own submissions' details
    assert board.own_submission(team_a, ids[0])["id"] == ids[0]
    with pytest.raises(ForbiddenError, match="another team's"):
        board.own_submission(team_b, ids[0])
    with pytest.raises(NotFoundError):
        board.own_submission(team_a, 999)


def test_scoring_failure_is_recorded_with_its_log(
    tmp_path: Path, bench: Path, files: dict[str, Path]
) -> None:
    board = make_board(tmp_path, bench)
    team, _ = board.add_team("lab-a")
    sid = board.submit(team, files["a"])
    board.file_path(board.submission_row(sid)["file_sha256"]).unlink()  # lost from the store
    claim = board.claim("w", 30.0)
    assert score_claim(board, claim, WorkerOptions()) == "failed"
    row = board.submission_row(sid)
    assert row["status"] == "failed"
    assert "found nothing there" in row["error"]
    assert "error:" in row["log"]
    with pytest.raises(NotFoundError, match="only its team sees it"):
        submission_view(board, sid)  # not public
    assert board_view(board)["evaluators"][0]["rows"] == []


def test_board_refuses_a_changed_benchmark(tmp_path: Path, bench: Path) -> None:
    copy = tmp_path / "bench.h5"
    copy.write_bytes(bench.read_bytes())
    board = Board(tmp_path / "board.db", benchmark=copy)
    with copy.open("ab") as handle:
        handle.write(b"\0")
    with pytest.raises(BoardError, match="the file changed"):
        Board(board.db).benchmark_ref()


@pytest.mark.slow
def test_worker_on_ray_stores_the_local_result(
    tmp_path: Path, bench: Path, files: dict[str, Path]
) -> None:
    pytest.importorskip("ray")
    stored = {}
    for backend in ("local", "ray"):
        board = Board(tmp_path / backend / "board.db", benchmark=bench, evaluators=("fce", "gsr"))
        team, _ = board.add_team("lab-a")
        sid = board.submit(team, files["a"])
        claim = board.claim("w", 600.0)
        assert score_claim(board, claim, WorkerOptions(backend=backend)) == "scored"
        stored[backend] = board.results(sid)
    assert json.dumps(stored["local"], sort_keys=True) == json.dumps(stored["ray"], sort_keys=True)
