"""A booth drive survives the app being killed -9 mid-drive: every decision the server answered is in the saved run,
none is invented. Saved by the racer's **Finish** (the page's button after "Driving stopped"), or, if the racer walked
away, by the next drive anyone starts. On the session's stack, exactly as `drem up` runs it (the app is restarted for
the other tests)."""
from __future__ import annotations

import json
import secrets
from typing import Any

import requests

from tests.browser.console_api import access_token, call, create_user

APP_START_S = 60.0


def drive(url: str, token: str, steps: int, throttle: float = 1.0) -> str:
    started = call(url, "POST", "/api/drive", token=token, body={"track_id": "drem_oval"}, expect=201)
    for step in range(steps):
        answer = call(url, "POST", f"/api/runs/{started['run_id']}/drive", token=token,
                      body={"steering": 0.0, "throttle": throttle})
        assert answer["frames"] == step + 1  # answered: the racer saw this decision happen
    return started["run_id"]


def controls(url: str, token: str, run_id: str) -> list[dict[str, Any]]:
    reply = requests.get(f"{url}/api/runs/{run_id}/artifacts/controls.jsonl", timeout=15,
                         headers={"Authorization": f"Bearer {token}"})
    assert reply.status_code == 200, reply.text
    return [json.loads(line) for line in reply.text.splitlines() if line]


def kill_and_restart_app(live_stack: Any) -> None:
    running = live_stack.running
    try:
        running.app.kill_hard()
        running.restart_app(timeout=APP_START_S)
    finally:
        if not running.app.alive():
            running.restart_app(timeout=APP_START_S)  # the session's other tests use this stack


def test_finish_after_a_kill_9_saves_every_answered_decision(live_stack: Any) -> None:
    url = live_stack.url
    username = create_user(live_stack, f"crash.{secrets.token_hex(3)}", "racer")
    token = access_token(live_stack, username)
    run_id = drive(url, token, 30)
    kill_and_restart_app(live_stack)

    # The page's next decision says what happened and what to do; Finish then saves the drive.
    lost = requests.post(f"{url}/api/runs/{run_id}/drive", json={"steering": 0, "throttle": 1}, timeout=15,
                         headers={"Authorization": f"Bearer {token}"})
    assert lost.status_code == 404 and "press Finish to save what you drove" in lost.json()["error"]["message"]
    other = access_token(live_stack, create_user(live_stack, f"crash.o.{secrets.token_hex(3)}", "racer"))
    call(url, "POST", f"/api/runs/{run_id}/drive/finish", token=other, expect=403)  # only its driver saves it
    saved = call(url, "POST", f"/api/runs/{run_id}/drive/finish", token=token)["run"]
    assert saved["status"] == "FINALISED" and saved["metrics"]["frames"] == 30, saved
    rows = controls(url, token, run_id)
    assert [row["index"] for row in rows] == list(range(30)) and all(row["speed"] == 3.0 for row in rows)
    assert rows[-1]["progress"] > rows[0]["progress"]  # the car really drove; the metrics are from these rows
    again = requests.post(f"{url}/api/runs/{run_id}/drive/finish", timeout=15,
                          headers={"Authorization": f"Bearer {token}"})
    assert again.status_code == 404  # saved once; its folder is gone


def test_a_drive_left_behind_by_a_crash_is_saved_when_the_next_drive_starts(live_stack: Any) -> None:
    url = live_stack.url
    walked_away = access_token(live_stack, create_user(live_stack, f"crash.w.{secrets.token_hex(3)}", "racer"))
    run_id = drive(url, walked_away, 12)
    kill_and_restart_app(live_stack)
    assert call(url, "GET", f"/api/runs/{run_id}", token=walked_away)["run"]["status"] == "RECORDING"

    next_racer = access_token(live_stack, create_user(live_stack, f"crash.n.{secrets.token_hex(3)}", "racer"))
    next_run = drive(url, next_racer, 3)
    saved = call(url, "GET", f"/api/runs/{run_id}", token=walked_away)["run"]
    assert saved["status"] == "FINALISED" and saved["metrics"]["frames"] == 12, saved
    assert len(controls(url, walked_away, run_id)) == 12
    finished = call(url, "POST", f"/api/runs/{next_run}/drive/finish", token=next_racer)["run"]
    assert finished["status"] == "FINALISED" and finished["metrics"]["frames"] == 3  # the next drive is unharmed
