"""The leaderboard's HTML pages (leaderboard/page.py): escaping, empty boards and missing values,
the static export, and, in headless Chromium when installed, a clean load, sorting by clicking
headers and the detail pages."""

from __future__ import annotations

import copy
import html
import json
from collections.abc import Iterator
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import pytest
from browser import console_log, order, page_problems, screenshot, start_browser, wait_for_script

from leaderboard.page import ASSETS, asset_text, render_index, render_submission, write_static

HOSTILE_TEAM = "<script>alert(1)</script>"
QUOTES = '"quotes" & ampersands'
HOSTILE_LABEL = "<img src=x onerror=alert(2)>"
HOSTILE_OBJECT = "<b>obj</b>"
HOSTILE_METRIC = "<i>metric</i>"


# --------------------------------------------------------------------------------------------
# Data: one real fce result on three benchmark objects, and board / submission views around it


@pytest.fixture(scope="module")
def fce_result(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A real ``EvaluationResult.to_dict()`` of fce (3 objects, 3 grasps each; about 1 s)."""
    from dg16m_env.benchmark.file import read_benchmark, write_benchmark
    from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK
    from dg16m_env.evaluators import load_benchmark_ref, make
    from dg16m_env.subjects.submission_writer import write_submission

    tmp = tmp_path_factory.mktemp("fce")
    bench = read_benchmark(EMBEDDED_BENCHMARK)
    ids = [o.object_id for o in bench.objects][:3]
    small = bench.select_objects(ids)
    write_benchmark(tmp / "b3.h5", small)
    ref = load_benchmark_ref(tmp / "b3.h5")
    poses = {i: small.poses[small.object_rows(i)[:3]] for i in ids}
    write_submission(tmp / "s3.h5", poses, benchmark=ref.sha256)
    return make("fce", benchmark=ref, progress=False).evaluate(tmp / "s3.h5").to_dict()


def rate(value: float | None, rows: int = 9, objects: int = 3) -> dict[str, Any]:
    """A rate dict with a made-up interval around ``value``."""
    if value is None:
        return {"rate": None, "ci_low": None, "ci_high": None, "rows": 0, "objects": 0}
    low, high = max(value - 0.04, 0.0), min(value + 0.03, 1.0)
    return {"rate": value, "ci_low": low, "ci_high": high, "rows": rows, "objects": objects}


#: (submission, team, label, fce rate) in rank order; two rows tie, the last has no score.
ROWS = [
    (3, "baselines", "force_closure", 0.997),
    (5, HOSTILE_TEAM, QUOTES, 0.91),
    (7, QUOTES, HOSTILE_LABEL, 0.85),
    (2, "Zeta", "random", 0.42),
    (9, "alpha", "ties", 0.42),
    (11, "baselines", "nothing", None),
]


@pytest.fixture(scope="module")
def board_view(fce_result: dict[str, Any]) -> dict[str, Any]:
    """A board with fce (6 rows), gsr (an unknown column, None rates) and an empty evaluator."""
    families = sorted(fce_result["per_family"])
    fce_rows = []
    for rank, (submission, team, label, value) in enumerate(ROWS, start=1):
        per_family = {
            f: rate(None if value is None else max(value - 0.1 * k, 0.0), 3, 1)
            for k, f in enumerate(families)
        }
        fce_rows.append(
            {
                "rank": rank,
                "submission": submission,
                "team": team,
                "label": label,
                "date": f"2026-11-{10 + rank:02d}T06:10:00Z",
                "evaluator_version": "1",
                "metrics": {"fce": rate(value)},
                "per_family": per_family,
            }
        )
    gsr_rows = [
        {
            "rank": 1,
            "submission": 3,
            "team": "baselines",
            "label": "force_closure",
            "date": "2026-11-11T06:10:00Z",
            "evaluator_version": "2",
            "metrics": {"gsr": rate(0.5), "gsr_gravity": rate(None), "mean_force": 12.345678},
            "per_family": {},
        },
        {
            "rank": 2,
            "submission": 5,
            "team": HOSTILE_TEAM,
            "label": QUOTES,
            "date": "2026-11-12T06:10:00Z",
            "evaluator_version": "2",
            "metrics": {"gsr": rate(0.25)},
            "per_family": {"bench": rate(0.3)},
        },
    ]
    return {
        "format": "dg16m-leaderboard",
        "version": 1,
        "title": "dg16m leaderboard",
        "generated_at": "2026-11-30T06:40:00Z",
        "benchmark": {"sha256": fce_result["benchmark"]["sha256"], "objects": 3, "embedded": True},
        "counts": {"teams": 5, "submissions": 7, "scored": 6, "queued": 1, "running": 0},
        "evaluators": [
            {
                "name": "fce",
                "headline": "fce",
                "columns": ["fce"],
                "families": families,
                "rows": fce_rows,
            },
            {
                "name": "gsr",
                "headline": "gsr",
                "columns": ["gsr", "gsr_gravity", "mean_force", HOSTILE_METRIC],
                "families": ["bench", "crate"],
                "rows": gsr_rows,
            },
            {"name": "empty", "headline": "x", "columns": ["x"], "families": [], "rows": []},
        ],
    }


@pytest.fixture(scope="module")
def submission_views(fce_result: dict[str, Any]) -> dict[int, dict[str, Any]]:
    """A detail view per row; submission 5's is its team's private view with a hostile log."""
    result = copy.deepcopy(fce_result)
    result["per_object"][HOSTILE_OBJECT] = {"grasps": 0, "fce": None}
    result["failures"] = {HOSTILE_OBJECT: "mesh <broken> & bad"}
    views: dict[int, dict[str, Any]] = {}
    for rank, (submission, team, label, value) in enumerate(ROWS, start=1):
        views[submission] = {
            "id": submission,
            "team": team,
            "label": label,
            "filename": f"{label}.h5",
            "date": f"2026-11-{10 + rank:02d}T06:10:00Z",
            "status": "scored" if value is not None else "failed",
            "file_sha256": "ab" * 32,
            "size": 123456,
            "evaluators": ["fce", "gsr"],
            "results": {"fce": result} if value is not None else {},
        }
    views[5].update(
        private=True,
        error="worker <lost> & retried",
        attempts=2,
        log="line 1\n</pre><script>alert(3)</script>\nline 3",
        events=[
            {"at": "2026-11-12T06:10:01Z", "state": "running", "worker": "host:1", "message": "x"},
            {"at": "2026-11-12T06:11:01Z", "state": "scored", "worker": "host:1", "message": ""},
        ],
    )
    return views


# --------------------------------------------------------------------------------------------
# HTML checks without a browser


class Tags(HTMLParser):
    """The start tags of a page and the text inside its script elements."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.script_text: list[str] = []
        self._in_script = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, dict(attrs)))
        self._in_script = tag == "script"

    def handle_endtag(self, tag: str) -> None:
        if tag == "script":
            self._in_script = False

    def handle_data(self, data: str) -> None:
        if self._in_script and data.strip():
            self.script_text.append(data)


