"""The racer queue beside the timekeeper ("on deck"): staff line racers up with their model, reorder, take them off;
"Ready race" on the head creates the race on the car holding their model and gives the next racer's model to a free
car of the track's fleet, whose load the panel follows from the car's reports and heartbeat. The queue's own rules
(order, limits, which model, two screens at once) are tried without HTTP in tests/domain/test_racer_queue_rules.py."""
from __future__ import annotations

import hashlib
import html
import json
import re
from dataclasses import dataclass, field
from typing import Any

import pytest

from tests.unit.models_helpers import ModelsApi, bearer, device_headers, onnx_archive
from tests.unit.operator_console_helpers import Console, field_error, text_of
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit


@dataclass
class Track:
    console: Console
    event_id: str
    cars: dict[str, str] = field(default_factory=dict)  # hostname → device id
    car_apis: dict[str, ModelsApi] = field(default_factory=dict)  # hostname → the car's own API client
    models: dict[str, dict[str, Any]] = field(default_factory=dict)  # racer → their model
    archives: dict[str, bytes] = field(default_factory=dict)  # racer → their model's archive
    racer_apis: dict[str, ModelsApi] = field(default_factory=dict)  # racer → their own API client

    @property
    def base(self) -> str:
        return f"/console/timekeeper/{self.event_id}/1"

    def add(self, racer: str, model: str | None = None, *, confirmed: bool = True) -> Any:
        """Add as staff who already said yes to models that have not passed scrutineering (no worker runs here)."""
        form = {"queue_racer": racer, "queue_model": model or self.models[racer]["name"]}
        return self.console.post(f"{self.base}/queue", {**form, "queue_confirmed": "yes"} if confirmed else form,
                                 htmx=True)

    def press(self, action: str, racer: str, **extra: str) -> Any:
        return self.console.post(f"{self.base}/queue/{action}", {"entry_id": self.entry_of(racer), **extra},
                                 htmx=True)

    def panel(self) -> str:
        reply = self.console.web.get(f"{self.base}/queue", headers={"HX-Request": "true"})
        assert reply.status_code == 200, reply.body
        return reply.body.decode()

    def on_deck(self, html: str | None = None) -> list[str]:
        return re.findall(r'class="tk-deck-racer">([^<]+)<', html or self.panel())

    def entry_of(self, racer: str) -> str:
        match = re.search(rf'data-entry="([0-9a-f]+)"[^>]*>(?:(?!data-entry).)*?>{re.escape(racer)}<', self.panel(),
                          re.S)
        assert match, f"{racer} is not in the queue"
        return match.group(1)

    def car_models(self, hostname: str) -> list[str]:
        reply = self.console.desk.call("GET", f"/api/cars/{self.cars[hostname]}/models")
        return [m["model_id"] for m in json.loads(reply.body)["assignment"]["models"]]


def _track(console: Console, *hostnames: str, racers: tuple[str, ...] = ("alice", "bob")) -> Track:
    scenario = Scenario(console.desk).add_fleet().add_event()
    track = Track(console, scenario.event_id)
    for hostname in hostnames:
        credential = console.desk.device(scenario.fleet_id, hostname, kind="car")
        track.cars[hostname] = _device_id(console, hostname)
        track.car_apis[hostname] = ModelsApi(console.desk.client, device_headers(credential))
    for index, racer in enumerate(racers):
        archive = onnx_archive(0.1 * (index + 1))
        api = ModelsApi(console.desk.client, bearer(console.users.access_token(racer, ("racer",))))
        track.models[racer] = api.upload_and_complete(f"{racer}-model.tar.gz", archive)
        track.archives[racer] = archive
        track.racer_apis[racer] = api
    console.sign_in("timekeeper", "operator")
    return track


def _device_id(console: Console, hostname: str) -> str:
    devices = json.loads(console.desk.call("GET", "/api/devices").body)["devices"]
    return next(d["device_id"] for d in devices if d["hostname"] == hostname)


