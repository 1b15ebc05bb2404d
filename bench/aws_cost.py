"""What one event day of live pages costs on AWS: today's polling design against the push design (issue 14).

Profile: 2,000 spectators for 8 hours, 4 tracks, a lap every 2 s on each track; spectators spread over each track's
big screen and stream overlay and everyone's phones (the phones spread evenly over the tracks' boards).

(a) polling: every spectator asks CloudFront -> API Gateway -> Lambda every 500 ms (204 while nothing changed, the
    fragment when it did), each Lambda read going to DynamoDB unless the instance's 250 ms cache has it.
(b) push: CloudFront carries page loads and one Server-Sent-Events request per (re)connection to the live server on
    Fargate behind an ALB; each update is gzipped once and delivered to every viewer of its channel (data transfer
    out), the server reads DynamoDB on a fixed poll per channel whatever the number of viewers, per task: the writer
    wakes the tasks (each board or overlay write POSTs the event id through CloudFront to one task, which relays it to
    the others: drem_live.wake_route), so the poll is only the fallback, every drem_live WOKEN_POLL_MS (250 ms).
Both pay the same non-live traffic (page HTML through API Gateway + Lambda, the timers' laps, the staff consoles) and
the same DynamoDB writes and writer reads per lap (the race transaction, the track board, the combined board and the
overlay, each read consistently before it is rewritten: `lap_writes`). Tasks: spectators / the live pages' scaling
target per task (drem_infra.live_pages.STREAMS_TARGET_PER_TASK: 80 % of the measured capacity of the task's 0.5 vCPU,
from `bench/live_latency.py --capacity`).

The message sizes are measured, not guessed: a 50-racer board and a racing overlay are built by the real publisher,
rendered by the live-region builders (chalicelib.views.live_regions, shared by the app and the live server) and
gzipped one message at a time as the live server does. The request model is pure arithmetic over the profile
(tests/unit/test_aws_cost.py checks it counts what the profile implies). Free tiers are ignored, tiered prices use
their first tier (the 2,000-spectator profile stays inside it; far larger crowds are overestimated), and fixed
infrastructure is charged for the whole 24-hour day that
holds the event (the stack stays deployed).

List prices, us-east-1 (CloudFront: United States edge), read on 2026-11-24 through the search tool:
- API Gateway REST $3.50 per million (first 333 M/month): docs.aws.amazon.com/whitepapers/latest/
  best-practices-api-gateway-private-apis-integration/cost-optimization.html (Table 4);
  aws.amazon.com/api-gateway/pricing
- Lambda $0.20 per million requests, $0.0000166667 per GB-second (x86): docs.aws.amazon.com/whitepapers/latest/
  how-aws-pricing-works/lambda.html; cloudchipr.com/blog/aws-lambda-pricing
- DynamoDB on-demand $0.125 per million read request units: airbyte.com/data-engineering-resources/dynamodb-pricing
  (the January 2025 on-demand price cut: aws.amazon.com/blogs/aws/amazon-dynamodb-on-demand-no-capacity-planning-and-
  pay-per-request-pricing); an eventually consistent read of up to 4 KB is half a unit, a strongly consistent one one.
- DynamoDB on-demand $0.625 per million write request units (same source); a write of up to 1 KB is one unit, a
  transactional write two (aws.amazon.com/dynamodb/pricing/provisioned, "Key terms", read through a mirror).
- CloudFront data transfer out $0.085 per GB (first 10 TB, United States): aws.amazon.com/cloudfront/pricing;
  HTTPS requests $0.0100 per 10,000 (HTTP $0.0075): same page's request table, and github.com/vreutova/
  infracost-idem-support/pull/15 (infracost's CloudFront rates); origin fetches from an ALB are free (same page).
- Application Load Balancer $0.0225 per hour, $0.008 per LCU-hour; one LCU = 25 new connections/s, 3,000 active
  connections, 1 GB processed per hour (EC2/IP targets) or 1,000 rule evaluations/s, whichever is highest:
  cloud-horizons.com/blog/alb-the-line-item-nobody-watches (May 2026), handbook.vantage.sh/aws/services/elb-pricing
- Fargate Linux/x86 $0.04048 per vCPU-hour, $0.004445 per GB-hour: vantage.sh/blog/fargate-pricing;
  factualminds.com/blog/amazon-fargate-ecs-task-pricing-2026 (June 2026)
- Public IPv4 addresses $0.005 per hour each (each task has one; the internal ALB none): nwobodo.me/notes/
  aws-extra-ipv4-cost-per-hour; vishalvyas.com/understand-aws-public-ipv4-address-usage-and-pricing

Goals (issue #34): push <= $20 per 8-hour day at 2,000 spectators and <= $100 at 20,000.
Run: .venv/bin/python bench/aws_cost.py [--spectators N,N] [--hours H]
"""
from __future__ import annotations

