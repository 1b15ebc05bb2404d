"""The live server's camera routes (feeds in video_feeds.py, who may call what in video_access.py).

    POST /live/video/car/frame              car (its device credential): one JPEG frame, `X-Frame-Time` = epoch ms
                                            it was taken; answers {"wanted": bool} (stop sending when false), and
                                            "video": {fps, width, height, view} once staff chose them
    GET  /live/video/car/demand?wanted=&wait_s=   car: long poll, answers {"wanted": bool} when it differs from
                                            `wanted` (or after wait_s ≤ 25)
    GET  /live/video/{event_id}?track=      public: MJPEG of the car of the track's live race; 204 when no race is
                                            live or its race names no car; ends when the race does
    GET  /live/video/cars/{device_id}       staff (admin, operator session): MJPEG preview of that car

Viewers get `multipart/x-mixed-replace` (MJPEG): each part a JPEG with `X-Timestamp` (seconds, the car's clock when
taken) and `X-Frame` (its number). A viewer that cannot keep up is sent the newest frame, never a queue.
"""
from __future__ import annotations

import asyncio
import re
from collections.abc import Awaitable, Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from aiohttp import web

from drem_live import video_fanout
from drem_live.video_feeds import MAX_FRAME_BYTES, MJPEG_CONTENT_TYPE, Feeds, Sink, looks_like_jpeg
from drem_live.video_peers import Peers, PeerSettings, Upload, serve_peers

FEEDS: web.AppKey[Feeds] = web.AppKey("video_feeds", Feeds)
ACCESS: web.AppKey[Any] = web.AppKey("video_access", object)
VIDEO_EXECUTOR: web.AppKey[ThreadPoolExecutor] = web.AppKey("video_executor", ThreadPoolExecutor)
PEERS: web.AppKey[Peers | None] = web.AppKey("video_peers", object)  # type: ignore[arg-type]
FANOUT: web.AppKey[video_fanout.FanOutWorker] = web.AppKey("video_fanout", video_fanout.FanOutWorker)
EVENT_ID = re.compile(r"[A-Za-z0-9_.-]{1,128}")
TRACK_ID = re.compile(r"[A-Za-z0-9_-]{1,32}")
DEVICE_ID = re.compile(r"[A-Za-z0-9_.-]{1,64}")
CORS = {"Access-Control-Allow-Origin": "*"}
NO_SNIFF = {"X-Content-Type-Options": "nosniff"}
WRITE_TIMEOUT_S = 5.0  # a viewer that takes longer than this to take one frame is dropped
RECHECK_S = 1.0  # how often a public stream re-reads which car is racing
MAX_DEMAND_WAIT_S = 25.0


def refuse(status: int, message: str) -> web.Response:
    return web.json_response({"message": message}, status=status, headers={**CORS, **NO_SNIFF})


async def _blocking(request: web.Request, call: Callable[..., Any], *args: Any) -> Any:
    return await asyncio.get_running_loop().run_in_executor(request.app[VIDEO_EXECUTOR], call, *args)


async def _car(request: web.Request) -> Any:
    return await _blocking(request, request.app[ACCESS].car, request.headers.get("Authorization", ""))


async def car_frame(request: web.Request) -> web.Response:
    car = await _car(request)
    if car is None:
        return refuse(401, "Send frames with this car's device credential: 'Authorization: Device <id>.<secret>'.")
    size = request.content_length
    if size is None or not 0 < size <= MAX_FRAME_BYTES:
        return refuse(413, f"A frame is one JPEG of at most {MAX_FRAME_BYTES} bytes, with its Content-Length.")
    jpeg = await request.content.readexactly(size)
    try:
        taken_ms = float(request.headers.get("X-Frame-Time", ""))
    except ValueError:
        return refuse(400, "X-Frame-Time must be the epoch milliseconds the frame was taken at.")
    if not looks_like_jpeg(jpeg):
        return refuse(415, "That is not a JPEG image.")
    feeds = request.app[FEEDS]
    feeds.feed(car.device_id, car.hostname).publish(jpeg, taken_ms)
    feeds.frames_in += 1
    peers = request.app[PEERS]
    if peers is not None:  # the viewers of the other live tasks see it too (drem_live.video_peers)
        peers.forward(Upload(car.device_id, car.hostname, jpeg, taken_ms))
    return web.json_response(_answer(car, feeds.wanted(car.device_id)))


async def car_demand(request: web.Request) -> web.Response:
    car = await _car(request)
    if car is None:
        return refuse(401, "Ask with this car's device credential: 'Authorization: Device <id>.<secret>'.")
    feeds = request.app[FEEDS]
    feeds.feed(car.device_id, car.hostname)  # known by its hostname too from now on
    try:
        wait_s = min(MAX_DEMAND_WAIT_S, max(0.0, float(request.query.get("wait_s", "0"))))
    except ValueError:
        return refuse(400, "wait_s must be a number of seconds.")
    reported = request.query.get("wanted") == "1"
    return web.json_response(_answer(car, await feeds.demand_change(car.device_id, reported, wait_s)))


