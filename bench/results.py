"""Bench: printed results and statistics, each beside the plain leaderboard page on the same data.

In one process, against moto in memory (the storage the unit tests use) with the real app through Chalice's test
client, so the figures are the app's own work (reads, ranking, rendering) without HTTP or disk noise:

1. a 200-racer event: the race summary PDF and the 200 certificates (`GET /api/events/{id}/results/…`), and the
   event's big-screen leaderboard page (`GET /leaderboard/{id}`);
2. 50 events / 5,000 submitted races: `GET /stats` from a cold cache (the world map's shapes and every per-process
   cache cleared first), and the leaderboard page of one of those events.

Goals (issue 15): summary <= 2 s, certificates <= 10 s, stats <= 1 s. Each figure is the median of 3 runs (the stats
cold run is repeated with the caches cleared each time). Ends with a RESULT line.
"""
from __future__ import annotations

import os
import re
import statistics
import sys
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "functions"))

RACERS = 200
EVENTS = 50
RACES_PER_EVENT = 100
RUNS = 3
STAGE = "bench"
REGION = "us-east-1"
GOALS = {"summary": 2.0, "certificates": 10.0, "stats": 1.0}


def median_seconds(action: Callable[[], Any], before: Callable[[], None] = lambda: None) -> float:
    times = []
    for _ in range(RUNS):
        before()
        started = time.perf_counter()
        action()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def submitted_race(event_id: str, index: int, sub: str, username: str, config: Any, start_ms: int) -> Any:
    from drem_leaderboard import race_machine
    from drem_leaderboard.commands import parse_command
    from drem_leaderboard.models import Racer, new_race

    race = new_race(race_id=uuid.uuid4().hex, event_id=event_id, track_id="1",
                    racer=Racer(sub=sub, username=username), config=config, now_ms=start_ms)
    now = start_ms
    for kind, step in (("start", 0), ("capture_lap", 9_000 + index * 7 % 2_000), ("capture_lap",
                                                                                  8_800 + index * 13 % 1_500),
                       ("capture_lap", 9_100 + index * 3 % 900), ("end", 0), ("submit", 0)):
        now += step
        race, _ = race_machine.apply(race, parse_command({"kind": kind}), now)
    return race


def seed(dynamodb: Any, events: int, races_per_event: int, countries: list[str]) -> list[str]:
    from datetime import date, timedelta

    from chalicelib.domain.events import Event, EventType, Track
    from chalicelib.domain.races import RaceRecord
    from chalicelib.settings import get_settings
    from chalicelib.storage.events import DynamoEventStore
    from chalicelib.storage.races import _race_item
    from drem_leaderboard.models import RaceConfig

    settings = get_settings()
    store, table = DynamoEventStore(dynamodb, settings.table("events")), settings.table("races")
    ids, config = [], RaceConfig(min_lap_ms=0, debounce_ms=0)
    for number in range(events):
        event = Event(event_id=uuid.uuid4().hex[:12], name=f"Bench Cup {number}", event_type=EventType.AWS_SUMMIT,
                      date=date(2026, 1, 1) + timedelta(days=7 * number),
                      country_code=countries[number % len(countries)],
                      sponsor="", race_config=config, tracks=(Track(track_id="1"),), landing_page_links=(),
                      created_at_ms=0, created_by="bench", updated_at_ms=0)
        store.create(event)
        for index in range(races_per_event):
            race = submitted_race(event.event_id, index, f"sub-{number}-{index}", f"racer_{number}_{index}", config,
                                  1_800_000_000_000 + index * 600_000)
            dynamodb.put_item(TableName=table, Item=_race_item(RaceRecord(race=race, created_by="bench")))
        ids.append(event.event_id)
    return ids


def stats_without_storage(ids: list[str]) -> None:
    """The /stats work after the reads: aggregate the digests of 5,000 races, draw the charts and the map, render the
    page. The events and digests are read once and kept (module global), so this times drem's own code only."""
    from chalicelib import services
    from chalicelib.domain.stats import ShownRacer, StatsFilter, compute, visible_events
    from chalicelib.views.stats_view import stats_page
    from drem_web import render

    global _READ
    if _READ is None:
        _READ = services.stats_digests().for_events(visible_events(services.event_store().list(), staff=False))
    stats = compute(_READ, StatsFilter(), lambda sub, username: ShownRacer(username))
    render.render_page("stats", htmx=False, view=stats_page(stats, StatsFilter(), staff=False))


_READ: Any = None


