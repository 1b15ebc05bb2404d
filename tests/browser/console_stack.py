"""The operator-console browser journeys run against `live_stack`. Until functions/app.py registers the console
blueprints, `console_url` starts a second app server on the same durable storage whose app has them added (the
same app otherwise); once app.py registers them it simply returns `live_stack.url`.

    python -m tests.browser.console_stack --port N   (the wrapper server itself)
"""
from __future__ import annotations

import sys
from collections.abc import Iterator
from typing import Any

import pytest

CONSOLE_PROBE = "/console/timekeeper"


def _registered(url: str) -> bool:
    """A registered console route sends an anonymous browser to /login; an unknown path does not."""
    import requests

    reply = requests.get(url + CONSOLE_PROBE, headers={"Accept": "text/html"}, allow_redirects=False, timeout=10)
    return reply.status_code == 303 and reply.headers.get("Location", "").startswith("/login")


@pytest.fixture(scope="session")
def console_url(live_stack: Any) -> Iterator[str]:
    if _registered(live_stack.url):
        yield live_stack.url
        return
    from drem_local import stack as local_stack

    port = local_stack.free_port()
    url = f"http://127.0.0.1:{port}"
    env = {**live_stack.env, "DREM_PUBLIC_URL": url}
    log = live_stack.state_dir.parent / "console-app.log"
    process = local_stack.spawn("console app server", [sys.executable, "-m", "tests.browser.console_stack",
                                                       "--port", str(port)], log, env=env)
    try:
        local_stack.wait_for_ok(url + local_stack.APP_HEALTH_PATH, process, 60.0)
        yield url
    finally:
        process.stop(10)


def main() -> int:
    from drem_local import appserver

    appserver._put_project_on_path()
    from app import app
    from chalicelib.routes import console_events, console_fleets, console_races, console_timekeeper

    for module, marker in ((console_events, "/console/events"), (console_fleets, "/console/fleets"),
                           (console_timekeeper, "/console/timekeeper"), (console_races, "/console/races")):
        if marker not in app.routes:
            app.register_blueprint(module.bp)
    return appserver.main(sys.argv[1:])


if __name__ == "__main__":
    raise SystemExit(main())
