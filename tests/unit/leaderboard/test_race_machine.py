"""The race state machine: what an operator's buttons do to a race, driven with an explicit server clock."""
from __future__ import annotations

import random

import pytest

from drem_leaderboard import commands as c
from drem_leaderboard.errors import IllegalCommandError, LapNotFoundError, RaceRuleError
from drem_leaderboard.models import LapSource, Race, RaceConfig, RaceStatus, RankingMethod
from drem_leaderboard.race_clock import current_lap_ms, race_time_left_ms, running_time_ms
from drem_leaderboard.race_machine import ALLOWED, apply

from .builders import T0, make_race, run

pytestmark = pytest.mark.unit

S = RaceStatus


def _running(config: RaceConfig | None = None) -> Race:
    return run(make_race(config), (c.Start(), T0))


# --- start, pause, resume -----------------------------------------------------------------------------------------


def test_start_runs_the_race_clock_and_counts_down_the_race_time():
    race, outcome = apply(make_race(RaceConfig(race_time_min=2)), c.Start(), T0)

    assert (outcome.previous_status, outcome.status) == (S.READY, S.RUNNING)
    assert race.started_at_ms == T0
    assert running_time_ms(race, T0 + 15_000) == 15_000
    assert race_time_left_ms(race, T0 + 15_000) == 105_000


def test_pause_stops_both_clocks_and_resume_continues_them():
    race = run(_running(), (c.Pause(), T0 + 10_000))

    assert race.status is S.PAUSED
    assert running_time_ms(race, T0 + 60_000) == 10_000
    assert current_lap_ms(race, T0 + 60_000) == 10_000

    race = run(race, (c.Resume(), T0 + 60_000))
    assert running_time_ms(race, T0 + 65_000) == 15_000


def test_toggle_starts_pauses_and_resumes_like_drems_single_button():
    race = make_race()
    statuses = []
    for now in (T0, T0 + 1_000, T0 + 2_000):
        race, outcome = apply(race, c.Toggle(), now)
        statuses.append(outcome.status)

    assert statuses == [S.RUNNING, S.PAUSED, S.RUNNING]


# --- capturing laps -------------------------------------------------------------------------------------------------


def test_manual_lap_time_is_race_clock_since_the_lap_began_without_paused_time():
    race = run(
        _running(),
        (c.CaptureLap(), T0 + 12_000),
        (c.Pause(), T0 + 15_000),
        (c.Resume(), T0 + 45_000),
    )
    race, outcome = apply(race, c.CaptureLap(car="car-7"), T0 + 55_000)

    assert [lap.time_ms for lap in race.laps] == [12_000, 13_000]
    assert outcome.lap is not None and outcome.lap.lap_id == 1
    assert outcome.lap.source is LapSource.MANUAL
    assert outcome.lap.car == "car-7"
    assert outcome.lap.captured_at_ms == T0 + 55_000
    assert race.status is S.RUNNING


def test_dnf_records_an_invalid_lap_and_pauses_the_race():
    race, outcome = apply(_running(), c.DidNotFinish(), T0 + 8_000)

    assert outcome.lap is not None
    assert (outcome.lap.is_valid, outcome.lap.source, outcome.lap.time_ms) == (False, LapSource.DNF, 8_000)
    assert race.status is S.PAUSED
    assert running_time_ms(race, T0 + 30_000) == 8_000


def test_capture_while_paused_is_refused_with_a_clear_message():
    race = run(_running(), (c.Pause(), T0 + 1_000))

    with pytest.raises(IllegalCommandError, match="^cannot capture a lap: the race is paused$"):
        apply(race, c.CaptureLap(), T0 + 2_000)


# --- resets and validity --------------------------------------------------------------------------------------------


def test_resets_count_on_the_running_lap_and_start_at_zero_on_the_next():
    race = run(_running(), (c.AddReset(), T0 + 1_000), (c.AddReset(), T0 + 2_000), (c.CaptureLap(), T0 + 9_000))

    assert race.laps[0].resets == 2
    assert race.current_lap_resets == 0


