"""The live fragments' render cache: after a change every spectator's poll gets the same HTML built once (and the
overlay's race read once per overlay version), the cache stays bounded, and a fragment served later than it was built
still lets the page show the right race clock."""
from __future__ import annotations

import re
import threading
import time
from typing import Any

import pytest

from tests.unit.race_helpers import Desk, FakeClock
from tests.unit.test_public_pages import html_get, live_region_url, racing

pytestmark = pytest.mark.unit


# --- the cache itself ------------------------------------------------------------------------------------------------


def test_concurrent_askers_of_one_key_share_one_build() -> None:
    from chalicelib.views.render_cache import VersionedCache

    cache: VersionedCache[str] = VersionedCache(8)
    builds: list[int] = []
    start = threading.Barrier(8)
    answers: list[str] = []

    def build() -> str:
        builds.append(1)
        time.sleep(0.05)  # long enough that every other asker arrives while this build runs
        return "<section>v1</section>"

    def ask() -> None:
        start.wait()
        answers.append(cache.get(("board", "e1", "1.1"), build))

    threads = [threading.Thread(target=ask) for _ in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(5)
    assert len(builds) == 1 and answers == ["<section>v1</section>"] * 8
    assert cache.get(("board", "e1", "1.2"), lambda: "<section>v2</section>") == "<section>v2</section>"


def test_cache_is_bounded_and_evicts_the_least_recently_used() -> None:
    from chalicelib.views.render_cache import VersionedCache

    cache: VersionedCache[str] = VersionedCache(2)
    built: list[str] = []

    def get(key: str) -> str:
        return cache.get(key, lambda: built.append(key) or key.upper())

    get("a"), get("b"), get("a"), get("c")  # "a" was used after "b": "b" is the one to go
    assert len(cache) == 2 and "a" in cache and "c" in cache and "b" not in cache
    assert get("b") == "B" and built == ["a", "b", "c", "b"]


def test_a_failed_build_is_not_cached() -> None:
    from chalicelib.views.render_cache import VersionedCache

    cache: VersionedCache[str] = VersionedCache(4)

    def broken() -> str:
        raise RuntimeError("storage unavailable")

    with pytest.raises(RuntimeError):
        cache.get("k", broken)
    assert "k" not in cache and cache.get("k", lambda: "ok") == "ok"


# --- through the app -------------------------------------------------------------------------------------------------


class Counting:
    def __init__(self, wrapped: Any) -> None:
        self.wrapped, self.calls = wrapped, 0

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        self.calls += 1
        return self.wrapped(*args, **kwargs)


def test_spectators_polling_after_a_lap_share_one_render_until_the_token_changes(
        desk: Desk, clock: FakeClock, monkeypatch: pytest.MonkeyPatch) -> None:
    from drem_web import render

    eid, rid = racing(desk, clock, "vera", laps=(10_000,))
    before = live_region_url(html_get(desk, f"/leaderboard/{eid}").body.decode(), "board-live")
    renders = Counting(render.fragment)
    monkeypatch.setattr(render, "fragment", renders)

    clock.advance(8_500)
    desk.ok(desk.command(eid, rid, "capture_lap"))
    spectators = [html_get(desk, before, {"HX-Request": "true"}) for _ in range(5)]
    assert {r.status_code for r in spectators} == {200} and len({r.body for r in spectators}) == 1
    assert 'data-time="8500"' in spectators[0].body.decode() and renders.calls == 1
    other_language = html_get(desk, before.replace("lang=en", "lang=de"), {"HX-Request": "true"})
    assert "Restzeit" in other_language.body.decode() and renders.calls == 2  # other options: their own render

    clock.advance(8_000)
    desk.ok(desk.command(eid, rid, "capture_lap"))
    after = html_get(desk, before, {"HX-Request": "true"})
    assert renders.calls == 3 and after.body != spectators[0].body and 'data-time="8000"' in after.body.decode()


def test_overlay_reads_its_race_once_per_overlay_version(desk: Desk, clock: FakeClock,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    from chalicelib import services

    eid, rid = racing(desk, clock, "vera", laps=(10_000,))
    reads = Counting(services.race_store)
    monkeypatch.setattr(services, "race_store", reads)  # counts stores built, one per race read

    pages = [html_get(desk, f"/overlay/{eid}").body.decode() for _ in range(3)]
    assert all('data-testid="previous-lap">0:10.000<' in page for page in pages) and reads.calls == 1
    clock.advance(9_000)
    desk.ok(desk.command(eid, rid, "capture_lap"))
    reads.calls = 0  # the lap itself read the race through the service
    page = html_get(desk, f"/overlay/{eid}").body.decode()
    assert 'data-testid="previous-lap">0:09.000<' in page and reads.calls == 1


def _clock(body: str, kind: str) -> tuple[int, int]:
    """(reading in ms, server time it was read at) of the fragment's `kind` ("down"/"up") clock."""
    match = re.search(rf'data-clock="{kind}" data-clock-at="(\d+)" data-clock-ms="(\d+)"', body)
    assert match, body
    return int(match.group(2)), int(match.group(1))


def test_a_fragment_served_later_than_it_was_built_still_gives_the_right_race_clock(
        desk: Desk, clock: FakeClock) -> None:
    from chalicelib.views.render_cache import LIVE_FRAGMENTS

    eid, rid = racing(desk, clock, "vera", laps=(10_000,))
    poll = live_region_url(html_get(desk, f"/overlay/{eid}").body.decode(), "overlay-live")
    clock.advance(8_500)
    desk.ok(desk.command(eid, rid, "capture_lap"))
    built = html_get(desk, poll, {"HX-Request": "true"})

    clock.advance(5_000)  # a spectator whose poll comes 5 s later gets the same (cached) HTML
    later = html_get(desk, poll, {"HX-Request": "true"})
    assert later.body == built.body
    sent_at = int(later.headers["X-Drem-Server-Ms"])
    assert sent_at == clock.now

    LIVE_FRAGMENTS.clear()  # what a fresh render at this moment shows
    fresh = html_get(desk, poll, {"HX-Request": "true"}).body.decode()
    for kind, sign in (("down", -1), ("up", +1)):
        reading, read_at = _clock(later.body.decode(), kind)
        assert read_at == clock.now - 5_000
        # live.js starts a running clock from reading +- (sent_at - read_at): the fresh render's reading
        assert reading + sign * (sent_at - read_at) == _clock(fresh, kind)[0]
