"""The base path the browser reached drem under, decided once per request: every URL the app produces starts with it
(templates through `render.url`, redirects through `responses.redirect`, scripts through `<meta name="drem-base">`).

In order, the first that applies:
1. `X-Forwarded-Prefix`, set by the proxy in front ("/drem" behind `https://example.org/drem/`; "/" from the CloudFront
   origin, which serves the site at its root). Like werkzeug's ProxyFix (`x_prefix=1`) the last value of a list is
   the one the nearest proxy set; like Spring's ForwardedHeaderFilter a trailing "/" is dropped.
2. On API Gateway, the stage ("/api") when the request came to the execute-api host itself: API Gateway strips the
   stage before the app sees the path, and names it in the request context (`stage`, `domainName`, and `path`, which
   still starts with it; chalice keeps that context as `Request.context`, chalice 1.34.0 chalice/app.py
   `Request.__init__`: `self.context = event_dict['requestContext']`).
3. The `DREM_BASE_PATH` setting.
4. "" (the site at the root).

Trust: the header is honoured from whoever sends it, the way the app already treats `X-Forwarded-Proto`
(security_headers: it only adds HSTS to that answer). It changes nothing but the links in the answer to that very
request: pages are rendered per request, the live-fragment cache keys carry the base path, and HTML answers say
`Vary: X-Forwarded-Prefix` so a shared cache never hands one client's variant to another. CloudFront replaces a
viewer's header of the same name with its origin header, and a proxy configured per docs/operations.md sets it. A
value that is not a plain path (segments of unreserved characters only: no scheme, host, "//", "..", quotes or
spaces) is ignored, so a forged header can never point a link at another site or break out of an attribute.
"""
from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

FORWARDED_PREFIX_HEADER = "X-Forwarded-Prefix"
MAX_LENGTH = 200
_SEGMENT = r"[A-Za-z0-9_~-][A-Za-z0-9._~-]*"
_PLAIN_PATH = re.compile(rf"(?:/{_SEGMENT})*/?")
# https://{api-id}.execute-api.{region}.amazonaws.com (also .com.cn in the China regions).
_EXECUTE_API_HOST = re.compile(r"[a-z0-9]+\.execute-api\.[a-z0-9-]+\.amazonaws\.com(?:\.cn)?")


def normalise(value: str) -> str | None:
    """`value` as a base path ("" for "/", no trailing "/"), or None when it is not a plain path."""
    value = value.strip()
    if len(value) > MAX_LENGTH or not value.startswith("/") or not _PLAIN_PATH.fullmatch(value):
        return None
    if any(segment in (".", "..") for segment in value.split("/")):
        return None
    return value.rstrip("/")


def from_forwarded_header(headers: Mapping[str, str]) -> str | None:
    raw = headers.get(FORWARDED_PREFIX_HEADER.lower())
    if raw is None:
        return None
    return normalise(raw.split(",")[-1])


def from_api_gateway_stage(context: Mapping[str, Any] | None) -> str | None:
    """"/{stage}" when API Gateway delivered a request addressed to its own execute-api host (a custom domain or
    CloudFront in front maps the stage away, and says so with its own prefix)."""
    context = context or {}
    stage, host, path = context.get("stage"), str(context.get("domainName") or ""), str(context.get("path") or "")
    if not isinstance(stage, str) or not _EXECUTE_API_HOST.fullmatch(host.lower()):
        return None
    prefix = normalise(f"/{stage}")
    if not prefix or not (path == prefix or path.startswith(prefix + "/")):
        return None
    return prefix


def for_request(headers: Mapping[str, str], context: Mapping[str, Any] | None, configured: str) -> str:
    """The base path of one request (see the module docstring for the order)."""
    forwarded = from_forwarded_header(headers)
    if forwarded is not None:
        return forwarded
    stage = from_api_gateway_stage(context)
    if stage is not None:
        return stage
    return configured
