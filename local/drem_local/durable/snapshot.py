"""Per-service pickle snapshots of moto's backends, committed together by one manifest.

Layout under `<state-dir>/snapshots/`: `<service>-<seq>.pickle` files plus `manifest.json`, which names the
current file of each service and the journal sequence number that file already contains. Writing a new file
never touches the old one; replacing the manifest is the single commit point. So the periodic snapshot pickles
under the request lock but writes its files without it (DurableApp.snapshot_if_dirty): requests are not held up
while a hundred megabytes of S3 objects go to disk.
"""
from __future__ import annotations

import copyreg
import json
import os
import pickle
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drem_local.durable.classify import COGNITO, DYNAMODB, S3

# moto backends per persisted service group
BACKENDS: dict[str, tuple[str, ...]] = {
    DYNAMODB: ("dynamodb", "dynamodbstreams"),
    S3: ("s3",),
    COGNITO: ("cognito-idp",),
}
MANIFEST = "manifest.json"


def register_picklers() -> None:
    """Cognito pools hold a joserfc RSAKey whose cryptography key object cannot be pickled as is."""
    from joserfc import jwk

    copyreg.pickle(jwk.RSAKey, lambda key: (jwk.RSAKey.import_key, (key.as_dict(private=True),)))


@dataclass
class Manifest:
    seq: int = 0  # every journal record up to here is in the snapshots
    files: dict[str, dict[str, Any]] = field(default_factory=dict)  # service -> {"file", "seq", "bytes"}
    written_at: float = 0.0

    def service_seq(self, service: str) -> int:
        entry = self.files.get(service)
        return int(entry["seq"]) if entry else 0

    def total_bytes(self) -> int:
        return sum(int(entry.get("bytes", 0)) for entry in self.files.values())


def fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_atomically(path: Path, data: bytes) -> None:
    tmp = path.with_name(path.name + ".tmp")
    try:
        # 0600: snapshots hold every account's password (the state dir is 0700 as well).
        with os.fdopen(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600), "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
    except OSError:
        tmp.unlink(missing_ok=True)  # on a full disk a half-written file would take the last free space
        raise
    os.replace(tmp, path)


@dataclass(frozen=True)
class Capture:
    seq: int  # every journal record up to here is in these pickles (for their services)
    pickles: dict[str, bytes]  # service -> pickled backends


@dataclass(frozen=True)
class Written:
    seq: int
    files: dict[str, dict[str, Any]]  # service -> manifest entry


class SnapshotStore:
    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.directory.mkdir(parents=True, exist_ok=True)
        self._in_flight: set[str] = set()  # files a snapshot writes outside the request lock, not committed yet

    def read_manifest(self) -> Manifest:
        path = self.directory / MANIFEST
        if not path.exists():
            return Manifest()
        raw = json.loads(path.read_text())
        return Manifest(seq=int(raw["seq"]), files=raw["files"], written_at=float(raw["written_at"]))

    def load_into_moto(self, manifest: Manifest) -> None:
        from moto.backends import get_backend

        for entry in manifest.files.values():
            state = pickle.loads((self.directory / entry["file"]).read_bytes())
            for backend_name, accounts in state.items():
                live = get_backend(backend_name)
                for account_id, regions in accounts.items():
                    account_backends = live[account_id]
                    for region, backend in regions.items():
                        dict.__setitem__(account_backends, region, backend)

    def write(self, manifest: Manifest, services: list[str], seq: int, *, full: bool) -> Manifest:
        """Pickle `services` as of journal `seq` and commit a new manifest. Caller holds the request lock."""
        return self.commit(manifest, self.write_files(self.capture(services, seq)), full=full)

    # A snapshot in three steps, so the slow one (writing and fsyncing files: seconds once S3 holds model archives)
    # runs without the request lock: `capture` (under the lock: the pickles, consistent with journal `seq`),
    # `write_files` (no lock), `commit` (under the lock: the manifest, the single commit point).

    @staticmethod
    def capture(services: list[str], seq: int) -> Capture:
        return Capture(seq, {service: pickle.dumps(_capture(service), protocol=pickle.HIGHEST_PROTOCOL)
                             for service in services})

    def write_files(self, capture: Capture) -> Written:
        """Write the captured pickles as new files (never the ones the manifest names). No lock needed; on a disk
        error the files of this attempt are removed and the error raised."""
        names = {service: f"{service}-{capture.seq:012d}.pickle" for service in capture.pickles}
        self._in_flight |= set(names.values())
        try:
            for service, data in capture.pickles.items():
                write_atomically(self.directory / names[service], data)
        except OSError:
            self._forget(names.values(), remove=True)
            raise
        return Written(capture.seq, {service: {"file": names[service], "seq": capture.seq, "bytes": len(data)}
                                     for service, data in capture.pickles.items()})

    def commit(self, manifest: Manifest, written: Written, *, full: bool) -> Manifest:
        """Name the written files in a new manifest. Caller holds the request lock. A service snapshotted again
        since the capture (an immediate snapshot, `write` under the lock) keeps its newer file."""
        files = dict(manifest.files)
        for service, entry in written.files.items():
            if manifest.service_seq(service) < written.seq:
                files[service] = entry
        new = Manifest(seq=max(manifest.seq, written.seq) if full else manifest.seq, files=files,
                       written_at=time.time())
        names = [entry["file"] for entry in written.files.values()]
        try:
            write_atomically(self.directory / MANIFEST, json.dumps(
                {"seq": new.seq, "files": new.files, "written_at": new.written_at}, indent=1).encode())
            fsync_dir(self.directory)
        except OSError:
            self._forget(names, remove=False)
            self._remove_unreferenced(manifest)  # the files of this failed attempt, so the disk gets its space back
            raise
        self._forget(names, remove=False)
        self._remove_unreferenced(new)
        return new

    def _forget(self, names: Iterable[str], *, remove: bool) -> None:
        for name in names:
            self._in_flight.discard(name)
            if remove:
                (self.directory / name).unlink(missing_ok=True)

    def _remove_unreferenced(self, manifest: Manifest) -> None:
        """Old snapshot files (and a failed attempt's), except those a snapshot is writing right now."""
        keep = {entry["file"] for entry in manifest.files.values()} | {MANIFEST} | self._in_flight
        keep |= {name + ".tmp" for name in self._in_flight}
        for path in self.directory.iterdir():
            if path.name not in keep:
                path.unlink(missing_ok=True)


def _capture(service: str) -> dict[str, dict[str, dict[str, Any]]]:
    from moto.backends import get_backend

    state: dict[str, dict[str, dict[str, Any]]] = {}
    for backend_name in BACKENDS[service]:
        accounts: dict[str, dict[str, Any]] = {}
        for account_id, region, backend in get_backend(backend_name).iter_backends():
            accounts.setdefault(account_id, {})[region] = backend
        state[backend_name] = accounts
    return state
