"""Turning botocore failures into domain errors by error *code* (never by message text)."""
from __future__ import annotations

from typing import Any

from botocore.exceptions import BotoCoreError, ClientError, EndpointConnectionError

from chalicelib.domain.errors import DremError, RateLimited, ServiceUnavailable, UpstreamError

_THROTTLING = {"TooManyRequestsException", "ThrottlingException", "ProvisionedThroughputExceededException",
               "LimitExceededException", "RequestLimitExceeded", "SlowDown"}


def error_code(exc: ClientError) -> str:
    return exc.response.get("Error", {}).get("Code", "")


def translate_common(exc: Exception, service: str) -> DremError:
    """The fallback for codes a specific adapter does not handle itself."""
    if isinstance(exc, ClientError):
        code = error_code(exc)
        if code in _THROTTLING:
            return RateLimited(f"{service} is busy; try again in a moment.")
        return UpstreamError(f"{service} refused the request ({code or 'unknown error'}).")
    if isinstance(exc, (EndpointConnectionError, BotoCoreError)):
        return ServiceUnavailable(f"{service} cannot be reached.")
    return UpstreamError(f"{service} failed unexpectedly.")


def call(client: Any, operation: str, service: str, *args: Any, **kwargs: Any) -> Any:
    """`client.operation(...)`, with any AWS failure turned into the domain error `translate_common` picks."""
    try:
        return getattr(client, operation)(*args, **kwargs)
    except (ClientError, BotoCoreError) as exc:
        raise translate_common(exc, service) from exc
