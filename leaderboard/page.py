"""The leaderboard's web pages: HTML rendered server-side from plain dicts ("views").

Everything a reader sees is in the HTML: tables, and bar charts as inline SVG. ``board.js`` only
adds sorting (click a column header); ``board.css`` the look. The pages hold no inline script,
event handler or ``style`` attribute, so they work under the service's Content-Security-Policy
(``default-src 'none'; style-src 'self'; script-src 'self'; img-src 'self' data:``) and opened
from ``file://`` with no network (:func:`write_static`).

Every string that comes from a view (team names, labels, file names, metric names, object ids,
log lines) goes through :func:`html.escape` with ``quote=True`` before it reaches the page.

The views (built by ``leaderboard.views``):

* board view: ``{"title", "generated_at", "benchmark": {"sha256", "objects", ...}, "counts",
  "tracks": [{"name", "title", "self_declared", ...}], "evaluators": [{"track", "name",
  "headline", "columns", "families", "rows": [{"rank", "submission", "team", "label", "date",
  "metrics", "per_family", "provenance" (cloud), ...}]}]}`` (a view without ``"tracks"`` or a
  section without ``"track"`` is mesh track);
* submission view: ``{"id", "team", "label", "filename", "date", "status", "track",
  "provenance", "file_sha256", "size", "evaluators", "results": {name:
  EvaluationResult.to_dict()}}``, plus ``"private", "error", "log", "attempts", "events"`` in a
  team's own view.

The code is cut in three modules, imports pointing one way (``page_html <- page_chart <- page``):
the small formatting helpers and the HTML document around a page's body are in
:mod:`leaderboard.page_html`, the board's per-family bar chart (inline SVG) in
:mod:`leaderboard.page_chart`. This module holds the static assets and export, the board page
and a submission's page; :data:`~leaderboard.page_html.DASH`,
:data:`~leaderboard.page_chart.PALETTE` and :data:`~leaderboard.page_chart.CHART_TOP` are
re-exported here.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import Any

from dg16m_core.atomic import write_text_atomic

from .page_chart import CHART_TOP, _family_chart
from .page_chart import PALETTE as PALETTE
from .page_html import (
    DASH,
    _e,
    _flatten,
    _is_number,
    _is_rate,
    _kv_table,
    _page,
    _percent,
    _plain,
    _size_text,
    _slug,
    _sortable_th,
    _time,
    _value_cell,
)
from .tracks import DEFAULT_TRACK, TRACK_INFO, provenance_rows, provenance_summary

#: The static assets, files under ``leaderboard/static/``.
ASSETS = ("board.css", "board.js")

_BADGE = ' <span class="badge">headline</span>'
_STATUSES = ("queued", "running", "scored", "failed")


# --------------------------------------------------------------------------------------------
# Assets and files


def asset_text(name: str) -> str:
    """The content of a static asset (one of :data:`ASSETS`).

    Raises:
        ValueError: ``name`` is not one of :data:`ASSETS`.
    """
    if name not in ASSETS:
        raise ValueError(f"asset: expected one of {list(ASSETS)}, found {name!r}")
    return resources.files("leaderboard").joinpath("static", name).read_text(encoding="utf-8")


def write_static(
    out: Path, board_view: Mapping[str, Any], submission_views: Mapping[int, Mapping[str, Any]]
) -> Path:
    """Write the board as static pages that work opened from ``file://`` (no server, no network).

    Writes ``out/index.html``, ``out/submissions/<id>.html`` for each submission view,
    ``out/assets/board.css``, ``out/assets/board.js`` and ``out/board.json`` (the board view),
    each file atomically.

    Args:
        out: the folder (created when missing).
        board_view: the board view.
        submission_views: submission id -> its submission view.

    Returns:
        ``out``.

    Raises:
        ValueError: a submission id is not an integer.
    """
    out = Path(out)
    pages = {_submission_id(key): view for key, view in submission_views.items()}
    for name in ASSETS:
        write_text_atomic(out / "assets" / name, asset_text(name))
    for submission, view in sorted(pages.items()):
        write_text_atomic(
            out / "submissions" / f"{submission}.html",
            render_submission(view, board_link="../index.html", assets="../assets/"),
        )
    write_text_atomic(
        out / "index.html",
        render_index(board_view, link=lambda i: f"submissions/{i}.html", assets="assets/"),
    )
    write_text_atomic(
        out / "board.json", json.dumps(board_view, indent=1, sort_keys=True, allow_nan=False) + "\n"
    )
    return out


def _submission_id(key: Any) -> int:
    """A submission id as an int (it names a file, so nothing else is accepted)."""
    if isinstance(key, bool):
        raise ValueError(f"submission id: expected an integer, found {key!r}")
    if isinstance(key, int):
        return key
    if isinstance(key, str) and key.isascii() and key.isdigit():
        return int(key)
    raise ValueError(f"submission id: expected an integer, found {key!r}")


# --------------------------------------------------------------------------------------------
# The board (index page)


def render_index(
    view: Mapping[str, Any],
    *,
    link: Callable[[int], str],
    assets: str,
    page_link: Callable[[int], str] | None = None,
) -> str:
    """The leaderboard page: per track (mesh, then cloud; each under its heading, the cloud
    track's marked self-declared), one sortable table and one per-family chart per evaluator,
    ranked within the track.

    Args:
        view: the board view (one page of it when it has ``"page"``).
        link: submission id -> href of its detail page.
        assets: prefix of the CSS and JS hrefs (e.g. ``"assets/"``).
        page_link: page number -> href of that page of the board (links to the previous and
            next pages when the view is one page of several).
    """
    title = str(view.get("title") or "leaderboard")
    evaluators: Sequence[Mapping[str, Any]] = view.get("evaluators") or []
    parts = [f'<header class="top">\n<h1>{_e(title)}</h1>\n']
    parts.append(_benchmark_line(view.get("benchmark") or {}, view.get("generated_at")))
    parts.append(_counts_line(view.get("counts") or {}))
    if evaluators:
        links = " ".join(
            f'<a href="#ev-{_section_key(ev)}">{_e(ev.get("name"))}{_track_suffix(ev)}</a>'
            for ev in evaluators
        )
        parts.append(f'<nav class="evaluators" aria-label="Evaluators">{links}</nav>\n')
    parts.append("</header>\n<main>\n")
    if not evaluators:
        parts.append('<p class="empty">No evaluators yet.</p>\n')
    for track, sections in _tracks_of(view):
        parts.append(_track_section(track, sections, link))
    paging = view.get("page")
    if isinstance(paging, Mapping) and page_link is not None:
        parts.append(_page_nav(paging, page_link))
    parts.append("</main>\n")
    parts.append(
        "<footer><p>Rates are means over rows; the bracket is the 95% confidence interval from "
        "resampling objects. A dash: no score.</p></footer>\n"
    )
    return _page(title, assets, "".join(parts), page_class="board-page")


def _track_of(ev: Mapping[str, Any]) -> str:
    """A section's track (a view of version 1 has none: mesh)."""
    return str(ev.get("track") or DEFAULT_TRACK)


def _section_key(ev: Mapping[str, Any]) -> str:
    """The id part of an evaluator's section: its name in the mesh track (``ev-fce``,
    ``table-fce``, as before tracks), ``<track>-<name>`` in another (``ev-cloud-fce``)."""
    track = _track_of(ev)
    name = str(ev.get("name") or "")
    return _slug(name if track == DEFAULT_TRACK else f"{track}-{name}")


def _track_suffix(ev: Mapping[str, Any]) -> str:
    track = _track_of(ev)
    return "" if track == DEFAULT_TRACK else f' <span class="track-tag">{_e(track)}</span>'


def _tracks_of(
    view: Mapping[str, Any],
) -> list[tuple[Mapping[str, Any], list[Mapping[str, Any]]]]:
    """The view's tracks (its ``"tracks"``, else those its sections name, else mesh), each with
    its sections in view order."""
    evaluators: Sequence[Mapping[str, Any]] = view.get("evaluators") or []
    tracks = [t for t in view.get("tracks") or [] if isinstance(t, Mapping)]
    if not tracks:
        names: list[str] = []
        for ev in evaluators:
            if _track_of(ev) not in names:
                names.append(_track_of(ev))
        tracks = [{"name": name} for name in names or [DEFAULT_TRACK]]
    return [
        (track, [ev for ev in evaluators if _track_of(ev) == str(track.get("name"))])
        for track in tracks
    ]


def _track_section(
    track: Mapping[str, Any], sections: Sequence[Mapping[str, Any]], link: Callable[[int], str]
) -> str:
    """One track: its heading (what its predictors saw; self-declared or not), then its
    evaluators' tables, ranked within the track."""
    name = str(track.get("name") or DEFAULT_TRACK)
    info = TRACK_INFO.get(name)
    title = str(track.get("title") or (info.title if info else f"{name} track"))
    declared = track.get("self_declared", info.self_declared if info else False)
    parts = [
        f'<section id="track-{_slug(name)}" class="track track-{_slug(name)}" '
        f'data-track="{_e(name)}">\n<h2 class="track-title">{_e(title)}</h2>\n'
    ]
    if declared:
        parts.append(
            '<p class="track-note">Each entry declares how it was run: the submission file '
            "carries the harness's provenance (harness version, noise model and seed, cameras, "
            "sandbox, the predictor's code hash), shown on its page. The server records it; it "
            "does not rerun the predictor. Ranked within this track only.</p>\n"
        )
    else:
        parts.append('<p class="track-note">Ranked within this track only.</p>\n')
    if not sections:
        parts.append(f'<p class="empty">No {_e(name)}-track submissions yet.</p>\n')
    for ev in sections:
        parts.append(_evaluator_section(ev, link))
    parts.append("</section>\n")
    return "".join(parts)


def _page_nav(paging: Mapping[str, Any], page_link: Callable[[int], str]) -> str:
    """Where this page is among the board's pages, with links to the previous and next."""
    number, pages = int(paging.get("number") or 1), int(paging.get("pages") or 1)
    limit = int(paging.get("limit") or 0)
    bits = []
    if number > 1:
        bits.append(f'<a rel="prev" href="{_e(page_link(number - 1))}">previous page</a>')
    bits.append(f"<span>page {number} of {pages} (up to {limit} rows per evaluator)</span>")
    if number < pages:
        bits.append(f'<a rel="next" href="{_e(page_link(number + 1))}">next page</a>')
    return f'<nav class="pages" aria-label="Pages">{" · ".join(bits)}</nav>\n'


def _benchmark_line(benchmark: Mapping[str, Any], generated_at: Any) -> str:
    sha = str(benchmark.get("sha256") or "")
    bits = []
    if sha:
        bits.append(f'benchmark <code title="{_e(sha)}">{_e(sha[:12])}</code>')
    if benchmark.get("objects") is not None:
        bits.append(f"{_e(benchmark.get('objects'))} objects")
    if benchmark.get("embedded"):
        bits.append("embedded")
    if generated_at:
        bits.append(f"generated {_time(generated_at)}")
    return f'<p class="benchmark">{" · ".join(bits) or DASH}</p>\n'


def _noun(key: str, count: Any) -> str:
    """ "teams" -> "team" when there is one (the counts' keys are plural nouns or states)."""
    if count == 1 and key in ("teams", "submissions"):
        return key[:-1]
    return key


def _counts_line(counts: Mapping[str, Any]) -> str:
    order = ("teams", "submissions", "scored", "queued", "running", "failed")
    keys = [k for k in order if k in counts] + sorted(k for k in counts if k not in order)
    bits = [
        f'<span class="count count-{_slug(k)}">{_e(counts[k])} {_e(_noun(k, counts[k]))}</span>'
        for k in keys
    ]
    return f'<p class="counts">{" · ".join(bits)}</p>\n' if bits else ""


def _evaluator_section(ev: Mapping[str, Any], link: Callable[[int], str]) -> str:
    name = str(ev.get("name") or "")
    slug = _section_key(ev)
    headline = ev.get("headline")
    columns = [str(c) for c in ev.get("columns") or []]
    rows: Sequence[Mapping[str, Any]] = ev.get("rows") or []
    parts = [
        f'<section id="ev-{slug}" class="evaluator" data-track="{_e(_track_of(ev))}">\n'
        f"<h3>{_e(name)}{_track_suffix(ev)}</h3>\n",
        f'<p class="headline">Ranked by <strong>{_e(headline)}</strong>.'
        ' <span class="hint">Click a column header to sort.</span></p>\n'
        if headline
        else "",
    ]
    if not rows:
        parts.append('<p class="empty">No scored submissions yet.</p>\n</section>\n')
        return "".join(parts)
    head = [
        _sortable_th("Rank", "number", sort="ascending"),
        _sortable_th("Team", "text"),
        _sortable_th("Submission", "text"),
    ]
    head += [
        _sortable_th(_e(c) + (_BADGE if c == headline else ""), "number", first="descending")
        for c in columns
    ]
    head.append(_sortable_th("Date", "text", first="descending"))
    body = []
    for row in rows:
        submission = row.get("submission")
        metrics = row.get("metrics") or {}
        cells = [
            f'<td class="num rank" data-value="{_e(row.get("rank"))}">{_e(row.get("rank"))}</td>',
            f'<td class="team" data-value="{_e(row.get("team"))}">{_e(row.get("team"))}</td>',
            f'<td class="submission" data-value="{_e(row.get("label"))}">'
            f'<a href="{_e(link(submission))}">{_e(row.get("label"))}</a> '
            f'<span class="id">#{_e(submission)}</span>{_declared_badge(ev, row)}</td>',
        ]
        cells += [_value_cell(metrics.get(c)) for c in columns]
        cells.append(
            f'<td class="date" data-value="{_e(row.get("date"))}">{_time(row.get("date"), day_only=True)}</td>'
        )
        body.append(f'<tr data-submission="{_e(submission)}">{"".join(cells)}</tr>\n')
    parts.append(
        f'<div class="scroll">\n<table class="board" id="table-{slug}">\n'
        f"<thead>\n<tr>{''.join(head)}</tr>\n</thead>\n<tbody>\n{''.join(body)}</tbody>\n"
        "</table>\n</div>\n"
    )
    parts.append(_family_chart(ev, rows[:CHART_TOP], key=slug))
    parts.append("</section>\n")
    return "".join(parts)


def _declared_badge(ev: Mapping[str, Any], row: Mapping[str, Any]) -> str:
    """A cloud entry's mark: "self-declared", its provenance in one line as the tooltip (none
    in the mesh track)."""
    provenance = row.get("provenance")
    if not isinstance(provenance, Mapping) or _track_of(ev) == DEFAULT_TRACK:
        return ""
    return (
        f' <span class="badge declared" title="{_e(provenance_summary(provenance))}">'
        "self-declared</span>"
    )


# --------------------------------------------------------------------------------------------
# A submission's page


def render_submission(view: Mapping[str, Any], *, board_link: str, assets: str) -> str:
    """A submission's detail page: its record, then each evaluator's full result (metrics,
    parameters, seeds, benchmark, per-family and per-object tables, failures); with the team's
    private view (``"private"`` in ``view``) also the error, the events and the log.

    Args:
        view: the submission view.
        board_link: href back to the board.
        assets: prefix of the CSS and JS hrefs (e.g. ``"../assets/"``).
    """
    submission = view.get("id")
    label = str(view.get("label") or view.get("filename") or f"#{submission}")
    results: Mapping[str, Mapping[str, Any]] = view.get("results") or {}
    evaluators = list(view.get("evaluators") or [])
    evaluators += [name for name in results if name not in evaluators]
    status = str(view.get("status") or "")
    status_cls = status if status in _STATUSES else "other"
    parts = [
        f'<nav class="back"><a href="{_e(board_link)}">\u2190 Back to the board</a></nav>\n',
        '<header class="top">\n',
        f'<h1>{_e(label)} <span class="id">#{_e(submission)}</span></h1>\n',
        f'<p class="meta"><span class="team">{_e(view.get("team"))}</span> · '
        f'<span class="status status-{status_cls}">{_e(status or DASH)}</span> · '
        f"{_time(view.get('date'))}</p>\n",
        "</header>\n<main>\n",
        '<section class="record">\n<h2>Submission</h2>\n',
        _record_table(view, results),
        "</section>\n",
        _provenance_section(view),
    ]
    if "private" in view:
        parts.append(_private_section(view))
    if not evaluators:
        parts.append('<p class="empty">No evaluators.</p>\n')
    for name in evaluators:
        result = results.get(name)
        if result is None:
            if status in ("queued", "running"):
                why = f"Not scored yet ({status})."
            elif status == "failed":
                why = "No result: the evaluation failed."
            else:
                why = "No result."
            parts.append(
                f'<section id="ev-{_slug(name)}" class="evaluator">\n<h2>{_e(name)}</h2>\n'
                f'<p class="empty">{_e(why)}</p>\n</section>\n'
            )
        else:
            parts.append(_result_section(str(name), result))
    parts.append("</main>\n")
    title = f"{label} #{submission} · {view.get('team') or ''}".rstrip(" ·")
    return _page(title, assets, "".join(parts), page_class="submission-page")


def _record_table(view: Mapping[str, Any], results: Mapping[str, Mapping[str, Any]]) -> str:
    shas = []
    benchmark = view.get("benchmark")
    if isinstance(benchmark, Mapping) and benchmark.get("sha256"):
        shas.append(str(benchmark["sha256"]))
    for result in results.values():
        sha = (result.get("benchmark") or {}).get("sha256")
        if sha and str(sha) not in shas:
            shas.append(str(sha))
    rows = [
        ("Team", _e(view.get("team"))),
        ("Label", _e(view.get("label"))),
        ("File", f"<code>{_e(view.get('filename'))}</code>"),
        ("File sha256", f'<code class="sha">{_e(view.get("file_sha256") or DASH)}</code>'),
        ("Size", _e(_size_text(view.get("size")))),
        ("Date", _time(view.get("date"))),
        ("Status", _e(view.get("status") or DASH)),
        ("Track", _track_text(view)),
        (
            "Benchmark sha256",
            "<br>".join(f'<code class="sha">{_e(s)}</code>' for s in shas) or DASH,
        ),
        ("Evaluators", _e(", ".join(str(n) for n in view.get("evaluators") or []) or DASH)),
    ]
    body = "".join(f'<tr><th scope="row">{k}</th><td>{v}</td></tr>\n' for k, v in rows)
    return f'<table class="kv record">\n<tbody>\n{body}</tbody>\n</table>\n'


def _track_text(view: Mapping[str, Any]) -> str:
    """The record's track: its name and what its predictor saw (self-declared for cloud)."""
    name = str(view.get("track") or DEFAULT_TRACK)
    info = TRACK_INFO.get(name)
    what = info.title.split(": ", 1)[-1] if info else ""
    return f'<span class="track-name">{_e(name)}</span>' + (f" · {_e(what)}" if what else "")


def _provenance_section(view: Mapping[str, Any]) -> str:
    """A cloud entry's provenance, as its submission file declares it (none for mesh)."""
    provenance = view.get("provenance")
    if not isinstance(provenance, Mapping) or str(view.get("track")) == DEFAULT_TRACK:
        return ""
    body = "".join(
        f'<tr><th scope="row">{_e(label)}</th><td><code>{_e(text)}</code></td></tr>\n'
        for label, text in provenance_rows(provenance)
    )
    return (
        '<section class="provenance">\n<h2>Provenance (self-declared)</h2>\n'
        '<p class="track-note">How the submitter ran the predictor, as recorded in the '
        "submission file by <code>dg16m evaluate --track cloud</code>; the server does not "
        "rerun it.</p>\n"
        f'<table class="kv provenance">\n<tbody>\n{body}</tbody>\n</table>\n</section>\n'
    )


def _private_section(view: Mapping[str, Any]) -> str:
    error = view.get("error")
    parts = ['<section class="private">\n<h2>Processing (visible to your team only)</h2>\n']
    if error:
        parts.append(f'<p class="error"><strong>Error:</strong> {_e(error)}</p>\n')
    else:
        parts.append('<p class="ok">No error.</p>\n')
    if view.get("attempts") is not None:
        parts.append(f'<p class="attempts">Attempts: {_e(view.get("attempts"))}</p>\n')
    events: Sequence[Mapping[str, Any]] = view.get("events") or []
    if events:
        body = "".join(
            f"<tr><td>{_time(ev.get('at'))}</td><td>{_e(ev.get('state'))}</td>"
            f"<td><code>{_e(ev.get('worker') or DASH)}</code></td>"
            f"<td>{_e(ev.get('message') or '')}</td></tr>\n"
            for ev in events
        )
        parts.append(
            '<h3>Events</h3>\n<table class="events">\n<thead><tr><th scope="col">At</th>'
            '<th scope="col">State</th><th scope="col">Worker</th><th scope="col">Message</th>'
            f"</tr></thead>\n<tbody>\n{body}</tbody>\n</table>\n"
        )
    log = view.get("log")
    parts.append("<h3>Log</h3>\n")
    parts.append(f'<pre class="log">{_e(log)}</pre>\n' if log else '<p class="none">empty</p>\n')
    parts.append("</section>\n")
    return "".join(parts)


def _result_section(name: str, result: Mapping[str, Any]) -> str:
    slug = _slug(name)
    headline = str(result.get("headline") or "")
    metrics: Mapping[str, Any] = result.get("metrics") or {}
    parts = [
        f'<section id="ev-{slug}" class="evaluator">\n',
        f"<h2>{_e(result.get('evaluator') or name)} "
        f'<span class="version">v{_e(result.get("evaluator_version"))}</span></h2>\n',
        f'<p class="meta">dg16m <span class="package-version">'
        f"{_e(result.get('package_version'))}</span> · headline "
        f"<strong>{_e(headline)}</strong>: {_headline_text(metrics.get(headline))}</p>\n",
        "<h3>Metrics</h3>\n",
        _metrics_table(metrics, headline),
        '<div class="records">\n',
        # The parameters (~30 rows, keys up to ~35 characters) take the grid's whole width.
        '<div class="wide"><h3>Parameters</h3>\n'
        f"{_kv_table(_flatten(result.get('parameters') or {}))}</div>\n",
        f"<div><h3>Seeds</h3>\n{_kv_table(_flatten(result.get('seeds') or {}))}</div>\n",
        f"<div><h3>Benchmark</h3>\n{_kv_table(_flatten(result.get('benchmark') or {}))}</div>\n",
        f"<div><h3>Subject</h3>\n{_kv_table(_flatten(result.get('subject') or {}))}</div>\n",
        "</div>\n",
    ]
    per_family: Mapping[str, Mapping[str, Any]] = result.get("per_family") or {}
    if per_family:
        parts.append("<h3>Per family</h3>\n")
        parts.append(_per_family_table(slug, per_family, headline))
    per_object: Mapping[str, Mapping[str, Any]] = result.get("per_object") or {}
    failures: Mapping[str, Any] = result.get("failures") or {}
    if per_object:
        parts.append(f"<h3>Per object ({len(per_object)})</h3>\n")
        rates = [m for m, v in metrics.items() if _is_rate(v)]
        parts.append(_per_object_table(slug, per_object, failures, rates))
    if failures:
        items = "".join(
            f"<li><code>{_e(k)}</code>: {_e(v)}</li>\n" for k, v in sorted(failures.items())
        )
        parts.append(
            f"<h3>Failures ({len(failures)})</h3>\n"
            "<p>These objects could not be scored; their grasps count as failures.</p>\n"
            f'<ul class="failures">\n{items}</ul>\n'
        )
    details = result.get("details") or {}
    if details:
        parts.append(f"<details>\n<summary>Details</summary>\n{_kv_table(_flatten(details))}")
        parts.append("</details>\n")
    parts.append("</section>\n")
    return "".join(parts)


def _headline_text(value: Any) -> str:
    if _is_rate(value):
        rate = value.get("rate")
        if not _is_number(rate):
            return DASH
        text = f"{_percent(rate)}%"
        if _is_number(value.get("ci_low")) and _is_number(value.get("ci_high")):
            text += f" [{_percent(value['ci_low'])}, {_percent(value['ci_high'])}]"
        return _e(text)
    return _e(_plain(value))


def _metrics_table(metrics: Mapping[str, Any], headline: str) -> str:
    rows = []
    for metric, value in metrics.items():
        badge = _BADGE if metric == headline else ""
        count = [value.get("rows"), value.get("objects")] if _is_rate(value) else [None, None]
        counts = "".join(
            f'<td class="num" data-value="{_e(c) if _is_number(c) else ""}">'
            f"{_e(c) if _is_number(c) else DASH}</td>"
            for c in count
        )
        rows.append(
            f'<tr data-metric="{_e(metric)}"><th scope="row">{_e(metric)}{badge}</th>'
            f"{_value_cell(value)}{counts}</tr>\n"
        )
    if not rows:
        return '<p class="none">none</p>\n'
    return (
        '<table class="metrics">\n<thead><tr><th scope="col">Metric</th>'
        '<th scope="col">Rate [95% CI]</th><th scope="col">Rows</th>'
        f'<th scope="col">Objects</th></tr></thead>\n<tbody>\n{"".join(rows)}</tbody>\n</table>\n'
    )


def _per_family_table(slug: str, per_family: Mapping[str, Mapping[str, Any]], headline: str) -> str:
    names: list[str] = []
    for entry in per_family.values():
        names += [str(m) for m in entry if str(m) not in names]
    if headline in names:
        names.remove(headline)
        names.insert(0, headline)
    head = _sortable_th("Family", "text", sort="ascending") + "".join(
        _sortable_th(_e(m), "number", first="descending") for m in names
    )
    head += _sortable_th("Objects", "number", first="descending")
    body = []
    for family, entry in per_family.items():
        objects = next(
            (
                v.get("objects")
                for v in entry.values()
                if _is_rate(v) and _is_number(v.get("objects"))
            ),
            None,
        )
        cells = "".join(_value_cell(entry.get(m)) for m in names)
        body.append(
            f'<tr data-family="{_e(family)}"><td class="text" data-value="{_e(family)}">'
            f"{_e(family)}</td>{cells}{_value_cell(objects)}</tr>\n"
        )
    return (
        f'<div class="scroll">\n<table class="sortable families" id="families-{slug}">\n'
        f"<thead><tr>{head}</tr></thead>\n<tbody>\n{''.join(body)}</tbody>\n</table>\n</div>\n"
    )


def _object_cell(value: Any, is_rate: bool) -> str:
    """A per-object value: a mean of a rate metric as a percentage, anything else as
    :func:`_value_cell` shows it."""
    if is_rate and _is_number(value):
        return f'<td class="num" data-value="{float(value)!r}">{_percent(value)}%</td>'
    return _value_cell(value)


def _per_object_table(
    slug: str,
    per_object: Mapping[str, Mapping[str, Any]],
    failures: Mapping[str, Any],
    rates: Iterable[str],
) -> str:
    """One sortable row per object; columns ``grasps`` then every other key of the entries
    (the means of the metrics in ``rates`` shown as percentages)."""
    rates = set(rates)
    names = ["grasps"]
    for entry in per_object.values():
        names += [str(m) for m in entry if str(m) not in names]
    head = _sortable_th("Object", "text", sort="ascending") + "".join(
        _sortable_th(_e(m), "number", first="descending")
        if all(
            _is_number(e.get(m)) or _is_rate(e.get(m)) or e.get(m) is None
            for e in per_object.values()
        )
        else _sortable_th(_e(m), "text")
        for m in names
    )
    body = []
    for object_id, entry in per_object.items():
        failed = object_id in failures
        note = (
            f' <span class="badge failed" title="{_e(failures[object_id])}">failed</span>'
            if failed
            else ""
        )
        cells = "".join(_object_cell(entry.get(m), m in rates) for m in names)
        row_class = ' class="failed"' if failed else ""
        body.append(
            f'<tr data-object="{_e(object_id)}"{row_class}>'
            f'<td class="text" data-value="{_e(object_id)}"><code>{_e(object_id)}</code>{note}</td>'
            f"{cells}</tr>\n"
        )
    return (
        f'<div class="scroll tall">\n<table class="sortable objects" id="objects-{slug}">\n'
        f"<thead><tr>{head}</tr></thead>\n<tbody>\n{''.join(body)}</tbody>\n</table>\n</div>\n"
    )
