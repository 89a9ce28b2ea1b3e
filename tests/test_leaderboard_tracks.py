"""Tracks on the leaderboard (leaderboard.tracks): a submission's track (mesh or cloud) and its
self-declared provenance come from its file's metadata; a mesh-track and a cloud-track result are
shown apart and ranked apart on the board (JSON API, static HTML, ``dg16m leaderboard show``,
the page in headless Chromium); a malformed track is refused with nothing stored; a board from
before tracks opens and its rows are mesh-track."""

from __future__ import annotations

import asyncio
import json
import sqlite3
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from browser import page_problems, screenshot, start_browser, wait_for_script
from leaderboard_data import (
    FakeResult,
    db_dump,
    running_service,
    small_benchmark,
    tree,
    valid_submission,
)
from starlette.requests import Request

from dg16m_core.cli import main
from dg16m_core.hashing import file_sha256
from dg16m_env.evaluators import load_benchmark_ref
from dg16m_env.subjects.submission import SubmissionInvalid
from dg16m_env.subjects.submission_writer import write_submission
from leaderboard.board import Board, BoardError
from leaderboard.page import write_static
from leaderboard.query_checks import InvalidParameterError
from leaderboard.queue import NewSubmission
from leaderboard.routes import SiteRoutes, answer
from leaderboard.routes.standings import StandingsRoutes
from leaderboard.schema import SCHEMA_VERSION, migrate, schema_version
from leaderboard.tokens import token_sha256
from leaderboard.tracks import MAX_PROVENANCE_BYTES, TRACK_INFO, TRACKS, TrackError, track_of
from leaderboard.views import board_view, submission_view
from leaderboard.worker import WorkerOptions, run_worker

CLOUD = {
    "name": "cloud",
    "harness_version": "1",
    "noise": "default",
    "noise_seed": 7,
    "cameras": 2,
    "camera_seed": 3,
    "predictor_sha256": "0123456789abcdef" * 4,
    "sandbox": "process",
}
"""A cloud-track provenance as ``dg16m evaluate --track cloud`` declares it."""


def tracked_submission(
    path: Path, benchmark: Path, track: Any, *, k: int = 1, offset: int = 9, method: str = "cloud"
) -> Path:
    """A valid submission (each object's stored dual grasps ``offset .. offset + k``) whose
    metadata carries ``track``."""
    ref = load_benchmark_ref(benchmark)
    poses = {}
    for object_id in ref.object_ids:
        rows = ref.benchmark.object_rows(object_id)
        poses[object_id] = ref.benchmark.poses[rows[(np.arange(k) + offset) % rows.size]]
    metadata = {"method": method, "track": track}
    return write_submission(path, poses, benchmark=ref.sha256, metadata=metadata)


def request(path: str, query: str = "") -> Request:
    scope = {"type": "http", "method": "GET", "path": path, "headers": []}
    return Request({**scope, "query_string": query.encode()})


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return small_benchmark(tmp_path_factory.mktemp("bench") / "bench3.h5")


@pytest.fixture(scope="module")
def two_tracks(tmp_path_factory: pytest.TempPathFactory, bench: Path) -> dict[str, Any]:
    """A board with a mesh-track and a cloud-track submission scored by a worker (fce on 3
    objects), and a second mesh-track row of score 0 (the queue's records only)."""
    root = tmp_path_factory.mktemp("tracks")
    board = Board(root / "board.db", benchmark=bench, evaluators=("fce",))
    mesh_team, _ = board.add_team("lab-mesh")
    cloud_team, _ = board.add_team("lab-cloud")
    mesh_file = valid_submission(root / "mesh.h5", bench, k=2, method="mesh pairs")
    cloud_file = tracked_submission(root / "cloud.h5", bench, CLOUD, method="cloud pairs")
    mesh = board.submit(mesh_team, mesh_file)
    cloud = board.submit(cloud_team, cloud_file)
    assert run_worker(board, WorkerOptions(idle_exit_s=0.01, poll_s=0.01)) == 2
    new = NewSubmission(mesh_team.id, mesh_team.name, "e" * 64, 1, "zero.h5", "zero", ["fce"])
    zero = board.jobs.enqueue(new)
    assert board.finish(board.claim("w", 60.0, submission_id=zero), {"fce": FakeResult(0.0)}, "")
    return {"board": board, "root": root, "mesh": mesh, "cloud": cloud, "zero": zero}


