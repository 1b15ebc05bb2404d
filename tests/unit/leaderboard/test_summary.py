"""Race summaries per racer and track, over SUBMITTED races only; no crash for a racer without a valid lap."""
from __future__ import annotations

import pytest

from drem_leaderboard.models import RaceConfig, RaceStatus, RankingMethod
from drem_leaderboard.summary import summarise_event, summarise_racer

from .builders import submitted_race

pytestmark = pytest.mark.unit


def test_summary_over_all_submitted_races_of_a_racer_on_a_track():
    first = submitted_race([12_000, 11_000, 30_000, 10_500], valid=[True, True, False, True], resets=[0, 1, 4, 0],
                           race_id="a")
    second = submitted_race([9_800, 10_000, 10_200], race_id="b", finished_at_ms=first.submitted_at_ms + 60_000)

    summary = summarise_racer([first, second])

    assert summary is not None
    assert (summary.races, summary.total_laps, summary.valid_laps, summary.invalid_laps) == (2, 7, 6, 1)
    assert summary.fastest_lap_ms == 9_800
    assert summary.fastest_average is not None and summary.fastest_average.avg_ms == 10_000
    assert summary.fastest_average_race_id == "b"
    assert summary.average_lap_ms == round((12_000 + 11_000 + 10_500 + 9_800 + 10_000 + 10_200) / 6)
    assert summary.lap_completion_pct == 85.7  # exact to one decimal, not DREM's 10 % steps (which says 90)
    assert summary.laps_per_attempt == 3.5
    assert summary.most_consecutive_valid_laps == 3
    assert summary.total_resets == 5


def test_a_racer_with_only_invalid_laps_gets_a_summary_with_empty_times():
    summary = summarise_racer([submitted_race([20_000, 25_000], valid=[False, False])])

    assert summary is not None
    assert summary.valid_laps == 0 and summary.invalid_laps == 2
    assert summary.fastest_lap_ms is None
    assert summary.fastest_average is None
    assert summary.average_lap_ms is None
    assert summary.lap_completion_pct == 0.0
    assert summary.most_consecutive_valid_laps == 0
    assert summary.best_lap_count is None


def test_a_submitted_race_without_laps_counts_as_an_attempt():
    summary = summarise_racer([submitted_race([])])

    assert summary is not None
    assert (summary.races, summary.total_laps, summary.lap_completion_pct, summary.laps_per_attempt) == (1, 0, None,
                                                                                                         0.0)


def test_races_that_were_not_submitted_do_not_count():
    discarded = submitted_race([8_000, 8_000, 8_000], race_id="d").model_copy(update={"status": RaceStatus.DISCARDED})
    kept = submitted_race([10_000], race_id="k")

    summary = summarise_racer([discarded, kept])
    assert summary is not None and summary.races == 1 and summary.fastest_lap_ms == 10_000
    assert summarise_racer([discarded]) is None


def test_a_summary_refuses_to_mix_racers_or_tracks():
    with pytest.raises(ValueError, match="one racer on one track"):
        summarise_racer([submitted_race([10_000]), submitted_race([10_000], track_id="2")])


def test_lap_count_result_is_the_best_race_by_valid_laps_then_elapsed_time():
    config = RaceConfig(ranking_method=RankingMethod.LAP_COUNT, lap_count_target=3)
    slow = submitted_race([10_000, 10_000, 10_000], race_id="slow", config=config)
    fast = submitted_race([9_000, 20_000, 9_000, 9_000], valid=[True, False, True, True], race_id="fast", config=config)
    short = submitted_race([5_000, 5_000], race_id="short", config=config)

    best = summarise_racer([slow, fast, short]).best_lap_count

    assert best is not None and best.race_id == "slow"  # 30 s beats 47 s, which includes the invalid lap's time
    assert best.valid_laps == 3 and best.elapsed_ms == 30_000


def test_event_summaries_group_by_track_and_racer():
    races = [
        submitted_race([10_000], race_id="1", sub="a", username="ann"),
        submitted_race([11_000], race_id="2", sub="a", username="ann", track_id="2"),
        submitted_race([12_000], race_id="3", sub="b", username="bob"),
    ]

    summaries = summarise_event(races)

    assert [(s.track_id, s.racer_sub) for s in summaries] == [("1", "a"), ("1", "b"), ("2", "a")]
