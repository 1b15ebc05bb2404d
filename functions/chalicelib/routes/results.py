"""Printed results: the race summary, podium sheet and certificates of an event as PDFs, for race staff.

The console's race admin page links here (a session cookie works like a bearer token on GET).
"""
from __future__ import annotations

from chalice import Blueprint, Response
from pydantic import BaseModel, ConfigDict, Field

from chalicelib import services
from chalicelib.auth.access import ADMIN, OPERATOR, route
from chalicelib.core.errors import NotFound
from chalicelib.core.principals import User
from chalicelib.domain.results import EventResults, event_results
from chalicelib.formats.race_export import slug

bp = Blueprint(__name__)

RESULTS_STAFF = {ADMIN, OPERATOR}


class ResultsQuery(BaseModel):
    model_config = ConfigDict(extra="ignore")
    track: str = Field(default="", max_length=32, pattern=r"^[A-Za-z0-9_-]*$")


def load_results(event_id: str) -> EventResults:
    event = services.event_store().get(event_id)
    if event is None:
        raise NotFound(f"There is no event {event_id}.", field="event_id")
    profiles = services.public_profiles()
    races = [record.race for record in services.race_store().list_event(event_id)]
    return event_results(event, races, profiles.public_by_subs)


@route(bp, "/api/events/{event_id}/results/{file_name}", allow=RESULTS_STAFF, query=ResultsQuery,
       summary="The event's race summary, podium sheet or certificates as a PDF (summary.pdf, podium.pdf, "
               "certificates.pdf); ?track= for one board")
def results_pdf(principal: User, event_id: str, file_name: str, query: ResultsQuery) -> Response:
    from chalicelib.views.results_pdf import render_document  # fpdf2 loads when a PDF is asked for, not at start

    results = load_results(event_id)
    body = render_document(results, file_name, query.track or None)
    suffix = f"-track-{query.track}" if query.track else ""
    # Named like the CSV exports (the event's name, not its id), so one event's files sort together.
    return Response(body=body, status_code=200, headers={
        "Content-Type": "application/pdf", "Cache-Control": "no-store",
        "Content-Disposition": f'attachment; filename="{slug(results.event_name)}{suffix}-{file_name}"'})