import argparse
import gzip
import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path

from drem_infra import live_pages

ROOT = Path(__file__).resolve().parent.parent
REGION = "us-east-1"
PRICES_READ_ON = "2026-11-24"
GOALS_DOLLARS = {2_000: 20.0, 20_000: 100.0}
# How many streams the stack's scaling puts on one live task: derived from the measured per-process capacity.
STREAMS_TARGET_PER_TASK = live_pages.STREAMS_TARGET_PER_TASK
GB = 1_000_000_000


@dataclass(frozen=True)
class Prices:
    api_gateway_per_million: float = 3.50
    lambda_per_million: float = 0.20
    lambda_per_gb_second: float = 0.0000166667
    dynamodb_per_million_rru: float = 0.125
    dynamodb_per_million_wru: float = 0.625
    cloudfront_per_10k_https: float = 0.0100
    cloudfront_per_gb_out: float = 0.085
    alb_per_hour: float = 0.0225
    alb_per_lcu_hour: float = 0.008
    fargate_per_vcpu_hour: float = 0.04048
    fargate_per_gb_hour: float = 0.004445
    public_ipv4_per_hour: float = 0.005


@dataclass(frozen=True)
class Profile:
    spectators: int = 2_000
    hours: float = 8.0
    tracks: int = 4
    lap_every_s: float = 2.0
    poll_every_s: float = 0.5  # today's live regions
    screens_per_track: int = 1  # the big-screen leaderboard
    overlays_per_track: int = 1  # the OBS stream overlay
    # How often a viewer's stream is (re)opened: phones sleep, walk out of WiFi and back; screens rarely.
    phone_reconnect_every_s: float = 600.0
    screen_reconnect_every_s: float = 3_600.0
    phone_page_loads: int = 2  # the event page once, the board once more later (a reload, a second track)
    static_files_per_page: int = 7  # CSS, JS, favicon, fonts, the event's logo: CloudFront cache hits (requests only)
    heartbeat_every_s: float = 15.0
    # The live server re-reads each channel's items on this fixed poll (per task, whatever the viewers): its real
    # interval on AWS, where the writer wakes it (drem_live.__main__.WOKEN_POLL_MS).
    server_poll_every_s: float = 0.25
    # The writer's wake-ups: one POST through CloudFront per write that changes a live page (the track board, the
    # combined board, the overlay: LeaderboardPublisher's on_change), and the Lambda's time waiting for its answer.
    # That time is an estimate, not measured (no AWS here); chalicelib.live_wake_http bounds it at 250 ms.
    wakes_per_lap: int = 3
    wake_post_ms: float = 20.0
    # Lambda: 512 MB (functions/.chalice/config.json); a poll answered 204 or from the render cache takes ~10 ms.
    lambda_memory_gb: float = 0.5
    lambda_poll_ms: float = 10.0
    lambda_page_ms: float = 60.0
    lambda_instance_cache_s: float = 0.25  # the per-instance poll cache (PublicViewCache)
    # Non-live traffic, the same in both designs: a lap POST per lap per track, staff consoles refreshing.
    staff: int = 12
    staff_request_every_s: float = 5.0
    # Fargate: the task size and how many streams one task carries (the scaling target, STREAMS_TARGET_PER_TASK).
    task_vcpu: float = 0.5
    task_memory_gb: float = 1.0
    viewers_per_task: int = STREAMS_TARGET_PER_TASK
    alb_public_ips: int = 0  # internal (a CloudFront VPC origin): no public address; was one per subnet/AZ
    infrastructure_hours: float = 24.0
    framing_bytes: int = 40  # per delivered message: HTTP/2 DATA frame + TLS record overhead

    @property
    def seconds(self) -> float:
        return self.hours * 3600

    @property
    def screens(self) -> int:
        return self.tracks * self.screens_per_track

    @property
    def overlays(self) -> int:
        return self.tracks * self.overlays_per_track

    @property
    def phones(self) -> int:
        return max(0, self.spectators - self.screens - self.overlays)

    @property
    def board_viewers(self) -> int:
        return self.screens + self.phones

    @property
    def channels(self) -> int:
        """A board and an overlay per track."""
        return 2 * self.tracks

    @property
    def laps(self) -> float:
        """Laps on all tracks: each changes its track's board and overlay once."""
        return self.tracks * self.seconds / self.lap_every_s

    @property
    def timer_requests(self) -> float:
        return self.laps

    @property
    def staff_requests(self) -> float:
        return self.staff * self.seconds / self.staff_request_every_s


