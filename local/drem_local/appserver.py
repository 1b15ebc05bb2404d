"""Serve the Chalice app over HTTP for local use and integration tests (instead of `chalice local`).

The app runs unchanged behind waitress, a production WSGI server (drem_local.http_front: bounded worker threads,
header and idle timeouts, body limits enforced before a body is read, the real client address), through chalice's
own LocalGateway (drem_local.chalice_wsgi). A URL no route matches is answered by the app's own 404 (page or JSON)
instead of API Gateway's 403 "Missing Authentication Token". TCP_NODELAY and a deep listen backlog are waitress's
defaults. No autoreloader: one process, which exits cleanly on SIGTERM/SIGINT. Logs are JSON lines on stderr.
A sweeper thread repairs what a crash can leave half done: it finishes interrupted registrations (at start, then every
`REGISTRATION_REPAIR_S`, so a storage-only crash needs no app restart), and it
finishes board publishes left pending (at start, then every `SWEEP_INTERVAL_S`), so boards equal what the races say
within seconds of a restart even if no race changes (see `RaceService`, `UserService`).
Every PURGE_INTERVAL_S it also purges model uploads never completed (`ModelService.purge_stale_uploads`), which S3
would otherwise keep for ever.

With --storage-url it also forwards `/_storage/...` to the local storage server (drem_local.storage_gateway), so
presigned uploads and downloads work from the venue network while storage itself stays on loopback.

    python -m drem_local.appserver --host 127.0.0.1 --port 8000 [--stage local] [--storage-url URL]
                                   [--threads N] [--trusted-proxy ADDRESS]
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import replace
from typing import Any

from drem_local.app_source import FUNCTIONS_DIR as PROJECT_DIR
from drem_local.app_source import use_app_source
from drem_local.chalice_wsgi import ChaliceWSGI
from drem_local.durable.guard import GATEWAY_PATH
from drem_local.http_front import FrontLimits, FrontServer, WSGIApp

SWEEP_INTERVAL_S = 2.0
# Half-registered accounts (a crash between the account and its role group) are repaired this often while the app
# runs, leaving alone those created in the last REGISTRATION_IN_FLIGHT_S (their registration may still be running).
REGISTRATION_REPAIR_S = float(os.environ.get("DREM_REGISTRATION_REPAIR_S", "10"))
REGISTRATION_IN_FLIGHT_S = float(os.environ.get("DREM_REGISTRATION_IN_FLIGHT_S", "30"))
PURGE_INTERVAL_S = 10 * 60


def make_server(host: str = "127.0.0.1", port: int = 8000, stage: str = "local", storage_url: str | None = None,
                limits: FrontLimits | None = None) -> FrontServer:
    """The Chalice app behind waitress (drem_local.http_front) on host:port (port 0 picks a free one: see
    `.server_address`); with `storage_url`, `/_storage/...` goes to that storage server instead of the app."""
    from chalice import local
    from chalice.cli.factory import CLIFactory

    _put_project_on_path()
    _prefer_installed_packages()
    _answer_unknown_urls_with_404(local.LocalGateway)
    factory = CLIFactory(str(PROJECT_DIR))
    config = factory.create_config_obj(chalice_stage_name=stage)
    logging.getLogger("botocore").setLevel(logging.WARNING)
    # What `chalice local` does to the app object (chalice/local.py create_local_server): a per-thread
    # current_request, since requests run on several worker threads at once.
    app_object = config.chalice_app
    local.CustomLocalChalice.__bases__ = (local.LocalChalice, app_object.__class__)
    app_object.__class__ = local.CustomLocalChalice
    app: WSGIApp = ChaliceWSGI(local.LocalGateway(app_object, config))
    limits = limits or FrontLimits()
    if storage_url:
        from drem_local.durable.__main__ import DEFAULT_MAX_POST_BYTES
        from drem_local.storage_gateway import StorageGateway

        app = _with_gateway(app, StorageGateway(storage_url))
        # An upload form: the model (at most the storage server's ceiling) plus the form's own fields.
        limits = replace(limits, body_limit_by_prefix=((GATEWAY_PATH + "/", DEFAULT_MAX_POST_BYTES + 1024 * 1024),))
    return FrontServer(app, host, port, limits, ident="drem")


def _with_gateway(app: WSGIApp, gateway: WSGIApp) -> WSGIApp:
    from drem_local.storage_gateway import is_gateway_path

    def dispatch(environ: dict[str, Any], start_response: Callable[..., Any]) -> Iterable[bytes]:
        if is_gateway_path(environ.get("PATH_INFO", "")):
            return gateway(environ, start_response)
        return app(environ, start_response)

    return dispatch


def sweep_pending_publishes(stopping: threading.Event, interval_s: float = SWEEP_INTERVAL_S,
                            storage_url: str | None = None) -> None:
    """Finish publish intents left by a crash: now, then every `interval_s` until `stopping` is set. Also finish
    registrations a crash interrupted: at once when the storage server restarted (see `StorageRestarts`), and every
    REGISTRATION_REPAIR_S for any other cause."""
    from chalicelib import logs, services
    from chalicelib.domain.races import STALE_INTENT_MS

    _finish_interrupted_registrations(0.0)  # at start nothing is in flight
    next_registration_repair = time.monotonic() + REGISTRATION_REPAIR_S
    older_than_ms = 0  # at start nothing is in flight: every intent left is a crash's
    restarts = StorageRestarts(storage_url)
    while True:
        try:
            finished = services.race_service().complete_pending_publishes(older_than_ms)
            older_than_ms = STALE_INTENT_MS
            if finished:
                logs.log(logging.WARNING, "finished board publishes a crash had left pending", count=finished)
        except Exception as exc:  # storage down or not set up yet: the intents stay, the next sweep tries again
            logs.log(logging.INFO, "publish sweep skipped", reason=str(exc)[:200])
        restarted_at = restarts.restarted_at()
        if restarted_at is not None:
            # Every request that wrote before the crash has had its answer (an error), or is retrying its next
            # step against the new server: an account from the journal (created, or replayed, before the restart
            # was ready) without a group will not get one from its own registration, so it is finished now
            # instead of after the in-flight grace.
            _finish_interrupted_registrations(max(0.0, time.time() - restarted_at))
        elif time.monotonic() >= next_registration_repair:
            # Also while running: a storage-only crash leaves half-registered racers without any app restart.
            _finish_interrupted_registrations(REGISTRATION_IN_FLIGHT_S)
            next_registration_repair = time.monotonic() + REGISTRATION_REPAIR_S
        if stopping.wait(interval_s):
            return


class StorageRestarts:
    """Notices that the storage server was restarted (a crash: the journal was replayed), from the start time its
    unsigned health answer carries (drem_local.durable)."""

    def __init__(self, storage_url: str | None) -> None:
        self.storage_url = storage_url
        self.seen: float | None = None

    def restarted_at(self) -> float | None:
        """The new server's start time the first time a restart is seen, else None."""
        if not self.storage_url:
            return None
        from drem_local.stack import HEALTH_PATH, http_get

        answer = http_get(self.storage_url + HEALTH_PATH, timeout=2.0)
        if answer is None or answer[0] != 200:
            return None
        try:
            started = float(json.loads(answer[1])["started_at"])
        except (ValueError, KeyError, TypeError):
            return None
        previous, self.seen = self.seen, started
        return None if previous is None or previous == started else started


