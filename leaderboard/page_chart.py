"""The board's chart (:mod:`leaderboard.page`): per evaluator, an inline SVG bar chart of the
headline rate per family of its first :data:`CHART_TOP` submissions by rank, one group per family
and one bar per submission in the colours of :data:`PALETTE`, the 95 % confidence intervals as
whiskers, family labels broken over at most two lines and a legend whose entries are cut at
``_LEGEND_CHARS`` characters (``_family_chart``, ``_label_lines``); like the rest of the page it
has no script and no ``style`` attribute.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from .page_html import DASH, _e, _is_number, _is_rate, _percent, _rate_of, _slug

#: Bar colours of the charts (Okabe-Ito, distinguishable with colour-vision deficiencies).
PALETTE = ("#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00", "#F0E442")

#: Submissions shown in an evaluator's chart (the first rows by rank).
CHART_TOP = 5

#: Longest legend entry of a chart (characters; longer ones are cut, in full in a tooltip).
_LEGEND_CHARS = 90


def _family_chart(
    ev: Mapping[str, Any], rows: Sequence[Mapping[str, Any]], key: str | None = None
) -> str:
    """An inline SVG bar chart: the headline rate per family (with its confidence interval as a
    whisker) of each of ``rows``; one group per family, one bar per submission, y from 0 to 100 %.
    Without families, one group of the overall headline rate. ``key`` names the chart's id
    (``chart-<key>``; default the evaluator's name: one chart per evaluator and track)."""
    name = str(ev.get("name") or "")
    headline = str(ev.get("headline") or "")
    families = [str(f) for f in ev.get("families") or []]
    if families:
        groups = [
            (family, [(r.get("per_family") or {}).get(family) for r in rows]) for family in families
        ]
    else:
        groups = [("overall", [(r.get("metrics") or {}).get(headline) for r in rows])]
    n_bars = max(len(rows), 1)
    plot_w_target = 860.0
    group_pad = 18.0
    bar_w = max(5.0, min(28.0, (plot_w_target / len(groups) - group_pad) / n_bars))
    group_w = bar_w * n_bars + group_pad
    left, right, top, plot_h, axis_h = 56.0, 16.0, 16.0, 220.0, 44.0
    legend_top = top + plot_h + axis_h
    legend_line = 20.0
    legends = [
        f"{r.get('rank')}. {r.get('label')} ({r.get('team')}) #{r.get('submission')}" for r in rows
    ]
    longest = max((min(len(t), _LEGEND_CHARS) for t in legends), default=0)
    plot_right = left + group_w * len(groups)
    width = max(plot_right, left + 18.0 + 6.8 * longest) + right
    height = legend_top + legend_line * len(rows) + 8.0

    def y_of(rate: float) -> float:
        return top + plot_h * (1.0 - min(max(rate, 0.0), 1.0))

    chart_id = f"chart-{_slug(name if key is None else key)}"
    track = str(ev.get("track") or "mesh")
    where = "" if track == "mesh" else f" ({track} track)"
    title = f"{name}{where}: {headline} by family, top {len(rows)} submissions"
    out = [
        f'<figure class="chart">\n<svg class="bars" id="{chart_id}" role="img" '
        f'aria-labelledby="{chart_id}-title" viewBox="0 0 {width:.0f} {height:.0f}" '
        f'width="{width:.0f}" height="{height:.0f}" xmlns="http://www.w3.org/2000/svg">\n'
        f'<title id="{chart_id}-title">{_e(title)}</title>\n'
    ]
    for tick in (0, 25, 50, 75, 100):
        y = y_of(tick / 100)
        out.append(
            f'<line class="grid" x1="{left:.1f}" x2="{plot_right:.1f}" y1="{y:.1f}" '
            f'y2="{y:.1f}" stroke="#ccc" stroke-width="1"/>'
            f'<text class="tick" x="{left - 6:.1f}" y="{y + 4:.1f}" text-anchor="end" '
            f'font-size="11" fill="currentColor">{tick}%</text>\n'
        )
    out.append(
        f'<text class="axis-title" x="14" y="{top + plot_h / 2:.1f}" text-anchor="middle" '
        f'font-size="11" fill="currentColor" transform="rotate(-90 14 {top + plot_h / 2:.1f})">'
        f"{_e(headline)} (%)</text>\n"
    )
    for g, (family, values) in enumerate(groups):
        x0 = left + g * group_w + group_pad / 2
        for b, value in enumerate(values):
            row = rows[b]
            x = x0 + b * bar_w
            colour = PALETTE[b % len(PALETTE)]
            rate = _rate_of(value)
            who = f"{row.get('label')} ({row.get('team')}, #{row.get('submission')})"
            if rate is None:
                out.append(
                    f'<text class="missing" x="{x + bar_w / 2:.1f}" y="{top + plot_h - 3:.1f}" '
                    f'text-anchor="middle" font-size="10" fill="currentColor">{DASH}'
                    f"<title>{_e(who)}, {_e(family)}: no score</title></text>\n"
                )
                continue
            y = y_of(rate)
            tip = f"{who}, {family}: {_percent(rate)}%"
            whisker = ""
            if (
                _is_rate(value)
                and _is_number(value.get("ci_low"))
                and _is_number(value.get("ci_high"))
            ):
                lo, hi = y_of(float(value["ci_low"])), y_of(float(value["ci_high"]))
                tip += f" [{_percent(value['ci_low'])}, {_percent(value['ci_high'])}]"
                cx, cap = x + bar_w / 2, max(bar_w / 4, 1.5)
                whisker = (
                    f'<g class="whisker" stroke="#222" stroke-width="1.2">'
                    f'<line x1="{cx:.1f}" x2="{cx:.1f}" y1="{lo:.1f}" y2="{hi:.1f}"/>'
                    f'<line x1="{cx - cap:.1f}" x2="{cx + cap:.1f}" y1="{lo:.1f}" y2="{lo:.1f}"/>'
                    f'<line x1="{cx - cap:.1f}" x2="{cx + cap:.1f}" y1="{hi:.1f}" y2="{hi:.1f}"/>'
                    "</g>"
                )
            out.append(
                f'<rect class="bar bar-{b}" x="{x + 0.5:.1f}" y="{y:.1f}" '
                f'width="{max(bar_w - 1, 1):.1f}" height="{top + plot_h - y:.1f}" '
                f'fill="{colour}"><title>{_e(tip)}</title></rect>{whisker}\n'
            )
        cx = x0 + bar_w * n_bars / 2
        lines = "".join(
            f'<tspan x="{cx:.1f}" dy="{0 if k == 0 else 13}">{_e(line)}</tspan>'
            for k, line in enumerate(_label_lines(family, max(4, int(group_w / 6.3)), 2))
        )
        out.append(
            f'<text class="family" x="{cx:.1f}" y="{top + plot_h + 16:.1f}" '
            f'text-anchor="middle" font-size="11" fill="currentColor">{lines}'
            f"<title>{_e(family)}</title></text>\n"
        )
    out.append(
        f'<line class="axis" x1="{left:.1f}" x2="{plot_right:.1f}" y1="{top + plot_h:.1f}" '
        f'y2="{top + plot_h:.1f}" stroke="currentColor" stroke-width="1"/>\n'
    )
    for b, text in enumerate(legends):
        y = legend_top + b * legend_line
        short = text if len(text) <= _LEGEND_CHARS else text[: _LEGEND_CHARS - 1] + "\u2026"
        out.append(
            f'<g class="legend"><rect x="{left:.1f}" y="{y:.1f}" width="12" height="12" '
            f'fill="{PALETTE[b % len(PALETTE)]}"/><text x="{left + 18:.1f}" y="{y + 10:.1f}" '
            f'font-size="12" fill="currentColor">{_e(short)}<title>{_e(text)}</title></text></g>\n'
        )
    out.append("</svg>\n")
    caption = (
        f"{_e(headline)} per family of the top {len(rows)} submissions; whiskers: 95% "
        "confidence intervals."
    )
    out.append(f"<figcaption>{caption}</figcaption>\n</figure>\n")
    return "".join(out)


def _label_lines(text: str, width: int, max_lines: int) -> list[str]:
    """``text`` in at most ``max_lines`` lines of about ``width`` characters, broken after
    ``_``, ``-`` or spaces where possible; what does not fit is cut with an ellipsis."""
    lines: list[str] = []
    rest = text
    while rest and len(lines) < max_lines:
        if len(rest) <= width:
            lines.append(rest)
            rest = ""
            break
        cut = max((rest.rfind(c, 1, width + 1) for c in "_- "), default=-1)
        cut = cut + 1 if cut > 0 else width
        lines.append(rest[:cut].rstrip())
        rest = rest[cut:].lstrip()
    if rest:
        lines[-1] = lines[-1][: max(width - 1, 1)] + "\u2026"
    return lines
