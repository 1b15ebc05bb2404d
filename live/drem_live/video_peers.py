"""Every live task shows every car's camera: the task a car's upload reached passes each frame on to its peers.

On AWS the load balancer sends a car's frames to one live task and each viewer to any task. Each task therefore
  - forwards every frame a car uploads to it to the other tasks (`POST /peer/frame`), each peer with at most one
    request in flight and one frame waiting: a newer frame replaces the waiting one (latest-frame-wins), so a slow or
    dead peer costs dropped frames, never memory or the car's upload;
  - tells the other tasks which cars its own viewers watch (`POST /peer/interest`, on every change and every
    INTEREST_EVERY_S), so a car is asked to send while any task has a viewer for it (drem_live.video_feeds).
Frames received from a peer are shown, never forwarded again (no loops). The same path carries the writer's wake-ups
(drem_live.wake_route): the task the writer reached relays each to the others (`POST /peer/wake`, the event id), which
wake their own channels and relay nothing.

Peers listen on their own port (PEER_LISTEN_ENV), never behind the load balancer; every request carries the shared
secret (PEER_SECRET_ENV) and is refused without it. Who the peers are (PEERS_ENV): `host:port` entries, each resolved
every RESOLVE_EVERY_S to all its addresses, so one DNS name with an A record per task (ECS service discovery) names
them all. A task finds itself in that list by its own random id, which each peer answers with.
"""
from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import logging
import os
import re
import secrets
import socket
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass

import aiohttp
from aiohttp import web

from drem_live.video_feeds import MAX_FRAME_BYTES, Feeds, looks_like_jpeg

PEERS_ENV = "DREM_LIVE_VIDEO_PEERS"  # "host:port[,host:port…]", e.g. the service discovery name of all live tasks
PEER_LISTEN_ENV = "DREM_LIVE_VIDEO_PEER_LISTEN"  # "host:port" this task takes its peers' requests on
PEER_SECRET_ENV = "DREM_LIVE_VIDEO_PEER_SECRET"
SECRET_HEADER = "X-Drem-Peer-Secret"
FROM_HEADER = "X-Drem-Peer-From"  # the sender's id (a task ignores what it sent itself)
ID_HEADER = "X-Drem-Peer-Id"  # the answering task's id
CAR_HEADER = "X-Drem-Car"
HOSTNAME_HEADER = "X-Drem-Car-Hostname"
RESOLVE_EVERY_S = 5.0
INTEREST_EVERY_S = 5.0
INTEREST_TTL_S = 15.0  # three missed reports and a peer's viewers no longer count
SEND_TIMEOUT_S = 2.0
MAX_NAMES = 1000
CAR_NAME = re.compile(r"[A-Za-z0-9_.-]{1,64}")
PEER_ID = re.compile(r"[0-9a-f]{16}")
EVENT_ID = re.compile(rb"[A-Za-z0-9_.-]{1,128}")

log = logging.getLogger("drem_live.video_peers")
Address = tuple[str, int]


@dataclass(frozen=True)
class PeerSettings:
    peers: tuple[Address, ...]
    listen: Address
    secret: str

    @classmethod
    def from_env(cls, env: dict[str, str] | None = None) -> PeerSettings | None:
        """None when the environment names no peers (one live process: nothing to share)."""
        env = dict(os.environ) if env is None else env
        if not env.get(PEERS_ENV):
            return None
        secret = env.get(PEER_SECRET_ENV, "")
        if len(secret) < 16:
            raise ValueError(f"{PEER_SECRET_ENV} must be a secret of at least 16 characters when {PEERS_ENV} is set.")
        return cls(tuple(_address(entry) for entry in env[PEERS_ENV].split(",") if entry.strip()),
                   _address(env.get(PEER_LISTEN_ENV, "")), secret)


def _address(entry: str) -> Address:
    host, _, port = entry.strip().rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"'{entry}' is not host:port ({PEERS_ENV}, {PEER_LISTEN_ENV}).")
    return host, int(port)


@dataclass(frozen=True)
class Upload:
    device_id: str
    hostname: str
    jpeg: bytes
    taken_ms: float


