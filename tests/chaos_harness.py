"""Crash-consistency chaos over HTTP, shared by `tests/integration/test_chaos.py` (a few rounds) and `bench/chaos.py`
(20 rounds with restart timings).

The stack is started the way `drem up` starts it (`drem_local.stack.start_stack`) and crashed children are brought
back by `drem up`'s own `Supervisor` (without backoff: the rounds crash it on purpose far more often than any event
would). Meanwhile, the way an event runs:

- two timers post laps on two tracks, each post retried with its idempotency key until it is answered;
- the registration desk registers racers, retrying the same registration until it is answered;
- an operator creates events; when storage stops answering mid-create, the client checks the event list before
  creating it again (what the error message tells a user to do), since event creation has no idempotency key;
- a racer uploads models (ticket, the file through the app's storage gateway, then "complete", each retried until
  answered); a check the kill cut short is left to the scrutineering worker, which must finish every one.

Each round kills -9 the storage server or the app (in turn) at a random moment, then restarts it. At the end every count
a user
would notice is compared with what was acknowledged: laps lost or counted twice, racers or events lost or created
twice, boards that differ from their races, and accounts left half-registered.
"""
from __future__ import annotations

import os
import random
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import requests

from drem_local.durable.kill_point import ENV as KILL_POINT_ENV
from drem_local.stack import RunningStack, StackConfig, free_port, start_stack
from drem_local.supervise import RestartPolicy, Supervisor

ADMIN_PASSWORD = "Chaos-Admin-Pass-1!"
RETRYABLE = {500, 502, 503, 504}
OP_DEADLINE_S = 90.0
LAP_STEP_MS = 5_000
NO_ANSWER = "(no answer: the connection failed)"  # over the 3 s minimum lap and the 2 s debounce


@dataclass
class ChaosReport:
    rounds: int = 0
    kills: Counter = field(default_factory=Counter)
    laps_acknowledged: int = 0
    laps_lost: int = 0
    laps_duplicated: int = 0
    racers_acknowledged: int = 0
    racers_lost: int = 0
    events_acknowledged: int = 0
    events_lost: int = 0
    events_duplicated: int = 0
    stale_boards: int = 0
    half_created_accounts: int = 0
    models_acknowledged: int = 0  # uploads whose file the storage gateway acknowledged
    models_lost: int = 0  # their record is gone
    models_stuck: int = 0  # still UPLOADED ("Checking…") once the worker had time to resume every check
    crash_restart_s: list[float] = field(default_factory=list)
    crash_restart_by_role: dict[str, list[float]] = field(default_factory=dict)
    clean_restart_s: list[float] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)  # answers no retry explains (a 4xx, or an op that never ended)
    misleading_answers: list[str] = field(default_factory=list)

    @property
    def acknowledged(self) -> int:
        return self.laps_acknowledged + self.racers_acknowledged + self.events_acknowledged + self.models_acknowledged

    @property
    def lost(self) -> int:
        return self.laps_lost + self.racers_lost + self.events_lost + self.models_lost

    @property
    def duplicated(self) -> int:
        return self.laps_duplicated + self.events_duplicated


