"""Timing-strip crossings: start and resume by strip, debounce, both strips = one lap, idempotent retries."""
from __future__ import annotations

import pytest

from drem_leaderboard import commands as c
from drem_leaderboard.models import LapSource, Race, RaceConfig, RaceStatus
from drem_leaderboard.race_clock import current_lap_ms
from drem_leaderboard.timer_input import (
    IgnoreReason,
    StripAction,
    StripEvent,
    decide,
    handle_strip_event,
    replay_outcome,
)

from .builders import T0, make_race, run

pytestmark = pytest.mark.unit

D0 = 5_000_000  # the Pi's clock is not the server's


def _cross(race: Race, device_ms: int, now_ms: int, sensor: int = 17, key: str | None = None):
    event = StripEvent(timestamp_ms=D0 + device_ms, sensor=sensor, idempotency_key=key or f"{sensor}-{device_ms}")
    return handle_strip_event(race, event, now_ms)


def test_the_first_crossing_starts_the_race_and_only_seeds_the_lap():
    race, outcome = _cross(make_race(), 0, T0)

    assert outcome.action is StripAction.START
    assert race.status is RaceStatus.RUNNING and race.started_at_ms == T0
    assert race.laps == ()
    assert race.lap_seed_ts_ms == D0


def test_a_lap_is_the_difference_of_two_device_timestamps():
    race, _ = _cross(make_race(), 0, T0)
    # The server received the second crossing late; the device time decides the lap.
    race, outcome = _cross(race, 12_345, T0 + 13_900, sensor=27)

    assert outcome.action is StripAction.LAP
    assert outcome.lap is not None
    assert (outcome.lap.time_ms, outcome.lap.source, outcome.lap.device_ts_ms) == (12_345, LapSource.TIMER, D0 + 12_345)
    assert outcome.lap.captured_at_ms == T0 + 13_900


def test_a_crossing_while_paused_resumes_and_starts_a_fresh_lap():
    race, _ = _cross(make_race(), 0, T0)
    race = run(race, (c.DidNotFinish(), T0 + 7_000))
    assert race.status is RaceStatus.PAUSED

    race, outcome = _cross(race, 40_000, T0 + 40_000)
    assert outcome.action is StripAction.RESUME and race.status is RaceStatus.RUNNING
    assert current_lap_ms(race, T0 + 40_000) == 0

    race, outcome = _cross(race, 52_000, T0 + 52_000)
    assert outcome.lap is not None and outcome.lap.time_ms == 12_000


def test_after_a_button_start_the_first_crossing_starts_lap_timing_at_the_line():
    race = run(make_race(), (c.Start(), T0))
    race, outcome = _cross(race, 0, T0 + 600)  # car staged before the line

    assert outcome.action is StripAction.SEED and race.laps == ()
    race, outcome = _cross(race, 11_000, T0 + 11_600)
    assert outcome.lap is not None and outcome.lap.time_ms == 11_000


def test_each_sensor_is_debounced_on_its_own():
    race, _ = _cross(make_race(RaceConfig(min_lap_ms=0)), 0, T0, sensor=17)

    race, outcome = _cross(race, 1_500, T0 + 1_500, sensor=17)
    assert outcome.action is StripAction.IGNORE and outcome.reason is IgnoreReason.SENSOR_DEBOUNCE
    assert race.laps == ()

    race, outcome = _cross(race, 1_600, T0 + 1_600, sensor=27)
    assert outcome.action is StripAction.LAP


def test_a_car_touching_both_strips_is_one_lap():
    race, _ = _cross(make_race(), 0, T0, sensor=17)
    race, _ = _cross(race, 150, T0 + 150, sensor=27)
    assert race.laps == ()

    race, first = _cross(race, 10_000, T0 + 10_000, sensor=17)
    race, second = _cross(race, 10_120, T0 + 10_120, sensor=27)

    assert first.action is StripAction.LAP
    assert second.action is StripAction.IGNORE and second.reason is IgnoreReason.SAME_CROSSING
    assert [lap.time_ms for lap in race.laps] == [10_000]


