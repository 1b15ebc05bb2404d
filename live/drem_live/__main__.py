"""`python -m drem_live --host H --port P [--workers N]`: the live server (see server.py).

It reads the app's DREM_* / AWS_* settings (chalicelib.settings) to reach storage. With several workers each is its own
process listening on the same port (SO_REUSEPORT: the kernel spreads connections over them), so one GIL does not cap
the polls; the first process starts the others and stops them when it stops (they also die with it).
"""
from __future__ import annotations

import argparse
import atexit
import ctypes
import gc
import logging
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile

DEFAULT_POLL_MS = 100
WOKEN_POLL_MS = 250
DEFAULT_KEEPALIVE_S = 15.0
# The cyclic collector's first threshold: Python's default (700) is crossed dozens of times a second by the objects of
# the requests in flight, which are freed by reference counting anyway (see _quiet_collector).
YOUNG_COLLECTION_THRESHOLD = 10_000
# How long a thread may hold the GIL while another waits for it. The event loop fans frames and fragments out in
# Python while the channels read storage and render on executor threads: at CPython's default (5 ms) a channel's
# read, which needs the GIL back after each socket wait, queued behind the loop's work 5 ms at a time.
SWITCH_INTERVAL_S = 0.0005
_PR_SET_PDEATHSIG = 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drem_live", description=__doc__.splitlines()[0])
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8002)
    parser.add_argument("--workers", type=int, default=int(os.environ.get("DREM_LIVE_WORKERS") or 1),
                        help="processes sharing the port (SO_REUSEPORT); default $DREM_LIVE_WORKERS or 1")
    parser.add_argument("--reuse-port", action="store_true", help=argparse.SUPPRESS)  # a worker started by the first
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(asctime)s drem_live %(message)s")
    hub = _video_hub_socket() if args.workers > 1 and not args.reuse_port else None
    if args.workers > 1 and not args.reuse_port:
        _share_wake_ups()
    others = [_start_worker(args) for _ in range(max(0, args.workers - 1))]
    try:
        _serve(args.host, args.port, reuse_port=args.workers > 1 or args.reuse_port, hub=hub)
    finally:
        for worker in others:
            worker.terminate()
        for worker in others:
            try:
                worker.wait(5)
            except subprocess.TimeoutExpired:
                worker.kill()
    return 0


def _share_wake_ups() -> None:
    """Several workers woken over HTTP (DREM_LIVE_WAKE_SECRET, on AWS) without a wake directory: give them a private
    one, so the worker a wake-up reaches wakes the others through their wake sockets (drem_live.wake_route)."""
    if os.environ.get("DREM_LIVE_WAKE_SECRET") and not os.environ.get("DREM_LIVE_WAKE_DIR"):
        directory = tempfile.mkdtemp(prefix="drem-live-wake-")  # owner-only
        os.environ["DREM_LIVE_WAKE_DIR"] = directory  # for this process and the workers it starts
        atexit.register(shutil.rmtree, directory, ignore_errors=True)


def _video_hub_socket() -> socket.socket:
    """The first worker holds the cars' camera feeds (drem_live.video_routes): the others pass the camera routes to it
    on this loopback socket, so a car uploads once whichever worker it reaches."""
    hub = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    hub.bind(("127.0.0.1", 0))
    os.environ["DREM_LIVE_VIDEO_HUB"] = f"http://127.0.0.1:{hub.getsockname()[1]}"  # for the workers started next
    return hub


def _start_worker(args: argparse.Namespace) -> subprocess.Popen[bytes]:
    def die_with_parent() -> None:
        try:
            ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
        except (OSError, AttributeError):
            pass  # not Linux: the parent still terminates its workers when it stops
    command = [sys.executable, "-m", "drem_live", "--host", args.host, "--port", str(args.port), "--workers", "1",
               "--reuse-port"]
    return subprocess.Popen(command, preexec_fn=die_with_parent)


def _serve(host: str, port: int, *, reuse_port: bool, hub: socket.socket | None = None) -> None:
    from aiohttp import web

    from drem_live.app_code import MIN_WAKE_SECRET_CHARS, WAKE_SECRET_ENV, AppCode
    from drem_live.limits import env_limits
    from drem_live.server import make_app

    wake_dir = os.environ.get("DREM_LIVE_WAKE_DIR") or ""
    wake_secret = os.environ.get(WAKE_SECRET_ENV) or ""
    if wake_secret and len(wake_secret) < MIN_WAKE_SECRET_CHARS:
        raise SystemExit(f"{WAKE_SECRET_ENV} must be a secret of at least {MIN_WAKE_SECRET_CHARS} characters.")
    # An idle poller's connection is not kept long locally; behind a load balancer the server must keep it longer
    # than the balancer does (DREM_LIVE_KEEPALIVE_S), or the balancer may send a request onto a closing one (a 502).
    keepalive_s = float(os.environ.get("DREM_LIVE_KEEPALIVE_S") or DEFAULT_KEEPALIVE_S)
    # Woken by the writer, the poll is only the fallback (and times a race's phases): it can be slower.
    woken = bool(wake_dir or wake_secret)
    poll_ms = int(os.environ.get("DREM_LIVE_POLL_MS") or (WOKEN_POLL_MS if woken else DEFAULT_POLL_MS))
    namespace = os.environ.get("DREM_LIVE_METRICS_NAMESPACE") or ""
    metrics = (namespace, os.environ.get("DREM_LIVE_METRICS_STAGE") or "") if namespace else None
    if hub is not None:
        os.environ.pop("DREM_LIVE_VIDEO_HUB", None)  # this process is the hub itself
    poll_s = max(10, poll_ms) / 1000
    app = make_app(AppCode.from_settings(poll_s), poll_s=poll_s, limits=env_limits(), wake_dir=wake_dir,
                   wake_secret=wake_secret, metrics=metrics)
    _quiet_collector()
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    logging.getLogger("drem_live").info("listening on http://%s:%d (pid %d, poll %d ms)", host, port, os.getpid(),
                                        poll_ms)
    web.run_app(app, host=host, port=port, reuse_port=reuse_port or None, shutdown_timeout=2.0, print=None,
                access_log=None, backlog=1024, keepalive_timeout=keepalive_s, sock=hub,
                handler_cancellation=True)  # a viewer leaving frees its stream at once


def _quiet_collector() -> None:
    """Keep the cyclic garbage collector off the poll path. Measured with wrk on one worker (200 connections polling
    the board): at the default thresholds the collector ran ~40 times a second over the in-flight requests' objects,
    about a seventh of the worker's CPU, and each full collection walked every object loaded at startup (chalicelib,
    pydantic, botocore: ~100,000) for tens of milliseconds, a latency spike for every poll waiting behind it. The
    objects of startup live as long as the process: frozen, the collector no longer walks them; young collections run
    when 10,000 more objects are alive, not 700 (cycles are still collected, only later)."""
    gc.collect()
    gc.freeze()
    gc.set_threshold(YOUNG_COLLECTION_THRESHOLD, *gc.get_threshold()[1:])


if __name__ == "__main__":
    raise SystemExit(main())