class Api:
    """The JSON API as a client calls it: no proxy, a timeout, and answers as (status, body) or None when the
    connection failed."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.http = requests.Session()
        self.http.trust_env = False
        self.token = ""

    def call(self, method: str, path: str, body: Any = None, *, auth: str | None = None) -> tuple[int, Any] | None:
        headers = {"Accept": "application/json"}
        authorization = auth if auth is not None else (f"Bearer {self.token}" if self.token else None)
        if authorization:
            headers["Authorization"] = authorization
        try:
            reply = self.http.request(method, self.url + path, json=body, headers=headers, timeout=15)
        except requests.RequestException:
            return None
        try:
            return reply.status_code, reply.json()
        except ValueError:
            return reply.status_code, reply.text

    def until_answered(self, method: str, path: str, body: Any = None, *, auth: str | None = None,
                       ok: tuple[int, ...] = (200, 201), failures: list[str] | None = None) -> Any:
        """Repeat the same request until it is answered (a retry is what every client here does); the messages of
        the failed attempts go to `failures`."""
        deadline = time.monotonic() + OP_DEADLINE_S
        while time.monotonic() < deadline:
            answer = self.call(method, path, body, auth=auth)
            if answer is not None and answer[0] in ok:
                return answer[1]
            if answer is not None and answer[0] not in RETRYABLE:
                raise RuntimeError(f"{method} {path} answered {answer[0]}: {answer[1]}")
            if failures is not None:
                failures.append(NO_ANSWER if answer is None else _message(answer[1]))
            time.sleep(0.2)
        raise RuntimeError(f"{method} {path} never answered within {OP_DEADLINE_S:.0f}s: {answer}")

    def login(self, username: str, password: str) -> None:
        self.token = self.until_answered("POST", "/api/auth/token", {"username": username, "password": password},
                                         auth="")["access_token"]


def _message(body: Any) -> str:
    return body.get("error", {}).get("message", "") if isinstance(body, dict) else str(body)[:200]


def _note_misleading(report: ChaosReport, what: str, failures: list[str]) -> None:
    """`what` turned out to have been stored by one of its failed attempts. If every one of them answered that
    storage 'cannot be reached' (as if nothing had happened), the one that stored it misled the user; an attempt
    without an answer, or one that said it may have been stored, explains it."""
    if failures and all(m.endswith("cannot be reached.") for m in failures):
        report.misleading_answers.append(f"{what}: {failures}")


@dataclass
class Track:
    track_id: str
    race_id: str
    racer: str
    next_ts: int
    acknowledged_keys: set[str] = field(default_factory=set)  # keys whose answer was a lap
    unanswered: dict[str, int] = field(default_factory=dict)  # key → timestamp of a post that got no answer (yet)


class Chaos:
    def __init__(self, state_dir: Path, *, seed: int, say: Callable[[str], None] = lambda line: None) -> None:
        self.random = random.Random(seed)
        self.say = say
        self.config = StackConfig(state_dir=state_dir, app_port=free_port(), storage_port=free_port(),
                                  live_port=free_port())
        self.stack: RunningStack | None = None
        # The storage server's kill point (tests/chaos_operations.py arms it; unarmed it does nothing).
        self.kill_point_file = state_dir.parent / "kill-point.json"
        self.report = ChaosReport()
        self.api = Api(self.config.app_url)
        self.tracks: list[Track] = []
        self.event_id = ""
        self.timer = ""
        self.registered: list[str] = []
        self.event_names: list[str] = []
        self.model_ids: list[str] = []
        self._stop = threading.Event()
        self._supervisor: Supervisor | None = None

    # --- lifecycle -------------------------------------------------------------------------------------------------

    def start(self, *, racing: bool = True) -> None:
        os.environ[KILL_POINT_ENV] = str(self.kill_point_file)  # read by the storage server this starts
        self.stack = start_stack(self.config, "admin", ADMIN_PASSWORD, timeout=60)
        self._supervisor = Supervisor(self.stack, self.say, RestartPolicy(max_crashes=1000, first_delay_s=0.0,
                                                                          max_delay_s=0.0))
        self.api.login("admin", ADMIN_PASSWORD)
        if racing:  # the timers' event and tracks for the traffic rounds
            self._set_up_racing()

    def close(self) -> None:
        self._stop.set()
        if self.stack is not None:
            self.stack.stop()

    def _set_up_racing(self) -> None:
        api = self.api
        fleet = api.until_answered("POST", "/api/fleets", {"name": "Chaos timers"})["fleet_id"]
        for racer in ("chaos-a", "chaos-b"):
            self._register(racer)
        event = api.until_answered("POST", "/api/events", {
            "name": "Chaos Summit", "event_type": "AWS_SUMMIT", "date": "2026-05-14", "country_code": "DE",
            "race_config": {"race_time_min": 10},
            "tracks": [{"track_id": "1", "fleet_id": fleet}, {"track_id": "2", "fleet_id": fleet}]})
        self.event_id = event["event_id"]
        code = api.until_answered("POST", "/api/devices/activation-codes",
                                  {"fleet_id": fleet, "hostname": "timer-1", "device_kind": "timer"})["code"]
        self.timer = api.until_answered("POST", "/api/devices/activate",
                                        {"code": code, "hostname": "timer-1", "device_kind": "timer"},
                                        auth="")["credential"]
        for track_id, racer in (("1", "chaos-a"), ("2", "chaos-b")):
            race = api.until_answered("POST", f"/api/events/{self.event_id}/races",
                                      {"track_id": track_id, "racer_username": racer})
            self.tracks.append(Track(track_id, race["race_id"], racer, next_ts=1_700_000_000_000))

    # --- the event's traffic ---------------------------------------------------------------------------------------

    def _post_lap(self, track: Track, key: str | None = None, timestamp_ms: int | None = None) -> None:
        """Post the next crossing (or, given `key`, repeat one that got no answer, as a timer does when it is back)."""
        retry = key is not None
        key = key or f"t{track.track_id}-{track.next_ts}"
        timestamp_ms = timestamp_ms if timestamp_ms is not None else track.next_ts
        track.unanswered[key] = timestamp_ms
        failures: list[str] = []
        answer = self.api.until_answered("POST", "/api/timing/strip-events", {
            "event_id": self.event_id, "track_id": track.track_id, "timestamp_ms": timestamp_ms, "sensor": 17,
            "idempotency_key": key}, auth=f"Device {self.timer}", ok=(200,), failures=failures)
        del track.unanswered[key]
        if answer["replayed"]:
            _note_misleading(self.report, f"lap {key}", failures)
        if answer["action"] == "lap":
            track.acknowledged_keys.add(key)
        if not retry:
            track.next_ts += LAP_STEP_MS

    def _register(self, username: str) -> None:
        failures: list[str] = []
        answer = self.api.until_answered("POST", "/api/users", {
            "username": username, "email": f"{username}@example.test", "country_code": "DE"}, ok=(201,),
            failures=failures)
        if answer.get("resumed"):
            _note_misleading(self.report, f"registration {username}", failures)
        self.registered.append(username)

    def _create_event(self, name: str) -> None:
        body = {"name": name, "event_type": "AWS_SUMMIT", "date": "2026-05-14", "country_code": "DE",
                "tracks": [{"track_id": "1"}]}
        deadline = time.monotonic() + OP_DEADLINE_S
        failures: list[str] = []
        while time.monotonic() < deadline:
            answer = self.api.call("POST", "/api/events", body)
            if answer is not None and answer[0] == 201:
                break
            if answer is not None and answer[0] not in RETRYABLE:
                raise RuntimeError(f"creating event {name} answered {answer[0]}: {answer[1]}")
            failures.append(NO_ANSWER if answer is None else _message(answer[1]))
            time.sleep(0.2)
            if name in self._event_names_stored():  # check before repeating it
                _note_misleading(self.report, f"event {name}", failures)
                break
        else:
            raise RuntimeError(f"creating event {name} never finished")
        self.event_names.append(name)

    def _upload_model(self, name: str, bias: float) -> None:
        from tests.unit.models_helpers import onnx_archive

        ticket = self.api.until_answered("POST", "/api/models", {"filename": f"{name}.tar.gz"}, ok=(201,))
        upload, data = ticket["upload"], onnx_archive(bias)
        deadline = time.monotonic() + OP_DEADLINE_S
        while True:  # a presigned POST of the same bytes again is harmless: the retry every browser would do
            try:
                posted = requests.post(upload["url"], data=upload["fields"], files={"file": (f"{name}.tar.gz", data)},
                                       timeout=30)
                if posted.status_code in (200, 204):
                    break
                if posted.status_code not in RETRYABLE:
                    raise RuntimeError(f"uploading {name} answered {posted.status_code}: {posted.text[:200]}")
            except requests.RequestException:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError(f"uploading {name} never finished")
            time.sleep(0.2)
        model_id = ticket["model"]["model_id"]
        self.model_ids.append(model_id)  # the file is stored: from here the check must finish, one way or another
        self.api.until_answered("POST", f"/api/models/{model_id}/complete", ok=(200,))

    def _event_names_stored(self) -> list[str]:
        events = self.api.until_answered("GET", "/api/events")
        items = events.get("events", events) if isinstance(events, dict) else events
        return [item["name"] for item in items]

    def _worker(self, step: Callable[[int], None]) -> None:
        index = 0
        while not self._stop.is_set():
            try:
                step(index)
            except Exception as exc:  # recorded and counted as a failure of the run
                self.report.errors.append(str(exc)[:300])
                return
            index += 1

    # --- rounds ----------------------------------------------------------------------------------------------------

    def run(self, rounds: int, *, round_s: tuple[float, float] = (0.5, 2.5)) -> ChaosReport:
        prefix = f"r{self.random.randrange(10**6):06d}"
        workers = [
            threading.Thread(target=self._worker, args=(lambda i, t=track: self._post_lap(t),), daemon=True)
            for track in self.tracks
        ] + [
            threading.Thread(target=self._worker, args=(lambda i: self._register(f"{prefix}-racer-{i}"),), daemon=True),
            threading.Thread(target=self._worker, args=(lambda i: self._create_event(f"{prefix} event {i}"),),
                             daemon=True),
            threading.Thread(target=self._worker, args=(
                lambda i: self._upload_model(f"{prefix}-model-{i}", (i + 1) / 1000 + self.random.random()),),
                daemon=True),
        ]
        for worker in workers:
            worker.start()
        try:
            for index in range(rounds):
                time.sleep(self.random.uniform(*round_s))  # a random moment in the traffic
                self._crash_and_restart(("storage", "app")[index % 2])  # both, whatever the number of rounds
                self.report.rounds += 1
        finally:
            self._stop.set()
            for worker in workers:
                worker.join(OP_DEADLINE_S + 10)
        self._settle_and_check()
        return self.report

    def _crash_and_restart(self, role: str) -> None:
        assert self.stack is not None and self._supervisor is not None
        process = self.stack.storage if role == "storage" else self.stack.app
        killed = time.perf_counter()
        process.kill_hard()
        self.report.kills[role] += 1
        self._supervisor.check()
        seconds = self._first_authenticated_200(killed)
        self.report.crash_restart_s.append(seconds)
        self.report.crash_restart_by_role.setdefault(role, []).append(seconds)

    def clean_restart(self) -> float:
        """Stop the way Ctrl-C stops drem up (app, then storage with a snapshot), then time starting both again
        (a crash's time runs from the kill, so it also holds noticing the crash and the journal replay)."""
        assert self.stack is not None
        self.stack.stop()
        started = time.perf_counter()
        self.stack.restart_storage(60)
        self.stack.restart_app(60)
        seconds = self._first_authenticated_200(started)
        self.report.clean_restart_s.append(seconds)
        return seconds

    def _first_authenticated_200(self, since: float) -> float:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            answer = self.api.call("GET", "/api/events")
            if answer is not None and answer[0] == 200:
                return time.perf_counter() - since
            time.sleep(0.01)
        raise RuntimeError("no authenticated 200 within 60s of the restart")

    # --- the verdict -----------------------------------------------------------------------------------------------

    def _settle_and_check(self) -> None:
        report, api = self.report, self.api
        for track in self.tracks:
            for key, timestamp_ms in list(track.unanswered.items()):  # a post whose client gave up: sent again
                self._post_lap(track, key, timestamp_ms)
            race = api.until_answered("GET", f"/api/events/{self.event_id}/races/{track.race_id}")
            laps = len(race["laps"])
            report.laps_acknowledged += len(track.acknowledged_keys)
            report.laps_lost += max(0, len(track.acknowledged_keys) - laps)
            report.laps_duplicated += max(0, laps - len(track.acknowledged_keys))
            if not self._board_catches_up(track, race):
                report.stale_boards += 1
        users = self._all_usernames()
        report.racers_acknowledged = len(self.registered)
        report.racers_lost = sum(1 for name in self.registered if name not in users)
        names = Counter(self._event_names_stored())
        report.events_acknowledged = len(self.event_names)
        report.events_lost = sum(1 for name in self.event_names if names[name] == 0)
        report.events_duplicated = sum(names[name] - 1 for name in self.event_names if names[name] > 1)
        report.half_created_accounts = sum(1 for name in users if not self._groups(name))
        report.models_acknowledged = len(self.model_ids)
        for model_id in self.model_ids:
            status = self._model_settled(model_id)
            report.models_lost += status is None
            report.models_stuck += status == "UPLOADED"

    def _model_settled(self, model_id: str, within_s: float = 120.0) -> str | None:
        """The model's status once its check is over (the worker resumes a check a kill cut short), or UPLOADED if
        it never ends within `within_s`; None when the model is gone."""
        deadline = time.monotonic() + within_s
        status = "UPLOADED"
        while time.monotonic() < deadline:
            answer = self.api.call("GET", f"/api/models/{model_id}")
            if answer is not None and answer[0] == 404:
                return None
            if answer is not None and answer[0] == 200:
                status = answer[1]["model"]["status"]
                if status != "UPLOADED":
                    return status
            time.sleep(0.5)
        return status

    def _board_catches_up(self, track: Track, race: dict[str, Any], within_s: float = 10.0) -> bool:
        """Boards equal races within seconds of the last restart, with no manual recompute."""
        valid = [lap for lap in race["laps"] if lap["is_valid"]]
        expected = (len(valid), min((lap["time_ms"] for lap in valid), default=None))
        deadline = time.monotonic() + within_s
        while time.monotonic() < deadline:
            board = self.api.call("GET", f"/api/leaderboard/{self.event_id}?track={track.track_id}")
            if board is not None and board[0] == 200:
                entries = [e for e in board[1]["entries"] if e["username"] == track.racer]
                if entries and (entries[0]["laps"], entries[0]["fastest_lap_ms"]) == expected:
                    return True
                if not entries and expected[0] == 0:
                    return True
            time.sleep(0.2)
        return False

    def _all_usernames(self) -> set[str]:
        names: set[str] = set()
        token = None
        while True:
            path = "/api/users?limit=60" + (f"&next={token}" if token else "")
            page = self.api.until_answered("GET", path)
            names.update(user["username"] for user in page["users"])
            token = page.get("next_token")
            if not token:
                return names

    def _groups(self, username: str) -> list[str]:
        reply = self.api.until_answered("GET", f"/api/users/{username}/groups")
        return reply.get("groups", []) if isinstance(reply, dict) else reply
