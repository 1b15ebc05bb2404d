"""Events: what is raced where and under which rules.

An event has one or more tracks (each with its fleet and leaderboard texts) and one race configuration
(`drem_leaderboard.models.RaceConfig`, the same model a race freezes a copy of when it is created, so editing an event
never changes a race already under way). With two or more tracks the event also gets a combined leaderboard.
Deleting an event, or removing one of its tracks, is refused while that track has a live race.
"""
from __future__ import annotations

import re
import uuid
from collections.abc import Callable
from datetime import date
from enum import StrEnum
from typing import Any, Literal, Protocol

from pydantic import BaseModel, ConfigDict, Field, computed_field, field_validator, model_validator

from chalicelib.core.errors import Conflict, InvalidInput, NotFound
from chalicelib.core.principals import User
from drem_leaderboard.models import RaceConfig

COMBINED_TRACK_ID = "combined"
DEFAULT_FOOTER = "Follow the race #AWSDeepRacer"
MAX_TRACKS = 10

# ISO 3166-1 alpha-2 (officially assigned codes).
ISO_COUNTRIES = frozenset("""
AD AE AF AG AI AL AM AO AQ AR AS AT AU AW AX AZ BA BB BD BE BF BG BH BI BJ BL BM BN BO BQ BR BS BT BV BW BY BZ CA CC
CD CF CG CH CI CK CL CM CN CO CR CU CV CW CX CY CZ DE DJ DK DM DO DZ EC EE EG EH ER ES ET FI FJ FK FM FO FR GA GB GD GE
GF GG GH GI GL GM GN GP GQ GR GS GT GU GW GY HK HM HN HR HT HU ID IE IL IM IN IO IQ IR IS IT JE JM JO JP KE KG KH KI KM
KN KP KR KW KY KZ LA LB LC LI LK LR LS LT LU LV LY MA MC MD ME MF MG MH MK ML MM MN MO MP MQ MR MS MT MU MV MW MX MY MZ
NA NC NE NF NG NI NL NO NP NR NU NZ OM PA PE PF PG PH PK PL PM PN PR PS PT PW PY QA RE RO RS RU RW SA SB SC SD SE SG SH
SI SJ SK SL SM SN SO SR SS ST SV SX SY SZ TC TD TF TG TH TJ TK TL TM TN TO TR TT TV TW TZ UA UG UM US UY UZ VA VC VE VG
VI VN VU WF WS YE YT ZA ZM ZW
""".split())

_TRACK_ID = re.compile(r"^[A-Za-z0-9_-]{1,32}$")


class EventType(StrEnum):
    PRIVATE_WORKSHOP = "PRIVATE_WORKSHOP"
    PRIVATE_TRACK_RACE = "PRIVATE_TRACK_RACE"
    OFFICIAL_WORKSHOP = "OFFICIAL_WORKSHOP"
    OFFICIAL_TRACK_RACE = "OFFICIAL_TRACK_RACE"
    AWS_SUMMIT = "AWS_SUMMIT"
    TEST_EVENT = "TEST_EVENT"
    OTHER = "OTHER"


TrackDirection = Literal["counter_clockwise", "clockwise"]
StatsVisibility = Literal["public", "staff"]


