"""View models for the public leaderboard page, the stream overlay and the commentator view.

Pure: they turn the materialised board/overlay items (the same bodies `GET /api/leaderboard|overlay/{event}` serve)
and, for lap detail, the live race into rows the templates print as they are: positions, m:ss.mmm strings, gaps,
flags, F1 colour classes. No template decides anything; nothing here reads storage or the clock.

Every colour that reaches CSS passes `safe_colour` (hex only), every flag `flag_emoji` (two ASCII letters only), so
no user-supplied text is ever interpolated into a style or an attribute outside jinja's autoescaping.
"""
from __future__ import annotations

import json
import re
from collections.abc import Callable, Iterable, Sequence
from functools import lru_cache
from typing import Literal

from pydantic import BaseModel, ConfigDict

from chalicelib.domain.leaderboards import OverlaySnapshot
from chalicelib.formats.figures import gap_time, lap_time, safe_colour
from drem_leaderboard.models import Lap, Race
from drem_leaderboard.ranking import COMBINED_TRACK_ID, DEFAULT_HIGHLIGHT_COLOUR, LeaderboardEntry

BoardFormat = Literal["fastest", "average"]
LapColour = Literal["purple", "green", "yellow", "red"]
OverlayPhase = Literal["racing", "post_race", "standings"]

DEFAULT_CHROMA = "#00ff00"
POST_RACE_HIGHLIGHT_MS = 30_000
DEFAULT_SUMMARY_SECONDS = 12  # DREM's leaderboard holds its race-summary footer for 12 s after a new entry
OVERLAY_TOP = 4
FINISHED_STATUSES = frozenset({"OVER", "SUBMITTED"})
_STATUS_LABELS = {"READY": "ready_to_start", "RUNNING": "now_racing", "PAUSED": "paused", "OVER": "finished",
                  "SUBMITTED": "finished"}
_PODIUM = {1: "gold", 2: "silver", 3: "bronze"}
_ALPHA2 = re.compile(r"[A-Za-z]{2}")
_REGIONAL_INDICATOR_A = 0x1F1E6
# Every poll parses the board/overlay bodies it was handed (for the version token); the poll cache hands out the same
# body for a while, so parsing each distinct body once saves validating a 50-row board hundreds of times a second.
# Callers share the parsed snapshot: nothing here mutates one (re-ranking sorts a copy, highlighting copies rows).
PARSED_BODIES = 64


# --- formatting ------------------------------------------------------------------------------------------------------


def clock_time(ms: int) -> str:
    """A countdown as m:ss (whole seconds, rounded up so 0:00 means the time is really over)."""
    seconds = (max(0, ms) + 999) // 1000
    return f"{seconds // 60}:{seconds % 60:02d}"


def signed_gap(ms: int | None) -> str:
    """A commentator's gap: +0.123 slower, -0.123 faster, ±0.000 level, – when there is nothing to compare."""
    if ms is None:
        return "–"
    if ms == 0:
        return "±0.000"
    return gap_time(ms) if ms > 0 else "-" + gap_time(-ms)[1:]


def flag_emoji(country_code: str | None) -> str:
    """The flag of an ISO 3166 alpha-2 code as two regional-indicator symbols; "" for anything else."""
    code = (country_code or "").strip()
    if not _ALPHA2.fullmatch(code):
        return ""
    return "".join(chr(_REGIONAL_INDICATOR_A + ord(letter) - ord("A")) for letter in code.upper())


# --- the stored items ------------------------------------------------------------------------------------------------


class BoardSnapshot(BaseModel):
    """A materialised board body (`GET /api/leaderboard/{event}`)."""
    model_config = ConfigDict(extra="ignore")
    track_id: str = COMBINED_TRACK_ID
    version: int = 0
    entries: list[LeaderboardEntry] = []

    @classmethod
    def parse(cls, body: str) -> BoardSnapshot:
        return _parse_board(body)

    @property
    def event_best_lap_ms(self) -> int | None:
        return min((e.fastest_lap_ms for e in self.entries if e.fastest_lap_ms is not None), default=None)


