"""Cookie names and Set-Cookie headers for browser sessions.

The session cookie holds the Cognito access token, the refresh cookie the refresh token; both HttpOnly so page
scripts never see them, SameSite=Lax so a link from elsewhere still arrives signed in, Path=/, and Secure whenever
the public URL is https.
"""
from __future__ import annotations

from collections.abc import Mapping

SESSION_COOKIE = "drem_session"
REFRESH_COOKIE = "drem_refresh"
CSRF_COOKIE = "drem_csrf"
CHALLENGE_COOKIE = "drem_challenge"

# Cognito's default refresh-token validity; the cookie must not outlive what it holds for long.
REFRESH_MAX_AGE_S = 30 * 24 * 3600


def parse_cookies(header: str | None) -> dict[str, str]:
    """The request's cookies (first value wins, as browsers send the most specific path first)."""
    cookies: dict[str, str] = {}
    for part in (header or "").split(";"):
        name, sep, value = part.strip().partition("=")
        if sep and name and name not in cookies:
            cookies[name] = value.strip().strip('"')
    return cookies


def request_cookies(headers: Mapping[str, str]) -> dict[str, str]:
    return parse_cookies(headers.get("cookie"))


def set_cookie(name: str, value: str, *, secure: bool, max_age: int | None = None, same_site: str = "Lax",
               path: str = "/", http_only: bool = True) -> str:
    parts = [f"{name}={value}", f"Path={path}", f"SameSite={same_site}"]
    if max_age is not None:
        parts.append(f"Max-Age={max_age}")
    if http_only:
        parts.append("HttpOnly")
    if secure:
        parts.append("Secure")
    return "; ".join(parts)


def clear_cookie(name: str, *, secure: bool, path: str = "/", same_site: str = "Lax") -> str:
    return set_cookie(name, "", secure=secure, max_age=0, path=path, same_site=same_site)


def session_cookies(access_token: str, refresh_token: str | None, expires_in: int, *, secure: bool) -> list[str]:
    cookies = [set_cookie(SESSION_COOKIE, access_token, secure=secure, max_age=expires_in)]
    if refresh_token:
        cookies.append(set_cookie(REFRESH_COOKIE, refresh_token, secure=secure, max_age=REFRESH_MAX_AGE_S))
    return cookies


def clear_session_cookies(*, secure: bool) -> list[str]:
    return [clear_cookie(SESSION_COOKIE, secure=secure), clear_cookie(REFRESH_COOKIE, secure=secure)]
