"""Race configuration: DREM's ranges, DREM's 9999 = unlimited, and a config frozen once copied into a race."""
from __future__ import annotations

import pydantic
import pytest

from drem_leaderboard.models import RaceConfig, RankingMethod, TrackType

pytestmark = pytest.mark.unit


def test_defaults_match_drem():
    config = RaceConfig()

    assert (config.race_time_min, config.resets_per_lap, config.track_type) == (2, None, TrackType.REINVENT_2018)
    assert (config.ranking_method, config.max_runs_per_racer, config.average_window) == (RankingMethod.BEST_LAP_TIME, 3,
                                                                                         3)
    assert (config.debounce_ms, config.min_lap_ms, config.race_time_ms) == (2_000, 3_000, 120_000)


def test_drems_9999_means_unlimited_even_as_a_string():
    config = RaceConfig.model_validate({"resets_per_lap": 9999, "max_runs_per_racer": "9999"})

    assert (config.resets_per_lap, config.max_runs_per_racer) == (None, None)
    assert RaceConfig.model_validate({"max_runs_per_racer": "2"}).max_runs_per_racer == 2


@pytest.mark.parametrize(
    "fields",
    [
        {"race_time_min": 0},
        {"race_time_min": 11},
        {"resets_per_lap": 11},
        {"resets_per_lap": -1},
        {"max_runs_per_racer": 6},
        {"average_window": 2},
        {"average_window": 8},
        {"track_type": "MONACO"},
        {"lap_count_target": 5},  # only meaningful for LAP_COUNT
    ],
)
def test_out_of_range_settings_are_rejected(fields):
    with pytest.raises(pydantic.ValidationError):
        RaceConfig.model_validate(fields)


def test_lap_count_races_take_a_target():
    config = RaceConfig(ranking_method=RankingMethod.LAP_COUNT, lap_count_target=10)

    assert config.lap_count_target == 10


def test_a_config_cannot_be_changed_after_creation():
    config = RaceConfig()

    with pytest.raises(pydantic.ValidationError):
        config.race_time_min = 5  # type: ignore[misc]


def test_runs_left_counts_down_to_zero_and_unlimited_has_no_limit():
    assert [RaceConfig(max_runs_per_racer=3).runs_left(done) for done in (0, 2, 3, 5)] == [3, 1, 0, 0]
    assert RaceConfig(max_runs_per_racer=9999).runs_left(40) is None
