"""Serve the Chalice app over HTTP for local use and integration tests (instead of `chalice local`).

Fixes over stock `chalice local`: TCP_NODELAY (otherwise every request on a kept-alive connection waits ~40 ms
for Nagle + delayed ACK), a deep listen backlog (a burst of browser and poller connections is queued, not reset),
a URL no route matches answered by the app's own 404 (page or JSON) instead of API Gateway's 403 "Missing
Authentication Token", and a browser tab closed mid-poll logged as one quiet line, not a BrokenPipe traceback.
No autoreloader: one process, which exits cleanly on SIGTERM/SIGINT. Logs are JSON lines on stderr.

    python -m drem_local.appserver --host 127.0.0.1 --port 8000 [--stage local]
"""
from __future__ import annotations

import argparse
import logging
import os
import signal
import socketserver
import sys
import threading
from pathlib import Path
from typing import Any

PROJECT_DIR = Path(__file__).resolve().parent.parent
REQUEST_QUEUE_SIZE = 1024


def make_server(host: str = "127.0.0.1", port: int = 8000, stage: str = "local") -> Any:
    """A `chalice.local.LocalDevServer` bound to host:port (port 0 picks a free one: see `.server.server_address`)."""
    from chalice import local
    from chalice.cli.factory import CLIFactory

    _put_project_on_path()
    _prefer_installed_packages()
    local.ChaliceRequestHandler.disable_nagle_algorithm = True
    local.ThreadedHTTPServer.request_queue_size = REQUEST_QUEUE_SIZE
    local.ThreadedHTTPServer.daemon_threads = True
    local.ThreadedHTTPServer.handle_error = _handle_error  # type: ignore[method-assign]
    _answer_unknown_urls_with_404(local.LocalGateway)
    # The request middleware already writes one JSON line per request; drop http.server's plain-text access log.
    local.ChaliceRequestHandler.log_message = _quiet  # type: ignore[method-assign]
    factory = CLIFactory(str(PROJECT_DIR))
    config = factory.create_config_obj(chalice_stage_name=stage)
    # Chalice's local server logs every request at INFO through the root logger; ours are JSON already.
    logging.getLogger("botocore").setLevel(logging.WARNING)
    return factory.create_local_server(config.chalice_app, config, host, port)


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
    if str(PROJECT_DIR) not in sys.path:
        sys.path.insert(0, str(PROJECT_DIR))


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
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    _put_project_on_path()
    from chalicelib import logs

    logs.configure(sys.stderr)
    server = make_server(args.host, args.port, args.stage)
    stopping = threading.Event()

    def stop(signum: int, _frame: Any) -> None:
        if not stopping.is_set():
            stopping.set()
            # shutdown() blocks until serve_forever returns, so it must run off the serving thread.
            threading.Thread(target=server.shutdown, daemon=True).start()

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
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
