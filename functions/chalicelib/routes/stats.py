"""The statistics page `/stats`: public, and more for signed-in staff (events the organiser keeps staff-only).

Server-rendered (SVG charts and world map), filtered with a plain GET form: works without JavaScript.
"""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, COMMENTATOR, OPERATOR, PUBLIC, route
from chalicelib.core.principals import Principal
from chalicelib.domain.stats import ShownRacer, StatsFilter, compute, visible_events
from chalicelib.views.stats_view import stats_page
from drem_web import render

bp = Blueprint(__name__)

STATS_STAFF = {ADMIN, OPERATOR, COMMENTATOR}


@route(bp, "/stats", allow=PUBLIC, query=StatsFilter)
def stats(principal: Principal, query: StatsFilter) -> Response:
    staff = bool(principal.roles & STATS_STAFF)
    data = services.stats_digests().for_events(visible_events(services.event_store().list(), staff=staff))
    profiles = services.public_profiles()

    def display_name(sub: str, username: str) -> ShownRacer:
        public = profiles.public_by_sub(sub)
        if public is None:
            return ShownRacer(username)
        return ShownRacer(public.display_name or public.username, public.country_code, public.username)

    return render.page("stats", view=stats_page(compute(data, query, display_name), query, staff=staff))
