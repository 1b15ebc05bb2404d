"""The device agent: heartbeats, staff commands, model pulls and the outbox, next to the drive loop.

Three background threads: `control` (every `tick_s`: deliver the outbox; heartbeat every `heartbeat_s`; fetch and carry
out commands every `command_poll_s`), `assignment` (a long poll: the server answers the moment staff change the car's
assignment, so a new racer's model reaches the car at once) and `models` (woken by a new assignment, and every
`assignment_poll_s` anyway: check the car still runs its model, download, verify, unpack, swap, load, then put the
other assigned models, the next racers', on the car so a swap is the load alone; every step reported through the
outbox, so status reports survive network loss and restarts).
A revoked credential (401) stops the agent cleanly: the car is stopped and `revoked` says why.
"""
from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from drem_cars import __version__
from drem_cars.client import DeviceClient, Rejected, Revoked, Unreachable
from drem_cars.drivers import CarDriver, CarUnreachable
from drem_cars.model_files import ModelError
from drem_cars.model_store import InstalledModel, ModelInstallError, ModelStore
from drem_cars.outbox import MODEL_STATUS, STRIP_EVENT, Outbox, OutboxItem

log = logging.getLogger("drem_cars.agent")


@dataclass(frozen=True)
class AgentTiming:
    tick_s: float = 0.25
    heartbeat_s: float = 3.0
    command_poll_s: float = 1.0
    assignment_poll_s: float = 2.0  # the car check (and the fallback when the server does not long-poll)
    assignment_wait_s: float = 20.0  # how long the server may hold an assignment request open


