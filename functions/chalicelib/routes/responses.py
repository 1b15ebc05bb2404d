"""Small response helpers shared by the route modules."""
from __future__ import annotations

from chalice import Response


def redirect(location: str, *, cookies: list[str] | None = None) -> Response:
    # 303: after a form POST the browser follows with a GET, so a reload never re-submits the form.
    headers: dict = {"Location": location}
    if cookies:
        headers["Set-Cookie"] = list(cookies)
    return Response(body="", status_code=303, headers=headers)


def safe_next(path: str | None) -> str:
    """Only same-site paths: "/races" yes; "//evil.example", "https://…" or "/\\evil" no (open redirects)."""
    if not path or not path.startswith("/") or path.startswith("//") or "\\" in path or "\n" in path:
        return "/"
    return path
