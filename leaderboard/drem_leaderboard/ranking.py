"""Leaderboards built from race summaries: one per track, and a combined one with each racer's best across tracks.

Order is total and deterministic: the ranked figure first, then who achieved it first (server clock), then username.
Racers with no valid lap are last and shown as DNF.
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Mapping
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, computed_field

from drem_leaderboard.averages import AverageWindow
from drem_leaderboard.models import RankingMethod
from drem_leaderboard.names import told_apart
from drem_leaderboard.summary import RaceSummary

COMBINED_TRACK_ID = "combined"
DEFAULT_HIGHLIGHT_COLOUR = "#0000FF"


class RacerProfile(BaseModel):
    """What the board shows about a racer beyond their results; looked up by the caller (Cognito / profiles)."""

    model_config = ConfigDict(frozen=True)

    username: str | None = None
    country_code: str | None = Field(default=None, max_length=8)
    highlight_colour: str | None = None
    avatar_url: str | None = Field(default=None, description="the racer's public identicon; None: no avatar chosen")


class LeaderboardEntry(BaseModel):
    model_config = ConfigDict(frozen=True)

    position: int = Field(ge=1)
    username: str
    # Whose entry this is, for the server alone (the overlay finds its racer's entry by it, not by a name two racers
    # may share): never in the public JSON, nor in the etag.
    racer_sub: str = Field(default="", exclude=True)
    country_code: str | None = None
    highlight_colour: str = DEFAULT_HIGHLIGHT_COLOUR
    avatar_url: str | None = None
    raced_by_proxy: bool = False
    track_id: str
    time_ms: int | None = Field(description="the ranked figure; None shows as DNF")
    gap_to_leader_ms: int | None = Field(
        default=None, description="time_ms - leader's time_ms; None for DNF or (LAP_COUNT) a different lap count"
    )
    fastest_lap_ms: int | None = None
    fastest_average: AverageWindow | None = None
    laps: int = Field(description="valid laps; under LAP_COUNT the valid laps of the racer's best race")
    is_dnf: bool = Field(description="no valid lap at all")


class Leaderboard(BaseModel):
    model_config = ConfigDict(frozen=True)

    track_id: str
    ranking_method: RankingMethod
    entries: tuple[LeaderboardEntry, ...] = ()
    version: int = Field(default=0, ge=0)

    @computed_field  # type: ignore[prop-decorator]
    @property
    def etag(self) -> str:
        """Changes exactly when what a viewer sees changes; the version counter is left out on purpose."""
        content = self.model_dump(mode="json", exclude={"version", "etag"})
        digest = hashlib.sha256(json.dumps(content, sort_keys=True, separators=(",", ":")).encode()).hexdigest()
        return f'"{digest[:32]}"'


def _sort_key(summary: RaceSummary, method: RankingMethod, username: str) -> tuple[Any, ...]:
    if method is RankingMethod.BEST_AVERAGE_LAP_TIME_X_LAP and summary.fastest_average is not None:
        return (0, summary.fastest_average.avg_ms, summary.fastest_average.achieved_at_ms, username)
    if method is RankingMethod.LAP_COUNT and summary.best_lap_count is not None:
        best = summary.best_lap_count
        return (0, -best.valid_laps, best.elapsed_ms, best.achieved_at_ms, username)
    if summary.fastest_lap_ms is not None and summary.fastest_lap_at_ms is not None:
        # Under the average method a racer without a full window ranks after every racer with one, by fastest lap.
        tier = 0 if method is RankingMethod.BEST_LAP_TIME else 1
        return (tier, summary.fastest_lap_ms, summary.fastest_lap_at_ms, username)
    return (2, username)


def _ranked_time(summary: RaceSummary, method: RankingMethod) -> int | None:
    if method is RankingMethod.BEST_LAP_TIME:
        return summary.fastest_lap_ms
    if method is RankingMethod.BEST_AVERAGE_LAP_TIME_X_LAP:
        return summary.fastest_average.avg_ms if summary.fastest_average else None
    return summary.best_lap_count.elapsed_ms if summary.best_lap_count else None


def _laps(summary: RaceSummary, method: RankingMethod) -> int:
    if method is RankingMethod.LAP_COUNT:
        return summary.best_lap_count.valid_laps if summary.best_lap_count else 0
    return summary.valid_laps


def _display_name(summary: RaceSummary, profiles: Mapping[str, RacerProfile]) -> str:
    profile = profiles.get(summary.racer_sub)
    return profile.username if profile and profile.username else summary.username


def shown_names(summaries: Iterable[RaceSummary], profiles: Mapping[str, RacerProfile]) -> dict[str, str]:
    """{racer sub: the name a board shows}: the display name, with the sign-in name after it when another racer
    on the same board goes by the same display name (drem_leaderboard.names)."""
    return told_apart({s.racer_sub: (_display_name(s, profiles), s.username) for s in summaries})


def rank(
    summaries: Iterable[RaceSummary],
    method: RankingMethod,
    *,
    track_id: str,
    profiles: Mapping[str, RacerProfile] | None = None,
    version: int = 0,
) -> Leaderboard:
    """The board for one track (only summaries of ``track_id`` are used), or for COMBINED_TRACK_ID: every racer
    once, with their best result on any track."""
    profiles = profiles or {}
    chosen = [s for s in summaries if track_id == COMBINED_TRACK_ID or s.track_id == track_id]
    shown = shown_names(chosen, profiles)
    keyed = [(_sort_key(s, method, shown[s.racer_sub]), s) for s in chosen]
    if track_id == COMBINED_TRACK_ID:
        best: dict[str, tuple[tuple[Any, ...], RaceSummary]] = {}
        for key, summary in keyed:
            current = best.get(summary.racer_sub)
            if current is None or (key, summary.track_id) < (current[0], current[1].track_id):
                best[summary.racer_sub] = (key, summary)
        keyed = list(best.values())
    ordered = [s for _, s in sorted(keyed, key=lambda pair: (pair[0], pair[1].racer_sub))]
    return Leaderboard(
        track_id=track_id,
        ranking_method=method,
        entries=tuple(_entries(ordered, method, profiles, shown)),
        version=version,
    )


def _entries(
    ordered: list[RaceSummary], method: RankingMethod, profiles: Mapping[str, RacerProfile], shown: Mapping[str, str]
) -> Iterable[LeaderboardEntry]:
    leader_time = _ranked_time(ordered[0], method) if ordered else None
    leader_laps = _laps(ordered[0], method) if ordered else 0
    for position, summary in enumerate(ordered, start=1):
        profile = profiles.get(summary.racer_sub, RacerProfile())
        time_ms = _ranked_time(summary, method)
        laps = _laps(summary, method)
        comparable = method is not RankingMethod.LAP_COUNT or laps == leader_laps
        yield LeaderboardEntry(
            position=position,
            username=shown[summary.racer_sub],
            racer_sub=summary.racer_sub,
            country_code=profile.country_code,
            highlight_colour=profile.highlight_colour or DEFAULT_HIGHLIGHT_COLOUR,
            avatar_url=profile.avatar_url,
            raced_by_proxy=summary.raced_by_proxy,
            track_id=summary.track_id,
            time_ms=time_ms,
            gap_to_leader_ms=(
                time_ms - leader_time if time_ms is not None and leader_time is not None and comparable else None
            ),
            fastest_lap_ms=summary.fastest_lap_ms,
            fastest_average=summary.fastest_average,
            laps=laps,
            is_dnf=summary.valid_laps == 0,
        )
