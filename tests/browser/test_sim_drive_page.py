"""The manual-drive page in real Chromium: holding keys drives the car, the page shows it, Record records."""
from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drem_sim import drive_server
from drem_sim.tracks import load_track

pytestmark = pytest.mark.browser

@pytest.fixture
def drive_page(chromium: Any, tmp_path: Path) -> Iterator[tuple[Any, drive_server.DriveServer]]:
    """The page of `drem sim drive` on the oval, in the session's Chromium (one Playwright per process)."""
    server, threads = drive_server.start(load_track("drem_oval"), tmp_path / "runs", port=0)
    context = chromium.new_context()
    try:
        page = context.new_page()
        page.set_default_timeout(10_000)
        page.goto(server.url)
        yield page, server
    finally:
        context.close()
        drive_server.stop(server, threads)


def _number(page: Any, element_id: str) -> float:
    return float(page.text_content(f"#{element_id}").split()[0].rstrip("°"))


def test_holding_the_up_arrow_drives_the_car_and_the_page_shows_progress(drive_page) -> None:
    page, server = drive_page
    page.wait_for_function("document.getElementById('track').textContent === 'drem_oval'")
    assert _number(page, "progress") == 0.0

    page.keyboard.down("ArrowUp")
    page.wait_for_function("parseFloat(document.getElementById('progress').textContent) > 3")
    page.keyboard.up("ArrowUp")

    assert _number(page, "progress") > 3 and server.session.state()["progress"] > 3
    # the camera view is a live 160x120 frame (polled: while the next frame loads the image may be empty)
    page.wait_for_function("document.getElementById('camera').complete"
                           " && document.getElementById('camera').naturalWidth === 160")


def test_steering_keys_and_the_record_button(drive_page) -> None:
    page, server = drive_page
    page.keyboard.down("KeyA")
    page.wait_for_function("document.getElementById('steering').textContent === '30°'")
    page.keyboard.up("KeyA")
    page.wait_for_function("document.getElementById('steering').textContent === '0°'")

    page.click("#record")
    page.wait_for_function("document.getElementById('recording').textContent.startsWith('on')")
    page.keyboard.down("KeyW")
    page.wait_for_function("parseFloat(document.getElementById('progress').textContent) > 1")
    page.keyboard.up("KeyW")
    page.click("#record")
    page.wait_for_function("document.getElementById('last-run').textContent.includes('frames')")

    run_dir = Path(server.session.state()["last_run"]["run_dir"])
    meta = json.loads((run_dir / "metadata.json").read_text())
    assert meta["driver"] == "human" and meta["frames"] > 0
    assert str(run_dir) in page.text_content("#last-run")