def test_staff_line_racers_up_reorder_and_take_them_off(console):
    track = _track(console, racers=("alice", "bob", "carol", "dave"))
    for racer in ("alice", "bob", "carol", "dave"):
        assert track.add(racer).status_code == 200

    page = console.web.get(track.base).body.decode()
    assert "On deck" in text_of(page)
    assert track.on_deck(page) == ["alice", "bob", "carol"]  # the next three; dave waits under "Later"
    assert "dave" in text_of(page.split('data-testid="queue-later"', 1)[1])

    moved = track.press("move", "carol", direction="up").body.decode()
    assert track.on_deck(moved) == ["alice", "carol", "bob"]
    track.press("move", "alice", direction="down")
    assert track.on_deck() == ["carol", "alice", "bob"]

    removed = track.press("remove", "carol").body.decode()
    assert track.on_deck(removed) == ["alice", "bob", "dave"]
    # Stored on the server: a second screen sees the same line.
    assert track.on_deck(console.web.get(track.base).body.decode()) == ["alice", "bob", "dave"]


def test_bad_input_gets_a_clear_message_and_loses_nothing(console):
    track = _track(console)
    track.add("alice")

    nobody = track.add("nobody-here", model="fast")
    assert nobody.status_code == 404
    assert field_error(nobody.body.decode(), "queue_racer")
    assert 'value="nobody-here"' in nobody.body.decode()  # what was typed stays in the form

    not_theirs = track.add("bob", model=track.models["alice"]["name"])
    assert not_theirs.status_code == 400
    assert html.unescape(field_error(not_theirs.body.decode(), "queue_model") or "") == (
        "bob has no model ready to race named 'alice-model'; their models: bob-model.")

    twice = track.add("alice")
    assert twice.status_code == 409 and field_error(twice.body.decode(), "queue_racer") == \
        "alice is already in the queue."

    stale = console.post(f"{track.base}/queue/remove", {"entry_id": "0" * 32}, htmx=True)
    assert stale.status_code == 404 and "no longer in the queue" in text_of(stale.body.decode())
    junk = console.post(f"{track.base}/queue/move", {"entry_id": track.entry_of("alice"), "direction": "sideways"},
                        htmx=True)
    assert junk.status_code == 400
    assert track.on_deck() == ["alice"]


def test_only_the_timekeepers_may_change_the_queue(console):
    track = _track(console)
    track.add("alice")
    console.sign_in("chris", "commentator")
    refused = console.post(f"{track.base}/queue/remove", {"entry_id": "0" * 32}, htmx=True)
    assert refused.status_code == 403
    assert console.web.get(f"{track.base}/queue").status_code == 403


def test_ready_race_pops_the_head_onto_their_car_and_preloads_the_next_model_on_a_free_car(console):
    track = _track(console, "car-1", "car-2")
    alice_model, bob_model = track.models["alice"]["model_id"], track.models["bob"]["model_id"]
    track.add("alice")
    track.add("bob")
    # The head's model went to a car straight away (a free car; the first by name), FIRST in its list (a car drives
    # the first assigned model that loads).
    assert track.car_models("car-1") == [alice_model] and track.car_models("car-2") == []
    assert "assigned to car-1" in text_of(track.panel())

    started = track.press("start", "alice")
    assert started.status_code == 200 and started.headers.get("HX-Trigger") == "tk-race-started"
    race = text_of(console.web.get(f"{track.base}/state").body.decode())
    assert "alice" in race and "Car: car-1" in race and "Ready to start" in race
    assert track.on_deck() == ["bob"]

    # The race runs on car-1: bob's model goes to the free car, car-2, while it runs.
    state = console.web.get(f"{track.base}/state").body.decode()
    race_id = state.split('data-race-id="', 1)[1].split('"', 1)[0]
    console.post(f"{track.base}/commands", {"kind": "toggle", "race_id": race_id}, htmx=True)
    assert track.car_models("car-2") == [bob_model] and track.car_models("car-1") == [alice_model]
    panel = track.panel()
    assert "assigned to car-2" in text_of(panel) and "Starts when the current race is submitted" in text_of(panel)

    car = track.car_apis["car-2"]
    report = car.call("POST", "/api/devices/self/assignment/status", {"model_id": bob_model, "status": "downloading"})
    assert report.status_code == 200
    assert 'data-state="loading"' in track.panel()
    md5 = hashlib.md5(track.archives["bob"]).hexdigest()
    beat = car.call("POST", "/api/devices/self/heartbeat", {"model": {"name": "bob-bob-model", "md5": md5}})
    assert beat.status_code == 200, beat.json_body
    panel = track.panel()
    assert 'data-state="loaded"' in panel and "loaded on car-2" in text_of(panel)


