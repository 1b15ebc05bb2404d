"""Who may call a route: declared once, next to the route, with `route(...)`.

    from chalicelib.auth.access import ADMIN, OPERATOR, PUBLIC, SIGNED_IN, route

    @route(bp, "/api/me", methods=["GET"], allow=SIGNED_IN)
    def whoami(principal: User) -> dict: ...

    @route(bp, "/api/events/{event_id}", methods=["DELETE"], allow={ADMIN, OPERATOR})
    def delete_event(principal: User, event_id: str) -> Response: ...

`allow` is PUBLIC, SIGNED_IN (any signed-in user, not devices) or a set of roles (Cognito groups and/or device
kinds CAR, TIMER). The wrapper resolves the caller from `Authorization: Bearer|Device` or the session cookie,
answers 401 (no or invalid credentials) or 403 (wrong role, missing CSRF token) through `chalicelib.http_errors`,
and calls the view with the Principal first and the URL parameters as keywords. Domain errors raised by the view
are mapped there too. Whether the caller may touch a particular object (racer A vs racer B) is the service's
decision: see `chalicelib.domain.ownership`.

`declared_routes(app)` lists every (path, method, allow) for the authorization-matrix test; `undeclared_routes(app)`
lists any route registered without this wrapper.
"""
from __future__ import annotations

import functools
import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import parse_qs

from chalice import Blueprint, Chalice, Response
from chalice.app import Request

from chalicelib import http_errors, logs
from chalicelib.auth import csrf
from chalicelib.auth.cookies import CSRF_COOKIE, request_cookies
from chalicelib.auth.principals import ANONYMOUS, Principal, Role
from chalicelib.auth.sessions import resolve_caller
from chalicelib.domain.errors import Forbidden, NotAuthenticated
from chalicelib.settings import get_settings
from drem_web import render

ADMIN, OPERATOR, COMMENTATOR, REGISTRATION, RACER = (Role.ADMIN, Role.OPERATOR, Role.COMMENTATOR,
                                                     Role.REGISTRATION, Role.RACER)
CAR, TIMER = Role.CAR, Role.TIMER
STAFF = frozenset({ADMIN, OPERATOR, COMMENTATOR, REGISTRATION})

FORM_CONTENT_TYPES = ["application/x-www-form-urlencoded", "application/json", "multipart/form-data"]


@dataclass(frozen=True)
class Allow:
    public: bool = False
    signed_in: bool = False
    roles: frozenset[Role] = frozenset()

    def decide(self, principal: Principal) -> None:
        """Return if `principal` may call; raise NotAuthenticated (→401) or Forbidden (→403) otherwise."""
        if self.public:
            return
        if principal.kind == "anonymous":
            raise NotAuthenticated("Sign in to continue.")
        if self.signed_in and principal.is_user:
            return
        if principal.roles & self.roles:
            return
        raise Forbidden(f"This needs the role {self.describe()}.")

    def permits(self, principal: Principal) -> bool:
        try:
            self.decide(principal)
        except (NotAuthenticated, Forbidden):
            return False
        return True

    def describe(self) -> str:
        if self.public:
            return "public"
        if self.signed_in:
            return "signed in"
        return " or ".join(sorted(r.value for r in self.roles))


PUBLIC = Allow(public=True)
SIGNED_IN = Allow(signed_in=True)


def as_allow(allow: Allow | Iterable[Role]) -> Allow:
    if isinstance(allow, Allow):
        return allow
    roles = frozenset(Role(r) for r in allow)
    if not roles:
        raise ValueError("allow= must name at least one role (or be PUBLIC / SIGNED_IN)")
    return Allow(roles=roles)


@dataclass(frozen=True)
class RouteAccess:
    allow: Allow
    view_name: str


@dataclass(frozen=True)
class DeclaredRoute:
    path: str
    method: str
    allow: Allow
    view_name: str


@dataclass
class RequestScope:
    """What one request carries through the wrapper: the caller, the CSRF token, cookies to set on the way out."""
    request: Request
    principal: Principal = ANONYMOUS
    via: str = "none"
    csrf_token: str = ""
    set_cookies: list[str] = field(default_factory=list)


