"""The live server's HTTP routes (aiohttp, one event loop; storage reads and rendering in worker threads).

    GET /live/healthz                               200 JSON: channels, streams, bytes per message (plain, gzip)
    GET /live/leaderboard/{event}?<fragment query>  text/event-stream of the big-screen board's live region
    GET /live/overlay/{event}?<fragment query>      text/event-stream of the overlay's live region
    GET /live/api/leaderboard/{event}?track=        the board JSON, ETag / If-None-Match / ?since= like /api/...
    GET /live/api/overlay/{event}?track=            the overlay JSON, the same way

A stream's messages are `id: <version token>`, `event: fragment`, `data:` the region's HTML (exactly what the app's
`…/live` fragment route renders: both build it with chalicelib.views.live_regions). The first message is the current
state, unless the client's Last-Event-ID already is; then one per token change, and a `: heartbeat` comment every
15 s. Public data only, read-only; `Access-Control-Allow-Origin: *` (no credentials).
"""
from __future__ import annotations

import asyncio
import ipaddress
import logging
import os
import re
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from aiohttp import web
from pydantic import ValidationError

from drem_live.app_code import AppCode, etag_matches, token_is_newer
from drem_live.channels import Channels, ChannelsFull, Subscriber
from drem_live.limits import Limits, StreamCount
from drem_live.metrics import publish_streams
from drem_live.polls import PollViews
from drem_live.prepared import PreparedResponse, takes_prepared
from drem_live.sse import GZIP_HEADER, HEARTBEAT, Message, accepts_gzip, clock_message
from drem_live.video_routes import add_video_routes
from drem_live.wake import WAKE, listen_for_wakes
from drem_live.wake_route import HTTP_WAKES, add_wake_route

log = logging.getLogger("drem_live")

HEARTBEAT_S = 15.0
FIRST_MESSAGE_TIMEOUT_S = 10.0
WRITE_TIMEOUT_S = 30.0  # a viewer that stops reading for this long is dropped
RETRY_MS = 2000  # how soon EventSource reconnects after a dropped connection
RETRY_AFTER_S = "10"
EVENT_ID = re.compile(r"[A-Za-z0-9_.-]{1,128}")
TRACK_ID = re.compile(r"[A-Za-z0-9_-]{1,32}")
COMBINED_TRACK = "combined"
CORS = {"Access-Control-Allow-Origin": "*"}
NO_SNIFF = {"X-Content-Type-Options": "nosniff"}

Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]

CODE: web.AppKey[AppCode] = web.AppKey("code", AppCode)
CHANNELS: web.AppKey[Channels] = web.AppKey("channels", Channels)
STREAMS: web.AppKey[StreamCount] = web.AppKey("streams", StreamCount)
POLLS: web.AppKey[PollViews] = web.AppKey("polls", PollViews)
KNOWN_EVENTS: web.AppKey[dict[str, tuple[list[str], float]]] = web.AppKey("known_events", dict)
UNKNOWN_EVENTS: web.AppKey[dict[str, float]] = web.AppKey("unknown_events", dict)
EVENT_READ_S = 5.0
EXECUTOR: web.AppKey[ThreadPoolExecutor] = web.AppKey("executor", ThreadPoolExecutor)


def refuse(status: int, message: str, **headers: str) -> web.Response:
    return web.json_response({"message": message}, status=status, headers={**CORS, **NO_SNIFF, **headers})


def public(handler: Handler) -> Handler:
    """Every route: a bounded query. Each handler sets CORS itself (public data, no credentials): cheaper on the hot
    poll path than a middleware."""
    async def bounded(request: web.Request) -> web.StreamResponse:
        limit = request.app[STREAMS].limits.max_query_bytes
        if len(request.query_string) > limit:
            return refuse(400, f"The query is longer than {limit} bytes.")
        return await handler(request)
    return bounded


async def preflight(_request: web.Request) -> web.Response:
    return web.Response(status=204, headers={**CORS, "Access-Control-Allow-Methods": "GET",
                                             "Access-Control-Allow-Headers": "Last-Event-ID, Cache-Control",
                                             "Access-Control-Max-Age": "86400"})


async def healthz(request: web.Request) -> web.Response:
    app = request.app
    wake = app.get(WAKE)
    return web.json_response({"ok": True, "pid": os.getpid(), "channels": len(app[CHANNELS]),
                              "streams": app[STREAMS].total, "message_bytes": app[CHANNELS].sizes.as_dict(),
                              "poll_ms": round(app[CHANNELS].poll_s * 1000),
                              "wakes": wake.received if wake is not None else None,
                              "http_wakes": app[HTTP_WAKES][0] if HTTP_WAKES in app else None},
                             headers={**CORS, **NO_SNIFF})


