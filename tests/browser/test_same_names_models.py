"""Issue 31: the operators' Models page named racers by sign-in name. Two racers both called Björn and 山田太郎 upload
models; the page names them by display name ("Björn (…)" where two collide) in its rows (the assign choices: see
tests/unit/test_console_staff.py), and its
racer box finds them by display name, at 1920×1080 and 390×844. `browser_errors` (conftest) fails it on a console
error or CSP violation."""
from __future__ import annotations

import secrets
from pathlib import Path
from typing import Any

import pytest

from tests.browser.console_api import access_token, call, create_user, sign_in
from tests.browser.test_timekeeper_on_deck import _upload_model
from tests.unit.models_helpers import onnx_archive

pytestmark = pytest.mark.browser

SCREENSHOTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "same-names"


def test_the_models_page_names_racers_by_display_name(chromium: Any, live_stack: Any, app_url: str,
                                                      browser_errors: Any) -> None:
    suffix = secrets.token_hex(2)
    shown = {}
    for index, (username, name) in enumerate((("mb_bjorn_a", "Björn"), ("mb_bjorn_b", "björn"),
                                              ("mb_yamada", "山田太郎"))):
        username = f"{username}_{suffix}"
        create_user(live_stack, username, "racer")
        token = access_token(live_stack, username)
        call(app_url, "PUT", "/api/me/profile", token=token, body={"display_name": name})
        _upload_model(app_url, token, f"{username}-fast.tar.gz", onnx_archive(0.07 * (index + 1)))
        shown[f"{username}-fast"] = name if name == "山田太郎" else f"{name} ({username})"
    operator = create_user(live_stack, f"mb-op-{suffix}", "operator")

    for size in ({"width": 1920, "height": 1080}, {"width": 390, "height": 844}):
        page = chromium.new_context(viewport=size).new_page()
        sign_in(page, app_url, operator)
        page.goto(f"{app_url}/console/models")
        for model, racer in shown.items():
            row = page.locator(f"[data-testid=staff-model-row][data-model-name='{model}']")
            assert row.get_by_test_id("model-racer").inner_text().strip() == racer
        page.fill("#racer", "山田")
        page.press("#racer", "End")  # the box asks on keyup, as a typing user sends it
        page.wait_for_function("() => [...document.querySelectorAll('[data-testid=model-racer]')]"
                               ".every(cell => cell.textContent.trim() === '山田太郎')", timeout=20_000)
        page.fill("#racer", "björn")
        page.press("#racer", "End")
        page.wait_for_function("() => [...document.querySelectorAll('[data-testid=model-racer]')]"
                               ".every(cell => cell.textContent.trim().toLowerCase().startsWith('björn'))",
                               timeout=20_000)
        SCREENSHOTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SCREENSHOTS / f"models-same-names-{size['width']}x{size['height']}.png"))
        page.context.close()