def route(bp: Blueprint | Chalice, path: str, *, allow: Allow | Iterable[Role], methods: Iterable[str] = ("GET",),
          content_types: list[str] | None = None, **route_kwargs: Any) -> Callable[[Callable[..., Any]], Callable]:
    declared = as_allow(allow)
    methods = [m.upper() for m in methods]
    if content_types is None and set(methods) & csrf.STATE_CHANGING_METHODS:
        content_types = FORM_CONTENT_TYPES

    def decorator(view: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(view)
        def handler(**params: Any) -> Response:
            return _handle(bp.current_request, declared, view, params)

        access = RouteAccess(declared, f"{view.__module__}.{view.__qualname__}")
        handler.drem_access = access  # type: ignore[attr-defined]
        extra = {"content_types": content_types} if content_types else {}
        bp.route(path, methods=methods, **extra, **route_kwargs)(handler)
        return handler

    return decorator


def declared_routes(app: Chalice) -> list[DeclaredRoute]:
    found = []
    for path, by_method in sorted(app.routes.items()):
        for method, entry in sorted(by_method.items()):
            access: RouteAccess | None = getattr(entry.view_function, "drem_access", None)
            if access is not None:
                found.append(DeclaredRoute(path, method, access.allow, access.view_name))
    return found


def undeclared_routes(app: Chalice) -> list[tuple[str, str]]:
    return [(path, method) for path, by_method in sorted(app.routes.items())
            for method, entry in sorted(by_method.items()) if not hasattr(entry.view_function, "drem_access")]


def form_fields(request: Request) -> dict[str, str]:
    """A urlencoded form body as {name: first value} (Chalice leaves form parsing to the app)."""
    content_type = (request.headers.get("content-type") or "").split(";")[0].strip().lower()
    if content_type != "application/x-www-form-urlencoded" or not request.raw_body:
        return {}
    parsed = parse_qs(request.raw_body.decode("utf-8", errors="replace"), keep_blank_values=True)
    return {name: values[0] for name, values in parsed.items()}


def current_scope() -> RequestScope:
    """The running request's scope (for views that need the CSRF token or must add cookies)."""
    scope = getattr(_local, "scope", None)
    if scope is None:
        raise RuntimeError("current_scope() is only available inside a route")
    return scope


# Per thread: chalice local serves each request on its own thread; Lambda runs one request at a time.
_local = threading.local()


def _handle(request: Request, declared: Allow, view: Callable[..., Any], params: dict[str, Any]) -> Response:
    settings = get_settings()
    cookies = request_cookies(request.headers)
    scope = RequestScope(request=request, csrf_token=cookies.get(CSRF_COOKIE, ""))
    if not scope.csrf_token and "authorization" not in request.headers:
        scope.csrf_token = csrf.new_token()
        scope.set_cookies.append(csrf.csrf_cookie(scope.csrf_token, secure=settings.cookie_secure))
    _local.scope = scope
    htmx = request.headers.get("hx-request") == "true"
    render.bind_request(htmx=htmx, principal=ANONYMOUS, csrf_token=scope.csrf_token)
    try:
        caller = resolve_caller(request.headers, cookies)
        scope.principal, scope.via = caller.principal, caller.via
        scope.set_cookies.extend(caller.set_cookies)
        logs.note_principal(caller.principal.id)
        render.bind_request(htmx=htmx, principal=caller.principal, csrf_token=scope.csrf_token)
        declared.decide(caller.principal)
        if request.method in csrf.STATE_CHANGING_METHODS and caller.via != "header":
            csrf.require_matching_token(cookies.get(CSRF_COOKIE), request.headers, form_fields(request))
        response = view(caller.principal, **params)
    except Exception as exc:  # every failure, expected or not, leaves through the one error→HTTP module
        response = http_errors.to_response(exc, request)
    finally:
        # The response is rendered by now; nothing of this caller may leak into the thread's next request.
        _local.scope = None
        render.bind_request()
    return _with_cookies(response, scope.set_cookies)


def _with_cookies(response: Any, cookies: list[str]) -> Response:
    if not isinstance(response, Response):
        response = Response(body=response)
    if not cookies:
        return response
    existing = response.headers.get("Set-Cookie")
    own = [existing] if isinstance(existing, str) else list(existing or [])
    # A view that sets a cookie itself (sign-in, sign-out) wins over the wrapper's renewal of the same cookie.
    own_names = {c.split("=", 1)[0] for c in own}
    response.headers["Set-Cookie"] = own + [c for c in cookies if c.split("=", 1)[0] not in own_names]
    return response
