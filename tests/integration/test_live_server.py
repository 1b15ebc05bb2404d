"""The live server (drem_live) as `drem up` runs it, over HTTP: pushed fragments equal the app's polled ones, the
stream honours Last-Event-ID and gzip, the JSON polls match the app's, and the caps answer 503 with Retry-After."""
from __future__ import annotations

import re
import subprocess
import sys
import time
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import requests

from drem_local import stack as local_stack
from tests.browser.test_live_pages import start_race, strip

pytestmark = pytest.mark.integration

NO_PROXY = {"http": "", "https": ""}


class EventStream:
    """Reads an SSE response message by message (gzip decoded incrementally when the server sent it)."""

    def __init__(self, response: requests.Response) -> None:
        self.response = response
        gzip = response.headers.get("Content-Encoding") == "gzip"
        self._decoder = zlib.decompressobj(16 + zlib.MAX_WBITS) if gzip else None
        self._chunks = response.raw.stream(1024, decode_content=False)
        self._buffer = b""

    def next(self) -> dict[str, str]:
        while b"\n\n" not in self._buffer:
            chunk = next(self._chunks)
            self._buffer += self._decoder.decompress(chunk) if self._decoder else chunk
        raw, self._buffer = self._buffer.split(b"\n\n", 1)
        message: dict[str, str] = {}
        for line in raw.decode().split("\n"):
            field, _, value = line.partition(": ")
            message[field] = message[field] + "\n" + value if field == "data" and field in message else value
        return message

    def next_fragment(self, within_s: float = 60.0) -> dict[str, str]:
        """The next fragment pushed; fails after `within_s` (heartbeats keep the read itself from ever timing out)."""
        deadline = time.monotonic() + within_s
        while True:
            message = self.next()
            if message.get("event") == "fragment":
                return message
            assert time.monotonic() < deadline, f"no fragment pushed within {within_s:.0f} s, only heartbeats"


def open_stream(url: str, **headers: str) -> EventStream:
    response = requests.get(url, stream=True, timeout=(5, 20), proxies=NO_PROXY, headers=headers)
    assert response.status_code == 200, response.text
    assert response.headers["Content-Type"].startswith("text/event-stream")
    assert response.headers["Access-Control-Allow-Origin"] == "*"
    return EventStream(response)


@pytest.fixture(scope="module")
def race(live_stack: Any) -> tuple[str, str, str]:
    return start_race(live_stack.url, live_stack.admin_username, live_stack.admin_password, racer="lina-live")


def test_health_answers_json(live_stack: Any) -> None:
    health = requests.get(live_stack.live_url + "/live/healthz", timeout=5, proxies=NO_PROXY).json()
    assert health["ok"] is True and "message_bytes" in health


def test_the_pushed_fragment_is_the_polled_fragment_and_a_lap_is_pushed(live_stack: Any, race: Any) -> None:
    eid, _race_id, timer = race
    query = "track=1&lang=en&tracks=1&summary_seconds=0"
    stream = open_stream(f"{live_stack.live_url}/live/leaderboard/{eid}?{query}", **{"Accept-Encoding": "identity"})
    first = stream.next_fragment()
    polled = requests.get(f"{live_stack.url}/leaderboard/{eid}/live?{query}", timeout=10, proxies=NO_PROXY)
    token = first["id"]
    assert polled.headers["ETag"] == f'"live-{token}"'
    # Byte for byte, but for the instant the race clocks were read at (each render reads the clock).
    clock = re.compile(r'data-clock-at="\d+"|data-clock-ms="\d+"|>\d+:\d\d(\.\d+)?<')
    assert clock.sub("", first["data"]) == clock.sub("", polled.text)

    seed = int(time.time() * 1000)
    strip(live_stack.url, timer, eid, seed, "live-push-1")
    strip(live_stack.url, timer, eid, seed + 8_765, "live-push-2")
    while True:  # each lap pushes a newer token; the board shows the lap once the race service published it
        pushed = stream.next_fragment()
        assert pushed["id"] != token
        if "0:08.765" in pushed["data"]:
            break
    stream.response.close()


