"""Whether htmx sent a request: then a page answers with its content block or a fragment, a form with the part it
swaps, and an expired session with a 401 (a 303 to the sign-in page would be swapped into the page)."""
from __future__ import annotations

from chalice.app import Request


def is_htmx(request: Request) -> bool:
    # htmx sets `HX-Request: true` on every request it makes (https://htmx.org/reference/#request_headers).
    return request.headers.get("hx-request") == "true"
