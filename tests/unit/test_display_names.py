"""Racers' real names: a display name in any script beside a simple sign-in name that is unique whatever its case.

What the issue's racers met: Björn_Andersson, Zoë.Müller, 山田太郎, 김민준, نور … refused by the desk and sign-up,
and boards, PDFs and statistics showing ASCII spellings."""
from __future__ import annotations

import json
import re
import unicodedata
from pathlib import Path

import pytest

from chalicelib.core.errors import InvalidInput
from chalicelib.domain.names import DISPLAY_NAME_MAX, check_display_name, grapheme_count
from tests.unit.pdf_helpers import pdf_text
from tests.unit.race_helpers import Desk
from tests.unit.scenario import Scenario
from tests.unit.users_helpers import call, error_message, sign_up_body

pytestmark = pytest.mark.unit

REAL_NAMES = ("Björn_Andersson", "Zoë.Müller", "José-García", "Amélie", "山田太郎", "Søren", "Łukasz", "Siobhán",
              "김민준", "نور", "Émile", "O’Brien", "Jean Luc")


@pytest.mark.parametrize("name", REAL_NAMES)
def test_real_names_in_any_script_are_display_names(name: str) -> None:
    assert check_display_name(name) == name


def test_a_name_typed_with_combining_accents_is_stored_composed_and_counted_as_seen() -> None:
    typed = "Ame\u0301lie"  # e + COMBINING ACUTE, as some keyboards send it
    stored = check_display_name(typed)
    assert stored == "Amélie" and unicodedata.is_normalized("NFC", stored)
    # 40 user-perceived characters pass even when each is two code points; the 41st is refused.
    assert grapheme_count("e\u0301" * DISPLAY_NAME_MAX) == DISPLAY_NAME_MAX
    assert check_display_name("x\u0323\u0301" * DISPLAY_NAME_MAX)  # three code points per letter, NFC keeps two
    with pytest.raises(InvalidInput, match="1 to 40 characters"):
        check_display_name("é" * (DISPLAY_NAME_MAX + 1))


@pytest.mark.parametrize("name", ["\u202eevil", "Anna\u2066x", "نور\u200f", "a\u061cb"])
def test_text_direction_controls_are_refused_with_their_own_message(name: str) -> None:
    with pytest.raises(InvalidInput, match="text-direction control") as refused:
        check_display_name(name)
    assert refused.value.field == "display_name"


@pytest.mark.parametrize("name", ["<script>", "a\u0000b", "🏎 Fast", "\u0301abc", "   "])
def test_markup_controls_emoji_and_lone_accents_are_refused(name: str) -> None:
    with pytest.raises(InvalidInput):
        check_display_name(name)


def test_sign_up_keeps_the_display_name_beside_the_simple_sign_in_name(client) -> None:
    for index, name in enumerate(REAL_NAMES):
        status, body = call(client, "POST", "/api/signup", sign_up_body(f"racer{index}", display_name=name))
        assert status == 201, (name, body)
        status, public = call(client, "GET", f"/api/profiles/racer{index}")
        assert status == 200 and (public["username"], public["display_name"]) == (f"racer{index}", name)
    # A real name where the sign-in name goes says where it belongs.
    status, body = call(client, "POST", "/api/signup", sign_up_body("Björn_Andersson"))
    assert status == 400 and body["error"]["field"] == "username"
    assert "write your name as you spell it under Display name" in error_message(body)


def test_sign_in_names_are_unique_whatever_their_case(client, users) -> None:
    users.create("admin", ("admin",))
    status, body = call(client, "POST", "/api/signup", sign_up_body("ADMIN"))
    assert status == 409 and error_message(body) == "The user name 'ADMIN' is taken."
    assert call(client, "POST", "/api/signup", sign_up_body("Mia.K"))[0] == 201
    for other in ("mia.k", "MIA.K"):
        assert call(client, "POST", "/api/signup", sign_up_body(other))[0] == 409
    staff = users.access_token("desk", ("registration",))
    status, body = call(client, "POST", "/api/users", {"username": "mia.K", "email": "m@example.test",
                                                       "country_code": "SE"}, token=staff)
    assert status == 409 and body["error"]["field"] == "username"


