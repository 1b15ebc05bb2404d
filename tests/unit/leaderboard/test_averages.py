"""Average windows: every run of X consecutive valid laps, and the race's fastest one."""
from __future__ import annotations

import random

import pytest

from drem_leaderboard.averages import AverageWindow, average_windows, fastest_window

from .builders import submitted_race

pytestmark = pytest.mark.unit


def _windows(times, valid=None, window=3):
    return average_windows(submitted_race(times, valid=valid).laps, window)


def test_every_run_of_consecutive_valid_laps_is_a_window():
    windows = _windows([10_000, 11_000, 12_000, 9_000])

    assert [(w.start_lap_id, w.end_lap_id, w.avg_ms) for w in windows] == [(0, 2, 11_000), (1, 3, 10_667)]


def test_an_invalid_lap_breaks_the_run():
    windows = _windows([10_000, 10_000, 10_000, 10_000, 10_000, 10_000, 10_000], valid=[True, True, False, True, True,
                                                                                        True, True])

    assert [(w.start_lap_id, w.end_lap_id) for w in windows] == [(3, 5), (4, 6)]


def test_too_few_valid_laps_give_no_window():
    assert _windows([10_000, 10_000]) == []
    assert fastest_window([]) is None


def test_the_mean_rounds_half_up_like_drem():
    assert _windows([1_000, 1_001], window=2)[0].avg_ms == 1_001


def test_the_fastest_window_wins_and_an_equal_one_set_earlier_beats_a_later_one():
    early = AverageWindow(start_lap_id=0, end_lap_id=2, avg_ms=9_000, achieved_at_ms=100)
    late = AverageWindow(start_lap_id=3, end_lap_id=5, avg_ms=9_000, achieved_at_ms=200)
    slow = AverageWindow(start_lap_id=1, end_lap_id=3, avg_ms=9_500, achieved_at_ms=50)

    assert fastest_window([late, slow, early]) == early


@pytest.mark.parametrize("seed", range(20))
def test_windows_match_a_brute_force_count_of_valid_runs(seed):
    rng = random.Random(seed)
    count, window = rng.randint(0, 15), rng.randint(3, 7)
    times = [rng.randint(5_000, 20_000) for _ in range(count)]
    valid = [rng.random() < 0.8 for _ in range(count)]

    windows = _windows(times, valid=valid or None, window=window) if count else []

    expected = [i for i in range(count - window + 1) if all(valid[i : i + window])]
    assert [w.start_lap_id for w in windows] == expected
    for w in windows:
        in_window = times[w.start_lap_id : w.end_lap_id + 1]
        assert min(in_window) <= w.avg_ms <= max(in_window)
