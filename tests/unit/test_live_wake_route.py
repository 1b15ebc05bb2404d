"""The writer's wake-up over HTTP, as on AWS (drem_live.wake_route, chalicelib.live_wake_http): two live servers'
real aiohttp apps on loopback, each the other's peer. A wake POSTed to one wakes its own channels and, relayed through
the peer port, the other's; without the wake secret nothing is read or woken; the writer never waits long on it."""
from __future__ import annotations

import asyncio
import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

import aiohttp
import pytest
from aiohttp import web

from chalicelib import live_wake
from chalicelib.live_wake import WAKE_PATH, WAKE_SECRET_HEADER, LiveWaker
from chalicelib.live_wake_http import HttpWaker
from chalicelib.settings import Settings
from drem_live.video_peers import PeerSettings
from drem_live.video_routes import PEERS, add_video_routes
from drem_live.wake_route import add_wake_route
from drem_local.stack import free_port
from tests import coroutines
from tests.waiting import wait_until

SECRET = "wake-secret-for-the-tests-only"
PEER_SECRET = "peer-secret-for-the-tests-only"


@dataclass
class Task:
    url: str
    woken: list[str] = field(default_factory=list)


@asynccontextmanager
async def two_tasks() -> AsyncIterator[tuple[Task, Task]]:
    """Two live servers' wake and peer routes, each the other's peer (as two Fargate tasks under one DNS name)."""
    peer_ports = [free_port(), free_port()]
    peer_list = tuple(("127.0.0.1", port) for port in peer_ports)
    runners, tasks = [], []
    for peer_port in peer_ports:
        task = Task(url="")
        app = web.Application(client_max_size=1024)
        add_video_routes(app, access=object(), peers=PeerSettings(peer_list, ("127.0.0.1", peer_port), PEER_SECRET))
        add_wake_route(app, SECRET, task.woken.append, wake_dir="")
        runner = web.AppRunner(app, access_log=None)
        await runner.setup()
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        task.url = f"http://127.0.0.1:{runner.addresses[0][1]}"
        runners.append((runner, app))
        tasks.append(task)
    try:
        async with asyncio.timeout(30):  # each has resolved the peer list
            while not all(app[PEERS].addresses for _, app in runners):  # type: ignore[union-attr]
                await asyncio.sleep(0.02)
        yield tasks[0], tasks[1]
    finally:
        for runner, _ in runners:
            await runner.cleanup()


async def _wait_for(condition, what: str, timeout_s: float = 30.0) -> None:
    async with asyncio.timeout(timeout_s):
        while not condition():
            await asyncio.sleep(0.02)


def test_a_wake_with_the_secret_wakes_this_tasks_channels_and_the_other_tasks_once() -> None:
    async def run() -> tuple[int, list[str], list[str]]:
        async with two_tasks() as (first, second), aiohttp.ClientSession() as client:
            async with client.post(first.url + WAKE_PATH, data=b"e-2026", headers={WAKE_SECRET_HEADER: SECRET}) as r:
                status = r.status
            await _wait_for(lambda: second.woken, "the other task is woken through its peer port")
            await asyncio.sleep(0)  # let the relay's answer to itself (if any) arrive before reading the counts
            return status, first.woken, second.woken

    status, first, second = coroutines.run(run())
    assert status == 204
    assert first == ["e-2026"], "this task's channels, once (its relay to itself wakes nothing)"
    assert second == ["e-2026"], "the other task's viewers get the lap too"


@pytest.mark.parametrize(("headers", "body", "status"), [
    ({}, b"e-2026", 403),                                           # no secret
    ({WAKE_SECRET_HEADER: "x" * len(SECRET)}, b"e-2026", 403),      # a forged one
    ({WAKE_SECRET_HEADER: SECRET[:-1]}, b"e-2026", 403),            # nearly the secret
    ({WAKE_SECRET_HEADER: SECRET}, b"e" * 129, 413),                # longer than an event id
    ({WAKE_SECRET_HEADER: SECRET}, b"e" * 1000, 413),
    ({WAKE_SECRET_HEADER: SECRET}, b"", 400),
    ({WAKE_SECRET_HEADER: SECRET}, b"../../etc", 400),              # not an event id
    ({WAKE_SECRET_HEADER: SECRET}, b"e1\ne2", 400),
])
def test_a_wake_without_the_secret_or_with_a_body_that_is_not_an_event_id_wakes_nobody(
        headers: dict[str, str], body: bytes, status: int) -> None:
    async def run() -> tuple[int, str, list[str], list[str]]:
        async with two_tasks() as (first, second), aiohttp.ClientSession() as client:
            async with client.post(first.url + WAKE_PATH, data=body, headers=headers) as r:
                answer = (r.status, (await r.json())["message"])
            return (*answer, first.woken, second.woken)

    got, message, first, second = coroutines.run(run())
    assert got == status and message
    assert first == [] and second == []


def test_the_peer_port_refuses_a_wake_without_the_peer_secret() -> None:
    async def run() -> tuple[int, list[str]]:
        port = free_port()
        app = web.Application()
        add_video_routes(app, access=object(), peers=PeerSettings((("127.0.0.1", port),), ("127.0.0.1", port),
                                                                  PEER_SECRET))
        woken: list[str] = []
        add_wake_route(app, SECRET, woken.append, wake_dir="")
        runner = web.AppRunner(app, access_log=None)
        await runner.setup()
        try:
            # The wake secret is not the peer secret: the writer's secret does not open the peer port.
            async with aiohttp.ClientSession() as client, client.post(
                    f"http://127.0.0.1:{port}/peer/wake", data=b"e1", headers={"X-Drem-Peer-Secret": SECRET}) as r:
                return r.status, woken
        finally:
            await runner.cleanup()

    assert coroutines.run(run()) == (403, [])


