"""Lazily built, cached boto3 clients (never at import: moto must be able to start first, and Lambda cold starts
should pay only for what a request uses). Tests call `reset_clients()` when the endpoint or region changes."""
from __future__ import annotations

from functools import lru_cache
from typing import Any

import boto3
import botocore.session
from botocore import UNSIGNED
from botocore.config import Config
from botocore.loaders import Loader, create_loader

from chalicelib.settings import get_settings
from chalicelib.storage.aws_errors import note_write_sent

# botocore 1.44 otherwise sends some DynamoDB calls to account-specific hosts that moto does not serve.
_BASE_CONFIG = Config(account_id_endpoint_mode="disabled", retries={"max_attempts": 3, "mode": "standard"},
                      connect_timeout=3, read_timeout=10)


@lru_cache(maxsize=1)
def _service_models() -> Loader:
    # botocore's reader of its bundled JSON (service models, endpoint rules), which caches what it has read. A fresh
    # boto3 Session brings a fresh one and re-reads ~1 MB of JSON for every client it makes (0.1-0.2 s each); shared,
    # a client costs ~10 ms. Only the read-only data is shared: each session still resolves its own credentials.
    return create_loader()


def boto_session(region: str, **credentials: str) -> boto3.session.Session:
    """A boto3 Session (credentials from `credentials`, else the usual chain) whose clients are cheap to make."""
    core = botocore.session.get_session()
    core.register_component("data_loader", _service_models())
    return boto3.session.Session(region_name=region, botocore_session=core, **credentials)


@lru_cache(maxsize=None)
def _client(service: str, region: str, endpoint_url: str | None) -> Any:
    config = _BASE_CONFIG
    if service == "s3":
        # s3v4 + path style: presigned URLs that moto (127.0.0.1) and browsers both accept.
        config = config.merge(Config(signature_version="s3v4", s3={"addressing_style": "path"} if endpoint_url else {}))
    made = boto_session(region).client(service, endpoint_url=endpoint_url, config=config)
    made.meta.events.register("before-call", note_write_sent)  # honest errors after a write (see aws_errors)
    # The local storage server accepts only requests signed with the installation's keys (from the environment).
    return sign_every_call(made) if endpoint_url else made


# The app server's same-origin path to the local storage server (drem_local.durable.guard.GATEWAY_PATH).
STORAGE_GATEWAY_PATH = "/_storage"


def client(service: str) -> Any:
    settings = get_settings()
    return _client(service, settings.region, settings.endpoint_url)


def client_for(service: str, region: str, endpoint_url: str | None) -> Any:
    """A client while the settings are still being made (they may need what it reads)."""
    return _client(service, region, endpoint_url)


def cognito() -> Any:
    return client("cognito-idp")


def dynamodb() -> Any:
    return client("dynamodb")


def s3() -> Any:
    return client("s3")


def s3_presigner() -> Any:
    """The S3 client that signs links for browsers and cars. On AWS the S3 client itself; locally one whose
    endpoint is the app's own storage gateway ({DREM_PUBLIC_URL}/_storage), because the storage server listens on
    loopback only and people reach just the app (on the venue network with `drem up --lan`). Never sends requests."""
    settings = get_settings()
    if not settings.endpoint_url:
        return s3()
    return _client("s3", settings.region, settings.public_url.rstrip("/") + STORAGE_GATEWAY_PATH)


def reset_clients() -> None:
    _client.cache_clear()


def sign_every_call(client: Any) -> Any:
    """Make `client` sign even the operations AWS serves unsigned (Cognito InitiateAuth, SignUp, ...).

    Only for the local storage server, which refuses every unsigned request (drem_local.durable.sigv4); on AWS these
    calls stay unsigned, as AWS expects."""
    def always_v4(signature_version: Any = None, **_kwargs: Any) -> str | None:
        return "v4" if signature_version in (UNSIGNED, "none") else None

    # register_first: botocore's own choose-signer handler would otherwise answer "unsigned" before ours is asked.
    client.meta.events.register_first(f"choose-signer.{client.meta.service_model.service_id.hyphenize()}", always_v4)
    return client
