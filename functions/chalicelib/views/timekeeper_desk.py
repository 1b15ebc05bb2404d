"""The timekeeper screen's view of a track, and the car side effects of driving a race from it.

The race itself lives on the server (`RaceService`, the track's live-race pointer), so every device that opens the
timekeeper for a track sees the same race. This module only adds what the screen needs around it: display strings,
whether the track's timer is connected (its heartbeat), the cars to choose from, and the tail light: the racer's
highlight colour when the race starts, white when it ends (queued as device commands to the race's car).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from pydantic import BaseModel, ConfigDict, Field

from chalicelib.core.errors import NotFound
from chalicelib.core.principals import User
from chalicelib.domain.devices import CommandRequest, CommandType, DeviceKind, DeviceService, DeviceView
from chalicelib.domain.events import Event, Track
from chalicelib.domain.races import CreateRaceInput, RaceService
from drem_leaderboard.commands import parse_command
from drem_leaderboard.models import RaceStatus
from drem_leaderboard.race_clock import current_lap_ms, race_time_left_ms

DEFAULT_TAIL_LIGHT = "#0000FF"
END_TAIL_LIGHT = "#FFFFFF"

# What the screen's buttons (and keyboard shortcuts) may send; each maps to one race command kind.
SCREEN_COMMANDS = frozenset({"toggle", "capture_lap", "dnf", "reset_add", "reset_remove", "undo_false_finish", "end",
                             "reopen", "submit", "discard", "set_lap_validity"})

_STATUS_TEXT = {RaceStatus.READY: "Ready to start", RaceStatus.RUNNING: "Running", RaceStatus.PAUSED: "Paused",
                RaceStatus.OVER: "Race over", RaceStatus.SUBMITTED: "Submitted", RaceStatus.DISCARDED: "Discarded"}
_TOGGLE_LABEL = {RaceStatus.READY: "Start", RaceStatus.RUNNING: "Pause", RaceStatus.PAUSED: "Resume"}
_RANKING_TEXT = {"BEST_LAP_TIME": "Ranked by fastest lap", "LAP_COUNT": "Ranked by most laps",
                 "BEST_AVERAGE_LAP_TIME_X_LAP": "Ranked by best average lap time of {window} laps"}


def clock_text(ms: int | None) -> str:
    """`M:SS.mmm` (what the screen and timekeeper.js both show)."""
    if ms is None:
        return "—"
    ms = max(0, int(ms))
    return f"{ms // 60_000}:{ms // 1000 % 60:02d}.{ms % 1000:03d}"


class LiveRacePointer(Protocol):
    def live_race_id(self, event_id: str, track_id: str) -> str | None: ...


class HighlightColours(Protocol):
    """What the desk shows of a racer's profile: their colour and the name they go by."""
    def highlight_colour(self, sub: str) -> str | None: ...
    def shown_name(self, sub: str, username: str) -> str: ...


class ScreenCommand(BaseModel):
    """A button press on the timekeeper screen (form fields)."""
    model_config = ConfigDict(extra="ignore")
    race_id: str = Field(min_length=1, max_length=64)
    kind: str
    lap_id: int | None = Field(default=None, ge=0)
    is_valid: bool | None = None


class LapRow(BaseModel):
    lap_id: int
    number: int
    time: str
    resets: int
    is_valid: bool
    dnf: bool
    source: str


class RaceScreen(BaseModel):
    race_id: str
    racer: str
    raced_by_proxy: bool
    car: str | None
    car_label: str
    status: str
    status_text: str
    toggle_label: str
    running: bool
    live: bool
    over: bool
    time_left_ms: int
    current_lap_ms: int
    time_left: str
    current_lap: str
    resets: str
    format_text: str
    fastest_lap: str
    fastest_average: str
    laps: list[LapRow]
    as_of_ms: int


class CarChoice(BaseModel):
    device_id: str
    label: str
    online: bool


class TimekeeperScreen(BaseModel):
    event_id: str
    event_name: str
    track_id: str
    track_title: str
    fleet_id: str | None
    timer_connected: bool
    timer_text: str
    cars: list[CarChoice]
    race: RaceScreen | None


