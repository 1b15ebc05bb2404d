"""Passing a car's frames to the other live servers (drem_live.video_peers): a peer that does not answer costs dropped
frames, never a queue; settings that would leave the peer port open without a secret are refused."""
from __future__ import annotations

import asyncio

import aiohttp
import pytest

from drem_live.video_feeds import Feeds
from drem_live.video_peers import Peers, PeerSettings, Upload
from tests import coroutines

JPEG = b"\xff\xd8\xff\xe0" + b"x" * 10 + b"\xff\xd9"


def test_a_peer_that_never_answers_gets_one_frame_in_flight_and_only_the_newest_waiting() -> None:
    async def run() -> tuple[int, int, float]:
        arrived, finished = asyncio.Event(), asyncio.Event()

        async def stall(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            arrived.set()
            await finished.wait()  # takes the request and never answers
            writer.close()

        server = await asyncio.start_server(stall, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        peers = Peers(Feeds(), PeerSettings((("127.0.0.1", port),), ("127.0.0.1", 0), "s" * 20))
        peers.addresses = {("127.0.0.1", port)}
        async with aiohttp.ClientSession() as peers.session:
            peers.forward(Upload("car-1", "eye-car", JPEG, 1.0))
            async with asyncio.timeout(10):
                await arrived.wait()  # the first frame is on its way and stays there
            for taken in range(2, 31):  # the rest of two seconds of a 15 fps car
                peers.forward(Upload("car-1", "eye-car", JPEG, float(taken)))
            waiting = peers._waiting[("127.0.0.1", port)].taken_ms
            in_flight = len(peers._sending)
            finished.set()
        server.close()
        return in_flight, peers.dropped, waiting

    in_flight, dropped, waiting = coroutines.run(run())
    assert (in_flight, dropped, waiting) == (1, 28, 30.0)  # the first in flight, the newest waiting, the rest dropped


@pytest.mark.parametrize("env, message", [
    ({"DREM_LIVE_VIDEO_PEERS": "live.internal:8081", "DREM_LIVE_VIDEO_PEER_LISTEN": "0.0.0.0:8081"}, "secret"),
    ({"DREM_LIVE_VIDEO_PEERS": "live.internal", "DREM_LIVE_VIDEO_PEER_SECRET": "s" * 20,
      "DREM_LIVE_VIDEO_PEER_LISTEN": "0.0.0.0:8081"}, "host:port"),
])
def test_peer_settings_without_a_secret_or_a_port_are_refused_with_what_is_wrong(env: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        PeerSettings.from_env(env)


def test_without_peers_a_live_server_shares_nothing() -> None:
    assert PeerSettings.from_env({}) is None
