"""The state directory: moto version pin, journal, snapshots, dirty flags and recovery."""
from __future__ import annotations

import hashlib
import hmac
import io
import logging
import os
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drem_local.durable.classify import PERSISTED
from drem_local.durable.journal import Journal, JournalRecord
from drem_local.durable.snapshot import Capture, Manifest, SnapshotStore, Written, register_picklers

log = logging.getLogger("drem.durable")

VERSION_FILE = "moto-version"
JOURNAL_FILE = "journal.bin"
SNAPSHOT_DIR = "snapshots"


class MotoVersionMismatch(RuntimeError):
    def __init__(self, state_dir: Path, stored: str, running: str) -> None:
        super().__init__(
            f"The state in {state_dir} was written by moto {stored}, but this install has moto {running}. "
            f"moto's pickled state only loads into the exact version that wrote it. Either reinstall moto=={stored}, "
            f"run `drem export` there and import into a fresh state dir, or start fresh with `rm -rf {state_dir}` "
            "(this deletes all local data).")
        self.stored = stored
        self.running = running


def running_moto_version() -> str:
    from importlib.metadata import version

    return version("moto")


def check_moto_version(state_dir: Path, running: str) -> None:
    """Pin the state dir to the moto version that writes it; refuse one written by another version."""
    version_path = state_dir / VERSION_FILE
    if version_path.exists():
        stored = version_path.read_text().strip()
        if stored != running:
            raise MotoVersionMismatch(state_dir, stored, running)
        return
    has_state = (state_dir / JOURNAL_FILE).exists() or (state_dir / SNAPSHOT_DIR / "manifest.json").exists()
    if has_state:
        raise MotoVersionMismatch(state_dir, "unknown (no moto-version file)", running)
    version_path.write_text(running + "\n")


@dataclass
class RecoveryReport:
    snapshot_seq: int
    journal_records: int
    replayed: int
    skipped: int
    failed: int
    torn_bytes: int
    seconds: float