def test_removing_a_reset_never_goes_below_zero_and_changes_nothing_at_zero():
    race = run(_running(), (c.AddReset(), T0 + 1_000), (c.RemoveReset(), T0 + 2_000))
    assert race.current_lap_resets == 0

    again, outcome = apply(race, c.RemoveReset(), T0 + 3_000)
    assert again.current_lap_resets == 0
    assert not outcome.changed
    assert again.version == race.version


@pytest.mark.parametrize(
    ("limit", "resets", "valid"),
    [(3, 3, True), (3, 4, False), (0, 0, True), (0, 1, False), (None, 10, True), (9999, 50, True)],
)
def test_a_lap_is_valid_only_when_its_resets_are_within_the_limit(limit, resets, valid):
    race = _running(RaceConfig(resets_per_lap=limit))
    race = run(race, *[(c.AddReset(), T0 + 100 * (i + 1)) for i in range(resets)])
    race, outcome = apply(race, c.CaptureLap(), T0 + 20_000)

    assert outcome.lap is not None and outcome.lap.is_valid is valid


def test_operator_can_flip_a_lap_valid_or_invalid_and_average_windows_follow():
    race = run(_running(), *[(c.CaptureLap(), T0 + 10_000 * (i + 1)) for i in range(3)])
    assert len(race.average_windows) == 1

    race, outcome = apply(race, c.SetLapValidity(lap_id=1, is_valid=False), T0 + 35_000)
    assert outcome.lap is not None and outcome.lap.is_valid is False
    assert race.average_windows == []

    race = run(race, (c.SetLapValidity(lap_id=1, is_valid=True), T0 + 36_000))
    assert [w.avg_ms for w in race.average_windows] == [10_000]


def test_a_dnf_lap_cannot_be_marked_valid_and_an_unknown_lap_is_reported():
    race = run(_running(), (c.DidNotFinish(), T0 + 5_000))

    with pytest.raises(IllegalCommandError, match="cannot mark lap 0 valid: it is a DNF"):
        apply(race, c.SetLapValidity(lap_id=0, is_valid=True), T0 + 6_000)
    with pytest.raises(LapNotFoundError, match="no lap 4"):
        apply(race, c.SetLapValidity(lap_id=4, is_valid=False), T0 + 6_000)


# --- undo false finish ----------------------------------------------------------------------------------------------


def test_undo_false_finish_removes_the_lap_and_gives_back_its_time_and_resets():
    race = run(
        _running(),
        (c.CaptureLap(), T0 + 10_000),
        (c.AddReset(), T0 + 11_000),
        (c.AddReset(), T0 + 12_000),
        (c.CaptureLap(), T0 + 14_000),  # the false finish: 4 s, 2 resets
        (c.AddReset(), T0 + 15_000),
    )
    race, outcome = apply(race, c.UndoFalseFinish(), T0 + 16_000)

    assert outcome.removed_lap is not None and outcome.removed_lap.time_ms == 4_000
    assert [lap.time_ms for lap in race.laps] == [10_000]
    assert current_lap_ms(race, T0 + 16_000) == 6_000
    assert race.current_lap_resets == 3
    race = run(race, (c.CaptureLap(), T0 + 20_000))
    assert (race.laps[1].time_ms, race.laps[1].resets) == (10_000, 3)


def test_undo_false_finish_without_laps_is_refused():
    with pytest.raises(IllegalCommandError, match="no lap has been recorded"):
        apply(_running(), c.UndoFalseFinish(), T0 + 1_000)


# --- race time expiry and lap targets -------------------------------------------------------------------------------


