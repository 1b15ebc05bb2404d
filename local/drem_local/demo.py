"""`drem up --demo`: a running stack that races by itself, so the leaderboard, overlay and commentator pages fill live.

What it sets up (all through the public API, like any operator would, and idempotent across restarts: the ids live
in `<state dir>/demo/demo.json`, the cars' credentials in `<state dir>/demo/cars/<hostname>/`):
- a `demo-director` admin account (fresh password each start; the demo process is the only one that knows it),
- the sample models of `sim/drem_sim/samples/` seeded as models of `default` (validated like any upload),
- demo racers with countries and highlight colours, a fleet, and an event with one track per sim car,
- sim cars activated in that fleet, each assigned the sample model, each a `drem car run --sim` subprocess,
- a race director: per track, a race for the next demo racer; the car's strip events start and lap it; once it is
  over (race time, then the next lap) it is submitted and the next racer's race is created.
"""
from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drem_local.api_client import ApiClient, ApiError
from drem_local.stack import ManagedProcess, RunningStack, spawn

DEMO_DIR = "demo"
DEMO_FILE = "demo.json"
DIRECTOR = "demo-director"
# The sim track the cars drive and the sample model trained on it: re:Invent 2018, whose DeepRacer route file ships
# with drem_sim; drem_oval (drem's own) only if that file is missing from the install.
SIM_TRACKS_AND_SAMPLES: tuple[tuple[str, str], ...] = (("reinvent_base", "drem-bc-sample"), ("drem_oval",
                                                                                             "drem-bc-oval"))
TRACK_IDS = ("1", "2")  # one sim car per track
RACE_TIME_MIN = 1
OVERDUE_S = 90.0  # a race still running this long after its race time is ended by the director
# username, country, highlight colour (from the profile palette), throttle cap: the sim is deterministic, so each
# racer's "driving style" is the staff throttle cap their car gets for the race (lap times differ by racer).
RACERS: tuple[tuple[str, str, str, int], ...] = (
    ("demo-ada", "GB", "#0000FF", 100), ("demo-linus", "FI", "#FF0000", 90), ("demo-grace", "US", "#FF8200", 96),
    ("demo-hedy", "AT", "#800080", 86), ("demo-alan", "SE", "#1E90FF", 93), ("demo-margaret", "DE", "#7CFC00", 98),
)
LIVE_STATUSES = {"READY", "RUNNING", "PAUSED", "OVER"}
_SEED_SCRIPT = """
import json, sys
from drem_local.app_source import use_app_source
use_app_source()
from chalicelib.domain.racer_models import seed_sample_models
from chalicelib import services
records = seed_sample_models(services.model_service(), sys.argv[1:])
print(json.dumps([{"model_id": r.model_id, "name": r.name, "status": r.status.value} for r in records]))
"""


class DemoError(RuntimeError):
    """The demo could not be set up; the message says why."""


@dataclass
class DemoCar:
    hostname: str
    track_id: str
    config_dir: Path
    device_id: str = ""
    process: ManagedProcess | None = None


@dataclass
class TrackDirector:
    track_id: str
    race_id: str | None = None
    created_at: float = 0.0


