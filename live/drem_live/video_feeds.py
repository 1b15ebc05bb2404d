"""The cars' camera feeds in the live server: one upload per car, any number of viewers (fan-out in memory).

Each car's feed keeps only its latest frame (latest-frame-wins): a viewer that falls behind skips to the newest frame
instead of queueing old ones, and the car's upload does not grow with the number of viewers. A frame is encoded for
the viewers once, as one part of a `multipart/x-mixed-replace` (MJPEG) stream, and the same bytes go to every one.

Demand: a car uploads only while someone may watch it. Viewers register interest under the name the race knows the car
by (its device id or hostname); a car asks whether it is wanted, by its device id, and the feed answers from the
interest held under either name. With several live tasks (drem_live.video_peers) the viewers of the other tasks count
too: each task tells its peers which cars its viewers watch, and a car is wanted while any task wants it.
Everything here runs on the server's one event loop (no locks).
"""
from __future__ import annotations

import asyncio
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

BOUNDARY = "drem-frame"
MJPEG_CONTENT_TYPE = f"multipart/x-mixed-replace;boundary={BOUNDARY}"
MAX_FRAME_BYTES = 512 * 1024


DROP_BEHIND_S = 5.0  # a viewer behind for this long is dropped
FAN_OUT_SLICE = 25  # viewers written in one turn of the event loop (about 0.6 ms at 30 KB a frame)


@dataclass(frozen=True)
class Frame:
    seq: int
    taken_ms: float  # the car's clock when the frame was taken (epoch ms): viewers measure glass-to-glass from it
    received_ms: float
    part: bytes  # the whole multipart part (boundary, headers, JPEG, CRLF): written as is to every viewer
    chunk: bytes = b""  # the same part as one HTTP/1.1 chunk (what a chunked response carries)


@dataclass(eq=False)
class Sink:
    """One viewer's connection, written straight from `CarFeed.publish`: a loop over the viewers per frame (in slices
    the event loop's other work runs between), no coroutine woken per viewer (500 viewers at 15 fps would be 7,500 task
    switches a second)."""
    transport: asyncio.BaseTransport
    chunked: bool = True
    shown: int = 0
    behind_since: float | None = None
    closed: asyncio.Event = field(default_factory=asyncio.Event)

    def offer(self, frame: Frame, now: float) -> None:
        transport = self.transport
        if self.closed.is_set() or frame.seq <= self.shown:
            return
        if transport.is_closing():
            self.closed.set()
            return
        if transport.get_write_buffer_size() > 0:  # type: ignore[attr-defined]
            # Latest frame wins: while any of its last frame is still unsent this one is skipped, and the viewer gets
            # the newest once that is out. So at most one frame (the rest of it the socket did not take at once) waits
            # in the server per viewer, and none is copied behind another: a backlog of frames would cost memory, a
            # copy into the transport's buffer per viewer, and the viewer a picture ever further behind the car.
            if self.behind_since is None:
                self.behind_since = now
            elif now - self.behind_since > DROP_BEHIND_S:
                transport.close()
                self.closed.set()
            return
        self.behind_since = None
        transport.write(frame.chunk if self.chunked else frame.part)  # type: ignore[attr-defined]
        self.shown = frame.seq


def mjpeg_part(jpeg: bytes, taken_ms: float, seq: int) -> bytes:
    # The part headers web_video_server sends (Content-type, X-Timestamp in seconds, Content-Length), plus our
    # frame number; see tests/cars/fake_deepracer_console.py for the upstream file.
    head = (f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {len(jpeg)}\r\n"
            f"X-Timestamp: {taken_ms / 1000:.6f}\r\nX-Frame: {seq}\r\n\r\n").encode()
    return head + jpeg + b"\r\n"


def looks_like_jpeg(data: bytes) -> bool:
    return len(data) >= 4 and data[:3] == b"\xff\xd8\xff" and data[-2:] == b"\xff\xd9"