def client_address(request: web.Request) -> str:
    header = request.app[STREAMS].limits.client_address_header
    named = request.headers.get(header, "").split(",")[-1].strip() if header else ""  # the nearest proxy's entry
    if not named:
        return request.remote or ""
    # CloudFront-Viewer-Address is "address:port" (IPv6 too: "2001:db8::1:443", itself a valid IPv6 address, so
    # only the header's name tells), and the port says nothing about who; X-Forwarded-For names an address.
    if header.lower() == "cloudfront-viewer-address":
        return named.rsplit(":", 1)[0]
    try:
        return str(ipaddress.ip_address(named))
    except ValueError:
        return named


async def event_tracks(request: web.Request, event_id: str) -> list[str] | None:
    """The event's track ids, or None when it does not exist (one read per EVENT_READ_S per event, remembered; a
    missing one too, so made-up ids cost one read each per window, not one per request): a stream of a made-up event
    opens no channel, and the tracks say which option sets the app offers (a track added since is seen within
    EVENT_READ_S; until then its streams take a slot of their page's own options)."""
    known, unknown = request.app[KNOWN_EVENTS], request.app[UNKNOWN_EVENTS]
    now = time.monotonic()
    remembered = known.get(event_id)
    if remembered is not None and now - remembered[1] < EVENT_READ_S:
        return remembered[0]
    if now - unknown.get(event_id, -EVENT_READ_S) < EVENT_READ_S:
        return None
    tracks = await asyncio.get_running_loop().run_in_executor(request.app[EXECUTOR], request.app[CODE].event_tracks,
                                                              event_id)
    if tracks is not None:
        if len(known) >= 10_000 and event_id not in known:
            known.clear()
        known[event_id] = (tracks, now)
    else:
        if len(unknown) >= 10_000:
            unknown.clear()
        unknown[event_id] = now
    return tracks


def stream_handler(kind: str) -> Handler:
    async def handle(request: web.Request) -> web.StreamResponse:
        return await stream(request, kind)
    return handle


async def stream(request: web.Request, kind: str) -> web.StreamResponse:
    app, code = request.app, request.app[CODE]
    event_id = request.match_info["event_id"]
    if not EVENT_ID.fullmatch(event_id):
        return refuse(400, "That is not an event id.")
    params = {k: v for k, v in request.query.items() if k != "v"}
    try:
        query = code.parse_query(kind, params)
    except ValidationError as exc:
        problems = "; ".join(f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors())
        return refuse(400, f"Bad query: {problems}")
    client = client_address(request)
    streams = app[STREAMS]
    key = code.channel_options(kind, event_id, query)
    refusal = streams.refusal(client, key, len(app[CHANNELS]))
    if refusal:
        return refuse(503, f"{refusal}; try again shortly.", **{"Retry-After": RETRY_AFTER_S})
    tracks = await event_tracks(request, event_id)
    if tracks is None:
        return refuse(404, f"There is no event {event_id}.")

    def step(last: Message | None) -> Message | None:  # in a worker thread: read, and render on a new token only
        region = code.region(kind, event_id, query, code.now_ms())
        if last is not None and not token_is_newer(region.token, last.token):
            return None
        return Message.fragment(region.token, region.render())

    subscriber = Subscriber()
    try:
        channel = app[CHANNELS].join(key, step, subscriber, page=(kind, event_id), event_id=event_id,
                                     offered=code.offered(query, tracks))
    except ChannelsFull as exc:
        return refuse(503, f"{exc}; try again shortly.", **{"Retry-After": RETRY_AFTER_S})
    streams.open(client, key)
    try:
        return await _write_stream(request, channel, subscriber)
    finally:
        streams.close(client, key)
        app[CHANNELS].leave(channel, subscriber)


async def _write_stream(request: web.Request, channel: Any, subscriber: Subscriber) -> web.StreamResponse:
    gzip = accepts_gzip(request.headers.get("Accept-Encoding", ""))
    try:
        await asyncio.wait_for(channel.first.wait(), FIRST_MESSAGE_TIMEOUT_S)
    except TimeoutError:
        return refuse(503, "The live page could not be read from storage; try again shortly.",
                      **{"Retry-After": RETRY_AFTER_S})
    response = web.StreamResponse(headers={
        **CORS, **NO_SNIFF, "Content-Type": "text/event-stream; charset=utf-8", "Cache-Control": "no-store",
        "X-Accel-Buffering": "no", **({"Content-Encoding": "gzip"} if gzip else {})})
    await response.prepare(request)
    opening = clock_message(request.app[CODE].now_ms(), RETRY_MS).bytes_for(gzip)
    await _write(request, response, (GZIP_HEADER if gzip else b"") + opening)
    # What this viewer has: its Last-Event-ID, then whatever it was sent. Only newer tokens go out (a broadcast that
    # reached it while it was joining included, and the channel's current state when it joined an open channel).
    shown: str | None = request.headers.get("Last-Event-ID") or None
    if subscriber.pending is None and channel.latest is not None:
        subscriber.offer(channel.latest)
    # No timer per viewer per message (profiled: timers were the largest cost of a push to thousands): heartbeats
    # come from the channels' one timer (Channels.beat_every), and a write is timed only when it may wait.
    while True:
        await subscriber.wake.wait()
        beat = subscriber.heartbeat_due
        message = subscriber.take()
        if message is not None and token_is_newer(message.token, shown):
            await _write(request, response, message.bytes_for(gzip))
            shown = message.token
        elif beat:
            await _write(request, response, HEARTBEAT.bytes_for(gzip))


