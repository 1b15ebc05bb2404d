"""Browser fixtures: Debian chromium driven by Playwright's sync API (no `playwright install`)."""
from __future__ import annotations

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


@pytest.fixture
def page(chromium: Any) -> Iterator[Any]:
    """A fresh browser context (no cookies) per test. Fails the test if the page broke the Content-Security-Policy
    (chromium logs every blocked script, handler, style or connection to the console)."""
    context = chromium.new_context()
    context.set_default_timeout(10_000)
    page = context.new_page()
    violations: list[str] = []
    page.on("console", lambda message: violations.append(message.text)
            if "Content Security Policy" in message.text else None)
    yield page
    # A route handler may still be answering a poll the page made as the test ended; without this, its
    # "Request context disposed" surfaces as an error in whichever test runs next on this worker.
    page.unroute_all(behavior="ignoreErrors")
    context.close()
    assert violations == [], f"the page broke the Content-Security-Policy: {violations}"


@pytest.fixture(scope="session")
def app_url(live_stack: Any) -> str:
    """The app of the session's live stack (functions/app.py with every blueprint), as the browser reaches it."""
    return live_stack.url
