"""drem behind a reverse proxy under a sub-path, in a real browser: the proxy serves the live stack's app at `/drem/`
only (nginx-style: the prefix stripped, `X-Forwarded-Prefix: /drem` added, the Host kept) and answers anything else
404. An operator signs in, creates an event and opens its leaderboard; not one request of the browser (pages, forms,
redirects, htmx polls, scripts, styles, icons) leaves the prefix."""
from __future__ import annotations

import http.client
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any
from urllib.parse import urlsplit

import pytest

from tests.browser.console_api import PASSWORD, create_user

pytestmark = pytest.mark.browser

PREFIX = "/drem"
# Headers a proxy does not pass along hop by hop (RFC 9110 7.6.1); Content-Length is set again from the body.
HOP_BY_HOP = {"connection", "keep-alive", "proxy-connection", "transfer-encoding", "upgrade", "te", "trailer",
              "content-length"}


@dataclass
class SubPathProxy:
    upstream: str
    url: str = ""
    served: list[str] = field(default_factory=list)
    outside: list[str] = field(default_factory=list)


def _handler(proxy: SubPathProxy) -> type[BaseHTTPRequestHandler]:
    upstream = urlsplit(proxy.upstream)

    class Handler(BaseHTTPRequestHandler):
        def log_message(self, *_args: Any) -> None:
            pass

        def _forward(self) -> None:
            if not self.path.startswith(PREFIX + "/"):
                proxy.outside.append(f"{self.command} {self.path}")
                self.send_error(404, "outside the proxied prefix")
                return
            proxy.served.append(f"{self.command} {self.path}")
            body = self.rfile.read(int(self.headers.get("Content-Length") or 0))
            headers = {name: value for name, value in self.headers.items()
                       if name.lower() not in HOP_BY_HOP and name.lower() != "x-forwarded-prefix"}
            headers["X-Forwarded-Prefix"] = PREFIX  # replaces whatever the client sent, as proxy_set_header does
            connection = http.client.HTTPConnection(upstream.hostname, upstream.port, timeout=30)
            try:
                connection.request(self.command, self.path[len(PREFIX):], body=body or None, headers=headers)
                answer = connection.getresponse()
                payload = answer.read()
                self.send_response(answer.status, answer.reason)
                for name, value in answer.getheaders():
                    if name.lower() not in HOP_BY_HOP:
                        self.send_header(name, value)
                self.send_header("Content-Length", str(len(payload)))
                self.end_headers()
                self.wfile.write(payload)
            finally:
                connection.close()

        do_GET = do_POST = do_PUT = do_PATCH = do_DELETE = do_HEAD = _forward

    return Handler


@pytest.fixture
def sub_path_proxy(app_url: str) -> Iterator[SubPathProxy]:
    proxy = SubPathProxy(upstream=app_url)
    server = ThreadingHTTPServer(("127.0.0.1", 0), _handler(proxy))
    proxy.url = f"http://127.0.0.1:{server.server_address[1]}"
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield proxy
    server.shutdown()
    server.server_close()


def test_an_operator_works_through_a_proxy_under_a_sub_path(live_stack, sub_path_proxy, page, browser_errors):
    # This proxy forwards the app only (no route to the live server): the board's stream is refused and it polls.
    browser_errors.allow(rf"{PREFIX}/live/leaderboard/.*status of 404")
    site = sub_path_proxy.url + PREFIX
    create_user(live_stack, "subpath-op", "operator")
    asked: list[str] = []
    page.on("request", lambda request: asked.append(request.url))

    # Asked for a console page, the browser is sent to sign in and back, under the prefix.
    page.goto(site + "/console/events")
    page.wait_for_url(site + "/login?next=/console/events")
    page.fill("#username", "subpath-op")
    page.fill("#password", PASSWORD)
    page.get_by_role("button", name="Sign in").click()
    page.wait_for_url(site + "/console/events")

    page.get_by_role("link", name="New event").click()
    page.wait_for_url(site + "/console/events/new")
    page.fill("#name", "Sub-path Summit")
    page.fill("#date", "2026-06-01")
    page.fill("#country_code", "Sweden (SE)")
    page.fill("#track-1-title", "Main track")
    page.get_by_role("button", name="Create event").click()
    page.wait_for_url(site + "/console/events?done=event-created")
    assert page.get_by_test_id("notice").inner_text() == "Event created."

    row = page.locator("tr", has_text="Sub-path Summit")
    row.get_by_role("link", name="Leaderboard").click()
    page.wait_for_url(f"{site}/leaderboard/**")
    event_id = page.url.split("/leaderboard/")[1].split("?")[0]
    # The board polls for updates through htmx: that request stays under the prefix too.
    with page.expect_request(lambda request: f"{PREFIX}/leaderboard/{event_id}/live" in request.url):
        pass

    assert sub_path_proxy.outside == [], "requests the proxy had to refuse"
    stray = [url for url in asked if not url.startswith(site + "/")]
    assert stray == [], f"browser requests outside {site}/"
    assert any(path.startswith(f"GET {PREFIX}/static/") for path in sub_path_proxy.served), "styles and scripts"
    assert any(path.startswith(f"POST {PREFIX}/console/events") for path in sub_path_proxy.served), "the event form"