def test_expiry_lets_the_running_lap_finish_and_ends_the_race_at_that_capture():
    race = run(_running(RaceConfig(race_time_min=1)), (c.CaptureLap(), T0 + 50_000))

    race, tick = apply(race, c.Tick(), T0 + 61_000)
    assert tick.time_expired and race.status is S.RUNNING
    assert race_time_left_ms(race, T0 + 61_000) == 0

    race, outcome = apply(race, c.CaptureLap(), T0 + 70_000)
    assert outcome.lap is not None and outcome.lap.time_ms == 20_000 and outcome.lap.is_valid
    assert outcome.race_ended and race.status is S.OVER
    assert race.ended_at_ms == T0 + 70_000


def test_expiry_is_noticed_by_the_capture_itself_without_a_tick():
    race, outcome = apply(_running(RaceConfig(race_time_min=1)), c.CaptureLap(), T0 + 75_000)

    assert outcome.lap is not None and outcome.lap.time_ms == 75_000
    assert outcome.time_expired and outcome.race_ended


def test_a_dnf_after_expiry_ends_the_race():
    race = run(_running(RaceConfig(race_time_min=1)), (c.Tick(), T0 + 60_000))
    race, outcome = apply(race, c.DidNotFinish(), T0 + 62_000)

    assert race.status is S.OVER and outcome.race_ended


def test_paused_time_does_not_count_towards_expiry():
    race = run(_running(RaceConfig(race_time_min=1)), (c.Pause(), T0 + 30_000))
    race, outcome = apply(race, c.Tick(), T0 + 600_000)

    assert not outcome.time_expired
    assert race_time_left_ms(race, T0 + 600_000) == 30_000


def test_lap_count_race_ends_when_the_target_of_valid_laps_is_reached():
    config = RaceConfig(ranking_method=RankingMethod.LAP_COUNT, lap_count_target=2, resets_per_lap=0)
    race = run(
        _running(config),
        (c.CaptureLap(), T0 + 10_000),
        (c.AddReset(), T0 + 11_000),
        (c.CaptureLap(), T0 + 20_000),  # invalid: does not count towards the target
    )
    assert race.status is S.RUNNING

    race, outcome = apply(race, c.CaptureLap(), T0 + 30_000)
    assert outcome.race_ended and race.status is S.OVER


# --- ending, reopening, submitting ---------------------------------------------------------------------------------


def test_end_stops_the_clock_and_reopen_goes_back_to_paused():
    race, outcome = apply(_running(), c.End(), T0 + 40_000)
    assert outcome.race_ended and race.status is S.OVER
    assert running_time_ms(race, T0 + 90_000) == 40_000

    race, outcome = apply(race, c.Reopen(), T0 + 50_000)
    assert race.status is S.PAUSED and race.ended_at_ms is None
    race = run(race, (c.Resume(), T0 + 60_000), (c.CaptureLap(), T0 + 65_000))
    assert race.laps[-1].time_ms == 45_000


def test_reopening_a_race_that_never_started_goes_back_to_ready():
    race = run(make_race(), (c.End(), T0), (c.Reopen(), T0 + 1))

    assert race.status is S.READY


def test_submit_and_discard_are_final():
    over = run(_running(), (c.CaptureLap(), T0 + 9_000), (c.End(), T0 + 10_000))

    submitted = run(over, (c.Submit(), T0 + 11_000))
    assert submitted.status is S.SUBMITTED and submitted.submitted_at_ms == T0 + 11_000
    assert run(over, (c.Discard(), T0 + 11_000)).status is S.DISCARDED
    with pytest.raises(IllegalCommandError, match="^cannot reopen the race: the race has been submitted$"):
        apply(submitted, c.Reopen(), T0 + 12_000)


# --- the whole table ------------------------------------------------------------------------------------------------


