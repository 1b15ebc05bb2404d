"""Tiny server-rendered SVG charts (no JavaScript): line charts over an ordinal x axis, and bar charts.

Every label is XML-escaped here and the result is returned as `Markup`, so templates embed it without `|safe` and a
racer-chosen model name can never inject markup.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from markupsafe import Markup, escape

PALETTE = ("#1f6feb", "#d1242f", "#1a7f37", "#9a6700", "#8250df", "#0a7d8c")
WIDTH, HEIGHT = 560, 260
LEFT, RIGHT, TOP, BOTTOM = 56, 16, 28, 48


@dataclass(frozen=True)
class Series:
    label: str
    points: list[tuple[int, float]]  # (x index into the chart's x labels, value)


MIN_SPAN = 0.5  # of the y axis, in the plotted unit: a constant 3.0 m/s draws as a flat line on ticks 2.6 … 3.4


def _scale(values: list[float]) -> tuple[float, float]:
    low, high = min(values), max(values)
    if high - low < MIN_SPAN:
        middle = (low + high) / 2
        low, high = middle - MIN_SPAN / 2, middle + MIN_SPAN / 2
    pad = (high - low) * 0.08
    return max(low - pad, 0.0) if low >= 0 else low - pad, high + pad


def nice_ticks(low: float, high: float, count: int = 5) -> list[float]:
    """Round values (steps of 1, 2, 2.5 or 5 × 10^k) from at or below `low` to at or above `high`, about `count` of
    them: each gridline sits exactly at the number its label says (a line at 2.855 labelled "2.9" misleads)."""
    high = high if high > low else low + 1.0
    raw = (high - low) / (count - 1)
    magnitude = 10 ** math.floor(math.log10(raw))
    step = next(m * magnitude for m in (1, 2, 2.5, 5, 10) if m * magnitude >= raw * (1 - 1e-9))
    first, last = math.floor(low / step + 1e-9), math.ceil(high / step - 1e-9)
    return [round(k * step, 10) for k in range(first, max(last, first + 1) + 1)]


def tick_labels(values: list[float]) -> list[str]:
    """The fewest decimals (up to 6) that tell every tick apart and say each exactly: never five ticks all reading
    "3", nor 2.75 shown as "2.8"."""
    for decimals in range(7):
        labels = [f"{value:.{decimals}f}" for value in values]
        exact = all(abs(float(label) - value) < 1e-9 for label, value in zip(labels, values, strict=True))
        if len(set(labels)) == len(labels) and exact:
            return labels
    return [f"{value:.4g}" for value in values]


def _frame(title: str, y_label: str, ticks: list[float], y_of) -> list[str]:
    parts = [f'<text x="{LEFT}" y="16" class="plot-title">{escape(title)}</text>',
             # Turned to read upwards, its glyphs hang to the right of x=4 (a baseline at x=12 let the page's
             # font push them past the chart's left edge, issue 31: the axis label cut at 1920).
             f'<text x="4" y="{TOP + (HEIGHT - TOP - BOTTOM) / 2:.0f}" transform="rotate(-90 4 '
             f'{TOP + (HEIGHT - TOP - BOTTOM) / 2:.0f})" text-anchor="middle" dominant-baseline="hanging" '
             f'font-size="13" class="plot-axis">{escape(y_label)}</text>',
             f'<line x1="{LEFT}" y1="{HEIGHT - BOTTOM}" x2="{WIDTH - RIGHT}" y2="{HEIGHT - BOTTOM}" stroke="#888"/>',
             f'<line x1="{LEFT}" y1="{TOP}" x2="{LEFT}" y2="{HEIGHT - BOTTOM}" stroke="#888"/>']
    for value, label in zip(ticks, tick_labels(ticks), strict=True):
        y = y_of(value)
        parts.append(f'<line x1="{LEFT}" y1="{y:.1f}" x2="{WIDTH - RIGHT}" y2="{y:.1f}" stroke="#eee"/>')
        parts.append(f'<text x="{LEFT - 4}" y="{y + 4:.1f}" text-anchor="end" class="plot-tick">{label}</text>')
    return parts


def _svg(parts: list[str], title: str, testid: str) -> Markup:
    body = "".join(parts)
    return Markup(f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {WIDTH} {HEIGHT}" width="{WIDTH}" '
                  f'height="{HEIGHT}" role="img" aria-label="{escape(title)}" class="plot" '
                  f'data-testid="{escape(testid)}">{body}</svg>')


def line_chart(series: list[Series], x_labels: list[str], *, title: str, y_label: str, testid: str) -> Markup:
    values = [v for s in series for _, v in s.points]
    if not values or not x_labels:
        return Markup(f'<p class="plot-empty" data-testid="{escape(testid)}">{escape(title)}: no data yet.</p>')
    ticks = nice_ticks(*_scale(values))
    low, high = ticks[0], ticks[-1]
    span = max(len(x_labels) - 1, 1)

    def x_of(index: int) -> float:
        return LEFT + (WIDTH - LEFT - RIGHT) * (index / span if len(x_labels) > 1 else 0.5)

    def y_of(value: float) -> float:
        return TOP + (HEIGHT - TOP - BOTTOM) * (1 - (value - low) / (high - low))

    parts = _frame(title, y_label, ticks, y_of)
    for index, label in enumerate(x_labels):
        parts.append(f'<text x="{x_of(index):.1f}" y="{HEIGHT - BOTTOM + 14}" text-anchor="middle" '
                     f'class="plot-tick">{escape(label[:14])}</text>')
    for number, line in enumerate(series):
        colour = PALETTE[number % len(PALETTE)]
        points = " ".join(f"{x_of(i):.1f},{y_of(v):.1f}" for i, v in line.points)
        parts.append(f'<polyline fill="none" stroke="{colour}" stroke-width="2" points="{points}">'
                     f'<title>{escape(line.label)}</title></polyline>')
        parts.extend(f'<circle cx="{x_of(i):.1f}" cy="{y_of(v):.1f}" r="3" fill="{colour}">'
                     f'<title>{escape(line.label)}: {v:.3f}</title></circle>' for i, v in line.points)
        parts.append(f'<text x="{LEFT + 8 + 120 * number}" y="{HEIGHT - 10}" fill="{colour}" '
                     f'class="plot-legend">{escape(line.label[:18])}</text>')
    return _svg(parts, title, testid)


def bar_chart(bars: list[tuple[str, float]], *, title: str, y_label: str, testid: str) -> Markup:
    if not bars:
        return Markup(f'<p class="plot-empty" data-testid="{escape(testid)}">{escape(title)}: no data yet.</p>')
    ticks = nice_ticks(0.0, max(v for _, v in bars) * 1.1 or 1.0)
    low, high = ticks[0], ticks[-1]

    def y_of(value: float) -> float:
        return TOP + (HEIGHT - TOP - BOTTOM) * (1 - (value - low) / (high - low))

    parts = _frame(title, y_label, ticks, y_of)
    slot = (WIDTH - LEFT - RIGHT) / len(bars)
    for index, (label, value) in enumerate(bars):
        x = LEFT + slot * index + slot * 0.15
        parts.append(f'<rect x="{x:.1f}" y="{y_of(value):.1f}" width="{slot * 0.7:.1f}" '
                     f'height="{y_of(low) - y_of(value):.1f}" fill="{PALETTE[index % len(PALETTE)]}">'
                     f'<title>{escape(label)}: {value:.3f}</title></rect>')
        parts.append(f'<text x="{x + slot * 0.35:.1f}" y="{HEIGHT - BOTTOM + 14}" text-anchor="middle" '
                     f'class="plot-tick">{escape(label[:16])}</text>')
    return _svg(parts, title, testid)
