"""The server-side race state machine: ``apply(race, command, now_ms) -> (race, outcome)``.

READY -> RUNNING <-> PAUSED -> OVER -> SUBMITTED | DISCARDED, with OVER -> PAUSED (reopen) like DREM's "Cancel".
Every function takes the server clock explicitly and returns a new race; nothing reads the time or does I/O.
The helpers ``begin_running``, ``resume_running`` and ``record_lap`` are shared with the timing-strip rules.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from pydantic import BaseModel, ConfigDict

from drem_leaderboard import commands as c
from drem_leaderboard.errors import IllegalCommandError, LapNotFoundError
from drem_leaderboard.models import Lap, LapSource, Race, RaceConfig, RaceStatus, RankingMethod
from drem_leaderboard.race_clock import current_lap_ms, running_time_ms, time_is_up

S = RaceStatus
_ANY = frozenset(RaceStatus)
_LIVE = frozenset({S.RUNNING, S.PAUSED})

# Which statuses accept which command; the docs table and the exhaustive transition test read this.
ALLOWED: dict[type[BaseModel], frozenset[RaceStatus]] = {
    c.Start: frozenset({S.READY}),
    c.Pause: frozenset({S.RUNNING}),
    c.Resume: frozenset({S.PAUSED}),
    c.Toggle: frozenset({S.READY, S.RUNNING, S.PAUSED}),
    c.CaptureLap: frozenset({S.RUNNING}),
    c.DidNotFinish: frozenset({S.RUNNING}),
    c.AddReset: _LIVE,
    c.RemoveReset: _LIVE,
    c.UndoFalseFinish: _LIVE,
    c.SetLapValidity: frozenset({S.RUNNING, S.PAUSED, S.OVER}),
    c.SelectCar: frozenset({S.READY, S.RUNNING, S.PAUSED}),
    c.Tick: _ANY,
    c.End: frozenset({S.READY, S.RUNNING, S.PAUSED}),
    c.Reopen: frozenset({S.OVER}),
    c.Submit: frozenset({S.OVER}),
    c.Discard: frozenset({S.OVER}),
}

_ACTIONS: dict[type[BaseModel], str] = {
    c.Start: "start the race",
    c.Pause: "pause the race",
    c.Resume: "resume the race",
    c.Toggle: "start, pause or resume the race",
    c.CaptureLap: "capture a lap",
    c.DidNotFinish: "record a DNF",
    c.AddReset: "add a car reset",
    c.RemoveReset: "remove a car reset",
    c.UndoFalseFinish: "undo a false finish",
    c.SetLapValidity: "change a lap's validity",
    c.SelectCar: "change the car",
    c.Tick: "check the race clock",
    c.End: "end the race",
    c.Reopen: "reopen the race",
    c.Submit: "submit the race",
    c.Discard: "discard the race",
}

_STATE_PHRASES = {
    S.READY: "the race has not started",
    S.RUNNING: "the race is running",
    S.PAUSED: "the race is paused",
    S.OVER: "the race is over",
    S.SUBMITTED: "the race has been submitted",
    S.DISCARDED: "the race has been discarded",
}


class TransitionOutcome(BaseModel):
    """What one command did, for the caller to publish (overlay status, car stop, leaderboard refresh)."""

    model_config = ConfigDict(frozen=True)

    command: str
    previous_status: RaceStatus
    status: RaceStatus
    lap: Lap | None = None
    removed_lap: Lap | None = None
    race_ended: bool = False
    time_expired: bool = False
    changed: bool = False


@dataclass(frozen=True)
class _Step:
    race: Race
    lap: Lap | None = None
    removed_lap: Lap | None = None


def illegal(action: str, status: RaceStatus) -> IllegalCommandError:
    return IllegalCommandError(f"cannot {action}: {_STATE_PHRASES[status]}")


def apply(race: Race, command: c.RaceCommand, now_ms: int) -> tuple[Race, TransitionOutcome]:
    """Apply one command at server time ``now_ms``; raises a RaceRuleError subclass when the rules forbid it."""
    kind = type(command)
    if race.status not in ALLOWED[kind]:
        raise illegal(_ACTIONS[kind], race.status)
    step = _HANDLERS[kind](note_expiry(race, now_ms), command, now_ms)
    return _finish(race, step, command.kind)


def _finish(before: Race, step: _Step, command_name: str) -> tuple[Race, TransitionOutcome]:
    after = step.race
    changed = after != before
    if changed:
        after = after.model_copy(update={"version": before.version + 1})
    return after, TransitionOutcome(
        command=command_name,
        previous_status=before.status,
        status=after.status,
        lap=step.lap,
        removed_lap=step.removed_lap,
        race_ended=before.status is not S.OVER and after.status is S.OVER,
        time_expired=after.time_expired,
        changed=changed,
    )


# --- shared transitions -------------------------------------------------------------------------------------------


def note_expiry(race: Race, now_ms: int) -> Race:
    """Flag the race time as expired once the clock says so. The race itself keeps running until the next lap."""
    if not race.time_expired and time_is_up(race, now_ms):
        return race.model_copy(update={"time_expired": True})
    return race


def begin_running(race: Race, now_ms: int) -> Race:
    return race.model_copy(
        update={
            "status": S.RUNNING,
            "started_at_ms": now_ms if race.started_at_ms is None else race.started_at_ms,
            "running_since_ms": now_ms,
            "paused_at_ms": None,
        }
    )


def resume_running(race: Race, now_ms: int) -> Race:
    """Resume from PAUSED. The device clock kept going while the race clock stood still, so the lap's seed moves
    forward by the pause: a timer lap never includes paused time."""
    seed = race.lap_seed_ts_ms
    if seed is not None and race.paused_at_ms is not None:
        seed += max(0, now_ms - race.paused_at_ms)
    resumed = begin_running(race, now_ms)
    return resumed.model_copy(update={"lap_seed_ts_ms": seed})


def pause_running(race: Race, now_ms: int) -> Race:
    return race.model_copy(
        update={
            "status": S.PAUSED,
            "running_ms": running_time_ms(race, now_ms),
            "running_since_ms": None,
            "paused_at_ms": now_ms,
        }
    )


def end_race(race: Race, now_ms: int) -> Race:
    stopped = pause_running(race, now_ms) if race.status is S.RUNNING else race
    return stopped.model_copy(
        update={
            "status": S.OVER,
            "ended_at_ms": now_ms,
            "paused_at_ms": now_ms if stopped.paused_at_ms is None else stopped.paused_at_ms,
        }
    )


def lap_is_valid(source: LapSource, resets: int, config: RaceConfig) -> bool:
    if source is LapSource.DNF:
        return False
    return config.resets_per_lap is None or resets <= config.resets_per_lap


def record_lap(
    race: Race,
    now_ms: int,
    *,
    time_ms: int,
    source: LapSource,
    device_ts_ms: int | None = None,
    car: str | None = None,
) -> tuple[Race, Lap]:
    """Append a lap and start the next one; then a DNF pauses, and expiry or a reached lap target end the race."""
    lap = Lap(
        lap_id=len(race.laps),
        time_ms=max(0, time_ms),
        resets=race.current_lap_resets,
        is_valid=lap_is_valid(source, race.current_lap_resets, race.config),
        source=source,
        car=car if car is not None else race.car,
        device_ts_ms=device_ts_ms,
        captured_at_ms=now_ms,
    )
    if device_ts_ms is not None:
        seed: int | None = device_ts_ms
    else:
        # Keep the seed meaning "device time at which the current lap began" for laps the timer did not see.
        seed = None if race.lap_seed_ts_ms is None else race.lap_seed_ts_ms + lap.time_ms
    after = race.model_copy(
        update={
            "laps": (*race.laps, lap),
            "current_lap_resets": 0,
            "lap_started_running_ms": running_time_ms(race, now_ms),
            "lap_seed_ts_ms": seed,
        }
    )
    if source is LapSource.DNF:
        after = pause_running(after, now_ms)
    if after.time_expired or _lap_target_reached(after):
        after = end_race(after, now_ms)
    return after, lap


def _lap_target_reached(race: Race) -> bool:
    target = race.config.lap_count_target
    if race.config.ranking_method is not RankingMethod.LAP_COUNT or target is None:
        return False
    return len(race.valid_laps) >= target


# --- command handlers -----------------------------------------------------------------------------------------------


def _start(race: Race, _: c.Start, now_ms: int) -> _Step:
    return _Step(begin_running(race, now_ms))


def _pause(race: Race, _: c.Pause, now_ms: int) -> _Step:
    return _Step(pause_running(race, now_ms))


def _resume(race: Race, _: c.Resume, now_ms: int) -> _Step:
    return _Step(resume_running(race, now_ms))


def _toggle(race: Race, _: c.Toggle, now_ms: int) -> _Step:
    if race.status is S.READY:
        return _Step(begin_running(race, now_ms))
    if race.status is S.RUNNING:
        return _Step(pause_running(race, now_ms))
    return _Step(resume_running(race, now_ms))


def _capture(race: Race, command: c.CaptureLap, now_ms: int) -> _Step:
    after, lap = record_lap(
        race, now_ms, time_ms=current_lap_ms(race, now_ms), source=LapSource.MANUAL, car=command.car
    )
    return _Step(after, lap=lap)


def _dnf(race: Race, command: c.DidNotFinish, now_ms: int) -> _Step:
    after, lap = record_lap(race, now_ms, time_ms=current_lap_ms(race, now_ms), source=LapSource.DNF, car=command.car)
    return _Step(after, lap=lap)


def _add_reset(race: Race, _: c.AddReset, now_ms: int) -> _Step:
    return _Step(race.model_copy(update={"current_lap_resets": race.current_lap_resets + 1}))


def _remove_reset(race: Race, _: c.RemoveReset, now_ms: int) -> _Step:
    return _Step(race.model_copy(update={"current_lap_resets": max(0, race.current_lap_resets - 1)}))


def _undo_false_finish(race: Race, _: c.UndoFalseFinish, now_ms: int) -> _Step:
    if not race.laps:
        raise IllegalCommandError("cannot undo a false finish: no lap has been recorded")
    removed = race.laps[-1]
    if removed.device_ts_ms is not None:
        seed: int | None = removed.device_ts_ms - removed.time_ms
    else:
        seed = None if race.lap_seed_ts_ms is None else race.lap_seed_ts_ms - removed.time_ms
    after = race.model_copy(
        update={
            "laps": race.laps[:-1],
            "current_lap_resets": race.current_lap_resets + removed.resets,
            "lap_started_running_ms": max(0, race.lap_started_running_ms - removed.time_ms),
            "lap_seed_ts_ms": seed,
        }
    )
    return _Step(after, removed_lap=removed)


def _set_validity(race: Race, command: c.SetLapValidity, now_ms: int) -> _Step:
    index = next((i for i, lap in enumerate(race.laps) if lap.lap_id == command.lap_id), None)
    if index is None:
        raise LapNotFoundError(f"cannot change a lap's validity: the race has no lap {command.lap_id}")
    lap = race.laps[index]
    if command.is_valid and lap.source is LapSource.DNF:
        raise IllegalCommandError(f"cannot mark lap {lap.lap_id} valid: it is a DNF")
    changed = lap.model_copy(update={"is_valid": command.is_valid})
    laps = (*race.laps[:index], changed, *race.laps[index + 1 :])
    return _Step(race.model_copy(update={"laps": laps}), lap=changed)


def _select_car(race: Race, command: c.SelectCar, now_ms: int) -> _Step:
    return _Step(race.model_copy(update={"car": command.car}))


def _tick(race: Race, _: c.Tick, now_ms: int) -> _Step:
    return _Step(race)


def _end(race: Race, _: c.End, now_ms: int) -> _Step:
    return _Step(end_race(race, now_ms))


def _reopen(race: Race, _: c.Reopen, now_ms: int) -> _Step:
    status = S.PAUSED if race.started_at_ms is not None else S.READY
    return _Step(race.model_copy(update={"status": status, "ended_at_ms": None}))


def _submit(race: Race, _: c.Submit, now_ms: int) -> _Step:
    return _Step(race.model_copy(update={"status": S.SUBMITTED, "submitted_at_ms": now_ms}))


def _discard(race: Race, _: c.Discard, now_ms: int) -> _Step:
    return _Step(race.model_copy(update={"status": S.DISCARDED}))


# Each handler takes (race, its own command type, now_ms); one dict type cannot say that per entry, hence `...`.
_HANDLERS: dict[type[BaseModel], Callable[..., _Step]] = {
    c.Start: _start,
    c.Pause: _pause,
    c.Resume: _resume,
    c.Toggle: _toggle,
    c.CaptureLap: _capture,
    c.DidNotFinish: _dnf,
    c.AddReset: _add_reset,
    c.RemoveReset: _remove_reset,
    c.UndoFalseFinish: _undo_false_finish,
    c.SetLapValidity: _set_validity,
    c.SelectCar: _select_car,
    c.Tick: _tick,
    c.End: _end,
    c.Reopen: _reopen,
    c.Submit: _submit,
    c.Discard: _discard,
}
