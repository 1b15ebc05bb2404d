"""Browsers that have signed in to an account before: their correct password is never refused for someone else's
guesses.

The "device cookie" defence (OWASP, "Slow Down Online Guessing Attacks with Device Cookies"): after a successful
sign-in the browser gets an HttpOnly cookie naming the account, signed by this app process. A sign-in from a browser
holding a valid one for that account is checked first and only counts its own failures; every other attempt shares
the account's small guess budget (`auth/rate_limits.py`). So a guesser at the venue (same address as everyone, behind
one NAT) can neither lock the admin out nor guess faster than that budget.

The signing key lives in this process only: after an app restart (or on another Lambda container on AWS) an older
cookie is simply not recognised and the browser counts as new until its next sign-in; nothing is stored server-side.
"""
from __future__ import annotations

import base64
import hashlib
import hmac
import secrets
import time

DEVICE_COOKIE = "drem_device"
MAX_AGE_S = 90 * 24 * 3600
_KEY = secrets.token_bytes(32)


def issue(account: str, now: float | None = None) -> str:
    """A cookie value vouching that this browser signed in to `account` (case-folded) until it expires."""
    expires = int((now if now is not None else time.time()) + MAX_AGE_S)
    payload = f"{_b64(account.strip().casefold())}.{expires}"
    return f"{payload}.{_mac(payload)}"


def device_id(token: str | None, account: str, now: float | None = None) -> str | None:
    """The browser's id (its token's MAC) when `token` is a valid, unexpired cookie for `account`; else None."""
    if not token or token.count(".") != 2:
        return None
    name, expires, mac = token.split(".")
    if not hmac.compare_digest(mac, _mac(f"{name}.{expires}")) or not expires.isdigit():
        return None
    if int(expires) < (now if now is not None else time.time()):
        return None
    if not hmac.compare_digest(name, _b64(account.strip().casefold())):
        return None
    return mac


def _b64(text: str) -> str:
    return base64.urlsafe_b64encode(text.encode()).decode().rstrip("=")


def _mac(payload: str) -> str:
    return base64.urlsafe_b64encode(hmac.new(_KEY, payload.encode(), hashlib.sha256).digest()).decode().rstrip("=")
