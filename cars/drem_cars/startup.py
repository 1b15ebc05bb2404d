"""The one start-up of everything that runs as this device (`drem car run`, `drem car status`, `drem timer`): the
saved credential, the API client, and the agent's files in the config dir (the outbox; a car's models)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from drem_cars.client import DeviceClient
from drem_cars.credentials import CredentialStore
from drem_cars.model_store import ModelStore
from drem_cars.outbox import Outbox


@dataclass(frozen=True)
class DeviceStartup:
    client: DeviceClient
    outbox: Outbox
    models: ModelStore | None  # None for a timer, which runs no models
    config_dir: Path


def start_device(config_dir: str | Path | None, *, api: str | None = None, runs_models: bool = True) -> DeviceStartup:
    """Raises NotActivated (its message says what to run) when this device has no credential yet."""
    store = CredentialStore(config_dir)
    client = DeviceClient(store, api=api)
    outbox = Outbox(store.directory / "outbox.sqlite3")
    models = ModelStore(store.directory / "models") if runs_models else None
    return DeviceStartup(client, outbox, models, store.directory)
