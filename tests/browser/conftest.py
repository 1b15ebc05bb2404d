"""Browser fixtures: Debian chromium driven by Playwright's sync API (no `playwright install`)."""
from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import pytest

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]


@pytest.fixture(scope="session")
def chromium() -> Iterator[Any]:
    from pathlib import Path

    from playwright.sync_api import sync_playwright

    if not Path(CHROMIUM).is_file():
        pytest.fail(f"{CHROMIUM} is missing: `make install-test` installs Debian chromium")
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield browser
        browser.close()


# Chromium logs every 4xx answer as "Failed to load resource"; these are drem's refusals that the page shows the
# person (a form's 400/409, the not-allowed page's 403, a wrong password's 401, a rate limit's 429). A missing file
# (404) or a server failure (5xx) still fails the test.
_REFUSAL_SHOWN_ON_PAGE = re.compile(r"^Failed to load resource: the server responded with a status of "
                                    r"(400|401|403|409|422|429) ")
# htmx logs a request it cancelled itself (the page navigated on, or a newer poll replaced it under hx-sync) as
# "htmx:afterRequest" + "htmx:sendAbort": nothing a person sees. A request that failed still fails the test, because
# htmx logs its own event beside afterRequest ("htmx:sendError", "htmx:timeout", "htmx:responseError").
_CANCELLED_BY_HTMX = re.compile(r"^htmx:(afterRequest|sendAbort)\b")


class BrowserErrors:
    """Every console error, uncaught page error and Content-Security-Policy violation seen in any browser context the
    test opens, from its first request to its last (typing, clicks and polls included, not only page loads).

    A test that provokes an error on purpose names it with `allow(pattern)`; anything else fails the test."""

    def __init__(self) -> None:
        self.seen: list[str] = []
        self._allowed: list[re.Pattern[str]] = []

    def allow(self, pattern: str) -> None:
        self._allowed.append(re.compile(pattern))

    def watch(self, context: Any) -> Any:
        context.on("console", self._console)
        context.on("weberror", lambda error: self.seen.append(f"uncaught error: {error.error}"))
        return context

    def _console(self, message: Any) -> None:
        if _REFUSAL_SHOWN_ON_PAGE.search(message.text) or _CANCELLED_BY_HTMX.match(message.text.strip()):
            return
        if message.type == "error" or "Content Security Policy" in message.text:
            where = (message.location or {}).get("url", "")
            self.seen.append(f"console {message.type} at {where}: {message.text}")

    def unexpected(self) -> list[str]:
        return [seen for seen in self.seen if not any(p.search(seen) for p in self._allowed)]


@pytest.fixture(autouse=True)
def browser_errors(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> Iterator[BrowserErrors]:
    """Watches every context made from the session's chromium during the test (the `page` fixture's and those a
    test makes itself) and fails the test on any error they logged."""
    errors = BrowserErrors()
    if "chromium" not in request.fixturenames:
        yield errors
        return
    chromium = request.getfixturevalue("chromium")
    new_context = chromium.new_context

    def watched_context(*args: Any, **kwargs: Any) -> Any:
        return errors.watch(new_context(*args, **kwargs))

    monkeypatch.setattr(chromium, "new_context", watched_context)
    yield errors
    unexpected = errors.unexpected()
    assert unexpected == [], "the browser logged errors while the test ran:\n" + "\n".join(unexpected)


@pytest.fixture
def page(chromium: Any, browser_errors: BrowserErrors) -> Iterator[Any]:
    """A fresh browser context (no cookies) per test; `browser_errors` fails the test on any console error, uncaught
    exception or Content-Security-Policy violation (chromium logs every blocked script, handler, style or
    connection to the console)."""
    context = chromium.new_context()
    context.set_default_timeout(10_000)
    page = context.new_page()
    yield page
    # A route handler may still be answering a poll the page made as the test ended; without this, its
    # "Request context disposed" surfaces as an error in whichever test runs next on this worker.
    page.unroute_all(behavior="ignoreErrors")
    context.close()


@pytest.fixture(scope="session")
def app_url(live_stack: Any) -> str:
    """The app of the session's live stack (functions/app.py with every blueprint), as the browser reaches it."""
    return live_stack.url
