"""An organiser uploads the event's logo on its edit page; the big screen, the overlay and the event's page show it,
a new upload shows at once, and only event staff can change it."""
from __future__ import annotations

import io
import json
import re
import uuid

import pytest
from PIL import Image

from tests.unit.operator_console_helpers import field_error

pytestmark = pytest.mark.unit

IMAGE_ACCEPT = "image/avif,image/webp,image/apng,image/svg+xml,image/*,*/*;q=0.8"


def _png(size: tuple[int, int], colour: tuple[int, int, int, int]) -> bytes:
    out = io.BytesIO()
    Image.new("RGBA", size, colour).save(out, format="PNG")
    return out.getvalue()


def _upload(console, event_id: str, data: bytes, *, filename: str = "logo.png", csrf: str | None = None):
    """The logo form as a browser posts it: multipart, the CSRF token as a field beside the file."""
    boundary = uuid.uuid4().hex
    token = console.web.csrf_token if csrf is None else csrf
    body = (f'--{boundary}\r\nContent-Disposition: form-data; name="csrf_token"\r\n\r\n{token}\r\n'
            f'--{boundary}\r\nContent-Disposition: form-data; name="logo"; filename="{filename}"\r\n'
            f"Content-Type: image/png\r\n\r\n").encode() + data + f"\r\n--{boundary}--\r\n".encode()
    headers = {"Content-Type": f"multipart/form-data; boundary={boundary}", "Accept": "text/html",
               "Cookie": "; ".join(f"{k}={v}" for k, v in console.web.cookies.items())}
    return console.web.client.http.post(f"/console/events/{event_id}/logo", headers=headers, body=body)


def _fetch(console, src: str, **headers: str):
    """The image as CloudFront asks for it (no cookies: its cache policy forwards none) with Chromium's Accept."""
    return console.web.client.http.get(src, headers={"Accept": IMAGE_ACCEPT, **headers})


def _logo_src(html: str, testid: str) -> str:
    match = re.search(rf'<img class="[^"]*" data-testid="{testid}" src="([^"]+)"', html)
    assert match, f"no {testid} on the page"
    return match.group(1).replace("&amp;", "&")


@pytest.fixture
def event_id(console) -> str:
    console.sign_in("eve", "operator")
    return console.desk.event(tracks=[{"track_id": "1"}])["event_id"]


def test_an_uploaded_logo_shows_on_the_big_screen_the_overlay_and_the_event_page(console, event_id):
    assert 'data-testid="board-logo"' not in console.web.get(f"/leaderboard/{event_id}").body.decode()

    reply = _upload(console, event_id, _png((600, 200), (255, 153, 0, 255)))

    assert reply.status_code == 303
    assert reply.headers["Location"] == f"/console/events/{event_id}/edit?done=logo-saved#logo"
    edit = console.web.get(f"/console/events/{event_id}/edit?done=logo-saved").body.decode()
    assert "Logo saved; the big screen, the overlay and the event&#39;s page show it." in edit
    src = _logo_src(console.web.get(f"/leaderboard/{event_id}").body.decode(), "board-logo")
    assert src == _logo_src(console.web.get(f"/overlay/{event_id}").body.decode(), "overlay-logo")
    assert src == _logo_src(console.web.get(f"/event/{event_id}").body.decode(), "landing-logo")
    assert src == _logo_src(edit, "logo-preview")

    image = _fetch(console, src)
    assert image.status_code == 200, image.body
    assert image.headers["Content-Type"] == "image/png"
    assert image.headers["Cache-Control"] == "public, max-age=31536000, immutable"
    assert "Set-Cookie" not in image.headers  # a cookie would make it private: CloudFront would not keep it
    assert Image.open(io.BytesIO(image.body)).getpixel((300, 100)) == (255, 153, 0)


def test_the_big_screen_fetched_by_htmx_shows_its_header_too(console, event_id):
    """htmx asks for a page's content only (HX-Request): the big screen's header parts come from an imported macro
    file, which that request used to miss (a 500, "'screen' is undefined")."""
    _upload(console, event_id, _png((300, 100), (255, 0, 0, 255)))
    reply = console.web.client.http.get(f"/leaderboard/{event_id}", headers={"HX-Request": "true",
                                                                             "Accept": "text/html"})
    assert reply.status_code == 200, reply.body[:300]
    html = reply.body.decode()
    assert 'data-testid="board-title"' in html and _logo_src(html, "board-logo") and "<html" not in html


