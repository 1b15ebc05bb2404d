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

Optional keywords document the route (for `chalicelib.openapi`) and validate its input:

    @route(bp, "/api/events", methods=["POST"], allow={ADMIN, OPERATOR}, body=NewEvent, response=Event,
           status_code=201, summary="Create an event", tags=("events",))
    def create_event(principal: User, body: NewEvent) -> Response: ...

`body=Model` validates the JSON (or urlencoded form) body into Model after the caller is authorised (invalid → 400
naming the field) and passes it as keyword `body`; `query=Model` does the same for the query string → keyword
`query`. `response` (a model or `list[Model]`), `status_code` (documented success status, default 200),
`conditional` (answers 304 to `If-None-Match`), `summary` (default: the view docstring's first line) and `tags`
are documentation only.

`csrf=False` skips the double-submit check. Only for PUBLIC routes whose callers hold no ambient credentials (a device
activating, an API client exchanging a password for tokens); such a view is always given the anonymous principal, so
a session cookie that rides along can never act through it.

`shared=True` marks a PUBLIC GET whose answer is the same for everyone (static files, the favicon, an event's logo):
no CSRF cookie is issued with it, because a `Set-Cookie` makes the answer private and CloudFront would never keep it.

`declared_routes(app)` lists every (path, method, allow, ...) for the authorization-matrix test and the OpenAPI
document; `undeclared_routes(app)` lists any route registered without this wrapper.
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
from pydantic import BaseModel, ValidationError

from chalicelib import base_path, http_errors, logs, multipart_form
from chalicelib.auth import csrf as double_submit
from chalicelib.auth.cookies import CSRF_COOKIE, request_cookies
from chalicelib.auth.sessions import resolve_caller
from chalicelib.core.errors import Forbidden, InvalidInput, NotAuthenticated
from chalicelib.core.principals import ANONYMOUS, Principal, Role
from chalicelib.htmx import is_htmx
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
class RouteDocs:
    """What a route says about its input and output (documentation; `body`/`query` are also validated)."""
    body: type[BaseModel] | None = None
    query: type[BaseModel] | None = None
    response: Any = None
    status_code: int = 200
    conditional: bool = False
    summary: str = ""
    description: str = ""
    tags: tuple[str, ...] = ()
    csrf: bool = True
    shared: bool = False


@dataclass(frozen=True)
class RouteAccess:
    allow: Allow
    view_name: str
    docs: RouteDocs = RouteDocs()


@dataclass(frozen=True)
class DeclaredRoute:
    path: str
    method: str
    allow: Allow
    view_name: str
    docs: RouteDocs = RouteDocs()


@dataclass
class RequestScope:
    """What one request carries through the wrapper: the caller, the CSRF token, cookies to set on the way out."""
    request: Request
    principal: Principal = ANONYMOUS
    via: str = "none"
    csrf_token: str = ""
    set_cookies: list[str] = field(default_factory=list)


def route(bp: Blueprint | Chalice, path: str, *, allow: Allow | Iterable[Role], methods: Iterable[str] = ("GET",),
          content_types: list[str] | None = None, body: type[BaseModel] | None = None,
          query: type[BaseModel] | None = None, response: Any = None, status_code: int = 200,
          conditional: bool = False, summary: str | None = None, tags: Iterable[str] = (), csrf: bool = True,
          shared: bool = False, **route_kwargs: Any) -> Callable[[Callable[..., Any]], Callable]:
    declared = as_allow(allow)
    if not csrf and not declared.public:
        raise ValueError(f"{path}: csrf=False is only for PUBLIC routes (a signed-in caller's cookie needs CSRF)")
    methods = [m.upper() for m in methods]
    if shared and (not declared.public or methods != ["GET"]):
        raise ValueError(f"{path}: shared=True is only for PUBLIC GET routes (the same answer for everyone)")
    if content_types is None and set(methods) & double_submit.STATE_CHANGING_METHODS:
        content_types = FORM_CONTENT_TYPES
    for name, model in (("body", body), ("query", query)):
        if model is not None and not (isinstance(model, type) and issubclass(model, BaseModel)):
            raise TypeError(f"{name}= must be a pydantic model class, not {model!r}")

    def decorator(view: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(view)
        def handler(**params: Any) -> Response:
            request = bp.current_request
            assert request is not None  # Chalice sets it before calling a view
            return _handle(request, declared, view, params, docs)

        doc_lines = (view.__doc__ or "").strip().splitlines()
        docs = RouteDocs(body=body, query=query, response=response, status_code=status_code,
                         conditional=conditional, summary=summary or _summary_from(doc_lines, view.__name__),
                         description="\n".join(line.strip() for line in doc_lines[1:]).strip(), tags=tuple(tags),
                         csrf=csrf, shared=shared)
        access = RouteAccess(declared, f"{view.__module__}.{view.__qualname__}", docs)
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
                found.append(DeclaredRoute(path, method, access.allow, access.view_name, access.docs))
    return found


def undeclared_routes(app: Chalice) -> list[tuple[str, str]]:
    return [(path, method) for path, by_method in sorted(app.routes.items())
            for method, entry in sorted(by_method.items()) if not hasattr(entry.view_function, "drem_access")]


def form_fields(request: Request) -> dict[str, str]:
    """A form body's text fields as {name: first value} (Chalice leaves form parsing to the app): urlencoded, or
    multipart (a form with a file input; its files come from `multipart_body`)."""
    header = request.headers.get("content-type") or ""
    content_type = header.split(";")[0].strip().lower()
    if multipart_form.is_multipart(content_type) and request.raw_body:
        return multipart_body(request).fields
    if content_type != "application/x-www-form-urlencoded" or not request.raw_body:
        return {}
    raw = request.raw_body  # bytes from API Gateway and chalice local; typed str | bytes by Chalice
    parsed = parse_qs(raw.decode("utf-8", errors="replace") if isinstance(raw, bytes) else raw, keep_blank_values=True)
    return {name: values[0] for name, values in parsed.items()}


def body_bytes(request: Request) -> bytes:
    """The request's body as bytes (API Gateway and chalice local give bytes; Chalice types it str | bytes)."""
    raw = request.raw_body or b""
    return raw if isinstance(raw, bytes) else raw.encode("utf-8")


def multipart_body(request: Request) -> multipart_form.MultipartForm:
    """The request's multipart form, parsed once (the CSRF check and the view both read it)."""
    cached: multipart_form.MultipartForm | None = getattr(request, "_drem_multipart", None)
    if cached is None:
        cached = multipart_form.parsed(request.headers.get("content-type") or "", body_bytes(request))
        request._drem_multipart = cached  # type: ignore[attr-defined]
    return cached


def uploaded_file(request: Request, name: str) -> multipart_form.UploadedFile | None:
    """The file a form posted in its file input `name`; None when none was chosen or the form is not multipart."""
    if not multipart_form.is_multipart(request.headers.get("content-type") or ""):
        return None
    return multipart_body(request).files.get(name)


def current_scope() -> RequestScope:
    """The running request's scope (for views that need the CSRF token or must add cookies)."""
    scope = getattr(_local, "scope", None)
    if scope is None:
        raise RuntimeError("current_scope() is only available inside a route")
    return scope


# Per thread: chalice local serves each request on its own thread; Lambda runs one request at a time.
_local = threading.local()


def _summary_from(doc_lines: list[str], view_name: str) -> str:
    if doc_lines and doc_lines[0].strip():
        return doc_lines[0].strip()
    return view_name.replace("_", " ").strip().capitalize()


def _validated_input(request: Request, docs: RouteDocs | None) -> dict[str, BaseModel]:
    """The declared body/query models, validated (a pydantic ValidationError → 400 naming the field)."""
    if docs is None:
        return {}
    found: dict[str, BaseModel] = {}
    if docs.body is not None:
        form = form_fields(request)
        found["body"] = docs.body.model_validate(form) if form else _json_body(docs.body, request.raw_body)
    if docs.query is not None:
        found["query"] = docs.query.model_validate(dict(request.query_params or {}))
    return found


def _json_body(model: type[BaseModel], raw: str | bytes | None) -> BaseModel:
    """`model` from a JSON body (none counts as `{}`); a body that is not a JSON object is named as such."""
    try:
        return model.model_validate_json(raw or b"{}")
    except ValidationError as exc:
        root_kinds = {error["type"] for error in exc.errors() if not error.get("loc")}
        if "json_invalid" in root_kinds:
            raise InvalidInput("The request body is not valid JSON.", field="body") from None
        if root_kinds & {"model_type", "model_attributes_type", "dict_type"}:
            raise InvalidInput("Send a JSON object.", field="body") from None
        raise


def _handle(request: Request, declared: Allow, view: Callable[..., Any], params: dict[str, Any],
            docs: RouteDocs | None = None) -> Response:
    settings = get_settings()
    cookies = request_cookies(request.headers)
    scope = RequestScope(request=request, csrf_token=cookies.get(CSRF_COOKIE, ""))
    # A browser gets a CSRF token with every answer it may post a form from; a file shared by everyone gets none.
    browser = "authorization" not in request.headers and not (docs is not None and docs.shared)
    if browser and not double_submit.fits(scope.csrf_token, None):
        _issue_csrf_token(scope, None, settings.cookie_secure)
    _local.scope = scope
    htmx = is_htmx(request)
    base = base_path.for_request(request.headers, request.context, settings.base_path)
    render.bind_request(htmx=htmx, principal=ANONYMOUS, csrf_token=scope.csrf_token, base_path=base)
    try:
        caller = resolve_caller(request.headers, cookies)
        scope.principal, scope.via = caller.principal, caller.via
        scope.set_cookies.extend(caller.set_cookies)
        logs.note_principal(caller.principal.id)
        secret = caller.csrf_secret if caller.via == "cookie" and caller.principal.is_user else None
        if browser and secret and not double_submit.fits(scope.csrf_token, secret):
            _issue_csrf_token(scope, secret, settings.cookie_secure)  # pages of this session get a bound token
        render.bind_request(htmx=htmx, principal=caller.principal, csrf_token=scope.csrf_token, base_path=base)
        declared.decide(caller.principal)
        checks_csrf = docs is None or docs.csrf
        if checks_csrf and request.method in double_submit.STATE_CHANGING_METHODS and caller.via != "header":
            double_submit.require_same_origin(request.headers, settings.public_url)
            double_submit.require_matching_token(cookies.get(CSRF_COOKIE), secret, request.headers,
                                                 form_fields(request))
        # A CSRF-exempt view must not act as whoever's cookie came along (a forged cross-site post would).
        acting = caller.principal if checks_csrf else ANONYMOUS
        response = view(acting, **params, **_validated_input(request, docs))
    except Exception as exc:  # every failure, expected or not, leaves through the one error→HTTP module
        response = http_errors.to_response(exc, request)
    finally:
        # The response is rendered by now; nothing of this caller may leak into the thread's next request.
        _local.scope = None
        render.bind_request()
    return _varying_on_base_path(_with_cookies(response, scope.set_cookies))


def _varying_on_base_path(response: Response) -> Response:
    """Pages and redirects hold URLs under the request's base path: a shared cache must key them by it."""
    headers = response.headers
    content_type = str(headers.get("Content-Type") or "")
    if content_type.startswith("text/html") or "Location" in headers or "HX-Redirect" in headers:
        vary = str(headers.get("Vary") or "")
        headers["Vary"] = f"{vary}, {base_path.FORWARDED_PREFIX_HEADER}" if vary else base_path.FORWARDED_PREFIX_HEADER
    return response


def _issue_csrf_token(scope: RequestScope, secret: str | None, secure: bool) -> None:
    scope.csrf_token = double_submit.new_token(secret)
    scope.set_cookies = [c for c in scope.set_cookies if not c.startswith(f"{CSRF_COOKIE}=")]
    scope.set_cookies.append(double_submit.csrf_cookie(scope.csrf_token, secure=secure))


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
