"""moto's WSGI app behind the write-ahead middleware, plus the snapshot timer and `/_drem/health`.

Browser-form uploads (presigned POST: any multipart/form-data POST, whatever its query) are also checked against
their signed policy's conditions (`post_policy`: bucket, key, size range, extra fields, redirects), which moto
ignores, and may carry no query or operation header: a refused upload is answered as S3 would and never reaches the
journal or moto."""
from __future__ import annotations

import io
import json
import logging
import threading
from collections.abc import Callable, Iterable
from typing import Any

from werkzeug.test import run_wsgi_app

from drem_local.durable.classify import MOTO_API, PERSISTED, S3, is_state_changing, needs_immediate_snapshot, service_of
from drem_local.durable.disk_guard import disk_refusal
from drem_local.durable.guard import StorageGuard, refuse, without_cors
from drem_local.durable.journal import JournalRecord
from drem_local.durable.kill_point import KillPoint
from drem_local.durable.lanes import Lanes
from drem_local.durable.post_policy import PostPolicyGuard, is_form_upload, refusal_response
from drem_local.durable.state import DurableState, replay_environ

log = logging.getLogger("drem.durable")

HEALTH_PATH = "/_drem/health"
# Snapshot rounds written without the request lanes before giving up until the next tick (writes kept coming during
# each round); the journal then keeps its newer records, which recovery replays on top of the snapshots.
SNAPSHOT_ROUNDS = 3
# Past this the last round holds every lane while it writes (up to a second or more once S3 holds model archives, and
# the public board waits meanwhile), so a journal that writes never let empty stays bounded.
FORCE_EMPTY_JOURNAL_ABOVE_BYTES = 256 * 1024 * 1024


def read_body(environ: dict[str, Any]) -> bytes:
    stream = environ["wsgi.input"]
    length = environ.get("CONTENT_LENGTH") or ""
    if length.strip().isdigit():
        return stream.read(int(length)) if int(length) else b""
    if environ.get("wsgi.input_terminated"):
        return stream.read()
    return b""


