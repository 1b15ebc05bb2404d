"""Racer screens over HTTP (Chalice test client + moto): sign-up and confirm, password, profile, my models, my races.
Each test checks what the page shows and that the change really happened in the services behind it."""
from __future__ import annotations

import re
from typing import Any

import pytest

from chalicelib.domain.names import USERNAME_LENGTH_MESSAGE
from tests.unit.conftest import PASSWORD, Browser
from tests.unit.models_helpers import ModelsApi, archive_without_metadata, bearer, onnx_archive
from tests.unit.racer_console_helpers import body, field_error, post, sign_in, signed_in, text

pytestmark = pytest.mark.unit


@pytest.fixture
def app(client: Any) -> Any:
    return client


def test_sign_up_shows_each_refusal_next_to_its_field_and_keeps_what_was_typed(app: Any) -> None:
    visitor = Browser(app)
    visitor.get("/signup")
    reply = post(visitor, "/signup", {"username": "a", "email": "ann@example.test", "country_code": "SE",
                                      "password": "Fast-Lap-2026"})
    assert reply.status_code == 400
    assert field_error(reply, "username") == USERNAME_LENGTH_MESSAGE
    assert 'value="ann@example.test"' in body(reply) and 'value="Sweden (SE)"' in body(reply)

    reply = post(visitor, "/signup", {"username": "ann", "email": "ann@example.test", "country_code": "",
                                      "password": "Fast-Lap-2026"})
    assert reply.status_code == 400
    assert field_error(reply, "country_code") == ("Choose a country: type its name or its two-letter code, "
                                                  "e.g. Sweden or SE.")


def test_sign_up_is_confirmed_at_once_locally_and_no_code_is_accepted(app: Any, aws_clients: Any,
                                                                      stack: Any) -> None:
    # Offline nothing is emailed, so a local stack confirms a self sign-up itself; any typed code is refused.
    visitor = Browser(app)
    visitor.get("/signup")
    reply = post(visitor, "/signup", {"username": "ann.racer", "email": "ann@example.test", "country_code": "se",
                                      "password": "Fast-Lap-2026"})
    assert reply.status_code == 200
    assert "Your account ann.racer is confirmed; you can sign in now." in text(reply)

    guessed = post(visitor, "/signup/confirm", {"username": "ann.racer", "code": "123456"})
    assert guessed.status_code == 400 and "code is wrong" in field_error(guessed, "code")
    missing = post(visitor, "/signup/confirm", {"username": "ann.racer", "code": ""})
    assert missing.status_code == 400 and field_error(missing, "code") == "Enter the code."

    account = aws_clients.cognito.admin_get_user(UserPoolId=stack.user_pool_id, Username="ann.racer")
    attributes = {a["Name"]: a["Value"] for a in account["UserAttributes"]}
    assert account["UserStatus"] == "CONFIRMED" and attributes["custom:countryCode"] == "SE"
    home = sign_in(Browser(app), "ann.racer", "Fast-Lap-2026").get("/")
    assert "Your roles: racer." in text(home)


def test_password_change_checks_the_current_one_and_the_repeat(app: Any, users: Any) -> None:
    racer = signed_in(app, users, "pia", "racer")
    wrong = post(racer, "/console/password", {"current_password": "nope", "new_password": "New-Pass-2026",
                                              "confirm_password": "New-Pass-2026"})
    assert wrong.status_code == 400 and field_error(wrong, "current_password") == "Your current password is not right."
    differ = post(racer, "/console/password", {"current_password": PASSWORD, "new_password": "New-Pass-2026",
                                               "confirm_password": "New-Pass-2027"})
    assert field_error(differ, "confirm_password") == "The two new passwords differ."
    weak = post(racer, "/console/password", {"current_password": PASSWORD, "new_password": "short",
                                             "confirm_password": "short"})
    assert field_error(weak, "new_password").startswith("This password is too weak.")

    done = post(racer, "/console/password", {"current_password": PASSWORD, "new_password": "New-Pass-2026",
                                             "confirm_password": "New-Pass-2026"})
    assert done.status_code == 200 and "Your password has been changed." in text(done)
    assert users.sign_in("pia", "New-Pass-2026")["AccessToken"]
    with pytest.raises(Exception, match="NotAuthorized"):
        users.sign_in("pia", PASSWORD)


def test_profile_colour_comes_from_the_palette_and_shows_in_the_public_profile(app: Any, users: Any) -> None:
    racer = signed_in(app, users, "ola", "racer")
    page = racer.get("/console/profile")
    assert body(page).count('name="highlight_colour"') == 8 and 'data-testid="avatar-preview"' in body(page)

    bad = post(racer, "/console/profile", {"highlight_colour": "#FFFFFF", "avatar": "identicon"})
    assert bad.status_code == 400
    assert "Pick a highlight colour from the palette" in field_error(bad, "highlight_colour")

    saved = post(racer, "/console/profile", {"highlight_colour": "#ff8200", "avatar": "identicon"})
    assert "Your profile is saved; the leaderboards show it now." in text(saved)
    checked = re.findall(r'value="(#[0-9A-F]{6})" aria-label="[^"]*"\s+checked', body(saved))
    assert checked == ["#FF8200"]  # the saved swatch is the one selected
    public = app.http.get("/api/profiles/ola", headers={"Accept": "application/json"}).json_body
    assert public["highlight_colour"] == "#FF8200"


