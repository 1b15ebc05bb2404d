"""Public live pages: the big-screen leaderboard (`/leaderboard/{event}`) and the OBS stream overlay
(`/overlay/{event}`), plus the fragment routes their live regions poll every 500 ms when they cannot be pushed to.

A page renders its live region once (views/live_regions.py builds it, for these routes and the live server alike).
With a live server (`DREM_LIVE_URL`, drem_live) the region subscribes to `/live/{kind}/{event}?…` (server-sent events:
one fragment per version change, pushed). Without one, or when the stream fails, it polls `…/live?…&v={token}`, where
the token names every materialised item version (and overlay phase, or a held race summary) it was built from. The
fragment route reads the same items as `GET /api/leaderboard|overlay/{event}` (through the process's poll cache) and
answers **204 No Content** while the token is current: htmx 2 leaves the DOM alone on 204, so an unchanged poll costs
no rendering and no flicker. An `If-None-Match` with the fragment's ETag gets a 304 the same way.

A changed token is rendered once per (fragment, event, options, token) and the same HTML is served to every poller
(`render_cache.LIVE_FRAGMENTS`); the overlay's race is read once per overlay version (`LIVE_RACES`). The only
wall-time-dependent parts, the race clocks, carry the server time they were computed at (`data-clock-at`) and each
200 carries the server time it was sent (`X-Drem-Server-Ms`): live.js advances a running clock by the difference, so a
fragment built earlier still shows the right time. live.js never swaps in a fragment whose token is older than the one
shown (`live_regions.token_is_newer`): on AWS another Lambda instance's cache may still hold an older board.
"""
from __future__ import annotations

from typing import Any
from urllib.parse import parse_qsl, urlencode

import qrcode
import qrcode.image.svg
from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import PUBLIC, route
from chalicelib.core.errors import NotFound
from chalicelib.core.principals import Principal
from chalicelib.domain.events import Event
from chalicelib.routes.responses import etag_matches
from chalicelib.settings import get_settings
from chalicelib.views import car_video
from chalicelib.views import live_regions as regions
from chalicelib.views import public_views as views
from chalicelib.views.event_landing import landing_url
from drem_leaderboard.models import Race
from drem_leaderboard.ranking import COMBINED_TRACK_ID
from drem_web import i18n, render

bp = Blueprint(__name__)

SERVER_TIME_HEADER = "X-Drem-Server-Ms"
# Re-exported: the commentator's route builds on the same query options.
PageOptions = regions.PageOptions
LeaderboardQuery = regions.LeaderboardQuery
OverlayQuery = regions.OverlayQuery
MAX_FOOTER_TRACKS = regions.MAX_FOOTER_TRACKS


def read_race(event_id: str, race_id: str) -> Race | None:
    record = services.race_store().get(event_id, race_id)
    return record.race if record else None


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


def live_fragment(region: regions.LiveRegion, options: tuple[Any, ...], client_token: str) -> Response:
    """204/304 while the client's token is current; else the fragment, built once per (name, options, token) and
    handed to every poller: a live partial must render nothing that depends on who asks."""
    reply = unchanged(region.token, client_token, bp.current_request.headers.get("if-none-match"))
    if reply is not None:
        return reply
    return Response(body=regions.cached_render(region, options), status_code=200, headers={
        "Content-Type": render.HTML, **fragment_headers(region.token), SERVER_TIME_HEADER: str(services.now_ms())})


def stream_url(poll_url: str) -> str:
    """Where the page's live region subscribes to pushed fragments (the live server, drem_live): the poll URL's path
    under `/live/` and its query without `v`; "" when there is no live server (the region keeps polling)."""
    base = get_settings().live_stream_base
    if base is None:
        return ""
    path, _, query = poll_url.partition("?")
    kind, event = path.strip("/").split("/")[:2]  # /leaderboard/{event}/live
    kept = urlencode([(k, v) for k, v in parse_qsl(query, keep_blank_values=True) if k != "v"])
    if render.base_path():
        # Reached under a prefix (a proxy's sub-path, or API Gateway's stage): the browser may not reach the live
        # server's own origin, so it subscribes under the same prefix, where the proxy routes /live/ to the live
        # server (docs/operations.md). Where nothing answers there, the region falls back to polling the app.
        return render.url(f"/live/{kind}/{event}?{kept}")
    return f"{base}/live/{kind}/{event}?{kept}"


