"""The whole-lap rule (drem_leaderboard.laps) on scripted drives: what every lap and completion figure is built from.

Distances are the drive's (laps × 100 + lap progress, in %), as `drem sim eval`, the simulator and a booth run feed
them; a scripted drive is the same calls a leg of driving makes."""
from __future__ import annotations

import pytest

from drem_leaderboard.laps import LapAttempts

pytestmark = pytest.mark.unit


def drive_to(laps: LapAttempts, start: float, end: float) -> None:
    for tenth in range(int(start * 10), int(end * 10) + 1):
        laps.moved(tenth / 10)


def test_two_clean_laps_from_the_standing_start_are_two_laps_timed_crossing_to_crossing() -> None:
    laps = LapAttempts(start_s=0.0)
    drive_to(laps, 0.0, 100.0)
    laps.crossed(9.25, 100.0)
    drive_to(laps, 100.0, 200.0)
    laps.crossed(18.0, 200.0)
    assert (laps.laps_completed, laps.lap_times_s, laps.ended()) == (2, [9.25, 8.75], [100.0, 100.0])


def test_a_lap_finished_from_where_the_car_was_put_back_is_no_lap_and_no_attempt() -> None:
    laps = LapAttempts(start_s=0.0)
    drive_to(laps, 0.0, 62.5)
    laps.left_track()  # the bend at 62.5 %: put back there
    drive_to(laps, 62.5, 100.0)  # the rest of the lap from rest, never taking that bend
    laps.crossed(11.0, 100.0)
    assert laps.laps_completed == 0 and laps.lap_times_s == []
    assert laps.ended() == [62.5]  # completion 62.5 %, not lifted by the stretch after the put-back

    drive_to(laps, 100.0, 200.0)  # then a whole lap from that crossing
    laps.crossed(20.0, 200.0)
    assert (laps.laps_completed, laps.lap_times_s, laps.ended()) == (1, [9.0], [62.5, 100.0])


def test_a_drive_stopped_on_the_line_or_after_a_put_back_adds_no_attempt_unless_it_ran_out_of_time() -> None:
    on_the_line = LapAttempts()
    drive_to(on_the_line, 0.0, 100.0)
    on_the_line.crossed(9.0, 100.0)
    assert on_the_line.ended() == [100.0]

    stuck = LapAttempts()
    drive_to(stuck, 0.0, 40.0)
    stuck.left_track()
    assert stuck.ended() == [40.0]  # the visitor stopped the run after the put-back
    assert stuck.ended(out_of_time=True) == [40.0, 0.0]  # an evaluation whose car never got going again

    unfinished = LapAttempts()
    drive_to(unfinished, 0.0, 100.0)
    unfinished.crossed(9.0, 100.0)
    drive_to(unfinished, 100.0, 199.99)
    assert unfinished.ended() == [100.0, 99.9]  # never shown as a whole lap it did not finish
