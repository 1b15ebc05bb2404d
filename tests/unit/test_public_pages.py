"""The public leaderboard page, the stream overlay and the commentator view over the real app (moto, real tokens):
what a viewer sees, escaping of hostile names, the query switches, the QR code, and cheap unchanged polls."""
from __future__ import annotations

import re
from typing import Any

import numpy as np
import pytest

from tests.unit.race_helpers import Desk, FakeClock
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit

HOSTILE_NAME = "<script>alert('pwned')</script>"


def html_get(desk: Desk, path: str, headers: dict[str, str] | None = None) -> Any:
    return desk.client.http.get(path, headers={"Accept": "text/html", **(headers or {})})


def racing(desk: Desk, clock: FakeClock, racer: str = "vera", laps: tuple[int, ...] = (10_000,),
           event_name: str = "Summit Stockholm 2026") -> tuple[str, str]:
    """(event id, race id): `racer`'s live race with `laps` at a new event."""
    scenario = Scenario(desk, clock).add_racers(racer).add_event(name=event_name).add_race(racer, laps)
    return scenario.event_id, scenario.race_id


def hostile_profile(desk: Desk, username: str, *, display: str, colour: str, country: str | None = "DE") -> None:
    from chalicelib.domain.profiles import Profile
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from chalicelib.storage.profiles import DynamoProfileStore

    sub = next(a["Value"] for a in desk.users.clients.cognito.admin_get_user(
        UserPoolId=desk.users.outputs.user_pool_id, Username=username)["UserAttributes"] if a["Name"] == "sub")
    DynamoProfileStore(clients.dynamodb(), get_settings().table("profiles")).put(
        Profile(sub=sub, username=display, country_code=country, highlight_colour=colour))


def live_region_url(html: str, region_id: str) -> str:
    match = re.search(rf'id="{region_id}"[^>]*hx-get="([^"]+)"', html, re.S)
    assert match, f"no polling region #{region_id}"
    return match.group(1).replace("&amp;", "&")


# --- leaderboard ---------------------------------------------------------------------------------------------------


def test_leaderboard_page_shows_rows_flag_time_and_live_footer_without_sign_in(desk: Desk, clock: FakeClock) -> None:
    eid, _ = racing(desk, clock, "vera", laps=(10_000, 9_876))
    hostile_profile(desk, "vera", display="vera", colour="#FF0000", country="SE")
    desk.ok(desk.call("POST", f"/api/events/{eid}/recompute"))

    page = html_get(desk, f"/leaderboard/{eid}")

    assert page.status_code == 200 and page.headers["Content-Type"].startswith("text/html")
    html = page.body.decode()
    assert "Summit Stockholm 2026" in html
    row = re.search(r'<li class="board-row gold" data-racer="vera" data-time="9876"(.*?)</li>', html, re.S)
    assert row, html
    assert 'src="/static/vendor/flags/se.svg"' in row.group(1) and "0:09.876" in row.group(1)  # Swedish flag, best lap
    assert "--racer-colour: #ff0000" in row.group(1)
    footer = re.search(r'data-testid="race-footer".*?</div>', html, re.S).group(0)
    assert "Now racing" in footer and "vera" in footer and "1:41" in footer  # 100.124 s left, rounded up
    assert 'data-running="true"' in footer


def test_hostile_racer_name_title_and_colour_are_escaped_everywhere(desk: Desk, clock: FakeClock) -> None:
    eid, _ = racing(desk, clock, "mallory", event_name="<img src=x onerror=alert(1)> Cup")
    hostile_profile(desk, "mallory", display=HOSTILE_NAME, colour="red;background:url(https://evil.example/x)")
    desk.ok(desk.call("POST", f"/api/events/{eid}/recompute"))

    for path in (f"/leaderboard/{eid}", f"/overlay/{eid}", f"/leaderboard/{eid}/live?track=1&tracks=1"):
        html = html_get(desk, path).body.decode()
        assert "<script>alert" not in html and "<img src=x" not in html, path
        assert "evil.example" not in html, path
    board = html_get(desk, f"/leaderboard/{eid}").body.decode()
    assert "&lt;script&gt;alert(&#39;pwned&#39;)&lt;/script&gt;" in board
    assert "&lt;img src=x onerror=alert(1)&gt; Cup" in board
    assert "--racer-colour: #0000ff" in board  # the hostile colour fell back to the default blue


