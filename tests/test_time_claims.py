"""Issue 56: every time claim of the README, the guide, the quickstart and the tutorials is a row
of the measured-times table that ``bench/time_claims.py`` writes, quoted with its value and date.

A *time claim* is a number followed by a unit of time (``53 s``, ``1 min 31 s``, ``about 10
min``, ``3 hours``) or "a minute" / "an hour". Each must be either

* a quote of a table row: the row's value exactly as :func:`display` writes it, followed
  (within the same paragraph, before the next quote) by the row's date and the reference
  ``[ID](times.md)`` (``docs/times.md`` from the README, ``../times.md`` from a tutorial), or
* one of the :data:`EXCEPTIONS` below: durations that are parameters of a task or a command
  (physics steps, hold times, budgets, time-outs), not how long a command takes.

No command runs here: the test reads files (well under a second).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from script_loader import load_script

ROOT = Path(__file__).resolve().parents[1]
TIMES = load_script(ROOT / "bench" / "time_claims.py", "time_claims")

FILES = sorted(
    {"README.md", "docs/guide.md", "docs/quickstart.md"}
    | {str(p.relative_to(ROOT)) for p in (ROOT / "docs" / "tutorials").glob("*.md")}
)

TIME = re.compile(
    r"(?<![\w.])(?:about |~)?\d[\d,.]*(?:\s*(?:-|–|to|and)\s*\d[\d,.]*)?\s*"
    r"(?:s|secs?|seconds?|min|mins|minutes?|h|hours?|CPU[- ]?(?:s|seconds?))\b(?:\s+\d+\s*s\b)?"
    r"|\b(?:a|an|half an) (?:minute|hour)\b",
    re.IGNORECASE,
)
REFERENCE = re.compile(r"\[([a-z0-9-]+)\]\((?:\.\./|docs/)?times\.md\)")
WINDOW = 400  # characters before a reference that belong to its quote (at most)

#: (file, pattern, reason): a time claim inside a match of ``pattern`` on its line is not a
#: duration of a command.
EXCEPTIONS: tuple[tuple[str, str, str], ...] = (
    (
        "docs/guide.md",
        r"\*close\* \(0\.5 s|\*gravity\* \(0\.4 s|0\.2 s each|over 0\.05 s",
        "the trial protocol's phases (task parameters)",
    ),
    (
        "docs/guide.md",
        r"\(10 s\)|\(30 s\)|600 s in all|\(5 s\)",
        "the leaderboard service's time-out defaults (arguments)",
    ),
    ("docs/guide.md", r"held 1 s", "Lift's success rule (hold time, a task parameter)"),
    (
        "docs/tutorials/own_meshes.md",
        r"\| (120|180|240) s \||\*\*10 minutes of|\d[\d.]* CPU s\b",
        "a stage's or an object's CPU budget (arguments of the command), or the CPU seconds a"
        " stage used in an example verdict",
    ),
)


def _text(name: str) -> str:
    return (ROOT / name).read_text()


def _excepted(name: str, text: str, start: int, end: int) -> bool:
    """Whether the claim at ``text[start:end]`` of file ``name`` is one of the exceptions."""
    line_start = text.rfind("\n", 0, start) + 1
    line_end = text.find("\n", end)
    line = text[line_start : line_end if line_end >= 0 else len(text)]
    for file, pattern, _reason in EXCEPTIONS:
        if file != name:
            continue
        for found in re.finditer(pattern, line):
            if line_start + found.start() <= start and end <= line_start + found.end():
                return True
    return False


def quotes(name: str, rows: dict[str, dict]) -> tuple[list[tuple[int, int]], list[str]]:
    """The character spans of file ``name`` that quote a table row's value, and the problems
    found with its references (unknown row, value or date missing before the reference)."""
    text = _text(name)
    spans: list[tuple[int, int]] = []
    problems: list[str] = []
    previous = 0
    for ref in REFERENCE.finditer(text):
        start = max(previous, ref.start() - WINDOW, text.rfind("\n\n", 0, ref.start()) + 1)
        segment = text[start : ref.start()]
        previous = ref.end()
        row = rows.get(ref.group(1))
        line = text.count("\n", 0, ref.start()) + 1
        if row is None:
            problems.append(f"{name}:{line}: expected a row of the table, found {ref.group(1)!r}")
            continue
        value = TIMES.display(row["wall_seconds"], row.get("approximate", False))
        pattern = r"\s+".join(map(re.escape, value.split()))  # a quote may wrap
        where = [m.span() for m in re.finditer(pattern, segment)]
        if not where:
            problems.append(
                f"{name}:{line}: expected the value {value!r} of row {row['id']} before its "
                f"reference, found {segment[-120:]!r}"
            )
        if row["date"] not in segment:
            problems.append(
                f"{name}:{line}: expected the date {row['date']} of row {row['id']} before its "
                f"reference, found {segment[-120:]!r}"
            )
        spans += [(start + a, start + b) for a, b in where]
    return spans, problems


@pytest.fixture(scope="module")
def rows() -> dict[str, dict]:
    return TIMES.read_table()


@pytest.mark.parametrize("name", FILES)
def test_every_time_claim_quotes_the_table(name: str, rows: dict[str, dict]) -> None:
    """Each duration stated in the file is a row's value with its date and reference."""
    text = _text(name)
    spans, problems = quotes(name, rows)
    for claim in TIME.finditer(text):
        start, end = claim.span()
        if any(a <= start and end <= b for a, b in spans) or _excepted(name, text, start, end):
            continue
        line = text.count("\n", 0, start) + 1
        problems.append(
            f"{name}:{line}: expected a time claim to quote a row of docs/times.md (value, date,"
            f" [ID](times.md)) or to be an exception, found {claim.group(0)!r}"
        )
    assert problems == []