def test_a_race_started_by_hand_on_the_head_s_car_moves_their_model_to_a_free_car(console):
    track = _track(console, "car-1", "car-2", racers=("alice", "bob", "walk-in"))
    track.add("alice")
    assert track.car_models("car-1") == [track.models["alice"]["model_id"]]

    # A walk-in races first, on car-1, from the race form: alice's model goes to car-2 while that race runs.
    ready = console.post(f"{track.base}/races", {"racer_username": "walk-in", "car": track.cars["car-1"]}, htmx=True)
    assert ready.status_code == 200, ready.body
    assert track.car_models("car-2") == [track.models["alice"]["model_id"]]
    assert "assigned to car-2" in text_of(track.panel())


def test_with_no_free_car_the_panel_says_so(console):
    track = _track(console, "car-1")
    track.add("alice")
    track.press("start", "alice")
    track.add("bob")
    panel = track.panel()
    assert 'data-state="no car"' in panel and "No free car in this track's fleet" in html.unescape(text_of(panel))
    assert track.car_models("car-1") == [track.models["alice"]["model_id"]]  # the racing car keeps its model


def test_with_one_car_the_next_racer_gets_it_once_the_race_is_over(console):
    track = _track(console, "car-1")
    track.add("alice")
    track.press("start", "alice")
    track.add("bob")  # car-1 is racing: no free car for bob yet
    state = console.web.get(f"{track.base}/state").body.decode()
    race_id = state.split('data-race-id="', 1)[1].split('"', 1)[0]
    for kind in ("end", "submit"):
        console.post(f"{track.base}/commands", {"kind": kind, "race_id": race_id}, htmx=True)

    assert track.press("start", "bob").status_code == 200
    assert "Car: car-1" in text_of(console.web.get(f"{track.base}/state").body.decode())
    assert track.car_models("car-1")[0] == track.models["bob"]["model_id"]  # first: the one the car drives


def test_with_one_car_a_race_ended_outside_the_timekeeper_frees_the_car_the_ready_button_names(console):
    """Issue 31: with one car, "Ready race for bob" named no car but then used car-1. Here the race is ended and
    submitted through the JSON API (race admin, a timer): the queue's next poll gives car-1 to bob and says so."""
    track = _track(console, "car-1")
    track.add("alice")
    track.press("start", "alice")
    state = console.web.get(f"{track.base}/state").body.decode()
    race_id = state.split('data-race-id="', 1)[1].split('"', 1)[0]
    track.add("bob")
    assert "No free car" in html.unescape(text_of(track.panel()))
    for kind in ("end", "submit"):
        console.desk.ok(console.desk.command(track.event_id, race_id, kind))

    panel = html.unescape(text_of(track.panel()))
    assert "Ready race for bob on car-1" in panel and "No free car" not in panel
    assert track.car_models("car-1")[0] == track.models["bob"]["model_id"]
    assert track.press("start", "bob").status_code == 200
    assert "Car: car-1" in text_of(console.web.get(f"{track.base}/state").body.decode())


def test_a_refused_race_leaves_the_head_in_the_queue(console):
    track = _track(console, "car-1")
    console.desk.ok(console.desk.create_race(track.event_id, "bob"), 201)  # a race is live on the track already
    track.add("alice")
    refused = track.press("start", "alice")
    assert refused.status_code == 409 and field_error(refused.body.decode(), "form")
    assert track.on_deck() == ["alice"]


def test_a_model_that_has_not_passed_scrutineering_is_queued_only_after_staff_say_yes(console):
    track = _track(console)

    asked = track.add("alice", confirmed=False)
    shown = html.unescape(asked.body.decode())
    assert asked.status_code == 409
    assert "alice – alice-model: not scrutineered yet (its test drive is queued)" in shown
    assert "add it anyway?" in shown and 'data-testid="queue-add-anyway"' in shown
    assert 'value="alice-model"' in shown  # what was typed stays, so "Add anyway" sends the same racer and model
    assert track.on_deck() == [], "nothing reaches the queue (and so no car) before the answer"

    assert track.add("alice", confirmed=True).status_code == 200
    assert track.on_deck() == ["alice"]


class _PowerCut(Exception):
    """Storage killed when the race's record had reached the journal: the queue change never happens."""


