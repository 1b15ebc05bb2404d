"""Timing-strip posts from real activated devices: the first crossing starts the race, laps come from device
timestamps, a retried post (same idempotency key) gets the same answer and never a second lap, debounce, and only
devices in the track's fleet may post."""
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


def test_repeated_idempotency_key_replays_the_answer_without_a_second_lap(desk: Desk, clock: FakeClock,
                                                                         timed_track) -> None:
    eid, rid, timer = timed_track
    desk.ok(desk.strip(timer, eid, T0, "a"))
    first = desk.ok(desk.strip(timer, eid, T0 + 11_000, "b"))
    again = desk.ok(desk.strip(timer, eid, T0 + 11_000, "b"))
    assert again == {**first, "replayed": True} and first["replayed"] is False
    assert len(_race(desk, eid, rid)["laps"]) == 1
    # Even a retry with a different body is answered from the store: the key is what identifies the crossing.
    assert desk.ok(desk.strip(timer, eid, T0 + 30_000, "b"))["lap"]["time_ms"] == 11_000
    assert len(_race(desk, eid, rid)["laps"]) == 1


def test_debounce_and_both_strips_are_one_crossing(desk: Desk, clock: FakeClock, timed_track) -> None:
    eid, rid, timer = timed_track
    desk.ok(desk.strip(timer, eid, T0, "s", sensor=17))
    bounce = desk.ok(desk.strip(timer, eid, T0 + 500, "s-bounce", sensor=17))
    assert (bounce["action"], bounce["reason"]) == ("ignore", "sensor_debounce")
    other_strip = desk.ok(desk.strip(timer, eid, T0 + 400, "s-other", sensor=27))
    assert (other_strip["action"], other_strip["reason"]) == ("ignore", "same_crossing")
    lap = desk.ok(desk.strip(timer, eid, T0 + 12_000, "lap", sensor=17))
    assert lap["lap"]["time_ms"] == 12_000
    assert len(_race(desk, eid, rid)["laps"]) == 1


def test_crossing_while_paused_resumes_and_after_end_is_ignored(desk: Desk, clock: FakeClock, timed_track) -> None:
    eid, rid, timer = timed_track
    desk.ok(desk.strip(timer, eid, T0, "1"))
    desk.ok(desk.command(eid, rid, "pause"))
    assert desk.ok(desk.strip(timer, eid, T0 + 20_000, "2"))["action"] == "resume"
    desk.ok(desk.command(eid, rid, "end"))
    late = desk.ok(desk.strip(timer, eid, T0 + 40_000, "3"))
    assert (late["action"], late["reason"]) == ("ignore", "race_not_live")
    desk.ok(desk.command(eid, rid, "submit"))
    after = desk.ok(desk.strip(timer, eid, T0 + 60_000, "4"))
    assert (after["action"], after["reason"], after["race_id"]) == ("ignore", "no_live_race", None)


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


def _board_laps(desk: Desk, eid: str) -> int:
    entries = desk.board(eid)["entries"]
    return entries[0]["laps"] if entries else 0


def test_a_retry_after_a_crash_before_the_board_write_publishes_the_stored_lap(
        desk: Desk, clock: FakeClock, timed_track, monkeypatch: pytest.MonkeyPatch) -> None:
    """The process dies right after the race write (its answer never reaches the timer): the lap is in the race, the
    board is a lap behind; the timer's retry is answered from the store AND brings the board up to date."""
    from chalicelib.domain.races import RaceService

    eid, rid, timer = timed_track
    desk.ok(desk.strip(timer, eid, T0, "s"))
    desk.ok(desk.strip(timer, eid, T0 + 10_000, "l1"))
    assert _board_laps(desk, eid) == 1
    with monkeypatch.context() as crash:
        crash.setattr(RaceService, "publish", lambda *args, **kwargs: None)  # dies before the board write
        desk.ok(desk.strip(timer, eid, T0 + 19_000, "l2"))
    assert len(_race(desk, eid, rid)["laps"]) == 2 and _board_laps(desk, eid) == 1
    replay = desk.ok(desk.strip(timer, eid, T0 + 19_000, "l2"))
    assert replay["replayed"] is True
    assert _board_laps(desk, eid) == 2 and desk.board(eid)["entries"][0]["fastest_lap_ms"] == 9_000


