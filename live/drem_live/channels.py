"""Channels: one per (kind, event, options) that anyone watches. A single watcher per channel reads storage when the
writer wakes it (`Channels.wake(event_id)`, drem_live.wake) and every `poll_s` as the fallback, renders the live
region once per token change (in a worker thread: boto3 and jinja block) and hands the same
message bytes to every subscriber. A channel never broadcasts a token that is not newer than the last one it sent
(`token_is_newer`), and it stops when its last subscriber leaves.

A subscriber keeps only the newest message it has not written yet: a slow phone skips intermediate boards instead of
queueing them, so memory per subscriber is bounded and nobody is shown an older board after a newer one.
"""
from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Hashable
from concurrent.futures import Executor
from dataclasses import dataclass, field

from drem_live.sse import Message

log = logging.getLogger("drem_live")
MIN_READ_GAP_S = 0.01  # however many wake-ups arrive, a channel reads at most this often



class ChannelsFull(Exception):
    """More channels than the cap: someone is opening many different option sets."""


@dataclass(eq=False)  # compared (and hashed) by identity: each is one viewer's connection
class Subscriber:
    pending: Message | None = None
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    heartbeat_due: bool = False

    def offer(self, message: Message) -> None:
        self.pending = message
        self.wake.set()

    def beat(self) -> None:
        """Ask for a heartbeat (Channels' one timer for everybody, instead of a timer per viewer per message)."""
        self.heartbeat_due = True
        self.wake.set()

    def take(self) -> Message | None:
        self.wake.clear()
        self.heartbeat_due = False
        message, self.pending = self.pending, None
        return message


@dataclass
class MessageSizes:
    """Bytes per broadcast message, plain and gzip (the AWS cost model prices data transfer per byte)."""
    messages: int = 0
    plain_bytes: int = 0
    gzip_bytes: int = 0

    def add(self, message: Message) -> None:
        self.messages += 1
        self.plain_bytes += len(message.plain)
        self.gzip_bytes += len(message.gzip)

    def as_dict(self) -> dict[str, float]:
        count = max(1, self.messages)
        return {"messages": self.messages, "plain_bytes_avg": round(self.plain_bytes / count, 1),
                "gzip_bytes_avg": round(self.gzip_bytes / count, 1)}


class Channel:
    def __init__(self, key: Hashable, step: Callable[[Message | None], Message | None], poll_s: float,
                 executor: Executor, sizes: MessageSizes, is_newer: Callable[[str, str | None], bool],
                 event_id: str = "") -> None:
        self.key = key
        self.event_id = event_id
        self._woken = asyncio.Event()
        self.subscribers: set[Subscriber] = set()
        self.latest: Message | None = None
        self.first = asyncio.Event()
        self._step = step
        self._poll_s = poll_s
        self._executor = executor
        self._sizes = sizes
        self._is_newer = is_newer
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(self._watch())

    def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()

    def wake(self) -> None:
        """Read again now (the writer changed this event); a wake during a read makes one more read after it."""
        self._woken.set()

    async def _watch(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            started = time.monotonic()
            self._woken.clear()
            try:
                message = await loop.run_in_executor(self._executor, self._step, self.latest)
            except asyncio.CancelledError:
                raise
            except Exception:  # storage briefly away: keep the last board on screen, try again next round
                log.exception("live channel %s could not read or render", self.key)
                message = None
            if message is not None and self._is_newer(message.token, self.latest.token if self.latest else None):
                self.latest = message
                self._sizes.add(message)
                for subscriber in self.subscribers:
                    subscriber.offer(message)
                self.first.set()
            try:
                await asyncio.wait_for(self._woken.wait(), max(0.0, self._poll_s - (time.monotonic() - started)))
            except TimeoutError:
                continue
            await asyncio.sleep(max(0.0, MIN_READ_GAP_S - (time.monotonic() - started)))


class Channels:
    """The open channels, capped in number."""

    def __init__(self, poll_s: float, executor: Executor, max_channels: int,
                 is_newer: Callable[[str, str | None], bool], max_per_page: int | None = None) -> None:
        self.poll_s = poll_s
        self.is_newer = is_newer
        self.executor = executor
        self.max_channels = max_channels
        self.max_per_page = max_per_page or max_channels
        self.sizes = MessageSizes()
        self._open: dict[Hashable, Channel] = {}
        self._pages: dict[Hashable, Hashable] = {}  # channel key -> its page (kind, event)

    def __len__(self) -> int:
        return len(self._open)

    def is_open(self, key: Hashable) -> bool:
        return key in self._open

    def join(self, key: Hashable, step: Callable[[Message | None], Message | None],
             subscriber: Subscriber, *, page: Hashable | None = None, event_id: str = "",
             offered: bool = False) -> Channel:
        """Subscribe to channel `key` (of `page`), opening it if there is room: joining an open one is always free.

        Option sets the app itself hands out (`offered`: drem's own pages and overlay links, a number bounded by the
        event's tracks, chalicelib.views.live_options) always get a channel while the server has room. Any other
        option set of a page (a hand-edited query) takes one of the page's `max_per_page` slots, and such option sets
        take at most half the server's channels, so made-up queries can neither refuse a page drem offers nor take
        every channel (issue 27: 4 addresses x 64 distinct queries took all 256). A channel of `event_id` is woken by
        `wake(event_id)` when the writer says that event changed."""
        channel = self._open.get(key)
        if channel is None:
            if len(self._open) >= self.max_channels:
                raise ChannelsFull(f"the live server already watches {self.max_channels} different pages")
            if not offered:
                self._check_room_for_other_options(page)
            channel = Channel(key, step, self.poll_s, self.executor, self.sizes, self.is_newer, event_id)
            self._open[key] = channel
            if page is not None and not offered:
                self._pages[key] = page
            channel.start()
        channel.subscribers.add(subscriber)
        return channel

    def _check_room_for_other_options(self, page: Hashable | None) -> None:
        if page is None:
            return
        if len(self._pages) >= max(1, self.max_channels // 2):
            raise ChannelsFull(f"the live server already watches {len(self._pages)} pages with options of their own")
        same_page = sum(1 for other in self._pages.values() if other == page)
        if same_page >= self.max_per_page:
            raise ChannelsFull(f"this page is already watched with {self.max_per_page} options of its own")

    def leave(self, channel: Channel, subscriber: Subscriber) -> None:
        channel.subscribers.discard(subscriber)
        if not channel.subscribers and self._open.get(channel.key) is channel:
            del self._open[channel.key]
            self._pages.pop(channel.key, None)
            channel.stop()

    async def beat_every(self, seconds: float) -> None:
        """Every `seconds`, a heartbeat to every subscriber not already woken for a message (an idle connection stays
        open through proxies), with one timer for the whole server."""
        while True:
            await asyncio.sleep(seconds)
            for channel in list(self._open.values()):
                for subscriber in channel.subscribers:
                    if not subscriber.wake.is_set():
                        subscriber.beat()

    def wake(self, event_id: str) -> int:
        """Wake every channel of `event_id`; how many there were."""
        woken = [channel for channel in self._open.values() if channel.event_id == event_id]
        for channel in woken:
            channel.wake()
        return len(woken)

    def stop_all(self) -> None:
        for channel in self._open.values():
            channel.stop()
        self._open.clear()