def main() -> int:
    from chalice.test import Client
    from moto import mock_aws

    from drem_local.bootstrap import clients_for, ensure_stack

    os.environ.update({"AWS_DEFAULT_REGION": REGION, "AWS_ACCESS_KEY_ID": "testing",
                       "AWS_SECRET_ACCESS_KEY": "testing"})
    with mock_aws():
        outputs = ensure_stack(clients_for(None, REGION), STAGE)
        os.environ.update(outputs.to_env())
        from app import app

        from chalicelib import services
        from chalicelib.formats import pdf_fonts
        from chalicelib.settings import get_settings
        from chalicelib.storage import clients
        from chalicelib.views import world_map
        from chalicelib.views.render_cache import LIVE_FRAGMENTS, LIVE_RACES

        get_settings.cache_clear()
        dynamodb = clients.dynamodb()
        with Client(app, project_dir=str(ROOT / "bench")) as client:
            # --- 200-racer event ------------------------------------------------------------------------------
            [big] = seed(dynamodb, 1, RACERS, ["SE"])
            services.race_service().recompute(big, by="bench")
            from chalicelib.routes.results import load_results
            from chalicelib.views.results_pdf import render_document

            def pdf(file_name: str) -> bytes:
                body = render_document(load_results(big), file_name, None)
                assert body.startswith(b"%PDF")
                return body

            def leaderboard(event_id: str) -> None:
                reply = client.http.get(f"/leaderboard/{event_id}", headers={"Accept": "text/html"})
                assert reply.status_code == 200, reply.status_code

            def cold() -> None:
                world_map.country_shapes.cache_clear()
                pdf_fonts.main_coverage.cache_clear()
                pdf_fonts.font_path.cache_clear()
                for cache in (LIVE_FRAGMENTS, LIVE_RACES):
                    getattr(cache, "clear", lambda: None)()

            summary_s = median_seconds(lambda: pdf("summary.pdf"), cold)
            certificates_s = median_seconds(lambda: pdf("certificates.pdf"), cold)
            loaded = load_results(big)  # the same documents from standings already read: rendering alone
            summary_render_s = median_seconds(lambda: render_document(loaded, "summary.pdf", None), cold)
            certificates_render_s = median_seconds(lambda: render_document(loaded, "certificates.pdf", None), cold)
            board_200_s = median_seconds(lambda: leaderboard(big))
            pages = len(re.findall(rb"/Type\s*/Page\b(?!s)", pdf("certificates.pdf")))

            # --- 50 events / 5,000 races ------------------------------------------------------------------------
            many = seed(dynamodb, EVENTS - 1, RACES_PER_EVENT, ["SE", "US", "JP", "DE", "BR", "AU", "GB", "IN"])
            services.race_service().recompute(many[0], by="bench")
            # The races were written straight into storage, so build each event's statistics digest the way the app
            # does when a race is submitted (timed: what one submit costs on top, times the 50 events).
            started = time.perf_counter()
            for event_id in [big, *many]:
                services.stats_digests().refresh(event_id)
            digests_s = time.perf_counter() - started

            def stats_page() -> None:
                reply = client.http.get("/stats", headers={"Accept": "text/html"})
                assert reply.status_code == 200 and b"stats-world-map" in reply.body, reply.status_code

            stats_s = median_seconds(stats_page, cold)
            board_stats_s = median_seconds(lambda: leaderboard(many[0]))
            stats_compute_s = median_seconds(lambda: stats_without_storage(ids=[big, *many]), cold)

    print(f"200-racer event:      summary.pdf {summary_s:.2f} s (rendering {summary_render_s:.2f} s) · "
          f"certificates.pdf ({pages} pages) {certificates_s:.2f} s (rendering {certificates_render_s:.2f} s) · "
          f"leaderboard page {board_200_s * 1000:.0f} ms")
    print(f"{EVENTS} events, {EVENTS * RACES_PER_EVENT} races: /stats cold {stats_s:.2f} s "
          f"(without the storage reads {stats_compute_s:.2f} s) · leaderboard page {board_stats_s * 1000:.0f} ms")
    print(f"Statistics digests: {len(many) + 1} events rebuilt in {digests_s:.2f} s "
          f"({digests_s / (len(many) + 1) * 1000:.0f} ms each: what a submit adds). Storage is moto in process; /stats "
          "reads the events and one digest per event (BatchGetItem); see docs/results.md.")
    met = summary_s <= GOALS["summary"] and certificates_s <= GOALS["certificates"] and stats_s <= GOALS["stats"]
    print(f"RESULT results: summary={summary_s:.2f}s certificates={certificates_s:.2f}s stats_cold={stats_s:.2f}s "
          f"stats_without_reads={stats_compute_s:.2f}s (leaderboard page {board_200_s * 1000:.0f}ms / "
          f"{board_stats_s * 1000:.0f}ms) | goal summary<=2s "
          f"certificates<=10s stats<=1s | {'met' if met else 'not met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