def test_a_client_that_has_the_current_token_is_not_sent_it_again(live_stack: Any, race: Any) -> None:
    eid = race[0]
    url = f"{live_stack.live_url}/live/overlay/{eid}?track=1"
    current = open_stream(url).next_fragment()["id"]
    again = open_stream(url, **{"Last-Event-ID": current})
    assert again.next()["event"] == "clock"  # the opening message; then nothing until the token changes
    assert again.next() == {"": "heartbeat"}  # 15 s later the heartbeat comment, and no resent fragment before it
    older = open_stream(url, **{"Last-Event-ID": "0.0-0"})
    assert older.next_fragment()["id"] == current


def test_the_stream_is_gzip_compressed_when_the_client_accepts_it(live_stack: Any, race: Any) -> None:
    stream = open_stream(f"{live_stack.live_url}/live/overlay/{race[0]}?track=1", **{"Accept-Encoding": "gzip"})
    assert stream.response.headers["Content-Encoding"] == "gzip"
    assert 'id="overlay-live"' in stream.next_fragment()["data"]


def test_bad_queries_and_unknown_events_get_a_clear_answer(live_stack: Any, race: Any) -> None:
    bad = requests.get(f"{live_stack.live_url}/live/leaderboard/{race[0]}?page_seconds=9999", timeout=5,
                       proxies=NO_PROXY)
    assert bad.status_code == 400 and "page_seconds" in bad.json()["message"]
    long = requests.get(f"{live_stack.live_url}/live/leaderboard/{race[0]}?lang={'x' * 2000}", timeout=5,
                        proxies=NO_PROXY)
    assert long.status_code == 400 and "longer than" in long.json()["message"]
    missing = requests.get(f"{live_stack.live_url}/live/overlay/no-such-event", timeout=5, proxies=NO_PROXY)
    assert missing.status_code == 404 and "no-such-event" in missing.json()["message"]


@pytest.mark.parametrize(("kind", "track"), [("leaderboard", "combined"), ("overlay", "1")])
def test_the_json_polls_answer_like_the_apps_with_etag_and_304(live_stack: Any, race: Any, kind: str,
                                                               track: str) -> None:
    eid = race[0]
    app = requests.get(f"{live_stack.url}/api/{kind}/{eid}?track={track}", timeout=10, proxies=NO_PROXY)
    live = requests.get(f"{live_stack.live_url}/live/api/{kind}/{eid}?track={track}", timeout=10, proxies=NO_PROXY)
    assert live.status_code == 200 and live.json() == app.json() and live.headers["ETag"] == app.headers["ETag"]
    again = requests.get(f"{live_stack.live_url}/live/api/{kind}/{eid}?track={track}", timeout=10, proxies=NO_PROXY,
                         headers={"If-None-Match": live.headers["ETag"]})
    assert again.status_code == 304 and again.content == b""


