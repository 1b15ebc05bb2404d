"""The device credential on disk: `<config dir>/credential.json`, mode 0600, replaced atomically.

Default config dir: `~/.config/drem-car/` (or `--config-dir`). The file holds the API URL, the device id and kind,
and the `Authorization: Device <credential>` secret — nothing else is secret on the car.
"""
from __future__ import annotations

import hashlib
import json
import os
import secrets
from dataclasses import asdict, dataclass
from pathlib import Path

DEFAULT_CONFIG_DIR = Path("~/.config/drem-car")
CREDENTIAL_FILE = "credential.json"
# The attempt id of an activation in progress, kept until its credential is saved: a rerun of `drem car activate`
# with the same code after a lost answer (or a crash of this process) resumes it (chalicelib/domain/activation.py).
ATTEMPT_FILE = "activation-attempt.json"


class NotActivated(RuntimeError):
    """No credential yet: run `drem car activate --code ...` first."""


@dataclass(frozen=True)
class StoredCredential:
    api: str
    device_id: str
    device_kind: str
    hostname: str
    fleet_id: str | None
    credential: str


def config_dir(path: str | Path | None) -> Path:
    return Path(path or DEFAULT_CONFIG_DIR).expanduser()


class CredentialStore:
    def __init__(self, directory: str | Path | None = None) -> None:
        self.directory = config_dir(directory)
        self.path = self.directory / CREDENTIAL_FILE

    def save(self, credential: StoredCredential) -> None:
        self._write(self.path, asdict(credential))
        (self.directory / ATTEMPT_FILE).unlink(missing_ok=True)

    def attempt_id_for(self, code: str) -> str:
        """The attempt id for activating with `code`: the one already drawn for it (a retry), else a new one, stored
        before it is ever sent."""
        path, code_hash = self.directory / ATTEMPT_FILE, _code_hash(code)
        try:
            stored = json.loads(path.read_text())
            if stored.get("code_sha256") == code_hash and isinstance(stored.get("attempt_id"), str):
                return str(stored["attempt_id"])
        except (FileNotFoundError, ValueError, AttributeError):
            pass
        attempt_id = secrets.token_urlsafe(24)
        self._write(path, {"code_sha256": code_hash, "attempt_id": attempt_id})
        return attempt_id

    def _write(self, path: Path, data: dict[str, object]) -> None:
        self.directory.mkdir(parents=True, exist_ok=True, mode=0o700)
        temporary = path.with_suffix(".tmp")
        # Created 0600 from the first byte: the secret is never readable by others, not even briefly.
        descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(descriptor, "w") as handle:
            json.dump(data, handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temporary, path)

    def load(self) -> StoredCredential:
        try:
            data = json.loads(self.path.read_text())
        except FileNotFoundError:
            raise NotActivated(f"this device is not activated (no {self.path}); run `drem car activate --code CODE "
                               "--api URL` (or `--aws` for a `make deploy` stage) first") from None
        return StoredCredential(**data)


def _code_hash(code: str) -> str:
    # Codes are typed by people: the server ignores case, spaces and dashes, and so does the match here.
    return hashlib.sha256("".join(ch for ch in code.upper() if ch.isalnum()).encode()).hexdigest()