def test_a_new_logo_gets_a_new_address_so_screens_show_it_at_once(console, event_id):
    _upload(console, event_id, _png((300, 100), (255, 0, 0, 255)))
    first = _logo_src(console.web.get(f"/leaderboard/{event_id}").body.decode(), "board-logo")
    _upload(console, event_id, _png((300, 100), (0, 0, 255, 255)))
    second = _logo_src(console.web.get(f"/leaderboard/{event_id}").body.decode(), "board-logo")

    assert first != second
    stale = _fetch(console, first)  # an old link is revalidated, never kept for good
    assert stale.headers["Cache-Control"] == "public, no-cache"
    assert Image.open(io.BytesIO(stale.body)).getpixel((5, 5)) == (0, 0, 255)
    etag = stale.headers["ETag"]
    assert _fetch(console, second, **{"If-None-Match": etag}).status_code == 304


def test_a_file_that_is_not_an_image_is_named_next_to_the_logo_input_and_the_old_logo_stays(console, event_id):
    _upload(console, event_id, _png((300, 100), (255, 0, 0, 255)))
    before = _logo_src(console.web.get(f"/leaderboard/{event_id}").body.decode(), "board-logo")

    reply = _upload(console, event_id, b"<svg onload=alert(1)>", filename="logo.svg")

    assert reply.status_code == 400
    html = reply.body.decode()
    assert field_error(html, "logo") == "SVG logos are not accepted (an SVG can carry scripts): export it as PNG."
    assert 'value="Summit Stockholm 2026"' in html  # the event form is still there, as saved
    assert _logo_src(console.web.get(f"/leaderboard/{event_id}").body.decode(), "board-logo") == before


def test_removing_the_logo_leaves_the_boards_text_only(console, event_id):
    _upload(console, event_id, _png((300, 100), (255, 0, 0, 255)))
    src = _logo_src(console.web.get(f"/leaderboard/{event_id}").body.decode(), "board-logo")

    reply = console.post(f"/console/events/{event_id}/logo/remove", {})

    assert reply.status_code == 303 and reply.headers["Location"].endswith("?done=logo-removed#logo")
    assert 'data-testid="board-logo"' not in console.web.get(f"/leaderboard/{event_id}").body.decode()
    assert _fetch(console, src).status_code == 404


def test_deleting_the_event_deletes_its_logo(console, event_id):
    _upload(console, event_id, _png((300, 100), (255, 0, 0, 255)))
    src = _logo_src(console.web.get(f"/leaderboard/{event_id}").body.decode(), "board-logo")
    assert console.post(f"/console/events/{event_id}/delete", {}).status_code == 303
    assert _fetch(console, src).status_code == 404


def test_only_event_staff_change_the_logo_and_a_forged_post_is_refused(console, event_id):
    logo = _png((300, 100), (255, 0, 0, 255))
    assert _upload(console, event_id, logo, csrf="forged-token").status_code == 403

    console.web.cookies.clear()
    console.sign_in("rita", "racer")
    assert _upload(console, event_id, logo).status_code == 403
    assert console.post(f"/console/events/{event_id}/logo/remove", {}).status_code == 403
    assert 'data-testid="board-logo"' not in console.web.get(f"/leaderboard/{event_id}").body.decode()


def test_the_api_takes_a_logo_as_the_image_body_and_removes_it(console, event_id):
    from tests.unit.conftest import bearer

    desk = console.desk
    jpeg = io.BytesIO()
    Image.new("RGB", (800, 200), (0, 120, 255)).save(jpeg, format="JPEG")
    headers = {**bearer(desk.tokens["op"]), "Content-Type": "image/jpeg", "Accept": "application/json"}

    reply = desk.client.http.put(f"/api/events/{event_id}/logo", headers=headers, body=jpeg.getvalue())

    assert reply.status_code == 200, reply.body
    saved = json.loads(reply.body)
    assert (saved["width"], saved["height"]) == (800, 200)
    assert f"/event/{event_id}/logo?v={saved['version']}" in console.web.get(f"/leaderboard/{event_id}").body.decode()
    refused = desk.client.http.put(f"/api/events/{event_id}/logo", headers=headers, body=b"not an image")
    assert refused.status_code == 400
    assert json.loads(refused.body)["error"]["message"].startswith("This file is not a PNG, JPEG, WebP or GIF image")

    assert desk.call("DELETE", f"/api/events/{event_id}/logo").status_code == 204
    assert 'data-testid="board-logo"' not in console.web.get(f"/leaderboard/{event_id}").body.decode()
