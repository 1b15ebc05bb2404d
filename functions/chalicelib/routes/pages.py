"""The start page, static assets, the site icon, and the answer for URLs no route knows."""
from __future__ import annotations

import mimetypes
import re

from chalice import Blueprint, Response

from chalicelib.auth.access import PUBLIC, route
from chalicelib.core.errors import NotFound
from chalicelib.core.principals import Principal
from chalicelib.routes.navigation import links_for
from drem_web import favicon, render

bp = Blueprint(__name__)

_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$")
_BINARY_PREFIXES = ("image/png", "image/jpeg", "image/gif", "font/", "application/octet-stream")


@route(bp, "/", allow=PUBLIC)
def home(principal: Principal) -> Response:
    return render.page("home", roles=sorted(r.value for r in principal.roles), links=links_for(principal))


@route(bp, "/static/{name}", allow=PUBLIC, shared=True)
def static_file(principal: Principal, name: str) -> Response:
    return _static(name, "", max_age=300)


@route(bp, "/static/vendor/{name}", allow=PUBLIC, shared=True)
def vendor_file(principal: Principal, name: str) -> Response:
    # Vendored files are pinned by package-lock.json; they change only with a new release of drem.
    return _static(name, "vendor", max_age=86400)


@route(bp, "/static/vendor/flags/{name}", allow=PUBLIC, shared=True)
def flag_file(principal: Principal, name: str) -> Response:
    # flag-icons' 4×3 SVGs, copied at setup (Makefile); named by lower-case ISO 3166-1 alpha-2 code.
    return _static(name, "vendor/flags", max_age=86400)


@route(bp, "/favicon.ico", allow=PUBLIC, shared=True)
def favicon_ico(principal: Principal) -> Response:
    """drem's icon (browsers ask for it on every site; a 403 here put an error in every page's console)"""
    return Response(body=favicon.ico_bytes(), headers={"Content-Type": favicon.CONTENT_TYPE,
                                                       "Cache-Control": "public, max-age=86400"})


# URLs no route matches: API Gateway (and Chalice's local gateway) answer them 403 "Missing Authentication Token".
# The local app server (drem_local.appserver) hands them to these two routes instead, so a browser gets the site's
# 404 page and an API client a JSON 404, both through the same middleware as every other answer.
NOT_FOUND_PATH = "/_drem/not-found"
API_NOT_FOUND_PATH = "/api/_drem/not-found"


@route(bp, NOT_FOUND_PATH, allow=PUBLIC)
def page_not_found(principal: Principal) -> Response:
    raise NotFound("There is no page at this address. Check the link, or start again from the start page.")


@route(bp, API_NOT_FOUND_PATH, allow=PUBLIC)
def api_not_found(principal: Principal) -> Response:
    raise NotFound("There is no API route at this path; GET /api/docs lists every route.")


def _static(name: str, folder: str, *, max_age: int) -> Response:
    base = (render.STATIC_DIR / folder).resolve()
    path = (base / name).resolve() if _SAFE_NAME.match(name) and ".." not in name else None
    if path is None or path.parent != base or not path.is_file():
        raise NotFound(f"There is no static file {name!r}.")
    mimetype = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
    binary = mimetype.startswith(_BINARY_PREFIXES)
    body = path.read_bytes() if binary else path.read_text(encoding="utf-8")
    content_type = mimetype if binary else f"{mimetype}; charset=utf-8"
    return Response(body=body, headers={"Content-Type": content_type, "Cache-Control": f"public, max-age={max_age}"})