@dataclass(frozen=True)
class Sizes:
    """Measured bytes (see measure())."""
    board_html: int
    board_gzip: int
    overlay_html: int
    overlay_gzip: int
    heartbeat_gzip: int
    board_item: int  # the DynamoDB item (body + ranking state + keys): what a read is billed by
    overlay_item: int
    race_item: int
    page_html: int
    combined_item: int = 0  # the combined board of all tracks (its body; no ranking state)
    outcome_item: int = 400  # a strip event's stored answer (idempotency record)
    poll_204: int = 350  # status line and headers of an unchanged poll


def read_units(item_bytes: int, *, consistent: bool) -> float:
    units = math.ceil(item_bytes / 4096)
    return units if consistent else units / 2


def write_units(item_bytes: int, *, transactional: bool = False) -> float:
    units = math.ceil(item_bytes / 1024)
    return 2 * units if transactional else units


def lap_writes(p: Profile, s: Sizes) -> tuple[float, float]:
    """(write units, read units) one lap costs the writer: the strip event reads the live pointer and the race, writes
    its answer and the race in one transaction; publishing reads and rewrites the track board (body + state), reads
    every track's board to rewrite the combined board, reads and rewrites the overlay, and deletes the publish
    intent."""
    wru = (write_units(s.outcome_item, transactional=True) + write_units(s.race_item, transactional=True)
           + write_units(s.board_item) + write_units(s.combined_item or s.board_item) + write_units(s.overlay_item)
           + 1)
    rru = (read_units(256, consistent=True) + read_units(s.race_item, consistent=True)
           + read_units(s.board_item, consistent=True) * (1 + p.tracks)
           + read_units(s.combined_item or s.board_item, consistent=True) + read_units(s.overlay_item, consistent=True))
    return wru, rru


@dataclass(frozen=True)
class Usage:
    """What a design uses in a day, per billed dimension."""
    cloudfront_requests: float = 0
    cloudfront_bytes_out: float = 0
    api_requests: float = 0
    lambda_requests: float = 0
    lambda_gb_seconds: float = 0
    dynamodb_rru: float = 0
    dynamodb_wru: float = 0
    alb_hours: float = 0
    alb_lcu_hours: float = 0
    fargate_vcpu_hours: float = 0
    fargate_gb_hours: float = 0
    public_ip_hours: float = 0
    delivered_updates: float = 0  # messages that reached a viewer (a changed fragment or a pushed update)
    live_dynamodb_reads: float = 0  # GetItems made for the live pages


