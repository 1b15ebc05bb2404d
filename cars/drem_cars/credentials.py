"""The device credential on disk: `<config dir>/credential.json`, mode 0600, replaced atomically.

Default config dir: `~/.config/drem-car/` (or `--config-dir`). The file holds the API URL, the device id and kind,
and the `Authorization: Device <credential>` secret — nothing else is secret on the car.
"""
from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path

DEFAULT_CONFIG_DIR = Path("~/.config/drem-car")
CREDENTIAL_FILE = "credential.json"


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
        self.directory.mkdir(parents=True, exist_ok=True, mode=0o700)
        temporary = self.path.with_suffix(".tmp")
        # Created 0600 from the first byte: the secret is never readable by others, not even briefly.
        descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(descriptor, "w") as handle:
            json.dump(asdict(credential), handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temporary, self.path)

    def load(self) -> StoredCredential:
        try:
            data = json.loads(self.path.read_text())
        except FileNotFoundError:
            raise NotActivated(f"this device is not activated (no {self.path}); run "
                               "`drem car activate --code CODE --api URL` first") from None
        return StoredCredential(**data)

    def forget(self) -> None:
        self.path.unlink(missing_ok=True)
