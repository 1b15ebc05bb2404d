"""The app in-process behind a front door that serves it under a path prefix, and a crawler that follows every URL a
page holds through that door.

Two doors, each delivering requests the way the real one does:
- `api_gateway_stage()`: the execute-api host. The browser asks for `/api/console/events`; API Gateway strips the
  stage and invokes the Lambda with a REST proxy event whose `path`/`resource` are the app's own path and whose
  `requestContext` names `stage`, `domainName` and the full `path` (AWS: "Input format of a Lambda function for proxy
  integration"; chalice/app.py `Request.__init__` keeps that context as `Request.context`). A URL outside the stage
  never reaches the app (API Gateway answers 403 "Missing Authentication Token").
- `reverse_proxy("/drem")`: nginx-style `location /drem/ { proxy_pass http://app/; proxy_set_header
  X-Forwarded-Prefix /drem; }`: the prefix is stripped, the header added, the Host kept; no stage in the context
  (the local app server's context, chalice/local.py `LambdaEventConverter`, has none either).

The crawler records every URL it met (attribute, Location, HX-Redirect) with where it came from, so a test can assert
that each one starts with the prefix and answers.
"""
from __future__ import annotations

import re
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from html.parser import HTMLParser
from typing import Any
from urllib.parse import urlencode, urljoin, urlsplit

from chalice.local import LambdaContext, RouteMatcher

EXECUTE_API_HOST = "a1b2c3d4e5.execute-api.eu-west-1.amazonaws.com"
PROXY_HOST = "events.example.org"
URL_ATTRIBUTES = {"href", "src", "action", "hx-get", "hx-post", "hx-put", "hx-patch", "hx-delete"}
POSTED_ATTRIBUTES = {"hx-post", "hx-put", "hx-patch", "hx-delete", "data-request-url"}


@dataclass(frozen=True)
class Reply:
    status: int
    headers: dict[str, list[str]]
    body: str

    def header(self, name: str) -> str | None:
        values = self.headers.get(name.lower())
        return values[0] if values else None


@dataclass
class FrontDoor:
    """Delivers browser requests for `prefix + path` to the Chalice app as the real front door would."""
    app: Any
    prefix: str
    host: str
    stage: str | None = None        # API Gateway: the stage the prefix names
    forwarded_prefix: str | None = None  # a reverse proxy: the header it sets
    outside_prefix: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._routes = RouteMatcher(list(self.app.routes))

    def request(self, method: str, url: str, headers: Mapping[str, str], body: bytes = b"") -> Reply:
        path_and_query = url[len(self.prefix):] if url.startswith(self.prefix + "/") else None
        if path_and_query is None:
            self.outside_prefix.append(url)
            return Reply(404, {}, f"{url} is outside {self.prefix}/")
        try:
            match = self._routes.match_route(path_and_query)
        except ValueError:
            return Reply(404, {}, f"no route for {path_and_query}")  # API Gateway: 403 Missing Authentication Token
        path = path_and_query.split("?")[0]
        all_headers = {"host": self.host, **{k.lower(): v for k, v in headers.items()}}
        if self.forwarded_prefix is not None:
            all_headers["x-forwarded-prefix"] = self.forwarded_prefix
        context: dict[str, Any] = {"httpMethod": method, "resourcePath": match.route, "path": path,
                                   "identity": {"sourceIp": "203.0.113.7"}, "requestId": "front-door"}
        if self.stage is not None:
            context.update(stage=self.stage, domainName=self.host, path=f"/{self.stage}{path}")
        event = {"resource": match.route, "path": path, "httpMethod": method, "headers": all_headers,
                 "multiValueQueryStringParameters": match.query_params or None, "pathParameters": match.captured,
                 "stageVariables": None, "requestContext": context, "body": body.decode() if body else None,
                 "isBase64Encoded": False}
        answer = self.app(event, LambdaContext("api_handler", memory_size=128))
        merged: dict[str, list[str]] = {}
        for name, value in (answer.get("headers") or {}).items():
            merged.setdefault(name.lower(), []).append(value)
        for name, values in (answer.get("multiValueHeaders") or {}).items():
            merged.setdefault(name.lower(), []).extend(values)
        text = "" if answer.get("isBase64Encoded") else str(answer.get("body") or "")
        return Reply(int(answer["statusCode"]), merged, text)


def api_gateway_stage(app: Any, stage: str = "api") -> FrontDoor:
    return FrontDoor(app, prefix=f"/{stage}", host=EXECUTE_API_HOST, stage=stage)


def reverse_proxy(app: Any, prefix: str = "/drem") -> FrontDoor:
    return FrontDoor(app, prefix=prefix, host=PROXY_HOST, forwarded_prefix=prefix)


@dataclass(frozen=True)
class FoundUrl:
    url: str
    kind: str  # the attribute or header it came from
    found_on: str
    posted: bool


