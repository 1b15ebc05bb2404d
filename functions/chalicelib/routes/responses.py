"""Small response helpers shared by the route modules."""
from __future__ import annotations

import re
from urllib.parse import unquote, urlsplit

from chalice import Response

from drem_web import render

# A same-site path: "/" then RFC 3986 path/query characters only. No whitespace or control characters (browsers
# strip tabs and newlines, so "/\t/evil" becomes "//evil"), no backslash (browsers read "/\evil" as "//evil").
_SAFE_PATH = re.compile(r"/[A-Za-z0-9\-._~!$&'()*+,;=:@/%?#]*")
# Percent-decoding rounds to look through: an attacker may encode the dangerous part once or twice.
_DECODE_ROUNDS = 3


def redirect(location: str, *, cookies: list[str] | None = None) -> Response:
    """The one way the app redirects: `location` is the app's own path ("/console/events"); the browser is sent to it
    under the request's base path (render.url)."""
    # 303: after a form POST the browser follows with a GET, so a reload never re-submits the form.
    headers: dict = {"Location": render.url(location)}
    if cookies:
        headers["Set-Cookie"] = list(cookies)
    return Response(body="", status_code=303, headers=headers)


def etag_matches(etag: str, if_none_match: str | None) -> bool:
    """Whether an `If-None-Match` header names `etag` (weak comparison: a `W/` prefix is ignored, RFC 9110 13.1.2)."""
    offered = [tag.strip().removeprefix("W/") for tag in (if_none_match or "").split(",")]
    return etag in offered


def safe_next(path: str | None) -> str:
    """Only same-site paths: "/races" yes; "//evil", "/\\evil", "/\\t/evil", "https://…", or any of those
    percent-encoded, no (open redirects). Anything doubtful becomes "/"."""
    if not path or len(path) > 2048 or not _SAFE_PATH.fullmatch(path):
        return "/"
    decoded = path
    for _ in range(_DECODE_ROUNDS):
        if not _same_site(decoded):
            return "/"
        decoded, previous = unquote(decoded), decoded
        if decoded == previous:
            return path
    return "/"  # still changing after several rounds of decoding: nothing a real page link needs


def _same_site(path: str) -> bool:
    if not path.startswith("/") or path[1:2] in ("/", "\\"):
        return False
    if any(ch.isspace() or ord(ch) < 0x20 or ord(ch) == 0x7F or ch == "\\" for ch in path):
        return False
    parts = urlsplit(path)
    return not parts.scheme and not parts.netloc
