"""Small helpers shared by the operator console's HTML routes: reading a form, redirecting after a post, turning a
validation or domain error into messages next to the form's fields, and rendering a form again with them."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from chalice import Response
from chalice.app import Request
from pydantic import ValidationError

from chalicelib.auth.access import form_fields
from chalicelib.domain.errors import DremError, InvalidInput, NotFound
from chalicelib.http_errors import status_for, validation_fields


def form(request: Request) -> dict[str, str]:
    """The posted form (htmx and plain browser posts are urlencoded), `csrf_token` left out."""
    fields = form_fields(request)
    fields.pop("csrf_token", None)
    return fields


def redirect(location: str) -> Response:
    """After a successful post: 303 for a plain browser, HX-Redirect for htmx (which would swap a 303's body)."""
    return Response(body="", status_code=303, headers={"Location": location, "HX-Redirect": location})


def field_errors(exc: Exception, rename: Callable[[str], str] = lambda name: name) -> dict[str, str]:
    """{form field: message} for a pydantic or domain error; unnamed problems go under "form"."""
    if isinstance(exc, ValidationError):
        found: dict[str, str] = {}
        for name, message in validation_fields(exc).items():
            # A rule over the whole input (no field) belongs at the top of the form.
            found.setdefault("form" if name == "body" else rename(name), message.removeprefix("Value error, "))
        return found
    if isinstance(exc, DremError):
        return {rename(exc.field) if exc.field else "form": exc.message}
    raise exc


def render_or_errors(action: Callable[[], Response], again: Callable[[dict[str, str], int], Response],
                     rename: Callable[[str], str] = lambda name: name, missing_field: str | None = None) -> Response:
    """Run `action`; if the input or a domain rule refuses it, render the form `again` with the messages next to the
    fields (400/409) instead of an error page, so nothing the operator typed is lost. A missing object stays a 404
    unless `missing_field` says which field named it."""
    try:
        return action()
    except (ValidationError, InvalidInput, DremError) as exc:
        if isinstance(exc, NotFound) and not exc.field:
            if missing_field is None:
                raise
            return again({missing_field: exc.message}, 400)
        if isinstance(exc, DremError) and status_for(exc) in (401, 403):
            raise
        return again(field_errors(exc, rename), status_for(exc))


def checkbox(fields: dict[str, Any], name: str) -> bool:
    return fields.get(name) in {"on", "true", "1", "yes"}


def optional(value: str | None) -> str | None:
    value = (value or "").strip()
    return value or None
