"""GET /healthz: is storage reachable, and (locally) how is the durable server's state dir.

Anyone (load balancers, `drem up` waiting for the app) gets only `{"status": ...}` and 200/503; the details (storage
URL, region, stage, state dir path, moto version) help an attacker map the install, so only staff see them."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import PUBLIC, STAFF, route
from chalicelib.core.principals import Principal
from chalicelib.domain.health import check_health
from chalicelib.settings import get_settings
from chalicelib.storage.health import fetch_durable_health

bp = Blueprint(__name__)


@route(bp, "/healthz", allow=PUBLIC)
def healthz(principal: Principal) -> Response:
    settings = get_settings()
    endpoint = settings.endpoint_url
    report = check_health(
        storage_label=settings.storage_label, region=settings.region, stage=settings.stage,
        probe_table=services.probe_storage,
        durable_health=(lambda: fetch_durable_health(endpoint)) if endpoint else None,
    )
    body = report.model_dump() if principal.roles & STAFF else {"status": report.status}
    return Response(body=body, status_code=200 if report.healthy else 503,
                    headers={"Cache-Control": "no-store"})
