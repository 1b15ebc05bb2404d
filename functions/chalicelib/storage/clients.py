"""Lazily built, cached boto3 clients (never at import: moto must be able to start first, and Lambda cold starts
should pay only for what a request uses). Tests call `reset_clients()` when the endpoint or region changes."""
from __future__ import annotations

from functools import lru_cache
from typing import Any

import boto3
from botocore.config import Config

from chalicelib.settings import get_settings
from chalicelib.storage.aws_errors import note_write_sent

# botocore 1.44 otherwise sends some DynamoDB calls to account-specific hosts that moto does not serve.
_BASE_CONFIG = Config(account_id_endpoint_mode="disabled", retries={"max_attempts": 3, "mode": "standard"},
                      connect_timeout=3, read_timeout=10)


@lru_cache(maxsize=None)
def _client(service: str, region: str, endpoint_url: str | None) -> Any:
    config = _BASE_CONFIG
    if service == "s3":
        # s3v4 + path style: presigned URLs that moto (127.0.0.1) and browsers both accept.
        config = config.merge(Config(signature_version="s3v4", s3={"addressing_style": "path"} if endpoint_url else {}))
    made = boto3.session.Session(region_name=region).client(service, endpoint_url=endpoint_url, config=config)
    made.meta.events.register("before-call", note_write_sent)  # honest errors after a write (see aws_errors)
    return made


def client(service: str) -> Any:
    settings = get_settings()
    return _client(service, settings.region, settings.endpoint_url)


def cognito() -> Any:
    return client("cognito-idp")


def dynamodb() -> Any:
    return client("dynamodb")


def s3() -> Any:
    return client("s3")


def reset_clients() -> None:
    _client.cache_clear()