class DurableApp:
    """WSGI middleware: journal (fsynced) before moto runs a state-changing request; answer after. Each request holds
    its lane (durable.lanes: S3's own, or the one for everything else) from its journal record to moto's answer."""

    def __init__(self, moto_app: Callable[..., Iterable[bytes]], state: DurableState,
                 guard: StorageGuard | None = None, upload_guard: PostPolicyGuard | None = None) -> None:
        self.moto_app = moto_app
        self.state = state
        self.guard = guard  # None only in tests that drive the middleware in-process
        self.upload_guard = upload_guard
        self.lanes = Lanes()
        self._snapshotting = threading.Lock()
        self.kill_point = KillPoint.from_environment()  # None unless a chaos harness started this server

    def recover(self):
        with self.lanes.everything():
            return self.state.recover(self._replay)

    def _replay(self, record: JournalRecord) -> int:
        app_iter, status, _headers = run_wsgi_app(self.moto_app, replay_environ(record), buffered=True)
        try:
            b"".join(app_iter)
        finally:
            getattr(app_iter, "close", lambda: None)()
        return int(status.split(" ", 1)[0])

    def snapshot_if_dirty(self, *, force: bool = False) -> bool:
        """Snapshot what changed and empty the journal. S3 is pickled holding only its own lane, then the other
        services holding only theirs (model archives take tens of ms each to pickle, and the public board's reads
        must not wait for them); the files are written without any lane, so requests keep being answered meanwhile.
        What they change is caught by the next round, up to `SNAPSHOT_ROUNDS`; past that the journal keeps its newer
        records until the next tick, unless it has grown past FORCE_EMPTY_JOURNAL_ABOVE_BYTES (or `force`): then a last
        round holds every lane throughout, so the journal is emptied."""
        with self._snapshotting:  # one snapshot at a time (the periodic one and the final one at stop)
            did = False
            for _ in range(SNAPSHOT_ROUNDS):
                did = self._snapshot_part(self.lanes.s3, (S3,), empties_journal=False) is not None or did
                emptied = self._snapshot_part(self.lanes.main, tuple(s for s in PERSISTED if s != S3),
                                              force=force and not did)
                if emptied is None:
                    return did
                did = True
                if emptied:
                    return True
            if not force and self.state.journal.bytes <= FORCE_EMPTY_JOURNAL_ABOVE_BYTES:
                return did
            with self.lanes.everything():
                return self.state.snapshot_all() or did

    def _snapshot_part(self, lane: threading.Lock, services: tuple[str, ...], *, force: bool = False,
                       empties_journal: bool = True) -> bool | None:
        """One capture, write and commit of `services`, pickled holding `lane` only (requests of the other lane are
        journaled and answered meanwhile): None if there was nothing to do, else whether the journal was emptied."""
        with lane:
            with self.lanes.state:
                plan = self.state.plan_snapshot(services, force=force, empties_journal=empties_journal)
            if plan is None:
                return None
            try:
                capture = self.state.snapshots.capture(*plan)
            except BaseException:
                with self.lanes.state:
                    self.state.abandon_snapshot(plan[0])
                raise
        try:
            written = self.state.write_snapshot(capture)
        except OSError:
            with self.lanes.state:
                self.state.abandon_snapshot(plan[0])
            raise
        with self.lanes.state:
            return self.state.finish_snapshot(written, empties_journal=empties_journal)

    def __call__(self, environ: dict[str, Any], start_response: Callable[..., Any]) -> Iterable[bytes]:
        if environ.get("PATH_INFO") == HEALTH_PATH:
            return self._health(start_response)
        upload_guard = self.upload_guard
        form_upload = upload_guard is not None and is_form_upload(environ)
        if form_upload and upload_guard and (too_big := upload_guard.refusal_before_reading(environ)):
            return refusal_response(too_big, start_response)
        body = read_body(environ)
        environ["wsgi.input"] = io.BytesIO(body)  # moto's dispatcher and Flask may each read it
        environ["CONTENT_LENGTH"] = str(len(body))
        refusal = self.guard.check(environ, body) if self.guard is not None else None
        if refusal is not None:  # before the journal: a refused request leaves no trace in the state
            return refuse(refusal, environ, start_response)
        service = service_of(environ)
        # After the signature check (which also strips the app's /_storage gateway prefix): the policy's conditions.
        # Every form upload, whichever service its headers or query name: moto would otherwise route on them.
        if form_upload and upload_guard and (broken := upload_guard.refusal(environ, body)):
            return refusal_response(broken, start_response)
        changing = is_state_changing(environ)
        captured: dict[str, Any] = {}

        def capture(status: str, headers: list[tuple[str, str]], exc_info: Any = None) -> Callable[[bytes], None]:
            captured["status"], captured["headers"] = status, headers
            return lambda data: None

        locks = self.lanes.locks_for(service, environ)
        with self.lanes.holding(locks):
            if changing and service in PERSISTED:
                try:
                    with self.lanes.state:
                        # Alone in the S3 lane, moto's seeded randomness belongs to a request in the main lane.
                        seq = self.state.record(service, environ, body, seed=self.lanes.main in locks)
                except OSError as exc:
                    disk_full = disk_refusal(exc, self.state.state_dir)
                    if disk_full is None:
                        raise
                    log.warning("refused a write: %s", disk_full.message)
                    return refuse(disk_full, environ, start_response)
                if self.kill_point is not None:
                    self.kill_point.after_record(seq)
            app_iter = self.moto_app(environ, capture)
            try:
                payload = b"".join(app_iter)
            finally:
                getattr(app_iter, "close", lambda: None)()
            if changing and service in PERSISTED and needs_immediate_snapshot(environ, service):
                with self.lanes.state:
                    self._snapshot_service(service)
            elif changing and service == MOTO_API:
                with self.lanes.state:
                    self.state.after_moto_api_call()
        start_response(captured["status"], without_cors(captured["headers"]))
        return [payload]

    def _snapshot_service(self, service: str) -> None:
        try:
            self.state.snapshot_service(service)
        except Exception:
            # The journal holds the request and its randomness is seeded from its record (DurableState.record), so
            # a replay draws the same ids: the answer may go out, and nothing acknowledged changes after a crash.
            log.exception("immediate snapshot of %s failed; the journal holds the request", service)

    def _health(self, start_response: Callable[..., Any]) -> Iterable[bytes]:
        body = json.dumps(self.state.health()).encode()
        start_response("200 OK", [("Content-Type", "application/json"), ("Content-Length", str(len(body)))])
        return [body]
