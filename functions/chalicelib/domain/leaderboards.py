"""Materialised leaderboards and overlays: rebuilt by the race service on every change, read by polls with one GetItem.

A board item keeps, next to its public body, the state it was ranked from: one `BoardRow` (summary + profile) per
racer. Refreshing one racer replaces their row and re-ranks; nothing else is read. The combined board is ranked from
the rows of every track board; it is written for single-track events too (then equal to the track's board), so a
poll without `?track=` always finds a board without looking the event up. Versions go up by one per write; a write is
skipped
when neither what viewers see (the board's etag) nor the stored rows changed, so polls keep getting 304.

Poll reads (`board`, `overlay`) go through a per-process `PublicViewCache`: hundreds of spectators polling every second
cost one GetItem per item per freshness window (250 ms) instead of one each. Writes through the publisher invalidate the
entry in the writing process, so that process serves its own writes at once; other processes see them within 250 ms.
"""
from __future__ import annotations

import hashlib
import json
import threading
import time
from collections.abc import Callable, Hashable, Iterable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Protocol

from pydantic import BaseModel, ConfigDict

from chalicelib.core.errors import Conflict
from drem_leaderboard.models import Race, RaceStatus, RankingMethod
from drem_leaderboard.names import name_key, with_sign_in_name
from drem_leaderboard.race_clock import current_lap_ms, race_time_left_ms
from drem_leaderboard.ranking import COMBINED_TRACK_ID, Leaderboard, LeaderboardEntry, RacerProfile, rank
from drem_leaderboard.summary import RaceSummary

BOARD_ATTEMPTS = 4
PUBLIC_READ_FRESH_MS = 250.0
# Entries per public board page. A 5,000-racer board is 1.6 MB of JSON: far past DynamoDB's 400 KB item limit, and
# more than a big screen shows. Polls and pushes read the first page (one GetItem); `?page=N` reads the others.
BOARD_PAGE_ENTRIES = 200


class StaleBoard(Exception):
    """Another writer changed the board/overlay item since it was read; re-read and try again."""


class PublicView(BaseModel):
    model_config = ConfigDict(frozen=True)
    version: int
    etag: str
    body: str


class Materialised(PublicView):
    """A board or overlay as its writer sees it: `body` is what polls get (a board's first page), `pages` the bodies
    of a long board's further pages (2, 3, ...), `state` the rows it was ranked from."""
    state: str = ""
    pages: tuple[str, ...] = ()


class BoardRow(BaseModel):
    model_config = ConfigDict(frozen=True)
    summary: RaceSummary
    profile: RacerProfile


class BoardState(BaseModel):
    rows: list[BoardRow] = []


# What a write's `build` gives: (body, etag, state) or (body, etag, state, further pages' bodies).
Built = tuple[str, str, str] | tuple[str, str, str, list[str]]


class BoardRepository(Protocol):
    def public(self, event_id: str, sort_key: str) -> PublicView | None: ...
    def get(self, event_id: str, sort_key: str) -> Materialised | None: ...
    def put(self, event_id: str, sort_key: str, item: Materialised, expected_version: int | None) -> None: ...


# --- the poll-side cache ---------------------------------------------------------------------------------------------


@dataclass
class _Entry:
    read_started: float
    value: PublicView | None


@dataclass
class _Flight:
    """One table read in progress; threads asking for the same key meanwhile wait for it instead of reading too."""
    done: threading.Event = field(default_factory=threading.Event)
    value: PublicView | None = None
    ok: bool = False
    invalidated: bool = False


