"""JSON API for racers' model archives, and the S3 upload-complete event handler (registered in app.py).

Per-object rule (chalicelib.domain.racer_models): a racer sees, completes and deletes only their own models (another
racer's model answers 403); admins and operators see and act on every model.
"""
from __future__ import annotations

import logging
from typing import Any

from chalice import Blueprint, Response

from chalicelib import logs, services
from chalicelib.auth.access import SIGNED_IN, route
from chalicelib.core.principals import User
from chalicelib.domain.model_scrutiny import ScrutineerRequest
from chalicelib.domain.racer_models import ListQuery, UploadRequest
from chalicelib.settings import get_settings

bp = Blueprint(__name__)


@route(bp, "/api/models", methods=["POST"], allow=SIGNED_IN, body=UploadRequest, status_code=201)
def request_upload(principal: User, body: UploadRequest) -> Response:
    ticket = services.model_service().request_upload(principal, body)
    return Response(body=ticket.public(), status_code=201)


@route(bp, "/api/models/{model_id}/complete", methods=["POST"], allow=SIGNED_IN)
def complete_upload(principal: User, model_id: str) -> dict:
    return {"model": services.model_service().complete(principal, model_id).public()}


@route(bp, "/api/models", allow=SIGNED_IN, query=ListQuery)
def list_models(principal: User, query: ListQuery) -> dict:
    page = services.model_service().list_models(principal, query)
    return {"models": [model.shown_to(principal) for model in page.models], "next": page.next_token}


@route(bp, "/api/models/{model_id}", allow=SIGNED_IN)
def get_model(principal: User, model_id: str) -> dict:
    return {"model": services.model_service().get(principal, model_id).shown_to(principal)}


@route(bp, "/api/models/{model_id}", methods=["DELETE"], allow=SIGNED_IN)
def delete_model(principal: User, model_id: str) -> dict:
    return {"model": services.model_service().delete(principal, model_id).public()}


@route(bp, "/api/models/{model_id}/scrutineer", methods=["POST"], allow=SIGNED_IN, body=ScrutineerRequest)
def scrutineer_model(principal: User, model_id: str, body: ScrutineerRequest) -> dict:
    """Test-drive the model in the simulator on an event's track (owner, admins, operators); the result is kept."""
    return {"model": services.scrutineer_service().scrutineer(principal, model_id, body).shown_to(principal)}


@route(bp, "/api/models/{model_id}/scrutineer/clip.gif", allow=SIGNED_IN,
       summary="The top-down GIF of the model's last background test drive (owner, admins, operators)")
def scrutineer_clip(principal: User, model_id: str) -> Response:
    body = services.scrutineer_service().clip(principal, model_id)
    return Response(body=body, status_code=200, headers={"Content-Type": "image/gif",
                                                         "Cache-Control": "private, max-age=60"})


def handle_upload_complete_event(event: dict[str, Any]) -> dict[str, Any]:
    """EventBridge "Object Created" (models bucket, uploads/ prefix) → validate the upload, exactly like /complete."""
    detail = event.get("detail") or {}
    bucket = (detail.get("bucket") or {}).get("name")
    key = (detail.get("object") or {}).get("key")
    if bucket != get_settings().bucket("models") or not isinstance(key, str):
        logs.log(logging.WARNING, "upload event for another bucket ignored", bucket=bucket, key=key)
        return {"ignored": True}
    record = services.model_service().complete_upload_key(key)
    return {"model_id": record.model_id, "status": record.status.value} if record else {"ignored": True}
