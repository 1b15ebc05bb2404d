"""The race service: races live on the server, every change is stored the moment it happens, and the track's
leaderboard and overlay are rebuilt right after.

- A race freezes a copy of its event's race config when it is created. Each track has at most one live race (a
  `LIVE#{trackId}` pointer written in the same transaction as the race); submit and discard clear it.
- Max runs per racer (`RaceConfig.max_runs_per_racer`) counts the racer's races at the event that were not
  discarded; an operator/admin may override it, and the override is recorded on the race.
- Commands go through `drem_leaderboard.race_machine.apply` with the server clock. Writes are conditional on the
  race's version; on a clash the service reloads and applies again (a few times) before answering 409.
- The leaderboard follows the race live: a racer's row is their submitted races plus the live race once it has a lap
  (counted as if submitted). Discarding the live race takes its laps off the board again.
"""
from __future__ import annotations

import uuid
from collections.abc import Callable, Iterable
from typing import Any, Protocol, TypeVar

from pydantic import BaseModel, ConfigDict, Field, model_validator

from chalicelib.auth.principals import Principal, Role, User
from chalicelib.domain.errors import Conflict, Forbidden, InvalidInput, NotFound
from chalicelib.domain.events import Event
from chalicelib.domain.leaderboards import BoardRow, LeaderboardPublisher
from chalicelib.domain.ownership import require_owner_or_role
from chalicelib.domain.race_export import CsvFile, ExportKind, export_csv
from drem_leaderboard import race_machine
from drem_leaderboard.commands import RaceCommand
from drem_leaderboard.errors import LapNotFoundError, RaceRuleError
from drem_leaderboard.models import TERMINAL_STATUSES, LapSource, Race, RaceStatus, Racer, new_race
from drem_leaderboard.race_clock import current_lap_ms, race_time_left_ms
from drem_leaderboard.ranking import Leaderboard, RacerProfile
from drem_leaderboard.summary import summarise_racer

WRITE_ATTEMPTS = 3
RACE_READERS = frozenset({Role.ADMIN, Role.OPERATOR, Role.COMMENTATOR})
T = TypeVar("T")


class StaleRace(Exception):
    """The race changed since it was read (another command or strip event won); reload and apply again."""


class MaxRunsOverride(BaseModel):
    model_config = ConfigDict(frozen=True)
    by: str
    runs_used: int
    max_runs: int


class RaceRecord(BaseModel):
    """What is stored per race: the pure race plus who created it and whether the max-runs rule was overridden."""
    model_config = ConfigDict(frozen=True)
    race: Race
    created_by: str
    max_runs_override: MaxRunsOverride | None = None


class CreateRaceInput(BaseModel):
    model_config = ConfigDict(extra="forbid")
    track_id: str = Field(min_length=1, max_length=32)
    racer_username: str = Field(min_length=1, max_length=128)
    raced_by_proxy: bool = False
    car: str | None = Field(default=None, max_length=128)
    override_max_runs: bool = False


class LapEdit(BaseModel):
    """Race admin's inline lap edit; fields left out keep their value."""
    model_config = ConfigDict(extra="forbid")
    time_ms: int | None = Field(default=None, ge=0, le=3_600_000)
    resets: int | None = Field(default=None, ge=0, le=1000)
    is_valid: bool | None = None

    @model_validator(mode="after")
    def _something(self) -> LapEdit:
        if self.time_ms is None and self.resets is None and self.is_valid is None:
            raise ValueError("give at least one of time_ms, resets, is_valid")
        return self


# --- ports ---------------------------------------------------------------------------------------------------------


class RaceRepository(Protocol):
    def get(self, event_id: str, race_id: str) -> RaceRecord | None: ...
    def live_race_id(self, event_id: str, track_id: str) -> str | None: ...
    def list_event(self, event_id: str, *, track_id: str | None = None,
                   racer_sub: str | None = None) -> list[RaceRecord]: ...
    def list_racer(self, racer_sub: str) -> list[RaceRecord]: ...
    def create_live(self, record: RaceRecord) -> None: ...
    def save(self, record: RaceRecord, expected_version: int) -> None: ...
    def finalise(self, record: RaceRecord, expected_version: int) -> None: ...
    def delete(self, event_id: str, race_id: str) -> None: ...


