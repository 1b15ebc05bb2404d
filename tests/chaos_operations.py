"""kill -9 inside multi-step operations, at kill points chosen on the storage journal, shared by `bench/chaos.py` and
`tests/integration/test_operation_kills.py`.

Each round takes one operation, the way its user runs it (the desk's registration, the timekeeper's Start on the racer
queue, `drem import` as a subprocess, a racer's model upload whose check and conversion the app and the scrutineering
worker finish, a booth visitor's Train whose job the trainer worker finishes: tests/chaos_booth.py), arms the storage
server's kill point (drem_local.durable.kill_point) to kill -9 the chosen processes right after the operation's Nth
journal record, N drawn over the records the operation writes (counted once on an
uncut run of it, as an independent campaign would), and runs it. The dead processes are started again by `drem up`'s
own Supervisor, the user repeats what got no answer (Start again, the same registration, the same import command), and
then the outcome is checked: nothing acknowledged lost, nothing made twice, nothing left half made or stuck.
"""
from __future__ import annotations

import json
import re
import secrets
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import requests

from drem_local.durable.kill_point import arm, disarm
from drem_local.stack import HEALTH_PATH, http_get
from tests.chaos_booth import BoothTraining
from tests.chaos_harness import OP_DEADLINE_S, RETRYABLE, Chaos

VICTIMS = ("storage", "app", "worker", "everything")
OPERATIONS = ("registration", "queue start", "import", "model upload", "booth training")
RACER_PASSWORD = "Chaos-Racer-Pass-1!"
DREM = str(Path(sys.executable).with_name("drem"))


@dataclass
class OperationFigures:
    runs: int = 0
    killed: int = 0  # runs whose kill point fired (an operation can write fewer records than its first run)
    acknowledged: int = 0
    lost: int = 0
    duplicated: int = 0
    stale: int = 0
    half: int = 0  # half made or stuck
    records: int = 0  # journal records of one uncut run
    victims: Counter = field(default_factory=Counter)
    problems: list[str] = field(default_factory=list)

    @property
    def clean(self) -> bool:
        return self.lost == self.duplicated == self.stale == self.half == 0 and not self.problems

    def line(self) -> str:
        return (f"{self.acknowledged} ack/{self.lost} lost/{self.duplicated} dup/{self.stale} stale/{self.half} half "
                f"({self.killed} of {self.runs} killed)")