@lru_cache(maxsize=PARSED_BODIES)
def _parse_board(body: str) -> BoardSnapshot:
    return BoardSnapshot.model_validate(json.loads(body))


def version_token(*versions: int | str) -> str:
    """What a page's poll carries as `v=`: every item version (and phase) the rendered fragment was built from."""
    return ".".join(str(v) for v in versions)


# --- leaderboard -----------------------------------------------------------------------------------------------------


class BoardRowView(BaseModel):
    position: int
    podium: str
    racer: str
    flag: str
    country_code: str
    colour: str
    proxy: bool
    time: str
    time_ms: int | None
    gap: str
    laps: int
    avatar: str = ""
    initial: str = ""
    highlighted: bool = False


def _figure(entry: LeaderboardEntry, fmt: BoardFormat | None) -> int | None:
    if fmt == "fastest":
        return entry.fastest_lap_ms
    if fmt == "average":
        return entry.fastest_average.avg_ms if entry.fastest_average else None
    return entry.time_ms


def board_rows(board: BoardSnapshot, fmt: BoardFormat | None, t: Callable[[str], str], *,
               show_flags: bool = True) -> list[BoardRowView]:
    """Rows in display order. `fmt` None keeps the event's ranking; "fastest"/"average" re-rank by that figure
    (stable: equal figures keep the board's order; racers without one are last, as DNF)."""
    entries = list(board.entries)
    if fmt is not None:
        entries.sort(key=lambda e: (_figure(e, fmt) is None, _figure(e, fmt) or 0))
    leader = _figure(entries[0], fmt) if entries else None
    rows = []
    for position, entry in enumerate(entries, start=1):
        figure = _figure(entry, fmt)
        gap = (entry.gap_to_leader_ms if fmt is None
               else (figure - leader if figure is not None and leader is not None else None))
        rows.append(BoardRowView(
            position=position, podium=_PODIUM.get(position, ""), racer=entry.username,
            flag=flag_emoji(entry.country_code) if show_flags else "",
            country_code=(entry.country_code or "").upper() if flag_emoji(entry.country_code) else "",
            colour=safe_colour(entry.highlight_colour, DEFAULT_HIGHLIGHT_COLOUR.lower()),
            proxy=entry.raced_by_proxy, time=lap_time(figure, t("dnf")), time_ms=figure, gap=gap_time(gap),
            laps=entry.laps, avatar=avatar_src(entry), initial=initial(entry.username)))
    return rows


# The only avatar address a board item may name: the profile route of a sign-in name (display names, which boards
# show, may be in any script and are not addresses).
_AVATAR_PATH = re.compile(r"^/api/profiles/[A-Za-z0-9._-]{1,128}/avatar\.svg$")


def avatar_src(entry: LeaderboardEntry | None) -> str:
    """The racer's identicon URL ("" when they chose none): the item's address, used only when it is a profile
    route; the colour in the query makes a changed highlight colour fetch a fresh image."""
    if entry is None or not entry.avatar_url or not _AVATAR_PATH.match(entry.avatar_url):
        return ""
    colour = safe_colour(entry.highlight_colour, DEFAULT_HIGHLIGHT_COLOUR.lower())
    return f"{entry.avatar_url}?c={colour[1:]}"


def initial(name: str) -> str:
    """What stands in for a missing avatar: the name's first letter or digit, upper-cased."""
    return next((c.upper() for c in name if c.isalnum()), "?")


class RaceFooterView(BaseModel):
    """The live race line under the board (and the lower third's clocks)."""
    track_id: str
    racer: str
    flag: str
    country_code: str
    colour: str
    proxy: bool
    status_label: str
    running: bool
    time_left_ms: int
    time_left: str
    current_lap_ms: int
    current_lap: str
    laps: int
    best_label: str
    best: str


