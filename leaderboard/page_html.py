"""HTML building blocks of the leaderboard's pages (:mod:`leaderboard.page`): every value as
escaped text (``_e``, :func:`html.escape` with ``quote=True``), numbers, rates, dates and sizes as
short text, a metric value as a sortable table cell (``_value_cell``), header cells that
``board.js`` sorts by, key/value tables, and the whole HTML document around a page's body
(``_page``); :data:`DASH` is what a missing value shows.
"""

from __future__ import annotations

import html
import json
import math
import re
from collections.abc import Iterable, Mapping
from typing import Any

#: What a missing value shows.
DASH = "\u2014"

_ISO = re.compile(r"^(\d{4}-\d{2}-\d{2})T(\d{2}:\d{2})(?::\d{2}(?:\.\d+)?)?(Z|[+-]\d{2}:?\d{2})?$")


def _e(value: Any) -> str:
    """``value`` as text, escaped for HTML text and attribute values."""
    return html.escape("" if value is None else str(value), quote=True)


def _is_number(value: Any) -> bool:
    """A finite int or float (not a bool)."""
    return (
        isinstance(value, (int, float))
        and not isinstance(value, bool)
        and math.isfinite(float(value))
    )


def _is_rate(value: Any) -> bool:
    """A rate dict (``{"rate", "ci_low", "ci_high", ...}``)."""
    return isinstance(value, Mapping) and "rate" in value


def _number_text(value: Any) -> str:
    """An int as is, a float with 4 significant digits."""
    if isinstance(value, int):
        return str(value)
    return f"{float(value):.4g}"


def _percent(value: float) -> str:
    return f"{100 * float(value):.1f}"


def _rate_of(value: Any) -> float | None:
    """The rate (or plain number) of a metric value; None when absent."""
    if _is_rate(value):
        rate = value.get("rate")
        return float(rate) if _is_number(rate) else None
    return float(value) if _is_number(value) else None


def _value_cell(value: Any, *, cls: str = "num") -> str:
    """A ``<td>`` for a metric value: a rate dict as ``76.3% [72.1, 80.2]``, a number with 4
    significant digits, anything absent as a dash; ``data-value`` is the number ("" if none)."""
    if _is_rate(value):
        rate = value.get("rate")
        if not _is_number(rate):
            return f'<td class="{cls} missing" data-value="">{DASH}</td>'
        low, high = value.get("ci_low"), value.get("ci_high")
        ci = (
            f' <span class="ci">[{_percent(low)}, {_percent(high)}]</span>'
            if _is_number(low) and _is_number(high)
            else ""
        )
        return f'<td class="{cls}" data-value="{float(rate)!r}">{_percent(rate)}%{ci}</td>'
    if _is_number(value):
        return f'<td class="{cls}" data-value="{value!r}">{_e(_number_text(value))}</td>'
    if isinstance(value, bool):
        return f'<td class="{cls}" data-value="{int(value)}">{"yes" if value else "no"}</td>'
    if isinstance(value, Mapping):
        text = ", ".join(f"{k} {_plain(v)}" for k, v in value.items())
        return f'<td class="text" data-value="{_e(text)}">{_e(text)}</td>'
    if isinstance(value, str):
        return f'<td class="text" data-value="{_e(value)}">{_e(value)}</td>'
    return f'<td class="{cls} missing" data-value="">{DASH}</td>'


def _plain(value: Any) -> str:
    """A short text for any JSON value (numbers with 4 significant digits)."""
    if value is None:
        return DASH
    if isinstance(value, bool):
        return "true" if value else "false"
    if _is_number(value):
        return _number_text(value)
    if isinstance(value, str):
        return value
    return json.dumps(value, sort_keys=True, default=str)


def _exact(value: Any) -> str:
    """A JSON value shown exactly (parameters, seeds, records): strings as is, else JSON."""
    if isinstance(value, str):
        return value
    return json.dumps(value, sort_keys=True, default=str)


def _date_text(value: Any) -> str:
    """``2026-11-30T06:10:00Z`` as ``2026-11-30 06:10 UTC``; other text unchanged."""
    text = "" if value is None else str(value)
    match = _ISO.match(text)
    if not match:
        return text or DASH
    day, minute, zone = match.groups()
    zone = "UTC" if zone in (None, "Z", "+00:00", "+0000") else zone
    return f"{day} {minute} {zone}"


def _time(value: Any, *, day_only: bool = False) -> str:
    """A ``<time>`` element for an ISO date (plain text when it is not one); ``day_only`` shows
    the day and keeps the minute in its tooltip (the board's narrow date column)."""
    if value is None or value == "":
        return DASH
    text = _date_text(value)
    if day_only and _ISO.match(str(value)):
        return f'<time datetime="{_e(value)}" title="{_e(text)}">{_e(text.split(" ")[0])}</time>'
    return f'<time datetime="{_e(value)}">{_e(text)}</time>'


def _size_text(size: Any) -> str:
    """``123456`` as ``120.6 KiB (123,456 bytes)``."""
    if not _is_number(size):
        return DASH
    size = int(size)
    value, unit = float(size), "bytes"
    for next_unit in ("KiB", "MiB", "GiB", "TiB"):
        if value < 1024:
            break
        value, unit = value / 1024, next_unit
    if unit == "bytes":
        return f"{size:,} bytes"
    return f"{value:.1f} {unit} ({size:,} bytes)"


def _slug(value: Any) -> str:
    """An id-friendly form of a name (letters, digits, ``-``, ``_``, ``.``), escaped."""
    text = re.sub(r"[^A-Za-z0-9_.-]+", "-", str(value)).strip("-") or "x"
    return _e(text)


def _flatten(record: Any, prefix: str = "") -> list[tuple[str, Any]]:
    """Nested mappings as ``(dotted.key, value)`` pairs (other values are leaves)."""
    if isinstance(record, Mapping) and (record or not prefix):
        pairs: list[tuple[str, Any]] = []
        for key, value in record.items():
            pairs += _flatten(value, f"{prefix}.{key}" if prefix else str(key))
        return pairs
    return [(prefix, record)]


def _sortable_th(label: str, kind: str, *, first: str | None = None, sort: str = "") -> str:
    """A header cell ``board.js`` sorts by (``label`` is already HTML)."""
    extra = f' data-first="{first}"' if first else ""
    extra += f' aria-sort="{sort}"' if sort else ""
    return f'<th scope="col" data-sort="{kind}"{extra}>{label}</th>'


def _page(title: str, assets: str, body: str, *, page_class: str) -> str:
    """A whole HTML document around ``body`` (``title`` is plain text)."""
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        '<meta name="color-scheme" content="light dark">\n'
        f"<title>{_e(title)}</title>\n"
        '<link rel="icon" href="data:,">\n'
        f'<link rel="stylesheet" href="{_e(assets)}board.css">\n'
        f'<script src="{_e(assets)}board.js" defer></script>\n'
        f'</head>\n<body class="{page_class}">\n{body}</body>\n</html>\n'
    )


def _kv_table(pairs: Iterable[tuple[str, Any]], *, cls: str = "kv") -> str:
    """A small key/value table (values shown exactly). A dotted key (``scene.solimp``) may
    break after its dots (``<wbr>``) in a narrow column."""
    rows = "".join(
        f'<tr><th scope="row">{_e(key).replace(".", ".<wbr>")}</th>'
        f"<td><code>{_e(_exact(value))}</code></td></tr>\n"
        for key, value in pairs
    )
    if not rows:
        return '<p class="none">none</p>\n'
    return f'<table class="{cls}">\n<tbody>\n{rows}</tbody>\n</table>\n'