def non_live(p: Profile, s: Sizes) -> Usage:
    """Pages, laps and staff: through CloudFront to API Gateway + Lambda in both designs."""
    page_loads = p.phones * p.phone_page_loads + p.screens + p.overlays
    api = page_loads + p.timer_requests + p.staff_requests
    static = page_loads * p.static_files_per_page
    wru, rru = lap_writes(p, s)
    return Usage(cloudfront_requests=api + static, cloudfront_bytes_out=page_loads * s.page_html,
                 api_requests=api, lambda_requests=api,
                 lambda_gb_seconds=api * p.lambda_page_ms / 1000 * p.lambda_memory_gb,
                 dynamodb_wru=p.laps * wru, dynamodb_rru=p.laps * rru)


def polling(p: Profile, s: Sizes) -> Usage:
    polls = p.spectators * p.seconds / p.poll_every_s
    # Each viewer's token changes once per lap on its track: one 200 with the fragment, the other polls answer 204.
    changed = p.board_viewers * p.seconds / p.lap_every_s + p.overlays * p.seconds / p.lap_every_s
    bytes_out = changed * (s.board_html + s.poll_204) + (polls - changed) * s.poll_204  # API Gateway sends it raw
    # Lambda instances busy at once; each re-reads a channel's items at most once per cache window.
    instances = max(1.0, polls / p.seconds * p.lambda_poll_ms / 1000)
    reads_per_item = min(polls, instances * p.channels * p.seconds / p.lambda_instance_cache_s)
    board_reads = reads_per_item * p.board_viewers / p.spectators
    overlay_reads = reads_per_item  # every poll reads its track's overlay too (footer or overlay)
    rru = board_reads * read_units(s.board_item, consistent=False) + overlay_reads * read_units(
        s.overlay_item, consistent=False)
    return _plus(non_live(p, s), Usage(
        cloudfront_requests=polls, cloudfront_bytes_out=bytes_out, api_requests=polls, lambda_requests=polls,
        lambda_gb_seconds=polls * p.lambda_poll_ms / 1000 * p.lambda_memory_gb, dynamodb_rru=rru,
        delivered_updates=changed, live_dynamodb_reads=board_reads + overlay_reads))


def tasks(p: Profile) -> int:
    return max(1, math.ceil(p.spectators / p.viewers_per_task))


def push(p: Profile, s: Sizes) -> Usage:
    phone_streams = p.phones * p.seconds / p.phone_reconnect_every_s
    screen_streams = (p.screens + p.overlays) * max(1.0, p.seconds / p.screen_reconnect_every_s)
    streams = phone_streams + screen_streams
    updates_per_channel = p.seconds / p.lap_every_s
    board_deliveries = p.board_viewers * updates_per_channel
    overlay_deliveries = p.overlays * updates_per_channel
    heartbeats = p.spectators * p.seconds / p.heartbeat_every_s
    bytes_out = (board_deliveries * (s.board_gzip + p.framing_bytes)
                 + overlay_deliveries * (s.overlay_gzip + p.framing_bytes)
                 + heartbeats * (s.heartbeat_gzip + p.framing_bytes))
    n_tasks = tasks(p)
    # Each task polls every channel's items (a board channel: its board + its overlay for the footer; an overlay
    # channel: the same two), and reads the race behind an overlay once per overlay version.
    polls = n_tasks * p.channels * p.seconds / p.server_poll_every_s
    item_reads = 2 * polls
    race_reads = n_tasks * p.tracks * updates_per_channel
    rru = (polls * (read_units(s.board_item, consistent=False) + read_units(s.overlay_item, consistent=False))
           + race_reads * read_units(s.race_item, consistent=True))
    # ALB: each hour billed at its highest LCU dimension (streams are spread evenly over the day here).
    per_hour = 3600 / p.seconds
    lcu = max(streams * per_hour / 3600 / 25, p.spectators / 3000, bytes_out * per_hour / GB)
    wakes = p.laps * p.wakes_per_lap  # task to task relays stay inside the VPC: not billed per request
    return _plus(non_live(p, s), Usage(
        cloudfront_requests=streams + wakes, cloudfront_bytes_out=bytes_out, dynamodb_rru=rru,
        lambda_gb_seconds=wakes * p.wake_post_ms / 1000 * p.lambda_memory_gb,
        alb_hours=p.infrastructure_hours, alb_lcu_hours=lcu * p.hours,
        fargate_vcpu_hours=n_tasks * p.task_vcpu * p.infrastructure_hours,
        fargate_gb_hours=n_tasks * p.task_memory_gb * p.infrastructure_hours,
        public_ip_hours=(p.alb_public_ips + n_tasks) * p.infrastructure_hours,
        delivered_updates=board_deliveries + overlay_deliveries, live_dynamodb_reads=item_reads + race_reads))


