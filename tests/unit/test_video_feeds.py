"""The live server's camera feeds without a network: a viewer that falls behind gets the newest frame, not a backlog;
a car is wanted exactly while someone watches it, under its device id or the hostname a race names it by."""
from __future__ import annotations

import asyncio

from drem_live.video_feeds import Feeds, looks_like_jpeg

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

    assert asyncio.run(run()) == [3, 0]


def test_every_viewer_gets_the_same_bytes_of_a_frame() -> None:
    async def run() -> bool:
        feed = Feeds().feed("car-1")
        waiting = [asyncio.create_task(feed.next_after(0, 2.0)) for _ in range(3)]
        await asyncio.sleep(0)
        feed.publish(JPEG, 5.0)
        frames = await asyncio.gather(*waiting)
        return all(f is frames[0] for f in frames) and frames[0] is not None and JPEG in frames[0].part

    assert asyncio.run(run())


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

    assert asyncio.run(run()) == [False, True, True, False]


def test_only_a_whole_jpeg_counts_as_a_frame() -> None:
    assert looks_like_jpeg(JPEG)
    assert not looks_like_jpeg(b"<svg onload=alert(1)>")
    assert not looks_like_jpeg(JPEG[:-2])
