"""How much does the public leaderboard read cost over the single GetItem it needs?

Starts a durable moto server and the app server as subprocesses (`bench/_stack.py`), materialises a
50-racer board and a 5,000-racer board (stored in pages and state parts) through the real publisher, then, for each,
interleaved in one run, times
  - handler: `GET /api/leaderboard/{eventId}?track=1` over HTTP (keep-alive) to the app server (the first page), and
  - getitem: boto3 `GetItem` of the same board item against the same moto server.
Goals: at 50 racers handler median <= 2x getitem median; at 5,000 racers the handler adds <= 20 ms to the GetItem.

    .venv/bin/python bench/read_overhead.py [--requests 400]
"""
from __future__ import annotations

import argparse
import http.client
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bench import _stack  # noqa: E402

SIZES = (50, 5_000)


def percentile(samples: list[float], pct: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(round(pct / 100 * (len(ordered) - 1))))]


def measure(app_port: int, storage_url: str, env: dict[str, str], requests: int,
            event_id: str) -> tuple[list[float], list[float]]:
    from drem_infra.resources import table_name
    from drem_local.storage_keys import StorageKeys, local_client

    # The app's own storage keys (drem_local.stack.app_environment puts them in its environment).
    keys = StorageKeys(env["AWS_ACCESS_KEY_ID"], env["AWS_SECRET_ACCESS_KEY"])
    dynamodb = local_client("dynamodb", storage_url, keys)
    key = {"pk": {"S": f"EVENT#{event_id}"}, "sk": {"S": "BOARD#1"}}
    table = table_name(env.get("DREM_STAGE", "local"), "leaderboards")
    connection = http.client.HTTPConnection("127.0.0.1", app_port, timeout=10)
    path = f"/api/leaderboard/{event_id}?track=1"

    def via_handler() -> None:
        connection.request("GET", path, headers={"Accept": "application/json"})
        reply = connection.getresponse()
        body = reply.read()
        if reply.status != 200 or b'"entries"' not in body:
            raise SystemExit(f"leaderboard read failed: {reply.status} {body[:200]!r}")

    def via_getitem() -> None:
        item = dynamodb.get_item(TableName=table, Key=key, ProjectionExpression="version, etag, body")["Item"]
        if "body" not in item:
            raise SystemExit("board item has no body")

    for _ in range(30):  # warm both paths (connections, imports, caches)
        via_handler()
        via_getitem()
    handler_ms, getitem_ms = [], []
    for _ in range(requests):
        for fn, samples in ((via_handler, handler_ms), (via_getitem, getitem_ms)):
            started = time.perf_counter()
            fn()
            samples.append((time.perf_counter() - started) * 1000)
    connection.close()
    return handler_ms, getitem_ms


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--requests", type=int, default=400)
    args = parser.parse_args(argv)

    measured: dict[int, tuple[list[float], list[float]]] = {}
    with _stack.bench_stack() as stack:
        for racers in SIZES:
            _stack.seed_board(stack.env, f"bench-{racers}", racers)
        for racers in SIZES:
            measured[racers] = measure(stack.port, stack.storage_url, stack.env, args.requests, f"bench-{racers}")

    figures, verdicts = [], []
    for racers, (handler_ms, getitem_ms) in measured.items():
        h_med, g_med = statistics.median(handler_ms), statistics.median(getitem_ms)
        print(f"board of {racers} racers, {args.requests} requests each (interleaved)")
        print(f"  handler  median {h_med:.2f} ms  p95 {percentile(handler_ms, 95):.2f} ms")
        print(f"  getitem  median {g_med:.2f} ms  p95 {percentile(getitem_ms, 95):.2f} ms")
        print(f"  ratio {h_med / g_med:.2f}x, added {h_med - g_med:.2f} ms")
        if racers == SIZES[0]:
            figures.append(f"{racers}: handler={h_med:.2f}ms getitem={g_med:.2f}ms ratio={h_med / g_med:.2f}x")
            verdicts.append(h_med / g_med <= 2.0)
        else:
            figures.append(f"{racers}: handler={h_med:.2f}ms getitem={g_med:.2f}ms added={h_med - g_med:.2f}ms")
            verdicts.append(h_med - g_med <= 20.0)
    verdict = "met" if all(verdicts) else "not met"
    print(f"RESULT read_overhead: {'; '.join(figures)} | goal <=2x at {SIZES[0]}, <=20ms added at {SIZES[1]} | "
          f"{verdict}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