@pytest.fixture(scope="module")
def capped_live_server(live_stack: Any, tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A second live server on the same storage with tiny caps (what a venue-WiFi attacker would run into)."""
    port = local_stack.free_port()
    env = {**live_stack.env, "DREM_LIVE_MAX_STREAMS": "3", "DREM_LIVE_MAX_STREAMS_PER_CLIENT": "2",
           "DREM_LIVE_MAX_CHANNELS": "1"}
    process = local_stack.spawn("capped live server", [sys.executable, "-m", "drem_live", "--host", "127.0.0.1",
                                                       "--port", str(port)],
                                tmp_path_factory.mktemp("capped") / "live.log", env=env)
    try:
        local_stack.wait_for_ok(f"http://127.0.0.1:{port}/live/healthz", process, 60)
        yield f"http://127.0.0.1:{port}"
    finally:
        process.stop(5)


def test_streams_beyond_the_caps_get_503_with_retry_after(capped_live_server: str, race: Any) -> None:
    url = f"{capped_live_server}/live/overlay/{race[0]}?track=1"
    kept = [open_stream(url), open_stream(url)]
    third = requests.get(url, stream=True, timeout=5, proxies=NO_PROXY)
    assert third.status_code == 503 and third.headers["Retry-After"] == "10"
    assert "too many live streams from one address" in third.json()["message"]
    for stream in kept:
        stream.response.close()
    other_options = f"{capped_live_server}/live/overlay/{race[0]}?track=1&lang=de"
    deadline = time.monotonic() + 10
    while True:  # the closed streams (and their channel) are released once the server sees them gone
        answer = requests.get(other_options, stream=True, timeout=5, proxies=NO_PROXY)
        if answer.status_code == 200 or time.monotonic() > deadline:
            break
        assert answer.status_code == 503, answer.text
        answer.close()
        time.sleep(0.1)
    assert answer.status_code == 200
    another_page = requests.get(url, stream=True, timeout=5, proxies=NO_PROXY)  # a second channel: over the cap of 1
    assert another_page.status_code == 503 and "different pages" in another_page.json()["message"]
    answer.close()


@pytest.fixture(scope="module")
def two_option_sets_live_server(live_stack: Any, tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A second live server on the same storage where a page may open only 2 option sets of its own."""
    port = local_stack.free_port()
    env = {**live_stack.env, "DREM_LIVE_MAX_CHANNELS_PER_PAGE": "2"}
    process = local_stack.spawn("live server, 2 option sets a page", [
        sys.executable, "-m", "drem_live", "--host", "127.0.0.1", "--port", str(port)],
        tmp_path_factory.mktemp("option-sets") / "live.log", env=env)
    try:
        local_stack.wait_for_ok(f"http://127.0.0.1:{port}/live/healthz", process, 60)
        yield f"http://127.0.0.1:{port}"
    finally:
        process.stop(5)


def test_made_up_option_sets_cannot_refuse_an_overlay_the_link_builder_made(two_option_sets_live_server: str,
                                                                              race: Any) -> None:
    """Issue 27: one client filled a page's option-set slots with hand-made queries and a real overlay was refused."""
    base = f"{two_option_sets_live_server}/live/overlay/{race[0]}"
    attacker = [open_stream(f"{base}?track=1&format=average&lang={lang}") for lang in ("en", "de")]
    refused = requests.get(f"{base}?track=1&format=average&lang=fr", stream=True, timeout=5, proxies=NO_PROXY)
    assert refused.status_code == 503 and "options of its own" in refused.json()["message"]
    # Every overlay the console's link builder offers still streams: another language, no gap column, chroma keyed.
    for query in ("trackId=1&lang=ja&gapToLeader=false", "trackId=1&showLeaderboard=false&lang=sv",
                  "trackId=1&chroma=true&chromaColor=%23FF00FF"):
        offered = open_stream(f"{base}?{query}")
        assert offered.next_fragment()["data"].startswith("<"), query
        offered.response.close()
    # The same hand-made options spelled another way (language case, the chroma key) are the channel already open.
    again = open_stream(f"{base}?track=1&format=average&lang=DE&chroma=true")
    assert again.next_fragment()["id"]
    for stream in [*attacker, again]:
        stream.response.close()


def test_drem_status_names_the_live_server(live_stack: Any) -> None:
    out = subprocess.run([sys.executable, "-m", "drem_local.cli", "status", "--state-dir", str(live_stack.state_dir)],
                         capture_output=True, text=True, timeout=60).stdout
    assert f"live server is pushing the public pages at {live_stack.live_url}" in out, out


def test_several_workers_share_the_port_and_stop_with_the_first(live_stack: Any,
                                                               tmp_path_factory: pytest.TempPathFactory) -> None:
    """`drem up` runs one live worker per core: new connections reach every worker process on the one port (so
    one GIL does not cap the spectators), and stopping the first process stops the others too."""
    port = local_stack.free_port()
    process = local_stack.spawn("two-worker live server", [sys.executable, "-m", "drem_live", "--host", "127.0.0.1",
                                                           "--port", str(port), "--workers", "2"],
                                tmp_path_factory.mktemp("workers") / "live.log", env=live_stack.env)
    try:
        local_stack.wait_for_ok(f"http://127.0.0.1:{port}/live/healthz", process, 60)
        pids: set[int] = set()
        deadline = time.monotonic() + 30
        while len(pids) < 2 and time.monotonic() < deadline:  # the second worker may still be starting
            with requests.Session() as fresh_connection:
                pids.add(fresh_connection.get(f"http://127.0.0.1:{port}/live/healthz", timeout=5,
                                              proxies=NO_PROXY).json()["pid"])
        assert len(pids) == 2, f"only {pids} answered on port {port}"
        assert process.popen.pid in pids
    finally:
        process.stop(10)
    (other,) = pids - {process.popen.pid}
    deadline = time.monotonic() + 10
    while running(other) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not running(other), "a worker outlived the live server it belonged to"


def child_pids(pid: int) -> list[int]:
    return [int(child) for child in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]


def worker_pids(pid: int) -> list[int]:
    """The live server's worker processes: `pid` and the workers it started (not its cameras' fan-out worker,
    drem_live.video_fanout, which serves no page and has no wake socket)."""
    def is_worker(child: int) -> bool:
        return b"drem_live.video_fanout" not in Path(f"/proc/{child}/cmdline").read_bytes()
    return [pid, *(child for child in child_pids(pid) if is_worker(child))]


def running(pid: int) -> bool:
    """Whether the process exists and has not exited (a zombie waiting to be reaped has exited)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    return "State:\tZ" not in status


def test_a_lap_wakes_every_live_worker_without_waiting_for_a_poll(live_stack: Any,
                                                                  tmp_path_factory: pytest.TempPathFactory) -> None:
    """The app's board write wakes the live server's processes (chalicelib.live_wake): a live server whose storage poll
    would come only in ten minutes still pushes the lap to every viewer, on each of its workers."""
    # A race of its own, started now: the module's race (3 minutes) may be over by the time this last test runs in a
    # loaded suite, and a lap after the race's time is not a lap on the board.
    eid, _race_id, timer = start_race(live_stack.url, live_stack.admin_username, live_stack.admin_password,
                                      racer="wanda-wake")
    port = local_stack.free_port()
    env = {**live_stack.env, "DREM_LIVE_POLL_MS": "600000"}
    process = local_stack.spawn("woken live server", [sys.executable, "-m", "drem_live", "--host", "127.0.0.1",
                                                      "--port", str(port), "--workers", "2"],
                                tmp_path_factory.mktemp("woken") / "live.log", env=env)
    try:
        local_stack.wait_for_ok(f"http://127.0.0.1:{port}/live/healthz", process, 60)
        # Both workers listen for wake-ups before the lap: the first process and the worker it started. (Counting the
        # directory's sockets is not enough: it also holds drem up's workers' and any a stopped server left behind.)
        wake_dir = Path(env["DREM_LIVE_WAKE_DIR"])
        workers = [process.popen.pid]
        deadline = time.monotonic() + 60
        while len(workers) < 2 or not all((wake_dir / f"{pid}.sock").exists() for pid in workers):
            assert time.monotonic() < deadline, f"workers {workers}, wake sockets {sorted(wake_dir.iterdir())}"
            time.sleep(0.05)
            workers = worker_pids(process.popen.pid)
        url = f"http://127.0.0.1:{port}/live/leaderboard/{eid}?track=1&lang=en&tracks=1&summary_seconds=0"
        streams = [open_stream(url, **{"Accept-Encoding": "identity"}) for _ in range(6)]
        shown = [stream.next_fragment()["id"] for stream in streams]
        seed = int(time.time() * 1000)
        strip(live_stack.url, timer, eid, seed, "wake-1")
        strip(live_stack.url, timer, eid, seed + 7_654, "wake-2")
        pushed_by = time.monotonic() + 60
        for stream, first in zip(streams, shown, strict=True):
            while True:  # a deadline fails the test: without a wake-up nothing comes before the 10-minute poll
                assert time.monotonic() < pushed_by, "the lap was not pushed to every viewer within 60 s"
                pushed = stream.next_fragment()
                assert pushed["id"] != first
                if "0:07.654" in pushed["data"]:
                    break
            stream.response.close()
        health = requests.get(f"http://127.0.0.1:{port}/live/healthz", timeout=5, proxies=NO_PROXY).json()
        assert health["poll_ms"] == 600000 and health["wakes"] >= 1
    finally:
        process.stop(10)
