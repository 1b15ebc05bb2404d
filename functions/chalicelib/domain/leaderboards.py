"""Materialised leaderboards and overlays: rebuilt by the race service on every change, read by polls with one GetItem.

A board item keeps, next to its public body, the state it was ranked from: one `BoardRow` (summary + profile) per
racer. Refreshing one racer replaces their row and re-ranks; nothing else is read. The combined board is ranked from
the rows of every track board; it is written for single-track events too (then equal to the track's board), so a
poll without `?track=` always finds a board without looking the event up. Versions go up by one per write; a write is skipped
when neither what viewers see (the board's etag) nor the stored rows changed, so polls keep getting 304.
"""
from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Mapping
from typing import Any, Protocol

from pydantic import BaseModel, ConfigDict

from chalicelib.domain.errors import Conflict
from drem_leaderboard.models import Race, RaceStatus, RankingMethod
from drem_leaderboard.race_clock import current_lap_ms, race_time_left_ms
from drem_leaderboard.ranking import COMBINED_TRACK_ID, Leaderboard, RacerProfile, rank
from drem_leaderboard.summary import RaceSummary

BOARD_ATTEMPTS = 4


class StaleBoard(Exception):
    """Another writer changed the board/overlay item since it was read; re-read and try again."""


class PublicView(BaseModel):
    model_config = ConfigDict(frozen=True)
    version: int
    etag: str
    body: str


class Materialised(PublicView):
    state: str = ""


class BoardRow(BaseModel):
    model_config = ConfigDict(frozen=True)
    summary: RaceSummary
    profile: RacerProfile


class BoardState(BaseModel):
    rows: list[BoardRow] = []


class BoardRepository(Protocol):
    def public(self, event_id: str, sort_key: str) -> PublicView | None: ...
    def get(self, event_id: str, sort_key: str) -> Materialised | None: ...
    def put(self, event_id: str, sort_key: str, item: Materialised, expected_version: int | None) -> None: ...


def board_key(track_id: str) -> str:
    return f"BOARD#{track_id}"


def overlay_key(track_id: str) -> str:
    return f"OVERLAY#{track_id}"


def _dumps(value: Any) -> str:
    return json.dumps(value, separators=(",", ":"), sort_keys=True)


def empty_board_body(event_id: str, track_id: str) -> str:
    return _dumps({"event_id": event_id, "track_id": track_id, "version": 0, "entries": []})


