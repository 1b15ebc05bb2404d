"""Probes for /healthz: can we reach storage, and (locally) how is the durable moto server's state dir doing."""
from __future__ import annotations

from typing import Any

import requests
from botocore.exceptions import BotoCoreError, ClientError

from chalicelib.storage.aws_errors import error_code

_TIMEOUT_S = 2.0


def probe_table(dynamodb: Any, table_name: str) -> str:
    """'ok', 'missing' (reachable, but the table does not exist) or 'unreachable'."""
    try:
        dynamodb.describe_table(TableName=table_name)
        return "ok"
    except ClientError as exc:
        return "missing" if error_code(exc) == "ResourceNotFoundException" else "unreachable"
    except BotoCoreError:
        return "unreachable"


def fetch_durable_health(endpoint_url: str) -> dict[str, Any] | str:
    """The durable server's own report (`GET {endpoint}/_drem/health`), or 'unreachable'."""
    try:
        reply = requests.get(f"{endpoint_url.rstrip('/')}/_drem/health", timeout=_TIMEOUT_S)
        reply.raise_for_status()
        body = reply.json()
    except (requests.RequestException, ValueError):
        return "unreachable"
    return body if isinstance(body, dict) else "unreachable"
