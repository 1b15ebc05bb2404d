"""`POST /live/wake`: the writer's wake-up where it cannot reach the live server's wake sockets (drem_live.wake). On
AWS the Lambda functions post the event id through CloudFront and the load balancer to one live task
(chalicelib.live_wake_http); that task wakes its own channels and relays the wake-up to the other live tasks through
their peer port (drem_live.video_peers, `POST /peer/wake`), so every task's viewers get the lap. A relayed wake-up
is never relayed again.

Who may call it: only the writer, which holds the stage's wake secret (WAKE_SECRET_HEADER, compared in constant time).
Without it the answer is 403 and nothing is read, neither the body nor storage. The body is one event id of at most
MAX_WAKE_BODY_BYTES (413 beyond, 400 when it is not an event id). The answer (204) does not wait for the relay.
"""
from __future__ import annotations

import asyncio
import hmac
import logging
import re
from collections.abc import Callable

from aiohttp import web

from drem_live.app_code import MAX_WAKE_BODY_BYTES, WAKE_PATH, WAKE_SECRET_HEADER, LiveWaker
from drem_live.video_routes import HUB_SESSION, HUB_URL, PEERS

log = logging.getLogger("drem_live")
EVENT_ID = re.compile(rb"[A-Za-z0-9_.-]{1,128}")
HUB_TIMEOUT_S = 2.0
NO_SNIFF = {"X-Content-Type-Options": "nosniff"}

WAKE_SECRET: web.AppKey[str] = web.AppKey("wake_secret", str)
WAKE_TASK: web.AppKey[Callable[[str], None]] = web.AppKey("wake_task", object)  # type: ignore[arg-type]
HTTP_WAKES: web.AppKey[list[int]] = web.AppKey("http_wakes", list)


def refuse(status: int, message: str) -> web.Response:
    return web.json_response({"message": message}, status=status, headers=NO_SNIFF)


def task_waker(woken: Callable[[str], None], wake_dir: str) -> Callable[[str], None]:
    """Wake every process of this task: each one's wake socket when there is a wake directory (several workers),
    else this process's channels."""
    return LiveWaker(wake_dir) if wake_dir else woken


async def take_wake(request: web.Request) -> web.Response:
    app = request.app
    if not hmac.compare_digest(request.headers.get(WAKE_SECRET_HEADER, "").encode(), app[WAKE_SECRET].encode()):
        return refuse(403, "Only drem's writer wakes the live server.")
    if (request.content_length or 0) > MAX_WAKE_BODY_BYTES:
        return refuse(413, f"The body is one event id of at most {MAX_WAKE_BODY_BYTES} bytes.")
    body = await request.read()  # bounded by the app's client_max_size even without a Content-Length
    if len(body) > MAX_WAKE_BODY_BYTES:
        return refuse(413, f"The body is one event id of at most {MAX_WAKE_BODY_BYTES} bytes.")
    if not EVENT_ID.fullmatch(body):
        return refuse(400, "The body is an event id.")
    event_id = body.decode()
    app[HTTP_WAKES][0] += 1
    hub = app.get(HUB_URL)
    if hub:  # a worker that is not the first: the first process holds the peers and wakes every worker
        asyncio.get_running_loop().create_task(_pass_to_hub(app, hub, event_id))
        return web.Response(status=204)
    app[WAKE_TASK](event_id)
    peers = app.get(PEERS)
    if peers is not None:
        peers.relay_wake(event_id)
    return web.Response(status=204)


async def _pass_to_hub(app: web.Application, hub: str, event_id: str) -> None:
    import aiohttp

    try:
        async with app[HUB_SESSION].post(hub + WAKE_PATH, data=event_id.encode(),
                                         headers={WAKE_SECRET_HEADER: app[WAKE_SECRET]},
                                         timeout=aiohttp.ClientTimeout(total=HUB_TIMEOUT_S)) as answer:
            await answer.read()
    except (aiohttp.ClientError, TimeoutError, OSError) as exc:
        log.warning("a wake-up did not reach the first worker (%s); the poll shows the change", exc)


def add_wake_route(app: web.Application, secret: str, woken: Callable[[str], None], wake_dir: str) -> None:
    """Mount POST WAKE_PATH (after the camera routes, whose peers it relays through); `woken(event_id)` wakes this
    process's channels."""
    app[WAKE_SECRET] = secret
    app[WAKE_TASK] = task = task_waker(woken, wake_dir)
    app[HTTP_WAKES] = [0]
    peers = app.get(PEERS)
    if peers is not None:
        peers.on_wake = task  # a wake-up relayed by another task wakes this one's processes too
    app.router.add_post(WAKE_PATH, take_wake)
