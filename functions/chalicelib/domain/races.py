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
- Boards are derived state, repaired by construction: every race write stores a `PublishIntent` for the racer's row
  in the same transaction, and the intent is deleted only after the row and overlay are rebuilt. If the process or
  storage dies in between, the intent is still there, and `complete_pending_publishes` (run by every race write
  after its own publish, by a timer's retry, and by the app server's sweeper) rebuilds the row from what the races
  say.
"""
from __future__ import annotations

import json
import logging
import uuid
from collections.abc import Callable, Iterable
from typing import Any, Protocol

from pydantic import BaseModel, ConfigDict, Field, model_validator

from chalicelib.core.errors import Conflict, DremError, Forbidden, InvalidInput, NotFound
from chalicelib.core.principals import Principal, Role, User
from chalicelib.domain.audit import AuditLog, AuditTrail, lap_state, standings
from chalicelib.domain.events import Event
from chalicelib.domain.leaderboards import BoardRow, LeaderboardPublisher
from chalicelib.domain.ownership import require_owner_or_role
from chalicelib.domain.race_writes import with_retries
from chalicelib.formats.race_export import CsvFile, ExportKind, export_csv
from drem_leaderboard import race_machine
from drem_leaderboard.commands import RaceCommand, SetLapValidity
from drem_leaderboard.errors import LapNotFoundError, RaceRuleError
from drem_leaderboard.models import TERMINAL_STATUSES, LapSource, Race, Racer, RaceStatus, new_race
from drem_leaderboard.names import told_apart
from drem_leaderboard.race_clock import current_lap_ms, race_time_left_ms
from drem_leaderboard.ranking import COMBINED_TRACK_ID, Leaderboard, RacerProfile
from drem_leaderboard.summary import summarise_racer

# A race write finishes other writes' intents only once they are this old: a younger one most likely belongs to a
# request that is publishing it right now, and rebuilding it too would only add load.
STALE_INTENT_MS = 2_000
log = logging.getLogger("drem.races")
RACE_READERS = frozenset({Role.ADMIN, Role.OPERATOR, Role.COMMENTATOR})


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
    # The device whose crossing first counted for this race; only it may post further crossings (a lap is the
    # difference of two timestamps of ONE device clock, and another device must not be able to lap this race).
    timed_by: str | None = None


class PublishIntent(BaseModel):
    """A racer's board row (and the track's overlay) still to rebuild after a race write. Stored with the write;
    `token` names the write, so finishing an older intent never drops a newer one."""
    model_config = ConfigDict(frozen=True)
    event_id: str
    track_id: str
    racer_sub: str
    racer_username: str
    race_id: str
    token: str

    @classmethod
    def of(cls, race: Race, *, deleted: bool = False) -> PublishIntent:
        return cls(event_id=race.event_id, track_id=race.track_id, racer_sub=race.racer.sub,
                   racer_username=race.racer.username, race_id=race.race_id,
                   token=f"{race.race_id}#{'deleted' if deleted else race.version}")


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
    def delete(self, record: RaceRecord) -> None: ...
    # Each write above also stores `PublishIntent.of(race)` in the same transaction.
    def pending_publishes(self, older_than_ms: int = 0) -> list[PublishIntent]: ...
    def complete_publish(self, intent: PublishIntent) -> None: ...


class EventSource(Protocol):
    def get(self, event_id: str) -> Event | None: ...


class RacerDirectory(Protocol):
    def get_user(self, username: str) -> Any: ...  # has .sub and .username (raises NotFound)
    def groups_of(self, username: str) -> list[str]: ...


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


def rule_error(exc: RaceRuleError) -> Exception:
    return NotFound(exc.message, field="lap_id") if isinstance(exc, LapNotFoundError) else Conflict(exc.message)


class StatsRefresher(Protocol):
    """Rebuilds an event's statistics digest from its races (domain/stats.py `StatsDigests`)."""

    def refresh(self, event_id: str) -> object: ...


