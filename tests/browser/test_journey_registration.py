"""The registration desk, in a real browser: an admin makes a colleague registration staff (Users page, active
search), the colleague creates racers one after another from the keyboard, and a new racer signs in with the
temporary password and chooses their own."""
from __future__ import annotations

import secrets

import pytest

pytestmark = pytest.mark.browser


def sign_in(page, url: str, username: str, password: str) -> None:
    page.goto(url + "/login")
    page.fill("#username", username)
    page.fill("#password", password)
    page.get_by_role("button", name="Sign in").click()


def choose_password(page, url: str, password: str) -> None:
    page.wait_for_url(url + "/login/new-password")
    page.fill("#new_password", password)
    page.fill("#confirm_password", password)
    page.get_by_role("button", name="Save password and sign in").click()
    page.wait_for_url(url + "/")


def create_at_desk(page, username: str, display_name: str = "") -> str:
    """Type a racer in, keyboard only (Enter submits); returns the temporary password shown. Like a person, it
    starts typing once the cursor is in the username field (autofocus on a fresh page, htmx's refocus after a
    swap): keys typed before that land nowhere."""
    page.wait_for_function("() => document.activeElement && document.activeElement.id === 'username'")
    page.keyboard.type(username)
    page.keyboard.press("Tab")
    page.keyboard.type(display_name)  # the name the racer goes by, in any script (empty: the sign-in name)
    page.keyboard.press("Tab")
    page.keyboard.type(f"{username}@example.test")
    page.fill("#country_code", "Germany")  # the country picker, by name
    page.focus("#email")
    page.keyboard.press("Enter")
    registered = page.get_by_test_id("registered-username").filter(has_text=username)
    try:
        registered.wait_for(timeout=30_000)
    except Exception as error:  # say what the desk showed instead (a refusal, an error page) rather than only a timeout
        raise AssertionError(f"{username} was not registered; the page shows: "
                             f"{page.locator('body').inner_text()[:1500]!r}") from error
    return page.get_by_test_id("temporary-password").inner_text()


def test_desk_staff_register_racers_who_then_choose_their_password(app_url, live_stack, page, chromium):
    suffix = secrets.token_hex(3)
    desk, first, second = f"desk-{suffix}", f"kim-{suffix}", f"lee-{suffix}"

    # The admin registers a colleague at the desk, then makes them registration staff on the Users page.
    sign_in(page, app_url, live_stack.admin_username, live_stack.admin_password)
    page.goto(app_url + "/console/registration")
    desk_password = create_at_desk(page, desk)
    page.goto(app_url + "/console/users")
    page.locator("#q").press_sequentially(desk[:7])  # active search: the table narrows as the admin types
    row = page.locator(f'[data-testid="user-row"][data-username="{desk}"]')
    row.wait_for()
    page.wait_for_function("() => document.querySelectorAll('[data-testid=user-row]').length === 1")
    row.get_by_test_id("user-role").select_option("registration")
    row.get_by_role("button", name="Set role").click()
    page.wait_for_function(
        f"() => document.querySelector('[data-username=\"{desk}\"] [data-testid=user-role]').value"
        " === 'registration'")
    page.context.clear_cookies()

    # The colleague signs in (temporary password → their own) and sees only the desk among staff screens.
    sign_in(page, app_url, desk, desk_password)
    choose_password(page, app_url, "Desk-Duty-2026")
    nav = page.get_by_test_id("nav-links").inner_text()
    assert "Registration" in nav and "Users" not in nav and "Models" not in nav.replace("My models", "")
    page.get_by_test_id("nav-links").get_by_role("link", name="Registration").click()
    page.wait_for_url(app_url + "/console/registration")
    assert page.evaluate("document.activeElement.id") == "username"  # autofocus: type straight away

    first_password = create_at_desk(page, first, "Siobhán Ó Sé")
    box = page.get_by_test_id("temporary-password-box")
    assert f"Account {first} for Siobhán Ó Sé is ready." in box.inner_text()
    # The form is reset for the next racer, the cursor back in the username, the country kept.
    assert page.input_value("#username") == "" and page.input_value("#email") == ""
    assert page.input_value("#country_code") == "Germany (DE)"
    # htmx applies autofocus once it has settled the swapped form: wait for it, then it must be the username.
    page.wait_for_function("() => document.activeElement && document.activeElement.id === 'username'", timeout=5_000)

    # A taken name is refused next to the field, nothing typed is lost.
    page.keyboard.type(first)
    page.keyboard.press("Tab")
    page.keyboard.press("Tab")
    page.keyboard.type("again@example.test")
    page.keyboard.press("Enter")
    page.locator("#username-error").wait_for()
    assert page.locator("#username-error").inner_text() == f"The user name '{first}' is taken."
    assert page.input_value("#email") == "again@example.test"
    # As after a registration, the desk puts the cursor back in the username once the swap has settled: wait for it,
    # or that late refocus lands in the middle of the next racer's typing (the email's letters went into the name).
    page.wait_for_function("() => document.activeElement && document.activeElement.id === 'username'", timeout=5_000)
    page.fill("#username", "")
    page.focus("#username")
    second_password = create_at_desk(page, second)
    assert second_password != first_password
    assert page.get_by_test_id("temporary-password").count() == 1  # only the latest racer's password is shown

    # The first racer signs in with the temporary password and chooses their own.
    racer = chromium.new_context().new_page()
    try:
        sign_in(racer, app_url, first, first_password)
        choose_password(racer, app_url, "My-Own-Pass-77")
        assert racer.get_by_test_id("signed-in-as").inner_text() == f"Signed in as {first}"
        assert "Your roles: racer." in racer.inner_text("main")
    finally:
        racer.context.close()