def race_footer(overlay: OverlaySnapshot, now_ms: int, t: Callable[[str], str],
                racer_entry: LeaderboardEntry | None = None, *, show_flags: bool = True) -> RaceFooterView | None:
    """The footer while a race is READY/RUNNING/PAUSED on the overlay's track; None otherwise."""
    if not overlay.is_live:
        return None
    time_left, current_lap = overlay.clocks_at(now_ms)
    average = overlay.ranking_method == "BEST_AVERAGE_LAP_TIME_X_LAP"
    best_ms = overlay.fastest_average_ms if average else overlay.fastest_lap_ms
    flag = flag_emoji(racer_entry.country_code) if racer_entry and show_flags else ""
    return RaceFooterView(
        track_id=overlay.track_id, racer=overlay.username, flag=flag,
        country_code=(racer_entry.country_code or "").upper() if racer_entry and flag else "",
        colour=safe_colour(racer_entry.highlight_colour if racer_entry else None, DEFAULT_HIGHLIGHT_COLOUR.lower()),
        proxy=overlay.raced_by_proxy, status_label=t(_STATUS_LABELS[overlay.status]), running=overlay.running,
        time_left_ms=time_left, time_left=clock_time(time_left), current_lap_ms=current_lap,
        current_lap=lap_time(current_lap), laps=overlay.valid_laps,
        best_label=t("best_average" if average else "best_lap"), best=lap_time(best_ms, "–"))


def entry_for(board: BoardSnapshot, username: str) -> LeaderboardEntry | None:
    return next((e for e in board.entries if e.username == username), None)


# --- the race summary the big screen holds after each race -----------------------------------------------------------


class RaceSummaryView(BaseModel):
    """The just-submitted race of one track, shown in place of the rows for `summary_seconds`."""
    track_id: str
    racer: str
    avatar: str
    initial: str
    flag: str
    country_code: str
    colour: str
    proxy: bool
    position: str
    best_label: str
    best: str
    laps: int
    gap: str


def summary_held(overlay: OverlaySnapshot, now_ms: int, hold_ms: int) -> bool:
    """True while a race submitted `now_ms - as_of_ms` ago is still within the hold. Only a submitted race: its result
    is on the board, so the position is real. A new race on the track makes the overlay live and ends the hold."""
    return overlay.status == "SUBMITTED" and 0 <= now_ms - overlay.as_of_ms < hold_ms


def race_summary(overlay: OverlaySnapshot, board: BoardSnapshot, t: Callable[[str], str], *,
                 show_flags: bool = True) -> RaceSummaryView:
    entry = entry_for(board, overlay.username)
    average = overlay.ranking_method == "BEST_AVERAGE_LAP_TIME_X_LAP"
    best_ms = overlay.fastest_average_ms if average else overlay.fastest_lap_ms
    flag = flag_emoji(entry.country_code) if entry and show_flags else ""
    leading = overlay.position == 1
    return RaceSummaryView(
        track_id=overlay.track_id, racer=overlay.username, avatar=avatar_src(entry), initial=initial(overlay.username),
        flag=flag, country_code=(entry.country_code or "").upper() if entry and flag else "",
        colour=safe_colour(entry.highlight_colour if entry else None, DEFAULT_HIGHLIGHT_COLOUR.lower()),
        proxy=overlay.raced_by_proxy, position=f"P{overlay.position}" if overlay.position else "–",
        best_label=t("best_average" if average else "best_lap"), best=lap_time(best_ms, t("no_valid_lap")),
        laps=overlay.valid_laps, gap=t("in_the_lead") if leading else (gap_time(overlay.gap_to_leader_ms) or "–"))


# --- F1 lap colours --------------------------------------------------------------------------------------------------


def lap_colour(lap: Lap, race_best_ms: int | None, event_best_ms: int | None) -> LapColour:
    """purple = fastest of the event, green = fastest of this race, yellow = valid, red = invalid."""
    if not lap.is_valid:
        return "red"
    if event_best_ms is not None and lap.time_ms <= event_best_ms:
        return "purple"
    if race_best_ms is not None and lap.time_ms <= race_best_ms:
        return "green"
    return "yellow"


