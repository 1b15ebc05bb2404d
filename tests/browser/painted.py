"""Waiting for the page itself, not for a fixed time, before a screenshot or a layout check."""
from __future__ import annotations

from typing import Any

# Resolves once the browser has painted two more frames: a resize or a swap done before it is on screen after it.
TWO_FRAMES = "() => new Promise(done => requestAnimationFrame(() => requestAnimationFrame(() => done(true))))"


def painted(page: Any) -> None:
    """Return once the page has laid out and painted what was done to it so far (a resize, a swap)."""
    page.evaluate(TWO_FRAMES)
