"""GET /healthz: is storage reachable, and (locally) how is the durable server's state dir."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib.auth.access import PUBLIC, route
from chalicelib.auth.principals import Principal
from chalicelib.domain.health import check_health
from chalicelib.settings import get_settings
from chalicelib.storage import clients
from chalicelib.storage.health import fetch_durable_health, probe_table

bp = Blueprint(__name__)


@route(bp, "/healthz", allow=PUBLIC)
def healthz(principal: Principal) -> Response:
    settings = get_settings()
    endpoint = settings.endpoint_url
    report = check_health(
        storage_label=settings.storage_label, region=settings.region, stage=settings.stage,
        probe_table=lambda: probe_table(clients.dynamodb(), settings.table("events")),
        durable_health=(lambda: fetch_durable_health(endpoint)) if endpoint else None,
    )
    return Response(body=report.model_dump(), status_code=200 if report.healthy else 503,
                    headers={"Cache-Control": "no-store"})