def _plus(a: Usage, b: Usage) -> Usage:
    return Usage(**{f: getattr(a, f) + getattr(b, f) for f in Usage.__dataclass_fields__})


def dollars(u: Usage, prices: Prices = Prices()) -> dict[str, float]:
    return {
        "CloudFront requests": u.cloudfront_requests / 10_000 * prices.cloudfront_per_10k_https,
        "CloudFront data out": u.cloudfront_bytes_out / GB * prices.cloudfront_per_gb_out,
        "API Gateway": u.api_requests / 1e6 * prices.api_gateway_per_million,
        "Lambda": (u.lambda_requests / 1e6 * prices.lambda_per_million
                   + u.lambda_gb_seconds * prices.lambda_per_gb_second),
        "DynamoDB reads": u.dynamodb_rru / 1e6 * prices.dynamodb_per_million_rru,
        "DynamoDB writes": u.dynamodb_wru / 1e6 * prices.dynamodb_per_million_wru,
        "ALB": u.alb_hours * prices.alb_per_hour + u.alb_lcu_hours * prices.alb_per_lcu_hour,
        "Fargate": (u.fargate_vcpu_hours * prices.fargate_per_vcpu_hour
                    + u.fargate_gb_hours * prices.fargate_per_gb_hour),
        "Public IPv4": u.public_ip_hours * prices.public_ipv4_per_hour,
    }


# --- measuring the messages ----------------------------------------------------------------------------------------


def sse_message(event: str, token: str, html: str) -> bytes:
    lines = "".join(f"data: {line}\n" for line in html.splitlines())
    return f"id: {token}\nevent: {event}\n{lines}\n".encode()


def gzipped(message: bytes) -> int:
    """One message compressed on its own (a complete gzip member; members concatenate into one valid stream)."""
    return len(gzip.compress(message, compresslevel=6, mtime=0))


