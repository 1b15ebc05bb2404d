"""How every HTML form of drem is handled (console pages, sign-in and sign-up), one way:

    values = submitted(bp.current_request, "name", "email")        # the posted fields, nothing else
    try:
        service.do(principal, SomeForm.model_validate(values))      # pydantic, then the domain's own rules
    except SHOWN_ON_FORM as exc:
        return _page(values=values, errors=field_errors(exc), status=error_status(exc))
    return redirect("/console/somewhere")                           # or the page again with a notice

The page is drawn again with the operator's `values` and `errors` keyed by input name, so nothing typed is lost and
each message sits next to its input (templates/partials/form.html ties them together). The CSRF token is checked
before the view runs (`chalicelib.auth.access`); `submitted` drops it so strict models never see it.

`route(..., body=Model)` stays the way of the JSON API: a refused body there is a 400 error answer, not a form.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any
from urllib.parse import parse_qs

from chalice import Response
from chalice.app import Request
from pydantic import ValidationError

from chalicelib.auth.access import form_fields
from chalicelib.core.errors import DremError, NotFound
from chalicelib.domain.countries import country_code_from_text
from chalicelib.http_errors import status_for
from chalicelib.routes import responses

# What a form shows next to its inputs: pydantic's and the domain's refusals, never unexpected errors.
SHOWN_ON_FORM = (ValidationError, DremError)
FORM = "form"  # errors that belong to no input: shown at the top of the form
_CSRF_FIELD = "csrf_token"


def submitted(request: Request, *fields: str) -> dict[str, str]:
    """The urlencoded form: only `fields` if named (stray inputs never reach a strict model), else every field
    (forms with numbered rows); never the CSRF token."""
    form = form_fields(request)
    if fields:
        return {name: form[name] for name in fields if name in form}
    return {name: value for name, value in form.items() if name != _CSRF_FIELD}


def submitted_list(request: Request, name: str) -> list[str]:
    """Every value of a repeated form field (checkboxes), in order; `submitted` keeps only the first."""
    content_type = (request.headers.get("content-type") or "").split(";")[0].strip().lower()
    if content_type != "application/x-www-form-urlencoded" or not request.raw_body:
        return []
    return parse_qs(request.raw_body.decode("utf-8", errors="replace")).get(name, [])


def field_errors(exc: Exception, default_field: str = FORM, *, rename: Callable[[str], str] = lambda name: name,
                 missing: str = "Enter the {label}.", missing_object_field: str | None = None) -> dict[str, str]:
    """{input name: message} for a refusal caught as SHOWN_ON_FORM.

    A message naming no field goes under `default_field`. `rename` maps a model's field path ("race_config.
    race_time_min", "tracks.0.fleet_id") to the input's name. `missing` words an empty required input ("Enter your
    {label}." on the racer's own forms). A NotFound naming no field is the page's own object (an event deleted
    meanwhile): raised again for the 404 page, unless `missing_object_field` is the input that named it."""
    if isinstance(exc, ValidationError):
        found: dict[str, str] = {}
        for error in exc.errors(include_url=False):
            path = [str(part) for part in error.get("loc", ())]
            name = rename(".".join(path)) if path else default_field
            found.setdefault(name, _plain(error, path, missing))
        return found
    if isinstance(exc, NotFound) and not exc.field:
        if missing_object_field is None:
            raise exc
        return {missing_object_field: exc.message}
    if isinstance(exc, DremError):
        return {rename(exc.field) if exc.field else default_field: exc.message}
    raise exc


def error_status(exc: Exception) -> int:
    """The form's status: 400 for bad input, 409 for a conflict, 429 when rate-limited (as the JSON API)."""
    return status_for(exc)


def with_country_code(values: dict[str, str], name: str = "country_code", *, required: bool = True) -> dict[str, str]:
    """A copy of `values` with the country picker's text ("Sweden (SE)", "sweden", "se") replaced by its code, for
    the strict domain model; InvalidInput naming the field for anything else. `values` keeps what was typed (shown
    again with the error). An optional picker left empty is dropped (no change)."""
    typed = values.get(name, "")
    if not required and not typed.strip():
        return {key: value for key, value in values.items() if key != name}
    return {**values, name: country_code_from_text(typed, field=name)}


def redirect(location: str, done: str = "") -> Response:
    """After a successful post: 303 for a plain browser, HX-Redirect for htmx (which would swap a 303's body).
    `done` names what was done (a key of `console.notices.DONE`): the page shows its success message."""
    if done:
        path, _, anchor = location.partition("#")
        location = f"{path}{'&' if '?' in path else '?'}done={done}" + (f"#{anchor}" if anchor else "")
    response = responses.redirect(location)
    response.headers["HX-Redirect"] = response.headers["Location"]  # the same URL, under the base path
    return response


def checkbox(fields: dict[str, Any], name: str) -> bool:
    return fields.get(name) in {"on", "true", "1", "yes"}


def optional(value: str | None) -> str | None:
    value = (value or "").strip()
    return value or None


def _plain(error: dict, path: list[str], missing: str) -> str:
    """pydantic's message in the words of a form: the field's own name, not 'String should have …'."""
    label = next((part for part in reversed(path) if not part.isdigit()), "value").replace("_", " ")
    kind = error.get("type")
    if kind == "missing" or (kind == "string_too_short" and not str(error.get("input") or "").strip()):
        return missing.format(label=label)
    if kind == "string_too_long":
        return f"The {label} is too long (at most {error.get('ctx', {}).get('max_length', '?')} characters)."
    return str(error.get("msg", "is invalid")).removeprefix("Value error, ")
