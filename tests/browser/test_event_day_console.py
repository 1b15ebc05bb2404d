"""Issue 13 (event day), the console as staff meet it in Chromium: the track types up to re:Invent 2024 on the event
form, confirming a self sign-up whose emailed code never came, pages that load without a single console error, and
the main console pages on a tablet (768×1024 and 1024×768) without sideways scrolling."""
from __future__ import annotations

from typing import Any

import pytest
import requests

from tests.browser.console_api import PASSWORD, access_token, call, cognito, create_user, sign_in, submitted_race
from tests.browser.test_event_day import SCREENSHOTS
from tests.unit.models_helpers import onnx_archive

pytestmark = pytest.mark.browser

TABLET_PORTRAIT = {"width": 768, "height": 1024}
DESKTOP = {"width": 1920, "height": 1080}
FOREVER = "re:Invent 2024 · Forever Raceway"


@pytest.fixture(scope="module")
def console_day(live_stack: Any) -> dict[str, Any]:
    """An operator's event day with something on every main page: an event with a long-named track, a race with laps,
    a car reporting in, a racer's model."""
    url = live_stack.url
    create_user(live_stack, "tab-op", "operator")
    token = access_token(live_stack, "tab-op")
    fleet = call(url, "POST", "/api/fleets", token=token, body={"name": "Tablet fleet"}, expect=201)
    event = call(url, "POST", "/api/events", token=token, expect=201, body={
        "name": "Tablet Championship Qualifier", "event_type": "OFFICIAL_TRACK_RACE", "date": "2026-06-02",
        "country_code": "DE", "sponsor": "Acme Robotics",
        "race_config": {"track_type": "FOREVER_RACEWAY"},
        "tracks": [{"track_id": "1", "fleet_id": fleet["fleet_id"], "leaderboard_title": "Main stage by the entrance"},
                   {"track_id": "2", "leaderboard_title": "Side stage"}]})
    event_id = event["event_id"]
    create_user(live_stack, "tab-racer", "racer")
    submitted_race(url, token, event_id, "tab-racer", [9_321, 9_876])
    code = call(url, "POST", "/api/devices/activation-codes", token=token, expect=201, body={
        "fleet_id": fleet["fleet_id"], "hostname": "tablet-car-with-a-long-hostname", "device_kind": "car"})["code"]
    credential = call(url, "POST", "/api/devices/activate", expect=201, body={
        "code": code, "hostname": "tablet-car-with-a-long-hostname", "device_kind": "car"})["credential"]
    call(url, "POST", "/api/devices/self/heartbeat", device=credential, body={"battery_pct": 58})
    racer_token = access_token(live_stack, "tab-racer")
    ticket = call(url, "POST", "/api/models", token=racer_token, body={"filename": "tablet-model.tar.gz"}, expect=201)
    posted = requests.post(ticket["upload"]["url"], data=ticket["upload"]["fields"], timeout=15,
                           files={"file": ("tablet-model.tar.gz", onnx_archive())})
    assert posted.status_code in (200, 204), posted.text
    call(url, "POST", f"/api/models/{ticket['model']['model_id']}/complete", token=racer_token, expect=200)
    return {"event_id": event_id}


# --- item 18: track types stop at 2023 ------------------------------------------------------------------------------

def test_the_new_event_form_offers_the_2024_track_and_the_saved_event_names_it(chromium, console_day, app_url,
                                                                                live_stack):
    context = chromium.new_context(viewport=DESKTOP)
    page = context.new_page()
    sign_in(page, app_url, "tab-op")
    page.goto(app_url + "/console/events/new")
    offered = page.locator("#track_type option").all_inner_texts()
    assert offered[:5] == ["re:Invent 2018", "re:Invent 2019", "re:Invent 2022", "re:Invent 2023", FOREVER], offered
    assert not [text for text in offered if "_" in text or text.isupper()]  # words, not enum values
    page.fill("#name", "Forever Cup")
    page.fill("#country_code", "Sweden (SE)")
    page.select_option("#track_type", label=FOREVER)
    page.get_by_role("button", name="Create event").click()
    page.wait_for_url(app_url + "/console/events?done=event-created")
    row = page.locator("tr", has_text="Forever Cup")
    assert row.get_by_test_id("event-track-type").inner_text() == FOREVER
    # Saved as DREM's value, and the edit form opens on it.
    event_id = row.get_attribute("data-event-id")
    saved = call(app_url, "GET", f"/api/events/{event_id}", token=access_token(live_stack, "tab-op"))
    assert saved["race_config"]["track_type"] == "FOREVER_RACEWAY"
    row.get_by_role("link", name="Edit").click()
    assert page.locator("#track_type option:checked").inner_text() == FOREVER
    context.close()


# --- item 4: staff have no way to confirm a self sign-up ------------------------------------------------------------

def test_an_admin_confirms_a_sign_up_whose_emailed_code_never_came_and_the_racer_signs_in(chromium, app_url,
                                                                                         live_stack):
    # What Cognito holds after a self sign-up on AWS whose code never arrived (no SES): an UNCONFIRMED account with
    # its racer role. A local stack confirms its own sign-ups at once, so the account is made the way AWS leaves it.
    client, pool = cognito(live_stack), live_stack.outputs.user_pool_id
    client.sign_up(ClientId=live_stack.outputs.user_pool_client_id, Username="ana.nocode", Password=PASSWORD,
                   UserAttributes=[{"Name": "email", "Value": "ana.nocode@example.test"},
                                   {"Name": "custom:countryCode", "Value": "ES"}])
    client.admin_add_user_to_group(UserPoolId=pool, Username="ana.nocode", GroupName="racer")
    create_user(live_stack, "tab-admin", "admin")

    racer = chromium.new_context(viewport=TABLET_PORTRAIT).new_page()
    racer.goto(app_url + "/login")
    racer.fill("#username", "ana.nocode")
    racer.fill("#password", PASSWORD)
    racer.get_by_role("button", name="Sign in").click()
    # Refused, and sent to the staff, who until now had no way to help.
    racer.get_by_text("This account is not confirmed yet; ask the event staff.").wait_for()

    context = chromium.new_context(viewport=TABLET_PORTRAIT)
    admin = context.new_page()
    sign_in(admin, app_url, "tab-admin")
    admin.goto(app_url + "/console/users?q=ana")
    row = admin.locator("tr[data-username='ana.nocode']")
    assert row.get_by_test_id("user-status").inner_text() == "waiting for the emailed code"
    row.get_by_role("button", name="Confirm ana.nocode").click()
    notice = admin.locator("tr[data-username='ana.nocode']").get_by_test_id("notice")
    notice.wait_for()
    assert notice.inner_text() == "ana.nocode is confirmed and can sign in now."
    assert admin.locator("tr[data-username='ana.nocode']").get_by_test_id("user-status").count() == 0
    assert admin.locator("tr[data-username='ana.nocode']").get_by_role("button", name="Confirm ana.nocode").count() \
        == 0
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    admin.screenshot(path=str(SCREENSHOTS / "users-confirmed-768.png"))

    sign_in(racer, app_url, "ana.nocode")  # with the password chosen at sign-up
    racer.goto(app_url + "/console/my-models")
    assert racer.locator("h1").first.inner_text().strip() != "Not allowed"
    racer.context.close()
    context.close()
