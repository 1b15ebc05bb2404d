"""The writer's wake-up as on AWS, where the functions cannot reach the live tasks' sockets: two live servers that
poll storage only every ten minutes and are each other's peers (as two Fargate tasks under one DNS name); a wake-up
POSTed to the first (as CloudFront passes the functions' POST to one task) pushes the lap to the viewers of both.

What a user notices: the lap is on every big screen and phone, whichever task the load balancer gave it, without the
storage poll; a wake-up without the stage's secret is refused and pushes nothing."""
from __future__ import annotations

import sys
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
import requests

from chalicelib.live_wake import WAKE_PATH, WAKE_SECRET_ENV, WAKE_SECRET_HEADER
from drem_live.video_peers import PEER_LISTEN_ENV, PEER_SECRET_ENV, PEERS_ENV
from drem_local import stack as local_stack
from tests.browser.test_live_pages import start_race, strip
from tests.integration.test_live_server import NO_PROXY, open_stream

pytestmark = pytest.mark.integration

WAKE_SECRET = "wake-secret-for-the-tests-only"
PEER_SECRET = "peer-secret-for-the-tests-only"
NEVER_MS = "600000"  # the storage poll: ten minutes, longer than the test may take


@pytest.fixture(scope="module")
def two_tasks(live_stack: Any, tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, str]]:
    """Two live servers the stack's app cannot reach (no wake directory of the stack's), woken over HTTP only."""
    peer_ports = [local_stack.free_port(), local_stack.free_port()]
    logs = tmp_path_factory.mktemp("wake-over-http")
    env = {name: value for name, value in live_stack.env.items() if name != "DREM_LIVE_WAKE_DIR"}
    env.update({"DREM_LIVE_POLL_MS": NEVER_MS, WAKE_SECRET_ENV: WAKE_SECRET, PEER_SECRET_ENV: PEER_SECRET,
                PEERS_ENV: ",".join(f"127.0.0.1:{port}" for port in peer_ports)})
    servers, urls = [], []
    try:
        for index, peer_port in enumerate(peer_ports):
            port = local_stack.free_port()
            # The first task runs two workers: whichever takes the wake-up, both workers' viewers get the lap.
            command = [sys.executable, "-m", "drem_live", "--host", "127.0.0.1", "--port", str(port),
                       "--workers", "2" if index == 0 else "1"]
            servers.append(local_stack.spawn(f"live task {index + 1}", command, logs / f"live-{index + 1}.log",
                                             env={**env, PEER_LISTEN_ENV: f"127.0.0.1:{peer_port}"}))
            urls.append(f"http://127.0.0.1:{port}")
        for url, server in zip(urls, servers, strict=True):
            local_stack.wait_for_ok(f"{url}/live/healthz", server, 60.0)
        yield urls[0], urls[1]
    finally:
        for server in servers:
            server.stop(10)


def health(url: str) -> dict[str, Any]:
    return requests.get(f"{url}/live/healthz", timeout=10, proxies=NO_PROXY).json()


def wake(url: str, event_id: str, secret: str = WAKE_SECRET) -> int:
    return requests.post(url + WAKE_PATH, data=event_id.encode(), headers={WAKE_SECRET_HEADER: secret}, timeout=10,
                         proxies=NO_PROXY).status_code


def test_a_wake_up_posted_to_one_task_pushes_the_lap_to_the_viewers_of_both(live_stack: Any,
                                                                             two_tasks: tuple[str, str]) -> None:
    first, second = two_tasks
    eid, _race_id, timer = start_race(live_stack.url, live_stack.admin_username, live_stack.admin_password,
                                      racer="nils-wake")
    query = "track=1&lang=en&tracks=1&summary_seconds=0"
    streams = [open_stream(f"{url}/live/leaderboard/{eid}?{query}", **{"Accept-Encoding": "identity"})
               for url in (*[first] * 6, second, second)]  # the kernel spreads the first six over both workers
    shown = [stream.next_fragment()["id"] for stream in streams]
    seed = int(time.time() * 1000)
    strip(live_stack.url, timer, eid, seed, "http-wake-1")
    strip(live_stack.url, timer, eid, seed + 6_543, "http-wake-2")

    assert wake(first, eid, secret="x" * len(WAKE_SECRET)) == 403
    assert health(first)["http_wakes"] == 0, "a forged wake-up is not taken"
    # The writer's wake-ups, as the functions send one after each board and overlay write (the board is published
    # right after the strip's answer, so they go on until the lap is seen; none reaches the second task directly).
    seen = threading.Event()

    def writer() -> None:
        while not seen.is_set():
            assert wake(first, eid) == 204
            seen.wait(0.5)

    waking = threading.Thread(target=writer, daemon=True)
    waking.start()
    try:
        pushed_by = time.monotonic() + 60
        for stream, before in zip(streams, shown, strict=True):
            while True:  # without a wake-up nothing comes before the ten-minute poll
                assert time.monotonic() < pushed_by, "the lap was not pushed to every task's viewers within 60 s"
                pushed = stream.next_fragment()
                assert pushed["id"] != before
                if "0:06.543" in pushed["data"]:
                    break
            stream.response.close()
    finally:
        seen.set()
        waking.join(10)
    first_health, second_health = health(first), health(second)
    assert first_health["poll_ms"] == second_health["poll_ms"] == int(NEVER_MS)
    assert second_health["http_wakes"] == 0, "the second task was woken only through its peer"
