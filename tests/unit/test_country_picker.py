"""The searchable country picker: what a person types (a name, a code, the list's "Sweden (SE)") becomes the ISO
code on every form that has one; anything else is refused next to the picker and stays typed."""
from __future__ import annotations

import json
from typing import Any

import pytest

from chalicelib.core.errors import InvalidInput
from chalicelib.domain.countries import COUNTRY_CHOICES, country_code_from_text, country_label
from tests.unit.racer_console_helpers import body, field_error, post, signed_in
from tests.unit.test_console_events import FORM

pytestmark = pytest.mark.unit


@pytest.mark.parametrize(("typed", "code"), [
    ("Sweden (SE)", "SE"), ("sweden", "SE"), ("  SWEDEN ", "SE"), ("se", "SE"), ("DE", "DE"),
    ("United Kingdom", "GB"), ("Bolivia", "BO"), ("Bolivia, Plurinational State of", "BO"),
    ("Côte d'Ivoire", "CI"), ("Korea, Republic of", "KR"),
])
def test_a_name_code_or_label_maps_to_the_code(typed: str, code: str) -> None:
    assert country_code_from_text(typed) == code


@pytest.mark.parametrize("typed", ["Swedn", "UK", "XX", "Sweden (DE)", "Swe", "<script>"])
def test_anything_else_is_refused_naming_the_field(typed: str) -> None:
    with pytest.raises(InvalidInput) as refused:
        country_code_from_text(typed)
    assert refused.value.field == "country_code" and "No country is called" in refused.value.message


def test_every_label_in_the_list_maps_back_to_its_own_code() -> None:
    assert len(COUNTRY_CHOICES) >= 249
    assert all(country_code_from_text(label) == code for code, label in COUNTRY_CHOICES)
    assert country_label("se") == "Sweden (SE)" and country_label("Swedn") == "Swedn"


def test_the_picker_is_a_labelled_searchable_input_with_every_country(client: Any) -> None:
    page = body(client.http.get("/signup"))
    assert '<label for="country_code">Country</label>' in page
    assert 'list="country_code-options"' in page and 'aria-describedby="country_code-hint"' in page
    assert page.count("<option value=") >= 249 and '<option value="Sweden (SE)">' in page


def test_sign_up_by_country_name_saves_the_code(client: Any, aws_clients: Any, stack: Any) -> None:
    from tests.unit.conftest import Browser

    visitor = Browser(client)
    visitor.get("/signup")
    reply = post(visitor, "/signup", {"username": "sven", "email": "sven@example.test", "country_code": "sweden",
                                      "password": "Fast-Lap-2026"})
    assert reply.status_code == 200, reply.body
    account = aws_clients.cognito.admin_get_user(UserPoolId=stack.user_pool_id, Username="sven")
    assert {a["Name"]: a["Value"] for a in account["UserAttributes"]}["custom:countryCode"] == "SE"


def test_the_desk_refuses_an_unknown_name_and_keeps_it_typed(client: Any, users: Any) -> None:
    desk = signed_in(client, users, "dana", "registration")
    desk.get("/console/registration")
    form = {"username": "kim-2", "email": "kim2@example.test", "country_code": "Germny"}
    refused = post(desk, "/console/registration", form, htmx=True)
    assert refused.status_code == 400
    assert field_error(refused, "country_code") == ("No country is called &#39;Germny&#39;: type its name or its "
                                                    "two-letter code (e.g. Sweden or SE) and pick it from the list.")
    assert 'value="Germny"' in body(refused) and 'value="kim2@example.test"' in body(refused)
    assert 'aria-invalid="true"' in body(refused) and "country_code-hint country_code-error" in body(refused)

    made = post(desk, "/console/registration", {**form, "country_code": "Germany (DE)"}, htmx=True)
    assert made.status_code == 201 and 'value="Germany (DE)"' in body(made)


def test_an_event_by_country_name_and_its_edit_form_shows_the_label(console) -> None:
    console.sign_in("eve", "operator")
    reply = console.post("/console/events", {**FORM, "country_code": "Norway", "track-2-use": ""})
    assert reply.status_code == 303, reply.body
    [event] = json.loads(console.desk.call("GET", "/api/events").body)["events"]
    assert event["country_code"] == "NO"
    edit = console.web.get(f"/console/events/{event['event_id']}/edit").body.decode()
    assert 'value="Norway (NO)"' in edit


def test_the_profile_country_is_searchable_and_shows_on_the_public_profile(client: Any, users: Any) -> None:
    racer = signed_in(client, users, "ada", "racer")
    racer.get("/console/profile")
    refused = post(racer, "/console/profile", {"highlight_colour": "#ff8200", "avatar": "identicon",
                                               "country_code": "Atlantis"})
    assert refused.status_code == 400 and "No country is called" in field_error(refused, "country_code")
    assert 'value="Atlantis"' in body(refused)

    saved = post(racer, "/console/profile", {"highlight_colour": "#ff8200", "avatar": "identicon",
                                             "country_code": "japan"})
    assert saved.status_code == 200 and 'value="Japan (JP)"' in body(saved)
    public = json.loads(client.http.get("/api/profiles/ada").body)
    assert public["country_code"] == "JP"