# --------------------------------------------------------------------------------------------
# A submission's track
# --------------------------------------------------------------------------------------------


def test_track_of_reads_the_metadata() -> None:
    assert track_of({}) == ("mesh", None)
    assert track_of({"method": "x"}) == ("mesh", None)
    assert track_of(None) == ("mesh", None)  # no metadata at all
    name, provenance = track_of({"track": CLOUD})
    assert name == "cloud"
    assert json.loads(provenance or "") == CLOUD
    assert track_of({"track": {"name": "mesh"}}) == ("mesh", '{"name":"mesh"}')
    for bad, found in (
        ({"name": "lidar"}, 'str "lidar"'),
        ({"name": "Cloud"}, 'str "Cloud"'),
        ({"harness_version": "1"}, "NoneType null"),
        ({"name": 1}, "int 1"),
    ):
        with pytest.raises(TrackError, match="expected track name 'mesh' or 'cloud', found") as e:
            track_of({"track": bad})
        assert found in str(e.value)
    with pytest.raises(TrackError, match=r'in an object .* found str "cloud"'):
        track_of({"track": "cloud"})
    with pytest.raises(TrackError, match=f"at most {MAX_PROVENANCE_BYTES} bytes"):
        track_of({"track": {"name": "cloud", "notes": "x" * MAX_PROVENANCE_BYTES}})
    with pytest.raises(TrackError, match="expected a JSON object"):
        track_of({"track": {"name": "cloud", "noise_seed": float("nan")}})


def test_the_board_presents_every_harness_track() -> None:
    assert list(TRACK_INFO) == list(TRACKS)  # a heading for each, in the harness's order
    assert TRACK_INFO["cloud"].self_declared
    assert not TRACK_INFO["mesh"].self_declared


def test_a_malformed_track_is_refused_and_nothing_stored(tmp_path: Path, bench: Path) -> None:
    board = Board(tmp_path / "board.db", benchmark=bench, evaluators=("fce",))
    team, _ = board.add_team("lab-a")
    before = (db_dump(board.db), tree(board.files))
    bad = tracked_submission(tmp_path / "bad.h5", bench, {**CLOUD, "name": "lidar"})
    with pytest.raises(SubmissionInvalid) as info:
        board.submit(team, bad)
    # refused by the file's validation (dg16m_env.subjects.track) or by the board's own check
    # (leaderboard.tracks), whichever comes first: the same place, both names and what came
    ((place, message),) = [(p.place, p.message) for p in info.value.problems]
    assert place == "attrs/metadata"
    for text in ("track: expected", "'mesh'", "'cloud'", "lidar"):
        assert text in message, message
    assert (db_dump(board.db), tree(board.files)) == before
    # the same through the command line: one line, exit 2
    code = main(["leaderboard", "submit", str(bad), "--team", "lab-a", "--db", str(board.db)])
    assert code == 2
    assert (db_dump(board.db), tree(board.files)) == before


def test_the_track_is_recorded_from_the_file(two_tracks: dict[str, Any]) -> None:
    board = two_tracks["board"]
    mesh = board.submission_row(two_tracks["mesh"])
    cloud = board.submission_row(two_tracks["cloud"])
    assert (mesh["track"], mesh["provenance"]) == ("mesh", None)
    assert cloud["track"] == "cloud"
    assert json.loads(cloud["provenance"]) == CLOUD
    view = submission_view(board, two_tracks["cloud"])
    assert (view["track"], view["provenance"]) == ("cloud", CLOUD)
    assert submission_view(board, two_tracks["mesh"])["track"] == "mesh"
    events = board.events(two_tracks["cloud"])
    assert "(cloud track)" in events[0]["message"]