def check_csp_clean(page: str) -> Tags:
    """No inline script, event handler, style attribute or element; no injected tags."""
    tags = Tags()
    tags.feed(page)
    names = [tag for tag, _ in tags.tags]
    assert "style" not in names
    assert "img" not in names
    assert "b" not in names
    assert "i" not in names
    assert not tags.script_text
    for tag, attrs in tags.tags:
        assert "style" not in attrs, tag
        assert not [a for a in attrs if a.startswith("on")], (tag, attrs)
        if tag == "script":
            assert attrs.get("src", "").endswith("board.js")
            assert "defer" in attrs
    return tags


def test_hostile_strings_appear_only_escaped(
    board_view: dict[str, Any], submission_views: dict[int, dict[str, Any]]
) -> None:
    index = render_index(board_view, link=lambda i: f"submissions/{i}.html", assets="assets/")
    details = [
        render_submission(v, board_link="../index.html", assets="../assets/")
        for v in submission_views.values()
    ]
    for page in [index, *details]:
        check_csp_clean(page)
        assert "<script>alert" not in page
        assert "<img src" not in page
        assert "<b>obj" not in page
        assert "<i>metric" not in page
        assert "</pre><script>" not in page
    assert html.escape(HOSTILE_TEAM, quote=True) in index
    assert html.escape(QUOTES, quote=True) in index  # &quot;quotes&quot; &amp; ampersands
    assert html.escape(HOSTILE_LABEL, quote=True) in index
    assert html.escape(HOSTILE_METRIC, quote=True) in index
    private = render_submission(submission_views[5], board_link="/", assets="/assets/")
    assert html.escape("</pre><script>alert(3)</script>") in private
    assert html.escape(HOSTILE_OBJECT) in private
    assert html.escape("mesh <broken> & bad") in private