class PublicViewCache:
    """Per-process cache of poll reads, keyed by (store namespace, event id, sort key).

    Staleness bound: an answer was read from the table at most `fresh_ms` ago (timed from the moment the read started),
    and a write made through this process's publisher is visible to the next read here. Single flight: while one
    thread reads an expired key, the others asking for it wait for that read. Refresh ahead: once an entry is older than
    `refresh_after_ms` (60 % of the window), the next asker reads it again while everyone else is still served the
    entry, so a busy key never expires and pollers do not queue behind a read. "No item" is cached like an item.
    """

    def __init__(self, fresh_ms: float = PUBLIC_READ_FRESH_MS, *, monotonic: Callable[[], float] = time.monotonic,
                 max_entries: int = 4096, wait_s: float = 5.0) -> None:
        self.fresh_ms = fresh_ms
        self.refresh_after_ms = fresh_ms * 0.6
        self._monotonic = monotonic
        self._max_entries = max_entries
        self._wait_s = wait_s
        self._lock = threading.Lock()
        self._entries: dict[Hashable, _Entry] = {}
        self._flights: dict[Hashable, _Flight] = {}

    def get(self, key: Hashable, load: Callable[[], PublicView | None]) -> PublicView | None:
        with self._lock:
            entry = self._entries.get(key)
            age_ms = (self._monotonic() - entry.read_started) * 1000 if entry is not None else None
            held = entry if age_ms is not None and age_ms <= self.fresh_ms else None
            flight: _Flight | None
            if held is not None:
                assert age_ms is not None  # held only when it was measured
                if age_ms < self.refresh_after_ms or key in self._flights:
                    return held.value
                flight = self._flights[key] = _Flight()  # refresh ahead: this asker reads, the others keep the entry
                leader = True
            else:
                flight = self._flights.get(key)
                leader = flight is None
                if flight is None:
                    flight = self._flights[key] = _Flight()
        if held is not None:
            return self._refresh_ahead(key, flight, load, held)
        if not leader:
            if flight.done.wait(self._wait_s) and flight.ok:
                return flight.value
            return load()  # the leader failed or hung: this request reads (and fails) on its own
        return self._lead(key, flight, load)

    def _refresh_ahead(self, key: Hashable, flight: _Flight, load: Callable[[], PublicView | None],
                       entry: _Entry) -> PublicView | None:
        try:
            return self._lead(key, flight, load)
        except Exception:
            if (self._monotonic() - entry.read_started) * 1000 <= self.fresh_ms:
                return entry.value  # the early read failed, but what we hold is still within the bound
            raise

    def _lead(self, key: Hashable, flight: _Flight, load: Callable[[], PublicView | None]) -> PublicView | None:
        started = self._monotonic()
        try:
            value = load()
        except BaseException:
            with self._lock:
                if self._flights.get(key) is flight:
                    del self._flights[key]
            flight.done.set()
            raise
        with self._lock:
            if self._flights.get(key) is flight:
                del self._flights[key]
            if not flight.invalidated:  # a write landed during the read: what it read may be older than the write
                if len(self._entries) >= self._max_entries:
                    self._entries.clear()
                self._entries[key] = _Entry(started, value)
            flight.value, flight.ok = value, True
        flight.done.set()
        return value

    def invalidate(self, key: Hashable) -> None:
        """Forget `key`, and keep a read already in flight from storing (or handing out to new askers) older data."""
        with self._lock:
            self._entries.pop(key, None)
            flight = self._flights.pop(key, None)
            if flight is not None:
                flight.invalidated = True

    def invalidate_event(self, event_id: str) -> None:
        """Forget every item of `event_id` (keys are (namespace, event id, sort key)), reads in flight included: the
        writer says it changed (the live server's wake-up)."""
        with self._lock:
            for key in [key for key in self._entries if _event_of(key) == event_id]:
                del self._entries[key]
            for key in [key for key in self._flights if _event_of(key) == event_id]:
                self._flights.pop(key).invalidated = True

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()
            for flight in self._flights.values():
                flight.invalidated = True
            self._flights.clear()


def _event_of(key: Hashable) -> object:
    return key[1] if isinstance(key, tuple) and len(key) == 3 else None


PROCESS_CACHE = PublicViewCache()


SCREEN_KEY = "SCREEN"  # the big screen's settings around the board (domain/big_screen.py)


def board_key(track_id: str) -> str:
    return f"BOARD#{track_id}"


def board_page_key(track_id: str, page: int) -> str:
    """Where page `page` (2, 3, ...) of a long board is read from (the storage adapter writes it there)."""
    return f"BOARD#{track_id}~PAGE#{page}"


def overlay_key(track_id: str) -> str:
    return f"OVERLAY#{track_id}"


def _dumps(value: Any) -> str:
    return json.dumps(value, separators=(",", ":"), sort_keys=True)


def empty_board_body(event_id: str, track_id: str) -> str:
    return _dumps({"event_id": event_id, "track_id": track_id, "version": 0, "entries": []})


# The overlay statuses of a race on track (drem_leaderboard RaceStatus values).
LIVE_STATUSES = frozenset({"READY", "RUNNING", "PAUSED"})
# Overlay bodies parsed and kept per process: every poll of every screen reads the same few.
PARSED_OVERLAYS = 64


