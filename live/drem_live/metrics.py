"""The live server's open streams as a CloudWatch metric, for scaling on what a task carries (not only its CPU).

With `DREM_LIVE_METRICS_NAMESPACE` set (the stack sets it on AWS), each process prints one line a minute in
CloudWatch's embedded metric format to stdout; the task's log driver ships it to CloudWatch Logs, which extracts the
metric (namespace, dimension `Stage`, `Streams`). Locally nothing is printed.
"""
from __future__ import annotations

import asyncio
import json
import sys
import time
from collections.abc import Callable
from typing import TextIO

from aiohttp import web

INTERVAL_S = 60.0


def emf_line(namespace: str, stage: str, streams: int, now_ms: int) -> str:
    """One embedded-metric-format record (AWS CloudWatch docs, "Specification: Embedded metric format")."""
    return json.dumps({"_aws": {"Timestamp": now_ms, "CloudWatchMetrics": [{
        "Namespace": namespace, "Dimensions": [["Stage"]], "Metrics": [{"Name": "Streams", "Unit": "Count"}]}]},
        "Stage": stage, "Streams": streams}, separators=(",", ":"))


def publish_streams(app: web.Application, namespace: str, stage: str, streams: Callable[[], int], *,
                    out: TextIO = sys.stdout, interval_s: float = INTERVAL_S) -> None:
    """Print the open streams every `interval_s` while `app` runs."""
    async def loop() -> None:
        while True:
            out.write(emf_line(namespace, stage, streams(), int(time.time() * 1000)) + "\n")
            out.flush()
            await asyncio.sleep(interval_s)

    tasks: list[asyncio.Task[None]] = []

    async def start(_app: web.Application) -> None:
        tasks.append(asyncio.get_running_loop().create_task(loop()))

    async def stop(_app: web.Application) -> None:
        for task in tasks:
            task.cancel()

    app.on_startup.append(start)
    app.on_cleanup.append(stop)
