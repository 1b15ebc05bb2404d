"""How figures read wherever drem writes them (boards, overlays, results PDFs, statistics, the audit trail): lap
times, gaps and colours. Plain text, no markup, so every layer from the domain up may use them."""
from __future__ import annotations

import re

_HEX_COLOUR = re.compile(r"#?([0-9a-fA-F]{3}|[0-9a-fA-F]{6})")


def lap_time(ms: int | None, dnf: str = "DNF") -> str:
    """1:02.345, 0:09.876; None → DNF."""
    if ms is None:
        return dnf
    minutes, rest = divmod(max(0, ms), 60_000)
    return f"{minutes}:{rest // 1000:02d}.{rest % 1000:03d}"


def gap_time(ms: int | None) -> str:
    """+0.123, +1:02.345; the leader and DNF show nothing."""
    if not ms:
        return ""
    if ms < 60_000:
        return f"+{ms // 1000}.{ms % 1000:03d}"
    return f"+{lap_time(ms)}"


def safe_colour(value: str | None, default: str) -> str:
    """`#rgb`/`#rrggbb` (the `#` optional in the input) or `default`: nothing else ever reaches a stylesheet."""
    match = _HEX_COLOUR.fullmatch((value or "").strip())
    return f"#{match.group(1).lower()}" if match else default