class LeaderboardPublisher:
    def __init__(self, boards: BoardRepository, clock_ms: Callable[[], int]) -> None:
        self._boards = boards
        self._clock_ms = clock_ms

    # --- reads -------------------------------------------------------------------------------------------------

    def board(self, event_id: str, track_id: str) -> PublicView:
        found = self._boards.public(event_id, board_key(track_id))
        return found or PublicView(version=0, etag='"v0"', body=empty_board_body(event_id, track_id))

    def overlay(self, event_id: str, track_id: str) -> PublicView:
        found = self._boards.public(event_id, overlay_key(track_id))
        return found or PublicView(version=0, etag='"v0"', body=_dumps(
            {"event_id": event_id, "track_id": track_id, "version": 0, "status": "NO_RACE"}))

    # --- writes ------------------------------------------------------------------------------------------------

    def refresh_racer(self, event_id: str, track_id: str, racer_sub: str, row: BoardRow | None,
                      method: RankingMethod, *, all_tracks: Iterable[str] = ()) -> Leaderboard:
        """Replace one racer's row on a track's board (None removes it), re-rank, and refresh the combined board."""
        def change(rows: dict[str, BoardRow]) -> dict[str, BoardRow]:
            rows = {sub: r for sub, r in rows.items() if sub != racer_sub}
            if row is not None:
                rows[racer_sub] = row
            return rows

        board = self._write_board(event_id, track_id, method, change)
        self._refresh_combined(event_id, list(all_tracks), method)
        return board

    def rebuild(self, event_id: str, rows_by_track: Mapping[str, list[BoardRow]], method: RankingMethod,
                all_tracks: Iterable[str]) -> dict[str, Leaderboard]:
        """Replace every board of an event from scratch (race admin's "recompute")."""
        tracks = list(all_tracks)
        boards = {track: self._write_board(event_id, track, method,
                                           lambda _old, t=track: {r.summary.racer_sub: r for r in rows_by_track.get(t, [])})
                  for track in tracks}
        boards[COMBINED_TRACK_ID] = self._refresh_combined(event_id, tracks, method)
        return boards

    def publish_overlay(self, race: Race, now_ms: int, board: Leaderboard | None, display_name: str) -> None:
        entry = next((e for e in board.entries if e.username == display_name), None) if board else None
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
            "position": entry.position if entry else None, "gap_to_leader_ms": entry.gap_to_leader_ms if entry else None,
        }
        self._write(event_id=race.event_id, sort_key=overlay_key(race.track_id),
                    build=lambda version, _state: (_dumps({**state, "version": version}), f'"v{version}"', ""))

    # --- plumbing ----------------------------------------------------------------------------------------------

    def _write_board(self, event_id: str, track_id: str, method: RankingMethod,
                     change: Callable[[dict[str, BoardRow]], dict[str, BoardRow]]) -> Leaderboard:
        result: dict[str, Leaderboard] = {}

        def build(version: int, old_state: str) -> tuple[str, str, str] | None:
            old_rows = _rows(old_state)
            rows = change(old_rows)
            board = _ranked(rows.values(), method, track_id, version)
            result["board"] = board
            state = BoardState(rows=sorted(rows.values(), key=lambda r: r.summary.racer_sub)).model_dump_json()
            return _board_body(event_id, board, self._clock_ms()), board.etag, state

        self._write(event_id, board_key(track_id), build, skip_unchanged=True)
        return result["board"]

    def _refresh_combined(self, event_id: str, tracks: list[str], method: RankingMethod) -> Leaderboard:
        rows: list[BoardRow] = []
        for track in tracks:
            stored = self._boards.get(event_id, board_key(track))
            rows.extend(_rows(stored.state).values() if stored else [])
        result: dict[str, Leaderboard] = {}

        def build(version: int, _old_state: str) -> tuple[str, str, str]:
            board = _ranked(rows, method, COMBINED_TRACK_ID, version)
            result["board"] = board
            return _board_body(event_id, board, self._clock_ms()), board.etag, ""

        self._write(event_id, board_key(COMBINED_TRACK_ID), build, skip_unchanged=True)
        return result["board"]

    def _write(self, event_id: str, sort_key: str, build: Callable[[int, str], tuple[str, str, str] | None], *,
               skip_unchanged: bool = False) -> None:
        for _ in range(BOARD_ATTEMPTS):
            current = self._boards.get(event_id, sort_key)
            version = (current.version if current else 0) + 1
            built = build(version, current.state if current else "")
            if built is None:
                return
            body, etag, state = built
            if skip_unchanged and current is not None and current.etag == etag and current.state == state:
                return
            try:
                self._boards.put(event_id, sort_key, Materialised(version=version, etag=etag, body=body, state=state),
                                 expected_version=current.version if current else None)
                return
            except StaleBoard:
                continue
        raise Conflict("The leaderboard is being updated by someone else; try again.")


def _rows(state: str) -> dict[str, BoardRow]:
    if not state:
        return {}
    return {row.summary.racer_sub: row for row in BoardState.model_validate_json(state).rows}


def _ranked(rows: Iterable[BoardRow], method: RankingMethod, track_id: str, version: int) -> Leaderboard:
    rows = list(rows)
    return rank([r.summary for r in rows], method, track_id=track_id,
                profiles={r.summary.racer_sub: r.profile for r in rows}, version=version)


def _board_body(event_id: str, board: Leaderboard, now_ms: int) -> str:
    return _dumps({"event_id": event_id, "updated_at_ms": now_ms, **board.model_dump(mode="json")})
