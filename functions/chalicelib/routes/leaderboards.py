"""Public polls: the materialised leaderboard and overlay of a track. One GetItem and the stored body, nothing else
(no sign-in look-up, no Query). Conditional: `ETag: "v{version}"`; `If-None-Match` with it, or `?since={version}`,
answers 304 with an empty body while nothing changed."""
from __future__ import annotations

from collections.abc import Mapping

from chalice import Blueprint, Response
from pydantic import BaseModel, Field

from chalicelib import services
from chalicelib.auth.access import PUBLIC, route
from chalicelib.core.errors import NotFound
from chalicelib.core.principals import Principal
from chalicelib.domain.leaderboards import PublicView
from chalicelib.routes.responses import etag_matches
from drem_leaderboard.ranking import COMBINED_TRACK_ID

bp = Blueprint(__name__)


def conditional(view: PublicView) -> Response:
    request = bp.current_request
    etag = f'"v{view.version}"'
    query: Mapping[str, str] = request.query_params or {}
    since = query.get("since")
    headers: dict[str, str | list[str]] = {"ETag": etag, "Cache-Control": "no-cache"}
    if etag_matches(etag, request.headers.get("if-none-match")) or since == str(view.version):
        return Response(body="", status_code=304, headers=headers)
    return Response(body=view.body, status_code=200, headers={**headers, "Content-Type": "application/json"})


class BoardQuery(BaseModel):
    track: str = Field(default=COMBINED_TRACK_ID, min_length=1, max_length=32)
    page: int = Field(default=1, ge=1, le=10_000, description="a long board's page (BOARD_PAGE_ENTRIES entries each)")
    since: str | None = None


@route(bp, "/api/leaderboard/{event_id}", allow=PUBLIC, conditional=True, query=BoardQuery)
def leaderboard(principal: Principal, event_id: str, query: BoardQuery) -> Response:
    view = services.publisher().board_page(event_id, query.track, query.page)
    if view is None:
        raise NotFound(f"The board of track {query.track} has no page {query.page}.")
    return conditional(view)


@route(bp, "/api/overlay/{event_id}", allow=PUBLIC, conditional=True)
def overlay(principal: Principal, event_id: str) -> Response:
    query: Mapping[str, str] = bp.current_request.query_params or {}
    track = query.get("track") or "1"
    return conditional(services.publisher().overlay(event_id, track))