def test_index_structure(board_view: dict[str, Any]) -> None:
    page = render_index(board_view, link=lambda i: f"/submissions/{i}", assets="/assets/")
    assert 'href="/assets/board.css"' in page
    assert 'src="/assets/board.js"' in page
    assert 'href="/submissions/3"' in page
    assert board_view["benchmark"]["sha256"][:12] in page
    for ev in board_view["evaluators"]:
        assert f'<section id="ev-{ev["name"]}"' in page
    assert page.count('<tr data-submission="') == 6 + 2
    assert '<table class="board" id="table-fce">' in page
    assert "99.7%" in page
    assert '<span class="ci">[95.7, 100.0]</span>' in page
    assert 'data-value="0.997"' in page
    assert page.count("<svg") == 2  # fce and gsr; none for the empty evaluator
    # a bar per family and charted submission that has a rate (the top 5 by rank)
    fce = board_view["evaluators"][0]
    drawn = sum(
        1
        for row in fce["rows"][:5]
        for family in fce["families"]
        if row["per_family"][family]["rate"] is not None
    )
    chart = page[page.index('id="chart-fce"') : page.index("</svg>", page.index('id="chart-fce"'))]
    assert drawn > 0
    assert chart.count('<rect class="bar ') == drawn
    assert 'role="img"' in page
    assert "<title" in page


def test_empty_board_and_missing_values(board_view: dict[str, Any]) -> None:
    page = render_index(board_view, link=lambda i: f"s/{i}", assets="")
    empty = page.split('<section id="ev-empty"')[1]
    assert "No scored submissions yet." in empty
    assert "<svg" not in empty
    gsr = page.split('<section id="ev-gsr"')[1].split("</table>")[0]
    rows = gsr.split("<tr data-submission=")[1:]
    # gsr_gravity's None rate, and the unknown metric: a dash with an empty data-value
    first = rows[0]
    assert first.count('data-value="">\u2014</td>') == 2
    assert "12.35" in first  # a plain number: 4 significant digits
    assert rows[1].count('data-value="">\u2014</td>') == 3
    # the fce row with no score
    fce = page.split('<section id="ev-fce"')[1].split("</table>")[0]
    assert fce.split('<tr data-submission="11">')[1].count('data-value="">\u2014') == 1

    nothing = dict(board_view, evaluators=[dict(board_view["evaluators"][0], rows=[])])
    page = render_index(nothing, link=str, assets="")
    assert "No scored submissions yet." in page
    assert "<svg" not in page
    assert "<table" not in page


def test_submission_page(
    fce_result: dict[str, Any], submission_views: dict[int, dict[str, Any]]
) -> None:
    page = render_submission(submission_views[3], board_link="/", assets="/assets/")
    check_csp_clean(page)
    assert 'href="/"' in page
    assert "force_closure" in page
    assert "#3" in page
    assert "120.6 KiB" in page
    assert "ab" * 32 in page
    assert fce_result["benchmark"]["sha256"] in page
    assert '<span class="version">v1</span>' in page
    assert page.count("<tr data-object=") == len(fce_result["per_object"]) + 1
    assert 'id="objects-fce"' in page
    assert 'id="families-fce"' in page
    assert '<p class="empty">No result.</p>' in page  # gsr was not run
    queued = dict(submission_views[11], status="queued")
    assert "Not scored yet (queued)." in render_submission(queued, board_link="/", assets="")
    assert "Processing" not in page
    assert "<pre" not in page
    private = render_submission(submission_views[5], board_link="/", assets="/assets/")
    assert "Processing" in private
    assert '<pre class="log">' in private
    assert "worker &lt;lost&gt; &amp; retried" in private
    assert private.count("host:1") == 2
    failed = render_submission(submission_views[11], board_link="/", assets="/assets/")
    assert "status-failed" in failed


