"""The JSON API described: `GET /api/openapi.json` (OpenAPI 3.1, generated from the route declarations) and
`GET /api/docs` (the same, as a page people can read)."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib.auth.access import PUBLIC, route
from chalicelib.core.principals import Principal
from chalicelib.openapi import build_document, operation_rows
from drem_web import render

bp = Blueprint(__name__)


@route(bp, "/api/openapi.json", allow=PUBLIC, tags=("docs",))
def openapi_document(principal: Principal) -> Response:
    """The OpenAPI 3.1 document of the JSON API"""
    return Response(body=build_document(bp.current_app), headers={"Cache-Control": "no-cache"})


@route(bp, "/api/docs", allow=PUBLIC, tags=("docs",))
def api_docs_page(principal: Principal) -> Response:
    """Every API operation: who may call it and what it takes"""
    return render.page("api_docs", operations=operation_rows(build_document(bp.current_app)))