def _finish_interrupted_registrations(older_than_s: float) -> None:
    """Accounts a crash left without profile or role group get them, and the log says who."""
    from chalicelib import logs, services

    try:
        finished = services.user_service().finish_interrupted_registrations(older_than_s=older_than_s)
    except Exception as exc:
        logs.log(logging.WARNING, "could not check for interrupted registrations", reason=str(exc)[:200])
        return
    if finished:
        logs.log(logging.WARNING, f"finished {len(finished)} registration(s) a crash had interrupted: "
                 f"{', '.join(finished)}. If a temporary password was never handed over, register the racer again "
                 "at the desk (same name and email) to get a new one.", usernames=finished)


def _purge_stale_uploads(stopping: threading.Event) -> None:
    from chalicelib import logs, services

    while not stopping.wait(PURGE_INTERVAL_S):
        try:
            services.model_service().purge_stale_uploads()
        except Exception as exc:  # the next round tries again; serving must go on
            logs.log(logging.WARNING, "purging stale uploads failed", error=repr(exc))


def _answer_unknown_urls_with_404(gateway_class: Any) -> None:
    """Chalice's local gateway raises ForbiddenError ("Missing Authentication Token") for a path no route matches;
    hand such a request to the app's not-found route (HTML for browsers, JSON under /api/), once per class."""
    if getattr(gateway_class, "_drem_not_found", False):
        return
    from chalice.local import ForbiddenError

    original = gateway_class.handle_request

    def handle_request(self: Any, method: str, path: str, headers: Any, body: Any) -> Any:
        try:
            return original(self, method, path, headers, body)
        except ForbiddenError:
            if _route_exists(self, path):
                raise
            from chalicelib.routes.pages import API_NOT_FOUND_PATH, NOT_FOUND_PATH

            target = API_NOT_FOUND_PATH if path.startswith("/api/") else NOT_FOUND_PATH
            return original(self, "GET", target, headers, None)

    gateway_class.handle_request = handle_request
    gateway_class._drem_not_found = True


