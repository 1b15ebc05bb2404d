"""HTML rendering: `page(name, **ctx)` for templates/pages/{name}.html, `fragment(name, **ctx)` for
templates/partials/{name}.html, both returning a text/html Chalice Response.

A page asked for by htmx (`HX-Request: true`) comes back as its `content` block only, so `hx-get` + `hx-target` can
swap the main region without a second copy of the layout. The backend binds per-request values (the principal, the
CSRF token, whether htmx asked, the base path) with `bind_request`; every template sees them.

Every URL a page holds goes through `url(path)` (a template global): the app's own root-relative path, put under the
base path the browser reached drem at (`/api` on the execute-api host, `/drem` behind a proxy; chalicelib.base_path
decides it per request). Absolute URLs, `data:` URIs and anything not starting with one "/" pass through unchanged.
"""
from __future__ import annotations

import threading
from functools import lru_cache
from pathlib import Path
from typing import Any

from chalice import Response
from jinja2 import Environment, FileSystemLoader, StrictUndefined, select_autoescape
from markupsafe import Markup

TEMPLATES_DIR = Path(__file__).resolve().parent / "templates"
STATIC_DIR = Path(__file__).resolve().parent / "static"
HTML = "text/html; charset=utf-8"

_local = threading.local()


@lru_cache(maxsize=1)
def environment() -> Environment:
    from drem_web import labels

    env = Environment(loader=FileSystemLoader(TEMPLATES_DIR), autoescape=select_autoescape(default=True),
                      undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True)
    env.filters.update(label=labels.label, laptime=labels.laptime)
    env.globals["url"] = url
    return env


def base_path() -> str:
    """The current request's base path ("" at the root; "/api", "/drem" under a prefix; never a trailing "/")."""
    return str((getattr(_local, "globals", None) or {}).get("base_path", ""))


def url(path: str) -> str:
    """`path` (the app's own root-relative path, e.g. "/console/events") as the browser must ask for it."""
    if not isinstance(path, str) or not path.startswith("/") or path.startswith("//"):
        return path
    if isinstance(path, Markup):  # a template concatenated escaped parts: keep it escaped exactly once
        return Markup(base_path()) + path
    return base_path() + path


def bind_request(*, htmx: bool = False, **request_globals: Any) -> None:
    """Values every template of the current request can use (e.g. principal, csrf_token)."""
    _local.htmx = htmx
    _local.globals = request_globals


def _context(ctx: dict[str, Any]) -> dict[str, Any]:
    merged = {"principal": None, "csrf_token": "", "flash": "", "base_path": ""}
    merged.update(getattr(_local, "globals", None) or {})
    merged.update(ctx)
    return merged


def render_page(name: str, *, htmx: bool = False, **ctx: Any) -> str:
    template = environment().get_template(f"pages/{name}.html")
    context = _context(ctx)
    if htmx and "content" in template.blocks:
        return "".join(template.blocks["content"](template.new_context(context)))
    return template.render(context)


def page(name: str, *, status: int = 200, headers: dict[str, str] | None = None, **ctx: Any) -> Response:
    body = render_page(name, htmx=getattr(_local, "htmx", False), **ctx)
    return Response(body=body, status_code=status, headers={"Content-Type": HTML, **(headers or {})})


def fragment(name: str, *, status: int = 200, headers: dict[str, str] | None = None, **ctx: Any) -> Response:
    body = environment().get_template(f"partials/{name}.html").render(_context(ctx))
    return Response(body=body, status_code=status, headers={"Content-Type": HTML, **(headers or {})})
