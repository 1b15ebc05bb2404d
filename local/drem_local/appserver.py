"""Serve the Chalice app over HTTP for local use and integration tests (instead of `chalice local`).

Fixes over stock `chalice local`: TCP_NODELAY (otherwise every request on a kept-alive connection waits ~40 ms
for Nagle + delayed ACK), a deep listen backlog (a burst of browser and poller connections is queued, not reset),
a URL no route matches answered by the app's own 404 (page or JSON) instead of API Gateway's 403 "Missing
Authentication Token", and a browser tab closed mid-poll logged as one quiet line, not a BrokenPipe traceback.
No autoreloader: one process, which exits cleanly on SIGTERM/SIGINT. Logs are JSON lines on stderr.
A sweeper thread repairs what a crash can leave half done: it finishes interrupted registrations (at start, then every
`REGISTRATION_REPAIR_S`, so a storage-only crash needs no app restart), and it
finishes board publishes left pending (at start, then every `SWEEP_INTERVAL_S`), so boards equal what the races say
within seconds of a restart even if no race changes (see `RaceService`, `UserService`).
Every PURGE_INTERVAL_S it also purges model uploads never completed (`ModelService.purge_stale_uploads`), which S3
would otherwise keep for ever.

With --storage-url it also forwards `/_storage/...` to the local storage server (drem_local.storage_gateway), so
presigned uploads and downloads work from the venue network while storage itself stays on loopback.

    python -m drem_local.appserver --host 127.0.0.1 --port 8000 [--stage local] [--storage-url URL]
"""
from __future__ import annotations

import argparse
import functools
import logging
import os
import signal
import socketserver
import sys
import threading
import time
from typing import Any

from drem_local.app_source import FUNCTIONS_DIR as PROJECT_DIR
from drem_local.app_source import use_app_source

REQUEST_QUEUE_SIZE = 1024
SWEEP_INTERVAL_S = 2.0
# Half-registered accounts (a crash between the account and its role group) are repaired this often while the app
# runs, leaving alone those created in the last REGISTRATION_IN_FLIGHT_S (their registration may still be running).
REGISTRATION_REPAIR_S = float(os.environ.get("DREM_REGISTRATION_REPAIR_S", "10"))
REGISTRATION_IN_FLIGHT_S = float(os.environ.get("DREM_REGISTRATION_IN_FLIGHT_S", "30"))
PURGE_INTERVAL_S = 10 * 60


def make_server(host: str = "127.0.0.1", port: int = 8000, stage: str = "local", storage_url: str | None = None) -> Any:
    """A `chalice.local.LocalDevServer` bound to host:port (port 0 picks a free one: see `.server.server_address`);
    with `storage_url`, `/_storage/...` goes to that storage server instead of the app."""
    from chalice import local
    from chalice.cli.factory import CLIFactory

    _put_project_on_path()
    _prefer_installed_packages()
    local.ChaliceRequestHandler.disable_nagle_algorithm = True
    local.ThreadedHTTPServer.request_queue_size = REQUEST_QUEUE_SIZE
    local.ThreadedHTTPServer.daemon_threads = True
    local.ThreadedHTTPServer.handle_error = _handle_error
    _answer_unknown_urls_with_404(local.LocalGateway)
    # The request middleware already writes one JSON line per request; drop http.server's plain-text access log.
    local.ChaliceRequestHandler.log_message = _quiet
    factory = CLIFactory(str(PROJECT_DIR))
    config = factory.create_config_obj(chalice_stage_name=stage)
    # Chalice's local server logs every request at INFO through the root logger; ours are JSON already.
    logging.getLogger("botocore").setLevel(logging.WARNING)
    server = factory.create_local_server(config.chalice_app, config, host, port)
    if storage_url:
        _add_storage_gateway(server, local.ChaliceRequestHandler, storage_url)
    return server