def test_assets() -> None:
    assert set(ASSETS) == {"board.css", "board.js"}
    assert "th.sortable" in asset_text("board.css")
    assert "aria-sort" in asset_text("board.js")
    for bad in ("nope.css", "../page.py", "static/board.css"):
        with pytest.raises(ValueError, match="asset"):
            asset_text(bad)


def test_write_static(
    tmp_path: Path, board_view: dict[str, Any], submission_views: dict[int, dict[str, Any]]
) -> None:
    out = tmp_path / "site"
    assert write_static(out, board_view, submission_views) == out
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    expected = ["assets/board.css", "assets/board.js", "board.json", "index.html"]
    expected += [f"submissions/{i}.html" for i in submission_views]
    assert files == sorted(expected)
    assert not [p for p in out.rglob("*") if p.name.startswith(".")]  # no temporary files
    assert json.loads((out / "board.json").read_text(encoding="utf-8")) == board_view
    assert (out / "assets" / "board.js").read_text(encoding="utf-8") == asset_text("board.js")
    index = (out / "index.html").read_text(encoding="utf-8")
    assert 'href="assets/board.css"' in index
    assert 'href="submissions/3.html"' in index
    detail = (out / "submissions" / "3.html").read_text(encoding="utf-8")
    assert 'href="../assets/board.css"' in detail
    assert 'href="../index.html"' in detail
    # Written again (e.g. after a new result): same files, still no leftovers.
    write_static(out, board_view, submission_views)
    assert not [p for p in out.rglob("*") if p.name.startswith(".")]
    bad_ids: Any = {"../x": submission_views[3]}
    with pytest.raises(ValueError, match="submission id"):
        write_static(tmp_path / "bad", board_view, bad_ids)


# --------------------------------------------------------------------------------------------
# In headless Chromium (skipped when it is not installed)


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """A headless Chromium driver shared by this file's browser tests."""
    driver = start_browser()
    yield driver
    driver.quit()


