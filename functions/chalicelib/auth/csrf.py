"""Double-submit CSRF protection for cookie-authenticated browser requests.

A random token lives in the `drem_csrf` cookie (SameSite=Strict, HttpOnly: the server renders it into the page) and
must come back, unchanged, in the form field `csrf_token` or the `X-CSRF-Token` header (htmx sends it from
`hx-headers` on <body>). Another site can make the browser send our cookies but cannot read the token to echo it.
Requests with an Authorization header carry no ambient credentials and are exempt.
"""
from __future__ import annotations

import hmac
import secrets
from collections.abc import Mapping

from chalicelib.auth.cookies import CSRF_COOKIE, set_cookie
from chalicelib.domain.errors import CsrfRejected

FORM_FIELD = "csrf_token"
HEADER = "x-csrf-token"
STATE_CHANGING_METHODS = frozenset({"POST", "PUT", "PATCH", "DELETE"})
_MIN_TOKEN_LENGTH = 32


def new_token() -> str:
    return secrets.token_urlsafe(32)


def csrf_cookie(token: str, *, secure: bool) -> str:
    return set_cookie(CSRF_COOKIE, token, secure=secure, same_site="Strict")


def require_matching_token(cookie_token: str | None, headers: Mapping[str, str], form: Mapping[str, str]) -> None:
    submitted = headers.get(HEADER) or form.get(FORM_FIELD) or ""
    if not cookie_token or len(cookie_token) < _MIN_TOKEN_LENGTH or not submitted:
        raise CsrfRejected("This form has expired or was not sent from drem. Reload the page and try again.")
    if not hmac.compare_digest(cookie_token.encode(), submitted.encode()):
        raise CsrfRejected("This form has expired or was not sent from drem. Reload the page and try again.")