def _races_of(console, event_id: str, racer: str) -> list[dict]:
    reply = console.desk.call("GET", f"/api/events/{event_id}/races")
    assert reply.status_code == 200, reply.body
    return [race for race in json.loads(reply.body)["races"] if race["username"] == racer]


@pytest.mark.parametrize("then", ["start again", "look at the queue"])
def test_a_start_cut_off_after_the_race_was_created_ends_as_one_race_and_a_shorter_queue(console, monkeypatch,
                                                                                         then):
    from chalicelib.domain.racer_queue import RacerQueueService

    track = _track(console, "car-1", "car-2")
    track.add("alice")
    track.add("bob")
    alice = track.entry_of("alice")
    real_remove = RacerQueueService.remove

    def cut_off(service, event_id, track_id, entry_id, *, missing_ok=False):
        monkeypatch.setattr(RacerQueueService, "remove", real_remove)  # only this once
        raise _PowerCut()

    monkeypatch.setattr(RacerQueueService, "remove", cut_off)
    crashed = console.post(f"{track.base}/queue/start", {"entry_id": alice}, htmx=True)
    assert crashed.status_code == 500
    assert len(_races_of(console, track.event_id, "alice")) == 1  # the race exists (READY) ...

    if then == "start again":  # ... the timekeeper presses Start again: the race it made is the answer
        again = console.post(f"{track.base}/queue/start", {"entry_id": alice}, htmx=True)
        assert again.status_code == 200, again.body
    assert track.on_deck() == ["bob"]  # the polled list no longer shows alice on deck
    assert len(_races_of(console, track.event_id, "alice")) == 1  # never a second race for her
    race = text_of(console.web.get(f"{track.base}/state").body.decode())
    assert "alice" in race and "Ready to start" in race


def test_a_start_whose_answer_was_lost_after_it_finished_answers_with_its_race_when_pressed_again(console,
                                                                                                 monkeypatch):
    """Found by the chaos bench (kill -9 of everything after the queue change): the race was made and the racer left
    the line, the answer never came, and Start pressed again said "Who is next changed meanwhile" (409)."""
    from chalicelib.domain.on_deck import OnDeck

    track = _track(console, "car-1", "car-2")
    track.add("alice")
    track.add("bob")
    alice = track.entry_of("alice")
    real_start = OnDeck.start_head

    def answer_lost(service, *args, **kwargs):
        real_start(service, *args, **kwargs)  # everything done ...
        raise _PowerCut()  # ... and the timekeeper never hears of it

    monkeypatch.setattr(OnDeck, "start_head", answer_lost)
    assert console.post(f"{track.base}/queue/start", {"entry_id": alice}, htmx=True).status_code == 500
    monkeypatch.setattr(OnDeck, "start_head", real_start)

    again = console.post(f"{track.base}/queue/start", {"entry_id": alice}, htmx=True)
    assert again.status_code == 200, again.body
    assert track.on_deck() == ["bob"]
    assert len(_races_of(console, track.event_id, "alice")) == 1  # one race, and it is the answer
    race = text_of(console.web.get(f"{track.base}/state").body.decode())
    assert "alice" in race and "Ready to start" in race


def test_the_queue_names_racers_by_display_name_and_tells_two_bjorns_apart(console):
    """Issue 31: the timekeeper's queue named racers by sign-in name. Now by display name; two racers in line both
    called Björn are "Björn (bjorn_a)" and "björn (bjorn_b)", and plain "Björn" once the other has left the line."""
    names = {"bjorn_a": "Björn", "bjorn_b": "björn", "yamada": "山田太郎", "zoe": "Zoë Müller"}
    track = _track(console, racers=tuple(names))
    for username, name in names.items():
        named = console.desk.client.http.put("/api/me/profile", body=json.dumps({"display_name": name}),
                                             headers={**track.racer_apis[username].headers,
                                                      "Content-Type": "application/json"})
        assert named.status_code == 200, named.body
        assert track.add(username).status_code == 200

    page = console.web.get(track.base).body.decode()
    assert track.on_deck(page) == ["Björn (bjorn_a)", "björn (bjorn_b)", "山田太郎"]
    assert "Zoë Müller" in text_of(page.split('data-testid="queue-later"', 1)[1])
    assert "Ready race for Björn (bjorn_a)" in text_of(page)

    track.press("remove", "björn (bjorn_b)")
    assert track.on_deck() == ["Björn", "山田太郎", "Zoë Müller"]
