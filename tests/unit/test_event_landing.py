"""The event landing page (`/event/{id}`): the page the QR code on every board opens, with the tracks' live boards,
the stream team's overlay links and the organiser's links."""
from __future__ import annotations

import html
import re

import pytest

from tests.unit.race_helpers import Desk

pytestmark = pytest.mark.unit

HTML = {"Accept": "text/html"}


def _links(page: str, testid: str) -> list[tuple[str, str]]:
    block = re.search(rf'data-testid="{testid}">(.*?)</ul>', page, re.S).group(1)
    return [(html.unescape(href), re.sub(r"<[^>]+>", "", text).strip())
            for href, text in re.findall(r'<a[^>]*href="([^"]+)"[^>]*>(.*?)</a>', block, re.S)]


def test_landing_page_lists_boards_overlays_and_the_organisers_links(desk: Desk) -> None:
    body = {"name": "Summit <Stockholm>", "event_type": "AWS_SUMMIT", "date": "2026-05-14", "country_code": "SE",
            "sponsor": "Acme", "tracks": [{"track_id": "1", "leaderboard_title": "Main track"},
                                          {"track_id": "2", "direction": "clockwise"}],
            "landing_page_links": [{"name": "Upload your model", "href": "/console/my-models"},
                                   {"name": "Survey", "href": "https://example.org/s?a=1&b=2",
                                    "description": "Tell us how it went"}]}
    eid = desk.ok(desk.call("POST", "/api/events", body), 201)["event_id"]
    reply = desk.anonymous_get(f"/event/{eid}", headers=HTML)
    assert reply.status_code == 200
    page = reply.body.decode()
    assert "<h1>Summit &lt;Stockholm&gt;</h1>" in page  # escaped, never markup
    assert _links(page, "landing-links") == [("/console/my-models", "Upload your model"),
                                             ("https://example.org/s?a=1&b=2", "Survey")]
    assert "Tell us how it went" in page
    assert _links(page, "landing-boards") == [(f"/leaderboard/{eid}?track=1", "Main track"),
                                              (f"/leaderboard/{eid}?track=2", "Track 2"),
                                              (f"/leaderboard/{eid}?track=combined", "All tracks combined")]
    overlays = [href for href, _ in _links(page, "landing-overlays")]
    assert overlays == [f"/overlay/{eid}?trackId=1", f"/overlay/{eid}?trackId=1&chroma=true",
                        f"/overlay/{eid}?trackId=2", f"/overlay/{eid}?trackId=2&chroma=true"]
    for href in overlays[:1] + [f"/leaderboard/{eid}?track=combined"]:
        assert desk.anonymous_get(href, headers=HTML).status_code == 200  # every link works
    assert desk.anonymous_get("/event/no-such-event", headers=HTML).status_code == 404


def test_the_board_qr_opens_the_landing_page_on_the_public_url(desk: Desk, monkeypatch) -> None:
    import cv2
    import numpy as np

    from chalicelib.settings import get_settings
    from tests.unit.test_public_pages import _qr_matrix

    monkeypatch.setenv("DREM_PUBLIC_URL", "https://race.example.org")
    get_settings.cache_clear()
    eid = desk.event()["event_id"]
    page = desk.anonymous_get(f"/leaderboard/{eid}", headers=HTML).body.decode()
    svg = re.search(r'data-testid="qr"><svg.*?</svg>', page, re.S).group(0)
    grid = _qr_matrix(svg[svg.index("<svg"):])
    image = np.pad(np.kron(~grid, np.ones((8, 8), dtype=bool)).astype(np.uint8) * 255, 32, constant_values=255)
    decoded, _points, _ = cv2.QRCodeDetector().detectAndDecode(image)
    assert decoded == f"https://race.example.org/event/{eid}"
    assert f"https://race.example.org/event/{eid}" in page  # the address printed under the code matches