def figure_colour(ms: int | None, race_best_ms: int | None, event_best_ms: int | None) -> str:
    """The colour class of a valid figure (a best lap): purple/green/yellow, "" when there is none."""
    if ms is None:
        return ""
    return lap_colour(Lap(lap_id=0, time_ms=ms, is_valid=True, source="manual", captured_at_ms=0),
                      race_best_ms, event_best_ms)


# --- overlay ---------------------------------------------------------------------------------------------------------


class LowerThirdView(BaseModel):
    footer: RaceFooterView
    best_colour: str
    previous_lap: str
    previous_colour: str
    # Where the racer stands on the board right now, and how far behind the leader ("" when leading or unranked).
    position: str = "–"
    gap_to_leader: str = ""


class OverlayView(BaseModel):
    phase: OverlayPhase
    lower_third: LowerThirdView | None = None
    rows: list[BoardRowView] = []
    show_standings: bool = True


def overlay_phase(overlay: OverlaySnapshot, now_ms: int) -> OverlayPhase:
    if overlay.is_live:
        return "racing"
    if overlay.status in FINISHED_STATUSES and now_ms - overlay.as_of_ms < POST_RACE_HIGHLIGHT_MS:
        return "post_race"
    return "standings"


def top_window(rows: Sequence[BoardRowView], focus: str | None, size: int = OVERLAY_TOP) -> list[BoardRowView]:
    """The top `size` rows; if `focus` ranks below them, the `size`-row window ending at them. Focus is highlighted."""
    index = next((i for i, row in enumerate(rows) if focus is not None and row.racer == focus), None)
    start = 0 if index is None or index < size else index - size + 1
    return [row.model_copy(update={"highlighted": i == index}) for i, row in enumerate(rows[start:start + size],
                                                                                          start=start)]


def overlay_view(overlay: OverlaySnapshot, board: BoardSnapshot, race: Race | None, now_ms: int,
                 t: Callable[[str], str], *, fmt: BoardFormat | None = None, show_flags: bool = True,
                 show_standings: bool = True) -> OverlayView:
    phase = overlay_phase(overlay, now_ms)
    rows = board_rows(board, fmt, t, show_flags=show_flags)
    if phase == "racing":
        footer = race_footer(overlay, now_ms, t, entry_for(board, overlay.username), show_flags=show_flags)
        assert footer is not None
        event_best = board.event_best_lap_ms
        previous = race.laps[-1] if race is not None and race.laps else None
        return OverlayView(phase=phase, show_standings=show_standings, lower_third=LowerThirdView(
            footer=footer, best_colour=figure_colour(overlay.fastest_lap_ms, overlay.fastest_lap_ms, event_best),
            previous_lap=lap_time(previous.time_ms) if previous else "–",
            previous_colour=lap_colour(previous, overlay.fastest_lap_ms, event_best) if previous else "",
            position=f"P{overlay.position}" if overlay.position else "–",
            gap_to_leader=gap_time(overlay.gap_to_leader_ms)))
    focus = overlay.username if phase == "post_race" else None
    return OverlayView(phase=phase, rows=top_window(rows, focus), show_standings=show_standings)


# --- commentator -----------------------------------------------------------------------------------------------------


class LapRowView(BaseModel):
    number: int
    time: str
    time_ms: int
    resets: int
    valid: bool
    colour: LapColour


class ChartBar(BaseModel):
    x: float
    y: float
    width: float
    height: float
    colour: LapColour
    label: str
    number: int


class LapChart(BaseModel):
    width: int
    height: int
    bars: list[ChartBar]
    best_line_y: float | None
    best_label: str