def test_language_switch_translates_the_page(desk: Desk, clock: FakeClock) -> None:
    eid, _ = racing(desk, clock)
    german = html_get(desk, f"/leaderboard/{eid}?lang=de").body.decode()
    english = html_get(desk, f"/leaderboard/{eid}?lang=en").body.decode()
    unknown = html_get(desk, f"/leaderboard/{eid}?lang=xx").body.decode()
    assert "Jetzt auf der Strecke" in german and "Restzeit" in german and 'lang="de"' in german
    assert "Now racing" in english and "Time left" in english and "Restzeit" not in english
    assert "Now racing" in unknown
    assert "lang=de" in live_region_url(german, "board-live")  # the live region keeps the language


@pytest.mark.parametrize("lang, now_racing, time_left", [
    ("es", "En pista", "Tiempo restante"), ("fr", "En piste", "Temps restant"), ("ja", "走行中", "残り時間"),
    ("sv", "På banan nu", "Tid kvar")])
def test_the_big_screen_speaks_the_event_s_language(desk: Desk, clock: FakeClock, lang: str, now_racing: str,
                                                    time_left: str) -> None:
    eid, _ = racing(desk, clock)
    page = html_get(desk, f"/leaderboard/{eid}?lang={lang}").body.decode()
    assert now_racing in page and time_left in page and f'lang="{lang}"' in page
    assert "Now racing" not in page


def test_every_language_translates_every_text() -> None:
    from drem_web import i18n

    english = set(i18n.CATALOGUE["en"])
    for lang, texts in i18n.CATALOGUE.items():
        assert set(texts) == english, f"{lang}: missing {sorted(english - set(texts))}"
        assert all(text.strip() for text in texts.values()), lang


def test_format_and_flag_switches(desk: Desk, clock: FakeClock) -> None:
    eid, _ = racing(desk, clock, "vera", laps=(10_000,))
    hostile_profile(desk, "vera", display="vera", colour="#00ff00", country="SE")
    desk.ok(desk.call("POST", f"/api/events/{eid}/recompute"))
    with_flags = html_get(desk, f"/leaderboard/{eid}").body.decode()
    without = html_get(desk, f"/leaderboard/{eid}?flag=false").body.decode()
    assert "/static/vendor/flags/se.svg" in with_flags and "/static/vendor/flags/" not in without
    average = html_get(desk, f"/leaderboard/{eid}?format=average").body.decode()
    assert re.search(r'data-racer="vera" data-time=""', average) and "DNF" in average  # one lap: no 3-lap average
    assert html_get(desk, f"/leaderboard/{eid}?format=slowest").status_code == 400
    assert html_get(desk, f"/leaderboard/{eid}?track=9").status_code == 404
    assert html_get(desk, "/leaderboard/no-such-event").status_code == 404


def _qr_matrix(svg: str) -> np.ndarray:
    """qrcode's SvgPathImage draws one `Mx,yH…V…H…z` square per dark module: rebuild the module grid from it."""
    size = int(re.search(r'viewBox="0 0 (\d+) \d+"', svg).group(1))
    grid = np.zeros((size, size), dtype=bool)
    for x, y in re.findall(r"M(\d+),(\d+)H", svg):
        grid[int(y), int(x)] = True
    return grid


def test_qr_code_is_inline_svg_that_decodes_to_the_page_url(desk: Desk, clock: FakeClock) -> None:
    import cv2

    eid, _ = racing(desk, clock)
    html = html_get(desk, f"/leaderboard/{eid}?lang=de").body.decode()
    svg = re.search(r'data-testid="qr"><svg.*?</svg>', html, re.S).group(0)
    grid = _qr_matrix(svg[svg.index("<svg"):])
    image = np.pad(np.kron(~grid, np.ones((8, 8), dtype=bool)).astype(np.uint8) * 255, 32,
                   constant_values=255)  # 8 px per module, dark = 0, on a white margin
    decoded, _points, _ = cv2.QRCodeDetector().detectAndDecode(image)
    assert decoded == f"http://127.0.0.1:8000/event/{eid}?lang=de"  # the event's landing page
    inside = svg[svg.index("<svg"):].split(">", 1)[1]
    assert "<script" not in inside and "http" not in inside  # module squares only: no script, no URL text
    assert 'data-testid="qr"' not in html_get(desk, f"/leaderboard/{eid}?qr=none").body.decode()


