"""A racer who types a staff address sees a "Not allowed" page for every staff screen, and the JSON API behind
those screens refuses the racer's session too."""
from __future__ import annotations

import secrets

import pytest

pytestmark = pytest.mark.browser

PASSWORD = "Only-Racing-42"
STAFF_PAGES = ["/console/users", "/console/models", "/console/registration", "/console/events", "/console/fleets",
               "/console/cars", "/console/timekeeper", "/console/races"]
STAFF_API = [("GET", "/api/users"), ("GET", "/api/devices"), ("GET", "/api/fleets"),
             ("POST", "/api/events"), ("PUT", "/api/users/admin/role")]


def make_racer(live_stack) -> str:
    username = f"racer-{secrets.token_hex(3)}"
    cognito = live_stack.client("cognito-idp")
    pool = live_stack.outputs.user_pool_id
    cognito.admin_create_user(UserPoolId=pool, Username=username, MessageAction="SUPPRESS",
                              UserAttributes=[{"Name": "email", "Value": f"{username}@example.test"}])
    cognito.admin_set_user_password(UserPoolId=pool, Username=username, Password=PASSWORD, Permanent=True)
    cognito.admin_add_user_to_group(UserPoolId=pool, Username=username, GroupName="racer")
    return username


def test_a_racer_gets_not_allowed_on_every_staff_page_and_from_the_api(app_url, live_stack, page):
    username = make_racer(live_stack)
    page.goto(app_url + "/login")
    page.fill("#username", username)
    page.fill("#password", PASSWORD)
    page.get_by_role("button", name="Sign in").click()
    page.wait_for_url(app_url + "/")
    nav = page.get_by_test_id("nav-links").inner_text().split("\n")
    # Group titles show upper-case (CSS); a racer has no Registration, Race control or Admin group.
    assert [line.strip() for line in nav if line.strip()] == ["RACER", "My models", "My races", "My model versions",
                                                              "Learning booth", "Profile", "RESULTS", "League"]

    for path in STAFF_PAGES:
        response = page.goto(app_url + path)
        assert response is not None and response.status == 403, path
        assert page.get_by_role("heading", level=1).inner_text() == "Not allowed", path
        assert "This needs the role" in page.get_by_test_id("error-message").inner_text(), path
        assert f"You are signed in as {username}" in page.inner_text("main"), path

    csrf = next(c["value"] for c in page.context.cookies() if c["name"] == "drem_csrf")
    for method, path in STAFF_API:
        # The racer's own session cookie rides along (page.request shares the browser's cookies).
        reply = page.request.fetch(app_url + path, method=method, data={} if method != "GET" else None,
                                   headers={"Accept": "application/json", "X-CSRF-Token": csrf})
        assert reply.status == 403, (method, path, reply.text())
        assert "This needs the role" in reply.json()["error"]["message"]

    # A staff action posted from the racer's page is refused too (server-side, not just hidden).
    reply = page.request.post(app_url + "/console/registration", headers={"X-CSRF-Token": csrf},
                              form={"username": "sneaky", "email": "s@example.test", "country_code": "SE"})
    assert reply.status == 403
    assert "Not allowed" in reply.text()