class RaceService:
    def __init__(self, races: RaceRepository, events: EventSource, racers: RacerDirectory, profiles: ProfileSource,
                 boards: LeaderboardPublisher, clock_ms: Callable[[], int], audit: AuditLog | None = None,
                 stats: StatsRefresher | None = None) -> None:
        self._races = races
        self._stats = stats
        self._audit = AuditTrail(audit, clock_ms)
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

    def existing_race(self, event_id: str, race_id: str) -> RaceRecord | None:
        return self._races.get(event_id, race_id)

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

    def create_race(self, principal: User, event_id: str, data: CreateRaceInput, *,
                    race_id: str | None = None) -> dict[str, Any]:
        """Create the race (with `race_id`, when the caller recorded that id before, as the racer queue does, so
        a repeat after a crash finds the race it created instead of making a second one)."""
        event = self.event(event_id)
        event.track(data.track_id)
        racer = self._racers.get_user(data.racer_username)
        if not self._racers.groups_of(racer.username):  # the last step of a registration: this one was cut off
            raise Conflict(f"The registration of {racer.username} was interrupted before it finished. Register "
                           f"{racer.username} again at the desk (same name and email) to finish it, then create "
                           "the race.", field="racer_username")
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
        race = new_race(race_id=race_id or uuid.uuid4().hex, event_id=event_id, track_id=data.track_id,
                        racer=Racer(sub=racer.sub, username=racer.username), config=config, now_ms=now,
                        raced_by_proxy=data.raced_by_proxy, car=data.car)
        record = RaceRecord(race=race, created_by=principal.id, max_runs_override=override)
        self._races.create_live(record)
        self.publish(event, race, now)
        return race_view(record, now, runs_used=used + 1, max_runs=config.max_runs_per_racer)

    def apply_command(self, event_id: str, race_id: str, command: RaceCommand, *, by: str = "") -> dict[str, Any]:
        event = self.event(event_id)
        replaced: list[Race] = []

        def attempt() -> tuple[RaceRecord, race_machine.TransitionOutcome, int]:
            record = self.record(event_id, race_id)
            replaced[:] = [record.race]
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
        if isinstance(command, SetLapValidity) and outcome.changed:
            self._audit_lap(event_id, by, "lap_validity", replaced[0], record.race, command.lap_id)
        return race_view(record, now, outcome=outcome.model_dump(mode="json"))

    def store(self, record: RaceRecord, expected_version: int) -> None:
        if record.race.status in TERMINAL_STATUSES:
            self._races.finalise(record, expected_version)
        else:
            self._races.save(record, expected_version)

    # --- race admin --------------------------------------------------------------------------------------------

    def edit_lap(self, event_id: str, race_id: str, lap_id: int, edit: LapEdit, *, by: str = "") -> dict[str, Any]:
        event = self.event(event_id)
        replaced: list[Race] = []  # the race as the winning attempt found it: the audit's "before"

        def attempt() -> RaceRecord:
            record = self.record(event_id, race_id)
            race = record.race
            replaced[:] = [race]
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
        self._audit_lap(event_id, by, "lap_edit", replaced[0], record.race, lap_id)
        return race_view(record, self.clock_ms())

    def _audit_lap(self, event_id: str, by: str, action: Any, before: Race, after: Race, lap_id: int) -> None:
        old = next((lap_state(lap) for lap in before.laps if lap.lap_id == lap_id), None)
        new = next((lap_state(lap) for lap in after.laps if lap.lap_id == lap_id), None)
        if old != new:
            self._audit.record(event_id, by, action, race_id=after.race_id, racer=after.racer.username,
                               lap_id=lap_id, before=old, after=new)

    def delete_race(self, event_id: str, race_id: str, *, by: str = "") -> None:
        event = self.event(event_id)
        record = self.record(event_id, race_id)
        if record.race.status not in TERMINAL_STATUSES:
            raise Conflict(f"Race {race_id} is live on track {record.race.track_id}; end and discard it instead.")
        self._races.delete(record)
        listing = _listing(record)
        self._audit.record(event_id, by, "race_delete", race_id=race_id, racer=record.race.racer.username,
                           before={k: listing[k] for k in ("track_id", "status", "laps", "valid_laps",
                                                           "fastest_lap_ms")})
        try:
            self._publish_change(event, record.race.track_id, record.race.racer, self.clock_ms(), None)
            self._finish(PublishIntent.of(record.race, deleted=True))
        except DremError as exc:
            _board_behind(record.race, exc)

    def recompute(self, event_id: str, *, by: str = "") -> dict[str, Any]:
        event = self.event(event_id)
        before = self._standings(event)
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
        self._refresh_stats(event_id)
        self._audit.record(event_id, by, "recompute", before={"boards": before}, after={"boards": {
            track: standings(board.model_dump(mode="json")) for track, board in boards.items()}})
        return {"event_id": event_id, "boards": {track: {"version": b.version, "entries": len(b.entries)}
                                                 for track, b in boards.items()}}

    def _standings(self, event: Event) -> dict[str, list[str]]:
        tracks = dict.fromkeys([*event.boards, COMBINED_TRACK_ID])  # the combined board exists for one track too
        return {track: standings(json.loads(self._boards.board(event.event_id, track).body)) for track in tracks}

    def export(self, event_id: str, file_name: str) -> CsvFile:
        kinds = {f"{kind.value}.csv": kind for kind in ExportKind}
        if file_name not in kinds:
            raise InvalidInput("Export laps.csv or summary.csv.", field="file_name")
        event = self.event(event_id)
        races = [r.race for r in self._races.list_event(event_id)]
        # The CSVs name racers as the boards do: their display name (a deleted racer anonymised), with the sign-in
        # name after it when two racers of the event go by the same display name.
        shown = told_apart({race.racer.sub: (self._profiles.racer_profile(race.racer.sub, race.racer.username)
                                             .username or race.racer.username, race.racer.username) for race in races})
        named = [race.model_copy(update={"racer": Racer(sub=race.racer.sub, username=shown[race.racer.sub])})
                 for race in races]
        return export_csv(event.name, named, kinds[file_name], self.clock_ms())

    # --- publishing --------------------------------------------------------------------------------------------

    def publish(self, event: Event, race: Race, now_ms: int, *, live_race_id: str | None = None) -> None:
        """After a change: publish it (`_publish_change`), then drop the publish intent the write stored, and finish
        any other write's intent a crash left behind. `live_race_id`: the track's live race when the caller has just
        read it (a timing crossing), so the lap's way to the board reads it once.

        The race change is already stored (with its intent) when this runs, so a storage failure here does not fail
        the request: the change is acknowledged and the intent makes sure the board catches up."""
        try:
            self._publish_change(event, race.track_id, race.racer, now_ms, race, live_race_id)
            self._finish(PublishIntent.of(race))
            self.complete_pending_publishes(STALE_INTENT_MS)
        except DremError as exc:
            _board_behind(race, exc)

    def complete_pending_publishes(self, older_than_ms: int = 0) -> int:
        """Publish again every race change whose publish intent is still stored (a crash or outage came between a
        race write and its board write), the same way the write itself publishes. Returns how many were finished."""
        finished = 0
        for intent in self._races.pending_publishes(older_than_ms):
            event = self._events.get(intent.event_id)
            if event is not None:  # else the event is gone; nothing left to publish to
                record = self._races.get(intent.event_id, intent.race_id)
                self._publish_change(event, intent.track_id,
                                     Racer(sub=intent.racer_sub, username=intent.racer_username), self.clock_ms(),
                                     record.race if record is not None else None)
                finished += 1
            self._races.complete_publish(intent)
        return finished

    def _publish_change(self, event: Event, track_id: str, racer: Racer, now_ms: int, race: Race | None,
                        known_live_race_id: str | None = None) -> None:
        """The one owner of "a race changed": the racer's board row (their submitted races + `race` if live), the
        track's overlay (when `race` is the track's current race), the combined board, then the statistics once a
        race is submitted or gone. `race` None: the race was deleted (its row is rebuilt without it).

        The live write and the crash replay (`complete_pending_publishes`) both come here, so a replayed change
        reaches exactly what the write would have."""
        races = [r.race for r in self._races.list_event(event.event_id, track_id=track_id, racer_sub=racer.sub)]
        if race is not None:  # the race just written wins over any older copy the listing returned
            races = [r for r in races if r.race_id != race.race_id] + [race]
        profile = self._profiles.racer_profile(racer.sub, racer.username)
        live = (known_live_race_id or self._races.live_race_id(event.event_id, track_id)) if race is not None else None
        self._boards.publish_change(event.event_id, track_id, racer.sub, self._row(races, profile),
                                    event.race_config.ranking_method, [t.track_id or "" for t in event.tracks],
                                    race=race, now_ms=now_ms, display_name=profile.username or racer.username,
                                    live_race_id=live)
        if race is None or race.status in TERMINAL_STATUSES:  # only submitted races count: no stats work per lap
            self._refresh_stats(event.event_id)

    def _refresh_stats(self, event_id: str) -> None:
        # Before the intent is dropped: a crash here leaves the intent, whose completion refreshes the digest too.
        if self._stats is not None:
            self._stats.refresh(event_id)

    def _finish(self, intent: PublishIntent) -> None:
        self._races.complete_publish(intent)

    def refresh_racer_board(self, event: Event, track_id: str, racer: Racer, now_ms: int,
                            changed: Race | None = None, *, combined: bool = True) -> Leaderboard:
        races = [r.race for r in self._races.list_event(event.event_id, track_id=track_id, racer_sub=racer.sub)]
        if changed is not None:  # the race just written wins over any older copy the listing returned
            races = [r for r in races if r.race_id != changed.race_id] + [changed]
        return self._boards.refresh_racer(event.event_id, track_id, racer.sub, self._row(races),
                                          event.race_config.ranking_method,
                                          all_tracks=[t.track_id or "" for t in event.tracks], combined=combined)

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

    def _row(self, races: Iterable[Race], profile: RacerProfile | None = None) -> BoardRow | None:
        summary = summarise_racer(c for r in races if (c := counts_on_board(r)) is not None)
        if summary is None:
            return None
        return BoardRow(summary=summary,
                        profile=profile or self._profiles.racer_profile(summary.racer_sub, summary.username))


def _board_behind(race: Race, exc: DremError) -> None:
    log.warning("race %s is stored but its board was not rebuilt yet (%s); its publish intent will be finished by "
                "the next request or the sweeper", race.race_id, exc.message)


def _listing(record: RaceRecord) -> dict[str, Any]:
    race = record.race
    return {"race_id": race.race_id, "event_id": race.event_id, "track_id": race.track_id,
            "racer_sub": race.racer.sub, "username": race.racer.username, "raced_by_proxy": race.raced_by_proxy,
            "status": race.status.value, "laps": len(race.laps), "valid_laps": len(race.valid_laps),
            "fastest_lap_ms": race.fastest_valid_lap.time_ms if race.fastest_valid_lap else None,
            "created_at_ms": race.created_at_ms, "submitted_at_ms": race.submitted_at_ms, "version": race.version,
            "max_runs_override": record.max_runs_override.model_dump() if record.max_runs_override else None}
