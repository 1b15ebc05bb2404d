"""A model whose test drive stops without a verdict, as a racer and as staff see it in a browser: the racer reads one
sentence (what was tried, what went wrong, what to do) and never an exception's name; staff also get the technical
detail, folded. Screenshots at 1920x1080 and 390x844 land in test-artifacts/ (reviewed copies in docs/screenshots/)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.browser.console_api import access_token, call, create_user, sign_in, upload_model
from tests.unit.models_helpers import UNREADABLE_IR_VERSION, onnx_archive

pytestmark = pytest.mark.browser

SCREENSHOTS = Path(__file__).resolve().parents[2] / "test-artifacts"
CODE_NAMES = re.compile(r"\b\w*(Error|Exception|Traceback)\b|onnxruntime|\w+\.\w+\.\w+")



def test_a_stopped_test_drive_is_a_sentence_for_the_racer_and_a_detail_for_staff(live_stack, app_url, page) -> None:
    create_user(live_stack, "words-racer", "racer")
    create_user(live_stack, "words-op", "operator")
    token = access_token(live_stack, "words-racer")
    model = upload_model(app_url, token, "too-new-graph.tar.gz", onnx_archive(0.2, ir_version=UNREADABLE_IR_VERSION))
    answer = call(app_url, "POST", f"/api/models/{model['model_id']}/scrutineer", token=token,
                  body={"track_type": "REINVENT_2018", "laps": 1})["model"]
    assert answer["scrutineer_status"] == "cannot_scrutineer", answer
    assert "detail" not in answer["scrutineer_result"], "the racer's API answer carries no technical detail"

    sign_in(page, app_url, "words-racer")
    page.set_viewport_size({"width": 1920, "height": 1080})
    page.goto(app_url + "/console/my-models")
    row = page.locator('[data-testid="model-row"][data-model-name="too-new-graph"]')
    reason = row.get_by_test_id("scrutiny-reason")
    reason.wait_for()
    text = reason.inner_text()
    assert "so it was not checked" in text and "Drive again" in text, text
    assert not CODE_NAMES.search(text), text
    assert row.get_by_test_id("scrutiny-detail").count() == 0, "racers never see the technical detail"
    SCREENSHOTS.mkdir(exist_ok=True)
    reason.scroll_into_view_if_needed()
    page.screenshot(path=str(SCREENSHOTS / "scrutiny-in-words-racer-1920x1080.png"))
    page.set_viewport_size({"width": 390, "height": 844})
    reason.scroll_into_view_if_needed()
    page.screenshot(path=str(SCREENSHOTS / "scrutiny-in-words-racer-390x844.png"))

    page.context.clear_cookies()
    sign_in(page, app_url, "words-op")
    page.set_viewport_size({"width": 1920, "height": 1080})
    page.goto(app_url + "/console/models?racer=words-racer")
    staff_row = page.locator('[data-testid="staff-model-row"][data-model-name="too-new-graph"]')
    detail = staff_row.get_by_test_id("scrutiny-detail")
    detail.get_by_text("Technical detail (staff)").click()
    detail_text = detail.locator("pre").inner_text()
    assert re.search(r"\w+(Error|Exception|Fail)\w*", detail_text), detail_text  # what the software said
    assert staff_row.get_by_test_id("scrutiny-reason").inner_text().startswith("could not scrutineer")
    detail.scroll_into_view_if_needed()
    page.screenshot(path=str(SCREENSHOTS / "scrutiny-in-words-staff-1920x1080.png"))
    page.set_viewport_size({"width": 390, "height": 844})
    detail.scroll_into_view_if_needed()
    page.screenshot(path=str(SCREENSHOTS / "scrutiny-in-words-staff-390x844.png"))
    assert page.evaluate("document.documentElement.scrollWidth") <= 390, "the detail wraps instead of a sideways scroll"
