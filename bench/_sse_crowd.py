"""A crowd of spectators for bench/live_latency.py with the live server: N event-stream subscribers (half the
leaderboard's stream, half the overlay's, the URLs the pages themselves subscribe to) in one asyncio child process,
each over its own HTTP/1.1 connection with `Accept-Encoding: gzip` as browsers send it. Each subscriber decodes its
own gzip stream and checks that the version tokens it is sent never go backwards (the rule live.js applies,
chalicelib.views.live_regions.token_is_newer). `run_crowd` returns its figures through a queue when `stop` is set.
"""
from __future__ import annotations

import asyncio
import os
import random
import sys
import time
import zlib
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "functions"))


async def _subscriber(url: str, stop: Any, stats: dict[str, Any], rng: random.Random, spread_s: float) -> None:
    from chalicelib.views.live_regions import token_is_newer

    await asyncio.sleep(rng.uniform(0, spread_s))  # arrive spread out, not as one burst
    parts = urlsplit(url)
    try:
        reader, writer = await asyncio.open_connection(parts.hostname, parts.port)
        writer.write((f"GET {parts.path}?{parts.query} HTTP/1.1\r\nHost: {parts.netloc}\r\n"
                      "Accept: text/event-stream\r\nAccept-Encoding: gzip\r\n\r\n").encode())
        head = await reader.readuntil(b"\r\n\r\n")
        status = int(head.split(b" ", 2)[1])
        if status != 200:
            raise ValueError(f"status {status}")
        stats["connected"] += 1
        decoder = zlib.decompressobj(16 + zlib.MAX_WBITS)
        text, last = b"", None
        while not stop.is_set():
            size_line = await reader.readuntil(b"\r\n")  # chunked transfer encoding
            size = int(size_line.strip(), 16)
            if size == 0:
                raise ValueError("the server ended the stream")
            chunk = await reader.readexactly(size + 2)
            text += decoder.decompress(chunk[:-2])
            while b"\n\n" in text:
                message, text = text.split(b"\n\n", 1)
                if not message.startswith(b"id: "):
                    continue
                token = message[4:message.index(b"\n")].decode()
                stats["messages"] += 1
                now = time.time()
                seen = stats["arrivals"].setdefault(token, [now, now])  # first and last viewer to get it
                seen[1] = now
                if last is not None and not token_is_newer(token, last):
                    stats["backwards"] += 1
                last = token
        writer.close()
    except (OSError, asyncio.IncompleteReadError, ValueError) as exc:
        if not stop.is_set():
            stats["errors"].append(repr(exc))


async def _crowd(urls: list[str], spectators: int, stop: Any) -> dict[str, Any]:
    stats: dict[str, Any] = {"connected": 0, "messages": 0, "backwards": 0, "errors": [], "arrivals": {}}
    rng = random.Random(11)
    tasks = [asyncio.create_task(_subscriber(urls[i % len(urls)], stop, stats, rng, 2.0)) for i in range(spectators)]
    started = time.monotonic()
    while not stop.is_set():
        await asyncio.sleep(0.1)
    await asyncio.sleep(0.2)
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    stats["seconds"] = time.monotonic() - started
    return stats


def run_crowd(urls: list[str], spectators: int, stop: Any, queue: Any, idle: bool = False) -> None:
    """`idle`: run at SCHED_IDLE, as the stand-in for phones that are other machines than the laptop (they take only
    CPU time the laptop's own processes do not want)."""
    if idle:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    stats = asyncio.run(_crowd(urls, spectators, stop))
    stats["first_error"] = stats["errors"][0] if stats["errors"] else ""
    stats["errors"] = len(stats["errors"])
    queue.put(stats)