async def _write(request: web.Request, response: web.StreamResponse, data: bytes) -> None:
    """Write `data`; a viewer that stops reading is dropped after WRITE_TIMEOUT_S. aiohttp's write waits only while
    the connection's send buffer is full, so a write onto an empty buffer needs no timer."""
    transport = request.transport
    if transport is not None and not transport.is_closing() and transport.get_write_buffer_size() == 0:
        await response.write(data)
        return
    async with asyncio.timeout(WRITE_TIMEOUT_S):
        await response.write(data)


def poll_handler(kind: str) -> Handler:
    default_track = COMBINED_TRACK if kind == "leaderboard" else "1"

    async def handle(request: web.Request) -> web.StreamResponse:
        event_id, query = request.match_info["event_id"], request.query
        track = query.get("track") or default_track
        if not EVENT_ID.fullmatch(event_id) or not TRACK_ID.fullmatch(track):
            return refuse(400, "That is not an event id and track id.")
        polls = request.app[POLLS]
        view = polls.fresh(kind, event_id, track) or await polls.get(kind, event_id, track)
        if_none_match, since = request.headers.get("If-None-Match"), query.get("since")
        unchanged = (if_none_match is not None and etag_matches(view.etag, if_none_match)) or \
            (since is not None and since == str(view.version))
        if takes_prepared(request):  # the answer's bytes as built with the view (drem_live.prepared)
            return PreparedResponse(view.wire_304 if unchanged else view.wire_200)
        if unchanged:
            return web.Response(status=304, headers=view.headers_304)
        return web.Response(body=view.body, headers=view.headers_200)
    return handle


def make_app(code: AppCode, *, poll_s: float, limits: Limits, threads: int = 8,
             wake_dir: str = "", wake_secret: str = "", metrics: tuple[str, str] | None = None) -> web.Application:
    """`wake_dir`: this task's processes' wake sockets (drem_live.wake); `wake_secret`: take the writer's wake-ups over
    HTTP too (drem_live.wake_route). `metrics` (namespace, stage): publish the open streams to CloudWatch
    (drem_live.metrics)."""
    executor = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="drem-live")

    def read_view(kind: str, event_id: str, track: str) -> tuple[int, str]:
        view = code.view(kind, event_id, track)
        return view.version, view.body

    app = web.Application(client_max_size=1024)
    app[CODE] = code
    app[EXECUTOR] = executor
    app[CHANNELS] = Channels(poll_s, executor, limits.max_channels, token_is_newer,
                             max_per_page=limits.max_channels_per_page)
    app[STREAMS] = StreamCount(limits)
    app[POLLS] = PollViews(read_view, poll_s, executor)
    app[KNOWN_EVENTS] = {}
    app[UNKNOWN_EVENTS] = {}
    def woken(event_id: str) -> None:
        code.changed(event_id)  # first: no channel may be handed what was read before the write
        app[CHANNELS].wake(event_id)
        app[POLLS].expire(event_id)

    if wake_dir:
        listen_for_wakes(app, wake_dir, woken)
    if metrics is not None:
        publish_streams(app, *metrics, streams=lambda: app[STREAMS].total)
    app.router.add_get("/live/healthz", healthz)
    for kind in ("leaderboard", "overlay"):
        app.router.add_get(f"/live/{kind}/{{event_id}}", public(stream_handler(kind)))
        app.router.add_get(f"/live/api/{kind}/{{event_id}}", public(poll_handler(kind)))
    add_video_routes(app)  # the cars' cameras (docs/racing.md "The car's eye")
    if wake_secret:
        add_wake_route(app, wake_secret, woken, wake_dir)
    app.router.add_route("OPTIONS", "/live/{tail:.*}", preflight)

    async def beat(_app: web.Application) -> AsyncIterator[None]:
        task = asyncio.get_running_loop().create_task(app[CHANNELS].beat_every(HEARTBEAT_S))
        yield
        task.cancel()

    app.cleanup_ctx.append(beat)

    async def close(_app: web.Application) -> None:
        app[CHANNELS].stop_all()
        executor.shutdown(wait=False, cancel_futures=True)

    app.on_shutdown.append(close)
    return app
