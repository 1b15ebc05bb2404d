"""The start page and static assets."""
from __future__ import annotations

import mimetypes
import re

from chalice import Blueprint, Response

from chalicelib.auth.access import PUBLIC, route
from chalicelib.auth.principals import Principal
from chalicelib.domain.errors import NotFound
from chalicelib.routes.navigation import links_for
from drem_web import render

bp = Blueprint(__name__)

_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$")
_BINARY_PREFIXES = ("image/png", "image/jpeg", "image/gif", "font/", "application/octet-stream")


@route(bp, "/", allow=PUBLIC)
def home(principal: Principal) -> Response:
    return render.page("home", roles=sorted(r.value for r in principal.roles), links=links_for(principal))


@route(bp, "/static/{name}", allow=PUBLIC)
def static_file(principal: Principal, name: str) -> Response:
    return _static(name, "", max_age=300)


@route(bp, "/static/vendor/{name}", allow=PUBLIC)
def vendor_file(principal: Principal, name: str) -> Response:
    # Vendored files are pinned by package-lock.json; they change only with a new release of drem.
    return _static(name, "vendor", max_age=86400)


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
