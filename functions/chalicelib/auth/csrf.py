"""CSRF protection for cookie-authenticated (and anonymous) browser requests: a signed double-submit token bound to
the session, plus an Origin check.

The `drem_csrf` cookie (SameSite=Strict, HttpOnly: the server renders it into the page) must come back, unchanged,
in the form field `csrf_token` or the `X-CSRF-Token` header (htmx sends it from `hx-headers` on <body>). Another
site can make the browser send our cookies but cannot read the token to echo it.

Plain double-submit is not enough: cookies ignore ports, so a page served from another port of the same host (or
any site that can set a cookie for our host) can plant a `drem_csrf` of its choosing and echo it. So for a signed-in
session the token is `nonce.HMAC(session secret, nonce)`, where the session secret names the sign-in the request runs
as (`session_secret`: the verified access token's sub and origin_jti): a planted token does not verify against the
victim's session, and nobody who lacks the session can compute one. Signed-out forms carry a plain nonce (there is
no session to ride).

On top, an unsafe request whose `Origin` (or, without it, `Referer`) names another origin than the one it was sent
to is refused, whatever its token. Requests with an Authorization header carry no ambient credentials and are exempt.
"""
from __future__ import annotations

import base64
import hashlib
import hmac
import secrets
from collections.abc import Mapping
from urllib.parse import urlsplit

from chalicelib.auth.cookies import CSRF_COOKIE, set_cookie
from chalicelib.core.errors import CsrfRejected

FORM_FIELD = "csrf_token"
HEADER = "x-csrf-token"
STATE_CHANGING_METHODS = frozenset({"POST", "PUT", "PATCH", "DELETE"})
_MIN_NONCE_LENGTH = 32
_MAC_CONTEXT = b"drem-csrf-v1:"
_REJECTED = "This form has expired or was not sent from drem. Reload the page and try again."
_OTHER_ORIGIN = "This request came from another site, so drem refused it. Use drem's own pages."


def session_secret(sub: str, origin_jti: str | None, access_token: str) -> str:
    """What a signed-in browser session's token is bound to: the sign-in the request runs as.

    `origin_jti` is shared by every token of one sign-in, refreshes included (Cognito), and is known only to whoever
    holds that session's tokens; with the user's sub it names exactly the session whose user the request acts as.
    (It was the refresh cookie, while the request ran as the access cookie's user: a planted refresh cookie with a
    token bound to it, beside the victim's access cookie, fitted; only the Origin check stopped that mixed pair.)"""
    return f"{sub}:{origin_jti}" if origin_jti else f"{sub}:{access_token}"


def new_token(secret: str | None = None) -> str:
    nonce = secrets.token_urlsafe(32)
    return f"{nonce}.{_mac(secret, nonce)}" if secret else nonce


def fits(token: str | None, secret: str | None) -> bool:
    """Is `token` a well-formed token for this session (any nonce when signed out)?"""
    if not token:
        return False
    nonce, dot, mac = token.partition(".")
    if len(nonce) < _MIN_NONCE_LENGTH:
        return False
    if secret is None:
        return True
    return bool(dot) and hmac.compare_digest(mac.encode(), _mac(secret, nonce).encode())


def csrf_cookie(token: str, *, secure: bool) -> str:
    return set_cookie(CSRF_COOKIE, token, secure=secure, same_site="Strict")


def bound_cookie(secret: str, *, secure: bool) -> str:
    """A fresh token for a session that is just starting (sign-in), as a Set-Cookie."""
    return csrf_cookie(new_token(secret), secure=secure)


def require_matching_token(cookie_token: str | None, secret: str | None, headers: Mapping[str, str],
                           form: Mapping[str, str]) -> None:
    submitted = headers.get(HEADER) or form.get(FORM_FIELD) or ""
    if not submitted or not fits(cookie_token, secret):
        raise CsrfRejected(_REJECTED)
    if not hmac.compare_digest(str(cookie_token).encode(), submitted.encode()):
        raise CsrfRejected(_REJECTED)


def require_same_origin(headers: Mapping[str, str], public_url: str) -> None:
    """Refuse when the browser says the request comes from another origin. Browsers send `Origin` on every
    cross-origin POST; a request with neither header (curl, old browsers) still needs the token."""
    origin = headers.get("origin")
    if origin is None:
        referer = headers.get("referer")
        if not referer:
            return
        parts = urlsplit(referer)
        origin = f"{parts.scheme}://{parts.netloc}"
    if origin.strip().lower().rstrip("/") not in _own_origins(headers, public_url):
        raise CsrfRejected(_OTHER_ORIGIN)


def _own_origins(headers: Mapping[str, str], public_url: str) -> set[str]:
    # The configured public URL, and the host the browser addressed (loopback and a LAN address both serve drem);
    # a cross-site page can change neither: the browser sets Host to where the request goes.
    parts = urlsplit(public_url)
    own = {f"{parts.scheme}://{parts.netloc}".lower()}
    host = (headers.get("host") or "").strip().lower()
    if host:
        own |= {f"http://{host}", f"https://{host}"}
    return own


def _mac(secret: str, nonce: str) -> str:
    digest = hmac.new(secret.encode(), _MAC_CONTEXT + nonce.encode(), hashlib.sha256).digest()
    return base64.urlsafe_b64encode(digest).rstrip(b"=").decode()
