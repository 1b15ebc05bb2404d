"""The live regions of the public pages (the big-screen leaderboard and the OBS overlay), built once for everyone who
watches them: the app's fragment routes (`…/live?…&v=`, polled) and the live server (drem_live, pushed over SSE)
both call `leaderboard_region` / `overlay_region` here, so a poll and a push carry exactly the same HTML.

A region is (version token, render): the token is read from the materialised items (one GetItem each) and names every
item version the HTML is built from, plus the time-dependent phases (the overlay's phase, a held race summary), so a
phase that advances with the clock changes the token too. `render()` builds the HTML; callers render once per token.

Tokens are ordered (`token_order`): groups separated by ".", each a "-"-separated tuple of integers compared
lexicographically (an overlay version, then its phase), and one token is newer than another when no group went back
and one went forward. The board and each overlay are versioned independently (on AWS each Lambda caches its reads for
250 ms), so two tokens may also be incomparable; a viewer never swaps to a token that is not newer (live.js does the
same comparison), and the newest state is newer than every earlier one, so it always gets through.
"""
from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Literal
from urllib.parse import quote, urlencode

from pydantic import BaseModel, ConfigDict, Field, field_validator

from chalicelib.domain.big_screen import ScreenSettings, parse_screen
from chalicelib.domain.leaderboards import LeaderboardPublisher
from chalicelib.views import public_views as views
from chalicelib.views.render_cache import LIVE_FRAGMENTS, LIVE_RACES
from drem_leaderboard.models import Race
from drem_leaderboard.ranking import COMBINED_TRACK_ID
from drem_web import i18n, render

_TRACK_ID = re.compile(r"[A-Za-z0-9_-]{1,32}")
MAX_FOOTER_TRACKS = 8
# The overlay's phases in the order one overlay version goes through them (a live race only ever shows "racing").
PHASE_ORDER = {"racing": 0, "post_race": 1, "standings": 2}


class PageOptions(BaseModel):
    """Query switches shared by the pages and their fragments (unknown languages fall back to English)."""
    model_config = ConfigDict(populate_by_name=True, extra="ignore")
    track: str | None = Field(default=None, max_length=32, pattern=r"^[A-Za-z0-9_-]+$")
    format: views.BoardFormat | None = None
    flag: bool = True
    lang: str = Field(default=i18n.DEFAULT_LANGUAGE, max_length=16)
    v: str = Field(default="", max_length=200)


class LeaderboardQuery(PageOptions):
    scroll: bool = True
    qr: Literal["header", "footer", "none"] = "footer"
    page_seconds: int = Field(default=8, ge=2, le=60, description="big screen: seconds each page of rows is shown")
    summary_seconds: int = Field(default=views.DEFAULT_SUMMARY_SECONDS, ge=0, le=120,
                                 description="big screen: seconds a submitted race's summary is held; 0 = off")
    tracks: str = Field(default="", max_length=300, description="live fragment: tracks whose race footer to show")

    @field_validator("tracks")
    @classmethod
    def _track_list(cls, value: str) -> str:
        found = [t for t in value.split(",") if t]
        if len(found) > MAX_FOOTER_TRACKS or not all(_TRACK_ID.fullmatch(t) for t in found):
            raise ValueError(f"tracks: up to {MAX_FOOTER_TRACKS} comma-separated track ids")
        return value


class OverlayQuery(PageOptions):
    track_id: str | None = Field(default=None, alias="trackId", max_length=32, pattern=r"^[A-Za-z0-9_-]+$")
    chroma: bool = False
    chroma_color: str = Field(default="", alias="chromaColor", max_length=64)
    gap_to_leader: bool = Field(default=True, alias="gapToLeader")
    show_leaderboard: bool = Field(default=True, alias="showLeaderboard")

    @property
    def overlay_track(self) -> str:
        return self.track or self.track_id or "1"


# --- version tokens ---------------------------------------------------------------------------------------------


