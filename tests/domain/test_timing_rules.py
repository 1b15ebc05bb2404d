"""The rules of timing-strip crossings, on the fast domain tier: TimingService and RaceService over the in-memory race,
board, event, account and device stores (tests/in_memory), no moto and no HTTP. What crosses a boundary stays in
tests/unit/test_timing_api.py: a real activated timer's posts reaching the race and the board, the 400s naming the
field, and the 401/403 answers of credentials that are bogus or not a device's."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import pytest

from chalicelib.core.errors import Forbidden, ServiceUnavailable
from chalicelib.core.principals import Device
from chalicelib.domain.activation import ActivationExchange, ActivationRecord
from chalicelib.domain.devices import DeviceKind, DeviceRecord, StatusEntry
from chalicelib.domain.leaderboards import LeaderboardPublisher
from chalicelib.domain.races import RaceService
from chalicelib.domain.timing import StripPost, TimingService
from tests.domain.race_desk import Desk, new_desk
from tests.in_memory.devices import InMemoryDeviceStore

pytestmark = pytest.mark.domain

T0 = 1_700_000_000_000  # device clock
FLEET = "track-fleet"


@dataclass
class Track:
    """Track 1 of event e1, timed by the devices of FLEET, with racer tia's race live on it (not started)."""
    desk: Desk
    devices: InMemoryDeviceStore
    timing: TimingService
    race_id: str
    timer: Device

    def device(self, hostname: str, fleet_id: str = FLEET, kind: DeviceKind = DeviceKind.TIMER) -> Device:
        """A device activated into `fleet_id` (the way ActivationService registers one: redeeming a code)."""
        code = ActivationRecord(code_hash=f"code-{hostname}", fleet_id=fleet_id, hostname=hostname, device_kind=kind,
                                expires_at_ms=10**13, created_at_ms=1, created_by="op")
        self.devices.put_activation(code)
        record = DeviceRecord(device_id=f"id-{hostname}", kind=kind, hostname=hostname, fleet_id=fleet_id,
                              secret_hash="s", registered_at_ms=2, activated_by="op")
        exchange = ActivationExchange(code="ABCD-EFGH", hostname=hostname, device_kind=kind)
        assert self.devices.redeem(code.code_hash, exchange, 3, record, StatusEntry.for_device(record), None)
        return Device(device_id=record.device_id, device_kind=kind.value)

    def strip(self, device: Device, timestamp_ms: int, key: str, sensor: int = 17) -> dict[str, Any]:
        post = StripPost(event_id="e1", track_id="1", timestamp_ms=timestamp_ms, sensor=sensor, idempotency_key=key)
        return self.timing.strip_event(device, post).model_dump(mode="json")

    def laps(self) -> list[int]:
        record = self.desk.races.get("e1", self.race_id)
        assert record is not None
        return [lap.time_ms for lap in record.race.laps]

    def board_laps(self) -> int:
        entries = self.desk.board_entries("e1")
        return int(entries[0]["laps"]) if entries else 0


def a_track(car: str | None = None) -> Track:
    desk, devices = new_desk(), InMemoryDeviceStore()
    desk.event(fleet_id=FLEET)
    desk.users.add("tia", "racer")
    timing = TimingService(desk.service, desk.races, devices, desk.clock, events=desk.events)
    track = Track(desk, devices, timing, "", Device(device_id="none", device_kind="timer"))
    track.timer = track.device("timer-1")
    track.race_id = desk.race("e1", "tia", **({"car": car} if car else {}))
    return track


@pytest.fixture
def track() -> Track:
    return a_track()


def test_the_first_crossing_starts_and_laps_come_from_device_timestamps(track: Track) -> None:
    start = track.strip(track.timer, T0, "k1")
    assert (start["action"], start["status"], start["race_id"]) == ("start", "RUNNING", track.race_id)
    track.desk.clock.advance(9_000)  # the server clock does not matter for timer laps
    lap = track.strip(track.timer, T0 + 10_250, "k2")
    assert lap["action"] == "lap" and lap["lap"]["time_ms"] == 10_250 and lap["lap"]["source"] == "timer"
    track.strip(track.timer, T0 + 19_000, "k3", sensor=27)
    assert track.laps() == [10_250, 8_750]
    assert track.desk.board_entries("e1")[0]["fastest_lap_ms"] == 8_750


def test_a_repeated_idempotency_key_replays_the_answer_without_a_second_lap(track: Track) -> None:
    track.strip(track.timer, T0, "a")
    first = track.strip(track.timer, T0 + 11_000, "b")
    again = track.strip(track.timer, T0 + 11_000, "b")
    assert again == {**first, "replayed": True} and first["replayed"] is False
    assert len(track.laps()) == 1
    # Even a retry with a different body is answered from the store: the key is what identifies the crossing.
    assert track.strip(track.timer, T0 + 30_000, "b")["lap"]["time_ms"] == 11_000
    assert len(track.laps()) == 1


def test_a_bounce_and_both_strips_are_one_crossing(track: Track) -> None:
    track.strip(track.timer, T0, "s", sensor=17)
    bounce = track.strip(track.timer, T0 + 500, "s-bounce", sensor=17)
    assert (bounce["action"], bounce["reason"]) == ("ignore", "sensor_debounce")
    other_strip = track.strip(track.timer, T0 + 400, "s-other", sensor=27)
    assert (other_strip["action"], other_strip["reason"]) == ("ignore", "same_crossing")
    assert track.strip(track.timer, T0 + 12_000, "lap", sensor=17)["lap"]["time_ms"] == 12_000
    assert len(track.laps()) == 1