class EventSource(Protocol):
    def get(self, event_id: str) -> Event | None: ...


class RacerDirectory(Protocol):
    def get_user(self, username: str) -> Any: ...  # has .sub and .username (raises NotFound)


class ProfileSource(Protocol):
    def racer_profile(self, sub: str, fallback_username: str) -> RacerProfile: ...


# --- helpers -------------------------------------------------------------------------------------------------------


def counts_on_board(race: Race) -> Race | None:
    """The race as the summary should see it: submitted races as they are, the live race (once it has a lap) as
    if it were submitted, everything else not at all."""
    if race.status is RaceStatus.SUBMITTED:
        return race
    if race.status is RaceStatus.DISCARDED or not race.laps:
        return None
    return race.model_copy(update={"status": RaceStatus.SUBMITTED,
                                   "submitted_at_ms": race.ended_at_ms or race.created_at_ms})


def race_view(record: RaceRecord, now_ms: int, **extra: Any) -> dict[str, Any]:
    race = record.race
    return {**race.model_dump(mode="json"), "max_runs_override": (
        record.max_runs_override.model_dump() if record.max_runs_override else None),
        "as_of_ms": now_ms, "time_left_ms": race_time_left_ms(race, now_ms),
        "current_lap_ms": current_lap_ms(race, now_ms), **extra}


def with_retries(attempt: Callable[[], T]) -> T:
    for _ in range(WRITE_ATTEMPTS):
        try:
            return attempt()
        except StaleRace:
            continue
    raise Conflict("The race was changed by someone else at the same moment; try again.")


def rule_error(exc: RaceRuleError) -> Exception:
    return NotFound(exc.message, field="lap_id") if isinstance(exc, LapNotFoundError) else Conflict(exc.message)