def _serve_in_thread(tasks_ready: threading.Event, stop: threading.Event, holder: dict) -> None:
    async def main() -> None:
        async with two_tasks() as (first, second):
            holder["tasks"] = (first, second)
            tasks_ready.set()
            while not stop.is_set():
                await asyncio.sleep(0.02)

    asyncio.run(main())


def test_the_writers_http_waker_wakes_every_task_through_one_of_them() -> None:
    ready, stop, holder = threading.Event(), threading.Event(), {}
    server = threading.Thread(target=_serve_in_thread, args=(ready, stop, holder), daemon=True)
    server.start()
    try:
        assert ready.wait(30)
        first, second = holder["tasks"]
        waker = HttpWaker(first.url + WAKE_PATH, SECRET)
        waker("e-lap")
        wait_until(lambda: first.woken and second.woken, 30, "both tasks woken by the writer's one POST")
        waker("e-lap-2")  # the kept connection carries the next
        wait_until(lambda: len(second.woken) == 2, 30, "the second wake-up reaches the other task too")
        assert first.woken == ["e-lap", "e-lap-2"] and waker.sent == 2 and waker.failed == 0
    finally:
        stop.set()
        server.join(30)


def test_a_live_server_that_does_not_answer_costs_the_writer_one_short_wait_then_none() -> None:
    """The writer returns while its wake-up is still unanswered; one that comes meanwhile waits behind it, and when it
    fails, that one and, for a while, further wake-ups are not even tried (the live server's poll shows those laps)."""
    import socket

    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen()
    port = listener.getsockname()[1]
    arrived: list[socket.socket] = []
    taker = threading.Thread(target=lambda: arrived.append(listener.accept()[0]), daemon=True)
    taker.start()
    waker = HttpWaker(f"http://127.0.0.1:{port}{WAKE_PATH}", SECRET, backoff_s=600, socket_timeout_s=600)
    try:
        waker("e1")  # returns although nothing will ever answer
        wait_until(lambda: arrived, 30, "the wake-up reached the stalled server")
        assert waker.sent == 0 and waker.failed == 0, "the writer did not wait for the answer"
        waker("e2")
        assert waker.remembered == 1 and waker.skipped == 0, "one wake-up in flight at a time, the next waits"
        listener.close()
        arrived[0].close()  # the server goes away without answering
        wait_until(lambda: waker.failed == 1, 30, "the unanswered wake-up failed")
        assert waker.skipped == 1 and waker.remembered == 0, "the waiting one is dropped with it"
        waker("e3")
        assert waker.skipped == 2, "after a failure the writer stops trying for a while"
    finally:
        listener.close()
        for conn in arrived:
            conn.close()


def test_a_wake_up_that_comes_while_one_is_in_flight_is_sent_right_after_it() -> None:
    """A lap writes the board and then the overlay: the overlay's wake-up must not be lost behind the board's, or the
    overlay would wait for the live server's poll. Two writes of one event meanwhile are one wake-up."""
    import socket

    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen()
    port = listener.getsockname()[1]
    bodies: list[bytes] = []
    answer_first = threading.Event()

    def serve() -> None:
        conn, _ = listener.accept()
        with conn, conn.makefile("rb") as requests_in:
            while True:
                length = 0
                while (line := requests_in.readline()) not in (b"\r\n", b""):
                    if line.lower().startswith(b"content-length:"):
                        length = int(line.split(b":")[1])
                if not line:
                    return
                bodies.append(requests_in.read(length))
                if len(bodies) == 1:
                    answer_first.wait(30)
                conn.sendall(b"HTTP/1.1 204 No Content\r\n\r\n")

    server = threading.Thread(target=serve, daemon=True)
    server.start()
    waker = HttpWaker(f"http://127.0.0.1:{port}{WAKE_PATH}", SECRET, socket_timeout_s=30)
    try:
        waker("e-board")  # its answer is held back: the writer returns after its bound
        wait_until(lambda: bodies, 30, "the first wake-up reached the live server")
        waker("e-overlay")
        waker("e-overlay")
        assert bodies == [b"e-board"] and waker.remembered == 1
        answer_first.set()
        wait_until(lambda: waker.sent == 2, 30, "the remembered wake-up sent once the first was answered")
        assert bodies == [b"e-board", b"e-overlay"] and waker.skipped == 0 and waker.remembered == 0
    finally:
        answer_first.set()
        listener.close()


def test_the_settings_choose_the_wake_path_and_refuse_a_short_secret(tmp_path) -> None:
    local = Settings.from_env({"DREM_LIVE_WAKE_DIR": str(tmp_path)})
    aws = Settings.from_env({"DREM_LIVE_WAKE_SECRET": SECRET, "DREM_PUBLIC_URL": "https://d111.cloudfront.net/drem"})
    assert isinstance(live_wake.waker(local), LiveWaker)
    assert isinstance(live_wake.waker(aws), HttpWaker)
    assert live_wake.wake_url(aws.public_url) == "https://d111.cloudfront.net/live/wake"
    assert live_wake.waker(Settings.from_env({})) is None, "no wake path: the live server polls"
    assert SECRET not in repr(aws)
    with pytest.raises(ValueError, match="at least 16"):
        Settings.from_env({"DREM_LIVE_WAKE_SECRET": "short"})