def test_sign_in_works_in_either_case(browser, client, users) -> None:
    assert call(client, "POST", "/api/signup", sign_up_body("Mia.K"))[0] == 201
    users.create("admin", ("admin",))  # made outside drem (as `drem up` makes the first admin): no profile yet
    browser.get("/login")
    reply = browser.post("/login", {"username": "ADMIN", "password": sign_up_body()["password"],
                                    "csrf_token": browser.csrf_token})
    assert reply.status_code == 303 and "Signed in as <strong>admin</strong>" in browser.get("/").body.decode()
    browser.cookies.clear()
    for typed in ("mia.k", "MIA.K", "Mia.K"):
        browser.get("/login")
        reply = browser.post("/login", {"username": typed, "password": sign_up_body()["password"],
                                        "csrf_token": browser.csrf_token})
        assert reply.status_code == 303, (typed, reply.body[:300])
        assert "Signed in as <strong>Mia.K</strong>" in browser.get("/").body.decode()


def test_boards_overlay_results_and_statistics_show_the_display_name(client, desk: Desk, scenario: Scenario,
                                                                       tmp_path: Path) -> None:
    staff = desk.token("desk", "registration")
    for username, name in (("yamada", "山田太郎"), ("noor", "نور"), ("bjorn", "Björn_Andersson"), ("minjun", "김민준")):
        status, body = call(client, "POST", "/api/users", {"username": username, "email": f"{username}@example.test",
                                                           "country_code": "SE", "display_name": name}, token=staff)
        assert status == 201, body
    scenario.add_event()
    eid = scenario.event_id
    for username, lap in (("yamada", 9_000), ("noor", 9_500), ("minjun", 9_700)):
        scenario.submitted_race(username, [lap])
    scenario.add_race("bjorn", [12_000])  # live: on the overlay
    board = desk.board(eid)
    assert [e["username"] for e in board["entries"]][:2] == ["山田太郎", "نور"]
    overlay = json.loads(desk.anonymous_get(f"/api/overlay/{eid}").body)
    assert overlay["username"] == "Björn_Andersson"
    page = desk.anonymous_get(f"/leaderboard/{eid}").body.decode()
    assert "山田太郎" in page and "نور" in page and ">yamada<" not in page
    assert "/api/profiles/yamada/avatar.svg" in page  # the avatar keeps the account's address
    stats = desk.anonymous_get("/stats").body.decode()
    assert "山田太郎" in stats and ">yamada<" not in stats
    summary = desk.call("GET", f"/api/events/{eid}/results/summary.pdf", headers={"Accept": "application/pdf"})
    text = pdf_text(summary.body, tmp_path)
    assert "山田太郎" in text and "김민준" in text and "yamada" not in text
    # Arabic is shaped (HarfBuzz): pdftotext reads the joined letters back in logical order.
    assert "نور" in text
    certificates = desk.call("GET", f"/api/events/{eid}/results/certificates.pdf?track=1",
                             headers={"Accept": "application/pdf"})
    # Nobody here picked a colour: their certificate frame and avatar are the board's blue stripe, not grey.
    from chalicelib.routes.results import load_results
    board = load_results(eid).boards[0]
    assert {entry.colour for entry in board.entries} == {"#0000ff"}
    (tmp_path / "certificates").mkdir()
    assert "김민준" in pdf_text(certificates.body, tmp_path / "certificates")
    # Named like the CSVs: after the event, not its id.
    assert 'filename="summit-stockholm-2026-summary.pdf"' in summary.headers["Content-Disposition"]
    laps_csv = desk.call("GET", f"/api/events/{eid}/export/summary.csv").body.decode()
    assert "山田太郎" in laps_csv and "نور" in laps_csv and "yamada" not in laps_csv


# --- two racers of one display name (issue 31) ---------------------------------------------------------------------


def test_only_display_names_that_collide_carry_the_sign_in_name() -> None:
    from drem_leaderboard.names import told_apart

    shown = told_apart({"a": ("Björn", "bjorn_a"), "b": ("björn", "bjorn_b"), "c": ("Bjo\u0308rn", "bjorn_c"),
                        "d": ("Zoë", "zoe"), "e": ("STRASSE", "s1"), "f": ("Straße", "s2")})
    # Case, and é typed as e + combining accent, do not make two names: the first three collide, as do the last two.
    assert shown == {"a": "Björn (bjorn_a)", "b": "björn (bjorn_b)", "c": "Bjo\u0308rn (bjorn_c)", "d": "Zoë",
                     "e": "STRASSE (s1)", "f": "Straße (s2)"}
    assert told_apart({"a": ("Björn", "bjorn_a")}) == {"a": "Björn"}  # alone: the name as it is


