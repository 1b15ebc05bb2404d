"""The base path of a request (chalicelib.base_path): which source wins, and that a forged header can only ever be
a plain path (no other site, no way out of an attribute)."""
from __future__ import annotations

import pytest

from chalicelib import base_path
from chalicelib.settings import Settings

EXECUTE_API = "a1b2c3d4e5.execute-api.eu-west-1.amazonaws.com"


def stage_context(stage: str = "api", host: str = EXECUTE_API, path: str = "/api/console/events") -> dict:
    # The parts of API Gateway's REST proxy requestContext that say where the request was addressed.
    return {"stage": stage, "domainName": host, "path": path, "resourcePath": "/console/events"}


@pytest.mark.parametrize(("header", "expected"), [
    ("/drem", "/drem"),
    ("/drem/", "/drem"),             # Spring's ForwardedHeaderFilter drops the trailing slash too
    ("/", ""),                       # CloudFront's origin: the site is at the root
    ("/events/drem-2026", "/events/drem-2026"),
    ("/outer, /inner", "/inner"),    # a list: the value of the nearest proxy (ProxyFix x_prefix=1)
])
def test_the_proxy_header_names_the_base_path(header, expected):
    assert base_path.for_request({"x-forwarded-prefix": header}, stage_context(), "/configured") == expected


@pytest.mark.parametrize("forged", [
    "https://evil.example", "//evil.example", "/\\evil.example", "/drem/../..", "/./drem", 'drem',
    '/drem"><script>alert(1)</script>', "/drem x", "/drem?next=//evil", "/drem#x", "/%2e%2e", "/dr\tem",
    "/" + "a" * 250,
])
def test_a_header_that_is_not_a_plain_path_is_ignored(forged):
    assert base_path.for_request({"x-forwarded-prefix": forged}, None, "/configured") == "/configured"
    assert base_path.for_request({"x-forwarded-prefix": forged}, stage_context(), "") == "/api"


def test_the_stage_counts_only_on_the_execute_api_host_with_the_stage_in_the_path():
    assert base_path.for_request({}, stage_context(), "") == "/api"
    assert base_path.for_request({}, stage_context(stage="prod", path="/prod"), "") == "/prod"
    # A custom domain (or CloudFront without its header) maps the stage away: the browser never saw it.
    assert base_path.for_request({}, stage_context(host="drem.example.org", path="/console/events"), "") == ""
    assert base_path.for_request({}, stage_context(path="/console/events"), "") == ""
    # chalice local's context has neither stage nor domain name.
    assert base_path.for_request({}, {"path": "/console/events", "resourcePath": "/console/events"}, "") == ""


def test_the_setting_applies_when_nothing_in_the_request_says_otherwise():
    assert base_path.for_request({}, None, "/drem") == "/drem"
    assert Settings.from_env({"DREM_BASE_PATH": "/drem/"}).base_path == "/drem"
    assert Settings.from_env({}).base_path == ""
    with pytest.raises(ValueError, match="DREM_BASE_PATH"):
        Settings.from_env({"DREM_BASE_PATH": "https://example.org/drem"})


def test_absolute_links_carry_the_configured_sub_path():
    # DREM_PUBLIC_URL may name the sub-path itself, or leave it to DREM_BASE_PATH; either way QR codes get both.
    joined = Settings.from_env({"DREM_PUBLIC_URL": "https://example.org/", "DREM_BASE_PATH": "/drem"})
    assert joined.public_url == "https://example.org/drem"
    named = Settings.from_env({"DREM_PUBLIC_URL": "https://example.org/drem", "DREM_BASE_PATH": "/drem"})
    assert named.public_url == "https://example.org/drem"
    assert Settings.from_env({"DREM_PUBLIC_URL": "https://example.org"}).public_url == "https://example.org"


def test_url_puts_only_the_apps_own_paths_under_the_base_path():
    from markupsafe import Markup

    from drem_web import render

    render.bind_request(base_path="/drem")
    try:
        assert render.url("/console/events?event_id=a&b") == "/drem/console/events?event_id=a&b"
        assert render.url("/") == "/drem/"
        for elsewhere in ("https://example.org/x", "//cdn.example.org/x", "data:image/png;base64,AA", "?track=2", ""):
            assert render.url(elsewhere) == elsewhere
        escaped = render.url(Markup("/leaderboard/e?a=1&amp;b=2"))  # concatenated escaped parts stay escaped once
        assert isinstance(escaped, Markup) and escaped == "/drem/leaderboard/e?a=1&amp;b=2"
        page = render.environment().from_string("<a href=\"{{ url('/x?a=' ~ v) }}\">").render(v="1&b=<2>")
        assert page == '<a href="/drem/x?a=1&amp;b=&lt;2&gt;">'
    finally:
        render.bind_request()
    assert render.url("/console/events") == "/console/events"  # outside a request: the root


def test_every_url_attribute_of_every_template_goes_through_url():
    """The crawl reaches the pages a nav shows; this catches a raw "/..." in any template, reached or not."""
    import re

    from drem_web.render import TEMPLATES_DIR

    attribute = re.compile(r'(?<![\w-])(href|src|action|hx-(?:get|post|put|patch|delete)|data-[a-z-]*url)="([^"]*)"')
    raw = [f"{path.relative_to(TEMPLATES_DIR)}: {name}={value}" for path in sorted(TEMPLATES_DIR.rglob("*.html"))
           for name, value in attribute.findall(path.read_text())
           if not value.startswith(("{{ url(", "#", "?", "https://", "mailto:"))]  # "?…": relative to the page
    assert raw == []
