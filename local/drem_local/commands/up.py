"""`drem up`: the whole local stack in one command, state kept in a directory across restarts."""
from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from pathlib import Path

HELP = "start the local stack (durable storage + live server + app) and keep it running until Ctrl-C"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--state-dir", type=Path, default=Path(os.environ.get("DREM_STATE_DIR", ".drem")),
                        help="where all local data lives (default .drem, or $DREM_STATE_DIR)")
    parser.add_argument("--port", type=int, default=8000, help="app port (default 8000; on 127.0.0.1 unless --lan)")
    parser.add_argument("--storage-port", type=int, default=8001,
                        help="durable moto (AWS API) port on 127.0.0.1, always loopback only (default 8001)")
    parser.add_argument("--live-port", type=int, default=None,
                        help="live server port: pushes the public pages' updates (default: app port + 2, i.e. 8002; "
                             "on the app's address)")
    parser.add_argument("--live-workers", type=int, default=os.cpu_count() or 1,
                        help="live server processes sharing its port (default: one per core)")
    network = parser.add_argument_group("the venue network (docs/operations.md)")
    network.add_argument("--lan", action="store_true",
                         help="serve the app to the venue network (phones, laptops, timers, cars), on every interface, "
                              "announced as this machine's address on its default route")
    network.add_argument("--host", metavar="ADDR", default=None,
                         help="serve the app on this address of the machine only (implies --lan); QR codes and "
                              "copy-paste commands carry it")
    network.add_argument("--public-url", metavar="URL", default=None,
                         help="the URL people use when a TLS proxy sits in front of the app (e.g. https://drem.lan); "
                              "https here makes the session cookies Secure")
    parser.add_argument("--no-trainer", action="store_true",
                        help="do not start the learning booth's training worker (docs/learning.md)")
    parser.add_argument("--demo", action="store_true",
                        help="also run a demo: sample models, demo racers, sim cars and a race director that races "
                             "them, so the leaderboard and overlay fill live (see docs/cars.md)")


class _Stop(Exception):
    pass


def _raise_stop(signum: int, _frame: object) -> None:
    raise _Stop(signal.Signals(signum).name)


def run(args: argparse.Namespace) -> int:
    from drem_local.stack import StackConfig, StackError, lan_config, start_stack

    config = StackConfig(state_dir=args.state_dir, app_port=args.port, storage_port=args.storage_port,
                         public_url=args.public_url, live_port=args.live_port, live_workers=max(1, args.live_workers),
                         trainer=not args.no_trainer)
    if args.lan or args.host:
        try:
            config = lan_config(config, args.host, args.public_url)
        except StackError as exc:
            print(f"drem up: could not start. {exc}", file=sys.stderr)
            return 1
    username = os.environ.get("DREM_ADMIN_USERNAME", "admin")
    password = os.environ.get("DREM_ADMIN_PASSWORD") or None
    signal.signal(signal.SIGTERM, _raise_stop)
    signal.signal(signal.SIGINT, _raise_stop)
    print(f"Starting drem with its data in {config.state_dir.resolve()} ...", flush=True)
    try:
        # No deadline: each child is waited for while it makes progress, and every 10 s we say what we wait for.
        stack = start_stack(config, username, password, say=lambda line: print(line, file=sys.stderr, flush=True))
    except StackError as exc:
        print(f"drem up: could not start. {exc}", file=sys.stderr)
        return 1
    except _Stop:
        print("drem up: interrupted while starting; everything started so far was stopped.", file=sys.stderr)
        return 1

    from drem_local.supervise import GaveUp, Supervisor

    demo = None
    supervisor = Supervisor(stack, say=lambda line: print(line, file=sys.stderr, flush=True))
    try:
        _print_ready(stack, admin_password_from_env=password is not None)
        if args.demo:
            demo = _start_demo(stack)
            if demo is None:
                stack.stop()
                return 1
        while True:
            supervisor.check()  # a crashed storage or app server is restarted; only repeated crashes end the loop
            if demo is not None:
                demo.step()
            time.sleep(1.0 if demo is not None else 0.5)
    except GaveUp as exc:
        if demo is not None:
            demo.stop()
        print(f"drem up: {exc}", file=sys.stderr)
        stack.stop()
        return 1
    except _Stop:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not cut the snapshot short
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        if demo is not None:
            print("\nStopping the demo cars ...", flush=True)
            demo.stop()
        print("\nStopping: app first, then the live server, then storage (it saves a snapshot) ...", flush=True)
        app_code, storage_code = stack.stop()
        if storage_code not in (0, None):
            print(f"The storage server exited with code {storage_code}; see {stack.storage.log_path}. "
                  "Its journal still holds every acknowledged write.", file=sys.stderr)
            return 1
        print("drem stopped cleanly. Your data is in " f"{config.state_dir.resolve()}.")
        return 0


