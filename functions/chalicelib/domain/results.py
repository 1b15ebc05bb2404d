"""After the race: the final standings of an event, per track board, as printed on the summary, podium sheet and
certificates (`results_pdf`).

Pure: built from the event's races and each racer's public profile with the same rules as the live board
(`drem_leaderboard.summary` + `ranking.rank`), so a printed position or time is the one the big screen showed. Only
submitted races count (a live race is not a result yet). Times are formatted like the pages (`0:08.838`).
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from datetime import date

from pydantic import BaseModel, ConfigDict

from chalicelib.domain.events import Event
from chalicelib.domain.profiles import PublicProfile
from chalicelib.formats.avatars import DEFAULT_COLOUR, NEUTRAL_COLOUR, avatar_seed, identicon_cells
from chalicelib.formats.figures import gap_time, lap_time, safe_colour
from drem_leaderboard.models import Race, RaceConfig, RankingMethod
from drem_leaderboard.ranking import COMBINED_TRACK_ID, RacerProfile, rank
from drem_leaderboard.summary import RaceSummary, summarise_racer

ProfileLookup = Callable[[list[str]], Mapping[str, PublicProfile]]  # subs → their public profiles (found ones)


class ResultEntry(BaseModel):
    model_config = ConfigDict(frozen=True)
    position: int
    username: str
    country_code: str
    colour: str
    avatar_cells: tuple[tuple[int, int], ...] | None  # the racer's identicon; None when they chose no avatar
    time: str
    gap: str
    best_lap: str
    valid_laps: int
    is_dnf: bool


class ResultsBoard(BaseModel):
    model_config = ConfigDict(frozen=True)
    track_id: str
    title: str
    ranking: str
    entries: tuple[ResultEntry, ...]

    @property
    def podium(self) -> tuple[ResultEntry, ...]:
        return tuple(e for e in self.entries[:3] if not e.is_dnf)


class EventResults(BaseModel):
    model_config = ConfigDict(frozen=True)
    event_id: str
    event_name: str
    event_date: date
    country_code: str
    sponsor: str
    boards: tuple[ResultsBoard, ...]

    def board(self, track_id: str) -> ResultsBoard | None:
        return next((b for b in self.boards if b.track_id == track_id), None)


def ranking_label(config: RaceConfig) -> str:
    if config.ranking_method is RankingMethod.BEST_AVERAGE_LAP_TIME_X_LAP:
        return f"Best average of {config.average_window} consecutive laps"
    if config.ranking_method is RankingMethod.LAP_COUNT:
        return "Most valid laps"
    return "Fastest lap"


def event_results(event: Event, races: Iterable[Race], profiles_of: ProfileLookup) -> EventResults:
    """Standings of every board of the event (each track, then the combined board when there are several)."""
    by_racer: dict[tuple[str, str], list[Race]] = {}
    for race in races:
        by_racer.setdefault((race.track_id, race.racer.sub), []).append(race)
    summaries = [s for _, group in sorted(by_racer.items()) if (s := summarise_racer(group)) is not None]
    found = profiles_of(sorted({s.racer_sub for s in summaries}))
    public = {s.racer_sub: found.get(s.racer_sub) for s in summaries}
    method = event.race_config.ranking_method
    boards = []
    for board_id in event.boards:
        title = _board_title(event, board_id)
        boards.append(_board(board_id, title, ranking_label(event.race_config), summaries, public, method))
    return EventResults(event_id=event.event_id, event_name=event.name, event_date=event.date,
                        country_code=event.country_code, sponsor=event.sponsor, boards=tuple(boards))


def _board_title(event: Event, board_id: str) -> str:
    if board_id == COMBINED_TRACK_ID:
        return "All tracks combined"
    track = event.track(board_id)
    return track.leaderboard_title or f"Track {board_id}"


def _board(board_id: str, title: str, ranking: str, summaries: list[RaceSummary],
           public: dict[str, PublicProfile | None], method: RankingMethod) -> ResultsBoard:
    profiles = {sub: _racer_profile(p) for sub, p in public.items() if p is not None}
    board = rank(summaries, method, track_id=board_id, profiles=profiles)
    entries = []
    for entry in board.entries:
        profile = public.get(entry.racer_sub)
        avatar = profile is not None and profile.avatar_url is not None and not profile.deleted
        entries.append(ResultEntry(
            position=entry.position, username=entry.username, country_code=(entry.country_code or "").upper(),
            # The board's colours: a racer who never picked one has the default stripe (grey only for the deleted).
            colour=safe_colour(profile.highlight_colour if profile else None, _unpicked_colour(profile)),
            avatar_cells=tuple(identicon_cells(avatar_seed(profile.username))) if avatar and profile else None,
            time=lap_time(entry.time_ms), gap=gap_time(entry.gap_to_leader_ms),
            best_lap=lap_time(entry.fastest_lap_ms), valid_laps=entry.laps, is_dnf=entry.is_dnf))
    return ResultsBoard(track_id=board_id, title=title, ranking=ranking, entries=tuple(entries))


def _unpicked_colour(profile: PublicProfile | None) -> str:
    return (NEUTRAL_COLOUR if profile is None or profile.deleted else DEFAULT_COLOUR).lower()


def _racer_profile(profile: PublicProfile) -> RacerProfile:
    return RacerProfile(username=profile.display_name or profile.username, country_code=profile.country_code,
                        highlight_colour=profile.highlight_colour)