def _route_exists(gateway: Any, path: str) -> bool:
    try:
        gateway.event_converter._route_matcher.match_route(path)
    except ValueError:
        return False
    return True


def _put_project_on_path() -> None:
    # chalicelib is not installed: like Chalice itself, import it from the project dir.
    use_app_source()


def _prefer_installed_packages() -> None:
    # Chalice appends functions/vendor/ to sys.path, and a path entry beats the editable-install finder: a stale
    # `drem build` copy would silently replace current code. Importing the packages first, with vendor/ off the path,
    # pins them (and so all their submodules) to the source tree.
    vendor = os.path.abspath(PROJECT_DIR / "vendor")
    saved = sys.path[:]
    sys.path[:] = [entry for entry in sys.path if os.path.abspath(entry or ".") != vendor]
    try:
        import drem_infra.resources  # noqa: F401
        import drem_leaderboard  # noqa: F401
        import drem_web  # noqa: F401
    finally:
        sys.path[:] = saved


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m drem_local.appserver", description=__doc__.split("\n")[0])
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=int(os.environ.get("DREM_APP_PORT", "8000")))
    parser.add_argument("--stage", default=os.environ.get("DREM_STAGE", "local"))
    parser.add_argument("--storage-url", default=None,
                        help="forward /_storage/... (presigned uploads and downloads) to this storage server")
    parser.add_argument("--threads", type=int, default=int(os.environ.get("DREM_APP_THREADS", "16")),
                        help="worker threads running the app (connections are read and written by one I/O loop)")
    parser.add_argument("--trusted-proxy", default=os.environ.get("DREM_TRUSTED_PROXY") or None,
                        help="the address of a reverse proxy in front: only its X-Forwarded-For names the client "
                             "(rate limits are per client address); without it the peer address is the client")
    parser.add_argument("--serve-only", action="store_true",
                        help="no repair sweeps (publishes, registrations, stale uploads): the learning booth's "
                             "container on AWS serves the booth's routes and does nothing else")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    _put_project_on_path()
    from chalicelib import logs

    logs.configure(sys.stderr)
    server = make_server(args.host, args.port, args.stage, args.storage_url,
                         FrontLimits(threads=args.threads, trusted_proxy=args.trusted_proxy))
    stopping = threading.Event()

    def stop(signum: int, _frame: Any) -> None:
        if not stopping.is_set():
            stopping.set()
            # shutdown() blocks until serve_forever returns, so it must run off the serving thread.
            threading.Thread(target=server.shutdown, daemon=True).start()

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    if not args.serve_only:
        threading.Thread(target=sweep_pending_publishes, args=(stopping, SWEEP_INTERVAL_S, args.storage_url),
                         name="publish-sweeper",
                         daemon=True).start()
        threading.Thread(target=_purge_stale_uploads, args=(stopping,), name="upload-purge", daemon=True).start()
    host, port = server.server_address
    logs.log(logging.INFO, "app server listening", url=f"http://{host}:{port}", stage=args.stage)
    try:
        server.serve_forever(poll_interval=0.2)
    finally:
        logs.log(logging.INFO, "app server stopped")
    return 0


if __name__ == "__main__":
    sys.exit(main())
