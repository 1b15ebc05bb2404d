"""Issue 13 (event day), as a browser and an API client meet the app server: unknown URLs get a 404 (the site's
page, or JSON under /api/), /favicon.ico is drem's icon, and a tab closed mid-poll leaves no traceback in the log."""
from __future__ import annotations

import socket
import struct

import pytest
import requests

pytestmark = pytest.mark.integration

BROWSER = {"Accept": "text/html,application/xhtml+xml,application/xml;q=0.9,*/*;q=0.8"}


def test_an_unknown_address_is_a_404_page_for_a_browser_and_json_for_the_api(live_stack):
    page = requests.get(live_stack.url + "/no/such/page", headers=BROWSER, timeout=10)
    assert page.status_code == 404 and page.headers["Content-Type"].startswith("text/html")
    assert "Not found" in page.text and "Missing Authentication Token" not in page.text
    assert 'href="/"' in page.text  # a way back

    api = requests.get(live_stack.url + "/api/no-such-route", headers={"Accept": "application/json"}, timeout=10)
    assert api.status_code == 404 and api.json()["error"]["code"] == "NotFound"
    posted = requests.post(live_stack.url + "/api/no/such/thing", json={}, timeout=10)
    assert posted.status_code == 404

    # Known routes keep their own answers (a real 403 stays a 403).
    assert requests.get(live_stack.url + "/api/users", timeout=10).status_code == 401


def test_favicon_is_an_ico_and_every_page_names_an_svg_icon(live_stack):
    icon = requests.get(live_stack.url + "/favicon.ico", timeout=10)
    assert icon.status_code == 200 and icon.headers["Content-Type"] == "image/x-icon"
    reserved, kind, count = struct.unpack("<HHH", icon.content[:6])
    assert (reserved, kind, count) == (0, 1, 1) and icon.content[6] == 32  # one 32×32 icon
    home = requests.get(live_stack.url + "/", headers=BROWSER, timeout=10).text
    assert 'rel="icon" href="/static/favicon.svg"' in home
    svg = requests.get(live_stack.url + "/static/favicon.svg", timeout=10)
    assert svg.status_code == 200 and svg.headers["Content-Type"].startswith("image/svg+xml")


def test_a_tab_closed_mid_poll_leaves_no_traceback_in_the_app_log(live_stack):
    log = live_stack.state_dir / "logs" / "app.log"
    before = log.stat().st_size
    request = (b"GET /api/docs HTTP/1.1\r\nHost: 127.0.0.1\r\nAccept: text/html\r\n\r\n")
    for _ in range(15):  # bounded: each one resets the connection before the answer is written
        with socket.create_connection(("127.0.0.1", int(live_stack.url.rsplit(":", 1)[1])), timeout=5) as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            sock.sendall(request)
    # The app server (waitress) drops a vanished client's connection without logging it (log_socket_errors off):
    # once it answers again, everything the resets could have written is in the log.
    assert requests.get(live_stack.url + "/healthz", timeout=10).status_code == 200
    written = log.read_text()[before:]
    assert "Traceback" not in written and "BrokenPipeError" not in written and "Socket error" not in written