def test_the_table_says_where_each_row_is_claimed(rows: dict[str, dict]) -> None:
    """A row's ``claimed_in`` files are exactly those that quote it, and every row of the
    script is in the table."""
    quoted: dict[str, set[str]] = {}
    for name in FILES:
        for ref in REFERENCE.finditer(_text(name)):
            quoted.setdefault(ref.group(1), set()).add(name)
    assert sorted(rows) == sorted(TIMES.BY_ID)
    for row_id, row in rows.items():
        assert set(row["claimed_in"]) == quoted.get(row_id, set()), row_id
        assert row["claimed_in"] == list(TIMES.BY_ID[row_id].claimed_in), row_id


def test_the_page_is_the_rendered_table(rows: dict[str, dict]) -> None:
    """``docs/times.md`` is the rendering of ``docs/_static/times.json`` (not edited apart),
    and each row has a date (``YYYY-MM-DD`` or ``undated`` for an estimate)."""
    assert TIMES.TABLE_MD.read_text() == TIMES.render(list(rows.values()))
    payload = json.loads(TIMES.TABLE_JSON.read_text())
    assert [row["id"] for row in payload["rows"]] == [c.id for c in TIMES.CLAIMS if c.id in rows]
    for row in rows.values():
        assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", row["date"]) or (
            row["date"] == "undated" and row["approximate"]
        ), row


def test_the_detector_finds_claims_and_skips_units_of_tasks() -> None:
    """The claim pattern catches the forms the docs used and leaves physics units alone."""
    found = [
        m.group(0)
        for m in TIME.finditer(
            "takes 11 min; about 45 s; 1.5 minutes; 90-97 s; ~20 min; 10 min 52 s; about a minute; "
            "2 CPU-seconds; 5 ms physics steps, 20 Hz, 0.05 m, 1,700 tests, 2 cores"
        )
    ]
    assert found == [
        "11 min",
        "about 45 s",
        "1.5 minutes",
        "90-97 s",
        "~20 min",
        "10 min 52 s",
        "a minute",
        "2 CPU-seconds",
    ]
    assert TIMES.display(652) == "10 min 52 s"
    assert TIMES.display(53.4) == "53 s"
    assert TIMES.display(600, approximate=True) == "about 10 min"