def _answer(car: Any, wanted: bool) -> dict[str, Any]:
    """What a car hears back: whether to send, and at which settings when staff chose them (the car's relay applies
    them from this answer on)."""
    video = getattr(car, "video", None)
    return {"wanted": wanted, **({"video": video} if video else {})}


async def racing_video(request: web.Request) -> web.StreamResponse:
    event_id, track_id = request.match_info["event_id"], request.query.get("track") or "1"
    if not EVENT_ID.fullmatch(event_id) or not TRACK_ID.fullmatch(track_id):
        return refuse(400, "That is not an event id and track id.")
    access = request.app[ACCESS]

    async def racing() -> str | None:
        return await _blocking(request, access.racing_car, event_id, track_id)

    car = await racing()
    if car is None:
        return web.Response(status=204, headers={**CORS, "Cache-Control": "no-store"})
    return await _watch(request, car, racing, public=True)


async def preview_video(request: web.Request) -> web.StreamResponse:
    device_id = request.match_info["device_id"]
    if not DEVICE_ID.fullmatch(device_id):
        return refuse(400, "That is not a device id.")
    if not await _blocking(request, request.app[ACCESS].is_staff, dict(request.cookies)):
        return web.json_response({"message": "Only staff (admin, operator) preview a car's camera; sign in."},
                                 status=403, headers=NO_SNIFF)

    async def same_car() -> str | None:
        return device_id
    return await _watch(request, device_id, same_car, public=False)


async def _watch(request: web.Request, car: str, racing: Callable[[], Awaitable[str | None]], *,
                 public: bool) -> web.StreamResponse:
    feeds = request.app[FEEDS]
    if feeds.full():
        return refuse(503, "Too many people are watching the cars' cameras; try again shortly.")
    response = web.StreamResponse(headers={
        **(CORS if public else {}), **NO_SNIFF, "Content-Type": MJPEG_CONTENT_TYPE,
        "Cache-Control": "no-store", "X-Accel-Buffering": "no"})
    chunked = request.version >= (1, 1)
    if chunked:
        response.enable_chunked_encoding()  # the feed writes whole HTTP/1.1 chunks to the connection itself
    watching, feed = car, None
    feeds.watch(watching)
    worker = request.app.get(FANOUT)
    viewer: int | None = None  # this connection's number at the fan-out worker, once it writes to it
    try:
        await response.prepare(request)
        if request.transport is None:
            return response
        # From here the feed writes each frame to this connection as it arrives (CarFeed.publish; or the fan-out
        # worker, drem_live.video_fanout); this coroutine only follows which car to show, and notices the viewer leave.
        transport = request.transport
        sink = Sink(transport, chunked=chunked)
        closed = sink.closed  # the worker sets it when it drops the viewer
        loop = asyncio.get_running_loop()
        checked = loop.time()
        while not closed.is_set():
            if feed is None and (feed := feeds.find(watching)) is not None:
                if viewer is not None and worker is not None:
                    worker.follow(viewer, feed.device_id)
                elif worker is None or (viewer := worker.attach(transport, chunked, feed.device_id,
                                                                closed.set)) is None:
                    feed.attach(sink)  # this process writes the frames (no worker, or it could not take the viewer)
            try:  # a car not heard from yet is looked for every 0.1 s; the race is re-read every RECHECK_S
                async with asyncio.timeout(RECHECK_S if feed is not None else 0.1):
                    await closed.wait()
            except TimeoutError:
                pass
            if loop.time() - checked < RECHECK_S:
                continue
            checked = loop.time()
            current = await racing()
            if current is None:
                break  # the race ended: the page's player falls back to nothing
            if current != watching:  # the next race's car: follow it
                if feed is not None:
                    feed.sinks.discard(sink)
                feeds.unwatch(watching)
                watching, feed, sink.shown = current, None, 0
                feeds.watch(watching)
    except ConnectionResetError:
        pass
    finally:
        if feed is not None:
            feed.sinks.discard(sink)
        feeds.unwatch(watching)
        if viewer is not None and worker is not None:
            # The race ended with the viewer still there: the worker ends the stream after the frame it may be writing
            # (this process must not write after it); else it lets go at once.
            worker.detach(viewer, end=not closed.is_set() and request.transport is not None)
            if request.transport is not None:
                request.transport.close()  # this process's copy of the connection; the worker's ends the stream
    return response


HUB_ENV = "DREM_LIVE_VIDEO_HUB"
HUB_SESSION: web.AppKey[Any] = web.AppKey("video_hub_session", object)
_FORWARDED = ("Authorization", "Cookie", "Content-Type", "Content-Length", "X-Frame-Time")
_RETURNED = ("Content-Type", "Cache-Control", "Access-Control-Allow-Origin", "X-Content-Type-Options")


