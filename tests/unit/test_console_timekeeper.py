"""The timekeeper screen: a race driven with its buttons lives on the server (a second screen sees it), laps and
resets show up, errors land next to the field, and the car's tail light follows the race."""
from __future__ import annotations

import json

import pytest

from tests.unit.operator_console_helpers import field_error, text_of
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit


def _setup(console, *, with_car: bool = True) -> tuple[dict, str | None]:
    scenario = Scenario(console.desk).add_fleet().add_event(race_time_min=2)
    car = scenario.add_car("car-1") if with_car else None
    scenario.add_racers("speedy")
    console.sign_in("timekeeper", "operator")
    return scenario.event, car


def _press(console, event_id: str, race_id: str, kind: str, **extra: str):
    return console.post(f"/console/timekeeper/{event_id}/1/commands", {"kind": kind, "race_id": race_id, **extra},
                        htmx=True)


def _race_id(html: str) -> str:
    return html.split('data-race-id="', 1)[1].split('"', 1)[0]


def test_a_race_run_from_the_screen_shows_laps_resets_and_lands_on_the_board(console, clock):
    event, car = _setup(console)
    base = f"/console/timekeeper/{event['event_id']}/1"

    ready = console.post(f"{base}/races", {"racer_username": "speedy", "car": car}, htmx=True)
    assert ready.status_code == 200, ready.body
    html = ready.body.decode()
    assert "Ready to start" in text_of(html) and "speedy" in text_of(html)
    race_id = _race_id(html)

    _press(console, event["event_id"], race_id, "toggle")
    clock.advance(10_000)
    _press(console, event["event_id"], race_id, "reset_add")
    lap = _press(console, event["event_id"], race_id, "capture_lap").body.decode()
    assert "0:10.000" in text_of(lap)  # the lap time is the race clock since the lap began
    assert "Pause" in lap

    # A second screen (a reload, another tablet) shows the same race, with the lap.
    other = console.web.get(base).body.decode()
    assert _race_id(other) == race_id and "0:10.000" in text_of(other)

    clock.advance(5_000)
    _press(console, event["event_id"], race_id, "capture_lap")
    undone = _press(console, event["event_id"], race_id, "undo_false_finish").body.decode()
    # The false finish is gone and its time is back on the running lap.
    assert 'data-lap="2"' not in undone and 'data-lap="1"' in undone
    assert 'data-testid="current-lap">0:05.000<' in undone
    over = _press(console, event["event_id"], race_id, "end").body.decode()
    assert "Race over" in text_of(over) and "Submit race" in over
    submitted = _press(console, event["event_id"], race_id, "submit").body.decode()
    assert "Next race" in text_of(submitted)  # back to racer selection

    board = console.desk.board(event["event_id"])
    assert [e["username"] for e in board["entries"]] == ["speedy"]


def test_the_tail_light_gets_the_racers_colour_at_the_start_and_white_at_the_end(console, clock):
    event, car = _setup(console)
    base = f"/console/timekeeper/{event['event_id']}/1"
    race_id = _race_id(console.post(f"{base}/races", {"racer_username": "speedy", "car": car}, htmx=True).body.decode())

    _press(console, event["event_id"], race_id, "toggle")
    clock.advance(30_000)  # the race runs a while (commands queued in one millisecond have no defined order)
    _press(console, event["event_id"], race_id, "end")

    commands = json.loads(console.desk.call("GET", f"/api/devices/{car}/commands").body)["commands"]
    colours = [c["parameters"]["colour"] for c in commands if c["type"] == "SET_TAIL_LIGHT"]
    assert colours == ["#0000FF", "#FFFFFF"]  # no profile colour: DREM's default blue, then white


def test_an_unknown_racer_is_named_next_to_the_racer_field(console):
    event, _car = _setup(console, with_car=False)

    reply = console.post(f"/console/timekeeper/{event['event_id']}/1/races", {"racer_username": "nobody-here"},
                         htmx=True)

    assert reply.status_code in (400, 404)
    html = reply.body.decode()
    assert field_error(html, "racer_username")
    assert 'value="nobody-here"' in html  # what the operator typed is kept


def test_a_command_the_rules_refuse_is_shown_not_a_500(console):
    event, _car = _setup(console, with_car=False)
    base = f"/console/timekeeper/{event['event_id']}/1"
    race_id = _race_id(console.post(f"{base}/races", {"racer_username": "speedy"}, htmx=True).body.decode())

    reply = _press(console, event["event_id"], race_id, "capture_lap")  # not started yet

    assert reply.status_code == 409
    assert "capture a lap" in field_error(reply.body.decode(), "form")


def test_the_timer_shows_as_connected_once_it_sends_a_heartbeat(console):
    desk = console.desk
    scenario = Scenario(desk).add_fleet().add_event().add_timer("timer-1")
    timer = scenario.timer
    console.sign_in("timekeeper", "operator")
    page = f"/console/timekeeper/{scenario.event_id}/1"
    assert "Timer offline" in text_of(console.web.get(page).body.decode())

    beat = desk.client.http.post("/api/devices/self/heartbeat", body=b"{}", headers={
        "Authorization": f"Device {timer}", "Content-Type": "application/json", "Accept": "application/json"})
    assert beat.status_code == 200, beat.body

    assert "Timer connected" in text_of(console.web.get(page).body.decode())


def test_commands_need_the_csrf_token_and_an_operator(console):
    event, _car = _setup(console, with_car=False)
    base = f"/console/timekeeper/{event['event_id']}/1"
    forged = console.web.post(f"{base}/races", {"racer_username": "speedy"})
    assert forged.status_code == 403

    racer_web = console.sign_in("someone", "racer")
    assert racer_web.get(base).status_code == 403


def test_a_sim_car_is_the_timer_only_of_the_races_it_drives(console):
    """Issue 31: track 2 said "Timed by sim car sim-car-1" while its race had no car (the sim car times track 1)."""
    desk = console.desk
    scenario = Scenario(desk).add_fleet()
    scenario.add_event(tracks=[{"track_id": "1", "fleet_id": scenario.fleet_id},
                               {"track_id": "2", "fleet_id": scenario.fleet_id}])
    sim = desk.device(scenario.fleet_id, "sim-car-1", kind="car")
    beat = desk.client.http.post("/api/devices/self/heartbeat", body=json.dumps({"times_laps": True}).encode(),
                                 headers={"Authorization": f"Device {sim}", "Content-Type": "application/json",
                                          "Accept": "application/json"})
    assert beat.status_code == 200, beat.body
    car_id = next(d["device_id"] for d in json.loads(desk.call("GET", "/api/devices").body)["devices"]
                  if d["hostname"] == "sim-car-1")
    console.sign_in("timekeeper", "operator")
    eid = scenario.event_id
    assert "Timed by sim car sim-car-1 when it drives the race" in text_of(
        console.web.get(f"/console/timekeeper/{eid}/2").body.decode())
    desk.ok(desk.create_race(eid, *_racer(desk, "tk-two"), "2"), 201)  # no car
    on_two = text_of(console.web.get(f"/console/timekeeper/{eid}/2").body.decode())
    assert "No timer for this race" in on_two and "Timed by sim car" not in on_two
    desk.ok(desk.create_race(eid, *_racer(desk, "tk-one"), "1", car=car_id), 201)
    assert "Timed by sim car sim-car-1" in text_of(console.web.get(f"/console/timekeeper/{eid}/1").body.decode())


def _racer(desk, username: str) -> tuple[str]:
    desk.users.create(username, ("racer",))
    return (username,)