def test_unchanged_poll_answers_204_and_a_new_lap_renders_the_row(desk: Desk, clock: FakeClock) -> None:
    eid, rid = racing(desk, clock, "vera", laps=(10_000,))
    poll = live_region_url(html_get(desk, f"/leaderboard/{eid}").body.decode(), "board-live")

    unchanged = html_get(desk, poll, {"HX-Request": "true"})
    assert unchanged.status_code == 204 and unchanged.body == b""

    clock.advance(8_500)
    desk.ok(desk.command(eid, rid, "capture_lap"))
    changed = html_get(desk, poll, {"HX-Request": "true"})
    assert changed.status_code == 200
    fragment = changed.body.decode()
    assert fragment.startswith('<section id="board-live"') and 'data-time="8500"' in fragment
    etag = changed.headers["ETag"]
    next_poll = live_region_url(fragment, "board-live")
    assert next_poll != poll and html_get(desk, next_poll, {"HX-Request": "true"}).status_code == 204
    assert html_get(desk, f"/leaderboard/{eid}/live?track=1&tracks=1",
                    {"If-None-Match": etag}).status_code == 304


# --- overlay -------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("colour, expected", [
    ("red;background:url(x)", "#00ff00"), ("ff00ff", "#ff00ff"), ("%23abc", "#abc"), ("12345", "#00ff00"),
    ("0000ff\"><script>", "#00ff00"), ("", "#00ff00"),
])
def test_chroma_colour_is_hex_or_green(desk: Desk, clock: FakeClock, colour: str, expected: str) -> None:
    eid, _ = racing(desk, clock)
    html = html_get(desk, f"/overlay/{eid}?chroma=1&chromaColor={colour}").body.decode()
    assert re.search(r'<body class="overlay-body chroma" style="--chroma: ([^"]*)"', html).group(1) == expected
    assert "url(x)" not in html and "<script>" not in html


def test_overlay_without_chroma_is_transparent_and_shows_lower_third_with_f1_colours(desk: Desk,
                                                                                     clock: FakeClock) -> None:
    eid, rid = racing(desk, clock, "vera", laps=(10_000, 9_000, 9_500))
    html = html_get(desk, f"/overlay/{eid}").body.decode()
    assert '<body class="overlay-body" data-testid="overlay">' in html and "topbar" not in html
    lower = re.search(r'data-testid="lower-third".*?</section>', html, re.S).group(0)
    assert "vera" in lower
    assert re.search(r'lap-purple" data-testid="best-lap">0:09.000<', lower)  # fastest of the event
    assert re.search(r'lap-yellow" data-testid="previous-lap">0:09.500<', lower)  # valid, not the best
    desk.ok(desk.call("POST", f"/api/events/{eid}/races/{rid}/commands",
                      {"kind": "set_lap_validity", "lap_id": 2, "is_valid": False}))
    html = html_get(desk, f"/overlay/{eid}").body.decode()
    assert re.search(r'lap-red" data-testid="previous-lap">0:09.500<', html)


def test_overlay_lower_third_shows_the_racer_s_position_and_gap_to_the_leader(desk: Desk, clock: FakeClock) -> None:
    eid, rid = racing(desk, clock, "lea", laps=(9_000,))
    desk.ok(desk.command(eid, rid, "end"))
    desk.ok(desk.command(eid, rid, "submit"))
    desk.users.create("vera", ("racer",))
    vera = desk.ok(desk.create_race(eid, "vera"), 201)["race_id"]
    desk.ok(desk.command(eid, vera, "start"))
    clock.advance(10_250)
    desk.ok(desk.command(eid, vera, "capture_lap"))

    lower = re.search(r'data-testid="lower-third".*?</section>', html_get(desk, f"/overlay/{eid}").body.decode(),
                      re.S).group(0)
    assert "vera" in lower
    assert re.search(r'data-testid="position">P2<', lower)
    assert re.search(r'data-testid="gap-to-leader">\+1\.250<', lower)
    without_gap = html_get(desk, f"/overlay/{eid}?gapToLeader=false").body.decode()
    assert 'data-testid="position">P2<' in without_gap and "gap-to-leader" not in without_gap


