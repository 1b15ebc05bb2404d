"""The live server's camera feeds without a network: a viewer that falls behind gets the newest frame, not a backlog;
a car is wanted exactly while someone watches it, under its device id or the hostname a race names it by."""
from __future__ import annotations

import asyncio
from collections.abc import Callable

from drem_live.video_feeds import Feeds, Sink, looks_like_jpeg
from tests import coroutines

JPEG = b"\xff\xd8\xff\xe0" + b"x" * 10 + b"\xff\xd9"


def test_a_viewer_that_fell_behind_gets_only_the_newest_frame() -> None:
    async def run() -> list[int]:
        feed = Feeds().feed("car-1", "eye-car")
        for taken in (1.0, 2.0, 3.0):  # three frames arrive while the viewer is busy writing
            feed.publish(JPEG, taken)
        first = await feed.next_after(0, 1.0)
        assert first is not None
        nothing = await feed.next_after(first.seq, 0.05)  # nothing newer: it waits, then gives up
        return [first.seq, 0 if nothing is None else nothing.seq]

    assert coroutines.run(run()) == [3, 0]


def test_every_viewer_gets_the_same_bytes_of_a_frame() -> None:
    async def run() -> bool:
        feed = Feeds().feed("car-1")
        waiting = [asyncio.create_task(feed.next_after(0, 2.0)) for _ in range(3)]
        await asyncio.sleep(0)
        feed.publish(JPEG, 5.0)
        frames = await asyncio.gather(*waiting)
        return all(f is frames[0] for f in frames) and frames[0] is not None and JPEG in frames[0].part

    assert coroutines.run(run())


def test_a_car_is_wanted_while_watched_by_its_hostname_or_id() -> None:
    async def run() -> list[bool]:
        feeds = Feeds()
        feeds.feed("car-1", "eye-car")  # the car asked once: its hostname is known
        seen = [feeds.wanted("car-1")]
        feeds.watch("eye-car")  # a race names the car by hostname
        seen.append(feeds.wanted("car-1"))
        seen.append(await feeds.demand_change("car-1", reported=False, timeout_s=5))  # answers at once
        feeds.unwatch("eye-car")
        seen.append(feeds.wanted("car-1"))
        return seen

    assert coroutines.run(run()) == [False, True, True, False]


def test_only_a_whole_jpeg_counts_as_a_frame() -> None:
    assert looks_like_jpeg(JPEG)
    assert not looks_like_jpeg(b"<svg onload=alert(1)>")
    assert not looks_like_jpeg(JPEG[:-2])


class Connection:
    """A viewer's connection as the event loop's transport shows it: what was written, and how much is unsent."""

    def __init__(self, unsent: int = 0) -> None:
        self.unsent, self.written, self.closed = unsent, [], False

    def is_closing(self) -> bool:
        return self.closed

    def get_write_buffer_size(self) -> int:
        return self.unsent

    def write(self, data: bytes) -> None:
        self.written.append(data)

    def close(self) -> None:
        self.closed = True


def test_a_frame_is_written_once_per_viewer_as_one_http_chunk_and_a_stuck_viewer_skips_then_is_dropped() -> None:
    async def run() -> tuple[Connection, Connection, Sink]:
        feed = Feeds().feed("car-1")
        quick, stuck = Connection(), Connection(unsent=10 * 1024 * 1024)
        stuck_sink = Sink(stuck)  # type: ignore[arg-type]
        feed.attach(Sink(quick))  # type: ignore[arg-type]
        feed.attach(stuck_sink)
        feed.publish(JPEG, 1.0)
        stuck_sink.behind_since = 0.0  # it has been behind since long ago
        feed.publish(JPEG, 2.0)
        return quick, stuck, stuck_sink

    quick, stuck, stuck_sink = coroutines.run(run())
    assert len(quick.written) == 2
    size, rest = quick.written[0].split(b"\r\n", 1)
    assert int(size, 16) == len(rest) - 2 and rest.startswith(b"--drem-frame\r\n") and JPEG in rest
    assert stuck.written == [] and stuck.closed and stuck_sink.closed.is_set()