class CommentatorView(BaseModel):
    footer: RaceFooterView | None
    status: str
    racer: str
    position_now: str
    projected_position: str
    gap_to_fastest: str
    fastest_lap: str
    fastest_lap_number: str
    fastest_average: str
    average_window: str
    event_best: str
    laps: list[LapRowView]
    chart: LapChart


def projected_position(board: BoardSnapshot, racer: str, figure_ms: int | None) -> int | None:
    """Where `figure_ms` would rank among everyone else's ranked times (equal times go behind, as they came first)."""
    if figure_ms is None:
        return None
    others = [e.time_ms for e in board.entries if e.username != racer and e.time_ms is not None]
    return 1 + sum(1 for other in others if other <= figure_ms)


def lap_rows(race: Race | None, event_best_ms: int | None) -> list[LapRowView]:
    if race is None:
        return []
    race_best = race.fastest_valid_lap.time_ms if race.fastest_valid_lap else None
    return [LapRowView(number=lap.lap_id + 1, time=lap_time(lap.time_ms), time_ms=lap.time_ms, resets=lap.resets,
                       valid=lap.is_valid, colour=lap_colour(lap, race_best, event_best_ms)) for lap in race.laps]


def lap_chart(laps: Iterable[LapRowView], event_best_ms: int | None, best_label: str, *, width: int = 640,
              height: int = 240) -> LapChart:
    """Bar per lap, height ∝ lap time (the tallest lap or the event best fills the plot), a line at the event best."""
    laps = list(laps)
    top = max([lap.time_ms for lap in laps] + [event_best_ms or 0, 1]) * 1.1
    plot_height = height - 24  # room for the lap numbers under the bars
    slot = width / max(len(laps), 1)
    bars = [ChartBar(x=round(i * slot + slot * 0.15, 1), width=round(slot * 0.7, 1),
                     height=round(plot_height * lap.time_ms / top, 1),
                     y=round(plot_height - plot_height * lap.time_ms / top, 1), colour=lap.colour, label=lap.time,
                     number=lap.number) for i, lap in enumerate(laps)]
    best_y = round(plot_height - plot_height * event_best_ms / top, 1) if event_best_ms else None
    return LapChart(width=width, height=height, bars=bars, best_line_y=best_y,
                    best_label=f"{best_label} {lap_time(event_best_ms)}" if event_best_ms else "")


def commentator_view(overlay: OverlaySnapshot, board: BoardSnapshot, race: Race | None, now_ms: int,
                     t: Callable[[str], str]) -> CommentatorView:
    entry = entry_for(board, overlay.username)
    event_best = board.event_best_lap_ms
    others_best = min((e.fastest_lap_ms for e in board.entries
                       if e.username != overlay.username and e.fastest_lap_ms is not None), default=None)
    fastest = race.fastest_valid_lap if race is not None else None
    average = race.fastest_average if race is not None else None
    ranked_figure = average.avg_ms if overlay.ranking_method == "BEST_AVERAGE_LAP_TIME_X_LAP" and average else (
        fastest.time_ms if fastest else None)
    gap = fastest.time_ms - others_best if fastest is not None and others_best is not None else None
    laps = lap_rows(race, event_best)
    projected = projected_position(board, overlay.username, ranked_figure)
    return CommentatorView(
        footer=race_footer(overlay, now_ms, t, entry), status=t(_STATUS_LABELS.get(overlay.status, "no_race")),
        racer=overlay.username, position_now=str(overlay.position or "–"),
        projected_position=str(projected or "–"),
        gap_to_fastest=signed_gap(gap),
        fastest_lap=lap_time(fastest.time_ms if fastest else None, "–"),
        fastest_lap_number=str(fastest.lap_id + 1) if fastest else "",
        fastest_average=lap_time(average.avg_ms if average else None, "–"),
        average_window=f"{average.start_lap_id + 1} - {average.end_lap_id + 1}" if average else "",
        event_best=lap_time(event_best, "–"), laps=laps, chart=lap_chart(laps, event_best, t("event_best")))
