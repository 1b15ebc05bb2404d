"""Racer profiles: own profile, palette rule, public view, admin edits, identicon avatars."""
from __future__ import annotations

from xml.etree import ElementTree

import pytest

from chalicelib.domain.profiles import HIGHLIGHT_PALETTE
from chalicelib.formats.avatars import DEFAULT_COLOUR, avatar_seed, identicon_cells, identicon_svg
from tests.unit.users_helpers import call, error_message

pytestmark = pytest.mark.unit


def _racer_with_country(users, aws_clients, stack, username, country="JP", groups=("racer",)):
    token = users.access_token(username, groups)
    aws_clients.cognito.admin_update_user_attributes(
        UserPoolId=stack.user_pool_id, Username=username,
        UserAttributes=[{"Name": "custom:countryCode", "Value": country}])
    return token


def test_own_profile_starts_with_the_account_country(client, users, aws_clients, stack):
    token = _racer_with_country(users, aws_clients, stack, "kei")
    status, body = call(client, "GET", "/api/me/profile", token=token)
    assert status == 200
    assert (body["username"], body["country_code"], body["highlight_colour"]) == ("kei", "JP", None)


def test_highlight_colour_must_come_from_the_palette(client, users):
    token = users.access_token("kei", ("racer",))
    status, body = call(client, "PUT", "/api/me/profile", {"highlight_colour": "#ff8200"}, token=token)
    assert status == 200 and body["highlight_colour"] == "#FF8200"
    for colour in ("#FFFFFF", "#123456", "red"):
        status, body = call(client, "PUT", "/api/me/profile", {"highlight_colour": colour}, token=token)
        assert status == 400 and body["error"]["field"] == "highlight_colour"
        assert all(hex_colour in error_message(body) for hex_colour in HIGHLIGHT_PALETTE)
    assert call(client, "GET", "/api/me/profile", token=token)[1]["highlight_colour"] == "#FF8200"
    status, body = call(client, "PUT", "/api/me/profile", {"email": "x@example.test"}, token=token)
    assert status == 400


def test_public_profile_shows_only_public_fields(client, users, aws_clients, stack):
    token = _racer_with_country(users, aws_clients, stack, "kei")
    call(client, "PUT", "/api/me/profile", {"highlight_colour": "#0000FF"}, token=token)
    status, body = call(client, "GET", "/api/profiles/KEI")
    assert status == 200
    assert body == {"username": "kei", "display_name": "kei", "country_code": "JP", "highlight_colour": "#0000FF",
                    "avatar_url": "/api/profiles/kei/avatar.svg", "deleted": False}
    assert call(client, "GET", "/api/profiles/nobody")[0] == 404


def test_only_admins_edit_someone_elses_profile(client, users):
    racer_a = users.access_token("racer-a", ("racer",))
    racer_b = users.access_token("racer-b", ("racer",))
    operator = users.access_token("op", ("operator",))
    admin = users.access_token("boss", ("admin",))
    call(client, "GET", "/api/me/profile", token=racer_a)
    assert call(client, "PUT", "/api/users/racer-a/profile", {"highlight_colour": "#FF0000"}, token=racer_b)[0] == 403
    assert call(client, "PUT", "/api/users/racer-a/profile", {"highlight_colour": "#FF0000"}, token=operator)[0] == 403
    status, body = call(client, "PUT", "/api/users/racer-a/profile", {"highlight_colour": "#FF0000"}, token=admin)
    assert status == 200 and body["highlight_colour"] == "#FF0000"
    # A user who never opened their profile (made outside drem) gets one when an admin edits it.
    users.create("imported", ("racer",))
    assert call(client, "PUT", "/api/users/imported/profile", {"avatar": "none"}, token=admin)[0] == 200
    assert call(client, "PUT", "/api/users/ghost/profile", {"avatar": "none"}, token=admin)[0] == 404


def test_avatar_is_a_deterministic_svg_in_the_highlight_colour(client, users):
    token = users.access_token("kei", ("racer",))
    call(client, "PUT", "/api/me/profile", {"highlight_colour": "#7CFC00"}, token=token)
    response = client.http.get("/api/profiles/kei/avatar.svg")
    assert response.status_code == 200
    assert response.headers["Content-Type"] == "image/svg+xml"
    svg = response.body.decode()
    # Drawn from the sign-in name, not the sub: the same avatar after export/import gives the account a new sub.
    assert svg == identicon_svg(avatar_seed("kei"), "#7CFC00", "kei") and 'fill="#7CFC00"' in svg
    assert client.http.get("/api/profiles/kei/avatar.svg").body.decode() == svg

    call(client, "PUT", "/api/me/profile", {"avatar": "none"}, token=token)
    assert client.http.get("/api/profiles/kei/avatar.svg").status_code == 404


def test_a_racer_who_never_picked_a_colour_has_the_boards_blue_avatar(client, users):
    token = users.access_token("ida", ("racer",))
    call(client, "GET", "/api/me/profile", token=token)  # the profile every sign-up and registration makes
    svg = client.http.get("/api/profiles/ida/avatar.svg").body.decode()
    assert f'fill="{DEFAULT_COLOUR}"' in svg and DEFAULT_COLOUR == "#0000FF"  # the stripe's blue, not grey


def test_avatar_escapes_every_value_it_embeds():
    colour, title = '"/><script>alert(1)</script>', "<img src=x onerror=alert(1)>&"
    svg = identicon_svg("sub-1", colour, title)
    assert "<script" not in svg and "<img" not in svg
    # Parsed back, the hostile values are plain text/attribute values and the SVG has only its own elements.
    root = ElementTree.fromstring(svg)
    namespace = "{http://www.w3.org/2000/svg}"
    assert root.find(f"{namespace}title").text == title
    assert root.find(f"{namespace}g").get("fill") == colour
    assert {element.tag.removeprefix(namespace) for element in root.iter()} == {"svg", "title", "rect", "g"}


def test_identicons_are_mirrored_and_differ_between_users():
    cells = set(identicon_cells("user-1"))
    assert all((4 - column, row) in cells for column, row in cells)
    assert identicon_cells("user-1") != identicon_cells("user-2")