class _UrlCollector(HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.found: list[tuple[str, str, bool]] = []
        self.base_meta: list[str] = []
        self.forms: list[dict[str, Any]] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        values = {name: value or "" for name, value in attrs}
        if tag == "meta" and values.get("name") == "drem-base":
            self.base_meta.append(values.get("content", ""))
        if tag == "form":
            self.forms.append({"action": values.get("action", ""), "method": values.get("method", "get").lower(),
                               "fields": {}})
        if tag == "input" and self.forms and values.get("name"):
            self.forms[-1]["fields"][values["name"]] = values.get("value", "")
        for name, value in values.items():
            if name in URL_ATTRIBUTES or re.fullmatch(r"data-[a-z-]*url", name):
                posted = name in POSTED_ATTRIBUTES or (
                    name == "action" and values.get("method", "get").lower() == "post")
                self.found.append((name, value, posted))


def parse(html: str) -> _UrlCollector:
    collector = _UrlCollector()
    collector.feed(html)
    return collector


@dataclass
class Crawler:
    """A browser-like client (cookie jar, CSRF token from the page) going through one front door."""
    door: FrontDoor
    cookies: dict[str, str] = field(default_factory=dict)
    found: list[FoundUrl] = field(default_factory=list)
    answers: dict[str, int] = field(default_factory=dict)  # GET URL → status
    posted: dict[str, int] = field(default_factory=dict)   # POST URL → status (asked without a CSRF token)
    base_metas: set[str] = field(default_factory=set)

    def request(self, method: str, url: str, *, form: Mapping[str, str] | None = None, htmx: bool = False) -> Reply:
        headers = {"Accept": "text/html"}
        if htmx:
            headers["HX-Request"] = "true"
        if self.cookies:
            headers["Cookie"] = "; ".join(f"{k}={v}" for k, v in self.cookies.items())
        body = b""
        if form is not None:
            body = urlencode(form).encode()
            headers["Content-Type"] = "application/x-www-form-urlencoded"
        reply = self.door.request(method, url, headers, body)
        for cookie in reply.headers.get("set-cookie", []):
            first, *attributes = [part.strip() for part in cookie.split(";")]
            name, _, value = first.partition("=")
            if "Max-Age=0" in attributes or not value:
                self.cookies.pop(name, None)
            else:
                self.cookies[name] = value
        for header in ("location", "hx-redirect"):
            target = reply.header(header)
            if target:
                self.found.append(FoundUrl(target, header, f"{method} {url}", posted=False))
        if (reply.header("content-type") or "").startswith("text/html"):
            page = parse(reply.body)
            self.base_metas.update(page.base_meta)
            for kind, value, posted in page.found:
                # A relative reference ("?track=2") resolves against the page, as a browser does.
                resolved = value if value.startswith(("/", "#")) or urlsplit(value).scheme else urljoin(url, value)
                self.found.append(FoundUrl(resolved, kind, url, posted))
        return reply

    def sign_in(self, username: str, password: str, *, then: str) -> Reply:
        """Through the sign-in form, as a person would: asked for `then`, sent to sign in, and back."""
        asked = self.request("GET", then)
        assert asked.status == 303, (then, asked.status)
        login_url = asked.header("location") or ""
        form = next(f for f in parse(self.request("GET", login_url).body).forms if "password" in f["fields"])
        fields = {**form["fields"], "username": username, "password": password}
        signed_in = self.request("POST", form["action"], form=fields)
        assert signed_in.status == 303, signed_in.body[:500]
        return signed_in

    def crawl(self, start: Iterable[str], *, max_requests: int = 250) -> None:
        """Follows every same-site GET URL found (pages, fragments, assets) breadth-first, each once; asks each
        posted URL once without a CSRF token (the app refuses before acting, but only a route that exists can)."""
        queue: deque[FoundUrl] = deque(FoundUrl(url, "start", "", posted=False) for url in start)
        seen_index = 0
        while True:
            while seen_index < len(self.found):
                queue.append(self.found[seen_index])
                seen_index += 1
            if not queue:
                return
            item = queue.popleft()
            url = item.url
            if not url.startswith("/") or url.startswith("//") or url in (self.posted if item.posted else self.answers):
                continue
            assert len(self.answers) + len(self.posted) < max_requests, "the crawl did not end: more URLs than expected"
            if item.posted:
                self.posted[url] = self._post_without_token(url)
                continue
            fragment = item.kind.startswith(("hx-", "data-"))  # htmx and the scripts ask for fragments
            self.answers[url] = self.request("GET", url, htmx=fragment).status

    def _post_without_token(self, url: str) -> int:
        reply = self.door.request("POST", url, {"Accept": "text/html", "HX-Request": "true", "Cookie": "; ".join(
            f"{k}={v}" for k, v in self.cookies.items() if k != "drem_csrf")}, b"")
        return reply.status