class OverlaySnapshot(BaseModel):
    """A materialised overlay body (`GET /api/overlay/{event}`, written by `publish_overlay`): the live race of one
    track."""
    model_config = ConfigDict(extra="ignore")
    track_id: str = "1"
    version: int = 0
    status: str = "NO_RACE"
    race_id: str | None = None
    username: str = ""
    raced_by_proxy: bool = False
    laps: int = 0
    valid_laps: int = 0
    last_lap_ms: int | None = None
    fastest_lap_ms: int | None = None
    fastest_average_ms: int | None = None
    ranking_method: str = "BEST_LAP_TIME"
    as_of_ms: int = 0
    running: bool = False
    time_left_ms: int = 0
    current_lap_ms: int = 0
    position: int | None = None
    gap_to_leader_ms: int | None = None

    @classmethod
    def parse(cls, body: str) -> OverlaySnapshot:
        return _parse_overlay(body)

    @property
    def is_live(self) -> bool:
        return self.status in LIVE_STATUSES

    def clocks_at(self, now_ms: int) -> tuple[int, int]:
        """(time left, current lap) at `now_ms`: the stored readings, advanced while the race runs."""
        elapsed = max(0, now_ms - self.as_of_ms) if self.running else 0
        return max(0, self.time_left_ms - elapsed), self.current_lap_ms + elapsed


@lru_cache(maxsize=PARSED_OVERLAYS)
def _parse_overlay(body: str) -> OverlaySnapshot:
    return OverlaySnapshot.model_validate(json.loads(body))



