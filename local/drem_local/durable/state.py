"""The state directory: moto version pin, journal, snapshots, dirty flags and recovery."""
from __future__ import annotations

import io
import logging
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drem_local.durable.classify import PERSISTED
from drem_local.durable.journal import Journal, JournalRecord
from drem_local.durable.snapshot import Manifest, SnapshotStore, register_picklers

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
    """Everything the middleware does to the disk. Every method runs under the server's one request lock."""

    def __init__(self, state_dir: Path, *, fsync: bool = True) -> None:
        self.state_dir = state_dir
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
        return self.recovery

    def record(self, service: str, environ: dict[str, Any], body: bytes) -> None:
        """Make a state-changing request durable before it runs."""
        self.last_seq += 1
        self.journal.append(JournalRecord(self.last_seq, service, journal_environ(environ), body))
        self.dirty.add(service)

    def snapshot_service(self, service: str) -> None:
        """Right after an operation with a random result: persist that service now, keep the journal for the rest."""
        self.manifest = self.snapshots.write(self.manifest, [service], self.last_seq, full=False)
        self.dirty.discard(service)

    def snapshot_all(self, *, force: bool = False) -> bool:
        """Snapshot every dirty service and empty the journal. False when there was nothing to do."""
        if not self.dirty and not force and self.journal.records == 0:
            return False
        self.manifest = self.snapshots.write(self.manifest, sorted(self.dirty & set(PERSISTED)), self.last_seq,
                                             full=True)
        self.journal.truncate()
        self.dirty.clear()
        return True

    def after_moto_api_call(self) -> None:
        """/moto-api/reset and friends touch every backend at once: mark all dirty and commit at once."""
        self.dirty.update(PERSISTED)
        self.snapshot_all(force=True)

    def health(self) -> dict[str, Any]:
        snapshot_age = time.time() - self.manifest.written_at if self.manifest.written_at else None
        return {
            "moto_version": self.moto_version,
            "state_dir": str(self.state_dir.resolve()),
            "writable": _is_writable(self.state_dir),
            "journal_bytes": self.journal.bytes,
            "journal_records": self.journal.records,
            "last_seq": self.last_seq,
            "last_snapshot_age_s": None if snapshot_age is None else round(snapshot_age, 3),
            "snapshot_bytes": self.manifest.total_bytes(),
            "dirty_services": sorted(self.dirty),
            "recovered_records": self.recovery.replayed if self.recovery else 0,
            "recovery_failed_records": self.recovery.failed if self.recovery else 0,
            "recovery_seconds": round(self.recovery.seconds, 3) if self.recovery else 0.0,
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


def _is_writable(path: Path) -> bool:
    probe = path / ".write-probe"
    try:
        probe.write_bytes(b"ok")
        probe.unlink()
        return True
    except OSError:
        return False