def test_a_crossing_while_paused_resumes_and_after_the_end_is_ignored(track: Track) -> None:
    track.strip(track.timer, T0, "1")
    track.desk.command("e1", track.race_id, "pause")
    assert track.strip(track.timer, T0 + 20_000, "2")["action"] == "resume"
    track.desk.command("e1", track.race_id, "end")
    late = track.strip(track.timer, T0 + 40_000, "3")
    assert (late["action"], late["reason"]) == ("ignore", "race_not_live")
    track.desk.command("e1", track.race_id, "submit")
    after = track.strip(track.timer, T0 + 60_000, "4")
    assert (after["action"], after["reason"], after["race_id"]) == ("ignore", "no_live_race", None)


def test_a_device_outside_the_tracks_fleet_is_refused_and_counts_nothing(track: Track) -> None:
    stranger = track.device("timer-2", fleet_id="other-fleet")
    with pytest.raises(Forbidden, match="Device id-timer-2 is not in the fleet of track 1"):
        track.strip(stranger, T0, "x")
    unregistered = Device(device_id="id-gone", device_kind="timer")
    with pytest.raises(Forbidden, match="not in the fleet"):
        track.strip(unregistered, T0, "y")
    assert track.desk.races.get("e1", track.race_id).race.status.value == "READY"


def test_a_retry_after_a_crash_before_the_board_write_publishes_the_stored_lap(
        track: Track, monkeypatch: pytest.MonkeyPatch) -> None:
    """The process dies right after the race write (its answer never reaches the timer): the lap is in the race, the
    board is a lap behind; the timer's retry is answered from the store AND brings the board up to date."""
    track.strip(track.timer, T0, "s")
    track.strip(track.timer, T0 + 10_000, "l1")
    assert track.board_laps() == 1
    with monkeypatch.context() as crash:
        crash.setattr(RaceService, "publish", lambda *args, **kwargs: None)  # dies before the board write
        track.strip(track.timer, T0 + 19_000, "l2")
    assert len(track.laps()) == 2 and track.board_laps() == 1
    assert track.strip(track.timer, T0 + 19_000, "l2")["replayed"] is True
    assert track.board_laps() == 2 and track.desk.board_entries("e1")[0]["fastest_lap_ms"] == 9_000


def test_a_left_over_publish_is_finished_by_the_sweeper_and_by_the_next_lap(
        track: Track, monkeypatch: pytest.MonkeyPatch) -> None:
    track.strip(track.timer, T0, "s")
    with monkeypatch.context() as crash:
        crash.setattr(RaceService, "publish", lambda *args, **kwargs: None)
        track.strip(track.timer, T0 + 10_000, "l1")
    assert track.board_laps() == 0
    assert track.desk.service.complete_pending_publishes() == 1  # what the app server's sweeper runs
    assert track.board_laps() == 1
    assert track.desk.service.complete_pending_publishes() == 0  # finished intents are gone
    # A left-over row is also brought up to date by the racer's next lap (its rebuild reads every race).
    with monkeypatch.context() as crash:
        crash.setattr(RaceService, "publish", lambda *args, **kwargs: None)
        track.strip(track.timer, T0 + 20_000, "l2")
    track.strip(track.timer, T0 + 29_000, "l3")
    assert track.board_laps() == 3


def test_a_board_write_failing_after_the_lap_is_stored_still_acknowledges_the_lap(
        track: Track, monkeypatch: pytest.MonkeyPatch) -> None:
    """Storage goes away between the race write and the board write: the lap is stored, so the answer is the lap
    (not 'cannot be reached'), and the board catches up once storage answers again."""
    track.strip(track.timer, T0, "s")

    def storage_down(*_args: Any, **_kwargs: Any) -> None:
        raise ServiceUnavailable("The leaderboards table cannot be reached.")

    with monkeypatch.context() as outage:
        outage.setattr(LeaderboardPublisher, "refresh_racer", storage_down)
        lap = track.strip(track.timer, T0 + 10_000, "l1")
    assert lap["action"] == "lap" and track.board_laps() == 0
    assert track.strip(track.timer, T0 + 10_000, "l1")["replayed"] is True
    assert track.board_laps() == 1


def test_a_second_timer_in_the_fleet_cannot_lap_a_race_another_timer_is_timing(track: Track) -> None:
    intruder = track.device("timer-2")
    track.strip(track.timer, T0, "start")
    with pytest.raises(Forbidden, match=f"Race {track.race_id} is timed by device id-timer-1"):
        track.strip(intruder, T0 + 3_500, "fake lap")
    assert track.laps() == []
    assert track.strip(track.timer, T0 + 12_000, "real lap")["lap"]["time_ms"] == 12_000


def test_a_car_times_only_the_race_it_is_the_car_of() -> None:
    track = a_track(car="car-a")
    own_car = track.device("car-a", kind=DeviceKind.CAR)
    other_car = track.device("car-b", kind=DeviceKind.CAR)
    with pytest.raises(Forbidden, match=f"is not the car of race {track.race_id}"):
        track.strip(other_car, T0, "b-start")
    assert track.strip(own_car, T0, "a-start")["action"] == "start"
    assert track.strip(own_car, T0 + 9_000, "a-lap")["lap"]["time_ms"] == 9_000