def test_a_left_over_publish_is_finished_by_the_sweeper_and_by_the_next_lap(
        desk: Desk, clock: FakeClock, timed_track, monkeypatch: pytest.MonkeyPatch) -> None:
    from chalicelib import services
    from chalicelib.domain.races import RaceService

    eid, rid, timer = timed_track
    desk.ok(desk.strip(timer, eid, T0, "s"))
    with monkeypatch.context() as crash:
        crash.setattr(RaceService, "publish", lambda *args, **kwargs: None)
        desk.ok(desk.strip(timer, eid, T0 + 10_000, "l1"))
    assert _board_laps(desk, eid) == 0
    assert services.race_service().complete_pending_publishes() == 1  # what the app server's sweeper runs
    assert _board_laps(desk, eid) == 1
    assert services.race_service().complete_pending_publishes() == 0  # finished intents are gone
    # A left-over row is also brought up to date by the racer's next lap (its rebuild reads every race).
    with monkeypatch.context() as crash:
        crash.setattr(RaceService, "publish", lambda *args, **kwargs: None)
        desk.ok(desk.strip(timer, eid, T0 + 20_000, "l2"))
    desk.ok(desk.strip(timer, eid, T0 + 29_000, "l3"))
    assert _board_laps(desk, eid) == 3


def test_a_board_write_failing_after_the_lap_is_stored_still_acknowledges_the_lap(
        desk: Desk, clock: FakeClock, timed_track, monkeypatch: pytest.MonkeyPatch) -> None:
    """Storage goes away between the race write and the board write: the lap is stored, so the answer is the lap
    (not 'cannot be reached'), and the board catches up once storage answers again."""
    from chalicelib.core.errors import ServiceUnavailable
    from chalicelib.domain.leaderboards import LeaderboardPublisher

    eid, rid, timer = timed_track
    desk.ok(desk.strip(timer, eid, T0, "s"))

    def storage_down(*_args, **_kwargs):
        raise ServiceUnavailable("The leaderboards table cannot be reached.")

    with monkeypatch.context() as outage:
        outage.setattr(LeaderboardPublisher, "refresh_racer", storage_down)
        lap = desk.ok(desk.strip(timer, eid, T0 + 10_000, "l1"))
    assert lap["action"] == "lap" and _board_laps(desk, eid) == 0
    assert desk.ok(desk.strip(timer, eid, T0 + 10_000, "l1"))["replayed"] is True
    assert _board_laps(desk, eid) == 1


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


def test_a_second_timer_in_the_fleet_cannot_lap_a_race_another_timer_is_timing(desk: Desk, clock: FakeClock,
                                                                             timed_track) -> None:
    eid, rid, timer = timed_track
    track_fleet = desk.ok(desk.call("GET", f"/api/events/{eid}"))["tracks"][0]["fleet_id"]
    intruder = desk.device(track_fleet, "timer-2")
    desk.ok(desk.strip(timer, eid, T0, "start"))

    refused = desk.strip(intruder, eid, T0 + 3_500, "fake lap")

    assert refused.status_code == 403
    assert f"Race {rid} is timed by device" in json.loads(refused.body)["error"]["message"]
    assert _race(desk, eid, rid)["laps"] == []
    assert desk.ok(desk.strip(timer, eid, T0 + 12_000, "real lap"))["lap"]["time_ms"] == 12_000


def test_a_car_times_only_the_race_it_is_the_car_of(desk: Desk, clock: FakeClock) -> None:
    fleet = desk.fleet()
    own_car = desk.device(fleet, "car-a", kind="car")
    other_car = desk.device(fleet, "car-b", kind="car")
    desk.users.create("cara", ("racer",))
    eid = desk.event(tracks=[{"track_id": "1", "fleet_id": fleet}])["event_id"]
    rid = desk.ok(desk.create_race(eid, "cara", car="car-a"), 201)["race_id"]

    refused = desk.strip(other_car, eid, T0, "b-start")

    assert refused.status_code == 403
    assert f"is not the car of race {rid}" in json.loads(refused.body)["error"]["message"]
    assert desk.ok(desk.strip(own_car, eid, T0, "a-start"))["action"] == "start"
    assert desk.ok(desk.strip(own_car, eid, T0 + 9_000, "a-lap"))["lap"]["time_ms"] == 9_000
