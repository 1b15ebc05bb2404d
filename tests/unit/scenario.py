"""Racing set-ups through the real API, in one place: racers, a fleet with a timer, an event, races with laps.

The race, timing, leaderboard, public-page and console tests all need "an event with a racer on track 1 and a race
with some laps" before they check anything; `Scenario` builds it step by step through the same JSON API the staff
use (a `Desk` signed in as operator "op"), with the server clock in hand so lap times are exact:

    scenario.add_racers("vera").add_event().add_race("vera", laps=[10_000])
    eid, rid = scenario.event_id, scenario.race_id

Every step asserts that the API accepted it, so a broken set-up fails where it broke, not in the test's assertions.
The `scenario` fixture (tests/unit/conftest.py) gives one over the `desk` and `clock` fixtures; console tests build
one over `console.desk`.
"""
from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from tests.unit.race_helpers import Desk, FakeClock


@dataclass
class Scenario:
    desk: Desk
    clock: FakeClock | None = None  # needed only for laps
    fleet_id: str = ""
    timer: str = ""  # the last timer's `Authorization: Device` credential
    event: dict[str, Any] | None = None
    race_id: str = ""

    @property
    def event_id(self) -> str:
        assert self.event is not None, "no event yet: call .add_event() first"
        return self.event["event_id"]

    def add_racers(self, *usernames: str) -> Scenario:
        for username in usernames:
            self.desk.users.create(username, ("racer",))
        return self

    def add_fleet(self, name: str = "Track fleet") -> Scenario:
        self.fleet_id = self.desk.fleet(name)
        return self

    def add_timer(self, hostname: str = "timer-1") -> Scenario:
        """An activated timer in the fleet (made first if there is none yet); its credential in `.timer`."""
        if not self.fleet_id:
            self.add_fleet()
        self.timer = self.desk.device(self.fleet_id, hostname, kind="timer")
        return self

    def add_car(self, hostname: str = "car-1") -> str:
        """An activated car in the fleet; its device id."""
        self.desk.device(self.fleet_id, hostname, kind="car")
        devices = json.loads(self.desk.call("GET", "/api/devices").body)["devices"]
        return next(device["device_id"] for device in devices if device["hostname"] == hostname)

    def add_event(self, *, tracks: list[dict[str, Any]] | None = None, **event: Any) -> Scenario:
        """An event (Desk.event's defaults: Summit Stockholm 2026, track 1); track 1 runs on the scenario's fleet if
        one was made and no tracks are given."""
        if tracks is None and self.fleet_id:
            tracks = [{"track_id": "1", "fleet_id": self.fleet_id}]
        self.event = self.desk.event(tracks=tracks, **event)
        return self

    def add_race(self, racer: str, laps: Iterable[int] = (), *, track: str = "1", start: bool = True,
                 submit: bool = False, event_id: str | None = None) -> Scenario:
        """A race for `racer` at the scenario's event (or `event_id`): created, started (unless start=False), one lap
        captured per duration in `laps` (the clock moved by that much first), then ended and submitted if `submit`.
        Its id in `.race_id`."""
        desk, event_id = self.desk, event_id or self.event_id
        self.race_id = desk.ok(desk.create_race(event_id, racer, track), 201)["race_id"]
        if start:
            desk.ok(desk.command(event_id, self.race_id, "start"))
        for lap_ms in laps:
            assert self.clock is not None, "laps need the clock: Scenario(desk, clock)"
            self.clock.advance(lap_ms)
            desk.ok(desk.command(event_id, self.race_id, "capture_lap"))
        if submit:
            desk.ok(desk.command(event_id, self.race_id, "end"))
            desk.ok(desk.command(event_id, self.race_id, "submit"))
        return self

    def submitted_race(self, racer: str, laps: Iterable[int], *, track: str = "1", event_id: str | None = None) -> str:
        """A race run to the end and submitted; its id."""
        return self.add_race(racer, laps, track=track, submit=True, event_id=event_id).race_id
