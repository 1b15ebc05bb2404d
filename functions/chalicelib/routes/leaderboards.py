"""Public polls: the materialised leaderboard and overlay of a track. One GetItem and the stored body, nothing else
(no sign-in look-up, no Query). Conditional: `ETag: "v{version}"`; `If-None-Match` with it, or `?since={version}`,
answers 304 with an empty body while nothing changed."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib.auth.access import PUBLIC, route
from chalicelib.auth.principals import Principal
from chalicelib.domain.leaderboards import PublicView
from chalicelib import services
from drem_leaderboard.ranking import COMBINED_TRACK_ID

bp = Blueprint(__name__)


def conditional(view: PublicView) -> Response:
    request = bp.current_request
    etag = f'"v{view.version}"'
    since = (request.query_params or {}).get("since")
    headers = {"ETag": etag, "Cache-Control": "no-cache"}
    offered = [tag.strip().removeprefix("W/") for tag in (request.headers.get("if-none-match") or "").split(",")]
    if etag in offered or since == str(view.version):
        return Response(body="", status_code=304, headers=headers)
    return Response(body=view.body, status_code=200, headers={**headers, "Content-Type": "application/json"})


@route(bp, "/api/leaderboard/{event_id}", allow=PUBLIC, conditional=True)
def leaderboard(principal: Principal, event_id: str) -> Response:
    track = (bp.current_request.query_params or {}).get("track") or COMBINED_TRACK_ID
    return conditional(services.publisher().board(event_id, track))


@route(bp, "/api/overlay/{event_id}", allow=PUBLIC, conditional=True)
def overlay(principal: Principal, event_id: str) -> Response:
    track = (bp.current_request.query_params or {}).get("track") or "1"
    return conditional(services.publisher().overlay(event_id, track))