class LeaderboardPublisher:
    def __init__(self, boards: BoardRepository, clock_ms: Callable[[], int], *,
                 cache: PublicViewCache | None = PROCESS_CACHE,
                 on_change: Callable[[str], None] | None = None) -> None:
        """`cache=None` reads the table on every poll; the default shares this process's cache. `on_change(event_id)`
        is told after every write (the live server's wake-up)."""
        self._on_change = on_change
        self._boards = boards
        self._clock_ms = clock_ms
        self._cache = cache
        # Keeps two stores (tables) in one process apart in the shared cache.
        self._namespace = getattr(boards, "cache_namespace", "")

    # --- reads -------------------------------------------------------------------------------------------------

    def board(self, event_id: str, track_id: str) -> PublicView:
        found = self._public(event_id, board_key(track_id))
        return found or PublicView(version=0, etag='"v0"', body=empty_board_body(event_id, track_id))

    def board_page(self, event_id: str, track_id: str, page: int) -> PublicView | None:
        """Page `page` (1 = `board`) of a track's board; None past its last page."""
        if page <= 1:
            return self.board(event_id, track_id)
        return self._public(event_id, board_page_key(track_id, page))

    def overlay(self, event_id: str, track_id: str) -> PublicView:
        found = self._public(event_id, overlay_key(track_id))
        return found or PublicView(version=0, etag='"v0"', body=_dumps(
            {"event_id": event_id, "track_id": track_id, "version": 0, "status": "NO_RACE"}))

    def screen(self, event_id: str) -> PublicView:
        """The big screen's published settings (domain/big_screen.py); version 0 with an empty body when none."""
        return self._public(event_id, SCREEN_KEY) or PublicView(version=0, etag='"v0"', body="")

    # --- writes ------------------------------------------------------------------------------------------------

    def publish_screen(self, event_id: str, body: str) -> None:
        """Publish the big screen's settings (a new version only when they changed); open screens are woken."""
        etag = '"' + hashlib.sha256(body.encode()).hexdigest()[:32] + '"'
        self._write(event_id, SCREEN_KEY, lambda version, _state: (
            json.dumps({**json.loads(body), "version": version}, separators=(",", ":"), sort_keys=True), etag, ""),
            skip_unchanged=True)

    def refresh_racer(self, event_id: str, track_id: str, racer_sub: str, row: BoardRow | None,
                      method: RankingMethod, *, all_tracks: Iterable[str] = (), combined: bool = True) -> Leaderboard:
        """Replace one racer's row on a track's board (None removes it), re-rank, and refresh the combined board
        (`combined=False`: the caller does, with `refresh_combined`, once it has published what is more urgent)."""
        def change(rows: dict[str, BoardRow]) -> dict[str, BoardRow]:
            rows = {sub: r for sub, r in rows.items() if sub != racer_sub}
            if row is not None:
                rows[racer_sub] = row
            return rows

        board = self._write_board(event_id, track_id, method, change)
        if combined:
            self._refresh_combined(event_id, list(all_tracks), method)
        return board

    def publish_change(self, event_id: str, track_id: str, racer_sub: str, row: BoardRow | None,
                       method: RankingMethod, all_tracks: Iterable[str], *, race: Race | None, now_ms: int,
                       display_name: str, live_race_id: str | None) -> Leaderboard:
        """A race changed: the racer's row on the track's board, then the overlay (if `race` may show there), then
        the combined board. In that order, so the big screen and the stream overlay show a lap as soon as each can
        (the live server is woken by each write), the combined board last."""
        board = self.refresh_racer(event_id, track_id, racer_sub, row, method, combined=False)
        if race is not None and self._overlay_may_show(race, live_race_id):
            self.publish_overlay(race, now_ms, board, display_name)
        self._refresh_combined(event_id, list(all_tracks), method)
        return board

    def _overlay_may_show(self, race: Race, live_race_id: str | None) -> bool:
        """The overlay (and the commentator) follow the track's current race: the live one, else the one it shows
        now. A lap edit of an older race, or a replay of its publish, changes its board row but must not make it
        "current" again."""
        if live_race_id is not None:
            return live_race_id == race.race_id
        shown = json.loads(self.overlay(race.event_id, race.track_id).body).get("race_id")
        return shown in (None, race.race_id)

    def refresh_combined(self, event_id: str, all_tracks: Iterable[str], method: RankingMethod) -> Leaderboard:
        """Re-rank the combined board from every track board's rows."""
        return self._refresh_combined(event_id, list(all_tracks), method)

    def rebuild(self, event_id: str, rows_by_track: Mapping[str, list[BoardRow]], method: RankingMethod,
                all_tracks: Iterable[str]) -> dict[str, Leaderboard]:
        """Replace every board of an event from scratch (race admin's "recompute")."""
        tracks = list(all_tracks)
        boards = {track: self._write_board(event_id, track, method, _replace_rows(rows_by_track.get(track, [])))
                  for track in tracks}
        boards[COMBINED_TRACK_ID] = self._refresh_combined(event_id, tracks, method)
        return boards

    def publish_overlay(self, race: Race, now_ms: int, board: Leaderboard | None, display_name: str) -> None:
        display_name, entry = overlay_name(board, display_name, race.racer.sub, race.racer.username)
        fastest = race.fastest_valid_lap
        average = race.fastest_average
        state = {
            "event_id": race.event_id, "track_id": race.track_id, "race_id": race.race_id,
            "status": race.status.value, "username": display_name, "raced_by_proxy": race.raced_by_proxy,
            "laps": len(race.laps), "valid_laps": len(race.valid_laps),
            "last_lap_ms": race.laps[-1].time_ms if race.laps else None,
            "fastest_lap_ms": fastest.time_ms if fastest else None,
            "fastest_average_ms": average.avg_ms if average else None,
            "current_lap_resets": race.current_lap_resets, "resets_per_lap": race.config.resets_per_lap,
            "ranking_method": race.config.ranking_method.value, "race_time_ms": race.config.race_time_ms,
            # Clock readings as of `as_of_ms`; while `running`, a viewer adds the time since to interpolate.
            "as_of_ms": now_ms, "running": race.status is RaceStatus.RUNNING,
            "time_left_ms": race_time_left_ms(race, now_ms), "current_lap_ms": current_lap_ms(race, now_ms),
            "position": entry.position if entry else None,
            "gap_to_leader_ms": entry.gap_to_leader_ms if entry else None,
        }
        self._write(event_id=race.event_id, sort_key=overlay_key(race.track_id),
                    build=lambda version, _state: (_dumps({**state, "version": version}), f'"v{version}"', ""))

    # --- plumbing ----------------------------------------------------------------------------------------------

    def _public(self, event_id: str, sort_key: str) -> PublicView | None:
        if self._cache is None:
            return self._boards.public(event_id, sort_key)
        return self._cache.get((self._namespace, event_id, sort_key), lambda: self._boards.public(event_id, sort_key))

    def _invalidate(self, event_id: str, sort_key: str) -> None:
        if self._cache is not None:
            self._cache.invalidate((self._namespace, event_id, sort_key))

    def _write_board(self, event_id: str, track_id: str, method: RankingMethod,
                     change: Callable[[dict[str, BoardRow]], dict[str, BoardRow]]) -> Leaderboard:
        result: dict[str, Leaderboard] = {}

        def build(version: int, old_state: str) -> Built | None:
            old_rows = _rows(old_state)
            rows = change(old_rows)
            board = _ranked(rows.values(), method, track_id, version)
            result["board"] = board
            state = BoardState(rows=sorted(rows.values(), key=lambda r: r.summary.racer_sub)).model_dump_json()
            first, *further = _board_pages(event_id, board, self._clock_ms())
            return first, board.etag, state, further

        self._write(event_id, board_key(track_id), build, skip_unchanged=True)
        return result["board"]

    def _refresh_combined(self, event_id: str, tracks: list[str], method: RankingMethod) -> Leaderboard:
        rows: list[BoardRow] = []
        for track in tracks:
            stored = self._boards.get(event_id, board_key(track))
            rows.extend(_rows(stored.state).values() if stored else [])
        result: dict[str, Leaderboard] = {}

        def build(version: int, _old_state: str) -> Built:
            board = _ranked(rows, method, COMBINED_TRACK_ID, version)
            result["board"] = board
            first, *further = _board_pages(event_id, board, self._clock_ms())
            return first, board.etag, "", further

        self._write(event_id, board_key(COMBINED_TRACK_ID), build, skip_unchanged=True)
        return result["board"]

    def _write(self, event_id: str, sort_key: str, build: Callable[[int, str], Built | None], *,
               skip_unchanged: bool = False) -> None:
        for _ in range(BOARD_ATTEMPTS):
            current = self._boards.get(event_id, sort_key)
            version = (current.version if current else 0) + 1
            built = build(version, current.state if current else "")
            if built is None:
                return
            body, etag, state, *more = built
            pages = tuple(more[0]) if more else ()
            if skip_unchanged and current is not None and current.etag == etag and current.state == state:
                return
            try:
                self._boards.put(event_id, sort_key, Materialised(version=version, etag=etag, body=body, state=state,
                                                                  pages=pages),
                                 expected_version=current.version if current else None)
                if self._on_change is not None:
                    self._on_change(event_id)
                return
            except StaleBoard:
                continue
            finally:
                # Also after a failed put: its outcome is unknown (a timeout may have written it).
                self._invalidate(event_id, sort_key)
        raise Conflict("The leaderboard is being updated by someone else; try again.")