def _start_demo(stack):
    """The demo (drem_local.demo) on the running stack, its URLs printed; None (and why, printed) if it failed."""
    from drem_local.api_client import ApiError
    from drem_local.demo import Demo, DemoError

    print("Setting up the demo: sample models, racers, an event and sim cars ...", flush=True)
    demo = Demo(stack, rate_hz=float(os.environ.get("DREM_DEMO_RATE_HZ", "15")))
    try:
        demo.start()
    except (DemoError, ApiError) as exc:
        print(f"drem up --demo: the demo could not start. {exc}", file=sys.stderr)
        demo.stop()
        return None
    except BaseException:
        demo.stop()
        raise
    lines = [f"Demo running: {len(demo.cars)} sim cars racing demo racers at event {demo.event_id}. Open:"]
    lines += [f"  {name + ':':<20} {url}" for name, url in demo.urls().items()]
    lines.append(f"  (car logs: {stack.config.log_dir.resolve()}/demo-sim-*.log)")
    print("\n".join(lines), flush=True)
    return demo


def _print_ready(stack, *, admin_password_from_env: bool) -> None:
    config, admin = stack.config, stack.admin
    lines = [
        f"drem is running (ready in {stack.timings['total_s']:.1f}s).",
        f"  Open the app:        {config.app_url}",
    ]
    if config.app_host != config.host:
        lines += [f"  Venue network:       listening on {config.app_host}:{config.app_port}; QR codes, activation "
                  "commands and upload links carry the URL above"]
        if not config.app_url.startswith("https://"):
            lines.append("  Plain HTTP:          anyone on an open WiFi can read sessions; use a WPA2/WPA3 network "
                         "(docs/security.md)")
    live_url = stack.env.get("DREM_LIVE_URL") or "none (the pages poll the app)"
    lines += [
        f"  Live pages:          {live_url}   (pushes board and overlay updates; {config.live_workers} "
        f"process{'es' if config.live_workers > 1 else ''})",
        f"  Storage (moto):      {config.storage_url}   (this machine only; signed requests only)",
        f"  Data directory:      {config.state_dir.resolve()}",
        f"  Logs:                {config.log_dir.resolve()}",
    ]
    lines.append(f"  Admin login:         {admin_login(admin, admin_password_from_env)}")
    if admin.created and not admin_password_from_env:
        lines.append("  (This password is shown only now. Write it down: drem keeps it only in the data directory, "
                     "which only your user account can read.)")
    lines.append("Press Ctrl-C to stop. `drem status` in another terminal shows what is running.")
    print("\n".join(lines), flush=True)


def admin_login(admin, password_from_env: bool) -> str:
    """What the banner says about the admin account: exactly what this start did to it."""
    if admin.created:
        if password_from_env:
            return f"{admin.username} (created now, with the password in DREM_ADMIN_PASSWORD)"
        return f"{admin.username} / {admin.password}"
    if password_from_env:
        return f"{admin.username} (password set from DREM_ADMIN_PASSWORD)"
    return f"{admin.username} (password unchanged)"