class DurableState:
    """Everything the middleware does to the disk. Every method runs under the server's `state` lock (durable.lanes),
    except `write_snapshot` (see DurableApp.snapshot_if_dirty)."""

    def __init__(self, state_dir: Path, *, fsync: bool = True, seed_secret: bytes | None = None) -> None:
        """`seed_secret` keys the randomness moto draws for each journaled request (see `seed_randomness`); the
        server passes the installation's storage secret, so a restart replays the same draws."""
        self.state_dir = state_dir
        self.seed_secret = seed_secret if seed_secret is not None else os.urandom(32)
        self.last_snapshot_error: str | None = None  # why the last snapshot failed (a full disk), until one succeeds
        self.state_dir.mkdir(parents=True, exist_ok=True)
        self.moto_version = running_moto_version()
        check_moto_version(state_dir, self.moto_version)
        register_picklers()
        self.journal = Journal(state_dir / JOURNAL_FILE, fsync=fsync)
        self.snapshots = SnapshotStore(state_dir / SNAPSHOT_DIR)
        self.manifest = Manifest()
        self.last_seq = 0
        self.dirty: set[str] = set()
        self.recovery: RecoveryReport | None = None
        # When recovery ended: the app's repair sweep tells a restart of this server by it, and everything the
        # journal replayed (an account replayed gets the replay's creation time) was created before it.
        self.started_at = time.time()

    def recover(self, replay: Callable[[JournalRecord], int]) -> RecoveryReport:
        """Load the snapshots, then replay each journal record its service's snapshot does not hold yet."""
        started = time.perf_counter()
        self.manifest = self.snapshots.read_manifest()
        self.snapshots.load_into_moto(self.manifest)
        existing = self.journal.open()
        replayed = skipped = failed = 0
        for record in existing.records:
            if record.seq <= self.manifest.service_seq(record.service):
                skipped += 1
                continue
            try:
                self.seed_randomness(record.seq)
                status = replay(record)
            except Exception:
                log.exception("replaying journal record %d (%s) raised; skipped", record.seq, record.service)
                failed += 1
                continue
            if status >= 500:
                log.warning("replaying journal record %d (%s) answered %d; skipped", record.seq, record.service, status)
                failed += 1
            else:
                replayed += 1
            self.dirty.add(record.service)
        self.last_seq = max([self.manifest.seq, *(entry["seq"] for entry in self.manifest.files.values()),
                             *(record.seq for record in existing.records)])
        self.recovery = RecoveryReport(self.manifest.seq, len(existing.records), replayed, skipped, failed,
                                       existing.torn_bytes, time.perf_counter() - started)
        self.started_at = time.time()
        return self.recovery

    def record(self, service: str, environ: dict[str, Any], body: bytes, *, seed: bool = True) -> int:
        """Make a state-changing request durable before it runs, and (with `seed`) seed moto's randomness for it;
        returns its sequence number. Raises OSError (nothing recorded) when the disk refuses the write."""
        seq = self.last_seq + 1
        self.journal.append(JournalRecord(seq, service, journal_environ(environ), body))
        self.last_seq = seq
        self.dirty.add(service)
        if seed:
            self.seed_randomness(seq)
        return seq

    def seed_randomness(self, seq: int) -> None:
        """Seed moto's one source of randomness (`mock_random`: user subs, refresh tokens, sessions, S3 version ids)
        from journal record `seq` and the installation's secret, so replaying that record after a crash draws the
        same ids the client was told. An acknowledged identity never depends on a snapshot succeeding (a full disk
        fails snapshots, never the journal's preallocated room). Keyed with the secret, so nobody can predict the
        tokens from a sequence number."""
        from moto.moto_api._internal import mock_random

        mock_random.seed(hmac.new(self.seed_secret, b"drem-journal-seq:%d" % seq, hashlib.sha256).digest())

    def snapshot_service(self, service: str) -> None:
        """Right after an operation with a random result: persist that service now, keep the journal for the rest."""
        self.manifest = self._noting_disk_errors(
            lambda: self.snapshots.write(self.manifest, [service], self.last_seq, full=False))
        self.dirty.discard(service)

    def snapshot_all(self, *, force: bool = False) -> bool:
        """Snapshot every dirty service and empty the journal. False when there was nothing to do."""
        if not self.dirty and not force and self.journal.records == 0:
            return False
        self.manifest = self._noting_disk_errors(lambda: self.snapshots.write(
            self.manifest, sorted(self.dirty & set(PERSISTED)), self.last_seq, full=True))
        self.journal.truncate()
        self.dirty.clear()
        return True

    def plan_snapshot(self, services: tuple[str, ...] = PERSISTED, *, force: bool = False,
                      empties_journal: bool = True) -> tuple[list[str], int] | None:
        """Under the state lock (and the lanes of `services`, held until they are pickled): which of `services` to
        pickle, and the journal sequence number the pickles will hold. None when there is nothing to do: none of them
        is dirty and (for the capture that may empty the journal) the journal is empty and no `force`. The planned
        services count as clean from here; `abandon_snapshot` marks them dirty again if the snapshot fails."""
        wanted = sorted(self.dirty & set(services))
        if not wanted and not (empties_journal and (force or self.journal.records)):
            return None
        self.dirty.difference_update(wanted)
        return wanted, self.last_seq

    def write_snapshot(self, capture: Capture) -> Written:
        """Without the request lanes: the slow part (files written and fsynced)."""
        try:
            return self.snapshots.write_files(capture)
        except OSError as exc:
            self.last_snapshot_error = f"{exc.strerror or exc} ({time.strftime('%H:%M:%S')})"
            raise

    def finish_snapshot(self, written: Written, *, empties_journal: bool = True) -> bool:
        """Under the state lock: commit the manifest; with `empties_journal`, empty the journal if every service is
        clean and nothing was recorded since the capture (else its newer records stay: recovery skips those a
        service's snapshot already holds). True if emptied."""
        complete = empties_journal and not self.dirty
        self.manifest = self._noting_disk_errors(
            lambda: self.snapshots.commit(self.manifest, written, full=complete))
        if not complete or self.last_seq != written.seq:
            return False
        self.journal.truncate()
        return True

    def abandon_snapshot(self, services: Iterable[str]) -> None:
        """Under the state lock, after a failed snapshot: the planned services are dirty again."""
        self.dirty.update(services)

    def _noting_disk_errors(self, write: Callable[[], Manifest]) -> Manifest:
        try:
            manifest = write()
        except OSError as exc:
            self.last_snapshot_error = f"{exc.strerror or exc} ({time.strftime('%H:%M:%S')})"
            raise
        self.last_snapshot_error = None
        return manifest

    def after_moto_api_call(self) -> None:
        """/moto-api/reset and friends touch every backend at once: mark all dirty and commit at once."""
        self.dirty.update(PERSISTED)
        self.snapshot_all(force=True)

    def health(self) -> dict[str, Any]:
        snapshot_age = time.time() - self.manifest.written_at if self.manifest.written_at else None
        disk = self.disk_health()
        return {
            "moto_version": self.moto_version,
            "state_dir": str(self.state_dir.resolve()),
            "writable": disk["writes"] != "refused",
            "disk": disk,
            "journal_bytes": self.journal.bytes,
            "journal_records": self.journal.records,
            "last_seq": self.last_seq,
            "last_snapshot_age_s": None if snapshot_age is None else round(snapshot_age, 3),
            "snapshot_bytes": self.manifest.total_bytes(),
            "dirty_services": sorted(self.dirty),
            "recovered_records": self.recovery.replayed if self.recovery else 0,
            "recovery_failed_records": self.recovery.failed if self.recovery else 0,
            "recovery_seconds": round(self.recovery.seconds, 3) if self.recovery else 0.0,
            "started_at": self.started_at,
        }

    def disk_health(self) -> dict[str, Any]:
        """What the disk lets the server do, truthfully: writes go to the journal's preallocated room first, so a
        full disk still takes writes (until that room is used up) while snapshots fail; a read-only one takes none.
        `writes`: "accepted", "journal-only" (snapshots fail; the journal holds everything) or "refused"."""
        from drem_local.disk import FULL, READ_ONLY, disk_state, sentence

        try:
            state = disk_state(self.state_dir)
            free, problem = state.free_bytes, state.problem
        except OSError:
            free, problem = 0, None
        if problem is None and self.last_snapshot_error is not None:
            problem = FULL  # statvfs sees room (root's reserve, a quota), but snapshots are refused
        room = self.journal.room
        if problem == READ_ONLY:
            writes = "refused"
        elif problem == FULL:
            writes = "journal-only" if room >= _SMALLEST_WRITE_BYTES else "refused"
        else:
            writes = "accepted"
        return {
            "problem": problem,
            "free_bytes": free,
            "journal_room_bytes": room,
            "writes": writes,
            "last_snapshot_error": self.last_snapshot_error,
            "message": sentence(problem, self.state_dir, _THEN[writes]) if problem else None,
        }

    def close(self) -> None:
        self.journal.close()