def test_a_viewer_still_taking_its_last_frame_skips_the_next_and_then_gets_the_newest_not_a_backlog() -> None:
    async def run() -> list[bytes]:
        feed = Feeds().feed("car-1")
        slow = Connection(unsent=100)  # the socket has not taken the last 100 bytes of the frame before
        feed.attach(Sink(slow))  # type: ignore[arg-type]
        feed.publish(JPEG, 1.0)
        feed.publish(JPEG, 2.0)
        slow.unsent = 0  # the network took it all
        feed.publish(JPEG, 3.0)
        return slow.written

    written = coroutines.run(run())
    assert len(written) == 1 and b"X-Frame: 3\r\n" in written[0]


def test_a_car_is_wanted_while_another_live_servers_viewers_watch_it_and_not_after_they_stop_saying_so() -> None:
    async def run() -> list[bool]:
        feeds = Feeds()
        feeds.feed("car-1", "eye-car")
        seen = [feeds.wanted("car-1")]
        feeds.watched_by_peer("0123456789abcdef", frozenset({"eye-car"}), ttl_s=60)
        seen.append(feeds.wanted("car-1"))
        feeds.watched_by_peer("0123456789abcdef", frozenset(), ttl_s=60)  # its viewers left
        seen.append(feeds.wanted("car-1"))
        feeds.watched_by_peer("fedcba9876543210", frozenset({"car-1"}), ttl_s=0)  # a peer that went quiet
        seen.append(feeds.wanted("car-1"))
        return seen

    assert coroutines.run(run()) == [False, True, False, False]


def test_a_peers_report_wakes_the_car_waiting_to_hear_it_is_wanted() -> None:
    async def run() -> bool:
        feeds = Feeds()
        feeds.feed("car-1", "eye-car")
        asking = asyncio.create_task(feeds.demand_change("car-1", reported=False, timeout_s=30))
        await asyncio.sleep(0)
        feeds.watched_by_peer("0123456789abcdef", frozenset({"eye-car"}), ttl_s=60)
        async with asyncio.timeout(10):
            return await asking

    assert coroutines.run(run())


def test_a_board_push_due_during_a_frames_fan_out_goes_out_before_the_last_viewers_get_the_frame() -> None:
    async def run() -> tuple[list[str], list[Connection]]:
        feed = Feeds().feed("car-1")
        order: list[str] = []
        viewers = [Connection() for _ in range(200)]
        for number, viewer in enumerate(viewers):
            viewer.write = lambda data, number=number: order.append(f"viewer {number}")  # type: ignore[method-assign]
            feed.attach(Sink(viewer))  # type: ignore[arg-type]
        feed.publish(JPEG, 1.0)
        asyncio.get_running_loop().call_soon(order.append, "board push")  # due while the frame is going out
        await until(lambda: len(order) == 201, 5.0)
        return order, viewers

    order, _ = coroutines.run(run())
    assert sorted(line for line in order if line != "board push") == sorted(f"viewer {n}" for n in range(200))
    assert order.index("board push") < 200  # the push went out before the last of the 200 viewers got the frame


def test_a_newer_frame_overtakes_an_older_ones_fan_out_and_every_viewer_ends_with_the_newest() -> None:
    async def run() -> list[Connection]:
        feed = Feeds().feed("car-1")
        viewers = [Connection() for _ in range(200)]
        for viewer in viewers:
            feed.attach(Sink(viewer))  # type: ignore[arg-type]
        feed.publish(JPEG, 1.0)
        feed.publish(JPEG, 2.0)  # before the first frame reached everyone
        await until(lambda: all(v.written for v in viewers), 5.0)
        for _ in range(20):  # the event loop's next turns: any leftover slice of the first frame runs (writes nothing)
            await asyncio.sleep(0)
        return viewers

    viewers = coroutines.run(run())
    assert all(b"X-Frame: 2" in v.written[-1] for v in viewers)
    assert all(len(v.written) <= 2 for v in viewers)
    assert any(len(v.written) == 1 for v in viewers)  # the last viewers never got the older frame


async def until(condition: Callable[[], bool], timeout_s: float) -> None:
    """Turns of the event loop until `condition` holds; fails after `timeout_s` (a generous bound, not a wait)."""
    async with asyncio.timeout(timeout_s):
        while not condition():
            await asyncio.sleep(0.001)
