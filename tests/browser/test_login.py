"""Signing in and out in a real browser against the local stack (durable moto + app server)."""
from __future__ import annotations

import pytest

pytestmark = pytest.mark.browser


def test_admin_signs_in_sees_home_and_signs_out(live_stack, page):
    page.goto(live_stack.url + "/")
    page.get_by_role("link", name="Sign in").first.click()
    page.wait_for_url(live_stack.url + "/login")

    page.fill("#username", live_stack.admin_username)
    page.fill("#password", live_stack.admin_password)
    page.get_by_role("button", name="Sign in").click()

    page.wait_for_url(live_stack.url + "/")
    assert page.get_by_test_id("signed-in-as").inner_text() == f"Signed in as {live_stack.admin_username}"
    assert "Your roles: admin." in page.inner_text("main")
    assert page.evaluate("typeof htmx !== 'undefined' && htmx.version") == "2.0.8"
    cookies = {c["name"]: c for c in page.context.cookies()}
    assert cookies["drem_session"]["httpOnly"] and cookies["drem_session"]["sameSite"] == "Lax"
    assert page.evaluate("document.cookie") == ""  # nothing readable by page scripts

    page.get_by_role("button", name="Sign out").click()

    page.wait_for_url(live_stack.url + "/login")
    assert page.get_by_role("button", name="Sign in").is_visible()
    assert "drem_session" not in {c["name"] for c in page.context.cookies()}


def test_wrong_password_shows_the_error_next_to_the_password_field(live_stack, page):
    page.goto(live_stack.url + "/login")

    page.fill("#username", live_stack.admin_username)
    page.fill("#password", "Not-The-Password-1")
    page.get_by_role("button", name="Sign in").click()

    error = page.locator("#password-error")
    error.wait_for()
    assert error.inner_text() == "Incorrect username or password."
    # The message sits right after the password input and is tied to it for screen readers.
    assert page.locator("#password + #password-error").count() == 1
    assert page.get_attribute("#password", "aria-describedby") == "password-error"
    assert page.input_value("#username") == live_stack.admin_username