def test_overlay_after_the_race_highlights_the_racer_then_shows_the_top_four(desk: Desk, clock: FakeClock) -> None:
    eid, rid = racing(desk, clock, "vera", laps=(10_000,))
    desk.ok(desk.command(eid, rid, "end"))
    desk.ok(desk.command(eid, rid, "submit"))
    html = html_get(desk, f"/overlay/{eid}").body.decode()
    assert "Just finished" in html and re.search(r'standings-row highlighted" data-racer="vera"', html)
    poll = live_region_url(html, "overlay-live")
    assert html_get(desk, poll, {"HX-Request": "true"}).status_code == 204

    clock.advance(31_000)  # the post-race highlight is over: the phase changes, so the poll renders
    later = html_get(desk, poll, {"HX-Request": "true"})
    assert later.status_code == 200 and "Top racers" in later.body.decode() and "highlighted" not in later.body.decode()


# --- commentator ---------------------------------------------------------------------------------------------------


def test_commentator_view_is_refused_to_anonymous_and_racers(desk: Desk, clock: FakeClock) -> None:
    eid, _ = racing(desk, clock)
    anonymous = html_get(desk, f"/commentator/{eid}")
    assert anonymous.status_code == 303 and anonymous.headers["Location"].startswith("/login")
    racer = desk.token("rita", "racer")
    for path in (f"/commentator/{eid}", f"/commentator/{eid}/live?track=1"):
        assert desk.client.http.get(path, headers={"Authorization": f"Bearer {racer}"}).status_code == 403
    assert html_get(desk, f"/commentator/{eid}/live?track=1", {"HX-Request": "true"}).status_code == 401


def test_commentator_sees_stats_lap_table_and_chart(desk: Desk, clock: FakeClock) -> None:
    eid, _ = racing(desk, clock, "vera", laps=(10_000, 9_000, 9_500))
    caster = desk.token("cora", "commentator")
    reply = desk.client.http.get(f"/commentator/{eid}", headers={"Authorization": f"Bearer {caster}",
                                                                  "Accept": "text/html"})
    assert reply.status_code == 200
    html = reply.body.decode()
    assert re.search(r'data-testid="position-now">1<', html)
    assert re.findall(r'<tr class="lap-(\w+)"><td>(\d)</td><td class="lap-time">([\d:.]+)<', html) == [
        ("yellow", "1", "0:10.000"), ("purple", "2", "0:09.000"), ("yellow", "3", "0:09.500")]
    chart = re.search(r'<svg class="lap-chart".*?</svg>', html, re.S).group(0)
    assert chart.count('<rect class="bar') == 3 and 'stroke-dasharray="8 6"' in chart
    assert "Event best 0:09.000" in chart


# --- avatars and the race summary on the big screen ----------------------------------------------------------------


def submitted(desk: Desk, clock: FakeClock, racer: str = "vera", laps: tuple[int, ...] = (10_000, 9_876)) -> str:
    """The event id after `racer`'s race with `laps` was ended and submitted."""
    eid, rid = racing(desk, clock, racer, laps=laps)
    desk.ok(desk.command(eid, rid, "end"))
    desk.ok(desk.command(eid, rid, "submit"))
    return eid


def test_every_row_shows_the_racer_s_avatar_or_their_initial(desk: Desk, clock: FakeClock) -> None:
    eid = submitted(desk, clock, "vera")
    desk.token("lea", "racer")
    lea = desk.ok(desk.create_race(eid, "lea"), 201)["race_id"]
    desk.ok(desk.command(eid, lea, "start"))
    clock.advance(11_000)
    desk.ok(desk.command(eid, lea, "capture_lap"))
    desk.ok(desk.command(eid, lea, "end"))
    desk.ok(desk.command(eid, lea, "submit"))
    # vera keeps the generated pattern, lea turns her avatar off: the board follows their profiles
    desk.tokens["vera"] = desk.users.sign_in("vera")["AccessToken"]
    desk.ok(desk.call("PUT", "/api/me/profile", {"highlight_colour": "#FF0000"}, as_user="vera"))
    desk.ok(desk.call("PUT", "/api/me/profile", {"avatar": "none", "highlight_colour": "#FF8200"}, as_user="lea"))

    html = html_get(desk, f"/leaderboard/{eid}?summary_seconds=0").body.decode()
    rows = dict(re.findall(r'<li class="board-row[^"]*" data-racer="(\w+)".*?(<span class="avatar.*?</span>)', html,
                           re.S))
    assert set(rows) == {"vera", "lea"}
    vera_avatar = re.search(r'<img src="([^"]+)"', rows["vera"]).group(1)
    assert vera_avatar == "/api/profiles/vera/avatar.svg?c=ff0000"
    image = desk.client.http.get(vera_avatar.split("?")[0])
    assert image.status_code == 200 and image.headers["Content-Type"] == "image/svg+xml"  # the identicon is served
    assert "<img" not in rows["lea"] and 'class="avatar-initial">L<' in rows["lea"]  # no avatar chosen: her initial


