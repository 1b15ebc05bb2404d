"""The app server with every console blueprint, for the racer/desk/forbidden journeys, until app.py registers them.

`live_stack` runs app.py as it is; `racer_console_url` starts a second app server process on the same storage and
user pool (same env) that also registers each `chalicelib.routes.console_*` blueprint app.py does not register
yet. Once app.py registers them all, it is the same app.

    python -m tests.browser.racer_console_stack PORT     (what the fixture runs)
"""
from __future__ import annotations

import importlib
import pkgutil
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[2]
# Ours must load; the other console modules are registered when they load (they may be mid-edit by their owners).
REQUIRED = ("console_racer", "console_registration", "console_users", "console_models")


@pytest.fixture(scope="session")
def racer_console_url(live_stack: Any, tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    from drem_local import stack as local_stack

    port = local_stack.free_port()
    url = f"http://127.0.0.1:{port}"
    env = {**live_stack.env, "DREM_PUBLIC_URL": url, "PYTHONPATH": str(REPO)}
    log = tmp_path_factory.mktemp("racer-console-app") / "app.log"
    process = local_stack.spawn("console app server", [sys.executable, "-m", "tests.browser.racer_console_stack",
                                                       str(port)], log, env=env)
    try:
        local_stack.wait_for_ok(url + local_stack.APP_HEALTH_PATH, process, 60.0)
    except BaseException:
        print(process.log_tail())
        process.stop(2)
        raise
    yield url
    process.stop(10)


def register_console_blueprints(app: Any) -> list[str]:
    import chalicelib.routes as routes

    added = []
    for info in pkgutil.iter_modules(routes.__path__):
        if not info.name.startswith("console_"):
            continue
        try:
            blueprint = getattr(importlib.import_module(f"chalicelib.routes.{info.name}"), "bp", None)
            if blueprint is not None and getattr(blueprint, "_current_app", None) is None:
                app.register_blueprint(blueprint)
                added.append(info.name)
        except Exception as exc:
            if info.name in REQUIRED:
                raise
            print(f"racer_console_stack: {info.name} not registered: {exc!r}", file=sys.stderr)
    return added


def main(argv: list[str]) -> int:
    from drem_local import appserver

    appserver._put_project_on_path()
    import app as app_module

    register_console_blueprints(app_module.app)
    server = appserver.make_server("127.0.0.1", int(argv[0]))
    server.serve_forever()
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
