"""The commentator view (`/commentator/{event}`): the racer on track, gap to fastest, current and projected position,
lap table and lap-time chart. Staff only (commentator, operator, admin); it polls `…/live` like the public pages
(204 while nothing changed)."""
from __future__ import annotations

from typing import Any
from urllib.parse import quote

from chalice import Blueprint, Response
from pydantic import Field

from chalicelib import services
from chalicelib.auth.access import ADMIN, COMMENTATOR, OPERATOR, route
from chalicelib.core.principals import User
from chalicelib.routes.public_pages import event_or_404, fragment_headers, read_race, unchanged
from chalicelib.views import car_video
from chalicelib.views import public_views as views
from chalicelib.views.live_regions import PageOptions, live_race, live_url, read_live
from drem_web import i18n, render

bp = Blueprint(__name__)

COMMENTATORS = {COMMENTATOR, OPERATOR, ADMIN}


class CommentatorQuery(PageOptions):
    track: str = Field(default="1", max_length=32, pattern=r"^[A-Za-z0-9_-]+$")


def commentator_live(event_id: str, query: CommentatorQuery) -> tuple[str, Any]:
    now_ms = services.now_ms()
    items = read_live(services.publisher(), event_id, query.track, [query.track])
    token = views.version_token(items.board.version, items.overlay.version)

    def context() -> dict[str, Any]:
        t = i18n.translator(query.lang)
        race = live_race(read_race, event_id, items.overlay)
        view = views.commentator_view(items.overlay, items.board, race, now_ms, t)
        poll = live_url(f"/commentator/{quote(event_id, safe='')}/live",
                        {"track": query.track, "lang": query.lang, "v": token})
        return {"view": view, "poll_url": poll, "token": token, "t": t}

    return token, context


@route(bp, "/commentator/{event_id}", allow=COMMENTATORS, query=CommentatorQuery)
def commentator_page(principal: User, event_id: str, query: CommentatorQuery) -> Response:
    """Live racer statistics for the commentator"""
    event = event_or_404(event_id)
    event.track(query.track)
    _token, context = commentator_live(event_id, query)
    tracks = [(t.track_id, event.track_name(t.track_id or "")) for t in event.tracks]
    return render.page("commentator", title=event.name, track=query.track, tracks=tracks,
                       lang=i18n.resolve_language(query.lang),
                       car_eye_url=car_video.racing_video_url(event_id, query.track), **context())


@route(bp, "/commentator/{event_id}/live", allow=COMMENTATORS, query=CommentatorQuery)
def commentator_fragment(principal: User, event_id: str, query: CommentatorQuery) -> Response:
    """The commentator view's live region; 204 while `v` is current"""
    token, context = commentator_live(event_id, query)
    if_none_match = bp.current_request.headers.get("if-none-match")
    return unchanged(token, query.v, if_none_match) or render.fragment(
        "commentator_live", headers=fragment_headers(token), **context())
