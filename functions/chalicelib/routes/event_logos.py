"""`/event/{event_id}/logo`: an event's logo, for the big screen, the overlay and the landing page (public, as they
are). Pages link to `?v={version}`: that address never changes its bytes, so browsers and CloudFront keep it for a
year; without (or with an old) `v` the answer must be revalidated, so a replaced logo shows at once."""
from __future__ import annotations

from chalice import Blueprint, Response
from pydantic import BaseModel, Field

from chalicelib import services
from chalicelib.auth.access import ADMIN, OPERATOR, PUBLIC, body_bytes, route
from chalicelib.core.principals import Principal, User
from chalicelib.domain.event_logos import LogoVersion
from chalicelib.formats import logo_image
from chalicelib.routes.responses import etag_matches

bp = Blueprint(__name__)

FOR_GOOD = "public, max-age=31536000, immutable"
EVENT_EDITORS = {ADMIN, OPERATOR}


class LogoQuery(BaseModel):
    v: str = Field(default="", max_length=64, description="the logo's version, as pages link to it")


@route(bp, "/event/{event_id}/logo", allow=PUBLIC, query=LogoQuery, shared=True)
def event_logo(principal: Principal, event_id: str, query: LogoQuery) -> Response:
    """An event's logo image (PNG or WebP); 404 when it has none"""
    logo = services.event_logo_service().logo(event_id)
    etag = f'"logo-{logo.version}"'
    caching = FOR_GOOD if query.v == logo.version else "public, no-cache"
    if etag_matches(etag, bp.current_request.headers.get("if-none-match")):
        return Response(body="", status_code=304, headers={"ETag": etag, "Cache-Control": caching})
    return Response(body=logo.data, headers={"Content-Type": logo.content_type, "ETag": etag, "Cache-Control": caching,
                                             "Content-Disposition": "inline"})


@route(bp, "/api/events/{event_id}/logo", methods=["PUT"], allow=EVENT_EDITORS, response=LogoVersion,
       content_types=list(logo_image.UPLOAD_TYPES))
def put_event_logo(principal: User, event_id: str) -> dict:
    """Replace the event's logo with the image in the body (PNG, JPEG, WebP or GIF, at most 2 MB)

    drem stores the image drawn again from its pixels (margin cropped, fitted into 960×360); the answer names the
    stored version, which the public pages link to as `/event/{event_id}/logo?v={version}`."""
    return services.event_logo_service().save(event_id, body_bytes(bp.current_request)).model_dump()


@route(bp, "/api/events/{event_id}/logo", methods=["DELETE"], allow=EVENT_EDITORS)
def delete_event_logo(principal: User, event_id: str) -> Response:
    """Remove the event's logo: its pages show the name alone"""
    services.event_logo_service().remove(event_id)
    return Response(body="", status_code=204)


def logo_path(event_id: str) -> str:
    """The address pages show the event's logo at (this version's, cacheable for good), or "" for none."""
    logo = services.event_logo_service().version(event_id)
    return f"/event/{event_id}/logo?v={logo.version}" if logo else ""
