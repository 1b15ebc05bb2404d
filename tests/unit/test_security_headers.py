"""Security headers on every response: CSP (no inline script anywhere), framing, nosniff, referrer, HSTS, and no
`public` caching of a response that sets a cookie."""
from __future__ import annotations

import re

import pytest

from tests.unit.conftest import bearer, cookie_attributes

pytestmark = pytest.mark.unit


def _csp(response) -> dict[str, str]:
    policy = response.headers["Content-Security-Policy"]
    return {part.split(" ", 1)[0]: part.split(" ", 1)[1] for part in policy.split("; ")}


@pytest.mark.parametrize("path", ["/", "/login", "/api/me", "/healthz", "/static/drem.css", "/static/missing.css",
                                  "/console/users"])
def test_every_response_carries_the_security_headers(client, stack, path):
    response = client.http.get(path, headers={"Accept": "text/html"})

    csp = _csp(response)
    assert csp["script-src"] == "'self'" and csp["object-src"] == "'none'" and csp["frame-ancestors"] == "'none'"
    assert csp["form-action"] == "'self'" and csp["base-uri"] == "'self'"
    assert response.headers["X-Frame-Options"] == "DENY"
    assert response.headers["X-Content-Type-Options"] == "nosniff"
    assert response.headers["Referrer-Policy"] == "same-origin"
    assert "Strict-Transport-Security" not in response.headers  # plain http: HSTS would be ignored or harmful


def test_a_signed_in_api_answer_carries_them_too(client, users):
    response = client.http.get("/api/me", headers=bearer(users.access_token("rita", ("racer",))))

    assert response.status_code == 200 and response.headers["X-Content-Type-Options"] == "nosniff"


@pytest.mark.parametrize("path", ["/overlay/e-1", "/leaderboard/e-1"])
def test_overlay_and_leaderboard_stay_embeddable_by_stream_tools(client, stack, path):
    response = client.http.get(path, headers={"Accept": "text/html"})

    assert _csp(response)["frame-ancestors"] == "*"
    assert "X-Frame-Options" not in response.headers
    assert _csp(response)["script-src"] == "'self'"


def test_hsts_when_served_over_https(client, stack, monkeypatch):
    from chalicelib.settings import get_settings

    monkeypatch.setenv("DREM_PUBLIC_URL", "https://drem.example")
    get_settings.cache_clear()

    assert client.http.get("/login").headers["Strict-Transport-Security"].startswith("max-age=")


def test_hsts_behind_an_https_proxy(client, stack):
    response = client.http.get("/login", headers={"X-Forwarded-Proto": "https"})

    assert "max-age=" in response.headers["Strict-Transport-Security"]


def test_static_files_set_no_cookie_so_a_shared_cache_keeps_them(client, stack):
    # CloudFront's cache forwards no cookies: to the app every static request looks like a first visit.
    first = client.http.get("/static/drem.css")
    assert cookie_attributes(first.headers, "drem_csrf") is None
    assert first.headers["Cache-Control"] == "public, max-age=300"
    icon = client.http.get("/favicon.ico", headers={"Accept": "image/avif,image/webp,*/*;q=0.8"})
    assert cookie_attributes(icon.headers, "drem_csrf") is None and icon.headers["Cache-Control"].startswith("public")
    form_page = client.http.get("/login")  # a page with a form still gets its CSRF token
    assert cookie_attributes(form_page.headers, "drem_csrf") is not None


def test_an_answer_that_sets_a_cookie_is_never_publicly_cacheable(stack):
    from chalice import Response

    from chalicelib.security_headers import add_security_headers
    from chalicelib.settings import get_settings

    class _Request:
        path, headers, context = "/anything", {}, {}

    response = Response(body="", headers={"Cache-Control": "public, max-age=300", "Set-Cookie": "drem_csrf=x"})
    add_security_headers(response, _Request(), get_settings())
    assert response.headers["Cache-Control"] == "private, max-age=300"


def test_upload_target_is_allowed_for_connect_only(client, stack):
    csp = _csp(client.http.get("/login"))

    assert csp["connect-src"].split()[0] == "'self'" and len(csp["connect-src"].split()) == 2


def test_no_template_carries_inline_script_the_policy_would_block(repo_root):
    # Inline handlers and inline <script> would be blocked by script-src 'self'; drem.js attaches behaviour.
    offenders = []
    for template in (repo_root / "web/drem_web/templates").rglob("*.html"):
        html = template.read_text()
        if re.search(r"\son[a-z]+\s*=", html) or re.search(r"\shx-on", html) or "javascript:" in html:
            offenders.append(template.name)
        for script in re.findall(r"<script\b[^>]*>", html):
            if "src=" not in script:
                offenders.append(f"{template.name}: {script}")
    assert offenders == []