class Peers:
    def __init__(self, feeds: Feeds, settings: PeerSettings) -> None:
        self.feeds = feeds
        self.settings = settings
        self.id = secrets.token_hex(8)
        self.addresses: set[Address] = set()
        self._myself: set[Address] = set()
        self._waiting: dict[Address, Upload] = {}
        self._sending: set[Address] = set()
        self._interest_changed = asyncio.Event()
        self.session: aiohttp.ClientSession | None = None
        self.forwarded = self.dropped = self.wakes_relayed = self.wakes_taken = 0
        # What a peer's relayed wake-up does here (drem_live.wake_route sets it); None: nothing to wake.
        self.on_wake: Callable[[str], None] | None = None
        feeds.on_interest_change = self._interest_changed.set

    def others(self) -> set[Address]:
        return self.addresses - self._myself

    def forward(self, upload: Upload) -> None:
        """Pass a car's frame to every other task, never waiting and never queueing more than one frame per peer."""
        for address in self.others():
            if address in self._sending:
                if address in self._waiting:
                    self.dropped += 1
                self._waiting[address] = upload  # the newest frame replaces the one still waiting
            else:
                self._sending.add(address)
                asyncio.get_running_loop().create_task(self._send_frames(address, upload))

    def relay_wake(self, event_id: str) -> None:
        """Tell every other task that `event_id` changed, without waiting for any of them (each post is bounded)."""
        body = event_id.encode()
        loop = asyncio.get_running_loop()
        for address in self.others():
            self.wakes_relayed += 1
            loop.create_task(self._post(address, "/peer/wake", body, {"Content-Type": "text/plain"}))

    async def _send_frames(self, address: Address, upload: Upload | None) -> None:
        try:
            while upload is not None:
                headers = {CAR_HEADER: upload.device_id, HOSTNAME_HEADER: upload.hostname,
                           "X-Frame-Time": repr(upload.taken_ms), "Content-Type": "image/jpeg"}
                if await self._post(address, "/peer/frame", upload.jpeg, headers):
                    self.forwarded += 1
                upload = self._waiting.pop(address, None)
        finally:
            self._sending.discard(address)

    async def _post(self, address: Address, path: str, body: bytes, headers: dict[str, str]) -> bool:
        if self.session is None or self.session.closed:
            return False  # the server is stopping
        try:
            async with self.session.post(
                    f"http://{address[0]}:{address[1]}{path}", data=body,
                    headers={**headers, SECRET_HEADER: self.settings.secret, FROM_HEADER: self.id},
                    timeout=aiohttp.ClientTimeout(total=SEND_TIMEOUT_S)) as response:
                if response.headers.get(ID_HEADER) == self.id:
                    self._myself.add(address)  # that address is this very task
                return response.status < 300
        except (aiohttp.ClientError, TimeoutError, OSError) as exc:
            log.debug("peer %s:%d did not take %s: %s", *address, path, exc)
            return False

    async def _tell_interest(self) -> None:
        body = json.dumps({"names": self.feeds.watched_here()}).encode()
        await asyncio.gather(*(self._post(a, "/peer/interest", body, {"Content-Type": "application/json"})
                               for a in self.others()))

    async def _resolve(self) -> None:
        found: set[Address] = set()
        loop = asyncio.get_running_loop()
        for host, port in self.settings.peers:
            try:
                infos = await loop.getaddrinfo(host, port, family=socket.AF_INET, type=socket.SOCK_STREAM)
            except OSError as exc:
                log.warning("cannot resolve peer %s: %s", host, exc)
                continue
            found |= {(str(info[4][0]), port) for info in infos}
        if found != self.addresses:
            log.info("video peers: %s", sorted(found))
            self._interest_changed.set()  # a new task learns at once what the others' viewers watch
        self.addresses = found

    async def run(self) -> None:
        """Keep the peer list current and report this task's viewers' interest, until cancelled."""
        loop = asyncio.get_running_loop()
        resolved_at = told_at = float("-inf")
        while True:
            if loop.time() - resolved_at >= RESOLVE_EVERY_S:
                await self._resolve()
                resolved_at = loop.time()
            if self._interest_changed.is_set() or loop.time() - told_at >= INTEREST_EVERY_S:
                self._interest_changed.clear()
                await self._tell_interest()
                told_at = loop.time()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(1.0):
                    await self._interest_changed.wait()

    # --- the peer port: what the other tasks send ------------------------------------------------------------------

    def _trusted(self, request: web.Request) -> bool:
        return hmac.compare_digest(request.headers.get(SECRET_HEADER, "").encode(), self.settings.secret.encode())

    async def take_frame(self, request: web.Request) -> web.Response:
        if not self._trusted(request):
            return web.json_response({"message": "Only the other live tasks send here."}, status=403)
        answer = {ID_HEADER: self.id}
        if request.headers.get(FROM_HEADER) == self.id:
            return web.Response(status=204, headers=answer)  # this task reached itself: shown already
        device_id, hostname = request.headers.get(CAR_HEADER, ""), request.headers.get(HOSTNAME_HEADER, "")
        if not CAR_NAME.fullmatch(device_id) or (hostname and not CAR_NAME.fullmatch(hostname)):
            return web.json_response({"message": "X-Drem-Car must name the car."}, status=400, headers=answer)
        size = request.content_length
        if size is None or not 0 < size <= MAX_FRAME_BYTES:
            return web.json_response({"message": "One JPEG frame, with its Content-Length."}, status=413,
                                     headers=answer)
        jpeg = await request.content.readexactly(size)
        try:
            taken_ms = float(request.headers.get("X-Frame-Time", ""))
        except ValueError:
            return web.json_response({"message": "X-Frame-Time: epoch ms."}, status=400, headers=answer)
        if not looks_like_jpeg(jpeg):
            return web.json_response({"message": "Not a JPEG."}, status=415, headers=answer)
        self.feeds.feed(device_id, hostname).publish(jpeg, taken_ms)
        self.feeds.frames_in += 1
        return web.Response(status=204, headers=answer)

    async def take_interest(self, request: web.Request) -> web.Response:
        if not self._trusted(request):
            return web.json_response({"message": "Only the other live tasks send here."}, status=403)
        answer = {ID_HEADER: self.id}
        sender = request.headers.get(FROM_HEADER, "")
        if sender == self.id:
            return web.Response(status=204, headers=answer)
        try:
            names = json.loads(await request.read())["names"]  # bounded by the peer app's client_max_size
            valid = (PEER_ID.fullmatch(sender) and isinstance(names, list) and len(names) <= MAX_NAMES
                     and all(isinstance(n, str) and CAR_NAME.fullmatch(n) for n in names))
        except (ValueError, KeyError, TypeError):
            valid = False
        if not valid:
            return web.json_response({"message": "{\"names\": [car names]} from a peer id."}, status=400,
                                     headers=answer)
        self.feeds.watched_by_peer(sender, frozenset(names), INTEREST_TTL_S)
        return web.Response(status=204, headers=answer)

    async def take_wake(self, request: web.Request) -> web.Response:
        if not self._trusted(request):
            return web.json_response({"message": "Only the other live tasks send here."}, status=403)
        answer = {ID_HEADER: self.id}
        if request.headers.get(FROM_HEADER) == self.id:
            return web.Response(status=204, headers=answer)  # this task reached itself: woken already
        body = await request.read()  # bounded by the peer app's client_max_size
        if not EVENT_ID.fullmatch(body):
            return web.json_response({"message": "The body is an event id."}, status=400, headers=answer)
        self.wakes_taken += 1
        if self.on_wake is not None:
            self.on_wake(body.decode())
        return web.Response(status=204, headers=answer)

    def peer_app(self) -> web.Application:
        app = web.Application(client_max_size=MAX_FRAME_BYTES + 1024)
        app.router.add_post("/peer/frame", self.take_frame)
        app.router.add_post("/peer/interest", self.take_interest)
        app.router.add_post("/peer/wake", self.take_wake)
        return app


def serve_peers(app: web.Application, peers: Peers) -> None:
    """Run the peer port and the peer list beside `app` (the live server), for as long as it runs."""
    async def lifetime(_app: web.Application) -> AsyncIterator[None]:
        peers.session = aiohttp.ClientSession(connector=aiohttp.TCPConnector(limit=0))
        runner = web.AppRunner(peers.peer_app(), access_log=None)
        await runner.setup()
        await web.TCPSite(runner, *peers.settings.listen, reuse_address=True).start()
        task = asyncio.get_running_loop().create_task(peers.run())
        try:
            yield
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
            await runner.cleanup()
            await peers.session.close()

    app.cleanup_ctx.append(lifetime)