def test_a_submitted_race_s_summary_holds_the_screen_then_the_rows_return(desk: Desk, clock: FakeClock) -> None:
    eid = submitted(desk, clock, "vera", laps=(10_000, 9_876))
    html = html_get(desk, f"/leaderboard/{eid}?summary_seconds=15").body.decode()
    summary = re.search(r'data-testid="race-summary".*?</article>', html, re.S)
    assert summary, html
    assert 'data-racer="vera"' in summary.group(0) and "Just finished" in summary.group(0)
    assert re.search(r'data-testid="summary-position">P1<', summary.group(0))
    assert re.search(r'data-testid="summary-best">0:09.876<', summary.group(0))
    assert re.search(r'data-testid="summary-laps">2<', summary.group(0))
    assert re.search(r'data-testid="summary-gap">Leader<', summary.group(0))
    assert '<ol class="board-rows" hidden>' in html  # the rows wait under the summary

    poll = live_region_url(html, "board-live")
    assert "summary_seconds=15" in poll
    assert html_get(desk, poll, {"HX-Request": "true"}).status_code == 204  # held: nothing new to render
    clock.advance(14_000)
    assert html_get(desk, poll, {"HX-Request": "true"}).status_code == 204
    clock.advance(1_500)  # the hold is over: the token changes, so the poll renders the rows again
    after = html_get(desk, poll, {"HX-Request": "true"})
    assert after.status_code == 200
    fragment = after.body.decode()
    assert "race-summary" not in fragment and '<ol class="board-rows">' in fragment and 'data-racer="vera"' in fragment
    assert html_get(desk, live_region_url(fragment, "board-live"), {"HX-Request": "true"}).status_code == 204


def test_summary_seconds_zero_turns_the_summary_off_and_bad_values_get_a_clear_message(desk: Desk,
                                                                                       clock: FakeClock) -> None:
    eid = submitted(desk, clock)
    assert "race-summary" not in html_get(desk, f"/leaderboard/{eid}?summary_seconds=0").body.decode()
    assert "race-summary" in html_get(desk, f"/leaderboard/{eid}").body.decode()  # on by default
    bad = html_get(desk, f"/leaderboard/{eid}?summary_seconds=-1")
    assert bad.status_code == 400 and "summary_seconds" in bad.body.decode()


def test_a_new_race_ends_the_summary_early_and_shows_the_now_racing_bar(desk: Desk, clock: FakeClock) -> None:
    eid = submitted(desk, clock, "vera")
    poll = live_region_url(html_get(desk, f"/leaderboard/{eid}?summary_seconds=60").body.decode(), "board-live")
    clock.advance(3_000)
    desk.users.create("lea", ("racer",))
    lea = desk.ok(desk.create_race(eid, "lea"), 201)["race_id"]
    desk.ok(desk.command(eid, lea, "start"))

    fragment = html_get(desk, poll, {"HX-Request": "true"})
    assert fragment.status_code == 200
    html = fragment.body.decode()
    assert "race-summary" not in html and '<ol class="board-rows">' in html
    footer = re.search(r'data-testid="race-footer".*?</div>', html, re.S).group(0)
    assert "Now racing" in footer and "lea" in footer


def test_on_the_combined_board_one_track_s_summary_leaves_the_other_track_s_race_bar(desk: Desk,
                                                                                      clock: FakeClock) -> None:
    scenario = Scenario(desk, clock).add_racers("vera", "lea").add_event(
        tracks=[{"track_id": "1"}, {"track_id": "2"}])
    scenario.add_race("lea", (9_500,), track="2")  # lea is racing on track 2
    scenario.submitted_race("vera", (9_100,), track="1")  # vera's race on track 1 has just been submitted

    html = html_get(desk, f"/leaderboard/{scenario.event_id}?track=combined").body.decode()
    summary = re.search(r'data-testid="race-summary".*?</article>', html, re.S).group(0)
    assert 'data-racer="vera"' in summary and "Track 1" in summary  # two tracks: the summary says whose it is
    footer = re.search(r'data-testid="race-footer".*?</div>', html, re.S).group(0)
    assert "Now racing" in footer and "lea" in footer