def measure(racers: int = 50) -> Sizes:
    """A `racers`-racer board and a racing overlay, published by the real LeaderboardPublisher into an in-memory
    store and rendered by the live-region routes exactly as a spectator's fragment is."""
    import os
    sys.path[:0] = [p for p in (str(ROOT / "functions"), str(ROOT)) if p not in sys.path]
    os.environ.setdefault("AWS_DEFAULT_REGION", REGION)

    from chalicelib.domain.big_screen import ScreenView
    from chalicelib.domain.leaderboards import (
        BoardRow,
        LeaderboardPublisher,
        Materialised,
        PublicView,
        board_key,
        overlay_key,
    )
    from chalicelib.views import live_regions
    from drem_leaderboard.models import Lap, LapSource, RaceConfig, Racer, RaceStatus, new_race
    from drem_leaderboard.ranking import Leaderboard, RacerProfile
    from drem_leaderboard.summary import summarise_racer
    from drem_web import render

    class MemoryBoards:
        def __init__(self) -> None:
            self.items: dict[tuple[str, str], Materialised] = {}

        def public(self, event_id: str, sort_key: str) -> PublicView | None:
            item = self.items.get((event_id, sort_key))
            return PublicView(version=item.version, etag=item.etag, body=item.body) if item else None

        def get(self, event_id: str, sort_key: str) -> Materialised | None:
            return self.items.get((event_id, sort_key))

        def put(self, event_id: str, sort_key: str, item: Materialised, expected_version: int | None) -> None:
            self.items[(event_id, sort_key)] = item

    from chalicelib.domain.leaderboards import board_key as _board_key

    now = 1_800_000_000_000
    event_id = "reinvent-2026"
    countries = ("SE", "US", "GB", "DE", "JP", "BR", "IN", "FR", "ES", "CA")
    boards = MemoryBoards()
    publisher = LeaderboardPublisher(boards, lambda: now, cache=None)
    rows, races = [], []
    for index in range(racers):
        racer = Racer(sub=f"3f1c9a2e-{index:04d}-4b7d-9e21-5c0d8a7b{index:04d}", username=f"racer_{index:03d}")
        laps = tuple(Lap(lap_id=i, time_ms=9_800 + 53 * index + 211 * i, is_valid=i != 2, source=LapSource.TIMER,
                         captured_at_ms=now - 60_000 + 12_000 * i) for i in range(5))
        race = new_race(race_id=f"race-{index:04d}", event_id=event_id, track_id="1", racer=racer,
                        config=RaceConfig(), now_ms=now - 180_000).model_copy(
            update={"laps": laps, "status": RaceStatus.SUBMITTED, "submitted_at_ms": now - 1_000})
        summary = summarise_racer([race])
        assert summary is not None
        rows.append(BoardRow(summary=summary, profile=RacerProfile(
            username=racer.username, country_code=countries[index % len(countries)], highlight_colour="#ff9900")))
        races.append(race)
    publisher.rebuild(event_id, {"1": rows}, RaceConfig().ranking_method, ["1"])
    racing = races[7].model_copy(update={"status": RaceStatus.RUNNING, "submitted_at_ms": None})
    board = Leaderboard.model_validate_json(publisher.board(event_id, "1").body)
    publisher.publish_overlay(racing, now, board, racing.racer.username)

    # The same builders the app's fragment routes and the live server use (chalicelib.views.live_regions).
    board_region = live_regions.leaderboard_region(publisher, event_id, "1", live_regions.LeaderboardQuery(), ["1"],
                                                   now)
    board_token, board_context, board_html = board_region.token, board_region.context, board_region.render()
    overlay_region = live_regions.overlay_region(publisher, lambda _event, _race: racing, event_id,
                                                 live_regions.OverlayQuery(track="1"), now)
    overlay_token, overlay_html = overlay_region.token, overlay_region.render()
    page_html = render.page("leaderboard", title="re:Invent 2026", track="1", tracks=["1"], lang="en", qr="none",
                            qr_svg="", page_url="https://drem.example.org/", stream_url=(
                                "/live/leaderboard/reinvent-2026?track=1"), car_eye_url=None,
                            view=ScreenView(title="re:Invent 2026", sponsor="", track_title="", footer="", links=(),
                                            logo_url="/event/reinvent-2026/logo?v=0123456789abcdef"),
                            **board_context()).body

    def item_bytes(key: tuple[str, str]) -> int:
        item = boards.items[key]
        return len(item.body) + len(item.state) + len(item.etag) + 64  # + keys, version, attribute names

    return Sizes(board_html=len(board_html.encode()),
                 board_gzip=gzipped(sse_message("board", board_token, board_html)),
                 overlay_html=len(overlay_html.encode()),
                 overlay_gzip=gzipped(sse_message("overlay", overlay_token, overlay_html)),
                 heartbeat_gzip=gzipped(b": heartbeat\n\n"),
                 board_item=item_bytes((event_id, board_key("1"))),
                 overlay_item=item_bytes((event_id, overlay_key("1"))),
                 race_item=len(racing.model_dump_json()) + 64, page_html=len(page_html.encode()),
                 # The combined board of 4 such tracks holds 4x the entries (it keeps no state of its own).
                 combined_item=4 * len(boards.items[(event_id, _board_key("combined"))].body) + 64)


# --- report ----------------------------------------------------------------------------------------------------------


