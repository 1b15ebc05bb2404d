"""Leaderboards: ranking methods, deterministic ties, DNF last, combined board, entry fields and the etag."""
from __future__ import annotations

import pytest

from drem_leaderboard.models import RaceConfig, RankingMethod
from drem_leaderboard.ranking import COMBINED_TRACK_ID, RacerProfile, rank
from drem_leaderboard.summary import RaceSummary, summarise_racer

from .builders import T0, submitted_race

pytestmark = pytest.mark.unit

M = RankingMethod


def _summary(sub: str, times: list[int], *, valid=None, track_id="1", at=T0, config=None, proxy=False) -> RaceSummary:
    race = submitted_race(
        times, valid=valid, sub=sub, username=sub, track_id=track_id, race_id=f"{sub}-{track_id}-{at}",
        finished_at_ms=at, config=config, raced_by_proxy=proxy,
    )  # fmt: skip
    summary = summarise_racer([race])
    assert summary is not None
    return summary


def _order(board) -> list[str]:
    return [entry.username for entry in board.entries]


def test_best_lap_time_ranks_the_fastest_valid_lap_first_with_gaps_to_the_leader():
    board = rank(
        [_summary("cat", [10_400]), _summary("ann", [9_900, 30_000]), _summary("bob", [8_000], valid=[False])],
        M.BEST_LAP_TIME,
        track_id="1",
    )

    assert _order(board) == ["ann", "cat", "bob"]
    assert [e.position for e in board.entries] == [1, 2, 3]
    assert [e.time_ms for e in board.entries] == [9_900, 10_400, None]
    assert [e.gap_to_leader_ms for e in board.entries] == [0, 500, None]
    assert board.entries[2].is_dnf


def test_equal_times_rank_who_set_it_first_and_then_by_name():
    board = rank(
        [
            _summary("zed", [10_000], at=T0 + 50_000),
            _summary("bea", [10_000], at=T0),
            _summary("abe", [10_000], at=T0),
        ],
        M.BEST_LAP_TIME,
        track_id="1",
    )

    assert _order(board) == ["abe", "bea", "zed"]


def test_racers_without_a_valid_lap_are_last_in_name_order():
    board = rank(
        [_summary("yan", [5_000], valid=[False]), _summary("xia", []), _summary("kim", [20_000])],
        M.BEST_LAP_TIME,
        track_id="1",
    )

    assert _order(board) == ["kim", "xia", "yan"]
    assert [e.is_dnf for e in board.entries] == [False, True, True]


def test_average_method_ranks_windows_and_puts_racers_without_one_after_them_by_fastest_lap():
    board = rank(
        [
            _summary("solo", [7_000, 50_000], valid=[True, False]),  # fastest lap of all, but no 3-lap window
            _summary("even", [10_000, 10_000, 10_000]),
            _summary("quick", [9_000, 9_500, 9_700]),
            _summary("pair", [8_000, 8_000]),
            _summary("none", [8_000], valid=[False]),
        ],
        M.BEST_AVERAGE_LAP_TIME_X_LAP,
        track_id="1",
    )

    assert _order(board) == ["quick", "even", "solo", "pair", "none"]
    assert [e.time_ms for e in board.entries] == [9_400, 10_000, None, None, None]
    assert board.entries[2].fastest_lap_ms == 7_000 and not board.entries[2].is_dnf


def test_lap_count_ranks_more_valid_laps_first_then_less_elapsed_time():
    config = RaceConfig(ranking_method=M.LAP_COUNT, lap_count_target=4)
    board = rank(
        [
            _summary("three", [9_000, 9_000, 9_000], config=config),
            _summary("fourslow", [12_000] * 4, config=config),
            _summary("fourfast", [10_000] * 4, config=config),
            _summary("zero", [9_000], valid=[False], config=config),
        ],
        M.LAP_COUNT,
        track_id="1",
    )

    assert _order(board) == ["fourfast", "fourslow", "three", "zero"]
    assert [e.laps for e in board.entries] == [4, 4, 3, 0]
    assert [e.gap_to_leader_ms for e in board.entries] == [0, 8_000, None, None]


def test_a_track_board_only_shows_that_track():
    board = rank([_summary("ann", [9_000], track_id="1"), _summary("bob", [8_000], track_id="2")], M.BEST_LAP_TIME,
                 track_id="2")

    assert _order(board) == ["bob"]


def test_combined_board_keeps_each_racers_best_track_once():
    board = rank(
        [
            _summary("ann", [9_000], track_id="1"),
            _summary("ann", [8_500], track_id="2"),
            _summary("bob", [8_800], track_id="1"),
        ],
        M.BEST_LAP_TIME,
        track_id=COMBINED_TRACK_ID,
    )

    assert [(e.username, e.track_id, e.time_ms) for e in board.entries] == [("ann", "2", 8_500), ("bob", "1", 8_800)]
    assert board.track_id == COMBINED_TRACK_ID


def test_entries_carry_profile_details_for_the_public_board():
    profiles = {"ann": RacerProfile(username="Ann R.", country_code="SE", highlight_colour="#FF00FF")}
    board = rank([_summary("ann", [9_000], proxy=True), _summary("bob", [9_500])], M.BEST_LAP_TIME, track_id="1",
                 profiles=profiles)

    ann, bob = board.entries
    assert (ann.username, ann.country_code, ann.highlight_colour, ann.raced_by_proxy) == ("Ann R.", "SE", "#FF00FF",
                                                                                          True)
    assert (bob.country_code, bob.highlight_colour, bob.raced_by_proxy) == (None, "#0000FF", False)


def test_the_etag_follows_the_content_not_the_version():
    summaries = [_summary("ann", [9_000]), _summary("bob", [9_500])]
    first = rank(summaries, M.BEST_LAP_TIME, track_id="1", version=1)
    same = rank(list(reversed(summaries)), M.BEST_LAP_TIME, track_id="1", version=2)
    faster = rank([*summaries, _summary("cy", [8_000])], M.BEST_LAP_TIME, track_id="1", version=3)

    assert first.etag == same.etag
    assert first.etag != faster.etag
    assert first.model_dump(mode="json")["etag"] == first.etag


def test_an_empty_board_has_no_entries():
    board = rank([], M.BEST_AVERAGE_LAP_TIME_X_LAP, track_id="1")

    assert board.entries == ()
