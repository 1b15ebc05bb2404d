"""Destructive console actions ask before they act: a confirmation page (delete an event or a race) or a question on
the button (deregister a car or delete its models, disable a user), and the confirmation page alone deletes nothing.
The timekeeper's E key asking first is tested in a browser (tests/browser/test_journey_timekeeper.py)."""
from __future__ import annotations

import json

import pytest

from tests.unit.racer_console_helpers import body, post, signed_in
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit


def test_car_deregistration_and_deleting_its_models_ask_first(console):
    fleet = console.desk.fleet()
    Scenario(console.desk, fleet_id=fleet).add_car("car-9")
    console.sign_in("boss", "admin")
    page = console.web.get("/console/cars").body.decode()
    assert 'data-confirm="Deregister car-9? Its credential stops working.">Deregister</button>' in page
    assert 'data-confirm="Delete every model on car-9?">Delete models</button>' in page


def test_event_and_race_deletion_go_through_a_confirmation_page_that_deletes_nothing(console, clock):
    scenario = Scenario(console.desk, clock).add_racers("ann").add_event()
    event_id = scenario.event["event_id"]
    race_id = scenario.submitted_race("ann", [12_345], event_id=event_id)
    console.sign_in("op-web", "operator")
    asked = console.web.get(f"/console/races/{event_id}/{race_id}/delete")
    assert asked.status_code == 200 and "Delete race" in asked.body.decode()
    assert console.web.get(f"/console/events/{event_id}/delete").status_code == 200
    assert console.desk.call("GET", f"/api/events/{event_id}/races/{race_id}").status_code == 200
    assert [e["event_id"] for e in json.loads(console.desk.call("GET", "/api/events").body)["events"]] == [event_id]


def test_disabling_a_user_asks_first_and_enabling_does_not(client, users):
    users.create("kim", ("racer",))
    admin = signed_in(client, users, "root", "admin")
    page = body(admin.get("/console/users"))
    row = page.split('data-username="kim"')[1].split("</tr>")[0]
    assert 'hx-confirm="Disable kim? They cannot sign in until enabled again."' in row
    disabled = post(admin, "/console/users/kim/disable", htmx=True)
    assert "hx-confirm" not in body(disabled)  # Enable undoes nothing: no question