def test_in_chromium(
    browser: Any,
    tmp_path: Path,
    board_view: dict[str, Any],
    submission_views: dict[int, dict[str, Any]],
    fce_result: dict[str, Any],
) -> None:
    from selenium.webdriver.common.by import By

    out = write_static(tmp_path / "site", board_view, submission_views)
    console_log(browser)  # empty the log
    browser.get((out / "index.html").as_uri())
    wait_for_script(browser)
    assert page_problems(browser) == []
    assert browser.title == "dg16m leaderboard"

    # Every row is shown, with the hostile strings as plain text.
    for ev in board_view["evaluators"]:
        assert len(order(browser, f"table-{ev['name']}")) == len(ev["rows"])
    cells = browser.find_elements(By.CSS_SELECTOR, "#table-fce td.team")
    assert [c.text for c in cells] == [team for _, team, _, _ in ROWS]
    assert browser.find_elements(By.CSS_SELECTOR, "#ev-empty p.empty")
    assert screenshot(browser, tmp_path, "leaderboard_index.png").stat().st_size > 10_000

    # Team: alphabetical (case-insensitive, ties in rank order), then reversed.
    served = [submission for submission, *_ in ROWS]
    team_of = {submission: team for submission, team, _, _ in ROWS}
    team = browser.find_element(By.CSS_SELECTOR, "#table-fce thead th:nth-child(2)")
    assert team.text.startswith("Team")
    team.click()
    assert order(browser, "table-fce") == sorted(served, key=lambda s: team_of[s].casefold())
    assert team.get_attribute("aria-sort") == "ascending"
    team.click()
    expected = sorted(served, key=lambda s: team_of[s].casefold(), reverse=True)
    assert order(browser, "table-fce") == expected
    assert team.get_attribute("aria-sort") == "descending"
    rank = browser.find_element(By.CSS_SELECTOR, "#table-fce thead th:nth-child(1)")
    assert rank.get_attribute("aria-sort") is None

    # The rate: best first on the first click, then ascending; the unscored row stays last.
    fce = browser.find_element(By.CSS_SELECTOR, "#table-fce thead th:nth-child(4)")
    fce.click()
    assert order(browser, "table-fce") == [3, 5, 7, 2, 9, 11]
    assert fce.get_attribute("aria-sort") == "descending"
    fce.click()
    assert order(browser, "table-fce") == [2, 9, 7, 5, 3, 11]
    assert fce.get_attribute("aria-sort") == "ascending"
    # Keyboard: Enter on the focused Rank header goes back to rank order.
    from selenium.webdriver.common.keys import Keys

    rank.send_keys(Keys.ENTER)
    assert order(browser, "table-fce") == served
    assert page_problems(browser) == []

    # A detail page: per-object rows, the evaluator version; its sortable object table.
    browser.find_element(By.CSS_SELECTOR, '#table-fce a[href="submissions/3.html"]').click()
    wait_for_script(browser)
    assert browser.current_url.endswith("/submissions/3.html")
    assert page_problems(browser) == []
    objects = browser.find_elements(By.CSS_SELECTOR, "#objects-fce tbody tr[data-object]")
    assert len(objects) == len(fce_result["per_object"]) + 1
    assert browser.find_element(By.CSS_SELECTOR, "#ev-fce h2 .version").text == "v1"
    ids = [r.get_attribute("data-object") for r in objects]
    assert HOSTILE_OBJECT in ids
    browser.find_element(By.CSS_SELECTOR, "#objects-fce thead th:nth-child(1)").click()
    rows = browser.find_elements(By.CSS_SELECTOR, "#objects-fce tbody tr[data-object]")
    assert next(r.get_attribute("data-object") for r in rows) == max(ids, key=str.casefold)
    screenshot(browser, tmp_path, "leaderboard_submission.png")
    browser.find_element(By.CSS_SELECTOR, "nav.back a").click()
    assert browser.current_url.endswith("/index.html")

    # The team's private view: the log shows as text.
    browser.get((out / "submissions" / "5.html").as_uri())
    wait_for_script(browser)
    assert "</pre><script>alert(3)</script>" in browser.find_element(By.CSS_SELECTOR, "pre").text
    assert page_problems(browser) == []
    screenshot(browser, tmp_path, "leaderboard_private.png")


CSP = "default-src 'none'; style-src 'self'; script-src 'self'; img-src 'self' data:"


@pytest.fixture
def csp_server(tmp_path: Path) -> Iterator[tuple[str, Path]]:
    """A local HTTP server of ``tmp_path/site`` that sends the service's Content-Security-Policy:
    ``(base URL, folder)``."""
    import functools
    import http.server
    import threading

    class Handler(http.server.SimpleHTTPRequestHandler):
        def end_headers(self) -> None:
            self.send_header("Content-Security-Policy", CSP)
            super().end_headers()

        def log_message(self, format: str, *args: Any) -> None:  # quiet
            pass

    site = tmp_path / "site"
    site.mkdir()
    handler = functools.partial(Handler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}", site
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=5)


def test_in_chromium_under_csp(
    browser: Any,
    csp_server: tuple[str, Path],
    board_view: dict[str, Any],
    submission_views: dict[int, dict[str, Any]],
) -> None:
    """Served with the service's Content-Security-Policy: no violation, the script runs."""
    from selenium.webdriver.common.by import By

    base, site = csp_server
    write_static(site, board_view, submission_views)
    console_log(browser)
    for page in ("index.html", "submissions/5.html"):
        browser.get(f"{base}/{page}")
        wait_for_script(browser)
        assert page_problems(browser) == []
    browser.get(f"{base}/index.html")
    wait_for_script(browser)
    team = browser.find_element(By.CSS_SELECTOR, "#table-fce thead th:nth-child(2)")
    team.click()
    assert team.get_attribute("aria-sort") == "ascending"
    assert page_problems(browser) == []