@dataclass
class Demo:
    stack: RunningStack
    rate_hz: float = 15.0
    event_id: str = ""
    fleet_id: str = ""
    cars: list[DemoCar] = field(default_factory=list)
    model_ids: list[str] = field(default_factory=list)
    sim_track: str = ""
    _api: ApiClient | None = None
    _directors: list[TrackDirector] = field(default_factory=list)
    _next_racer: Any = None

    @property
    def directory(self) -> Path:
        return self.stack.config.state_dir / DEMO_DIR

    @property
    def api(self) -> ApiClient:
        assert self._api is not None, "start() signs the director in"
        return self._api

    # --- set-up ------------------------------------------------------------------------------------------------

    def start(self) -> None:
        self.directory.mkdir(parents=True, exist_ok=True)
        self._sign_in_director()
        self.sim_track, sample = demo_track_and_sample()
        available = {m["model_id"] for m in self._seed_samples() if m["status"] == "AVAILABLE"}
        if f"sample-{sample}" not in available:
            raise DemoError(f"the sample model {sample} did not pass validation; see sim/drem_sim/samples/")
        self.model_ids = [f"sample-{sample}"]
        self._ensure_racers()
        saved = self._load()
        self.fleet_id = str(saved.get("fleet_id")) if saved.get("fleet_id") and self._exists(
            f"/api/fleets/{saved['fleet_id']}") else self.api.post("/api/fleets", {"name": "Demo sim cars"})["fleet_id"]
        self.event_id = str(saved.get("event_id")) if saved.get("event_id") and self._exists(
            f"/api/events/{saved['event_id']}") else self._create_event()
        self.cars = [self._ensure_car(track_id) for track_id in TRACK_IDS]
        self._save()
        for car in self.cars:
            self.api.put(f"/api/cars/{car.device_id}/models", {"model_ids": self.model_ids[:1]})
            car.process = self._spawn_car(car)
        self._directors = [TrackDirector(track_id) for track_id in TRACK_IDS]
        self._next_racer = itertools.cycle([(username, cap) for username, _, _, cap in RACERS])

    def _sign_in_director(self) -> None:
        from drem_local.bootstrap import clients_for, ensure_admin, generate_password
        from drem_local.storage_keys import load

        config = self.stack.config
        password = generate_password()
        ensure_admin(clients_for(config.storage_url, config.region, load(config.state_dir)), self.stack.outputs,
                     DIRECTOR, password)
        self._api = ApiClient(config.app_url)
        self._api.sign_in(DIRECTOR, password)

    def _seed_samples(self) -> list[dict[str, Any]]:
        import drem_sim

        archives = sorted(str(p) for p in (Path(drem_sim.__file__).parent / "samples").glob("*.tar.gz"))
        done = subprocess.run([sys.executable, "-c", _SEED_SCRIPT, *archives], env=self.stack.env,
                              capture_output=True, text=True, timeout=120)
        if done.returncode != 0:
            raise DemoError(f"seeding the sample models failed:\n{done.stderr[-2000:]}")
        return json.loads(done.stdout.strip().splitlines()[-1])

    def _ensure_racers(self) -> None:
        for username, country, colour, _cap in RACERS:
            try:
                self.api.post("/api/users", {"username": username, "email": f"{username}@demo.drem.local",
                                             "country_code": country})
            except ApiError as exc:
                if exc.status != 409:
                    raise
            self.api.put(f"/api/users/{username}/profile", {"highlight_colour": colour, "avatar": "identicon"})

    def _create_event(self) -> str:
        return self.api.post("/api/events", {
            "name": "drem demo: sim cars", "event_type": "OTHER", "date": time.strftime("%Y-%m-%d"),
            "country_code": "SE",
            "race_config": {"race_time_min": RACE_TIME_MIN, "max_runs_per_racer": None},
            "tracks": [{"track_id": track_id, "fleet_id": self.fleet_id} for track_id in TRACK_IDS]})["event_id"]

    def _ensure_car(self, track_id: str) -> DemoCar:
        from drem_cars.client import activate
        from drem_cars.credentials import CredentialStore, NotActivated

        hostname = f"demo-sim-{track_id}"
        car = DemoCar(hostname, track_id, self.directory / "cars" / hostname)
        store = CredentialStore(car.config_dir)
        try:
            credential = store.load()
            if credential.fleet_id == self.fleet_id and self._exists(f"/api/devices/{credential.device_id}"):
                car.device_id = credential.device_id
                return car
        except NotActivated:
            pass
        code = self.api.post("/api/devices/activation-codes",
                             {"fleet_id": self.fleet_id, "hostname": hostname, "device_kind": "car"})["code"]
        credential = activate(self.stack.config.app_url, code, hostname)
        store.save(credential)
        car.device_id = credential.device_id
        return car

    def _spawn_car(self, car: DemoCar) -> ManagedProcess:
        argv = [sys.executable, "-m", "drem_local.cli", "car", "--config-dir", str(car.config_dir), "run", "--sim",
                "--track", self.sim_track, "--event", self.event_id, "--race-track", car.track_id,
                "--rate-hz", str(self.rate_hz)]
        env = {k: v for k, v in self.stack.env.items() if not k.startswith(("AWS_", "DREM_"))}
        env["DREM_CAR_NO_REEXEC"] = "1"
        return spawn(f"sim car {car.hostname}", argv, self.stack.config.log_dir / f"{car.hostname}.log", env=env)

    def _exists(self, path: str) -> bool:
        try:
            self.api.get(path)
        except ApiError as exc:
            if exc.status in (403, 404):
                return False
            raise
        return True

    def _load(self) -> dict[str, Any]:
        try:
            return json.loads((self.directory / DEMO_FILE).read_text())
        except (OSError, ValueError):
            return {}

    def _save(self) -> None:
        path = self.directory / DEMO_FILE
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps({"event_id": self.event_id, "fleet_id": self.fleet_id,
                                   "cars": [{"hostname": c.hostname, "track_id": c.track_id,
                                             "device_id": c.device_id} for c in self.cars]}, indent=2))
        os.replace(tmp, path)

    # --- race director -----------------------------------------------------------------------------------------

    def step(self) -> None:
        """One round of the race director over every track (call about once a second)."""
        for director in self._directors:
            try:
                self._direct(director)
            except ApiError as exc:  # a refused command must not stop the demo; the next round looks again
                print(f"demo: track {director.track_id}: {exc}", file=sys.stderr, flush=True)

    def _direct(self, director: TrackDirector) -> None:
        races = f"/api/events/{self.event_id}/races"
        if director.race_id is None:
            live = [r for r in self.api.get(races, {"track": director.track_id})["races"]
                    if r["status"] in LIVE_STATUSES]
            if live:  # left by an earlier run of the demo: carry on with it
                director.race_id, director.created_at = live[-1]["race_id"], time.monotonic()
            else:
                username, throttle_cap = next(self._next_racer)
                car = next(c for c in self.cars if c.track_id == director.track_id)
                self.api.post(f"/api/devices/{car.device_id}/commands",
                              {"type": "SET_THROTTLE_CAP", "throttle_cap_pct": throttle_cap})
                director.race_id = self.api.post(races, {
                    "track_id": director.track_id, "racer_username": username, "car": car.hostname})["race_id"]
                director.created_at = time.monotonic()
                return
        view = self.api.get(f"{races}/{director.race_id}")
        status = view.get("race", view)["status"]
        overdue = time.monotonic() - director.created_at > RACE_TIME_MIN * 60 + OVERDUE_S
        if status == "OVER" or (overdue and status in ("RUNNING", "PAUSED")):
            if status != "OVER":
                self.api.post(f"{races}/{director.race_id}/commands", {"kind": "end"})
            self.api.post(f"{races}/{director.race_id}/commands", {"kind": "submit"})
            director.race_id = None
        elif status not in LIVE_STATUSES:
            director.race_id = None  # submitted or discarded by someone else

    # --- output and shutdown -----------------------------------------------------------------------------------

    def urls(self) -> dict[str, str]:
        base, event = self.stack.config.app_url, self.event_id
        return {"Leaderboard": f"{base}/leaderboard/{event}", "Overlay (track 1)": f"{base}/overlay/{event}?trackId=1",
                "Commentator (staff sign-in)": f"{base}/commentator/{event}", "Console": f"{base}/console/races"}

    def stop(self, timeout: float = 10.0) -> None:
        """Ctrl-C to each car (it stops driving and flushes its outbox), then SIGTERM/SIGKILL any that will not go."""
        running = [car.process for car in self.cars if car.process is not None and car.process.alive()]
        for process in running:
            process.popen.send_signal(signal.SIGINT)
        deadline = time.monotonic() + timeout
        for process in running:
            try:
                process.popen.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                process.stop(2)


def demo_track_and_sample() -> tuple[str, str]:
    """The first sim track of SIM_TRACKS_AND_SAMPLES this machine has, with the sample model trained on it."""
    from drem_sim.tracks import TrackError, load_track

    for track, sample in SIM_TRACKS_AND_SAMPLES:
        try:
            load_track(track)
        except TrackError:
            continue
        return track, sample
    raise DemoError("none of the demo tracks can be loaded: " + ", ".join(t for t, _ in SIM_TRACKS_AND_SAMPLES))
