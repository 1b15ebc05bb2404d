"""How much does the public leaderboard read cost over the single GetItem it needs?

Starts a durable moto server and the app server as subprocesses (like `tests/stack_fixtures.py`), materialises a
50-racer board through the real publisher, then, interleaved in one run, times
  - handler: `GET /api/leaderboard/{eventId}?track=1` over HTTP (keep-alive) to the app server, and
  - getitem: boto3 `GetItem` of the same board item against the same moto server.
Goal: handler median <= 2x getitem median.

    .venv/bin/python bench/read_overhead.py [--requests 400]
"""
from __future__ import annotations

import argparse
import http.client
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "functions"))

EVENT_ID = "bench-event"
RACERS = 50


def serve(port: int) -> None:
    """App-server mode: the real app, plus the leaderboard blueprint if app.py does not register it yet."""
    import app as app_module
    from chalicelib.routes import leaderboards
    from drem_local.appserver import make_server

    if "/api/leaderboard/{event_id}" not in app_module.app.routes:
        app_module.app.register_blueprint(leaderboards.bp)
    make_server("127.0.0.1", port).serve_forever()


def seed_board(env: dict[str, str]) -> None:
    """A realistic board: 50 racers with three submitted laps each, ranked and written by the real publisher."""
    import os

    os.environ.update(env)
    from chalicelib.domain.leaderboards import BoardRow, LeaderboardPublisher
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from chalicelib.storage.leaderboards import DynamoBoardStore
    from drem_leaderboard.models import Lap, LapSource, RaceConfig, RaceStatus, Racer, new_race
    from drem_leaderboard.ranking import RacerProfile
    from drem_leaderboard.summary import summarise_racer

    get_settings.cache_clear()
    publisher = LeaderboardPublisher(DynamoBoardStore(clients.dynamodb(), get_settings().table("leaderboards")),
                                     lambda: int(time.time() * 1000))
    rows = []
    for index in range(RACERS):
        racer = Racer(sub=f"sub-{index:03d}", username=f"racer{index:03d}")
        laps = tuple(Lap(lap_id=i, time_ms=9_000 + 37 * index + 101 * i, is_valid=True, source=LapSource.MANUAL,
                         captured_at_ms=1_000 + i) for i in range(3))
        race = new_race(race_id=f"race-{index}", event_id=EVENT_ID, track_id="1", racer=racer, config=RaceConfig(),
                        now_ms=1).model_copy(update={"laps": laps, "status": RaceStatus.SUBMITTED,
                                                     "submitted_at_ms": 2_000})
        summary = summarise_racer([race])
        assert summary is not None
        rows.append(BoardRow(summary=summary, profile=RacerProfile(username=racer.username, country_code="SE")))
    publisher.rebuild(EVENT_ID, {"1": rows}, RaceConfig().ranking_method, ["1"])


def percentile(samples: list[float], pct: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(round(pct / 100 * (len(ordered) - 1))))]


def measure(app_port: int, storage_url: str, env: dict[str, str], requests: int) -> tuple[list[float], list[float]]:
    import boto3
    from botocore.config import Config

    from drem_infra.resources import table_name

    dynamodb = boto3.session.Session(region_name="us-east-1", aws_access_key_id="testing",
                                      aws_secret_access_key="testing").client(
        "dynamodb", endpoint_url=storage_url, config=Config(account_id_endpoint_mode="disabled"))
    key = {"pk": {"S": f"EVENT#{EVENT_ID}"}, "sk": {"S": "BOARD#1"}}
    table = table_name(env.get("DREM_STAGE", "local"), "leaderboards")
    connection = http.client.HTTPConnection("127.0.0.1", app_port, timeout=10)
    path = f"/api/leaderboard/{EVENT_ID}?track=1"

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
    parser.add_argument("--serve", type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve is not None:
        serve(args.serve)
        return 0

    from drem_local import stack as local_stack

    with tempfile.TemporaryDirectory(prefix="drem-bench-") as tmp:
        config = local_stack.StackConfig(state_dir=Path(tmp) / "state", app_port=local_stack.free_port(),
                                         storage_port=local_stack.free_port())
        config.state_dir.mkdir(parents=True)
        storage = local_stack.start_storage(config, timeout=60)
        app: Any = None
        try:
            outputs, _admin = local_stack.bootstrap(config, "admin", None)
            env = local_stack.app_environment(config, outputs)
            app = local_stack.spawn("app server", [sys.executable, str(Path(__file__).resolve()), "--serve",
                                                   str(config.app_port)], config.log_dir / "app.log", env=env)
            local_stack.wait_for_ok(config.app_url + local_stack.APP_HEALTH_PATH, app, 60)
            seed_board(env)
            handler_ms, getitem_ms = measure(config.app_port, config.storage_url, env, args.requests)
        finally:
            if app is not None:
                app.stop(10)
            storage.stop(30)

    h_med, g_med = statistics.median(handler_ms), statistics.median(getitem_ms)
    ratio = h_med / g_med
    print(f"requests each: {args.requests} (interleaved), board of {RACERS} racers")
    print(f"handler  median {h_med:.2f} ms  p95 {percentile(handler_ms, 95):.2f} ms")
    print(f"getitem  median {g_med:.2f} ms  p95 {percentile(getitem_ms, 95):.2f} ms")
    print(f"p95 ratio {percentile(handler_ms, 95) / percentile(getitem_ms, 95):.2f}x")
    verdict = "met" if ratio <= 2.0 else "not met"
    print(f"RESULT read_overhead: handler={h_med:.2f}ms getitem={g_med:.2f}ms ratio={ratio:.2f}x | goal <=2x | "
          f"{verdict}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
