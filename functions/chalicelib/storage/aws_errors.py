"""Turning botocore failures into domain errors by error *code* (never by message text)."""
from __future__ import annotations

import re
import threading
from collections.abc import Iterator
from typing import Any

from botocore.exceptions import BotoCoreError, ClientError, EndpointConnectionError

from chalicelib import logs
from chalicelib.core.errors import (
    DremError,
    MaybeStored,
    RateLimited,
    ServiceUnavailable,
    StorageDiskFull,
    UpstreamError,
)

# The local storage server's refusals when its disk is full or read-only (drem_local.durable.disk_guard); their
# message names the path and what to do, so it is passed on as it is.
_DISK_CODES = {"DremDataDiskFull", "DremDataDiskReadOnly"}
_THROTTLING = {"TooManyRequestsException", "ThrottlingException", "ProvisionedThroughputExceededException",
               "LimitExceededException", "RequestLimitExceeded", "SlowDown"}


def error_code(exc: ClientError) -> str:
    return exc.response.get("Error", {}).get("Code", "")


# Operations that only read. Anything else changes state, so a connection lost during it may have stored it.
_READ_OPERATIONS = ("get_", "list_", "query", "scan", "describe_", "head_", "batch_get_", "transact_get_",
                    "admin_get_", "admin_list_", "generate_presigned_", "initiate_auth", "admin_initiate_auth")


def is_write(operation: str) -> bool:
    return not operation.startswith(_READ_OPERATIONS)


_written = threading.local()


def note_write_sent(model: Any = None, **_kwargs: Any) -> None:
    """botocore `before-call` hook (see `clients`): remember that this request has sent a state-changing call."""
    name = getattr(model, "name", "")
    if name and is_write(_snake(name)):
        _written.request_id = logs.current_request_id()


def writes_sent() -> bool:
    """Did the current request already send a write? Then a later failure must not claim nothing was stored."""
    request_id = logs.current_request_id()
    return request_id is not None and getattr(_written, "request_id", None) == request_id


def _snake(name: str) -> str:
    return re.sub(r"(?<!^)(?=[A-Z])", "_", name).lower()


def translate_common(exc: Exception, service: str, *, write: bool = False) -> DremError:
    """The fallback for codes a specific adapter does not handle itself.

    `write=True` for a state-changing call: when the connection fails, the request (or one of botocore's retries of
    it) may have reached storage and been stored before it went away, so the answer must not claim it was not. The
    same holds for any failure after an earlier write of the same HTTP request (say, a registration's account was
    created and reading its groups failed): `writes_sent` knows.
    """
    if isinstance(exc, ClientError):
        code = error_code(exc)
        if code in _THROTTLING:
            return RateLimited(f"{service} is busy; try again in a moment.")
        if code in _DISK_CODES:
            return StorageDiskFull(exc.response.get("Error", {}).get("Message") or "drem's data disk is full.")
        return UpstreamError(f"{service} refused the request ({code or 'unknown error'}).")
    if isinstance(exc, (EndpointConnectionError, BotoCoreError)):
        if write or writes_sent():
            return MaybeStored(f"{service} stopped answering while this change was being saved, so it may or may not "
                               "have been stored. Check before repeating it; a request with an idempotency key is "
                               "safe to retry with the same key.")
        return ServiceUnavailable(f"{service} cannot be reached.")
    return UpstreamError(f"{service} failed unexpectedly.")


def call(client: Any, operation: str, service: str, *args: Any, **kwargs: Any) -> Any:
    """`client.operation(...)`, with any AWS failure turned into the domain error `translate_common` picks."""
    try:
        return getattr(client, operation)(*args, **kwargs)
    except (ClientError, BotoCoreError) as exc:
        raise translate_common(exc, service, write=is_write(operation)) from exc


def all_items(client: Any, operation: str, service: str, **kwargs: Any) -> Iterator[dict[str, Any]]:
    """Every item of a DynamoDB `query` or `scan`, page after page (a page's LastEvaluatedKey is where the next one
    starts). Lazy: a caller that stops early reads no further page."""
    while True:
        page = call(client, operation, service, **kwargs)
        yield from page.get("Items", [])
        if "LastEvaluatedKey" not in page:
            return
        kwargs = {**kwargs, "ExclusiveStartKey": page["LastEvaluatedKey"]}


_BATCH_KEYS = 100  # BatchGetItem's limit per call
_BATCH_ATTEMPTS = 5  # DynamoDB may leave keys unprocessed under load; ask again this many times at most


def batch_items(client: Any, table: str, keys: list[dict[str, Any]], service: str,
                **options: Any) -> Iterator[dict[str, Any]]:
    """The items stored under `keys` in `table` (missing ones are left out), read with BatchGetItem, 100 keys a
    call, asking again for the keys a call left unprocessed. `options` go with every request (ConsistentRead,
    ProjectionExpression)."""
    for start in range(0, len(keys), _BATCH_KEYS):
        request: dict[str, Any] = {table: {"Keys": keys[start:start + _BATCH_KEYS], **options}}
        for _attempt in range(_BATCH_ATTEMPTS):
            reply = call(client, "batch_get_item", service, RequestItems=request)
            yield from reply.get("Responses", {}).get(table, [])
            request = reply.get("UnprocessedKeys") or {}
            if not request:
                break


# A DynamoDB write whose condition did not hold: the single-item form, and a transaction one of whose conditions
# failed (DynamoDB names the item in CancellationReasons; drem's callers only need "nothing was written").
_CONDITION_FAILED = {"ConditionalCheckFailedException", "TransactionCanceledException"}


def write_if(client: Any, operation: str, service: str, **kwargs: Any) -> bool:
    """`client.operation(**kwargs)` for a conditional write: False when its condition failed (nothing was written),
    True when it was written; any other AWS failure becomes the domain error `translate_common` picks."""
    try:
        getattr(client, operation)(**kwargs)
    except ClientError as exc:
        if error_code(exc) in _CONDITION_FAILED:
            return False
        raise translate_common(exc, service, write=True) from exc
    except BotoCoreError as exc:
        raise translate_common(exc, service, write=True) from exc
    return True