async def via_hub(request: web.Request) -> web.StreamResponse:
    """In a worker that is not the hub: the camera routes are the hub's (one process holds every car's feed, so one
    upload reaches the viewers of every worker); the request and its answer pass through unchanged."""
    import aiohttp

    body = None
    if request.method == "POST":
        if (request.content_length or 0) > MAX_FRAME_BYTES:
            return refuse(413, f"A frame is one JPEG of at most {MAX_FRAME_BYTES} bytes, with its Content-Length.")
        # The whole frame (content.read(n) may stop at what has arrived so far); without a length the hub refuses it.
        size = request.content_length
        body = await request.content.readexactly(size) if size else await request.content.read(MAX_FRAME_BYTES)
    headers = {name: request.headers[name] for name in _FORWARDED if name in request.headers}
    try:
        upstream = await request.app[HUB_SESSION].request(
            request.method, request.app[HUB_URL] + request.path_qs, headers=headers, data=body,
            timeout=aiohttp.ClientTimeout(total=None, connect=5, sock_read=None))
    except aiohttp.ClientError:
        return refuse(503, "The cars' cameras are not available right now; try again shortly.")
    async with upstream:
        response = web.StreamResponse(status=upstream.status, headers={
            name: upstream.headers[name] for name in _RETURNED if name in upstream.headers})
        await response.prepare(request)
        try:
            async for chunk in upstream.content.iter_any():
                await asyncio.wait_for(response.write(chunk), WRITE_TIMEOUT_S)
        except (ConnectionResetError, TimeoutError, aiohttp.ClientError):
            pass
    return response


HUB_URL: web.AppKey[str] = web.AppKey("video_hub_url", str)


def add_video_routes(app: web.Application, access: Any | None = None, *, threads: int = 4,
                     hub_url: str | None = None, peers: PeerSettings | None = None) -> None:
    """Mount the camera routes; `access` defaults to the app's (drem_live.video_access.VideoAccess). With `hub_url`
    (default $DREM_LIVE_VIDEO_HUB, which the first of several workers gives the others) they pass to that hub. With
    `peers` (default from $DREM_LIVE_VIDEO_PEERS…, drem_live.video_peers) the feeds are shared with other servers."""
    import os

    hub_url = hub_url if hub_url is not None else os.environ.get(HUB_ENV, "")
    if hub_url:
        _add_hub_proxy(app, hub_url)
        return
    if access is None:
        from drem_live.video_access import VideoAccess

        access = VideoAccess()
    feeds = app[FEEDS] = Feeds()
    app[ACCESS] = access
    peers = peers if peers is not None else PeerSettings.from_env()
    app[PEERS] = None
    if peers is not None:
        app[PEERS] = shared = Peers(feeds, peers)
        serve_peers(app, shared)
    executor = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="drem-video")
    app[VIDEO_EXECUTOR] = executor
    if video_fanout.wanted():
        _add_fan_out_worker(app, feeds)
    app.router.add_post("/live/video/car/frame", car_frame)
    app.router.add_get("/live/video/car/demand", car_demand)
    app.router.add_get("/live/video/cars/{device_id}", preview_video)
    app.router.add_get("/live/video/{event_id}", racing_video)

    async def close(_app: web.Application) -> None:
        executor.shutdown(wait=False, cancel_futures=True)

    app.on_shutdown.append(close)


def _add_fan_out_worker(app: web.Application, feeds: Feeds) -> None:
    """The viewers' frames are written by a worker process at the lowest CPU priority (drem_live.video_fanout)."""

    async def start(_app: web.Application) -> None:
        worker = app[FANOUT] = video_fanout.FanOutWorker()
        worker.start(asyncio.get_running_loop())
        feeds.remote = worker.frame

    async def stop(_app: web.Application) -> None:
        feeds.remote = None
        app[FANOUT].stop()

    app.on_startup.append(start)
    app.on_cleanup.append(stop)


def _add_hub_proxy(app: web.Application, hub_url: str) -> None:
    import aiohttp

    app[HUB_URL] = hub_url.rstrip("/")

    async def open_session(_app: web.Application) -> None:
        # Each viewer holds one connection to the hub while it watches: no pool limit (the hub caps viewers).
        app[HUB_SESSION] = aiohttp.ClientSession(connector=aiohttp.TCPConnector(limit=0), auto_decompress=False)

    async def close_session(_app: web.Application) -> None:
        await app[HUB_SESSION].close()

    app.on_startup.append(open_session)
    app.on_cleanup.append(close_session)
    app.router.add_post("/live/video/car/frame", via_hub)
    app.router.add_get("/live/video/car/demand", via_hub)
    app.router.add_get("/live/video/cars/{device_id}", via_hub)
    app.router.add_get("/live/video/{event_id}", via_hub)
