"""`drem up --demo` as a user runs it: a subprocess on free ports in a fresh state dir. The demo's sim cars race demo
racers until the public leaderboard shows laps; Ctrl-C stops everything (cars included) cleanly; a second start on
the same state dir carries on with the same event and the same cars."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import requests

from drem_local import stack as local_stack

pytestmark = pytest.mark.integration


def start_demo(state_dir: Path, app_port: int, storage_port: int, log: Path) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("AWS_", "DREM_"))}
    env["NO_PROXY"] = "127.0.0.1,localhost"
    return subprocess.Popen([sys.executable, "-m", "drem_local.cli", "up", "--demo", "--state-dir", str(state_dir),
                             "--port", str(app_port), "--storage-port", str(storage_port)],
                            stdout=open(log, "w"), stderr=subprocess.STDOUT, env=env)


def wait_for(what: str, check, timeout_s: float, process: subprocess.Popen, log: Path):  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert process.poll() is None, f"drem up --demo exited early:\n{log.read_text()}"
        value = check()
        if value:
            return value
        time.sleep(0.5)
    pytest.fail(f"timed out after {timeout_s:.0f} s waiting for {what}:\n{log.read_text()}")


def demo_state(state_dir: Path) -> dict | None:
    try:
        return json.loads((state_dir / "demo" / "demo.json").read_text())
    except (OSError, ValueError):
        return None


def processes_using(state_dir: Path) -> list[int]:
    """Pids of live processes whose command line names the state dir (storage, app and the demo's cars all do)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if str(state_dir).encode() in (entry / "cmdline").read_bytes():
                    found.append(int(entry.name))
            except OSError:
                continue
    return found


def stop_with_ctrl_c(process: subprocess.Popen, log: Path) -> str:
    process.send_signal(signal.SIGINT)
    try:
        code = process.wait(60)
    except subprocess.TimeoutExpired:
        process.kill()
        pytest.fail(f"drem up --demo did not stop within 60 s of Ctrl-C:\n{log.read_text()}")
    output = log.read_text()
    assert code == 0, output
    return output


def test_drem_up_demo_races_sim_cars_live_stops_cleanly_and_resumes(tmp_path) -> None:
    state_dir = tmp_path / "state"
    app_port, storage_port = local_stack.free_port(), local_stack.free_port()
    url = f"http://127.0.0.1:{app_port}"
    log = tmp_path / "first.log"
    demo = start_demo(state_dir, app_port, storage_port, log)
    try:
        state = wait_for("the demo event", lambda: demo_state(state_dir), 240, demo, log)  # a busy laptop starts slowly
        event_id = state["event_id"]

        def laps_on_board() -> list[dict]:
            board = requests.get(f"{url}/api/leaderboard/{event_id}", timeout=10).json()
            return [e for e in board["entries"] if e.get("fastest_lap_ms")]

        rows = wait_for("a lap on the public leaderboard", laps_on_board, 180, demo, log)
        printed = log.read_text()
        for page in (f"{url}/leaderboard/{event_id}", f"{url}/overlay/{event_id}", f"{url}/commentator/{event_id}"):
            assert page in printed, f"the demo prints where to look ({page})"
    finally:
        output = stop_with_ctrl_c(demo, log) if demo.poll() is None else log.read_text()
    assert rows[0]["username"].startswith("demo-") and rows[0]["country_code"] and rows[0]["highlight_colour"]
    assert 5_000 < rows[0]["fastest_lap_ms"] < 20_000, "a sim lap of re:Invent 2018 by the sample model"
    assert "drem stopped cleanly" in output
    assert processes_using(state_dir) == [], "no car, app or storage process outlives Ctrl-C"

    log = tmp_path / "second.log"
    again = start_demo(state_dir, app_port, storage_port, log)
    try:
        wait_for("the demo to run again", lambda: "Demo running" in log.read_text(), 240, again, log)
        assert demo_state(state_dir) == state, "the same event, fleet and cars are used again"
        board = requests.get(f"{url}/api/leaderboard/{event_id}", timeout=10).json()
        assert {e["username"] for e in board["entries"]} >= {r["username"] for r in rows}, "earlier laps are kept"
    finally:
        stop_with_ctrl_c(again, log)
    assert processes_using(state_dir) == []