def test_a_board_from_before_tracks_opens_and_its_rows_are_mesh(
    tmp_path: Path, bench: Path
) -> None:
    db = tmp_path / "old.db"
    conn = sqlite3.connect(db, isolation_level=None)
    assert migrate(conn, target=2) == [1, 2]
    setting = {"path": str(bench), "sha256": file_sha256(bench), "object_ids": ["a", "b", "c"]}
    conn.execute(
        "INSERT INTO settings VALUES ('benchmark', ?), ('evaluators', '[\"fce\"]'), "
        "('title', '\"old board\"'), ('created_at', '1.0')",
        (json.dumps({**setting, "mesh_root": None}),),
    )
    conn.execute("INSERT INTO teams VALUES (1, 'old team', ?, 1.0)", (token_sha256("x"),))
    for sid, score in ((1, 0.25), (2, 0.75)):
        conn.execute(
            "INSERT INTO submissions (id, team_id, file_sha256, size, filename, label, "
            "evaluators, created_at, status) VALUES (?, 1, ?, 10, 'f.h5', ?, '[\"fce\"]', ?, "
            "'scored')",
            (sid, f"{sid:064x}", f"old {sid}", float(sid)),
        )
        conn.execute(
            "INSERT INTO jobs (submission_id, state, queued_at, updated_at) "
            "VALUES (?, 'done', 1.0, 1.0)",
            (sid,),
        )
        result = json.dumps(FakeResult(score).to_dict())
        conn.execute("INSERT INTO results VALUES (?, 'fce', '1', ?, ?, 2.0)", (sid, score, result))
    conn.close()

    board = Board(db, create=False)
    conn = sqlite3.connect(db)
    assert schema_version(conn) == SCHEMA_VERSION == 3
    assert conn.execute("SELECT id, track, provenance FROM submissions").fetchall() == [
        (1, "mesh", None),
        (2, "mesh", None),
    ]
    conn.close()
    view = board_view(board)
    assert [(s["track"], s["name"]) for s in view["evaluators"]] == [("mesh", "fce")]
    assert [(r["submission"], r["rank"]) for r in view["evaluators"][0]["rows"]] == [(2, 1), (1, 2)]
    assert submission_view(board, 1)["track"] == "mesh"
    assert board.integrity_check() == "ok"


# --------------------------------------------------------------------------------------------
# Shown apart: views, API, static HTML, the command line
# --------------------------------------------------------------------------------------------


def sections_of(view: dict[str, Any]) -> dict[tuple[str, str], list[tuple[int, int]]]:
    """(track, evaluator) -> the section's (submission, rank) rows."""
    return {
        (s["track"], s["name"]): [(r["submission"], r["rank"]) for r in s["rows"]]
        for s in view["evaluators"]
    }


def test_views_rank_each_track_apart(two_tracks: dict[str, Any]) -> None:
    board, mesh, cloud, zero = (two_tracks[k] for k in ("board", "mesh", "cloud", "zero"))
    view = board_view(board)
    # ranked together, the score-0 row would be third; within the mesh track it is second
    assert sections_of(view) == {
        ("mesh", "fce"): [(mesh, 1), (zero, 2)],
        ("cloud", "fce"): [(cloud, 1)],
    }
    assert [t["name"] for t in view["tracks"]] == ["mesh", "cloud"]
    assert view["tracks"][1]["title"] == TRACK_INFO["cloud"].title
    assert view["tracks"][1]["self_declared"] is True
    (cloud_row,) = view["evaluators"][1]["rows"]
    assert cloud_row["provenance"] == CLOUD
    assert "provenance" not in view["evaluators"][0]["rows"][0]
    only = board_view(board, track="cloud")
    assert sections_of(only) == {("cloud", "fce"): [(cloud, 1)]}
    paged = board_view(board, page=1, limit=1)
    assert sections_of(paged) == {("mesh", "fce"): [(mesh, 1)], ("cloud", "fce"): [(cloud, 1)]}
    assert paged["page"]["pages"] == 2
    assert [s["total"] for s in paged["evaluators"]] == [2, 1]
    with pytest.raises(InvalidParameterError, match="expected track name 'mesh' or 'cloud'"):
        board_view(board, track="mesh,cloud")
    with pytest.raises(InvalidParameterError, match="expected track name"):
        board.scored_page("fce", 0, 10, track="all")


