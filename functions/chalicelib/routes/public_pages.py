"""Public live pages: the big-screen leaderboard (`/leaderboard/{event}`) and the OBS stream overlay
(`/overlay/{event}`), plus the fragment routes their live regions poll every 500 ms.

A page renders its live region once; the region then polls `…/live?…&v={token}`, where the token names every
materialised item version (and overlay phase, or a held race summary) it was built from. The fragment route reads the
same items as `GET /api/leaderboard|overlay/{event}` (through the process's poll cache) and answers **204 No Content**
while the token is current: htmx 2 leaves the DOM alone on 204, so an unchanged poll costs no rendering and no
flicker. An `If-None-Match` with the fragment's ETag gets a 304 the same way (for clients that cache).

A changed token is rendered once per (fragment, event, options, token) and the same HTML is served to every poller
(`domain/render_cache.LIVE_FRAGMENTS`); the overlay's race is read once per overlay version (`LIVE_RACES`). The only
wall-time-dependent parts, the race clocks, carry the server time they were computed at (`data-clock-at`) and each
200 carries the server time it was sent (`X-Drem-Server-Ms`): live.js advances a running clock by the difference, so a
fragment built earlier still shows the right time.
"""
from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal
from urllib.parse import quote, urlencode

import qrcode
import qrcode.image.svg
from chalice import Blueprint, Response
from pydantic import BaseModel, ConfigDict, Field, field_validator

from chalicelib import services
from chalicelib.auth.access import PUBLIC, route
from chalicelib.auth.principals import Principal
from chalicelib.domain.errors import NotFound
from chalicelib.domain.events import Event
from chalicelib.routes.responses import etag_matches
from chalicelib.settings import get_settings
from chalicelib.views import public_views as views
from chalicelib.views.event_landing import landing_url
from chalicelib.views.render_cache import LIVE_FRAGMENTS, LIVE_RACES
from drem_leaderboard.models import Race
from drem_leaderboard.ranking import COMBINED_TRACK_ID
from drem_web import i18n, render

bp = Blueprint(__name__)

_TRACK_ID = re.compile(r"[A-Za-z0-9_-]{1,32}")
MAX_FOOTER_TRACKS = 8
SERVER_TIME_HEADER = "X-Drem-Server-Ms"


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


# --- reading the live items (the same GetItems as the JSON polls) -------------------------------------------------


@dataclass(frozen=True)
class LiveItems:
    board: views.BoardSnapshot
    overlays: list[views.OverlaySnapshot]

    @property
    def overlay(self) -> views.OverlaySnapshot:
        return self.overlays[0]


def read_live(event_id: str, board_track: str, overlay_tracks: list[str]) -> LiveItems:
    publisher = services.publisher()
    return LiveItems(board=views.BoardSnapshot.parse(publisher.board(event_id, board_track).body),
                     overlays=[views.OverlaySnapshot.parse(publisher.overlay(event_id, t).body)
                               for t in overlay_tracks])


def live_race(event_id: str, overlay: views.OverlaySnapshot) -> Race | None:
    """The race behind the overlay (lap detail for colours and the lap table); only read when a fragment renders."""
    race_id = overlay.race_id
    if not race_id:
        return None

    def read() -> Race | None:
        record = services.race_store().get(event_id, race_id)
        return record.race if record else None

    return LIVE_RACES.get((event_id, overlay.track_id, race_id, overlay.version), read)


def event_or_404(event_id: str) -> Event:
    event = services.event_store().get(event_id)
    if event is None:
        raise NotFound(f"There is no event {event_id}.", field="event_id")
    return event


def board_track(event: Event, requested: str | None) -> str:
    track = requested or (COMBINED_TRACK_ID if event.combined_board else event.tracks[0].track_id or "1")
    if track not in event.boards:
        raise NotFound(f"Event {event.event_id} has no track {track!r}.", field="track")
    return track


def unchanged(token: str, client_token: str, if_none_match: str | None) -> Response | None:
    """204 when the client's `v` is current, 304 for a matching If-None-Match; None means render."""
    etag = f'"live-{token}"'
    if client_token == token:
        return Response(body="", status_code=204, headers={"Cache-Control": "no-store"})
    if etag_matches(etag, if_none_match):
        return Response(body="", status_code=304, headers={"ETag": etag, "Cache-Control": "no-cache"})
    return None


def fragment_headers(token: str) -> dict[str, str]:
    return {"ETag": f'"live-{token}"', "Cache-Control": "no-cache"}


def live_fragment(name: str, options: tuple[Any, ...], token: str, client_token: str,
                  context: Callable[[], dict[str, Any]]) -> Response:
    """204/304 while the client's token is current; else the fragment, built once per (name, options, token) and
    handed to every poller: a live partial must render nothing that depends on who asks."""
    reply = unchanged(token, client_token, bp.current_request.headers.get("if-none-match"))
    if reply is not None:
        return reply
    # The fragment's poll URL sits under the request's base path: the same board reached at / and at /api differs.
    key = (name, render.base_path(), *options, token)
    body = LIVE_FRAGMENTS.get(key, lambda: render.fragment(name, **context()).body)
    return Response(body=body, status_code=200, headers={
        "Content-Type": render.HTML, **fragment_headers(token), SERVER_TIME_HEADER: str(services.now_ms())})


def live_url(path: str, params: dict[str, Any]) -> str:
    kept = {k: ("true" if v is True else "false" if v is False else v) for k, v in params.items()
            if v is not None and v != ""}
    return f"{path}?{urlencode(kept)}"


