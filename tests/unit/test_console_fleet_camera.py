"""Issue 35 on the Fleets page: staff set the camera of every car of a fleet at once (frame rate, size, the model's
own view) with the same choices as a car's row on the Cars page; the page says how many cars got it. Racers and
anonymous visitors may not, a forged post (no CSRF token) is refused, and bad input is refused with a message naming
the choice while every car keeps what it had."""
from __future__ import annotations

import html as html_text
import json
import re

import pytest

from tests.unit.operator_console_helpers import text_of
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit

MODEL_VIEW = {"fps": "20", "size": "640x480", "view": "model"}


def _video(console, device_id: str) -> dict | None:
    return json.loads(console.desk.call("GET", f"/api/devices/{device_id}").body).get("video")


def _fleet_with_two_cars_and_a_timer(console) -> tuple[str, list[str]]:
    fleet = console.desk.fleet("Track 1 cars")
    scenario = Scenario(console.desk, fleet_id=fleet)
    cars = [scenario.add_car("car-1"), scenario.add_car("car-2")]
    console.desk.device(fleet, "timer-1", kind="timer")
    return fleet, cars


def _selected(html: str, form_testid: str) -> dict[str, str]:
    """The option each select of one form shows selected: what staff see chosen."""
    form = re.search(rf'<form[^>]*data-testid="{re.escape(form_testid)}".*?</form>', html, re.S)
    assert form, f"no form {form_testid}"
    chosen = {}
    for name, options in re.findall(r'<select name="(\w+)"[^>]*>(.*?)</select>', form.group(0), re.S):
        picked = re.search(r'<option value="([^"]*)"[^>]*\bselected\b', options)
        chosen[name] = picked.group(1) if picked else ""
    return chosen


def test_staff_set_a_fleets_camera_and_every_car_of_the_fleet_gets_it(console):
    fleet, cars = _fleet_with_two_cars_and_a_timer(console)
    other_fleet = console.desk.fleet("Spare cars")
    spare = Scenario(console.desk, fleet_id=other_fleet).add_car("spare-1")
    console.sign_in("op-web", "operator")
    page = console.web.get("/console/fleets").body.decode()
    assert _selected(page, f"fleet-video-{fleet}") == {"fps": "15", "size": "480x360", "view": "camera"}

    reply = console.post(f"/console/fleets/{fleet}/video", MODEL_VIEW)

    assert reply.status_code == 200, reply.body
    shown = text_of(reply.body.decode())
    assert ("Camera settings (20 fps, 640×480, model view) saved for the 2 cars of Track 1 cars; each sends at them "
            "within about 10 seconds.") in shown
    assert "Its 2 cars are set to 20 fps, 640×480, model view." in shown
    for car in cars:
        assert _video(console, car) == {"fps": 20, "width": 640, "height": 480, "view": "model"}
    assert _video(console, spare) is None  # another fleet's car keeps its own
    cars_page = console.web.get("/console/cars").body.decode()
    for hostname in ("car-1", "car-2"):
        assert _selected(cars_page, f"video-{hostname}") == MODEL_VIEW
    assert _selected(console.web.get("/console/fleets").body.decode(), f"fleet-video-{fleet}") == MODEL_VIEW


def test_a_fleet_whose_cars_differ_says_so_and_one_car_is_named_as_one(console):
    fleet, cars = _fleet_with_two_cars_and_a_timer(console)
    lone = console.desk.fleet("Lone car")
    Scenario(console.desk, fleet_id=lone).add_car("lone-1")
    assert console.desk.call("PUT", f"/api/devices/{cars[0]}/video", {"fps": 5}).status_code == 200
    console.sign_in("op-web", "operator")
    page = text_of(console.web.get("/console/fleets").body.decode())
    assert "Its 2 cars are set differently; this sets them all alike." in page
    assert "Its car is set to 15 fps, 480×360, camera." in page
    reply = console.post(f"/console/fleets/{lone}/video", {"fps": "10", "size": "320x240", "view": "camera"})
    assert "saved for the 1 car of Lone car;" in text_of(reply.body.decode())


def test_a_setting_made_over_the_api_that_the_forms_do_not_offer_is_shown_as_it_is(console):
    """7 fps and 400×300 are within bounds (the API takes them) but not among the options: both pages show them
    selected rather than the first option, which saving the form unchanged would have put on the cars."""
    fleet, _cars = _fleet_with_two_cars_and_a_timer(console)
    set_over_api = console.desk.call("PUT", f"/api/fleets/{fleet}/video", {"fps": 7, "width": 400, "height": 300})
    assert set_over_api.status_code == 200, set_over_api.body
    console.sign_in("op-web", "operator")
    shown = {"fps": "7", "size": "400x300", "view": "camera"}
    assert _selected(console.web.get("/console/fleets").body.decode(), f"fleet-video-{fleet}") == shown
    assert _selected(console.web.get("/console/cars").body.decode(), "video-car-1") == shown


def test_racers_anonymous_visitors_and_forged_posts_may_not_set_a_fleets_camera(console):
    fleet, cars = _fleet_with_two_cars_and_a_timer(console)
    racer = console.sign_in("rita", "racer")
    assert console.post(f"/console/fleets/{fleet}/video", MODEL_VIEW).status_code == 403
    assert racer.get("/console/fleets").status_code == 403
    racer.cookies.clear()
    racer.get("/login")  # an anonymous visitor with a CSRF token of its own
    anonymous = console.post(f"/console/fleets/{fleet}/video", MODEL_VIEW)
    assert anonymous.status_code in (401, 403) or anonymous.headers["Location"].startswith("/login")
    console.sign_in("op-web", "operator")
    assert console.web.post(f"/console/fleets/{fleet}/video", MODEL_VIEW).status_code == 403  # no CSRF token
    assert [_video(console, car) for car in cars] == [None, None]


@pytest.mark.parametrize("form, field, message", [
    ({"fps": "0"}, "fps", "Frame rate: Input should be greater than or equal to 1"),
    ({"fps": "99"}, "fps", "Frame rate: Input should be less than or equal to 30"),
    ({"fps": "fast"}, "fps", "Frame rate: Input should be a valid integer"),
    ({"size": "huge"}, "size", "Size: Give the size as WIDTHxHEIGHT, e.g. 480x360."),
    ({"size": "5000x5000"}, "width", "Width: Input should be less than or equal to 1280"),
    ({"view": "thermal"}, "view", "View: Input should be 'camera' or 'model'"),
])
def test_bad_camera_settings_are_refused_next_to_the_fleets_form_and_change_no_car(console, form: dict, field: str,
                                                                                    message: str):
    fleet, cars = _fleet_with_two_cars_and_a_timer(console)
    console.sign_in("op-web", "operator")
    assert console.post(f"/console/fleets/{fleet}/video", MODEL_VIEW).status_code == 200

    reply = console.post(f"/console/fleets/{fleet}/video", {**MODEL_VIEW, "fps": "5", "view": "camera", **form})

    assert reply.status_code == 400
    html = reply.body.decode()
    error = re.search(rf'id="{fleet}-{field}-error"[^>]*>([^<]*)<', html)
    assert error and html_text.unescape(error.group(1)).startswith(message), html
    assert "saved for" not in text_of(html)
    for car in cars:
        assert _video(console, car) == {"fps": 20, "width": 640, "height": 480, "view": "model"}


def test_an_unknown_fleet_is_not_found(console):
    console.sign_in("op-web", "operator")
    assert console.post("/console/fleets/no-such-fleet/video", MODEL_VIEW).status_code == 404
