"""What the console's HTML routes share: the submitted form (without the CSRF field), errors keyed by form field,
and whether htmx asked (then a route answers with a fragment instead of the whole page)."""
from __future__ import annotations

from urllib.parse import parse_qs

from chalice.app import Request
from pydantic import ValidationError

from chalicelib.auth.access import form_fields
from chalicelib.domain.errors import DremError
from chalicelib.http_errors import status_for

# What a form's inputs show when a service refuses them: pydantic and domain errors, never unexpected ones.
SHOWN_ON_FORM = (ValidationError, DremError)


def submitted(request: Request, *fields: str) -> dict[str, str]:
    """The urlencoded form, keeping only `fields` (the CSRF token and stray inputs never reach a strict model)."""
    form = form_fields(request)
    return {name: form[name] for name in fields if name in form}


def is_htmx(request: Request) -> bool:
    return request.headers.get("hx-request") == "true"


def field_errors(exc: Exception, default_field: str) -> dict[str, str]:
    """{field: message} so each message can sit next to its input."""
    if isinstance(exc, ValidationError):
        found: dict[str, str] = {}
        for error in exc.errors(include_url=False):
            name = str(error["loc"][0]) if error.get("loc") else default_field
            found.setdefault(name, _plain(name, error))
        return found
    return {getattr(exc, "field", None) or default_field: getattr(exc, "message", str(exc))}


def error_status(exc: Exception) -> int:
    return status_for(exc)


def _plain(name: str, error: dict) -> str:
    label = name.replace("_", " ")
    if error.get("type") in ("missing", "string_too_short"):
        return f"Enter the {label}."
    if error.get("type") == "string_too_long":
        return f"The {label} is too long."
    message = str(error.get("msg", "is invalid"))
    return message.removeprefix("Value error, ")


def submitted_list(request: Request, name: str) -> list[str]:
    """Every value of a repeated form field (checkboxes), in order; `form_fields` keeps only the first."""
    content_type = (request.headers.get("content-type") or "").split(";")[0].strip().lower()
    if content_type != "application/x-www-form-urlencoded" or not request.raw_body:
        return []
    return parse_qs(request.raw_body.decode("utf-8", errors="replace")).get(name, [])