def qr_svg(url: str) -> str:
    """The QR code of `url` as inline SVG markup (qrcode's own path image: no text of `url` ends up in it)."""
    # border=4 modules: the quiet zone the QR spec asks for (phones scan a projected code more reliably).
    image = qrcode.make(url, image_factory=qrcode.image.svg.SvgPathImage, box_size=10, border=4)
    return image.to_string(encoding="unicode")


# --- leaderboard ---------------------------------------------------------------------------------------------------


@route(bp, "/leaderboard/{event_id}", allow=PUBLIC, query=LeaderboardQuery)
def leaderboard_page(principal: Principal, event_id: str, query: LeaderboardQuery) -> Response:
    """The public big-screen leaderboard of an event (projector and phones)"""
    event = event_or_404(event_id)
    track = board_track(event, query.track)
    footer_tracks = [track] if track != COMBINED_TRACK_ID else [t.track_id or "" for t in event.tracks]
    region = regions.leaderboard_region(services.publisher(), event_id, track, query,
                                        footer_tracks[:MAX_FOOTER_TRACKS], services.now_ms())
    # The header and footer as the event says now; the live region carries later edits (domain/big_screen.py).
    settings = services.screen_publisher().caught_up(event)
    live = {**region.context(), "pushed_screen": None}
    page_url = landing_url(get_settings().public_url, event_id, query.lang)  # the QR opens the event's landing page
    shown = next((t for t in event.tracks if t.track_id == track), None)  # None on the combined board
    return render.page("leaderboard", title=event.name, track=track, tracks=event.boards, lang=i18n.resolve_language(
        query.lang), qr=query.qr, qr_svg=qr_svg(page_url) if query.qr != "none" else "", page_url=page_url,
        view=settings.view(event_id, track), stream_url=stream_url(live["poll_url"]),
        car_eye_url=car_video.shown_when_asked(event_id, shown.track_id or "1" if shown else "1",
                                               bp.current_request.query_params), **live)


@route(bp, "/leaderboard/{event_id}/live", allow=PUBLIC, query=LeaderboardQuery)
def leaderboard_fragment(principal: Principal, event_id: str, query: LeaderboardQuery) -> Response:
    """The leaderboard's live region; 204 while `v` is current"""
    track, footer_tracks = regions.leaderboard_fragment_tracks(query)
    region = regions.leaderboard_region(services.publisher(), event_id, track, query, footer_tracks,
                                        services.now_ms())
    return live_fragment(region, regions.leaderboard_options(event_id, query), query.v)


# --- overlay -------------------------------------------------------------------------------------------------------


@route(bp, "/overlay/{event_id}", allow=PUBLIC, query=OverlayQuery)
def overlay_page(principal: Principal, event_id: str, query: OverlayQuery) -> Response:
    """The OBS browser-source overlay (1920×1080, transparent or chroma-key background)"""
    event = event_or_404(event_id)
    event.track(query.overlay_track)  # NotFound for a track the event does not have
    region = regions.overlay_region(services.publisher(), read_race, event_id, query, services.now_ms())
    # The name and logo as the event says now; the live region carries later edits (domain/big_screen.py).
    settings = services.screen_publisher().caught_up(event)
    live = {**region.context(), "pushed_screen": None}
    chroma = views.safe_colour(query.chroma_color, views.DEFAULT_CHROMA) if query.chroma else ""
    return render.page("overlay", title=event.name, chroma=chroma, lang=i18n.resolve_language(query.lang),
                       stream_url=stream_url(live["poll_url"]), screen=settings.view(event_id, query.overlay_track),
                       car_eye_url=car_video.shown_when_asked(event_id, query.overlay_track,
                                                              bp.current_request.query_params), **live)


@route(bp, "/overlay/{event_id}/live", allow=PUBLIC, query=OverlayQuery)
def overlay_fragment(principal: Principal, event_id: str, query: OverlayQuery) -> Response:
    """The overlay's live region; 204 while `v` is current"""
    region = regions.overlay_region(services.publisher(), read_race, event_id, query, services.now_ms())
    return live_fragment(region, regions.overlay_options(event_id, query), query.v)
