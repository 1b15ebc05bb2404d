"""A crowd of MJPEG viewers in one asyncio child process (bench/car_video.py): each opens the live server's car video
(`multipart/x-mixed-replace`, chunked) on its own connection, reads every part, and records how long after the car took
the frame (its X-Timestamp) the part arrived, and the longest gap between two frames (a stall)."""
from __future__ import annotations

import asyncio
import random
import time
from typing import Any
from urllib.parse import urlsplit


async def _viewer(url: str, stop: Any, stats: dict[str, Any], rng: random.Random, spread_s: float) -> None:
    await asyncio.sleep(rng.uniform(0, spread_s))  # arrive spread out, not as one burst
    parts = urlsplit(url)
    try:
        reader, writer = await asyncio.open_connection(parts.hostname, parts.port)
        writer.write(f"GET {parts.path}?{parts.query} HTTP/1.1\r\nHost: {parts.netloc}\r\n\r\n".encode())
        head = await reader.readuntil(b"\r\n\r\n")
        status = int(head.split(b" ", 2)[1])
        if status != 200:
            raise ValueError(f"status {status}")
        stats["connected"] += 1
        last_arrival = None
        while not stop.is_set():
            # The live server writes each MJPEG part as one HTTP chunk (live/drem_live/video_feeds.py, Frame.chunk),
            # so a chunk is read whole and only its part's headers are parsed: the stand-in's own CPU stays small.
            size = int((await reader.readuntil(b"\r\n")).strip(), 16)  # chunked transfer encoding
            if size == 0:
                raise ValueError("the server ended the stream")
            chunk = await reader.readexactly(size + 2)
            head_end = chunk.find(b"\r\n\r\n", 0, 512)
            if head_end < 0:
                raise ValueError("a chunk that does not start with an MJPEG part's headers")
            fields = dict(line.split(b": ", 1) for line in chunk[:head_end].split(b"\r\n")[1:] if b": " in line)
            if int(fields[b"Content-Length"]) != size - head_end - 4 - 2:
                raise ValueError("a chunk that is not one whole MJPEG part")
            now = time.time()
            stats["delays_ms"].append((now - float(fields[b"X-Timestamp"])) * 1000)
            if last_arrival is not None:
                stats["max_gap_s"] = max(stats["max_gap_s"], now - last_arrival)
                if now - last_arrival > 1.0:
                    stats["stalls"] += 1
            last_arrival = now
            stats["frames"] += 1
        writer.close()
    except (OSError, asyncio.IncompleteReadError, ValueError, KeyError) as exc:
        if not stop.is_set():
            stats["errors"].append(repr(exc))


async def _crowd(url: str, viewers: int, stop: Any, connected: Any) -> dict[str, Any]:
    stats: dict[str, Any] = {"connected": 0, "frames": 0, "stalls": 0, "max_gap_s": 0.0, "delays_ms": [],
                             "errors": [], "starved_s": 0.0}
    rng = random.Random(35)
    tasks = [asyncio.create_task(_viewer(url, stop, stats, rng, 3.0)) for _ in range(viewers)]
    while not stop.is_set():
        # How late this process's own loop wakes: at SCHED_IDLE on a busy shared machine the stand-in itself may get no
        # CPU for a while, and a viewer's gap then is the stand-in's, not the live server's (printed beside stalls).
        asked = time.monotonic()
        await asyncio.sleep(0.1)
        stats["starved_s"] = max(stats["starved_s"], time.monotonic() - asked - 0.1)
        if connected is not None:
            connected.value = stats["connected"]
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    return stats


def run_crowd(url: str, viewers: int, stop: Any, queue: Any, connected: Any = None) -> None:
    """Child process entry: watch until `stop` is set, then put the stats (delays sampled down to 20 000) on `queue`;
    `connected` (a shared integer, if given) counts the viewers connected so far.
    The viewers stand in for 500 other machines (phones, OBS PCs), so here they run SCHED_IDLE (bench/_placement.py):
    only on CPU time that what does run on the event laptop (the live server, the app) does not want, and never on
    the car's core."""
    import os

    from bench import _placement

    os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    if _placement.two_cores():
        os.sched_setaffinity(0, _placement.STAND_IN_CORES)
    stats = asyncio.run(_crowd(url, viewers, stop, connected))
    delays = stats["delays_ms"]
    step = max(1, len(delays) // 20_000)
    stats["delays_ms"] = delays[::step]
    queue.put(stats)