def test_my_models_lists_status_and_reason_and_polls_only_while_uploaded(app: Any, users: Any) -> None:
    racer = signed_in(app, users, "ada", "racer")
    api = ModelsApi(app, bearer(users.sign_in("ada")["AccessToken"]))
    good = api.upload_and_complete("fast-lap.tar.gz", onnx_archive())
    bad = api.upload_and_complete("no-meta.tar.gz", archive_without_metadata())
    waiting = api.request_upload("waiting.tar.gz").json_body["model"]

    page = racer.get("/console/my-models")
    shown = text(page)
    assert "fast-lap Ready to race" in shown
    assert "no-meta the archive has no model_metadata.json at its top level Not valid" in shown
    assert 'src="/static/upload.js"' in body(page)
    polling = racer.get(f"/console/my-models/{waiting['model_id']}/row")
    assert 'hx-trigger="every 2s"' in body(polling) and "Waiting to be checked…" in text(polling)
    settled = racer.get(f"/console/my-models/{good['model_id']}/row")
    assert f'hx-get="/console/my-models/{good["model_id"]}/row"' not in body(settled)
    assert "Ready to race" in text(settled)
    # Its background test drive is queued: only the scrutineering box polls itself, until the drive is over.
    assert f'hx-get="/console/models/{good["model_id"]}/scrutiny" hx-trigger="every 2s"' in body(settled)
    assert "queued" in text(racer.get(f"/console/models/{good['model_id']}/scrutiny"))
    assert bad["status"] == "NOT_VALID"


def test_a_racer_deletes_own_models_only(app: Any, users: Any) -> None:
    ada = signed_in(app, users, "ada", "racer")
    bob = signed_in(app, users, "bob", "racer")
    model = ModelsApi(app, bearer(users.sign_in("ada")["AccessToken"])).upload_and_complete(
        "fast-lap.tar.gz", onnx_archive())

    assert bob.get(f"/console/my-models/{model['model_id']}/row").status_code == 403
    refused = post(bob, f"/console/my-models/{model['model_id']}/delete", htmx=True)
    assert refused.status_code == 403 and "This belongs to another user." in text(refused)
    assert "fast-lap" not in text(bob.get("/console/my-models"))

    gone = post(ada, f"/console/my-models/{model['model_id']}/delete", htmx=True)
    assert gone.status_code == 200 and "Model fast-lap deleted." in text(gone)
    assert "<html" not in body(gone)  # a fragment for the row, not a page
    assert "No models yet" in text(ada.get("/console/my-models"))


def test_state_changes_without_the_csrf_token_are_refused(app: Any, users: Any) -> None:
    racer = signed_in(app, users, "eve", "racer")
    racer.get("/console/profile")
    reply = racer.post("/console/profile", {"highlight_colour": "#FF0000"})
    assert reply.status_code == 403
    public = app.http.get("/api/profiles/eve", headers={"Accept": "application/json"}).json_body
    assert public["highlight_colour"] is None  # nothing changed


def test_my_races_starts_empty_and_another_racers_race_is_not_shown(app: Any, users: Any) -> None:
    racer = signed_in(app, users, "ivy", "racer")
    page = racer.get("/console/my-races")
    assert page.status_code == 200 and "You have not raced yet." in text(page)
    assert racer.get("/console/my-races/no-event/no-race").status_code == 404


def test_nav_shows_a_racer_only_their_own_screens(app: Any, users: Any) -> None:
    racer = signed_in(app, users, "kai", "racer")
    nav = body(racer.get("/")).split('data-testid="nav-links">')[1].split("</nav>")[0]
    assert [link for link in ("/console/my-models", "/console/my-races", "/console/profile") if link in nav]
    for staff in ("/console/users", "/console/models\"", "/console/registration", "/console/events"):
        assert staff not in nav


def test_a_racer_scrutineers_a_model_from_my_models_and_sees_the_result(app: Any, users: Any) -> None:
    ada = signed_in(app, users, "ada", "racer")
    bob = signed_in(app, users, "bob", "racer")
    model = ModelsApi(app, bearer(users.sign_in("ada")["AccessToken"])).upload_and_complete(
        "drive-me.tar.gz", onnx_archive(0.001))
    assert 'data-testid="scrutineer-button"' in body(ada.get("/console/my-models"))

    refused = post(bob, f"/console/models/{model['model_id']}/scrutineer", {"track_type": "REINVENT_2018"}, htmx=True)
    assert refused.status_code == 403
    driven = post(ada, f"/console/models/{model['model_id']}/scrutineer",
                  {"track_type": "REINVENT_2018", "laps": "1"}, htmx=True)

    assert driven.status_code == 200, text(driven)
    shown = text(driven)
    assert re.search(r"(passed|failed) on re:Invent 2018: [01]/1 laps completed, best lap .+, \d+ off-tracks?", shown)
    assert "scrutineer-result" in body(ada.get(f"/console/my-models/{model['model_id']}/row"))  # kept on the model
    bad = post(ada, f"/console/models/{model['model_id']}/scrutineer", {"laps": "9"}, htmx=True)
    assert bad.status_code == 400 and "laps" in text(bad).lower()
