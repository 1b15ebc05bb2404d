"""The statistics page (`/stats`): events, racers and laps over time, per country on a world map, and the fastest laps
per track type, over every event the viewer may see, with filters (track direction, country, dates).

Rules follow DREM's statistics engine: test events are left out, only submitted races count, and a lap under 5 s
counts as invalid (a timing artefact). Events the organiser keeps staff-only (`stats_visibility = "staff"`) count
only for signed-in staff.

The page never reads races. Each event has a stored digest (`EventDigest`: per submitted race its racer, track,
lap counts and best valid lap — all the page needs), rebuilt by the race service whenever one of the event's races
stops being live, is edited, deleted or recomputed (DREM keeps a statistics table the same way). A digest is
rebuilt from a consistent listing of the event's races, and a write only replaces a digest built from an older
listing, so two races submitted at once cannot leave it behind. An event without a digest yet (imported, or from
before digests) gets one on the first read. `compute` is pure: events and digests in, what the page prints out.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from datetime import date
from typing import NamedTuple, Protocol

from pydantic import BaseModel, ConfigDict, Field

from chalicelib.domain.countries import country_name
from chalicelib.domain.events import Event, EventType, TrackDirection
from chalicelib.domain.races import RaceRecord
from chalicelib.formats.figures import lap_time
from drem_leaderboard.models import Race, RaceStatus
from drem_leaderboard.names import told_apart

MIN_LAP_MS = 5_000
TOP_LAPS = 10
DIRECTION_LABELS = {"counter_clockwise": "Counter-clockwise", "clockwise": "Clockwise"}


class StatsFilter(BaseModel):
    """The page's filter form (GET query): empty means "all"."""
    model_config = ConfigDict(extra="ignore")
    direction: TrackDirection | None = None
    country: str | None = Field(default=None, pattern=r"^[A-Za-z]{2}$")
    date_from: date | None = Field(default=None, alias="from")
    date_to: date | None = Field(default=None, alias="to")


class ShownRacer(NamedTuple):
    """How a lap's racer is shown: their display name (a deleted racer's tombstone name), their own country, and the
    name that tells them apart from another racer of the same display name ("" : the race's sign-in name)."""
    name: str
    country_code: str | None = None
    sign_in_name: str = ""


class FastLap(BaseModel):
    model_config = ConfigDict(frozen=True)
    position: int
    username: str
    time: str
    time_ms: int
    event_name: str
    event_date: date
    # The racer's country (their profile's), not the event's.
    country_code: str
    country: str
    direction: str


class TrackTypeStats(BaseModel):
    model_config = ConfigDict(frozen=True)
    track_type: str
    races: int
    best: str
    fastest: tuple[FastLap, ...]


class Totals(BaseModel):
    model_config = ConfigDict(frozen=True)
    events: int
    racers: int
    races: int
    laps: int
    valid_laps: int
    countries: int


class Stats(BaseModel):
    model_config = ConfigDict(frozen=True)
    totals: Totals
    by_month: tuple[tuple[str, int, int], ...]  # (YYYY-MM, events, races)
    events_by_country: dict[str, int]
    racers_by_country: dict[str, int]
    track_types: tuple[TrackTypeStats, ...]
    fastest: tuple[FastLap, ...]
    countries: tuple[str, ...]  # every country with a visible event (the filter's choices)


class RaceDigest(BaseModel):
    """What /stats needs of one submitted race."""
    model_config = ConfigDict(frozen=True)
    sub: str
    username: str
    track_id: str
    track_type: str
    laps: int
    valid_laps: int
    best_valid_ms: int | None


class EventDigest(BaseModel):
    """The submitted races of one event, as /stats reads them (one stored item per event)."""
    model_config = ConfigDict(frozen=True)
    event_id: str
    races: tuple[RaceDigest, ...]


def _counts(lap_ms: int, is_valid: bool) -> bool:
    return is_valid and lap_ms >= MIN_LAP_MS


def digest_of(event_id: str, races: Iterable[Race]) -> EventDigest:
    entries = []
    for race in races:
        if race.status is not RaceStatus.SUBMITTED:
            continue
        valid = [lap.time_ms for lap in race.laps if _counts(lap.time_ms, lap.is_valid)]
        entries.append(RaceDigest(sub=race.racer.sub, username=race.racer.username, track_id=race.track_id,
                                  track_type=race.config.track_type.value, laps=len(race.laps),
                                  valid_laps=len(valid), best_valid_ms=min(valid, default=None)))
    return EventDigest(event_id=event_id, races=tuple(sorted(entries, key=lambda d: (d.track_id, d.sub))))


class DigestStore(Protocol):
    def digests(self, event_ids: Sequence[str]) -> dict[str, EventDigest]: ...
    def put(self, digest: EventDigest, listed_at_ms: int) -> None: ...


class EventRaces(Protocol):
    def list_event(self, event_id: str) -> Sequence[RaceRecord]: ...


class StatsDigests:
    """Keeps each event's digest equal to what its races say (see the module docstring)."""

    def __init__(self, store: DigestStore, races: EventRaces, clock_ms: Callable[[], int]) -> None:
        self._store = store
        self._races = races
        self._clock_ms = clock_ms

    def refresh(self, event_id: str) -> EventDigest:
        listed_at = self._clock_ms()  # before the listing: a later listing sees at least what this one sees
        digest = digest_of(event_id, (record.race for record in self._races.list_event(event_id)))
        self._store.put(digest, listed_at)
        return digest

    def for_events(self, events: Sequence[Event]) -> list[tuple[Event, tuple[RaceDigest, ...]]]:
        stored = self._store.digests([event.event_id for event in events])
        return [(event, (stored.get(event.event_id) or self.refresh(event.event_id)).races) for event in events]