def test_two_racers_called_bjorn_are_told_apart_on_boards_overlay_results_and_csv(client, desk: Desk,
                                                                                   scenario: Scenario,
                                                                                   tmp_path: Path) -> None:
    staff = desk.token("desk", "registration")
    for username in ("bjorn_a", "bjorn_b", "zoe_m"):
        name = {"zoe_m": "Zoë"}.get(username, "Björn")
        status, body = call(client, "POST", "/api/users", {"username": username, "email": f"{username}@example.test",
                                                           "country_code": "SE", "display_name": name}, token=staff)
        assert status == 201, body
    scenario.add_event()
    eid = scenario.event_id
    scenario.submitted_race("bjorn_a", [9_000])
    scenario.submitted_race("zoe_m", [9_500])
    scenario.add_race("bjorn_b", [12_000])  # live, and slower: the overlay must show the second Björn's place

    board = desk.board(eid)
    assert [e["username"] for e in board["entries"]] == ["Björn (bjorn_a)", "Zoë", "Björn (bjorn_b)"]
    assert "racer_sub" not in board["entries"][0]  # whose entry it is stays on the server
    overlay = json.loads(desk.anonymous_get(f"/api/overlay/{eid}").body)
    assert (overlay["username"], overlay["position"]) == ("Björn (bjorn_b)", 3)
    page = desk.anonymous_get(f"/leaderboard/{eid}").body.decode()
    assert "Björn (bjorn_a)" in page and "Björn (bjorn_b)" in page
    commentator = desk.call("GET", f"/commentator/{eid}").body.decode()
    assert "Björn (bjorn_b)" in commentator

    for kind in ("end", "submit"):  # results and CSVs count submitted races
        desk.ok(desk.command(eid, scenario.race_id, kind))
    summary = desk.call("GET", f"/api/events/{eid}/results/summary.pdf", headers={"Accept": "application/pdf"})
    text = pdf_text(summary.body, tmp_path)
    assert "Björn (bjorn_a)" in text and "Björn (bjorn_b)" in text and "Zoë" in text and "(zoe_m)" not in text
    csv_text = desk.call("GET", f"/api/events/{eid}/export/summary.csv").body.decode()
    assert "Björn (bjorn_a)" in csv_text and "Björn (bjorn_b)" in csv_text and "(zoe_m)" not in csv_text
    certificates = desk.call("GET", f"/api/events/{eid}/results/certificates.pdf?track=1",
                             headers={"Accept": "application/pdf"})
    (tmp_path / "certificates").mkdir()
    assert "Björn (bjorn_b)" in pdf_text(certificates.body, tmp_path / "certificates")


def test_two_racers_called_bjorn_are_told_apart_on_the_statistics_page(client, desk: Desk,
                                                                        scenario: Scenario) -> None:
    staff = desk.token("desk", "registration")
    for username, name in (("bjorn_a", "Björn"), ("yamada", "山田"), ("bjorn_b", "björn")):
        status, body = call(client, "POST", "/api/users", {"username": username, "email": f"{username}@example.test",
                                                           "country_code": "SE", "display_name": name}, token=staff)
        assert status == 201, body
    scenario.add_event()
    for username, lap in (("bjorn_a", 9_000), ("yamada", 9_500), ("bjorn_b", 9_700)):
        scenario.submitted_race(username, [lap])

    page = desk.anonymous_get("/stats").body.decode()
    tables = re.findall(r'data-testid="(stats-fastest[^"]*)">(.*?)</table>', page, re.S)
    assert len(tables) >= 2  # the fastest laps overall and per track type
    for testid, table in tables:
        names = [re.findall(r"<td[^>]*>([^<]*)</td>", row)[1] for row in re.findall(r"<tr>(.*?)</tr>", table, re.S)
                 if "<td" in row]
        assert names == ["Björn (bjorn_a)", "山田", "björn (bjorn_b)"], (testid, names)