class RaceService:
    def __init__(self, races: RaceRepository, events: EventSource, racers: RacerDirectory, profiles: ProfileSource,
                 boards: LeaderboardPublisher, clock_ms: Callable[[], int]) -> None:
        self._races = races
        self._events = events
        self._racers = racers
        self._profiles = profiles
        self._boards = boards
        self.clock_ms = clock_ms

    # --- queries -----------------------------------------------------------------------------------------------

    def event(self, event_id: str) -> Event:
        event = self._events.get(event_id)
        if event is None:
            raise NotFound(f"There is no event {event_id}.", field="event_id")
        return event

    def record(self, event_id: str, race_id: str) -> RaceRecord:
        record = self._races.get(event_id, race_id)
        if record is None:
            raise NotFound(f"Event {event_id} has no race {race_id}.", field="race_id")
        return record

    def get_race(self, principal: Principal, event_id: str, race_id: str) -> dict[str, Any]:
        record = self.record(event_id, race_id)
        require_owner_or_role(principal, record.race.racer.sub, RACE_READERS)
        return race_view(record, self.clock_ms())

    def list_races(self, event_id: str, track_id: str | None) -> list[dict[str, Any]]:
        event = self.event(event_id)
        if track_id is not None:
            event.track(track_id)
        records = self._races.list_event(event_id, track_id=track_id)
        return [_listing(r) for r in sorted(records, key=lambda r: (r.race.created_at_ms, r.race.race_id))]

    def my_races(self, principal: User) -> list[dict[str, Any]]:
        records = self._races.list_racer(principal.sub)
        return [_listing(r) for r in sorted(records, key=lambda r: (r.race.created_at_ms, r.race.race_id))]

    # --- race lifecycle ----------------------------------------------------------------------------------------

    def create_race(self, principal: User, event_id: str, data: CreateRaceInput) -> dict[str, Any]:
        event = self.event(event_id)
        event.track(data.track_id)
        racer = self._racers.get_user(data.racer_username)
        config = event.race_config
        used = sum(1 for r in self._races.list_event(event_id, racer_sub=racer.sub)
                   if r.race.status is not RaceStatus.DISCARDED)
        override = None
        if config.runs_left(used) == 0:
            if not data.override_max_runs:
                raise Conflict(f"{racer.username} has used {used} of {config.max_runs_per_racer} runs at this event.",
                               field="override_max_runs")
            if not principal.roles & {Role.ADMIN, Role.OPERATOR}:
                raise Forbidden("Only an operator or admin may override the maximum number of runs.")
            override = MaxRunsOverride(by=principal.username, runs_used=used, max_runs=config.max_runs_per_racer or 0)
        now = self.clock_ms()
        race = new_race(race_id=uuid.uuid4().hex, event_id=event_id, track_id=data.track_id,
                        racer=Racer(sub=racer.sub, username=racer.username), config=config, now_ms=now,
                        raced_by_proxy=data.raced_by_proxy, car=data.car)
        record = RaceRecord(race=race, created_by=principal.id, max_runs_override=override)
        self._races.create_live(record)
        self.publish(event, race, now)
        return race_view(record, now, runs_used=used + 1, max_runs=config.max_runs_per_racer)

    def apply_command(self, event_id: str, race_id: str, command: RaceCommand) -> dict[str, Any]:
        event = self.event(event_id)

        def attempt() -> tuple[RaceRecord, race_machine.TransitionOutcome, int]:
            record = self.record(event_id, race_id)
            now = self.clock_ms()
            try:
                after, outcome = race_machine.apply(record.race, command, now)
            except RaceRuleError as exc:
                raise rule_error(exc) from exc
            updated = record.model_copy(update={"race": after})
            if outcome.changed:
                self.store(updated, record.race.version)
            return updated, outcome, now

        record, outcome, now = with_retries(attempt)
        if outcome.changed:
            self.publish(event, record.race, now)
        return race_view(record, now, outcome=outcome.model_dump(mode="json"))

    def store(self, record: RaceRecord, expected_version: int) -> None:
        if record.race.status in TERMINAL_STATUSES:
            self._races.finalise(record, expected_version)
        else:
            self._races.save(record, expected_version)

    # --- race admin --------------------------------------------------------------------------------------------

    def edit_lap(self, event_id: str, race_id: str, lap_id: int, edit: LapEdit) -> dict[str, Any]:
        event = self.event(event_id)

        def attempt() -> RaceRecord:
            record = self.record(event_id, race_id)
            race = record.race
            index = next((i for i, lap in enumerate(race.laps) if lap.lap_id == lap_id), None)
            if index is None:
                raise NotFound(f"Race {race_id} has no lap {lap_id}.", field="lap_id")
            lap = race.laps[index]
            if edit.is_valid and lap.source is LapSource.DNF:
                raise InvalidInput(f"Lap {lap_id} is a DNF; it cannot be valid.", field="is_valid")
            changes = {k: v for k, v in edit.model_dump().items() if v is not None}
            laps = (*race.laps[:index], lap.model_copy(update=changes), *race.laps[index + 1:])
            updated = record.model_copy(update={"race": race.model_copy(
                update={"laps": laps, "version": race.version + 1})})
            self._races.save(updated, race.version)
            return updated

        record = with_retries(attempt)
        self.publish(event, record.race, self.clock_ms())
        return race_view(record, self.clock_ms())

    def delete_race(self, event_id: str, race_id: str) -> None:
        event = self.event(event_id)
        record = self.record(event_id, race_id)
        if record.race.status not in TERMINAL_STATUSES:
            raise Conflict(f"Race {race_id} is live on track {record.race.track_id}; end and discard it instead.")
        self._races.delete(event_id, race_id)
        self.refresh_racer_board(event, record.race.track_id, record.race.racer, self.clock_ms())

    def recompute(self, event_id: str) -> dict[str, Any]:
        event = self.event(event_id)
        grouped: dict[tuple[str, str], list[Race]] = {}
        for record in self._races.list_event(event_id):
            grouped.setdefault((record.race.track_id, record.race.racer.sub), []).append(record.race)
        rows_by_track: dict[str, list[BoardRow]] = {}
        for (track_id, _sub), races in sorted(grouped.items()):
            row = self._row(races)
            if row is not None:
                rows_by_track.setdefault(track_id, []).append(row)
        boards = self._boards.rebuild(event_id, rows_by_track, event.race_config.ranking_method,
                                     [t.track_id or "" for t in event.tracks])
        return {"event_id": event_id, "boards": {track: {"version": b.version, "entries": len(b.entries)}
                                                 for track, b in boards.items()}}

    def export(self, event_id: str, file_name: str) -> CsvFile:
        kinds = {f"{kind.value}.csv": kind for kind in ExportKind}
        if file_name not in kinds:
            raise InvalidInput("Export laps.csv or summary.csv.", field="file_name")
        event = self.event(event_id)
        races = [r.race for r in self._races.list_event(event_id)]
        return export_csv(event.name, races, kinds[file_name], self.clock_ms())

    # --- publishing --------------------------------------------------------------------------------------------

    def publish(self, event: Event, race: Race, now_ms: int) -> None:
        """After a change: the racer's board row (their submitted races + this one if live), then the overlay."""
        board = self.refresh_racer_board(event, race.track_id, race.racer, now_ms, changed=race)
        name = self._profiles.racer_profile(race.racer.sub, race.racer.username).username or race.racer.username
        self._boards.publish_overlay(race, now_ms, board, name)

    def refresh_racer_board(self, event: Event, track_id: str, racer: Racer, now_ms: int,
                            changed: Race | None = None) -> Leaderboard:
        races = [r.race for r in self._races.list_event(event.event_id, track_id=track_id, racer_sub=racer.sub)]
        if changed is not None:  # the race just written wins over any older copy the listing returned
            races = [r for r in races if r.race_id != changed.race_id] + [changed]
        return self._boards.refresh_racer(event.event_id, track_id, racer.sub, self._row(races),
                                          event.race_config.ranking_method,
                                          all_tracks=[t.track_id or "" for t in event.tracks])

    def refresh_racer_everywhere(self, racer_sub: str) -> int:
        """After a profile change (colour, country, name): rebuild the racer's row on every board they are on, so
        the boards and overlays show the new colour; returns how many boards were refreshed."""
        now = self.clock_ms()
        seen: dict[tuple[str, str], Racer] = {}
        for record in self._races.list_racer(racer_sub):
            seen.setdefault((record.race.event_id, record.race.track_id), record.race.racer)
        refreshed = 0
        for (event_id, track_id), racer in sorted(seen.items(), key=lambda item: item[0]):
            try:
                event = self.event(event_id)
            except NotFound:  # an event deleted since: nothing to show
                continue
            self.refresh_racer_board(event, track_id, racer, now)
            refreshed += 1
        return refreshed

    def _row(self, races: Iterable[Race]) -> BoardRow | None:
        summary = summarise_racer(c for r in races if (c := counts_on_board(r)) is not None)
        if summary is None:
            return None
        return BoardRow(summary=summary, profile=self._profiles.racer_profile(summary.racer_sub, summary.username))


def _listing(record: RaceRecord) -> dict[str, Any]:
    race = record.race
    return {"race_id": race.race_id, "event_id": race.event_id, "track_id": race.track_id,
            "racer_sub": race.racer.sub, "username": race.racer.username, "raced_by_proxy": race.raced_by_proxy,
            "status": race.status.value, "laps": len(race.laps), "valid_laps": len(race.valid_laps),
            "fastest_lap_ms": race.fastest_valid_lap.time_ms if race.fastest_valid_lap else None,
            "created_at_ms": race.created_at_ms, "submitted_at_ms": race.submitted_at_ms, "version": race.version,
            "max_runs_override": record.max_runs_override.model_dump() if record.max_runs_override else None}