@lru_cache(maxsize=1024)  # the live server compares each broadcast token once per viewer: parse it once
def token_order(token: str) -> tuple[tuple[int, ...], ...] | None:
    """The comparable form of a token ("12.5-1.7-0" → ((12,), (5, 1), (7, 0))); None if it is not one."""
    try:
        return tuple(tuple(int(part) for part in group.split("-")) for group in token.split("."))
    except ValueError:
        return None


def token_is_newer(candidate: str, shown: str | None) -> bool:
    """True when `candidate` may replace `shown`: every group the same or later, one of them later. Anything beats
    nothing; tokens of another shape (another page's options) are never compared, they are taken."""
    if not shown:
        return True
    new, old = token_order(candidate), token_order(shown)
    if new is None or old is None or [len(g) for g in new] != [len(g) for g in old]:
        return candidate != shown
    return all(a >= b for a, b in zip(new, old, strict=True)) and new != old


# --- reading the live items (the same GetItems as the JSON polls) -------------------------------------------------


@dataclass(frozen=True)
class LiveItems:
    board: views.BoardSnapshot
    overlays: list[views.OverlaySnapshot]
    screen: ScreenSettings | None = None
    screen_version: int = 0

    @property
    def overlay(self) -> views.OverlaySnapshot:
        return self.overlays[0]


@dataclass(frozen=True)
class LiveRegion:
    """What one viewer of a live region sees now: its version token and how to build its HTML (render once per
    token: nothing in it depends on who asks)."""
    token: str
    context: Callable[[], dict[str, Any]]
    template: str

    def render(self) -> str:
        return render.fragment(self.template, **self.context()).body


def read_live(publisher: LeaderboardPublisher, event_id: str, board_track: str, overlay_tracks: list[str], *,
              screen: bool = False) -> LiveItems:
    """The items a live region is built from; `screen`: also the big screen's settings (name, sponsor, footer)."""
    shown = publisher.screen(event_id) if screen else None
    return LiveItems(board=views.BoardSnapshot.parse(publisher.board(event_id, board_track).body),
                     overlays=[views.OverlaySnapshot.parse(publisher.overlay(event_id, t).body)
                               for t in overlay_tracks],
                     screen=parse_screen(shown.body) if shown else None, screen_version=shown.version if shown else 0)


def live_race(read_race: Callable[[str, str], Race | None], event_id: str,
              overlay: views.OverlaySnapshot) -> Race | None:
    """The race behind the overlay (lap detail for colours and the lap table); only read when a fragment renders."""
    race_id = overlay.race_id
    if not race_id:
        return None
    return LIVE_RACES.get((event_id, overlay.track_id, race_id, overlay.version), lambda: read_race(event_id, race_id))


def live_url(path: str, params: dict[str, Any]) -> str:
    kept = {k: ("true" if v is True else "false" if v is False else v) for k, v in params.items()
            if v is not None and v != ""}
    return f"{path}?{urlencode(kept)}"


def cached_render(region: LiveRegion, options: tuple[Any, ...]) -> str:
    """The region's HTML, built once per (template, base path, options, token) in this process and shared by every
    viewer. The base path is in the key because the fragment's own poll URL sits under it: the same board reached at
    / and at /api differs."""
    return LIVE_FRAGMENTS.get((region.template, render.base_path(), *options, region.token), region.render)


# --- leaderboard ---------------------------------------------------------------------------------------------------


def leaderboard_fragment_tracks(query: LeaderboardQuery) -> tuple[str, list[str]]:
    """(board track, race-footer tracks) of a fragment request: the page passes both in its poll URL."""
    track = query.track or COMBINED_TRACK_ID
    return track, [t for t in query.tracks.split(",") if t] or ([track] if track != COMBINED_TRACK_ID else [])


