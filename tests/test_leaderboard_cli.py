"""The ``dg16m leaderboard`` command line, round trip: init, team add/list/token, submit
(scored in process, and queued for a worker), show, status, render, and the static export in
headless Chromium; errors exit 2 with one line."""

from __future__ import annotations

import json
import stat
from pathlib import Path
from typing import Any

import pytest
from browser import console_log, order, page_problems, screenshot, start_browser, wait_for_script
from leaderboard_data import db_dump, small_benchmark, valid_submission

from dg16m_core.cli import main
from leaderboard.board import Board


def run(capsys: pytest.CaptureFixture[str], *args: Any) -> tuple[int, str, str]:
    code = main(["leaderboard", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return small_benchmark(tmp_path_factory.mktemp("bench") / "bench3.h5")


def test_round_trip(capsys: pytest.CaptureFixture[str], tmp_path: Path, bench: Path) -> None:
    db = tmp_path / "board.db"
    code, out, _ = run(capsys, "init", "--db", db, "--benchmark", bench, "--evaluators", "fce")
    assert code == 0
    assert "3 objects" in out
    assert "evaluators fce" in out
    code, _, err = run(capsys, "init", "--db", db, "--benchmark", bench)
    assert code == 2
    assert "a board exists there" in err

    token_file = tmp_path / "lab-a.token"
    code, out, _ = run(capsys, "team", "add", "lab-a", "--db", db, "--token-file", token_file)
    assert code == 0
    assert stat.S_IMODE(token_file.stat().st_mode) == 0o600
    token = token_file.read_text().strip()
    assert token not in out
    assert Board(db).authenticate(token).name == "lab-a"
    code, _, err = run(capsys, "team", "add", "lab-c", "--db", db, "--token-file", token_file)
    assert code == 2
    assert "expected a new file" in err
    assert [t.name for t in Board(db).teams()] == ["lab-a"]  # refused before the team was made
    assert token_file.read_text().strip() == token
    code, out, _ = run(capsys, "team", "add", "lab-b", "--db", db)
    assert code == 0
    assert "shown once" in out
    token_b = out.strip().splitlines()[-1]
    assert Board(db).authenticate(token_b).name == "lab-b"
    code, out, _ = run(capsys, "team", "token", "lab-b", "--db", db)
    assert Board(db).authenticate(token_b) is None
    code, out, _ = run(capsys, "team", "list", "--db", db)
    assert [line.split()[0] for line in out.splitlines()] == ["lab-a", "lab-b"]

    first = valid_submission(tmp_path / "first.h5", bench, k=2, method="pairs")
    second = valid_submission(tmp_path / "second.h5", bench, k=1, offset=11)
    code, out, _ = run(capsys, "submit", first, "--team", "lab-a", "--db", db)
    assert code == 0
    assert "#1 pairs (lab-a): scored" in out
    assert "fce" in out
    assert "fce v1: scoring" in out  # the scoring log as it is written, not silence
    code, out, _ = run(
        capsys, "submit", second, "--team", "lab-b", "--db", db, "--queue-only", "--label", "one"
    )
    assert code == 0
    assert "#2 stored and queued" in out
    code, out, _ = run(capsys, "status", "--db", db)
    assert "1 queued" in out
    assert "#2 lab-b/one: queued" in out
    code, out, _ = run(capsys, "worker", "--db", db, "--max-jobs", "1", "--poll", "0.1")
    assert code == 0
    assert "#2: scored" in out
    code, out, _ = run(capsys, "status", "2", "--db", db)
    assert "#2 one (lab-b): scored" in out
    assert "events:" in out
    assert "log:" in out

    code, out, _ = run(capsys, "show", "--db", db)
    assert code == 0
    assert "2 teams, 2 submissions" in out
    assert "fce (ranked by fce)" in out
    assert "pairs #1" in out
    assert "one #2" in out
    code, out, _ = run(capsys, "show", "--db", db, "--json")
    view = json.loads(out)
    assert [len(s["rows"]) for s in view["evaluators"]] == [2]
    code, _, err = run(capsys, "show", "--db", db, "--evaluator", "gsr")
    assert code == 2
    assert "expected one of fce" in err

    before = db_dump(db)
    code, _, err = run(capsys, "submit", first, "--team", "lab-a", "--db", db)
    assert code == 2
    assert "already submitted as #1" in err
    code, _, err = run(capsys, "submit", first, "--team", "nobody", "--db", db)
    assert code == 2
    assert "lab-a, lab-b" in err
    bad = tmp_path / "bad.h5"
    bad.write_text("not a submission")
    code, _, err = run(capsys, "submit", bad, "--team", "lab-a", "--db", db)
    assert code == 2
    assert "without the HDF5 signature" in err
    assert db_dump(db) == before

    site = tmp_path / "site"
    code, out, _ = run(capsys, "render", "--db", db, "--out", site)
    assert code == 0
    assert "2 submission pages" in out
    assert sorted(p.name for p in (site / "submissions").iterdir()) == ["1.html", "2.html"]
    assert json.loads((site / "board.json").read_text())["format"] == "dg16m-leaderboard"
    assert not [p for p in site.rglob("*") if ".tmp" in p.name]

    driver = start_browser()
    try:
        console_log(driver)
        driver.get((site / "index.html").as_uri())
        wait_for_script(driver)
        assert page_problems(driver) == []
        assert order(driver, "table-fce") == [
            r["submission"] for r in view["evaluators"][0]["rows"]
        ]
        from selenium.webdriver.common.by import By

        team = driver.find_element(By.CSS_SELECTOR, "#table-fce thead th:nth-child(2)")
        team.click()
        team.click()  # descending: lab-b first
        assert order(driver, "table-fce") == [2, 1]
        screenshot(driver, tmp_path, "leaderboard_static.png")
    finally:
        driver.quit()


def test_missing_board_and_bad_arguments(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    for args in (("show",), ("status",), ("render", "--out", tmp_path / "x"), ("worker",)):
        code, _, err = run(capsys, *args, "--db", tmp_path / "none.db")
        assert code == 2
        assert "found nothing at" in err
    assert not (tmp_path / "none.db").exists()
    code, _, err = run(capsys, "submit", tmp_path / "x.h5", "--db", tmp_path / "b.db")
    assert code == 2
    assert "--team" in err
    monkeypatch.delenv("DG16M_TOKEN", raising=False)
    code, _, err = run(capsys, "submit", tmp_path / "x.h5", "--url", "http://127.0.0.1:9")
    assert code == 2
    assert "expected the team's token" in err
    monkeypatch.setenv("DG16M_TOKEN", "dg16m_" + "x" * 43)
    code, _, err = run(capsys, "submit", tmp_path / "x.h5", "--url", "ftp://x")
    assert code == 2
    assert "expected http(s)://host:port" in err


def test_baseline_entries_script(tmp_path: Path, bench: Path) -> None:
    """scripts/leaderboard_baselines.py puts the reference submissions on a board, scored,
    and a second run adds nothing."""
    import subprocess
    import sys

    script = Path(__file__).resolve().parents[1] / "scripts" / "leaderboard_baselines.py"
    db = tmp_path / "board.db"
    command = [sys.executable, str(script), "--db", str(db), "--benchmark", str(bench)]
    command += ["--k", "2", "--evaluators", "fce", "--no-progress"]
    first = subprocess.run(command, capture_output=True, text=True, timeout=300, check=False)
    assert first.returncode == 0, first.stdout + first.stderr
    board = Board(db, create=False)
    rows = board.submissions()
    assert sorted(r["label"] for r in rows) == [
        "baseline: benchmark_fc_pass",
        "baseline: farthest",
        "baseline: force_closure",
        "baseline: random",
    ]
    assert {r["status"] for r in rows} == {"scored"}
    assert stat.S_IMODE((tmp_path / "baselines.token").stat().st_mode) == 0o600
    before = db_dump(db)
    again = subprocess.run(command, capture_output=True, text=True, timeout=300, check=False)
    assert again.returncode == 0, again.stdout + again.stderr
    assert again.stdout.count("skipped") == 4
    assert db_dump(db) == before


def test_baseline_entries_script_submits_predictors(tmp_path: Path, bench: Path) -> None:
    """``--predictors`` runs each module:callable predictor (here the point-cloud random-rank
    control) and puts its submission on the board; ``--strategies ''`` leaves the pairing
    references out; a second run adds nothing."""
    import subprocess
    import sys

    script = Path(__file__).resolve().parents[1] / "scripts" / "leaderboard_baselines.py"
    db = tmp_path / "board.db"
    command = [sys.executable, str(script), "--db", str(db), "--benchmark", str(bench)]
    command += ["--k", "2", "--evaluators", "fce", "--no-progress", "--strategies", ""]
    command += ["--predictors", "baselines.cloud_predictor:random_predictor"]
    first = subprocess.run(command, capture_output=True, text=True, timeout=300, check=False)
    assert first.returncode == 0, first.stdout + first.stderr
    assert "random_predictor: wrote" in first.stdout
    rows = Board(db, create=False).submissions()
    assert [(r["label"], r["status"]) for r in rows] == [("baseline: random_predictor", "scored")]
    before = db_dump(db)
    again = subprocess.run(command, capture_output=True, text=True, timeout=300, check=False)
    assert again.returncode == 0, again.stdout + again.stderr
    assert again.stdout.count("skipped") == 1
    assert db_dump(db) == before