class CarAgent:
    def __init__(self, client: DeviceClient, driver: CarDriver, outbox: Outbox, store: ModelStore | None,
                 timing: AgentTiming = AgentTiming(), clock: Callable[[], float] = time.monotonic) -> None:
        self.client = client
        self.driver = driver
        self.outbox = outbox
        self.store = store
        self.timing = timing
        self._clock = clock
        self._stop = threading.Event()
        self._deliver_lock = threading.Lock()
        self._threads: list[threading.Thread] = []
        self._done_commands: set[str] = set()
        self._reported: dict[str, tuple[str, str | None]] = {}  # model_id → (status, md5) last queued
        # A sim car carries its own timing line (its strip events time the track): staff see it as the timer.
        self.times_laps = False
        self._failed: set[tuple[str, str]] = set()  # (model_id, archive md5) that cannot install: not retried
        self.loaded: InstalledModel | None = None
        self.revoked: str | None = None
        self.restart_requested = False
        self.last_heartbeat_ok: float | None = None
        self._assignment: dict[str, Any] | None = None  # the last one the server gave
        self._assignment_lock = threading.Lock()
        self._watching = False  # the assignment thread fetches; the models thread uses what it fetched
        self._assignment_changed = threading.Event()

    # --- lifecycle ---
    def start(self) -> None:
        self._threads = [threading.Thread(target=self._loop, args=(self.control_tick, self.timing.tick_s),
                                          name="drem-agent-control", daemon=True)]
        if self.store is not None:
            self._watching = True
            self._threads += [threading.Thread(target=self._watch_assignment, name="drem-agent-assignment",
                                               daemon=True),
                              threading.Thread(target=self._models_loop, name="drem-agent-models", daemon=True)]
        for thread in self._threads:
            thread.start()

    def stop(self, timeout: float = 10.0) -> None:
        self._stop.set()
        self._assignment_changed.set()
        for thread in self._threads:
            # The assignment thread may sit in a long poll for 20 s; it writes nothing, so it is not waited for
            # (a daemon thread: Ctrl-C stops the agent at once).
            if thread is not threading.current_thread() and thread.name != "drem-agent-assignment":
                thread.join(timeout)

    @property
    def stopped(self) -> bool:
        return self._stop.is_set()

    def wait(self, timeout: float | None = None) -> bool:
        return self._stop.wait(timeout)

    def _loop(self, step: Callable[[], None], period: float) -> None:
        while not self._stop.is_set():
            try:
                step()
            except Revoked as exc:
                self._revoke(str(exc))
                return
            except Exception:  # one bad cycle must not kill the agent; the next cycle tries again
                log.exception("agent cycle failed")
            self._stop.wait(period)

    def _models_loop(self) -> None:
        while not self._stop.is_set():
            try:
                self.sync_models()
            except Revoked as exc:
                self._revoke(str(exc))
                return
            except Exception:  # one bad cycle must not kill the agent; the next cycle tries again
                log.exception("agent cycle failed")
            self._assignment_changed.wait(self.timing.assignment_poll_s)
            self._assignment_changed.clear()

    def _watch_assignment(self) -> None:
        """Hold a long poll open on the assignment; wake the models thread the moment it changes."""
        version: int | None = None
        while not self._stop.is_set():
            asked = self._clock()
            try:
                assignment = (self.client.assignment() if version is None else
                              self.client.assignment(wait_for_version=version, wait_s=self.timing.assignment_wait_s))
            except Revoked as exc:
                self._revoke(str(exc))
                return
            except Exception as exc:  # unreachable, refused: asked again shortly, the models thread keeps checking
                log.warning("assignment: %s", exc)
                self._stop.wait(self.timing.assignment_poll_s)
                continue
            with self._assignment_lock:
                self._assignment = assignment
            fresh = assignment.get("version")
            self._assignment_changed.set()  # new version, or fresh download links for the same one
            if fresh == version and self._clock() - asked < self.timing.assignment_wait_s / 2:
                self._stop.wait(self.timing.assignment_poll_s)  # a server that does not hold the request: poll
            version = fresh if isinstance(fresh, int) else None

    def _revoke(self, reason: str) -> None:
        self.revoked = reason
        log.error("%s; stopping the car and the agent", reason)
        self.driver.emergency_stop()
        self._stop.set()

    # --- control thread ---
    _next_heartbeat = 0.0
    _next_commands = 0.0

    def control_tick(self) -> None:
        now = self._clock()
        if now >= self._next_heartbeat:
            self._next_heartbeat = now + self.timing.heartbeat_s
            self.heartbeat()
        if now >= self._next_commands:
            self._next_commands = now + self.timing.command_poll_s
            self.run_commands()
        self.flush_outbox()

    def heartbeat(self) -> bool:
        try:
            self.client.heartbeat(self.telemetry())
        except Unreachable as exc:
            log.warning("heartbeat: %s", exc)
            return False
        self.last_heartbeat_ok = self._clock()
        self.driver.heartbeat_ok()
        return True

    def telemetry(self) -> dict[str, Any]:
        readings = (("battery_pct", self.driver.battery_pct()), ("fps", self.driver.fps()),
                    ("inference_latency_ms", self.driver.inference_ms()))
        # faults after the readings: reading the battery is how a device-console car learns of its faults
        body: dict[str, Any] = {"agent_version": __version__, "faults": self.driver.faults()[:10]}
        if self.times_laps:
            body["times_laps"] = True
        if self.loaded is not None:
            body["model"] = {"name": self.loaded.name[:200], "md5": self.loaded.archive_md5}
        for key, value in readings:
            if value is not None:
                body[key] = value
        return body

    def flush_outbox(self) -> int:
        with self._deliver_lock:
            return self.outbox.deliver(self._send)

    def _send(self, item: OutboxItem) -> Any:
        if item.kind == STRIP_EVENT:
            return self.client.strip_event(item.body)
        if item.kind == MODEL_STATUS:
            return self.client.report_model_status(item.body)
        raise Rejected(f"unknown outbox item kind {item.kind!r}")

    # --- commands ---
    def run_commands(self) -> None:
        try:
            commands = self.client.commands()
        except Unreachable as exc:
            log.warning("commands: %s", exc)
            return
        for command in commands:
            self.run_command(command)

    def run_command(self, command: dict[str, Any]) -> None:
        command_id = command["command_id"]
        if command_id not in self._done_commands:
            ok, message = self._execute(command["type"], command.get("parameters") or {})
            self._done_commands.add(command_id)  # carried out once per process, even if the ack must wait
        else:
            ok, message = True, "carried out earlier; acknowledging again"
        try:
            self.client.acknowledge(command_id, ok, message)
        except (Unreachable, Rejected) as exc:
            log.warning("command %s ack: %s (will retry)", command_id, exc)
            return
        if command["type"] == "RESTART_SERVICE" and ok:
            self.restart_requested = True  # only after the ack reached the server, or it would restart forever
            self._stop.set()

    def _execute(self, kind: str, parameters: dict[str, Any]) -> tuple[bool, str]:
        try:
            if kind == "EMERGENCY_STOP":
                self.driver.emergency_stop()
                return True, "stopped"
            if kind == "START_CAR":
                self.driver.start_car()
                return True, "started"
            if kind == "SET_THROTTLE_CAP":
                self.driver.set_throttle_cap(int(parameters["throttle_cap_pct"]))
                return True, f"throttle capped at {parameters['throttle_cap_pct']}%"
            if kind == "SET_TAIL_LIGHT":
                message = self.driver.set_tail_light(str(parameters["colour"]))
                return True, message or f"tail light {parameters['colour']}"
            if kind == "DELETE_ALL_MODELS":
                self.driver.delete_all_models()
                self.loaded = None
                removed = self.store.delete_all() if self.store is not None else 0
                self._reported.clear()
                self._failed.clear()
                return True, f"deleted {removed} model(s)"
            if kind == "RESTART_SERVICE":
                self.driver.emergency_stop()
                return True, "restarting the agent"
        except Exception as exc:  # the staff member sees why it failed
            return False, f"{kind} failed: {exc}"
        return False, f"this agent does not know the command {kind!r}"

    # --- models ---
    def _report(self, model_id: str, status: str, *, md5: str | None = None, reason: str | None = None,
                now: bool = True) -> None:
        """Queue a status report; `now` delivers it at once, else the control thread's next tick (0.25 s) does, so
        a step on the way (downloading, verified) does not wait for the server before the next step starts."""
        if self._reported.get(model_id) == (status, md5):
            return
        self._reported[model_id] = (status, md5)
        body: dict[str, Any] = {"model_id": model_id, "status": status}
        if md5 is not None:
            body["md5"] = md5
        if reason is not None:
            body["reason"] = reason[:300]
        self.outbox.enqueue(MODEL_STATUS, body)
        if now:
            self.flush_outbox()

    def sync_models(self) -> None:
        assert self.store is not None
        if self._watching:
            with self._assignment_lock:
                fetched = self._assignment  # the assignment thread's latest (kept while the server is away)
            if fetched is None:
                return
            assignment = fetched
        else:
            try:
                assignment = self.client.assignment()
                self._assignment = assignment
            except Unreachable as exc:
                log.warning("assignment: %s", exc)
                if self._assignment is None:
                    return
                assignment = self._assignment  # the server is away, the car may not be: keep checking it
        assigned = assignment["models"]
        self.store.remove_except({m["model_id"] for m in assigned})
        installed: list[tuple[dict[str, Any], InstalledModel]] = []
        for entry in assigned:
            model = self._ensure_installed(entry)
            if model is not None:
                installed.append((entry, model))
        if self.loaded is not None and self.loaded.model_id not in {m["model_id"] for m in assigned}:
            self.driver.unload_models()
            self.loaded = None
        for position, (_entry, model) in enumerate(installed):  # the first assigned model that loads drives
            if (model.model_id, model.archive_md5) in self._failed:
                continue
            reloading = False
            if self.loaded is not None and self.loaded.path == model.path:
                lost = self.driver.model_lost(model)  # the car's own state, not our memory of it
                if lost is None:
                    self._report(model.model_id, "loaded", md5=model.archive_md5)
                    self._preload([m for _e, m in installed[position + 1:]])
                    return
                self.loaded, reloading = None, True
                self._report(model.model_id, "verified", md5=model.archive_md5, reason=lost)
            if self.loaded is not None and self.loaded.model_id != model.model_id:
                previous, self.loaded = self.loaded, None  # still assigned, behind this one: it stops driving
                self._report(previous.model_id, "verified", md5=previous.archive_md5, now=False,  # before "loaded"
                             reason="ready, waiting for its turn (the model before it in the assignment drives)")
            try:
                self.driver.load_model(model)
            except CarUnreachable as exc:
                log.warning("loading %s: %s (trying again on the next check)", model.name, exc)
                return
            except (ModelError, OSError) as exc:
                self._failed.add((model.model_id, model.archive_md5))
                self._report(model.model_id, "failed", reason=f"cannot load: {exc}")
                continue
            self.loaded = model
            if reloading:
                self.driver.reloaded(model)
            self._report(model.model_id, "loaded", md5=model.archive_md5)
            self._preload([m for _e, m in installed[position + 1:]])
            return

    def _preload(self, following: list[InstalledModel]) -> None:
        """The next racers' models (assigned after the driving one) go onto the car now, while it drives, so
        swapping to one of them is the load call alone."""
        for model in following:
            if self._stop.is_set() or (model.model_id, model.archive_md5) in self._failed:
                continue
            try:
                self.driver.preload(model)
            except CarUnreachable as exc:
                log.warning("putting %s on the car: %s (trying again on the next check)", model.name, exc)
                return
            except Exception as exc:  # noqa: BLE001 - its load will say why, in its report; the racer drives on
                log.warning("putting %s on the car ahead of its turn: %s", model.name, exc)

    def _ensure_installed(self, entry: dict[str, Any]) -> InstalledModel | None:
        assert self.store is not None  # only the sync with a model store installs
        model_id, md5 = entry["model_id"], entry.get("md5")
        if not md5:
            self._report(model_id, "failed", reason="the server gave no md5 for this model")
            return None
        existing = self.store.find(model_id, md5)
        if existing is not None or (model_id, md5) in self._failed:
            return existing  # installed (maybe unloadable: the load loop skips those), or a failed download
        self._report(model_id, "downloading", now=False)
        onnx = entry.get("onnx") if isinstance(entry.get("onnx"), dict) else None  # a console model's conversion
        try:
            return self.store.install(
                model_id, entry["name"], entry.get("folder") or entry["name"], md5,
                download=lambda handle: self.client.download(entry["url"], handle),
                on_verified=lambda actual: self._report(model_id, "verified", md5=actual, now=False),
                converted=(lambda handle: self.client.download(onnx["url"], handle), onnx["md5"]) if onnx else None)
        except Unreachable as exc:
            log.warning("model %s download: %s (will retry)", model_id, exc)
            self._reported.pop(model_id, None)
            return None
        except ModelInstallError as exc:
            self._failed.add((model_id, md5))
            self._report(model_id, "failed", reason=str(exc))
            return None