def _add_storage_gateway(server: Any, handler_class: type, storage_url: str) -> None:
    from drem_local.storage_gateway import forward, is_gateway_path

    class GatewayRequestHandler(handler_class):
        def _route(self) -> None:
            if is_gateway_path(self.path.split("?", 1)[0]):
                forward(self, storage_url)
            else:
                self._generic_handle()

        do_GET = do_PUT = do_POST = do_HEAD = do_DELETE = do_PATCH = do_OPTIONS = _route

    wrapped = server._wrapped_handler  # functools.partial(handler_class, app_object=..., config=...)
    server.server.RequestHandlerClass = functools.partial(GatewayRequestHandler, *wrapped.args, **wrapped.keywords)


def sweep_pending_publishes(stopping: threading.Event, interval_s: float = SWEEP_INTERVAL_S) -> None:
    """Finish publish intents left by a crash: now, then every `interval_s` until `stopping` is set."""
    from chalicelib import logs, services
    from chalicelib.domain.races import STALE_INTENT_MS

    _finish_interrupted_registrations(0.0)  # at start nothing is in flight
    next_registration_repair = time.monotonic() + REGISTRATION_REPAIR_S
    older_than_ms = 0  # at start nothing is in flight: every intent left is a crash's
    while True:
        try:
            finished = services.race_service().complete_pending_publishes(older_than_ms)
            older_than_ms = STALE_INTENT_MS
            if finished:
                logs.log(logging.WARNING, "finished board publishes a crash had left pending", count=finished)
        except Exception as exc:  # storage down or not set up yet: the intents stay, the next sweep tries again
            logs.log(logging.INFO, "publish sweep skipped", reason=str(exc)[:200])
        if time.monotonic() >= next_registration_repair:
            # Also while running: a storage-only crash leaves half-registered racers without any app restart.
            _finish_interrupted_registrations(REGISTRATION_IN_FLIGHT_S)
            next_registration_repair = time.monotonic() + REGISTRATION_REPAIR_S
        if stopping.wait(interval_s):
            return


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


def _quiet(*_args: Any) -> None:
    return None


# A client that goes away before its answer is written (a tab closed or reloaded mid-poll) is normal on event day.
_CLIENT_GONE = (BrokenPipeError, ConnectionResetError, ConnectionAbortedError, TimeoutError)


def _handle_error(self: Any, request: Any, client_address: Any) -> None:
    """socketserver prints a traceback for any error while serving a request; a vanished client is not an error."""
    error = sys.exc_info()[1]
    if isinstance(error, _CLIENT_GONE):
        from chalicelib import logs

        logs.log(logging.INFO, "client went away", client=str(client_address[0]), error=type(error).__name__)
        return
    socketserver.BaseServer.handle_error(self, request, client_address)


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
    parser.add_argument("--serve-only", action="store_true",
                        help="no repair sweeps (publishes, registrations, stale uploads): the learning booth's "
                             "container on AWS serves the booth's routes and does nothing else")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    _put_project_on_path()
    from chalicelib import logs

    logs.configure(sys.stderr)
    server = make_server(args.host, args.port, args.stage, args.storage_url)
    stopping = threading.Event()

    def stop(signum: int, _frame: Any) -> None:
        if not stopping.is_set():
            stopping.set()
            # shutdown() blocks until serve_forever returns, so it must run off the serving thread.
            threading.Thread(target=server.shutdown, daemon=True).start()

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    if not args.serve_only:
        threading.Thread(target=sweep_pending_publishes, args=(stopping,), name="publish-sweeper",
                         daemon=True).start()
        threading.Thread(target=_purge_stale_uploads, args=(stopping,), name="upload-purge", daemon=True).start()
    host, port = server.server.server_address[:2]
    logs.log(logging.INFO, "app server listening", url=f"http://{host}:{port}", stage=args.stage)
    try:
        server.server.serve_forever(poll_interval=0.2)
    finally:
        server.server.server_close()
        logs.log(logging.INFO, "app server stopped")
    return 0


if __name__ == "__main__":
    sys.exit(main())