def report(p: Profile, s: Sizes) -> tuple[float, float]:
    a, b = polling(p, s), push(p, s)
    print(f"aws_cost: {p.spectators:,} spectators, {p.hours:g} h, {p.tracks} tracks, a lap every {p.lap_every_s:g} s "
          f"per track; {p.screens} big screens, {p.overlays} overlays, {p.phones:,} phones; "
          f"list prices {REGION} read {PRICES_READ_ON}")
    print(f"measured: 50-racer board fragment {s.board_html:,} B raw, {s.board_gzip:,} B as one gzipped SSE message; "
          f"overlay {s.overlay_html:,} B / {s.overlay_gzip:,} B; heartbeat {s.heartbeat_gzip} B; "
          f"DynamoDB items: board {s.board_item:,} B, overlay {s.overlay_item:,} B; page {s.page_html:,} B")
    wru, rru = lap_writes(p, s)
    print(f"per lap: {wru:g} write units, {rru:g} read units (writer), {p.wakes_per_lap} wake-up POSTs (push); live "
          f"server fallback poll every {p.server_poll_every_s * 1000:g} ms per channel per task; {tasks(p)} task(s) "
          f"of {p.viewers_per_task:,} viewers")
    counts = [("CloudFront requests", "cloudfront_requests", 1), ("CloudFront GB out", "cloudfront_bytes_out", GB),
              ("API Gateway requests", "api_requests", 1), ("Lambda requests", "lambda_requests", 1),
              ("Lambda GB-s", "lambda_gb_seconds", 1), ("DynamoDB read units", "dynamodb_rru", 1),
              ("DynamoDB write units", "dynamodb_wru", 1),
              ("ALB hours", "alb_hours", 1), ("ALB LCU-hours", "alb_lcu_hours", 1),
              ("Fargate vCPU-hours", "fargate_vcpu_hours", 1), ("Fargate GB-hours", "fargate_gb_hours", 1),
              ("Public IPv4 hours", "public_ip_hours", 1), ("updates delivered", "delivered_updates", 1),
              ("live DynamoDB reads", "live_dynamodb_reads", 1)]
    print(f"{'count':<24}{'polling':>18}{'push':>18}")
    for label, field, unit in counts:
        print(f"{label:<24}{getattr(a, field) / unit:>18,.1f}{getattr(b, field) / unit:>18,.1f}")
    da, db = dollars(a), dollars(b)
    print(f"{'dollars':<24}{'polling':>18}{'push':>18}")
    for line in da:
        print(f"{line:<24}{da[line]:>18,.2f}{db[line]:>18,.2f}")
    total_a, total_b = sum(da.values()), sum(db.values())
    print(f"{'total per day':<24}{total_a:>18,.2f}{total_b:>18,.2f}")
    return total_a, total_b


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spectators", default=",".join(str(n) for n in GOALS_DOLLARS),
                        help="comma-separated crowd sizes")
    parser.add_argument("--hours", type=float, default=Profile.hours)
    args = parser.parse_args()
    sizes = measure()
    figures, met = [], True
    for spectators in (int(n) for n in args.spectators.split(",")):
        profile = replace(Profile(), spectators=spectators, hours=args.hours)
        total_a, total_b = report(profile, sizes)
        print()
        figures.append(f"{spectators:,}: polling=${total_a:,.2f} push=${total_b:,.2f}")
        goal = GOALS_DOLLARS.get(spectators)
        met &= goal is not None and total_b <= goal
    met &= set(GOALS_DOLLARS) <= {int(n) for n in args.spectators.split(",")}
    goals = " and ".join(f"push<=${g:g} at {n:,}" for n, g in GOALS_DOLLARS.items())
    print(f"RESULT aws_cost: {'; '.join(figures)} ({args.hours:g} h, {Profile.tracks} tracks, {REGION} list prices "
          f"of {PRICES_READ_ON}, DynamoDB writes counted, live poll {Profile.server_poll_every_s * 1000:g} ms) | "
          f"goal {goals} per {args.hours:g}-hour day | {'met' if met else 'not met'}")


if __name__ == "__main__":
    main()
