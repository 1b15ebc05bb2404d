"""The per-installation AWS key pair that the local storage server accepts, and the state dir's file permissions.

On AWS, IAM decides who may call DynamoDB, S3 and Cognito. Locally the durable moto server is the only guard: it
verifies every request's SigV4 signature against this one key pair (drem_local.durable.sigv4). The pair is drawn at
the first `drem up`, kept in `<state-dir>/storage-keys.json` (0600, in a 0700 dir) and handed to the app, the
bootstrap and the CLI; nothing else on the machine can sign a request, so nothing else can read or change the event.
"""
from __future__ import annotations

import json
import os
import secrets
import stat
import string
from dataclasses import dataclass
from pathlib import Path
from typing import Any

KEYS_FILE = "storage-keys.json"
DIR_MODE = 0o700
FILE_MODE = 0o600
_KEY_ID_ALPHABET = string.ascii_uppercase + "234567"


class StorageKeysMissing(RuntimeError):
    """The state dir holds no storage keys (nothing was started there, or the file was removed)."""


@dataclass(frozen=True)
class StorageKeys:
    access_key_id: str
    secret_access_key: str

    def boto_kwargs(self) -> dict[str, str]:
        return {"aws_access_key_id": self.access_key_id, "aws_secret_access_key": self.secret_access_key}

    def environment(self) -> dict[str, str]:
        return {"AWS_ACCESS_KEY_ID": self.access_key_id, "AWS_SECRET_ACCESS_KEY": self.secret_access_key}

    def __repr__(self) -> str:  # never print the secret into a log or a test failure
        return f"StorageKeys(access_key_id={self.access_key_id!r}, secret_access_key=<hidden>)"


def generate() -> StorageKeys:
    # The shape of an IAM user key (AKIA + 16 base32 characters, 40-character secret), so every client accepts it.
    key_id = "AKIA" + "".join(secrets.choice(_KEY_ID_ALPHABET) for _ in range(16))
    return StorageKeys(key_id, secrets.token_urlsafe(30))


def load(state_dir: Path) -> StorageKeys:
    path = state_dir / KEYS_FILE
    try:
        data = json.loads(path.read_text())
        return StorageKeys(str(data["access_key_id"]), str(data["secret_access_key"]))
    except FileNotFoundError:
        raise StorageKeysMissing(f"{path} does not exist: start the local stack with `drem up --state-dir "
                                 f"{state_dir}` first") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise StorageKeysMissing(f"{path} is unreadable ({exc.__class__.__name__}); it holds the storage keys of "
                                 "this installation") from None


def load_or_create(state_dir: Path) -> StorageKeys:
    """The installation's keys; drawn and written (0600, atomically, never overwritten) on first use."""
    secure_state_dir(state_dir)
    path = state_dir / KEYS_FILE
    if path.exists():
        return load(state_dir)
    keys = generate()
    tmp = path.with_name(f".{KEYS_FILE}.{os.getpid()}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, FILE_MODE)
    with os.fdopen(fd, "w") as handle:
        json.dump({"access_key_id": keys.access_key_id, "secret_access_key": keys.secret_access_key}, handle)
        handle.flush()
        os.fsync(handle.fileno())
    try:
        os.link(tmp, path)  # fails if another process won the race: then its keys are the keys
    except FileExistsError:
        pass
    finally:
        tmp.unlink(missing_ok=True)
    return load(state_dir)


def secure_state_dir(state_dir: Path) -> None:
    """Create the state dir 0700 and tighten everything already in it (older installs wrote 0644 files)."""
    state_dir.mkdir(parents=True, exist_ok=True, mode=DIR_MODE)
    for directory, _dirnames, filenames in os.walk(state_dir):
        _restrict(Path(directory), DIR_MODE)
        for name in filenames:
            _restrict(Path(directory) / name, FILE_MODE)


def _restrict(path: Path, mode: int) -> None:
    try:
        if stat.S_IMODE(path.lstat().st_mode) & ~mode and not path.is_symlink():
            path.chmod(mode)
    except OSError:
        pass  # vanished meanwhile (a snapshot replaced it) or not ours: the server reports what it cannot write



def sign_every_call(client: Any) -> Any:
    """Make `client` sign even the operations AWS serves unsigned (Cognito InitiateAuth, SignUp, ...): the local
    storage server refuses anything unsigned. Same as chalicelib.storage.clients.sign_every_call, which the app uses
    (chalicelib is not importable where the drem CLI runs, and drem_local is not in the Lambda bundle)."""
    from botocore import UNSIGNED

    def always_v4(signature_version: Any = None, **_kwargs: Any) -> str | None:
        return "v4" if signature_version in (UNSIGNED, "none") else None

    # register_first: botocore's own choose-signer handler would otherwise answer "unsigned" before ours is asked.
    client.meta.events.register_first(f"choose-signer.{client.meta.service_model.service_id.hyphenize()}", always_v4)
    return client


def local_client(service: str, endpoint_url: str, keys: StorageKeys, region: str = "us-east-1",
                 config: Any = None) -> Any:
    """A boto3 client for the local storage server, signing every call with the installation's keys (for tests,
    benches and scripts; S3 gets SigV4 and path-style addressing like the app's own client)."""
    import boto3
    from botocore.config import Config

    base = Config(account_id_endpoint_mode="disabled")
    if service == "s3":
        base = base.merge(Config(signature_version="s3v4", s3={"addressing_style": "path"}))
    config = base.merge(config) if config is not None else base
    client = boto3.session.Session(region_name=region, **keys.boto_kwargs()).client(
        service, endpoint_url=endpoint_url, config=config)
    return sign_every_call(client)