def test_the_api_shows_tracks_apart(two_tracks: dict[str, Any]) -> None:
    board, mesh, cloud, zero = (two_tracks[k] for k in ("board", "mesh", "cloud", "zero"))
    api = answer(StandingsRoutes(board).api_board)
    answered = asyncio.run(api(request("/api/board")))
    assert answered.status_code == 200
    view = json.loads(answered.body)
    assert view["version"] == 2
    assert sections_of(view) == {
        ("mesh", "fce"): [(mesh, 1), (zero, 2)],
        ("cloud", "fce"): [(cloud, 1)],
    }
    one = json.loads(asyncio.run(api(request("/api/board", "track=cloud&limit=1"))).body)
    assert sections_of(one) == {("cloud", "fce"): [(cloud, 1)]}
    mesh_pages = json.loads(asyncio.run(api(request("/api/board", "track=mesh&limit=1"))).body)
    assert mesh_pages["page"]["next"] == "/api/board?page=2&limit=1&track=mesh"
    for bad in ("track=both", "track=mesh&track=cloud"):
        refused = asyncio.run(api(request("/api/board", bad)))
        assert refused.status_code == 422, bad
        assert "expected" in json.loads(refused.body)["error"]
    page = asyncio.run(answer(SiteRoutes(board).index)(request("/", "track=cloud"))).body.decode()
    assert '<section id="track-cloud"' in page
    assert '<section id="track-mesh"' not in page


def index_sections(page: str) -> dict[str, str]:
    """A board page's track sections: track -> its HTML."""
    out = {}
    for part in page.split('<section id="track-')[1:]:
        name = part.split('"', 1)[0]
        out[name] = part
    return out


def test_static_html_shows_tracks_apart(two_tracks: dict[str, Any], tmp_path: Path) -> None:
    board, mesh, cloud, zero = (two_tracks[k] for k in ("board", "mesh", "cloud", "zero"))
    view = board_view(board)
    ids = [mesh, cloud, zero]
    out = write_static(tmp_path / "site", view, {i: submission_view(board, i) for i in ids})
    page = (out / "index.html").read_text()
    tracks = index_sections(page)
    assert list(tracks) == ["mesh", "cloud"]
    assert "Mesh track: predictors see the object&#x27;s mesh" in tracks["mesh"]
    assert "Cloud track: predictors see only the benchmark&#x27;s depth cameras" in tracks["cloud"]
    assert "self-declared" in tracks["cloud"]
    assert f'<tr data-submission="{mesh}">' in tracks["mesh"]
    assert f'<tr data-submission="{zero}">' in tracks["mesh"]
    assert f'<tr data-submission="{cloud}">' not in tracks["mesh"]
    assert tracks["cloud"].count("<tr data-submission=") == 1
    assert f'<tr data-submission="{cloud}">' in tracks["cloud"]
    assert '<table class="board" id="table-fce">' in tracks["mesh"]
    assert '<table class="board" id="table-cloud-fce">' in tracks["cloud"]
    assert 'id="chart-cloud-fce"' in tracks["cloud"]
    details = (out / "submissions" / f"{cloud}.html").read_text()
    provenance = details.split('<section class="provenance">')[1].split("</section>")[0]
    assert "Provenance (self-declared)" in provenance
    for text in ("<code>0123456789ab</code>", "default", "process", "Noise seed", "Cameras"):
        assert text in provenance
    assert CLOUD["predictor_sha256"] not in provenance  # shortened
    assert "Provenance" not in (out / "submissions" / f"{mesh}.html").read_text()
    assert json.loads((out / "board.json").read_text()) == view


