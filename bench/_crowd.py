"""A crowd of spectators for bench/live_latency.py: N keep-alive HTTP/1.1 connections in one asyncio process, each
polling a page's live fragment with the version token IT holds (`&v=`, replaced from each 200's `data-version`),
every `interval` (uniform in [0.5, 1.5] x the pages' period). Unlike wrk, whose Lua state is per thread, every
connection keeps its own token, so after a change each spectator gets its own 200 as real browsers would.

Runs in a child process (spawned) so it shares no interpreter lock with the browser driver; `run_crowd` returns its
figures through a queue when `stop` is set.
"""
from __future__ import annotations

import asyncio
import random
import re
import time
from typing import Any

_VERSION = re.compile(rb'data-version="([^"]+)"')


async def _spectator(host: str, port: int, path: str, token: str, period_s: float, stop: Any,
                     stats: dict[str, Any], rng: random.Random) -> None:
    await asyncio.sleep(rng.uniform(0, period_s))  # arrive spread out, not as one burst
    reader, writer = await asyncio.open_connection(host, port)
    try:
        while not stop.is_set():
            request = (f"GET {path}&v={token} HTTP/1.1\r\nHost: {host}:{port}\r\nHX-Request: true\r\n"
                       "Accept: text/html\r\n\r\n").encode()
            started = time.perf_counter()
            writer.write(request)
            head = await reader.readuntil(b"\r\n\r\n")
            status = int(head.split(b" ", 2)[1])
            length = re.search(rb"(?im)^content-length:\s*(\d+)", head)
            body = await reader.readexactly(int(length.group(1))) if length else b""
            stats["latencies_ms"].append((time.perf_counter() - started) * 1000)
            stats["statuses"][status] = stats["statuses"].get(status, 0) + 1
            if status == 200 and (found := _VERSION.search(body)):
                token = found.group(1).decode()
            await asyncio.sleep(rng.uniform(0.5 * period_s, 1.5 * period_s))
    except (OSError, asyncio.IncompleteReadError, ValueError) as exc:
        stats["errors"].append(repr(exc))
    finally:
        writer.close()


async def _crowd(host: str, port: int, fragments: list[tuple[str, str]], size: int, period_s: float,
                 stop: Any) -> dict[str, Any]:
    stats: dict[str, Any] = {"latencies_ms": [], "statuses": {}, "errors": []}
    rng = random.Random(size)
    started = time.perf_counter()
    tasks = [asyncio.create_task(_spectator(host, port, *fragments[i % len(fragments)], period_s, stop, stats, rng))
             for i in range(size)]
    await asyncio.gather(*tasks)
    stats["seconds"] = time.perf_counter() - started
    return stats


class _ThreadsafeFlag:
    """The multiprocessing Event, polled without blocking the event loop."""

    def __init__(self, event: Any) -> None:
        self._event = event

    def is_set(self) -> bool:
        return self._event.is_set()


def run_crowd(host: str, port: int, fragments: list[tuple[str, str]], size: int, period_s: float, stop: Any,
              results: Any) -> None:
    stats = asyncio.run(_crowd(host, port, fragments, size, period_s, _ThreadsafeFlag(stop)))
    latencies = sorted(stats["latencies_ms"])
    count = len(latencies)
    results.put({
        "polls": count, "rate": count / stats["seconds"] if stats["seconds"] else 0.0,
        "p50_ms": latencies[count // 2] if count else 0.0,
        "p99_ms": latencies[min(count - 1, int(count * 0.99))] if count else 0.0,
        "s200": stats["statuses"].get(200, 0), "s204": stats["statuses"].get(204, 0),
        "other": sum(n for s, n in stats["statuses"].items() if s not in (200, 204)),
        "errors": len(stats["errors"]), "first_error": stats["errors"][0] if stats["errors"] else "",
    })
