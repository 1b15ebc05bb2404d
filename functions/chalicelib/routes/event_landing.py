"""`/event/{event_id}`: the public landing page of an event (the target of the QR code on every board)."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib.auth.access import PUBLIC, route
from chalicelib.core.principals import Principal
from chalicelib.routes.event_logos import logo_path
from chalicelib.routes.public_pages import event_or_404
from chalicelib.views.event_landing import landing_view
from drem_web import render

bp = Blueprint(__name__)


@route(bp, "/event/{event_id}", allow=PUBLIC)
def event_landing(principal: Principal, event_id: str) -> Response:
    """An event's public page: tracks, live boards, overlay links and the organiser's links"""
    return render.page("event_landing", view=landing_view(event_or_404(event_id)), logo_url=logo_path(event_id))