def test_a_crossing_under_the_minimum_lap_time_is_not_a_lap():
    race = run(make_race(RaceConfig(min_lap_ms=5_000, debounce_ms=0)), (c.Start(), T0))
    race, _ = _cross(race, 0, T0)
    # A manual capture moved the lap start; a strip trigger 1 s later is the same finish, not a 1 s lap.
    race = run(race, (c.CaptureLap(), T0 + 9_000))
    race, outcome = _cross(race, 10_000, T0 + 10_000)

    assert outcome.reason is IgnoreReason.LAP_TOO_SHORT
    assert len(race.laps) == 1


def test_crossings_older_than_one_counted_are_ignored():
    race, _ = _cross(make_race(), 10_000, T0)
    race, outcome = _cross(race, 4_000, T0 + 1_000, sensor=27)

    assert outcome.reason is IgnoreReason.OUT_OF_ORDER


def test_crossings_after_the_race_is_over_change_nothing():
    race = run(make_race(), (c.End(), T0))
    after, outcome = _cross(race, 0, T0 + 1)

    assert outcome.reason is IgnoreReason.RACE_NOT_LIVE
    assert after == race


def test_a_strip_lap_after_expiry_ends_the_race():
    race, _ = _cross(make_race(RaceConfig(race_time_min=1)), 0, T0)
    race, outcome = _cross(race, 70_000, T0 + 70_000)

    assert outcome.lap is not None and outcome.lap.is_valid
    assert outcome.race_ended and race.status is RaceStatus.OVER


def test_a_button_pause_is_not_counted_in_the_next_strip_lap():
    race, _ = _cross(make_race(), 0, T0)
    race = run(race, (c.Pause(), T0 + 5_000), (c.Resume(), T0 + 35_000))
    race, outcome = _cross(race, 42_000, T0 + 42_000)

    assert outcome.lap is not None and outcome.lap.time_ms == 12_000


def test_undoing_a_false_strip_finish_measures_the_real_lap_from_the_original_seed():
    race, _ = _cross(make_race(), 0, T0)
    race, _ = _cross(race, 4_000, T0 + 4_000)  # something else hit the strip
    race = run(race, (c.UndoFalseFinish(), T0 + 5_000))
    race, outcome = _cross(race, 11_000, T0 + 11_000)

    assert outcome.lap is not None and outcome.lap.time_ms == 11_000
    assert [lap.time_ms for lap in race.laps] == [11_000]


def test_a_repeated_idempotency_key_returns_the_original_outcome_without_a_second_lap():
    race, _ = _cross(make_race(), 0, T0)
    event = StripEvent(timestamp_ms=D0 + 10_000, sensor=17, idempotency_key="pi-1:lap-2")
    race, original = handle_strip_event(race, event, T0 + 10_000)
    stored = {event.idempotency_key: original}

    # The device retries after a lost response; by now the same timestamp would read as a debounce.
    assert decide(race, event).reason is IgnoreReason.SENSOR_DEBOUNCE
    replay = replay_outcome(stored[event.idempotency_key])

    assert replay.replayed and not original.replayed
    assert replay.model_copy(update={"replayed": False}) == original
    assert replay.lap is not None and replay.lap.time_ms == 10_000
    assert len(race.laps) == 1


def test_decide_does_not_change_the_race():
    race, _ = _cross(make_race(), 0, T0)
    snapshot = race.model_dump()

    decide(race, StripEvent(timestamp_ms=D0 + 9_000, sensor=27, idempotency_key="k"))

    assert race.model_dump() == snapshot


def test_each_accepted_or_fired_crossing_bumps_the_version_once():
    race = make_race()
    race, outcome = _cross(race, 0, T0)
    assert (race.version, outcome.race_version) == (1, 1)
    same, outcome = _cross(race, 100, T0 + 100)  # sensor debounce: nothing changes
    assert same.version == 1 and outcome.race_version == 1
