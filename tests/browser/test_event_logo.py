"""The event's logo as an organiser meets it in Chromium: uploaded on the event's edit page (a refused file named next
to the input), then shown beside the event's name on the big screen at 1920×1080 and on a phone, and on the chroma
overlay on an opaque tile."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from PIL import Image, ImageDraw, ImageFont

from tests.browser.console_api import access_token, call, create_user, sign_in, submitted_race

pytestmark = pytest.mark.browser

REPO = Path(__file__).resolve().parents[2]
SCREENSHOTS = REPO / "test-artifacts" / "big-screen"
BIG_SCREEN = {"width": 1920, "height": 1080}
PHONE = {"width": 390, "height": 844}


def sponsor_logo(path: Path) -> Path:
    """A wide logo on a transparent background, the way sponsors hand them out."""
    logo = Image.new("RGBA", (1200, 400), (0, 0, 0, 0))
    draw = ImageDraw.Draw(logo)
    draw.rounded_rectangle((20, 60, 300, 340), radius=60, fill=(255, 153, 0, 255))
    draw.polygon([(90, 280), (160, 110), (230, 280)], fill=(255, 255, 255, 255))
    draw.text((340, 110), "ACME", font=ImageFont.load_default(size=190), fill=(255, 255, 255, 255))
    logo.save(path)
    return path


@pytest.fixture(scope="module")
def event_id(live_stack: Any) -> str:
    create_user(live_stack, "logo-op", "operator")
    token = access_token(live_stack, "logo-op")
    event_id: str = call(live_stack.url, "POST", "/api/events", token=token, expect=201, body={
        "name": "Logo Cup", "event_type": "OFFICIAL_TRACK_RACE", "date": "2026-06-01", "country_code": "SE",
        "sponsor": "Acme Robotics", "race_config": {"race_time_min": 3},
        "tracks": [{"track_id": "1", "leaderboard_title": "Main stage"}]})["event_id"]
    for racer, lap_ms in (("logo-racer-1", 8_912), ("logo-racer-2", 9_304)):  # a board with rows, as on the day
        create_user(live_stack, racer, "racer")
        submitted_race(live_stack.url, token, event_id, racer, [lap_ms])
    return event_id


def test_an_organiser_uploads_a_logo_and_the_big_screen_shows_it_beside_the_name(
        chromium: Any, live_stack: Any, app_url: str, event_id: str, tmp_path: Path) -> None:
    context = chromium.new_context(viewport={"width": 1280, "height": 900})
    page = context.new_page()
    sign_in(page, app_url, "logo-op")
    page.goto(f"{app_url}/console/events/{event_id}/edit")

    svg = tmp_path / "logo.svg"
    svg.write_text('<svg xmlns="http://www.w3.org/2000/svg"><script>alert(1)</script></svg>')
    page.set_input_files("#logo-file", str(svg))
    page.get_by_role("button", name="Upload logo").click()
    error = page.locator("#logo-error")
    error.wait_for()
    assert error.inner_text() == "SVG logos are not accepted (an SVG can carry scripts): export it as PNG."

    page.set_input_files("#logo-file", str(sponsor_logo(tmp_path / "acme.png")))
    page.get_by_role("button", name="Upload logo").click()
    page.get_by_test_id("notice").wait_for()
    assert page.get_by_test_id("notice").inner_text().startswith("Logo saved")
    preview = page.get_by_test_id("logo-preview")
    preview.scroll_into_view_if_needed()
    page.wait_for_function("() => document.querySelector('[data-testid=logo-preview]').complete")
    assert 600 <= preview.evaluate("img => img.naturalWidth") <= 960  # the drawn logo, its margin cropped
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    page.get_by_test_id("logo-section").screenshot(path=str(SCREENSHOTS / "logo-console-section-1280.png"))
    context.close()

    for size in (BIG_SCREEN, PHONE):
        viewer = chromium.new_context(viewport=size)
        board = viewer.new_page()
        board.goto(f"{app_url}/leaderboard/{event_id}?summary_seconds=0")
        board.wait_for_function("() => { const img = document.querySelector('[data-testid=board-logo]');"
                                " return img && img.complete; }")
        logo = board.get_by_test_id("board-logo").evaluate("""img => {
            const box = img.getBoundingClientRect(), title = document.querySelector('.board-title');
            const tbox = title.getBoundingClientRect();
            return {natural: img.naturalWidth, width: box.width, height: box.height, right: box.right,
                    titleLeft: tbox.left, titleMiddle: tbox.top + tbox.height / 2,
                    middle: box.top + box.height / 2};
        }""")
        assert logo["natural"] >= 600, logo  # the image really loaded
        assert logo["right"] <= logo["titleLeft"], logo  # beside the name, not over it
        assert abs(logo["middle"] - logo["titleMiddle"]) < logo["height"], logo
        if size is BIG_SCREEN:
            assert logo["height"] >= 60, logo  # about 6 cm on a 2 m wide screen: seen from 5 m
        SCREENSHOTS.mkdir(parents=True, exist_ok=True)
        board.screenshot(path=str(SCREENSHOTS / f"logo-{size['width']}x{size['height']}.png"))
        viewer.close()

    overlay_context = chromium.new_context(viewport=BIG_SCREEN)
    overlay = overlay_context.new_page()
    overlay.goto(f"{app_url}/overlay/{event_id}?trackId=1&chroma=1")
    overlay.wait_for_function("() => { const img = document.querySelector('[data-testid=overlay-logo]');"
                              " return img && img.complete && img.naturalWidth > 0; }")
    tile = overlay.get_by_test_id("overlay-logo").evaluate("img => getComputedStyle(img).backgroundColor")
    assert tile == "rgb(11, 15, 25)"  # opaque: the keyer cannot eat into the logo's soft edges
    overlay.screenshot(path=str(SCREENSHOTS / "logo-overlay-chroma-1920x1080.png"))
    overlay_context.close()