def test_the_gsr_table_fits_a_1400_pixel_window(
    browser: Any, tmp_path: Path, board_view: dict[str, Any]
) -> None:
    """All five gsr columns and the date stay in view at 1400 px (the date was cut off)."""
    import copy

    columns = ["gsr", "gsr_gravity", "gsr_valid", "gsr_valid_gravity", "label_rate"]
    view = copy.deepcopy(board_view)
    gsr = next(ev for ev in view["evaluators"] if ev["name"] == "gsr")
    gsr["columns"] = columns
    for row in gsr["rows"]:
        row["label"] = "force-closure pairing"
        row["metrics"] = {c: rate(0.628, 20, 4) for c in columns}
    out = write_static(tmp_path / "site", view, {})
    browser.set_window_size(1400, 900)
    browser.get((out / "index.html").as_uri())
    widths = browser.execute_script(
        "const t = document.querySelector('#ev-gsr table');"
        "return [t.scrollWidth, t.parentElement.clientWidth];"
    )
    assert widths[0] <= widths[1], widths
    date = browser.execute_script("return document.querySelector('#ev-gsr td.date time').title")
    assert date == "2026-11-11 06:10 UTC"  # the minute stays in the tooltip


def test_counts_read_in_the_singular_for_one() -> None:
    from leaderboard.page import _counts_line

    line = _counts_line({"teams": 1, "submissions": 1, "scored": 1})
    assert ">1 team<" in line
    assert ">1 submission<" in line
    assert ">2 teams<" in _counts_line({"teams": 2})


def gsr_parameters() -> dict[str, Any]:
    """The ``parameters`` of a gsr result on the shipped benchmark, built as the gsr evaluator
    builds them (no simulation), plus one long JSON list."""
    from dg16m_env.benchmark.file import read_benchmark
    from dg16m_env.benchmark.names import EMBEDDED_BENCHMARK

    params = read_benchmark(EMBEDDED_BENCHMARK).parameters()
    return {
        "perturbation": params.perturbation.to_dict(),
        "scene": {**params.scene.to_dict(), "long_list": list(range(0, 2000, 37))},
        "protocol": params.protocol.to_dict(),
    }


@pytest.mark.parametrize("width", [1280, 420])
def test_parameter_values_wrap_at_words_in_chromium(
    browser: Any, tmp_path: Path, fce_result: dict[str, Any], width: int
) -> None:
    """Issue 43: a gsr result's Parameters table drew each value one character per line (a
    value cell that may break anywhere shrank to one character next to the long keys). Each
    value now keeps a usable width: a short one on one line, a long JSON list broken at its
    commas into a few lines, on a desktop and a phone-sized window."""
    result = copy.deepcopy(fce_result)
    result.update(evaluator="gsr", headline="fce", parameters=gsr_parameters())
    view = {"id": 1, "team": "t", "label": "gsr", "status": "scored", "results": {"gsr": result}}
    out = write_static(tmp_path / "site", {"evaluators": []}, {1: view})
    browser.set_window_size(width, 900)
    try:
        browser.get((out / "submissions" / "1.html").as_uri())
        # A value's lines: the line boxes of its inline <code> (one rectangle per line).
        cells = browser.execute_script(
            """const box = Array.from(document.querySelectorAll('#ev-gsr .records > div'))
                .find(div => div.querySelector('h3').textContent === 'Parameters');
            return Array.from(box.querySelectorAll('table.kv tr')).map(tr => {
              const td = tr.querySelector('td');
              return {key: tr.querySelector('th').textContent, text: td.textContent,
                      width: td.getBoundingClientRect().width,
                      lines: td.querySelector('code').getClientRects().length};
            })"""
        )
        if width == 1280:
            screenshot(browser, tmp_path, "leaderboard_gsr_parameters.png")
    finally:
        browser.set_window_size(1280, 900)
    assert len(cells) >= 30
    assert "scene.solimp" in [c["key"] for c in cells]
    for cell in cells:
        assert cell["width"] >= 120, cell  # was 27 px: one character
        if len(cell["text"]) <= 24:  # "[0.95, 0.99, 0.001]", "0.0001", "null"
            assert cell["lines"] == 1, cell
    long = next(c for c in cells if c["key"] == "scene.long_list")
    # ~300 characters: a few lines broken at ", " (was one line per character).
    assert 1 <= long["lines"] <= (3 if width == 1280 else 20), long