def _race_in(status: RaceStatus) -> Race:
    with_lap = run(_running(), (c.CaptureLap(), T0 + 10_000))
    return {
        S.READY: make_race(),
        S.RUNNING: with_lap,
        S.PAUSED: run(with_lap, (c.Pause(), T0 + 11_000)),
        S.OVER: run(with_lap, (c.End(), T0 + 11_000)),
        S.SUBMITTED: run(with_lap, (c.End(), T0 + 11_000), (c.Submit(), T0 + 12_000)),
        S.DISCARDED: run(with_lap, (c.End(), T0 + 11_000), (c.Discard(), T0 + 12_000)),
    }[status]


_ONE_OF_EACH: list[c.RaceCommand] = [
    c.Start(), c.Pause(), c.Resume(), c.Toggle(), c.CaptureLap(), c.DidNotFinish(), c.AddReset(), c.RemoveReset(),
    c.UndoFalseFinish(), c.SetLapValidity(lap_id=0, is_valid=False), c.SelectCar(car="car-2"), c.Tick(), c.End(),
    c.Reopen(), c.Submit(), c.Discard(),
]  # fmt: skip


def test_every_command_kind_is_in_the_table():
    assert {type(command) for command in _ONE_OF_EACH} == set(ALLOWED)


@pytest.mark.parametrize("status", list(S))
@pytest.mark.parametrize("command", _ONE_OF_EACH, ids=lambda command: command.kind)
def test_each_command_is_accepted_exactly_in_its_allowed_states(status, command):
    race = _race_in(status)

    if status in ALLOWED[type(command)]:
        after, outcome = apply(race, command, T0 + 20_000)
        assert outcome.previous_status is status
        assert after.version == race.version + (1 if outcome.changed else 0)
    else:
        with pytest.raises(IllegalCommandError, match=r"^cannot .+: the race (is|has) .+$"):
            apply(race, command, T0 + 20_000)


# --- properties -----------------------------------------------------------------------------------------------------


def test_apply_never_changes_the_race_it_was_given():
    race = run(_running(), (c.CaptureLap(), T0 + 10_000))
    snapshot = race.model_dump()

    apply(race, c.UndoFalseFinish(), T0 + 11_000)
    apply(race, c.DidNotFinish(), T0 + 11_000)

    assert race.model_dump() == snapshot


@pytest.mark.parametrize("seed", range(25))
def test_random_operator_sessions_keep_the_race_consistent(seed):
    rng = random.Random(seed)
    race = make_race(RaceConfig(race_time_min=1, resets_per_lap=2))
    now = T0
    last_running = 0
    for _ in range(60):
        now += rng.choice([0, 250, 1_000, 4_000, 9_000])
        command = rng.choice(_ONE_OF_EACH)
        try:
            after, outcome = apply(race, command, now)
        except RaceRuleError:
            continue
        assert after.version == race.version + (1 if outcome.changed else 0)
        race = after
        assert [lap.lap_id for lap in race.laps] == list(range(len(race.laps)))
        assert race.current_lap_resets >= 0
        assert running_time_ms(race, now) >= last_running
        last_running = running_time_ms(race, now)
        assert sum(lap.time_ms for lap in race.laps) <= running_time_ms(race, now)
        for lap in race.laps:
            if lap.source is LapSource.DNF:
                assert not lap.is_valid
        if race.status in (S.SUBMITTED, S.DISCARDED):
            break


def test_commands_parse_from_json_bodies():
    assert c.parse_command({"kind": "capture_lap", "car": "car-1"}) == c.CaptureLap(car="car-1")
    assert c.parse_command({"kind": "set_lap_validity", "lap_id": 2, "is_valid": False}).lap_id == 2
    with pytest.raises(ValueError):
        c.parse_command({"kind": "warp_speed"})


def test_a_race_survives_a_json_round_trip_unchanged():
    race = run(_running(), (c.AddReset(), T0 + 1_000), (c.CaptureLap(), T0 + 10_000), (c.Pause(), T0 + 11_000))
    race = race.model_copy(update={"sensor_last_ts_ms": {17: 5_000}})

    assert Race.model_validate_json(race.model_dump_json()) == race
