"""The drem API and web app. This file only wires things together: middleware, one Blueprint per URL area, and the
Lambda entry points that are not HTTP routes."""
from __future__ import annotations

from chalice import Chalice

from chalicelib import logs
from chalicelib.core.principals import set_device_credential_verifier
from chalicelib.formats import logo_image
from chalicelib.routes import (
    accounts,
    api_docs,
    assignments,
    booth,
    booth_pages,
    commentator,
    devices,
    event_landing,
    event_logos,
    events,
    fleets,
    health,
    labels,
    leaderboards,
    league,
    login,
    pages,
    ping,
    profiles,
    public_pages,
    racer_models,
    races,
    registry,
    results,
    stats,
    timing,
    users,
)
from chalicelib.routes.console import events as console_events
from chalicelib.routes.console import fleets as console_fleets
from chalicelib.routes.console import models as console_models
from chalicelib.routes.console import racer as console_racer
from chalicelib.routes.console import racer_queue as console_racer_queue
from chalicelib.routes.console import races as console_races
from chalicelib.routes.console import registration as console_registration
from chalicelib.routes.console import timekeeper as console_timekeeper
from chalicelib.routes.console import users as console_users
from chalicelib.security_headers import security_headers_middleware
from drem_infra.resources import UPLOAD_COMPLETE_FUNCTION
from drem_web import favicon

app = Chalice(app_name="drem")
app.register_middleware(logs.request_log_middleware, "http")
app.register_middleware(security_headers_middleware, "http")
# Bodies of these types are bytes. Chalice base64-encodes such responses for API Gateway, which decodes them for the
# viewer whatever the viewer's Accept header says (the stack sets the API's own binary media types to */*:
# infra_cdk/drem_infra/stack.py). Printed results and labels are PDFs; a model's scrutineering clip is a GIF; an
# event's logo is stored as PNG or WebP and uploaded as any of logo_image.UPLOAD_TYPES; a form with a file input is
# multipart; /favicon.ico is an icon; a league push uploads a .tar.gz.
for binary_type in ("application/pdf", *sorted({"image/gif", *logo_image.CONTENT_TYPES, *logo_image.UPLOAD_TYPES}),
                    "multipart/form-data", favicon.CONTENT_TYPE, "application/gzip", "application/x-gzip"):
    app.api.binary_types.append(binary_type)

for blueprint_module in (pages, health, login, accounts, users, profiles, events, fleets, devices, racer_models,
                         assignments, races, timing, leaderboards, api_docs, public_pages, commentator, console_events,
                         console_fleets, console_timekeeper, console_races, console_racer, console_registration,
                         console_users, console_models, console_racer_queue, league, registry, results, labels,
                         stats, event_landing, event_logos, booth, booth_pages, ping):
    app.register_blueprint(blueprint_module.bp)

set_device_credential_verifier(devices.verify_device_credential)


@app.lambda_function(name=UPLOAD_COMPLETE_FUNCTION)
def upload_complete(event, context):
    """On AWS: the models bucket's EventBridge "Object Created" rule for uploads/ lands here."""
    return racer_models.handle_upload_complete_event(event)