def leaderboard_region(publisher: LeaderboardPublisher, event_id: str, track: str, query: LeaderboardQuery,
                       footer_tracks: list[str], now_ms: int) -> LiveRegion:
    """The leaderboard's live region: board rows, race footers and held race summaries."""
    items = read_live(publisher, event_id, track, footer_tracks, screen=True)
    # A held summary is part of the token (0 while held, 1 after): its end changes the token, so viewers re-render.
    # The big screen's settings come last: an edited footer or sponsor changes the token like a lap does.
    held = [o for o in items.overlays if views.summary_held(o, now_ms, query.summary_seconds * 1000)]
    token = views.version_token(items.board.version,
                                *(f"{o.version}-{0 if o in held else 1}" for o in items.overlays),
                                items.screen_version)

    def context() -> dict[str, Any]:
        t = i18n.translator(query.lang)
        footers = [f for o in items.overlays if (f := views.race_footer(
            o, now_ms, t, views.entry_for(items.board, o.username), show_flags=query.flag)) is not None]
        summaries = [views.race_summary(o, items.board, t, show_flags=query.flag) for o in held]
        poll = live_url(f"/leaderboard/{quote(event_id, safe='')}/live", {
            "track": track, "format": query.format, "flag": query.flag, "scroll": query.scroll, "lang": query.lang,
            "tracks": ",".join(footer_tracks), "page_seconds": query.page_seconds,
            "summary_seconds": query.summary_seconds, "v": token})
        return {"rows": views.board_rows(items.board, query.format, t, show_flags=query.flag), "footers": footers,
                "summaries": summaries, "poll_url": poll, "token": token, "scroll": query.scroll, "t": t,
                "clock_at": now_ms, "page_ms": query.page_seconds * 1000,
                # Swapped in out of band beside the rows (partials/board_screen.html); None: the page's stay.
                "pushed_screen": items.screen.view(event_id, track) if items.screen else None, "board_track": track}

    return LiveRegion(token, context, "leaderboard_live")


def leaderboard_options(event_id: str, query: LeaderboardQuery) -> tuple[Any, ...]:
    track, footer_tracks = leaderboard_fragment_tracks(query)
    return (event_id, track, tuple(footer_tracks), query.model_dump_json(exclude={"v"}))


# --- overlay -------------------------------------------------------------------------------------------------------


def overlay_region(publisher: LeaderboardPublisher, read_race: Callable[[str, str], Race | None], event_id: str,
                   query: OverlayQuery, now_ms: int) -> LiveRegion:
    """The overlay's live region; its token carries the phase (racing, just finished, standings) and the version of
    the event's name and logo it shows."""
    track = query.overlay_track
    items = read_live(publisher, event_id, track, [track], screen=True)
    phase = views.overlay_phase(items.overlay, now_ms)
    # The event's name and logo (the big screen's settings) come last: an edit of either changes the token.
    token = views.version_token(items.board.version, f"{items.overlay.version}-{PHASE_ORDER[phase]}",
                                items.screen_version)

    def context() -> dict[str, Any]:
        t = i18n.translator(query.lang)
        race = live_race(read_race, event_id, items.overlay) if phase == "racing" else None
        view = views.overlay_view(items.overlay, items.board, race, now_ms, t, fmt=query.format,
                                  show_flags=query.flag, show_standings=query.show_leaderboard)
        poll = live_url(f"/overlay/{quote(event_id, safe='')}/live", {
            "track": track, "format": query.format, "flag": query.flag, "lang": query.lang,
            "gapToLeader": query.gap_to_leader, "showLeaderboard": query.show_leaderboard, "v": token})
        return {"view": view, "poll_url": poll, "token": token, "gap_to_leader": query.gap_to_leader, "t": t,
                "clock_at": now_ms,
                # Swapped in out of band beside the region (partials/overlay_brand.html); None: the page's stay.
                "pushed_screen": items.screen.view(event_id, track) if items.screen else None}

    return LiveRegion(token, context, "overlay_live")


def overlay_options(event_id: str, query: OverlayQuery) -> tuple[Any, ...]:
    return (event_id, query.overlay_track, query.model_dump_json(exclude={"v"}))
