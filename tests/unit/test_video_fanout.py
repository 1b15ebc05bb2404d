"""The cars' frames written to viewers by the fan-out worker (drem_live.video_fanout): a real worker process, viewer
connections as the live server hands them over (a duplicate of the socket, after the response headers)."""
from __future__ import annotations

import asyncio
import os
import socket
import sys
import time

import pytest

from drem_live.video_fanout import FanOutWorker
from drem_live.video_feeds import CarFeed
from tests.coroutines import run

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="SCM_RIGHTS and SCHED_IDLE are Linux's")


class Viewer:
    """The phone's end of one connection, and the live server's end as aiohttp holds it (a transport)."""

    def __init__(self, phone: socket.socket, transport: asyncio.BaseTransport) -> None:
        self.phone, self.transport = phone, transport
        self.received = b""

    async def read_until(self, text: bytes, deadline_s: float = 20.0) -> bytes:
        loop = asyncio.get_running_loop()
        end = time.monotonic() + deadline_s
        while text not in self.received:
            assert time.monotonic() < end, f"{text!r} never arrived; got {self.received[-200:]!r}"
            try:
                self.received += await asyncio.wait_for(loop.sock_recv(self.phone, 65536), 1.0)
            except TimeoutError:
                continue
        return self.received


async def connect() -> Viewer:
    server_end, phone = socket.socketpair()
    server_end.setblocking(False)
    phone.setblocking(False)
    transport, _ = await asyncio.get_running_loop().connect_accepted_socket(asyncio.Protocol, server_end)
    return Viewer(phone, transport)


def published(feed: CarFeed, number: int) -> None:
    feed.publish(b"\xff\xd8\xff" + f"frame-{number}".encode() + b"\xff\xd9", time.time() * 1000)


def test_the_worker_writes_each_frame_to_every_viewer_of_its_car_and_takes_only_idle_cpu() -> None:
    async def scenario() -> None:
        worker = FanOutWorker()
        worker.start(asyncio.get_running_loop())
        try:
            assert os.sched_getscheduler(worker._process.pid) == os.SCHED_IDLE
            feed, other = CarFeed("car-1", remote=worker.frame), CarFeed("car-2", remote=worker.frame)
            viewers = [await connect() for _ in range(3)]
            for viewer in viewers:
                worker.attach(viewer.transport, True, "car-1", lambda: None)
            elsewhere = await connect()
            worker.attach(elsewhere.transport, True, "car-2", lambda: None)
            for number in range(1, 4):
                published(feed, number)
                for viewer in viewers:
                    await viewer.read_until(f"frame-{number}".encode())
            published(other, 9)
            await elsewhere.read_until(b"frame-9")
            assert b"frame-1" not in elsewhere.received  # only the car it follows
            assert all(b"X-Frame: 3" in viewer.received for viewer in viewers)
            assert all(b"frame-9" not in viewer.received for viewer in viewers)
        finally:
            worker.stop()

    run(scenario())


def test_a_viewer_that_follows_the_next_car_gets_its_frames_and_one_let_go_gets_no_more() -> None:
    async def scenario() -> None:
        worker = FanOutWorker()
        worker.start(asyncio.get_running_loop())
        try:
            first, second = CarFeed("car-1", remote=worker.frame), CarFeed("car-2", remote=worker.frame)
            follower, leaver = await connect(), await connect()
            following = worker.attach(follower.transport, True, "car-1", lambda: None)
            leaving = worker.attach(leaver.transport, True, "car-1", lambda: None)
            published(first, 1)
            await follower.read_until(b"frame-1")
            await leaver.read_until(b"frame-1")
            worker.detach(leaving)
            worker.follow(following, "car-2")
            published(second, 2)
            await follower.read_until(b"frame-2")  # the worker has read both messages (they arrive in order)
            published(first, 3)
            published(second, 4)
            await follower.read_until(b"frame-4")
            assert b"frame-3" not in follower.received
            assert b"frame-2" not in leaver.received and b"frame-3" not in leaver.received
        finally:
            worker.stop()

    run(scenario())