@dataclass
class CarFeed:
    device_id: str
    hostname: str = ""
    latest: Frame | None = None
    sinks: set[Sink] = field(default_factory=set)
    # Set when a worker process writes the frames to the viewers (drem_live.video_fanout): each frame goes to it once.
    remote: Callable[[str, Frame], None] | None = None
    _next: asyncio.Event = field(default_factory=asyncio.Event)

    def publish(self, jpeg: bytes, taken_ms: float) -> Frame:
        seq = (self.latest.seq + 1) if self.latest else 1
        part = mjpeg_part(jpeg, taken_ms, seq)
        frame = self.latest = Frame(seq, taken_ms, time.time() * 1000, part, b"%x\r\n%b\r\n" % (len(part), part))
        if self.remote is not None:
            self.remote(self.device_id, frame)
        self._fan_out(frame, list(self.sinks), 0)
        woken, self._next = self._next, asyncio.Event()
        woken.set()
        return frame

    def _fan_out(self, frame: Frame, sinks: list[Sink], start: int) -> None:
        """Writes the frame to FAN_OUT_SLICE viewers, then lets the event loop run what is due (a board push, a lap)
        before the next slice: 500 viewers at once held the loop 13 ms (25 ms p95) a frame."""
        if frame is not self.latest:
            return  # a newer frame is on its way to every viewer: latest-frame-wins
        now = time.monotonic()
        for sink in sinks[start:start + FAN_OUT_SLICE]:
            sink.offer(frame, now)
        rest = start + FAN_OUT_SLICE
        if rest < len(sinks):
            asyncio.get_running_loop().call_soon(self._fan_out, frame, sinks, rest)

    def attach(self, sink: Sink) -> None:
        """The viewer gets every frame from now on, starting with the newest one there is."""
        self.sinks.add(sink)
        if self.latest is not None:
            sink.offer(self.latest, time.monotonic())

    async def next_after(self, seq: int, timeout_s: float) -> Frame | None:
        """The latest frame newer than `seq`, waiting up to `timeout_s` for one (None: none came)."""
        if self.latest is not None and self.latest.seq > seq:
            return self.latest
        waiter = self._next
        try:
            async with asyncio.timeout(timeout_s):  # not wait_for: on 3.11 that makes a task per viewer per frame
                await waiter.wait()
        except TimeoutError:
            return None
        return self.latest if self.latest is not None and self.latest.seq > seq else None


class Feeds:
    def __init__(self, max_viewers: int = 5000) -> None:
        self.max_viewers = max_viewers
        self._feeds: dict[str, CarFeed] = {}
        self._names: dict[str, str] = {}  # hostname or device id → device id
        self._interest: Counter[str] = Counter()  # car name → viewers watching it
        self._demand_changed: dict[str, asyncio.Event] = {}
        self._remote: dict[str, tuple[float, frozenset[str]]] = {}  # peer id → (expires, the car names it watches)
        self.on_interest_change: Callable[[], None] | None = None  # the peers are told (drem_live.video_peers)
        self.remote: Callable[[str, Frame], None] | None = None  # a fan-out worker's (drem_live.video_fanout)
        self.viewers = 0
        self.frames_in = 0

    def feed(self, device_id: str, hostname: str = "") -> CarFeed:
        feed = self._feeds.get(device_id)
        if feed is None:
            feed = self._feeds[device_id] = CarFeed(device_id, hostname)
        feed.remote = self.remote
        if hostname:
            feed.hostname = hostname
            self._names[hostname] = device_id
        self._names[device_id] = device_id
        return feed

    def find(self, car_name: str) -> CarFeed | None:
        device_id = self._names.get(car_name)
        return self._feeds.get(device_id) if device_id else None

    def wanted(self, device_id: str) -> bool:
        feed = self._feeds.get(device_id)
        names = {device_id, *((feed.hostname,) if feed and feed.hostname else ())}
        if any(self._interest[name] > 0 for name in names):
            return True
        now = time.monotonic()
        return any(expires > now and not names.isdisjoint(watched) for expires, watched in self._remote.values())

    def watched_here(self) -> list[str]:
        """The car names this server's own viewers watch (what its peers are told)."""
        return sorted(name for name, count in self._interest.items() if count > 0)

    def watched_by_peer(self, peer_id: str, names: frozenset[str], ttl_s: float) -> None:
        """A peer's viewers watch these cars (its whole list, replacing the last one), for the next `ttl_s`: a peer
        that stops telling (stopped, cut off) stops counting by itself."""
        _expires, before = self._remote.get(peer_id, (0.0, frozenset()))
        self._remote[peer_id] = (time.monotonic() + ttl_s, names)
        for name in before ^ names:
            self._wake(name)

    def watch(self, car_name: str) -> None:
        self.viewers += 1
        self._interest[car_name] += 1
        if self._interest[car_name] == 1:
            self._wake(car_name)
            self._tell_peers()

    def unwatch(self, car_name: str) -> None:
        self.viewers -= 1
        self._interest[car_name] -= 1
        if self._interest[car_name] <= 0:
            del self._interest[car_name]
            self._wake(car_name)
            self._tell_peers()

    def _tell_peers(self) -> None:
        if self.on_interest_change is not None:
            self.on_interest_change()

    def full(self) -> bool:
        return self.viewers >= self.max_viewers

    async def demand_change(self, device_id: str, reported: bool, timeout_s: float) -> bool:
        """Whether the car is wanted, answered at once when that differs from what it `reported`, else when it
        changes or after `timeout_s` (a long poll: a race's start reaches the car at once)."""
        deadline = time.monotonic() + timeout_s
        while self.wanted(device_id) == reported:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            event = self._demand_changed.setdefault(device_id, asyncio.Event())
            try:
                await asyncio.wait_for(event.wait(), left)
            except TimeoutError:
                break
        return self.wanted(device_id)

    def _wake(self, car_name: str) -> None:
        device_id = self._names.get(car_name, car_name)
        event = self._demand_changed.pop(device_id, None)
        if event is not None:
            event.set()

    def as_dict(self) -> dict[str, int]:
        return {"cars": len(self._feeds), "viewers": self.viewers, "frames_in": self.frames_in}