# The parts of a WSGI environ that decide what moto does; sockets, streams and server objects stay out.
_ENVIRON_KEYS = ("REQUEST_METHOD", "SCRIPT_NAME", "PATH_INFO", "QUERY_STRING", "CONTENT_TYPE", "CONTENT_LENGTH",
                 "SERVER_NAME", "SERVER_PORT", "SERVER_PROTOCOL", "REQUEST_URI", "RAW_URI", "wsgi.url_scheme",
                 "wsgi.input_terminated")


def journal_environ(environ: dict[str, Any]) -> dict[str, Any]:
    from moto.core.request import PRESERVED_HEADER_NAMES_ENVIRON_KEY

    kept = {key: environ[key] for key in _ENVIRON_KEYS if key in environ}
    kept.update((key, value) for key, value in environ.items() if key.startswith("HTTP_"))
    if PRESERVED_HEADER_NAMES_ENVIRON_KEY in environ:
        kept[PRESERVED_HEADER_NAMES_ENVIRON_KEY] = dict(environ[PRESERVED_HEADER_NAMES_ENVIRON_KEY])
    return kept


def replay_environ(record: JournalRecord) -> dict[str, Any]:
    environ = dict(record.environ)
    environ.update({
        "wsgi.input": io.BytesIO(record.body),
        "wsgi.errors": sys.stderr,
        "wsgi.version": (1, 0),
        "wsgi.multithread": False,
        "wsgi.multiprocess": False,
        "wsgi.run_once": False,
        "CONTENT_LENGTH": str(len(record.body)),
    })
    return environ


# A journal record of the smallest write drem makes (its request headers dominate): with less room than this left,
# every write is refused.
_SMALLEST_WRITE_BYTES = 4096
_THEN = {
    "accepted": "nothing more is needed.",
    "journal-only": "snapshots resume by themselves. Until then writes go on into the journal's reserved room "
                    "(every acknowledged write survives a crash), and are refused with this message once it is "
                    "used up.",
    "refused": "writes resume by themselves; until then every change is refused with this message (nothing stored "
               "before is lost).",
}