def visible_events(events: Iterable[Event], *, staff: bool) -> list[Event]:
    return [e for e in events if e.event_type is not EventType.TEST_EVENT and (staff or e.stats_visibility == "public")]


def _event_matches(event: Event, wanted: StatsFilter) -> bool:
    if wanted.country and event.country_code != wanted.country.upper():
        return False
    if wanted.date_from and event.date < wanted.date_from:
        return False
    if wanted.date_to and event.date > wanted.date_to:
        return False
    return not wanted.direction or any(t.direction == wanted.direction for t in event.tracks)


Candidate = tuple[int, str, str, Event, str, str]  # (ms, sub, username, event, track type, direction)


def compute(events_and_races: Sequence[tuple[Event, Sequence[RaceDigest]]], wanted: StatsFilter,
            display_name: Callable[[str, str], ShownRacer]) -> Stats:
    """`events_and_races` holds the visible events only, each with its submitted races' digests;
    `display_name(sub, username)` is what a lap is shown under (a deleted racer's tombstone name)."""
    countries = tuple(sorted({e.country_code for e, _ in events_and_races}))
    chosen = [(e, races) for e, races in events_and_races if _event_matches(e, wanted)]
    months: dict[str, list[int]] = {}
    event_countries: Counter[str] = Counter()
    racers_by_country: dict[str, set[str]] = {}
    racers: set[str] = set()
    laps = valid = race_count = 0
    candidates: list[Candidate] = []
    by_type: dict[str, int] = Counter()
    for event, races in chosen:
        directions = {t.track_id: t.direction for t in event.tracks}
        month = months.setdefault(event.date.strftime("%Y-%m"), [0, 0])
        month[0] += 1
        event_countries[event.country_code] += 1
        for race in races:
            direction = directions.get(race.track_id, "counter_clockwise")
            if wanted.direction and direction != wanted.direction:
                continue
            race_count += 1
            month[1] += 1
            racers.add(race.sub)
            racers_by_country.setdefault(event.country_code, set()).add(race.sub)
            by_type[race.track_type] += 1
            laps += race.laps
            valid += race.valid_laps
            if race.best_valid_ms is not None:  # a racer's best lap is the best of their races' bests
                candidates.append((race.best_valid_ms, race.sub, race.username, event, race.track_type, direction))
    candidates.sort(key=lambda c: (c[0], c[2]))
    tops = {track_type: _top(c for c in candidates if c[4] == track_type) for track_type in by_type}
    overall = _top(candidates)
    # One page, one view: a racer is told apart from a namesake in any of its tables, the same way in every one.
    named = _named({c[1]: c[2] for top in (overall, *tops.values()) for c in top}, display_name)
    per_type = [TrackTypeStats(track_type=track_type, races=count,
                               best=lap_time(next((c[0] for c in candidates if c[4] == track_type), None), "—"),
                               fastest=_fast_laps(tops[track_type], named))
                for track_type, count in sorted(by_type.items())]
    return Stats(
        totals=Totals(events=len(chosen), racers=len(racers), races=race_count, laps=laps, valid_laps=valid,
                      countries=len(event_countries)),
        by_month=tuple((m, v[0], v[1]) for m, v in sorted(months.items())),
        events_by_country=dict(event_countries), racers_by_country={c: len(s) for c, s in racers_by_country.items()},
        track_types=tuple(per_type), fastest=_fast_laps(overall, named), countries=countries)


def _top(candidates: Iterable[Candidate]) -> list[Candidate]:
    """The TOP_LAPS fastest laps, one per racer (their best)."""
    best: list[Candidate] = []
    seen: set[str] = set()
    for candidate in candidates:
        if candidate[1] in seen:
            continue
        seen.add(candidate[1])
        best.append(candidate)
        if len(best) == TOP_LAPS:
            break
    return best


def _named(usernames: dict[str, str], display_name: Callable[[str, str], ShownRacer]) -> dict[str, ShownRacer]:
    """{sub: how the page shows them} for the racers its tables name (a profile read each, once): a display name
    another of them also goes by gets the sign-in name after it (drem_leaderboard.names)."""
    racers = {sub: display_name(sub, username) for sub, username in usernames.items()}
    shown = told_apart({sub: (r.name, r.sign_in_name or usernames[sub]) for sub, r in racers.items()})
    return {sub: r._replace(name=shown[sub]) for sub, r in racers.items()}


def _fast_laps(top: list[Candidate], named: dict[str, ShownRacer]) -> tuple[FastLap, ...]:
    laps = []
    for i, (ms, sub, _username, event, _type, direction) in enumerate(top, start=1):
        racer = named[sub]
        code = racer.country_code or ""
        laps.append(FastLap(position=i, username=racer.name, time=lap_time(ms), time_ms=ms, event_name=event.name,
                            event_date=event.date, country_code=code, country=country_name(code),
                            direction=DIRECTION_LABELS[direction]))
    return tuple(laps)