class TimekeeperDesk:
    def __init__(self, races: RaceService, live: LiveRacePointer, devices: DeviceService,
                 colours: HighlightColours, clock_ms: Callable[[], int]) -> None:
        self._races = races
        self._live = live
        self._devices = devices
        self._colours = colours
        self._clock_ms = clock_ms

    def screen(self, event_id: str, track_id: str) -> TimekeeperScreen:
        event = self._races.event(event_id)
        track = event.track(track_id)
        devices = self._fleet_devices(track)
        race_id = self._live.live_race_id(event_id, track_id)
        race = self._race_screen(event, race_id, devices) if race_id else None
        timers = [d for d in devices if d.kind is DeviceKind.TIMER or (d.telemetry and d.telemetry.times_laps)]
        # A timing car (a sim car) times only the races it is the car of: not a live race on another car or none.
        if race is not None:
            timers = [d for d in timers if d.kind is DeviceKind.TIMER or d.device_id == race.car]
        connected = any(d.online for d in timers)
        return TimekeeperScreen(
            event_id=event_id, event_name=event.name, track_id=track_id,
            track_title=event.track_name(track_id), fleet_id=track.fleet_id,
            timer_connected=connected, timer_text=_timer_text(track, timers, connected, live=race is not None),
            cars=[CarChoice(device_id=d.device_id, label=_car_label(d), online=d.online)
                  for d in devices if d.kind is DeviceKind.CAR], race=race)

    def start_race(self, principal: User, event_id: str, data: CreateRaceInput) -> TimekeeperScreen:
        self._races.create_race(principal, event_id, data)
        return self.screen(event_id, data.track_id)

    def press(self, principal: User, event_id: str, track_id: str, press: ScreenCommand) -> TimekeeperScreen:
        if press.kind not in SCREEN_COMMANDS:
            raise NotFound(f"The timekeeper has no button {press.kind!r}.", field="kind")
        payload: dict[str, Any] = {"kind": press.kind}
        if press.kind == "set_lap_validity":
            payload.update(lap_id=press.lap_id, is_valid=press.is_valid)
        record = self._races.record(event_id, press.race_id)
        if press.kind in {"capture_lap", "dnf"} and record.race.car:
            payload["car"] = record.race.car
        view = self._races.apply_command(event_id, press.race_id, parse_command(payload), by=principal.username)
        self._tail_light(principal, view)
        return self.screen(event_id, track_id)

    def _tail_light(self, principal: User, view: dict[str, Any]) -> None:
        car, outcome = view.get("car"), view.get("outcome") or {}
        if not car or not outcome.get("changed"):
            return
        started = outcome["previous_status"] == RaceStatus.READY and outcome["status"] == RaceStatus.RUNNING
        ended = outcome["status"] == RaceStatus.OVER and outcome["previous_status"] != RaceStatus.OVER
        if started:
            colour = self._colours.highlight_colour(view["racer"]["sub"]) or DEFAULT_TAIL_LIGHT
        elif ended:
            colour = END_TAIL_LIGHT
        else:
            return
        try:
            self._devices.queue_command(principal, car, CommandRequest(type=CommandType.SET_TAIL_LIGHT,
                                                                       colour=colour))
        except NotFound:
            pass  # the car was deregistered mid-race; the race itself goes on

    def _fleet_devices(self, track: Track) -> list[DeviceView]:
        if not track.fleet_id:
            return self._devices.list_devices()
        return self._devices.list_devices(fleet_id=track.fleet_id)

    def _race_screen(self, event: Event, race_id: str, devices: list[DeviceView]) -> RaceScreen:
        record = self._races.record(event.event_id, race_id)
        race, now = record.race, self._clock_ms()
        time_left, current_lap = race_time_left_ms(race, now), current_lap_ms(race, now)
        config = race.config
        allowed = "∞" if config.resets_per_lap is None else str(config.resets_per_lap)
        labels = {d.device_id: _car_label(d) for d in devices}
        fastest = race.fastest_valid_lap
        average = race.fastest_average
        return RaceScreen(
            race_id=race.race_id, racer=self._colours.shown_name(race.racer.sub, race.racer.username),
            raced_by_proxy=race.raced_by_proxy, car=race.car,
            car_label=labels.get(race.car or "", race.car or "No car"), status=race.status.value,
            status_text=_STATUS_TEXT[race.status], toggle_label=_TOGGLE_LABEL.get(race.status, "Start"),
            running=race.status is RaceStatus.RUNNING,
            live=race.status in {RaceStatus.RUNNING, RaceStatus.PAUSED}, over=race.status is RaceStatus.OVER,
            time_left_ms=time_left, current_lap_ms=current_lap, time_left=clock_text(time_left),
            current_lap=clock_text(current_lap), resets=f"{race.current_lap_resets} / {allowed}",
            format_text=_RANKING_TEXT[config.ranking_method.value].format(window=config.average_window)
            + f" · {config.race_time_min} min",
            fastest_lap=clock_text(fastest.time_ms) if fastest else "—",
            fastest_average=clock_text(average.avg_ms) if average else "—",
            laps=[LapRow(lap_id=lap.lap_id, number=lap.lap_id + 1, time=clock_text(lap.time_ms), resets=lap.resets,
                         is_valid=lap.is_valid, dnf=lap.source.value == "dnf", source=lap.source.value)
                  for lap in race.laps],
            as_of_ms=now)


def _car_label(device: DeviceView) -> str:
    return f"{device.hostname} ({'online' if device.online else 'offline'})"


def _timer_text(track: Track, timers: list[DeviceView], connected: bool, *, live: bool) -> str:
    if not track.fleet_id:
        return "No fleet on this track: capture laps by hand"
    if not timers:
        if live:
            return "No timer for this race (a sim car times only the races it drives): capture laps by hand"
        return "No timer in this track's fleet: capture laps by hand"
    if connected:
        timing_cars = [d.hostname for d in timers if d.kind is DeviceKind.CAR and d.online]
        if timing_cars and len(timing_cars) == sum(1 for d in timers if d.online):
            return f"Timed by sim car {', '.join(timing_cars)}" + ("" if live else " when it drives the race")
        return "Timer connected"
    return "Timer offline: capture laps by hand"
