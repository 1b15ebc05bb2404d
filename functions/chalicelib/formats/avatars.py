"""Deterministic SVG identicons: a mirrored 5×5 grid drawn from a hash of the racer's sign-in name (`avatar_seed`:
the same after `drem export`/`drem import`, which give the account a new sub), in their highlight colour, or the
board's default colour for a racer who never picked one (so the avatar matches their row's stripe).

Every value placed in the SVG is XML-escaped, even ones drem validated, because the SVG is served from our origin.
"""
from __future__ import annotations

import hashlib
from xml.sax.saxutils import escape

from drem_leaderboard.ranking import DEFAULT_HIGHLIGHT_COLOUR

_GRID = 5
_CELL = 10
_MARGIN = 5
NEUTRAL_COLOUR = "#9E9E9E"
# The board's stripe colour for a racer without one.
DEFAULT_COLOUR = DEFAULT_HIGHLIGHT_COLOUR


def avatar_seed(username: str) -> str:
    """What a racer's identicon is drawn from: their sign-in name, case-folded (unique in any case)."""
    return f"racer:{username.casefold()}"


def identicon_cells(seed: str) -> list[tuple[int, int]]:
    """(column, row) of filled cells; the left half is drawn from the hash and mirrored onto the right."""
    digest = hashlib.sha256(seed.encode("utf-8")).digest()
    cells = []
    for row in range(_GRID):
        for column in range((_GRID + 1) // 2):
            if digest[row * 3 + column] & 1:
                cells.append((column, row))
                if column != _GRID - 1 - column:
                    cells.append((_GRID - 1 - column, row))
    return sorted(cells)


def identicon_svg(seed: str, colour: str | None, title: str) -> str:
    size = _GRID * _CELL + 2 * _MARGIN
    fill = _attribute(colour or DEFAULT_COLOUR)
    rects = "".join(
        f'<rect x="{_MARGIN + column * _CELL}" y="{_MARGIN + row * _CELL}" width="{_CELL}" height="{_CELL}"/>'
        for column, row in identicon_cells(seed))
    return (f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {size} {size}" width="{size}" height="{size}" '
            f'role="img"><title>{escape(title)}</title><rect width="{size}" height="{size}" fill="#FFFFFF"/>'
            f'<g fill="{fill}">{rects}</g></svg>')


def _attribute(value: str) -> str:
    return escape(value, {'"': "&quot;", "'": "&apos;"})