def test_the_command_line_shows_tracks_apart(
    two_tracks: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    board, cloud = two_tracks["board"], two_tracks["cloud"]
    db = str(board.db)
    assert main(["leaderboard", "show", "--db", db]) == 0
    out = capsys.readouterr().out
    mesh_part, cloud_part = out.split("== Cloud track")
    assert "== Mesh track: predictors see the object's mesh" in mesh_part
    assert "lab-mesh" in mesh_part
    assert "lab-cloud" not in mesh_part
    assert f"cloud pairs #{cloud}" in cloud_part
    assert "lab-mesh" not in cloud_part
    assert "self-declared: noise default (seed 7) · cameras 2 · sandbox process" in cloud_part
    assert main(["leaderboard", "show", "--db", db, "--track", "cloud", "--json"]) == 0
    only = json.loads(capsys.readouterr().out)
    assert sections_of(only) == {("cloud", "fce"): [(cloud, 1)]}
    with pytest.raises(SystemExit) as refused:
        main(["leaderboard", "show", "--db", db, "--track", "both"])
    assert refused.value.code == 2
    assert "invalid choice: 'both'" in capsys.readouterr().err
    assert main(["leaderboard", "render", "--db", db, "--out", str(tmp_path / "html")]) == 0
    capsys.readouterr()
    assert (tmp_path / "html" / "submissions" / f"{cloud}.html").is_file()
    page = (tmp_path / "html" / "index.html").read_text()
    assert list(index_sections(page)) == ["mesh", "cloud"]


def test_an_empty_cloud_track_is_still_explained(tmp_path: Path, bench: Path) -> None:
    board = Board(tmp_path / "board.db", benchmark=bench, evaluators=("fce",))
    view = board_view(board)
    assert [s["track"] for s in view["evaluators"]] == ["mesh"]
    assert [(t["name"], t["shown"]) for t in view["tracks"]] == [("mesh", True), ("cloud", False)]
    out = write_static(tmp_path / "site", view, {})
    tracks = index_sections((out / "index.html").read_text())
    assert "No cloud-track submissions yet." in tracks["cloud"]
    assert "No scored submissions yet." in tracks["mesh"]


# --------------------------------------------------------------------------------------------
# In headless Chromium (skipped when it is not installed)
# --------------------------------------------------------------------------------------------


def test_tracks_apart_in_chromium(two_tracks: dict[str, Any], tmp_path: Path) -> None:
    from selenium.webdriver.common.by import By

    board, mesh, cloud, zero = (two_tracks[k] for k in ("board", "mesh", "cloud", "zero"))
    views = {i: submission_view(board, i) for i in (mesh, cloud, zero)}
    out = write_static(tmp_path / "site", board_view(board), views)
    driver = start_browser()
    try:
        driver.get((out / "index.html").as_uri())
        wait_for_script(driver)
        assert page_problems(driver) == []

        def rows(css: str) -> list[int]:
            found = driver.find_elements(By.CSS_SELECTOR, f"{css} tbody tr[data-submission]")
            return [int(r.get_attribute("data-submission")) for r in found]

        assert rows("#track-mesh #table-fce") == [mesh, zero]
        assert rows("#track-cloud #table-cloud-fce") == [cloud]
        assert rows("#track-mesh #table-cloud-fce") == []
        headings = [h.text for h in driver.find_elements(By.CSS_SELECTOR, "h2.track-title")]
        assert headings == [TRACK_INFO["mesh"].title, TRACK_INFO["cloud"].title]
        ranks = driver.find_elements(By.CSS_SELECTOR, "#table-cloud-fce td.rank")
        assert [r.text for r in ranks] == ["1"]
        # the mesh block is above the cloud block on the page, and they do not overlap
        mesh_box = driver.find_element(By.ID, "track-mesh").rect
        cloud_box = driver.find_element(By.ID, "track-cloud").rect
        assert mesh_box["y"] + mesh_box["height"] <= cloud_box["y"]
        screenshot(driver, tmp_path, "leaderboard_tracks.png")

        driver.find_element(
            By.CSS_SELECTOR, f'#table-cloud-fce a[href="submissions/{cloud}.html"]'
        ).click()
        wait_for_script(driver)
        assert page_problems(driver) == []
        cells = driver.find_elements(By.CSS_SELECTOR, "table.provenance td")
        shown = {c.text for c in cells}
        assert {"0123456789ab", "default", "process", "7", "2", "3", "1"} <= shown
        screenshot(driver, tmp_path, "leaderboard_cloud_submission.png")
    finally:
        driver.quit()


def test_only_cloud_rows_are_marked_self_declared() -> None:
    from leaderboard.page import render_index

    def section(track: str) -> dict[str, Any]:
        row = {"rank": 1, "submission": 1 if track == "mesh" else 2, "team": "t", "label": "x"}
        row.update(date="2026-01-01T00:00:00Z", metrics={}, per_family={})
        row["provenance"] = {"name": track, "predictor_sha256": "ab" * 32}
        return {"track": track, "name": "fce", "headline": "fce", "columns": ["fce"], "rows": [row]}

    page = render_index({"evaluators": [section("mesh"), section("cloud")]}, link=str, assets="")
    tracks = index_sections(page)
    assert "self-declared</span>" not in tracks["mesh"]
    assert tracks["cloud"].count('<span class="badge declared" title="noise not declared') == 1
    assert "predictor abababababab" in tracks["cloud"]


def test_over_http_a_cloud_upload_is_ranked_apart_and_a_bad_track_refused(
    tmp_path: Path, bench: Path
) -> None:
    """The service on loopback: uploads (a mesh file, a cloud file, a malformed track), a
    worker, then ``/api/board`` and ``/``."""
    import httpx

    from leaderboard.limits import ServiceConfig

    board = Board(tmp_path / "board.db", benchmark=bench, evaluators=("fce",))
    _, token = board.add_team("lab-a")
    mesh_file = valid_submission(tmp_path / "mesh.h5", bench, k=2, method="mesh pairs")
    cloud_file = tracked_submission(tmp_path / "cloud.h5", bench, CLOUD, method="cloud pairs")
    bad_file = tracked_submission(tmp_path / "bad.h5", bench, {"name": "mesh+cloud"})
    with running_service(board, ServiceConfig()) as (url, _):
        client = httpx.Client(
            base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=30.0
        )
        ids = {}
        for name, path in (("mesh", mesh_file), ("cloud", cloud_file)):
            answered = client.post(
                f"/api/submissions?filename={path.name}", content=path.read_bytes()
            )
            assert answered.status_code == 202, answered.text
            ids[name] = answered.json()["submission"]
        before = db_dump(board.db)
        refused = client.post("/api/submissions?filename=bad.h5", content=bad_file.read_bytes())
        assert refused.status_code == 422
        (problem,) = refused.json()["problems"]
        assert problem["place"] == "attrs/metadata"
        assert "mesh+cloud" in problem["message"]
        assert "'cloud'" in problem["message"]
        assert db_dump(board.db) == before
        assert run_worker(board, WorkerOptions(idle_exit_s=0.01, poll_s=0.01)) == 2
        view = client.get("/api/board").json()
        assert sections_of(view) == {
            ("mesh", "fce"): [(ids["mesh"], 1)],
            ("cloud", "fce"): [(ids["cloud"], 1)],
        }
        page = client.get("/").text
        tracks = index_sections(page)
        assert f'<tr data-submission="{ids["cloud"]}">' in tracks["cloud"]
        assert f'<tr data-submission="{ids["cloud"]}">' not in tracks["mesh"]
        details = client.get(f"/submissions/{ids['cloud']}").text
        assert "Provenance (self-declared)" in details
        assert client.get("/api/board?track=all").status_code == 422
        client.close()


def test_a_result_of_another_track_is_refused(tmp_path: Path, bench: Path) -> None:
    class OtherTrack(FakeResult):
        def to_dict(self) -> dict[str, Any]:
            return {**super().to_dict(), "subject": {"kind": "submission", "track": "cloud"}}

    board = Board(tmp_path / "board.db", benchmark=bench, evaluators=("fce",))
    team, _ = board.add_team("lab-a")
    sid = board.jobs.enqueue(NewSubmission(team.id, team.name, "f" * 64, 1, "a.h5", "a", ["fce"]))
    claim = board.claim("w", 60.0, submission_id=sid)
    assert claim is not None
    with pytest.raises(BoardError, match="expected a result of a mesh-track submission"):
        board.finish(claim, {"fce": OtherTrack(0.5)}, "")
    assert board.submission_row(sid)["status"] == "running"
    assert board.finish(claim, {"fce": FakeResult(0.5)}, "")
