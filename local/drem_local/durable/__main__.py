"""`python -m drem_local.durable --state-dir DIR --host 127.0.0.1 --port N`: the durable moto server."""
from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
from pathlib import Path

log = logging.getLogger("drem.durable")

# Stable pool/client ids (a hash of the name) so a pool re-created from the journal keeps its id.
STABLE_ID_ENV = {
    "MOTO_COGNITO_IDP_USER_POOL_ID_STRATEGY": "HASH",
    "MOTO_COGNITO_IDP_USER_POOL_CLIENT_ID_STRATEGY": "HASH",
    # moto's Flask apps otherwise answer every Origin with Access-Control-Allow-Origin (flask_cors).
    "MOTO_DISABLE_GLOBAL_CORS": "true",
}
EXIT_VERSION_MISMATCH = 3
EXIT_DISK = 4  # the state dir's disk is full or read-only
DEFAULT_MAX_POST_BYTES = 256 * 1024 * 1024  # above the app's 128 MiB model limit plus the form's own fields


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m drem_local.durable", description=__doc__)
    parser.add_argument("--state-dir", type=Path, required=True)
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8001)
    parser.add_argument("--snapshot-interval", type=float, default=5.0,
                        help="seconds between snapshots while something changed (default 5)")
    parser.add_argument("--no-fsync", action="store_true", help="skip fsync of the journal (faster, not crash-safe)")
    parser.add_argument("--max-post-bytes", type=int, default=DEFAULT_MAX_POST_BYTES,
                        help="largest browser-form upload body read at all (the signed policy's own size range is "
                             "enforced on top; default 256 MiB)")
    return parser.parse_args(argv)


def _cannot_start(exc: OSError, state_dir: Path) -> int:
    """A full or read-only state dir, said in words (drem up quotes it); any other OSError stays a traceback."""
    from drem_local.disk import problem_of, sentence

    problem = problem_of(exc)
    if problem is None:
        raise exc
    print(f"drem durable server: cannot start. {sentence(problem, state_dir, 'start drem again.')}", file=sys.stderr)
    return EXIT_DISK


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    os.environ.update(STABLE_ID_ENV)
    os.umask(0o077)  # journal, snapshots and logs hold plaintext passwords: readable by this user only
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    logging.getLogger("werkzeug").setLevel(logging.ERROR)

    from werkzeug.serving import make_server

    from drem_local.durable.guard import StorageGuard
    from drem_local.durable.post_policy import PostPolicyGuard
    from drem_local.durable.server import DurableApp
    from drem_local.durable.state import DurableState, MotoVersionMismatch
    from drem_local.storage_keys import load_or_create

    try:
        keys = load_or_create(args.state_dir)  # also makes the state dir 0700 and its files 0600
        state = DurableState(args.state_dir, fsync=not args.no_fsync, seed_secret=keys.secret_access_key.encode())
    except MotoVersionMismatch as exc:
        print(f"drem durable server: refusing to start. {exc}", file=sys.stderr)
        return EXIT_VERSION_MISMATCH
    except OSError as exc:
        return _cannot_start(exc, args.state_dir)

    from moto.moto_server.werkzeug_app import DomainDispatcherApplication, MotoRequestHandler, create_backend_app

    from drem_local.durable import token_signing
    from drem_local.token_key import ensure_signing_key

    # Before recovery: replayed sign-ins and every later token are signed with this installation's own key.
    token_signing.install(ensure_signing_key(args.state_dir))

    os.environ.setdefault("MOTO_PORT", str(args.port))
    upload_guard = PostPolicyGuard({keys.access_key_id: keys.secret_access_key}.get,
                                   max_body_bytes=args.max_post_bytes)
    _list_moto_modules_once()
    app = DurableApp(DomainDispatcherApplication(create_backend_app), state, StorageGuard(keys), upload_guard)
    try:
        report = app.recover()
    except OSError as exc:
        return _cannot_start(exc, args.state_dir)
    log.info("recovered state from %s: snapshot seq %d, %d journal records (%d replayed, %d already in snapshots, "
             "%d failed), torn tail %d bytes, %.2fs", args.state_dir, report.snapshot_seq, report.journal_records,
             report.replayed, report.skipped, report.failed, report.torn_bytes, report.seconds)

    server = make_server(args.host, args.port, app, threaded=True, request_handler=MotoRequestHandler)
    stopping = threading.Event()

    def snapshot_loop() -> None:
        while not stopping.wait(args.snapshot_interval):
            try:
                app.snapshot_if_dirty()
            except Exception:
                log.exception("periodic snapshot failed; the journal still holds every change")

    def stop(signum: int, _frame: object) -> None:
        stopping.set()
        threading.Thread(target=server.shutdown, daemon=True).start()

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    threading.Thread(target=snapshot_loop, name="snapshots", daemon=True).start()
    log.info("durable moto %s listening on http://%s:%d, state in %s", state.moto_version, args.host,
             server.server_port, args.state_dir)
    try:
        server.serve_forever()
    finally:
        stopping.set()
        try:
            app.snapshot_if_dirty(force=True)  # no request comes any more: the journal is emptied
            log.info("stopped; state snapshotted to %s", args.state_dir)
        except OSError as exc:
            log.warning("stopped without a final snapshot (%s); the journal holds every change and is replayed on the "
                        "next start", exc.strerror or exc)
        state.close()
    return 0


def _list_moto_modules_once() -> None:
    """moto's dispatcher asks `moto.backends.list_of_moto_modules()` on every request, which lists moto's package
    directory and stats each entry (about 60 system calls a DynamoDB request, profiled); the package does not change
    while the server runs, so it is listed once."""
    from moto import backends

    modules = tuple(backends.list_of_moto_modules())
    backends.list_of_moto_modules = lambda: modules


if __name__ == "__main__":
    sys.exit(main())