def qr_svg(url: str) -> str:
    """The QR code of `url` as inline SVG markup (qrcode's own path image: no text of `url` ends up in it)."""
    # border=4 modules: the quiet zone the QR spec asks for (phones scan a projected code more reliably).
    image = qrcode.make(url, image_factory=qrcode.image.svg.SvgPathImage, box_size=10, border=4)
    return image.to_string(encoding="unicode")


# --- leaderboard ---------------------------------------------------------------------------------------------------


def leaderboard_live(event_id: str, track: str, query: LeaderboardQuery, footer_tracks: list[str],
                     now_ms: int) -> tuple[str, Callable[[], dict[str, Any]]]:
    """(version token, a function building the template context of the leaderboard's live region)."""
    items = read_live(event_id, track, footer_tracks)
    # A held summary is part of the token: its end (or a new race) changes the token, so the next poll renders.
    held = [o for o in items.overlays if views.summary_held(o, now_ms, query.summary_seconds * 1000)]
    token = views.version_token(items.board.version, *(o.version for o in items.overlays),
                                *(f"s{o.track_id}" for o in held))

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
                "clock_at": now_ms, "page_ms": query.page_seconds * 1000}

    return token, context


@route(bp, "/leaderboard/{event_id}", allow=PUBLIC, query=LeaderboardQuery)
def leaderboard_page(principal: Principal, event_id: str, query: LeaderboardQuery) -> Response:
    """The public big-screen leaderboard of an event (projector and phones)"""
    event = event_or_404(event_id)
    track = board_track(event, query.track)
    footer_tracks = [track] if track != COMBINED_TRACK_ID else [t.track_id or "" for t in event.tracks]
    _token, live = leaderboard_live(event_id, track, query, footer_tracks[:MAX_FOOTER_TRACKS], services.now_ms())
    page_url = landing_url(get_settings().public_url, event_id, query.lang)  # the QR opens the event's landing page
    shown = next((t for t in event.tracks if t.track_id == track), None)  # None on the combined board
    return render.page("leaderboard", title=event.name, track=track, tracks=event.boards, lang=i18n.resolve_language(
        query.lang), qr=query.qr, qr_svg=qr_svg(page_url) if query.qr != "none" else "", page_url=page_url,
        track_title=shown.leaderboard_title if shown else "",
        board_footer=(shown or event.tracks[0]).leaderboard_footer,
        sponsor=event.sponsor, links=event.landing_page_links, **live())


@route(bp, "/leaderboard/{event_id}/live", allow=PUBLIC, query=LeaderboardQuery)
def leaderboard_fragment(principal: Principal, event_id: str, query: LeaderboardQuery) -> Response:
    """The leaderboard's live region; 204 while `v` is current"""
    track = query.track or COMBINED_TRACK_ID
    footer_tracks = [t for t in query.tracks.split(",") if t] or ([track] if track != COMBINED_TRACK_ID else [])
    token, live = leaderboard_live(event_id, track, query, footer_tracks, services.now_ms())
    options = (event_id, track, tuple(footer_tracks), query.model_dump_json(exclude={"v"}))
    return live_fragment("leaderboard_live", options, token, query.v, live)


# --- overlay -------------------------------------------------------------------------------------------------------


def overlay_live(event_id: str, query: OverlayQuery, now_ms: int) -> tuple[str, Callable[[], dict[str, Any]]]:
    """(version token incl. phase, a function building the template context: lap detail is read only to render)."""
    track = query.overlay_track
    items = read_live(event_id, track, [track])
    phase = views.overlay_phase(items.overlay, now_ms)
    token = views.version_token(items.board.version, items.overlay.version, phase)

    def context() -> dict[str, Any]:
        t = i18n.translator(query.lang)
        race = live_race(event_id, items.overlay) if phase == "racing" else None
        view = views.overlay_view(items.overlay, items.board, race, now_ms, t, fmt=query.format,
                                  show_flags=query.flag, show_standings=query.show_leaderboard)
        poll = live_url(f"/overlay/{quote(event_id, safe='')}/live", {
            "track": track, "format": query.format, "flag": query.flag, "lang": query.lang,
            "gapToLeader": query.gap_to_leader, "showLeaderboard": query.show_leaderboard, "v": token})
        return {"view": view, "poll_url": poll, "token": token, "gap_to_leader": query.gap_to_leader, "t": t,
                "clock_at": now_ms}

    return token, context


@route(bp, "/overlay/{event_id}", allow=PUBLIC, query=OverlayQuery)
def overlay_page(principal: Principal, event_id: str, query: OverlayQuery) -> Response:
    """The OBS browser-source overlay (1920×1080, transparent or chroma-key background)"""
    event = event_or_404(event_id)
    event.track(query.overlay_track)  # NotFound for a track the event does not have
    _token, context = overlay_live(event_id, query, services.now_ms())
    chroma = views.safe_colour(query.chroma_color, views.DEFAULT_CHROMA) if query.chroma else ""
    return render.page("overlay", title=event.name, chroma=chroma, lang=i18n.resolve_language(query.lang),
                       **context())


@route(bp, "/overlay/{event_id}/live", allow=PUBLIC, query=OverlayQuery)
def overlay_fragment(principal: Principal, event_id: str, query: OverlayQuery) -> Response:
    """The overlay's live region; 204 while `v` is current"""
    token, context = overlay_live(event_id, query, services.now_ms())
    options = (event_id, query.overlay_track, query.model_dump_json(exclude={"v"}))
    return live_fragment("overlay_live", options, token, query.v, context)
