"""Timing-strip posts from real activated devices, through the API: the first crossing starts the race and laps come
from device timestamps, reaching the race and the board; only devices in the track's fleet may post (403), a bogus
credential is 401, and a bad post is a 400 naming the field. The rules of crossings (replays, debounce, pause and
end, crash recovery, who may time a race) are tests/domain/test_timing_rules.py's, on the in-memory stores."""
from __future__ import annotations

import json

import pytest

from tests.unit.race_helpers import Desk, FakeClock
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit

T0 = 1_700_000_000_000  # device clock


@pytest.fixture
def timed_track(scenario: Scenario) -> tuple[str, str, str]:
    """(event id, race id, timer credential): a live race on track 1, whose fleet holds the timer."""
    scenario.add_timer("timer-1").add_racers("tia").add_event().add_race("tia", start=False)
    return scenario.event_id, scenario.race_id, scenario.timer


def _race(desk: Desk, eid: str, rid: str) -> dict:
    return desk.ok(desk.call("GET", f"/api/events/{eid}/races/{rid}"))


def test_first_crossing_starts_and_laps_come_from_device_timestamps(desk: Desk, clock: FakeClock,
                                                                   timed_track) -> None:
    eid, rid, timer = timed_track
    start = desk.ok(desk.strip(timer, eid, T0, "k1"))
    assert (start["action"], start["status"], start["race_id"]) == ("start", "RUNNING", rid)
    clock.advance(9_000)  # the server clock does not matter for timer laps
    lap = desk.ok(desk.strip(timer, eid, T0 + 10_250, "k2"))
    assert lap["action"] == "lap" and lap["lap"]["time_ms"] == 10_250 and lap["lap"]["source"] == "timer"
    desk.ok(desk.strip(timer, eid, T0 + 19_000, "k3", sensor=27))
    race = _race(desk, eid, rid)
    assert [lap["time_ms"] for lap in race["laps"]] == [10_250, 8_750]
    assert desk.board(eid)["entries"][0]["fastest_lap_ms"] == 8_750


def test_devices_outside_the_track_fleet_are_refused(desk: Desk, clock: FakeClock, timed_track) -> None:
    eid, _rid, _timer = timed_track
    stranger = desk.device(desk.fleet("Other fleet"), "timer-2")
    refused = desk.strip(stranger, eid, T0, "x")
    assert refused.status_code == 403
    assert "not in the fleet of track 1" in json.loads(refused.body)["error"]["message"]
    bogus = desk.strip("dev-unknown.secret", eid, T0, "x")
    assert bogus.status_code == 401
    desk.token("ursula", "racer")
    as_user = desk.call("POST", "/api/timing/strip-events", {"event_id": eid, "track_id": "1", "timestamp_ms": T0,
                                                             "sensor": 17, "idempotency_key": "x"}, as_user="ursula")
    assert as_user.status_code == 403


def test_bad_strip_post_names_the_field(desk: Desk, clock: FakeClock, timed_track) -> None:
    eid, _rid, timer = timed_track
    reply = desk.client.http.post("/api/timing/strip-events", body=json.dumps(
        {"event_id": eid, "track_id": "1", "timestamp_ms": -5, "sensor": 17, "idempotency_key": "k"}).encode(),
        headers={"Authorization": f"Device {timer}", "Content-Type": "application/json"})
    assert reply.status_code == 400 and json.loads(reply.body)["error"]["field"] == "timestamp_ms"


@pytest.mark.parametrize("timestamp_ms", [10**18, 10**30, 4_102_444_800_001])
def test_a_device_clock_past_2100_is_a_400_and_the_race_keeps_counting(desk: Desk, clock: FakeClock, timed_track,
                                                                     timestamp_ms: int) -> None:
    eid, rid, timer = timed_track
    desk.ok(desk.strip(timer, eid, T0, "start"))

    absurd = desk.strip(timer, eid, timestamp_ms, "absurd")

    assert absurd.status_code == 400, absurd.body
    error = json.loads(absurd.body)["error"]
    assert error["field"] == "timestamp_ms" and "4102444800000" in error["message"]
    # Before the bound, 10**18 froze the race: every true crossing after it read as out of order.
    lap = desk.ok(desk.strip(timer, eid, T0 + 11_000, "true lap"))
    assert lap["action"] == "lap" and lap["lap"]["time_ms"] == 11_000
    assert [lap["time_ms"] for lap in _race(desk, eid, rid)["laps"]] == [11_000]
