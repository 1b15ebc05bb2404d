"""Security headers on every response (Chalice HTTP middleware, registered in app.py).

* Content-Security-Policy: scripts only from drem itself (no inline scripts or handlers: drem.js attaches them; htmx
  runs without eval), no plugins, forms and `<base>` only to drem; `connect-src` adds the storage origin browsers
  upload models to (the local storage server, or S3 on AWS) and the live server's origin when it has its own
  (`DREM_LIVE_URL`: the public pages' event streams). Inline `style` attributes stay allowed: templates set
  racer colours as CSS variables, and a style cannot run code. `/_storage/...` (the local storage gateway) is
  answered before the app runs, with its own `Content-Security-Policy: sandbox`.
* frame-ancestors: 'none' (with X-Frame-Options DENY for old browsers) except the overlay and leaderboard pages,
  which stream producers embed in a browser source or a production dashboard's frame. They are public and
  read-only, so a framing page has nothing to trick anyone into clicking.
* nosniff, Referrer-Policy same-origin (event and model ids stay on drem), HSTS when served over HTTPS.
* A response that sets a cookie is never `public` in a shared cache (the cookie would be handed to others).
"""
from __future__ import annotations

from typing import Any
from urllib.parse import urlsplit

from chalice import Response
from chalice.app import Request

from chalicelib.settings import Settings, get_settings

EMBEDDABLE_PREFIXES = ("/overlay/", "/leaderboard/")
HSTS = "max-age=31536000"


def security_headers_middleware(event: Request, get_response: Any) -> Response:
    response = get_response(event)
    add_security_headers(response, event, get_settings())
    return response


def add_security_headers(response: Response, request: Request, settings: Settings) -> None:
    headers = response.headers
    embeddable = (request.path or "").startswith(EMBEDDABLE_PREFIXES)
    headers["Content-Security-Policy"] = content_security_policy(settings, embeddable=embeddable)
    if not embeddable:
        headers["X-Frame-Options"] = "DENY"
    headers["X-Content-Type-Options"] = "nosniff"
    headers["Referrer-Policy"] = "same-origin"
    if _served_over_https(request, settings):
        headers["Strict-Transport-Security"] = HSTS
    cache = headers.get("Cache-Control") or ""
    if isinstance(cache, str) and headers.get("Set-Cookie") and "public" in cache:
        headers["Cache-Control"] = cache.replace("public", "private")


def content_security_policy(settings: Settings, *, embeddable: bool) -> str:
    connect = ["'self'", _upload_origin(settings)]
    images = ["'self'", "data:", "blob:"]  # blob: the car's eye paints each camera frame from one (car_eye.js)
    if settings.live_origin and settings.live_origin not in connect:
        connect.append(settings.live_origin)  # the live pages' event stream (drem_live) on its own port
        images.append(settings.live_origin)  # staff's camera previews (an MJPEG <img> on the Cars page)
    directives = {
        "default-src": "'self'",
        "script-src": "'self'",
        "style-src": "'self' 'unsafe-inline'",
        "img-src": " ".join(images),
        "connect-src": " ".join(connect),
        "object-src": "'none'",
        "base-uri": "'self'",
        "form-action": "'self'",
        "frame-ancestors": "*" if embeddable else "'none'",
    }
    return "; ".join(f"{name} {value}" for name, value in directives.items())


def _upload_origin(settings: Settings) -> str:
    if settings.endpoint_url:
        # Presigned links point at the app's storage gateway under the public URL, which may be another origin than
        # the one a page was opened from (127.0.0.1 on the laptop, the LAN address in the links).
        parts = urlsplit(settings.public_url)
        return f"{parts.scheme}://{parts.netloc}"
    return "https://*.amazonaws.com"  # presigned S3 POSTs go to the bucket's own host


def _served_over_https(request: Request, settings: Settings) -> bool:
    forwarded = request.headers.get("x-forwarded-proto", "")
    return settings.cookie_secure or forwarded.lower() == "https"