class Track(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    track_id: str | None = Field(default=None, description="'1', '2', … assigned when left out")
    fleet_id: str | None = Field(default=None, max_length=64)
    leaderboard_title: str = Field(default="", max_length=120)
    leaderboard_footer: str = Field(default=DEFAULT_FOOTER, max_length=200)
    direction: TrackDirection = Field(default="counter_clockwise",
                                      description="the way cars go round (statistics filter fastest laps by it)")

    @field_validator("track_id")
    @classmethod
    def _plain_track_id(cls, value: str | None) -> str | None:
        if value is not None and (not _TRACK_ID.match(value) or value == COMBINED_TRACK_ID):
            raise ValueError("use 1-32 letters, digits, '-' or '_' (and not 'combined')")
        return value


class LandingPageLink(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str = Field(min_length=1, max_length=80)
    description: str = Field(default="", max_length=300)
    href: str = Field(min_length=1, max_length=500)

    @field_validator("href")
    @classmethod
    def _web_or_site_link(cls, value: str) -> str:
        if not (value.startswith(("https://", "http://")) or (value.startswith("/") and not value.startswith("//"))):
            raise ValueError("use an http(s):// address or a path on this site starting with '/'")
        return value


DEFAULT_LINKS = (LandingPageLink(name="Upload your own model and race",
                                 description="Upload a model, then race it on the track.",
                                 href="/console/my-models"),)


class EventInput(BaseModel):
    """What an operator sends to create or replace an event."""
    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str = Field(min_length=1, max_length=120)
    event_type: EventType
    date: date
    country_code: str
    sponsor: str = Field(default="", max_length=120)
    race_config: RaceConfig = Field(default_factory=RaceConfig)
    tracks: list[Track] = Field(default_factory=lambda: [Track()], min_length=1, max_length=MAX_TRACKS)
    landing_page_links: list[LandingPageLink] = Field(default_factory=lambda: list(DEFAULT_LINKS), max_length=20)
    stats_visibility: StatsVisibility = Field(
        default="public", description="whether the event counts on the public /stats page or only on the staff's")

    @field_validator("name", "sponsor")
    @classmethod
    def _trimmed(cls, value: str) -> str:
        return value.strip()

    @field_validator("country_code")
    @classmethod
    def _iso_country(cls, value: str) -> str:
        code = value.strip().upper()
        if code not in ISO_COUNTRIES:
            raise ValueError("use a two-letter ISO 3166-1 country code, e.g. GB, US, SE")
        return code

    @model_validator(mode="after")
    def _unique_track_ids(self) -> EventInput:
        given = [t.track_id for t in self.tracks if t.track_id is not None]
        if len(given) != len(set(given)):
            raise ValueError("tracks: each track_id must be used once")
        return self


class Event(BaseModel):
    model_config = ConfigDict(frozen=True)

    event_id: str
    name: str
    event_type: EventType
    date: date
    country_code: str
    sponsor: str
    race_config: RaceConfig
    tracks: tuple[Track, ...]
    landing_page_links: tuple[LandingPageLink, ...]
    stats_visibility: StatsVisibility = "public"
    created_at_ms: int
    created_by: str
    updated_at_ms: int
    version: int = 1

    @computed_field  # type: ignore[prop-decorator]
    @property
    def combined_board(self) -> bool:
        """Several tracks get a combined leaderboard (DREM's pseudo-track 'combined')."""
        return len(self.tracks) >= 2

    @computed_field  # type: ignore[prop-decorator]
    @property
    def boards(self) -> list[str]:
        ids = [t.track_id or "" for t in self.tracks]
        return ids + [COMBINED_TRACK_ID] if self.combined_board else ids

    def track(self, track_id: str) -> Track:
        for candidate in self.tracks:
            if candidate.track_id == track_id:
                return candidate
        raise NotFound(f"Event {self.event_id} has no track {track_id!r}.", field="track_id")

    def track_name(self, track_id: str) -> str:
        """What staff and viewers call a track: its leaderboard title, else "Track 2"."""
        if track_id == COMBINED_TRACK_ID:
            return "All tracks"
        found = next((t for t in self.tracks if t.track_id == track_id), None)
        return (found.leaderboard_title if found else "") or f"Track {track_id}"


class EventRepository(Protocol):
    def get(self, event_id: str) -> Event | None: ...
    def list(self) -> list[Event]: ...
    def create(self, event: Event) -> None: ...
    def replace(self, event: Event, expected_version: int) -> None: ...
    def delete(self, event_id: str) -> None: ...


class LiveRaceProbe(Protocol):
    def has_live_race(self, event_id: str, track_id: str) -> bool: ...


class FleetLookup(Protocol):
    def fleet_exists(self, fleet_id: str) -> bool: ...


class EventService:
    def __init__(self, events: EventRepository, live_races: LiveRaceProbe, fleets: FleetLookup,
                 clock_ms: Callable[[], int], on_saved: Callable[[Event], None] | None = None) -> None:
        """`on_saved(event)` after each create or update: the big screen's settings are published (big_screen.py)."""
        self._on_saved = on_saved
        self._events = events
        self._live = live_races
        self._fleets = fleets
        self._clock_ms = clock_ms

    def list_events(self) -> list[Event]:
        # Newest first, as DREM's events table sorts by date.
        return sorted(self._events.list(), key=lambda e: (e.date, e.created_at_ms), reverse=True)

    def get_event(self, event_id: str) -> Event:
        event = self._events.get(event_id)
        if event is None:
            raise NotFound(f"There is no event {event_id}.")
        return event

    def create_event(self, principal: User, data: EventInput) -> Event:
        now = self._clock_ms()
        event = Event(event_id=uuid.uuid4().hex[:12], created_at_ms=now, created_by=principal.sub, updated_at_ms=now,
                      **self._fields(data))
        self._events.create(event)
        self._saved(event)
        return event

    def update_event(self, principal: User, event_id: str, data: EventInput) -> Event:
        current = self.get_event(event_id)
        fields = self._fields(data, keep=current.tracks)
        kept = {t.track_id for t in fields["tracks"]}
        for track in current.tracks:
            if track.track_id not in kept:
                self._refuse_if_live(event_id, track.track_id or "", "remove track")
        updated = Event.model_validate({**current.model_dump(), **fields, "updated_at_ms": self._clock_ms(),
                                        "version": current.version + 1})
        self._events.replace(updated, expected_version=current.version)
        self._saved(updated)
        return updated

    def _saved(self, event: Event) -> None:
        if self._on_saved is not None:
            self._on_saved(event)

    def delete_event(self, principal: User, event_id: str) -> None:
        event = self.get_event(event_id)
        for track in event.tracks:
            self._refuse_if_live(event_id, track.track_id or "", "delete the event")
        self._events.delete(event_id)

    def _refuse_if_live(self, event_id: str, track_id: str, action: str) -> None:
        if self._live.has_live_race(event_id, track_id):
            raise Conflict(f"Track {track_id} has a race in progress; finish or discard it before you {action}.",
                           field="tracks")

    def _fields(self, data: EventInput, keep: tuple[Track, ...] = ()) -> dict[str, Any]:
        # A fleet the event already names may since have been deleted; only newly named fleets must exist.
        already_named = {t.fleet_id for t in keep}
        for index, track in enumerate(data.tracks):
            if track.fleet_id and track.fleet_id not in already_named and not self._fleets.fleet_exists(track.fleet_id):
                raise InvalidInput(f"There is no fleet {track.fleet_id}.", field=f"tracks.{index}.fleet_id")
        return {"name": data.name, "event_type": data.event_type, "date": data.date,
                "country_code": data.country_code, "sponsor": data.sponsor, "race_config": data.race_config,
                "tracks": _numbered(data.tracks, keep), "landing_page_links": tuple(data.landing_page_links),
                "stats_visibility": data.stats_visibility}


def _numbered(tracks: list[Track], existing: tuple[Track, ...]) -> tuple[Track, ...]:
    """Give tracks without an id the next free number ('1', '2', …), never reusing an id the event already had."""
    taken = {t.track_id for t in tracks if t.track_id} | {t.track_id for t in existing if t.track_id}
    numbered, counter = [], 0
    for track in tracks:
        if track.track_id is None:
            counter += 1
            while str(counter) in taken:
                counter += 1
            taken.add(str(counter))
            track = track.model_copy(update={"track_id": str(counter)})
        numbered.append(track)
    return tuple(numbered)