class OperationKills:
    def __init__(self, chaos: Chaos, work_dir: Path) -> None:
        assert chaos.stack is not None and chaos._supervisor is not None, "start the chaos stack first"
        self.chaos = chaos
        self.stack = chaos.stack
        self.supervisor = chaos._supervisor
        self.api = chaos.api
        self.work_dir = work_dir
        self.kill_file = Path(chaos.kill_point_file)
        self.figures: dict[str, OperationFigures] = {name: OperationFigures() for name in OPERATIONS}
        self.random = chaos.random
        self._racer_api = None
        self._queue_event = ""
        self._export_dir: Path | None = None
        self._export_racers: list[str] = []
        self._count = 0
        self.booth = BoothTraining(self)
        # One supervising thread for the campaign's whole life: a child is started with PR_SET_PDEATHSIG, so it gets
        # SIGTERM when the thread that started it ends (a thread per round would stop every server it restarted).
        self._checking = threading.Lock()
        self._stop = threading.Event()
        self._keeper = threading.Thread(target=self._keep_up, name="chaos-supervisor", daemon=True)
        self._keeper.start()

    def close(self) -> None:
        self._stop.set()
        self._keeper.join(120)

    # --- rounds ------------------------------------------------------------------------------------------------------

    def run(self, operation: str, victim: str, *, at_record: int | None = None,
            at_fraction: float | None = None) -> None:
        """One round: `operation` killed (`victim`) after its journal record `at_record`, or the one `at_fraction` of
        the way through its records, or one drawn over them."""
        figures = self.figures[operation]
        run, check = self._operation(operation)
        if not figures.records and at_record is None:  # once: the journal records of an uncut run, from its start
            started: list[int] = []
            outcome = run(lambda _pid: started.append(self._last_seq()))
            if operation == "model upload":  # its check and conversion run on after the upload is answered
                self.chaos._model_settled(outcome)
            figures.records = max(1, self._last_seq() - started[0])
            check(outcome)
        figures.runs += 1
        figures.victims[victim] += 1
        n = at_record or (max(1, round(at_fraction * figures.records)) if at_fraction is not None
                          else self.random.randint(1, figures.records))
        fired = self._kill_after(n, victim, run, check)
        figures.killed += fired

    def _kill_after(self, n: int, victim: str, run: Callable[[Callable[[int], None] | None], Any],
                    check: Callable[[Any], None]) -> bool:
        def arm_for(client_pid: int | None) -> None:  # each operation calls it once, when its client starts
            arm(self.kill_file, self._last_seq() + n, self._victim_pids(victim, client_pid),
                kill_storage=victim in ("storage", "everything"))

        try:
            outcome = run(arm_for)
        finally:
            fired = not self.kill_file.exists()
            disarm(self.kill_file)
        self._wait_all_up()
        check(outcome)
        return fired

    def _victim_pids(self, victim: str, client_pid: int | None) -> list[int]:
        stack = self.stack
        worker = client_pid or (stack.scrutineer.pid if stack.scrutineer else None)
        if victim == "app":
            return [stack.app.pid]
        if victim == "worker":
            return [worker] if worker else []
        if victim == "everything":  # a power cut: every process of the stack (the trainer too, once it runs)
            pids = [p.pid for p in (stack.app, stack.live, stack.scrutineer, stack.trainer) if p is not None]
            return pids + ([client_pid] if client_pid and client_pid not in pids else [])
        return []

    def _keep_up(self) -> None:
        """drem up's supervision, every 0.2 s."""
        while not self._stop.wait(0.2):
            try:
                self._check()
            except Exception as exc:
                self._problem("supervisor", f"restart failed: {exc}"[:300])

    def _check(self) -> None:
        with self._checking:
            self.supervisor.check()

    def _wait_all_up(self) -> None:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            if self.api.call("GET", "/api/events") is not None:
                return
            time.sleep(0.2)
        self._problem("supervisor", "the stack did not come back within 90 s")

    def _last_seq(self) -> int:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            answer = http_get(self.stack.config.storage_url + HEALTH_PATH)
            if answer is not None and answer[0] == 200:
                return int(json.loads(answer[1])["last_seq"])
            time.sleep(0.2)
        raise RuntimeError("the storage server's health never answered")

    def _problem(self, operation: str, text: str) -> None:
        self.figures.setdefault(operation, OperationFigures()).problems.append(text)

    def _operation(self, name: str) -> tuple[Callable[..., Any], Callable[[Any], None]]:
        table: dict[str, tuple[Callable[..., Any], Callable[[Any], None]]] = {
                "registration": (self._registration_run, self._registration_check),
                "queue start": (self._queue_run, self._queue_check),
                "import": (self._import_run, self._import_check),
                "model upload": (self._model_run, self._model_check),
                "booth training": (self.booth.run, self.booth.check)}
        return table[name]

    def _name(self, what: str) -> str:
        self._count += 1
        return f"op{secrets.token_hex(2)}-{what}-{self._count}"

    # --- registration: the desk registers a racer and repeats it until it is answered --------------------------------

    def _registration_run(self, arm_for: Callable[[int | None], None]) -> str:
        username = self._name("racer")
        arm_for(None)
        self.api.until_answered("POST", "/api/users", {"username": username, "email": f"{username}@example.test",
                                                       "country_code": "DE"}, ok=(201,))
        return username

    def _registration_check(self, username: str) -> None:
        figures = self.figures["registration"]
        figures.acknowledged += 1
        listed = [u for u in self._users() if u["username"] == username]
        figures.lost += not listed
        figures.duplicated += max(0, len(listed) - 1)
        groups = self.api.until_answered("GET", f"/api/users/{username}/groups")
        groups = groups.get("groups", []) if isinstance(groups, dict) else groups
        if listed and "racer" not in groups:
            figures.half += 1
            self._problem("registration", f"{username} has no racer group: {groups}")

    def registration_visibility(self) -> float:
        """Seconds from a storage kill -9 right after a sign-up's account record (before its role group) until the
        racer is listed with the racer group, with nobody registering them again."""
        username = self._name("cutoff")
        arm(self.kill_file, self._last_seq() + 1, [], kill_storage=True)
        self.api.call("POST", "/api/users", {"username": username, "email": f"{username}@example.test",
                                             "country_code": "DE"})
        killed = time.monotonic()  # the desk got its error: the storage server died under it
        deadline = killed + 120
        while time.monotonic() < deadline:
            answer = self.api.call("GET", f"/api/users/{username}/groups")
            if answer is not None and answer[0] == 200:
                groups = answer[1].get("groups", []) if isinstance(answer[1], dict) else answer[1]
                if "racer" in groups:
                    return time.monotonic() - killed
            time.sleep(0.2)
        self._problem("registration", f"{username} cut off by a storage kill was not whole within 120 s")
        return float("inf")

    def _users(self) -> list[dict[str, Any]]:
        users: list[dict[str, Any]] = []
        token = None
        while True:
            page = self.api.until_answered("GET", "/api/users?limit=60" + (f"&next={token}" if token else ""))
            users += page["users"]
            token = page.get("next_token")
            if not token:
                return users

    # --- queue start: the timekeeper presses Start on the head of the racer queue, again if it got no answer --------

    def _queue_setup(self) -> None:
        if self._queue_event:
            return
        from drem_local.stack import REGION
        from drem_local.storage_keys import load, local_client

        api = self.api
        fleet = api.until_answered("POST", "/api/fleets", {"name": "Queue chaos"})["fleet_id"]
        event = api.until_answered("POST", "/api/events", {
            "name": "Queue chaos", "event_type": "AWS_SUMMIT", "date": "2026-05-14", "country_code": "DE",
            "tracks": [{"track_id": "1", "fleet_id": fleet}]})
        self._queue_event = event["event_id"]
        racer = "queue-chaos-racer"
        api.until_answered("POST", "/api/users", {"username": racer, "email": f"{racer}@example.test",
                                                  "country_code": "DE"}, ok=(201,))
        cognito = local_client("cognito-idp", self.stack.config.storage_url, load(self.stack.config.state_dir),
                               REGION)
        cognito.admin_set_user_password(UserPoolId=self.stack.outputs.user_pool_id, Username=racer,
                                        Password=RACER_PASSWORD, Permanent=True)
        from tests.chaos_harness import Api

        racer_api = Api(self.stack.config.app_url)
        racer_api.login(racer, RACER_PASSWORD)
        saved_api, self.api = self.api, racer_api
        try:
            self.model_name = self._upload("queue-model", 0.5)[1]
        finally:
            self.api = saved_api

    @property
    def _queue_base(self) -> str:
        return f"/console/timekeeper/{self._queue_event}/1/queue"

    def _form(self, path: str, form: dict[str, str]) -> tuple[int, str] | None:
        try:
            reply = self.api.http.post(self.api.url + path, data=form, timeout=15, headers={
                "Authorization": f"Bearer {self.api.token}", "HX-Request": "true"})
        except requests.RequestException:
            return None
        return reply.status_code, reply.text

    def _queue_panel(self) -> str:
        deadline = time.monotonic() + OP_DEADLINE_S
        while time.monotonic() < deadline:
            try:
                reply = self.api.http.get(self.api.url + self._queue_base, timeout=15, headers={
                    "Authorization": f"Bearer {self.api.token}", "HX-Request": "true"})
                if reply.status_code == 200:
                    return reply.text
            except requests.RequestException:
                pass
            time.sleep(0.2)
        raise RuntimeError("the queue panel never answered")

    def _queue_run(self, arm_for: Callable[[int | None], None]) -> tuple[str, int]:
        self._queue_setup()
        racer = "queue-chaos-racer"
        before = 0  # every earlier round's race was discarded
        answer = None
        while answer is None or answer[0] in RETRYABLE:
            answer = self._form(self._queue_base, {"queue_racer": racer, "queue_model": self.model_name,
                                                   "queue_confirmed": "yes"})
        entry = _entry_of(self._queue_panel(), racer)
        arm_for(None)
        deadline = time.monotonic() + OP_DEADLINE_S
        while time.monotonic() < deadline:  # the timekeeper presses Start until the page answers
            answer = self._form(self._queue_base + "/start", {"entry_id": entry})
            if answer is not None and answer[0] == 200:
                return racer, before
            if answer is not None and answer[0] not in RETRYABLE:  # a user would see this refusal: counted
                self._problem("queue start", f"Start answered {answer[0]}: {re.sub(r'<[^>]+>', ' ', answer[1])[:200]}")
                return racer, before
            time.sleep(0.2)
        self._problem("queue start", "Start never answered")
        return racer, before

    def _queue_check(self, outcome: tuple[str, int]) -> None:
        racer, before = outcome
        figures = self.figures["queue start"]
        figures.acknowledged += 1
        races = self._races_of(racer)  # the discarded ones of earlier rounds left out
        figures.lost += len(races) <= before
        figures.duplicated += max(0, len(races) - before - 1)
        if racer in re.findall(r'class="tk-deck-racer">([^<]+)<', self._queue_panel()):
            figures.stale += 1  # the polled list still shows the racer on deck
        for race in races:  # the track is free for the next round: the timekeeper discards the race
            for kind in ("start", "end", "discard"):  # each refused (409) when the race is past it already
                self.api.until_answered("POST", f"/api/events/{self._queue_event}/races/{race['race_id']}/commands",
                                        {"kind": kind}, ok=(200, 409))

    def _races_of(self, racer: str) -> list[dict[str, Any]]:
        reply = self.api.until_answered("GET", f"/api/events/{self._queue_event}/races")
        races = reply.get("races", reply) if isinstance(reply, dict) else reply
        return [race for race in races if race["username"] == racer and race["status"] != "DISCARDED"]

    # --- import: `drem import` of an export, run again until it exits 0 ----------------------------------------------

    def _import_setup(self) -> None:
        if self._export_dir is not None:
            return
        api = self.api
        event = api.until_answered("POST", "/api/events", {
            "name": "Import chaos source", "event_type": "AWS_SUMMIT", "date": "2026-05-14", "country_code": "DE",
            "tracks": [{"track_id": "1"}, {"track_id": "2"}]})
        racers = [f"import-chaos-{index}" for index in range(2)]
        for track_id, racer in enumerate(racers, start=1):  # one racer per track: one live race per track
            api.until_answered("POST", "/api/users", {"username": racer, "email": f"{racer}@example.test",
                                                      "country_code": "DE"}, ok=(201,))
            race = api.until_answered("POST", f"/api/events/{event['event_id']}/races",
                                      {"track_id": str(track_id), "racer_username": racer})
            for kind in ("start", "end", "submit"):  # an export holds finished races only
                api.until_answered("POST", f"/api/events/{event['event_id']}/races/{race['race_id']}/commands",
                                   {"kind": kind})
        folder = self.work_dir / "import-chaos-export"
        done = subprocess.run([DREM, "export", event["event_id"], "--out", str(folder), "--state-dir",
                               str(self.stack.config.state_dir)], capture_output=True, text=True, timeout=120)
        if done.returncode != 0:
            raise RuntimeError(f"drem export failed: {done.stderr[-500:]}")
        self._export_dir, self._export_racers = folder, racers

    def _forget_racers(self) -> None:
        """The import is to create these accounts again (as on a fresh stack)."""
        from drem_local.stack import REGION
        from drem_local.storage_keys import load, local_client

        cognito = local_client("cognito-idp", self.stack.config.storage_url, load(self.stack.config.state_dir),
                               REGION)
        for username in self._export_racers:
            try:
                cognito.admin_delete_user(UserPoolId=self.stack.outputs.user_pool_id, Username=username)
            except cognito.exceptions.UserNotFoundException:
                pass

    def _import_run(self, arm_for: Callable[[int | None], None]) -> dict[str, Any]:
        self._import_setup()
        self._forget_racers()
        assert self._export_dir is not None
        event_id = f"imported-{secrets.token_hex(4)}"
        argv = [DREM, "import", str(self._export_dir), "--event-id", event_id, "--state-dir",
                str(self.stack.config.state_dir)]
        runs: list[tuple[int, str]] = []
        deadline = time.monotonic() + OP_DEADLINE_S
        while time.monotonic() < deadline:  # the operator runs the same command again until it says imported
            process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            if not runs:
                arm_for(process.pid)
            output, _ = process.communicate(timeout=120)
            runs.append((process.returncode, output))
            if process.returncode == 0:
                break
            self._wait_all_up()
        return {"event_id": event_id, "runs": runs}

    def _import_check(self, outcome: dict[str, Any]) -> None:
        from chalicelib.storage.audit import AUDIT_PREFIX
        from chalicelib.storage.event_archive import StackLocation, connect

        figures = self.figures["import"]
        event_id, runs = outcome["event_id"], outcome["runs"]
        figures.acknowledged += 1
        if not runs or runs[-1][0] != 0:
            figures.half += 1
            self._problem("import", f"{event_id}: never exited 0: {runs[-1][1][-300:] if runs else 'not run'}")
            return
        assert self._export_dir is not None
        resume = self._export_dir.parent / f"{self._export_dir.name}.import-{event_id}.resume.json"
        if resume.exists():
            figures.half += 1
            self._problem("import", f"{event_id}: the resume file (plaintext passwords) was left behind")
        if self.api.call("GET", f"/api/events/{event_id}") in (None,) or \
                (self.api.call("GET", f"/api/events/{event_id}") or (0,))[0] != 200:
            figures.lost += 1
        storage = connect(StackLocation.from_state_dir(self.stack.config.state_dir))
        audit = [i for i in storage.partition("races", f"EVENT#{event_id}", AUDIT_PREFIX)
                 if i["action"]["S"] == "import"]
        figures.duplicated += max(0, len(audit) - 1)
        if not audit:
            figures.half += 1
            self._problem("import", f"{event_id}: no 'Event imported' audit entry")
        shown = runs[-1][1]
        for username in self._export_racers:
            groups = self.api.until_answered("GET", f"/api/users/{username}/groups")
            groups = groups.get("groups", []) if isinstance(groups, dict) else groups
            if "racer" not in groups:
                figures.half += 1
                self._problem("import", f"{event_id}: {username} has no racer group")
            if not any(f"account {username}: temporary password" in out for _, out in runs) or \
                    f"account {username}:" not in shown:
                figures.half += 1
                self._problem("import", f"{event_id}: {username}'s temporary password was never shown at the end")

    # --- model upload: ticket, the file, complete; the check and conversion finish by themselves --------------------

    def _upload(self, name: str, bias: float) -> tuple[str, str]:
        from tests.unit.models_helpers import onnx_archive

        ticket = self.api.until_answered("POST", "/api/models", {"filename": f"{name}.tar.gz"}, ok=(201,))
        upload, data = ticket["upload"], onnx_archive(bias)
        deadline = time.monotonic() + OP_DEADLINE_S
        while time.monotonic() < deadline:
            try:
                posted = requests.post(upload["url"], data=upload["fields"], files={"file": (f"{name}.tar.gz", data)},
                                       timeout=30)
                if posted.status_code in (200, 204):
                    break
            except requests.RequestException:
                pass
            time.sleep(0.2)
        model_id = ticket["model"]["model_id"]
        self.api.until_answered("POST", f"/api/models/{model_id}/complete", ok=(200,))
        return model_id, ticket["model"]["name"]

    def _model_run(self, arm_for: Callable[[int | None], None]) -> str:
        arm_for(None)
        return self._upload(self._name("model"), self.random.random())[0]

    def _model_check(self, model_id: str) -> None:
        figures = self.figures["model upload"]
        figures.acknowledged += 1
        status = self.chaos._model_settled(model_id)
        figures.lost += status is None
        if status == "UPLOADED":
            figures.half += 1
            self._problem("model upload", f"{model_id} still Checking… after 120 s")


def _entry_of(panel: str, racer: str) -> str:
    match = re.search(rf'data-entry="([0-9a-f]+)"[^>]*>(?:(?!data-entry).)*?>{re.escape(racer)}<', panel, re.S)
    if not match:
        raise RuntimeError(f"{racer} is not in the queue")
    return match.group(1)
