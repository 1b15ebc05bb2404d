"""Operator console: events (list, create, edit, delete with confirmation) and each event's logo. Calls the same
`EventService` as the JSON API; the form lives in `console_event_form`."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, OPERATOR, route, uploaded_file
from chalicelib.core.principals import User
from chalicelib.domain.countries import COUNTRY_CHOICES
from chalicelib.formats import logo_image
from chalicelib.routes.console import event_form
from chalicelib.routes.console.forms import SHOWN_ON_FORM, error_status, field_errors, redirect, submitted
from chalicelib.routes.console.notices import done_notice
from chalicelib.settings import get_settings
from chalicelib.views.overlay_links import OverlayLinkOptions, overlay_link
from drem_web import render

bp = Blueprint(__name__)

EVENT_EDITORS = {ADMIN, OPERATOR}


@route(bp, "/console/events", allow=EVENT_EDITORS)
def events_page(principal: User) -> Response:
    return render.page("console/events", events=services.event_service().list_events(),
                       flash=done_notice(bp.current_request))


@route(bp, "/console/events/{event_id}/overlay", allow=EVENT_EDITORS, query=OverlayLinkOptions)
def overlay_link_page(principal: User, event_id: str, query: OverlayLinkOptions) -> Response:
    """Build the OBS browser-source address of a track's overlay: each option explained, the link to paste"""
    event = services.event_service().get_event(event_id)
    event.track(query.track)  # NotFound for a track the event does not have
    public_url = get_settings().public_url.rstrip("/")
    link = overlay_link(public_url, event_id, query)
    # The preview opens the same overlay on the address this page was reached at (the template adds the base path).
    return render.page("console/overlay_link", event=event, options=query, link=link,
                       path=link.removeprefix(public_url))


@route(bp, "/console/events/new", allow=EVENT_EDITORS)
def new_event_page(principal: User) -> Response:
    return _form_page(None, event_form.blank_form(), {})


@route(bp, "/console/events", methods=["POST"], allow=EVENT_EDITORS)
def create_event(principal: User) -> Response:
    values = submitted(bp.current_request)  # every field: the track rows are numbered
    try:
        services.event_service().create_event(principal, event_form.event_input(values))
    except SHOWN_ON_FORM as exc:
        return _form_page(None, event_form.posted_form(values), _event_errors(exc, values), error_status(exc))
    return redirect("/console/events", done="event-created")


@route(bp, "/console/events/{event_id}/edit", allow=EVENT_EDITORS)
def edit_event_page(principal: User, event_id: str) -> Response:
    return _form_page(event_id, event_form.form_of(services.event_service().get_event(event_id)), {})


@route(bp, "/console/events/{event_id}", methods=["POST"], allow=EVENT_EDITORS)
def update_event(principal: User, event_id: str) -> Response:
    values = submitted(bp.current_request)
    try:
        services.event_service().update_event(principal, event_id, event_form.event_input(values))
    except SHOWN_ON_FORM as exc:
        return _form_page(event_id, event_form.posted_form(values), _event_errors(exc, values), error_status(exc))
    return redirect("/console/events", done="event-saved")


@route(bp, "/console/events/{event_id}/logo", methods=["POST"], allow=EVENT_EDITORS)
def upload_logo(principal: User, event_id: str) -> Response:
    """Store the posted image (file input `logo`) as the event's logo, shown on its big screen, overlay and page"""
    upload = uploaded_file(bp.current_request, logo_image.FIELD)
    try:
        services.event_logo_service().save(event_id, upload.data if upload else b"")
    except SHOWN_ON_FORM as exc:
        view = event_form.form_of(services.event_service().get_event(event_id))
        return _form_page(event_id, view, field_errors(exc, logo_image.FIELD), error_status(exc))
    return redirect(f"/console/events/{event_id}/edit#logo", done="logo-saved")


@route(bp, "/console/events/{event_id}/logo/remove", methods=["POST"], allow=EVENT_EDITORS)
def remove_logo(principal: User, event_id: str) -> Response:
    services.event_logo_service().remove(event_id)
    return redirect(f"/console/events/{event_id}/edit#logo", done="logo-removed")


@route(bp, "/console/events/{event_id}/delete", allow=EVENT_EDITORS)
def confirm_delete_page(principal: User, event_id: str) -> Response:
    return render.page("console/event_delete", event=services.event_service().get_event(event_id), errors={})


@route(bp, "/console/events/{event_id}/delete", methods=["POST"], allow=EVENT_EDITORS)
def delete_event(principal: User, event_id: str) -> Response:
    try:
        services.event_service().delete_event(principal, event_id)
    except SHOWN_ON_FORM as exc:
        # The confirmation has no inputs: every refusal (races still on a track) goes at its top.
        return render.page("console/event_delete", status=error_status(exc),
                           event=services.event_service().get_event(event_id),
                           errors=field_errors(exc, rename=lambda _name: "form"))
    return redirect("/console/events", done="event-deleted")


def _event_errors(exc: Exception, values: dict[str, str]) -> dict[str, str]:
    return event_form.country_message(field_errors(exc, rename=event_form.rename_for(values)), values)


def _form_page(event_id: str | None, view: event_form.EventFormView, errors: dict[str, str],
               status: int = 200) -> Response:
    logo = services.event_logo_service().version(event_id) if event_id else None
    return render.page("console/event_form", status=status, event_id=event_id, form=view, errors=errors,
                       fleets=services.fleet_service().list_fleets(), countries=COUNTRY_CHOICES, logo=logo,
                       flash=done_notice(bp.current_request))