def overlay_name(board: Leaderboard | None, display_name: str, racer_sub: str,
                 sign_in_name: str) -> tuple[str, LeaderboardEntry | None]:
    """(the name the overlay shows, the racer's board entry): the name the board shows them by, so two racers of one
    display name are told apart there too ("Björn (bjorn_b)", drem_leaderboard.names)."""
    entries = board.entries if board else ()
    entry = next((e for e in entries if e.racer_sub == racer_sub), None)
    if entry is not None:
        return entry.username, entry
    # Not on the board yet (no lap): told apart when someone on it goes by the same display name.
    key = name_key(display_name)
    taken = any(name_key(e.username) == key or name_key(e.username).startswith(key + " (") for e in entries)
    return (with_sign_in_name(display_name, sign_in_name) if taken else display_name), None


def board_item_content(event_id: str, track_id: str, rows: Iterable[BoardRow], method: RankingMethod, version: int,
                       updated_at_ms: int) -> tuple[str, str]:
    """(body, etag) of the board item these rows give, exactly as the publisher writes it; `drem import` uses it to
    refuse an exported board whose public body was edited apart from its rows."""
    board = _ranked(rows, method, track_id, version)
    return _board_pages(event_id, board, updated_at_ms)[0], board.etag


def _rows(state: str) -> dict[str, BoardRow]:
    if not state:
        return {}
    return {row.summary.racer_sub: row for row in BoardState.model_validate_json(state).rows}


def _replace_rows(rows: list[BoardRow]) -> Callable[[dict[str, BoardRow]], dict[str, BoardRow]]:
    """A board change that drops whatever the board held and keeps these rows (one per racer)."""
    return lambda _old: {r.summary.racer_sub: r for r in rows}


def _ranked(rows: Iterable[BoardRow], method: RankingMethod, track_id: str, version: int) -> Leaderboard:
    rows = list(rows)
    return rank([r.summary for r in rows], method, track_id=track_id,
                profiles={r.summary.racer_sub: r.profile for r in rows}, version=version)


def _board_pages(event_id: str, board: Leaderboard, now_ms: int) -> list[str]:
    """The board's public bodies, one per page of BOARD_PAGE_ENTRIES entries. A board that fits one page is exactly
    what it always was; a longer one says on each page which page it is, how many there are and how many entries."""
    whole = {"event_id": event_id, "updated_at_ms": now_ms, **board.model_dump(mode="json")}
    entries = whole["entries"]
    if len(entries) <= BOARD_PAGE_ENTRIES:
        return [_dumps(whole)]
    count = -(-len(entries) // BOARD_PAGE_ENTRIES)
    return [_dumps({**whole, "entries": entries[(page - 1) * BOARD_PAGE_ENTRIES:page * BOARD_PAGE_ENTRIES],
                    "page": page, "pages": count, "total_entries": len(entries)}) for page in range(1, count + 1)]
