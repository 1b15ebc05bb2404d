"""After every change in the console the operator reads what was done: a success message carried through the 303
redirect (`?done=`, chalicelib.routes.console.notices) or drawn by the answer itself (a user's row, the profile)."""
from __future__ import annotations

import json
import re
from typing import Any

import pytest

from tests.unit.conftest import PASSWORD
from tests.unit.models_helpers import ModelsApi, bearer, onnx_archive
from tests.unit.racer_console_helpers import post, signed_in
from tests.unit.scenario import Scenario
from tests.unit.test_console_events import FORM

pytestmark = pytest.mark.unit


def _notice(html: str) -> str | None:
    found = re.search(r'data-testid="notice">(.*?)</p>', html, re.S)
    return found.group(1).strip() if found else None


def _followed(console, reply: Any) -> str | None:
    """The notice of the page a successful post redirects to, opened as the browser would (anchor dropped)."""
    assert reply.status_code == 303, reply.body
    page = console.web.get(reply.headers["Location"].split("#")[0])
    assert page.status_code == 200
    return _notice(page.body.decode())


def _event_id(console) -> str:
    [event] = json.loads(console.desk.call("GET", "/api/events").body)["events"]
    return event["event_id"]


def test_creating_saving_and_deleting_an_event_each_say_so(console):
    console.sign_in("eve", "operator")
    form = {**FORM, "track-2-use": ""}
    assert _followed(console, console.post("/console/events", form)) == "Event created."
    event_id = _event_id(console)
    assert _followed(console, console.post(f"/console/events/{event_id}",
                                           {**form, "name": "Summit Oslo"})) == "Event saved."
    assert _followed(console, console.post(f"/console/events/{event_id}/delete", {})) == "Event deleted."
    # The plain list, opened again, says nothing: the message belongs to the change.
    assert _notice(console.web.get("/console/events").body.decode()) is None


def test_a_made_up_done_flag_shows_nothing_and_is_never_echoed(console):
    console.sign_in("eve", "operator")
    page = console.web.get("/console/events?done=%3Cb%3Epwned%3C%2Fb%3E").body.decode()
    assert _notice(page) is None and "pwned" not in page


def test_fleet_and_car_changes_each_say_so(console):
    fleet = console.desk.fleet()
    spare = console.desk.fleet("Spare cars")
    car = Scenario(console.desk, fleet_id=fleet).add_car("car-1")
    console.sign_in("boss", "admin")

    assert _followed(console, console.post("/console/fleets", {"name": "Pit lane"})) == "Fleet created."
    moved = _followed(console, console.post(f"/console/cars/{car}/fleet", {"fleet_id": spare}))
    assert moved == "Car moved; its row below shows the fleet."
    cleared = _followed(console, console.post(f"/console/cars/{car}/models", {"clear": "1"}))
    assert cleared == "Models on the car changed; its row below shows them."
    sent = _followed(console, console.post(f"/console/cars/{car}/commands", {"type": "EMERGENCY_STOP"}))
    assert sent is not None and sent.startswith("Emergency stop sent to car-1.")
    gone = _followed(console, console.post(f"/console/cars/{car}/deregister", {}))
    assert gone == "Car deregistered; its credential no longer works."


def test_a_lap_edit_and_a_race_deletion_each_say_so(console, clock):
    scenario = Scenario(console.desk, clock).add_racers("ann").add_event()
    event_id = scenario.event["event_id"]
    race_id = scenario.submitted_race("ann", [12_345], event_id=event_id)
    console.sign_in("op-web", "operator")
    base = f"/console/races/{event_id}/{race_id}"

    saved = _followed(console, console.post(f"{base}/laps/0", {"time_s": "11.5", "resets": "0", "is_valid": "on"}))
    assert saved == "Lap saved; the leaderboard shows the change."
    deleted = _followed(console, console.post(f"{base}/delete", {}))
    assert deleted == "Race deleted; the leaderboard no longer counts it."


def test_role_changes_and_disabling_say_so_in_the_users_row(client: Any, users: Any) -> None:
    users.create("kim", ("racer",))
    admin = signed_in(client, users, "root", "admin")
    admin.get("/console/users")

    role = post(admin, "/console/users/kim/role", {"role": "operator"}, htmx=True)
    assert role.status_code == 200 and _notice(role.body.decode()) == "kim&#39;s role is now Operator."
    disabled = post(admin, "/console/users/kim/disable", htmx=True)
    assert _notice(disabled.body.decode()) == "kim is disabled and cannot sign in."
    enabled = post(admin, "/console/users/kim/enable", htmx=True)
    assert _notice(enabled.body.decode()) == "kim is enabled and can sign in again."
    refused = post(admin, "/console/users/root/disable", htmx=True)  # not oneself: the refusal, no success
    assert refused.status_code >= 400 and _notice(refused.body.decode()) is None


def test_profile_password_and_model_deletion_each_say_so(client: Any, users: Any) -> None:
    racer = signed_in(client, users, "ada", "racer")
    racer.get("/console/profile")
    saved = post(racer, "/console/profile", {"highlight_colour": "#ff8200", "avatar": "identicon"})
    assert _notice(saved.body.decode()) == "Your profile is saved; the leaderboards show it now."

    model = ModelsApi(client, bearer(users.sign_in("ada")["AccessToken"])).upload_and_complete(
        "fast-lap.tar.gz", onnx_archive())
    deleted = post(racer, f"/console/my-models/{model['model_id']}/delete")  # without htmx: redirect and message
    assert deleted.status_code == 303
    assert _notice(racer.get(deleted.headers["Location"]).body.decode()) == "Model deleted."

    changed = post(racer, "/console/password", {"current_password": PASSWORD, "new_password": "New-Pass-2026",
                                                "confirm_password": "New-Pass-2026"})
    assert _notice(changed.body.decode()) == "Your password has been changed."
    refused = post(racer, "/console/password", {"current_password": "nope", "new_password": "New-Pass-2027",
                                                "confirm_password": "New-Pass-2027"})
    assert refused.status_code == 400 and _notice(refused.body.decode()) is None  # a refusal is no success
