"""Shared plumbing for the live-update benches: a durable moto server + the live server (drem_live, started the way
`drem up` starts it) + the real app server as subprocesses on free ports (like `tests/stack_fixtures.py`), the JSON
API as a client calls it, a seeded 50-racer board, a wrk runner with
a Lua script, and percentiles.

The app server is the real `app.py`; `/api/ping` (chalicelib.routes.ping) is added to the bench's app process only
if app.py does not register it yet.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "functions"))

SEEDED_RACERS = 49
WRK = "/usr/bin/wrk"
_NO_PROXY = urllib.request.build_opener(urllib.request.ProxyHandler({}))


def serve(port: int, host: str = "127.0.0.1") -> None:
    """App-server mode: the real app (functions/app.py, every blueprint registered) behind waitress."""
    from drem_local import appserver

    # With the storage gateway, as `drem up` runs it: presigned uploads and downloads go through /_storage.
    appserver.make_server(host, port, storage_url=os.environ.get("AWS_ENDPOINT_URL")).serve_forever()


@dataclass
class BenchStack:
    url: str
    port: int
    storage_url: str
    env: dict[str, str]
    admin_username: str
    admin_password: str
    tmp: Path
    live_url: str = ""  # no live server: the pages poll the app
    live_port: int = 0
    app_pid: int = 0
    storage_pid: int = 0
    live_pid: int = 0


@contextmanager
def bench_stack(extra_env: dict[str, str] | None = None, live_workers: int = 1) -> Iterator[BenchStack]:
    from drem_local import stack as local_stack
    from drem_local.bootstrap import generate_password

    with tempfile.TemporaryDirectory(prefix="drem-bench-") as tmp_name:
        tmp = Path(tmp_name)
        config = local_stack.StackConfig(state_dir=tmp / "state", app_port=local_stack.free_port(),
                                         storage_port=local_stack.free_port(), live_port=local_stack.free_port(),
                                         live_workers=live_workers)
        config.state_dir.mkdir(parents=True)
        storage = local_stack.start_storage(config, timeout=60)
        app: Any = None
        live: Any = None
        try:
            password = generate_password()
            outputs, _admin = local_stack.bootstrap(config, "admin", password)
            env = {**local_stack.app_environment(config, outputs), "PYTHONPATH": str(ROOT), **(extra_env or {})}
            live = local_stack.start_live(config, env, timeout=60)
            script = "import sys; from bench._stack import serve; serve(int(sys.argv[1]))"
            app = local_stack.spawn("app server", [sys.executable, "-c", script, str(config.app_port)],
                                    config.log_dir / "app.log", env=env)
            local_stack.wait_for_ok(config.app_url + local_stack.APP_HEALTH_PATH, app, 60)
            yield BenchStack(url=config.app_url, port=config.app_port, storage_url=config.storage_url, env=env,
                             admin_username="admin", admin_password=password, tmp=tmp, live_url=config.live_url,
                             live_port=config.live_server_port, app_pid=app.pid, storage_pid=storage.pid,
                             live_pid=live.pid)
        finally:
            if app is not None:
                app.stop(10)
            if live is not None:
                live.stop(10)
            storage.stop(30)


# --- the JSON API, as the operator's tools and a timer device call it ----------------------------------------------


def call(url: str, method: str, path: str, body: Any = None, *, authorization: str | None = None) -> Any:
    headers = {"Content-Type": "application/json", "Accept": "application/json"}
    if authorization:
        headers["Authorization"] = authorization
    request = urllib.request.Request(url + path, method=method, headers=headers,
                                     data=None if body is None else json.dumps(body).encode())
    with _NO_PROXY.open(request, timeout=30) as reply:
        text = reply.read()
    return json.loads(text) if text else None


@dataclass(frozen=True)
class LiveRace:
    event_id: str
    race_id: str
    timer_credential: str


def start_live_race(stack: BenchStack, racer: str = "lina") -> LiveRace:
    """An event (one track, 10 min races), a racer, a fleet with an activated timer, and a started race."""
    url = stack.url
    bearer = "Bearer " + call(url, "POST", "/api/auth/token", {
        "username": stack.admin_username, "password": stack.admin_password})["access_token"]
    call(url, "POST", "/api/users", {"username": racer, "email": f"{racer}@example.test", "country_code": "DE"},
         authorization=bearer)
    fleet = call(url, "POST", "/api/fleets", {"name": "Timers"}, authorization=bearer)
    event = call(url, "POST", "/api/events", {
        "name": "Bench Summit", "event_type": "AWS_SUMMIT", "date": "2026-05-14", "country_code": "DE",
        "race_config": {"race_time_min": 10}, "tracks": [{"track_id": "1", "fleet_id": fleet["fleet_id"]}]},
        authorization=bearer)
    code = call(url, "POST", "/api/devices/activation-codes", {
        "fleet_id": fleet["fleet_id"], "hostname": "timer-1", "device_kind": "timer"}, authorization=bearer)["code"]
    credential = call(url, "POST", "/api/devices/activate", {
        "code": code, "hostname": "timer-1", "device_kind": "timer"})["credential"]
    eid = event["event_id"]
    race = call(url, "POST", f"/api/events/{eid}/races", {"track_id": "1", "racer_username": racer},
                authorization=bearer)
    call(url, "POST", f"/api/events/{eid}/races/{race['race_id']}/commands", {"kind": "start"}, authorization=bearer)
    return LiveRace(eid, race["race_id"], credential)


def strip_event(url: str, race: LiveRace, timestamp_ms: int, key: str) -> dict[str, Any]:
    return call(url, "POST", "/api/timing/strip-events", {
        "event_id": race.event_id, "track_id": "1", "timestamp_ms": timestamp_ms, "sensor": 17,
        "idempotency_key": key}, authorization=f"Device {race.timer_credential}")


def seed_board(env: dict[str, str], event_id: str, racers: int = SEEDED_RACERS) -> None:
    """`racers` racers with three submitted laps each on track 1, ranked and written by the real publisher (their rows
    stay when the race service later refreshes another racer's row)."""
    os.environ.update(env)
    from chalicelib.domain.leaderboards import BoardRow, LeaderboardPublisher
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from chalicelib.storage.leaderboards import DynamoBoardStore
    from drem_leaderboard.models import Lap, LapSource, RaceConfig, Racer, RaceStatus, new_race
    from drem_leaderboard.ranking import RacerProfile
    from drem_leaderboard.summary import summarise_racer

    get_settings.cache_clear()
    publisher = LeaderboardPublisher(DynamoBoardStore(clients.dynamodb(), get_settings().table("leaderboards")),
                                     lambda: int(time.time() * 1000), cache=None)
    rows = []
    for index in range(racers):
        racer = Racer(sub=f"sub-{index:03d}", username=f"racer{index:03d}")
        laps = tuple(Lap(lap_id=i, time_ms=40_000 + 37 * index + 101 * i, is_valid=True, source=LapSource.MANUAL,
                         captured_at_ms=1_000 + i) for i in range(3))
        race = new_race(race_id=f"seed-{index}", event_id=event_id, track_id="1", racer=racer, config=RaceConfig(),
                        now_ms=1).model_copy(update={"laps": laps, "status": RaceStatus.SUBMITTED,
                                                     "submitted_at_ms": 2_000})
        summary = summarise_racer([race])
        assert summary is not None
        rows.append(BoardRow(summary=summary, profile=RacerProfile(username=racer.username, country_code="SE")))
    publisher.rebuild(event_id, {"1": rows}, RaceConfig().ranking_method, ["1"])


# --- wrk --------------------------------------------------------------------------------------------------------------

# Shared Lua tail: per-thread status counts, and one JSON line (`WRKJSON {...}`) in done().
LUA_SUMMARY = r"""
local threads = {}
function setup(thread)
  thread:set("id", #threads)
  table.insert(threads, thread)
end
function summary_status(status)
  if status == 200 then ok200 = (ok200 or 0) + 1
  elseif status == 204 then ok204 = (ok204 or 0) + 1
  elseif status == 304 then ok304 = (ok304 or 0) + 1
  else other = (other or 0) + 1 end
end
function done(summary, latency, requests)
  local c = {s200 = 0, s204 = 0, s304 = 0, other = 0}
  for _, t in ipairs(threads) do
    c.s200 = c.s200 + (t:get("ok200") or 0); c.s204 = c.s204 + (t:get("ok204") or 0)
    c.s304 = c.s304 + (t:get("ok304") or 0); c.other = c.other + (t:get("other") or 0)
  end
  local e = summary.errors
  io.write(string.format('WRKJSON {"requests":%d,"duration_us":%d,"p50_us":%d,"p95_us":%d,"p99_us":%d,' ..
    '"max_us":%d,"connect_errors":%d,"read_errors":%d,"write_errors":%d,"timeouts":%d,"non_2xx_3xx":%d,' ..
    '"s200":%d,"s204":%d,"s304":%d,"other":%d}\n',
    summary.requests, summary.duration, latency:percentile(50), latency:percentile(95), latency:percentile(99),
    latency.max, e.connect, e.read, e.write, e.timeout, e.status, c.s200, c.s204, c.s304, c.other))
end
"""


def start_wrk(url: str, lua: str, *, connections: int, threads: int, seconds: float, tmp: Path,
              name: str) -> subprocess.Popen[str]:
    script = tmp / f"{name}.lua"
    script.write_text(lua + LUA_SUMMARY)
    return subprocess.Popen([WRK, "-t", str(threads), "-c", str(connections), "-d", f"{seconds:.0f}s",
                             "--timeout", "5s", "-s", str(script), url],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def wrk_result(process: subprocess.Popen[str], timeout: float) -> dict[str, Any]:
    out, _ = process.communicate(timeout=timeout)
    line = next((ln for ln in out.splitlines() if ln.startswith("WRKJSON ")), None)
    if line is None:
        raise SystemExit(f"wrk gave no summary:\n{out}")
    result = json.loads(line.removeprefix("WRKJSON "))
    result["rate"] = result["requests"] / (result["duration_us"] / 1e6)
    return result


# --- figures ----------------------------------------------------------------------------------------------------------


def cpu_seconds(pid: int) -> float:
    """CPU seconds (user + system) process `pid` has used so far; 0.0 once it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime (fields 14, 15 of stat)


def machine_load() -> str:
    """The 1-minute load average: the machine is shared, so every figure is printed next to it."""
    return f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"


def percentile(samples: list[float], pct: float) -> float:
    """Nearest-rank percentile (p95 of 40 samples is the 38th smallest)."""
    ordered = sorted(samples)
    rank = max(1, -(-len(ordered) * pct // 100))
    return ordered[int(rank) - 1]
