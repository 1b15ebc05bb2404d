"""Start, watch and stop the local stack: the durable moto server, the bootstrap, the app server, the live server
(drem_live: the public pages' pushed updates, on the app's port + 2), the scrutineering worker
(drem_local.workers.scrutineer: background test drives of uploaded models) and, for `drem up`, the learning
booth's trainer (drem_local.workers.trainer).

Shared by `drem up`, `drem status`, the integration-test fixtures and `bench/startup.py`, so all of them run the
stack the same way. Child processes get their own session (a Ctrl-C reaches only `drem up`, which then stops them
in order) and a parent-death signal (if `drem up` itself is killed they get SIGTERM and the storage snapshots).
"""
from __future__ import annotations

import contextlib
import ctypes
import json
import os
import random
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

STACK_FILE = "stack.json"
LOG_DIR = "logs"
DEFAULT_HOST = "127.0.0.1"
DEFAULT_APP_PORT = 8000
DEFAULT_STORAGE_PORT = 8001
REGION = "us-east-1"
HEALTH_PATH = "/_drem/health"
APP_HEALTH_PATH = "/healthz"
LIVE_HEALTH_PATH = "/live/healthz"
LIVE_PORT_OFFSET = 2  # 8000 app, 8001 storage, 8002 live
_PR_SET_PDEATHSIG = 1
# Credentials a shell may hold that must never steer (or leak into) calls to the local storage server.
_SHELL_AWS_VARIABLES = ("AWS_PROFILE", "AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY", "AWS_SESSION_TOKEN",
                        "AWS_SECURITY_TOKEN")


class StackError(RuntimeError):
    """The stack could not start; the message says why in plain words."""


def disk_error(exc: OSError, where: Path, doing: str) -> StackError | OSError:
    """A StackError in words when `exc` is a full or read-only disk (drem_local.disk); `exc` itself otherwise."""
    from drem_local.disk import problem_of, sentence

    problem = problem_of(exc)
    if problem is None:
        return exc
    return StackError(f"{doing}: {sentence(problem, where, 'run drem up again; nothing stored so far is lost.')}")


def _data_dir_of(log_path: Path) -> Path:
    """The state dir a child's log lives in (<state-dir>/logs/<name>.log), the path people know."""
    return log_path.parent.parent if log_path.parent.name == LOG_DIR else log_path.parent


def _disk_words(where: Path) -> str:
    """Why a child may have died: its disk, when that disk is full or read-only now; "" otherwise."""
    from drem_local.disk import disk_state, sentence

    try:
        state = disk_state(where)
    except OSError:
        return ""
    if state.problem is None:
        return ""
    return " " + sentence(state.problem, where, "run drem up again; nothing stored so far is lost.")


@dataclass(frozen=True)
class StackConfig:
    """Storage always listens on `host` (loopback). The app listens there too, unless `app_bind` names the venue
    network address (or 0.0.0.0, every interface); `announce` is the address people on that network use."""
    state_dir: Path
    host: str = DEFAULT_HOST
    app_port: int = DEFAULT_APP_PORT
    storage_port: int = DEFAULT_STORAGE_PORT
    stage: str = "local"
    region: str = REGION
    snapshot_interval: float = 5.0
    app_bind: str | None = None
    announce: str | None = None
    public_url: str | None = None  # a TLS proxy's URL in front of the app, when there is one
    trainer: bool = False  # also run the learning booth's worker (drem_local.workers.trainer); `drem up` does
    live_port: int | None = None  # None: the app's port + 2
    live_workers: int = 1  # live server processes sharing its port (SO_REUSEPORT)

    @property
    def storage_url(self) -> str:
        return f"http://{self.host}:{self.storage_port}"

    @property
    def app_host(self) -> str:
        return self.app_bind or self.host

    @property
    def app_url(self) -> str:
        """The URL people open, QR codes carry and presigned links point at (DREM_PUBLIC_URL)."""
        if self.public_url:
            return self.public_url.rstrip("/")
        return f"http://{self.announce or self.app_host}:{self.app_port}"

    @property
    def live_server_port(self) -> int:
        return self.live_port or self.app_port + LIVE_PORT_OFFSET

    @property
    def live_url(self) -> str:
        """The live server's origin for the pages (DREM_LIVE_URL): on the app's address, its own port. Behind a proxy
        (public_url) the pages subscribe through it, under its address (the proxy routes /live/ to the live server:
        docs/operations.md); where it does not, their streams fail and they poll the app instead."""
        if self.public_url:
            return self.public_url.rstrip("/")
        return f"http://{self.announce or self.app_host}:{self.live_server_port}"

    @property
    def live_local_url(self) -> str:
        host = self.host if self.app_host in (self.host, "0.0.0.0") else self.app_host
        return f"http://{host}:{self.live_server_port}"

    @property
    def app_local_url(self) -> str:
        """Where this machine reaches the app (health checks): loopback unless the app listens elsewhere only."""
        host = self.host if self.app_host in (self.host, "0.0.0.0") else self.app_host
        return f"http://{host}:{self.app_port}"

    @property
    def log_dir(self) -> Path:
        return self.state_dir / LOG_DIR


# --- processes ------------------------------------------------------------------------------------------------

@dataclass
class ManagedProcess:
    name: str
    popen: subprocess.Popen
    log_path: Path
    log_start: int = 0  # where this run's lines begin in the (appended-to) log file

    @property
    def pid(self) -> int:
        return self.popen.pid

    def alive(self) -> bool:
        return self.popen.poll() is None

    def stop(self, timeout: float = 10.0) -> int | None:
        """SIGTERM, wait, then SIGKILL if it will not go."""
        if self.alive():
            # The background workers run at SCHED_IDLE and nice: on a busy laptop they get the CPU to act on SIGTERM
            # only now and then (beside two CPU-bound processes the scrutineer took over 20 s to stop). A process that
            # is asked to stop gets a normal share of the CPU to do it.
            _normal_priority(self.popen.pid)
            self.popen.send_signal(signal.SIGTERM)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait(5)
        return self.popen.returncode

    def kill_hard(self) -> None:
        """kill -9: what a crash or power cut looks like to the state dir."""
        if self.alive():
            self.popen.kill()
        self.popen.wait(5)

    def log_tail(self, lines: int = 40) -> str:
        """The last lines this run wrote (never an earlier run's: the log file is appended to across restarts)."""
        try:
            with open(self.log_path, "rb") as handle:
                handle.seek(self.log_start)
                text = handle.read().decode(errors="replace")
        except OSError:
            return ""
        return "\n".join(text.splitlines()[-lines:])


def _die_with_parent() -> None:
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        pass  # not Linux: children then outlive a killed parent, and `drem up` reports their pids next time


def _child_setup() -> None:
    os.umask(0o077)  # whatever a child writes into the state dir (logs, journal, snapshots) stays private
    _die_with_parent()


def _normal_priority(pid: int) -> None:
    with contextlib.suppress(AttributeError, OSError):  # not Linux, already gone, or not allowed: it stops later
        os.sched_setscheduler(pid, os.SCHED_OTHER, os.sched_param(0))
    with contextlib.suppress(OSError):
        os.setpriority(os.PRIO_PROCESS, pid, 0)


def spawn(name: str, argv: list[str], log_path: Path, env: dict[str, str] | None = None) -> ManagedProcess:
    try:
        log_path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        log = os.fdopen(os.open(log_path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o600), "ab")
        log_start = log.tell()  # append mode starts at the end: this run's lines begin here
        log.write(f"\n--- {time.strftime('%Y-%m-%d %H:%M:%S')} starting {' '.join(argv)}\n".encode())
        log.flush()
    except OSError as exc:
        raise disk_error(exc, _data_dir_of(log_path), f"the {name} could not write its log {log_path}") from exc
    popen = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env,
                             start_new_session=True, preexec_fn=_child_setup)
    log.close()
    return ManagedProcess(name, popen, log_path, log_start)


def lan_address() -> str:
    """This machine's address on the network its default route leaves by (the venue WiFi or switch)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("192.0.2.1", 9))  # TEST-NET-1: connecting a UDP socket only picks a route, sends nothing
            address = probe.getsockname()[0]
        except OSError:
            address = ""
    if not address or address.startswith("127.") or address == "0.0.0.0":
        raise StackError("this machine has no network address to serve the venue on (no default route). Join the "
                         "venue network first, or name the address with --host ADDR (see `ip -4 addr`).")
    return address


def lan_config(config: StackConfig, host: str | None, public_url: str | None = None) -> StackConfig:
    """`config` serving the app on the venue network: on `host` (an address of this machine; 0.0.0.0 or None means
    every interface, announced as the default route's address). Storage stays on loopback whatever `host` is."""
    from dataclasses import replace

    bind = host or "0.0.0.0"
    if bind != "0.0.0.0":
        require_local_address(bind)
    announce = lan_address() if bind == "0.0.0.0" and not public_url else (None if bind == "0.0.0.0" else bind)
    return replace(config, app_bind=bind, announce=announce, public_url=public_url)


def require_local_address(address: str) -> None:
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            probe.bind((address, 0))
    except OSError as exc:
        raise StackError(f"{address} is not an IPv4 address of this machine ({exc.strerror}); `ip -4 addr` lists "
                         "them") from None


def port_in_use(host: str, port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError:
            return True
    return False


def free_port(host: str = DEFAULT_HOST) -> int:
    """A port nothing listens on now, for a server that must be able to restart on it (tests, benches).

    Drawn below the kernel's ephemeral range: a port the kernel hands out (bind to 0) is also where it puts the local
    end of outgoing connections, so a server restarted on one could find a client's connection holding it ("Address
    already in use", seen once in a full test run)."""
    low, _ = _ephemeral_ports()
    for _ in range(200):
        port = random.randrange(max(1024, low - 20000), low)
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            try:
                probe.bind((host, port))
            except OSError:
                continue
            return port
    raise StackError(f"no free port on {host} below {low}")


def _ephemeral_ports() -> tuple[int, int]:
    try:
        low, high = Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()
        return int(low), int(high)
    except (OSError, ValueError):
        return 32768, 60999  # Linux's default; macOS and Windows start at 49152, above it


_NO_PROXY = urllib.request.build_opener(urllib.request.ProxyHandler({}))


def http_get(url: str, timeout: float = 2.0) -> tuple[int, bytes] | None:
    """(status, body), or None when nothing answers. Never goes through a proxy: everything here is local."""
    try:
        with _NO_PROXY.open(url, timeout=timeout) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()
    except (OSError, ValueError):
        return None


# Seconds a starting child may go without any progress (no CPU time, no log line) before it counts as stuck. Not a
# deadline: a child that keeps working may take as long as it needs (drem_local.readiness).
STALL_S = 120.0


def wait_for_ok(url: str, process: ManagedProcess, timeout: float = STALL_S,
                say: Callable[[str], None] | None = None, needs: ManagedProcess | None = None) -> float:
    """Poll `url` until it answers 200; seconds it took. `timeout` bounds only a stall: the wait goes on as long as
    the process keeps working (drem_local.readiness), and `say` hears every 10 s what it is waiting for. Fails early,
    with the log tail, if the process dies, or if `needs` (the storage server an app restart waits on) dies meanwhile:
    the app would answer 503 for ever, busy enough never to count as stalled."""
    from drem_local.readiness import ChildExited, ReadinessWait, StillWaiting, process_progress

    def answered() -> bool:
        answer = http_get(url, timeout=1.0)
        return answer is not None and answer[0] == 200

    def alive() -> bool:
        if needs is not None and not needs.alive():
            raise StackError(f"the {needs.name} stopped while the {process.name} was starting; it is started again "
                             "first")
        return process.alive()

    wait = ReadinessWait(f"the {process.name} (pid {process.pid}) to answer {url}", answered, alive,
                         lambda: process_progress(process.pid, process.log_path), stall_s=timeout, say=say)
    try:
        return wait.run()
    except ChildExited:
        raise StackError(f"the {process.name} exited with code {process.popen.returncode} before {url} "
                         f"answered.{_disk_words(_data_dir_of(process.log_path))} "
                         f"Last lines of {process.log_path}:\n{process.log_tail()}") from None
    except StillWaiting as exc:
        raise StackError(f"the {process.name} seems stuck: {exc}. "
                         f"Last lines of {process.log_path}:\n{process.log_tail()}") from None


# --- the three steps ------------------------------------------------------------------------------------------

def start_storage(config: StackConfig, timeout: float = STALL_S,
                  say: Callable[[str], None] | None = None) -> ManagedProcess:
    from drem_local.storage_keys import load_or_create

    _require_free_port(config.host, config.storage_port, "storage (durable moto) server", "--storage-port")
    load_or_create(config.state_dir)  # before the log dir: the state dir must be 0700 from the start
    process = spawn("storage server", [
        sys.executable, "-m", "drem_local.durable", "--state-dir", str(config.state_dir),
        "--host", config.host, "--port", str(config.storage_port),
        "--snapshot-interval", str(config.snapshot_interval),
    ], config.log_dir / "storage.log", env=_child_env())
    try:
        wait_for_ok(config.storage_url + HEALTH_PATH, process, timeout, say)
    except BaseException:
        process.stop(2)
        raise
    return process


def bootstrap(config: StackConfig, admin_username: str, admin_password: str | None):
    """Create the tables, buckets, user pool and admin (idempotent). Returns (StackOutputs, AdminCredentials)."""
    from drem_local.bootstrap import clients_for, ensure_admin, ensure_stack
    from drem_local.storage_keys import load_or_create

    clients = clients_for(config.storage_url, config.region, load_or_create(config.state_dir))
    outputs = ensure_stack(clients, config.stage)
    admin = ensure_admin(clients, outputs, admin_username, admin_password)
    return outputs, admin


def app_environment(config: StackConfig, outputs: Any) -> dict[str, str]:
    from drem_local.storage_keys import load_or_create

    env = _child_env()
    env.update(outputs.to_env())
    env.update(load_or_create(config.state_dir).environment())  # the only keys the storage server accepts
    env.update(
        AWS_ENDPOINT_URL=config.storage_url,
        AWS_DEFAULT_REGION=config.region,
        AWS_REGION=config.region,
        AWS_ACCOUNT_ID_ENDPOINT_MODE="disabled",
        DREM_STAGE=config.stage,
        DREM_STATE_DIR=str(config.state_dir.resolve()),
        DREM_PUBLIC_URL=config.app_url,
        # The app's board writes wake the live server's processes here (chalicelib.live_wake).
        DREM_LIVE_WAKE_DIR=str((config.state_dir / "live-wake").resolve()),
    )
    env.setdefault("DREM_LIVE_URL", config.live_url)
    return env


def start_app(config: StackConfig, env: dict[str, str], timeout: float = STALL_S,
              say: Callable[[str], None] | None = None, storage: ManagedProcess | None = None) -> ManagedProcess:
    _require_free_port(config.app_host, config.app_port, "app server", "--port")
    process = spawn("app server", [
        sys.executable, "-m", "drem_local.appserver", "--host", config.app_host, "--port", str(config.app_port),
        "--storage-url", config.storage_url,
    ], config.log_dir / "app.log", env=env)
    try:
        wait_for_ok(config.app_local_url + APP_HEALTH_PATH, process, timeout, say, needs=storage)
    except BaseException:
        process.stop(2)
        raise
    return process


def start_trainer(config: StackConfig, env: dict[str, str]) -> ManagedProcess:
    """The learning booth's worker: the app's environment, its own log; it is ready when it polls (no port)."""
    return spawn("booth trainer", [sys.executable, "-m", "drem_local.workers.trainer"],
                 config.log_dir / "trainer.log", env=env)


def start_scrutineer(config: StackConfig, env: dict[str, str]) -> ManagedProcess:
    """The scrutineering worker: it has no port; it takes jobs from the queue in storage (drem status shows it)."""
    return spawn("scrutineering worker", [sys.executable, "-m", "drem_local.workers.scrutineer"],
                 config.log_dir / "scrutineer.log", env=env)


def start_live(config: StackConfig, env: dict[str, str], timeout: float = STALL_S, *,
               wait: bool = True, say: Callable[[str], None] | None = None) -> ManagedProcess:
    """The live server (drem_live), on the app's address; it reads storage with the app's settings. `wait=False`
    returns at once (then `wait_for_live`), so it can start while the app does."""
    _require_free_port(config.app_host, config.live_server_port, "live server", "--live-port")
    process = spawn("live server", [
        sys.executable, "-m", "drem_live", "--host", config.app_host, "--port", str(config.live_server_port),
        "--workers", str(config.live_workers),
    ], config.log_dir / "live.log", env=env)
    if wait:
        wait_for_live(config, process, timeout, say)
    return process


def wait_for_live(config: StackConfig, process: ManagedProcess, timeout: float,
                  say: Callable[[str], None] | None = None) -> None:
    try:
        wait_for_ok(config.live_local_url + LIVE_HEALTH_PATH, process, timeout, say)
    except BaseException:
        process.stop(2)
        raise


def _child_env() -> dict[str, str]:
    env = {name: value for name, value in os.environ.items() if name not in _SHELL_AWS_VARIABLES}
    env["NO_PROXY"] = ",".join(filter(None, [env.get("NO_PROXY"), "127.0.0.1", "localhost"]))
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _require_free_port(host: str, port: int, what: str, flag: str) -> None:
    if port_in_use(host, port):
        raise StackError(f"port {port} on {host} is already in use, so the {what} cannot start there. "
                         f"Stop whatever uses it (`drem status` shows whether it is an older drem), "
                         f"or pick another port with {flag}.")


# --- the whole stack ------------------------------------------------------------------------------------------

@dataclass
class RunningStack:
    config: StackConfig
    storage: ManagedProcess
    app: ManagedProcess
    outputs: Any
    admin: Any
    env: dict[str, str]
    live: ManagedProcess | None = None
    timings: dict[str, float] = field(default_factory=dict)
    trainer: ManagedProcess | None = None
    scrutineer: ManagedProcess | None = None

    say: Callable[[str], None] | None = None  # hears what a restart is waiting for (drem up prints it)

    def restart_storage(self, timeout: float = STALL_S) -> None:
        """Start the storage server again on the same state dir and port (it recovers from its journal)."""
        self.storage = start_storage(self.config, timeout, self.say)
        self._record_pids()

    def restart_app(self, timeout: float = STALL_S) -> None:
        self.app = start_app(self.config, self.env, timeout, self.say, storage=self.storage)
        self._record_pids()

    def restart_trainer(self, timeout: float = STALL_S) -> None:
        self.trainer = start_trainer(self.config, self.env)
        self._record_pids()

    def restart_scrutineer(self, timeout: float = STALL_S) -> None:
        self.scrutineer = start_scrutineer(self.config, self.env)
        self._record_pids()

    def restart_live(self, timeout: float = STALL_S) -> None:
        self.live = start_live(self.config, self.env, timeout, say=self.say)
        self._record_pids()

    def _record_pids(self) -> None:
        write_stack_file(self.config, self.outputs, self.admin.username, storage_pid=self.storage.pid,
                         app_pid=self.app.pid, live_pid=self.live.pid if self.live else None,
                         trainer_pid=self.trainer.pid if self.trainer else None,
                         scrutineer_pid=self.scrutineer.pid if self.scrutineer else None)

    def stop(self) -> tuple[int | None, int | None]:
        """The workers and the app first (they may still be writing), then the live server, then storage, which
        snapshots on SIGTERM."""
        for worker in (self.trainer, self.scrutineer):
            if worker is not None:
                worker.stop()
        app_code = self.app.stop()
        if self.live is not None:
            self.live.stop()
        storage_code = self.storage.stop(timeout=30.0)
        stack_file = self.config.state_dir / STACK_FILE
        info = read_stack_file(self.config.state_dir)
        if info is not None and info.get("pids", {}).get("storage") == self.storage.pid:
            info["stopped_at"] = time.time()
            _write_json(stack_file, info)
        return app_code, storage_code


def start_stack(config: StackConfig, admin_username: str = "admin", admin_password: str | None = None,
                *, timeout: float = STALL_S, say: Callable[[str], None] | None = None) -> RunningStack:
    """Start everything in order. `timeout` bounds only a child that stops making progress (drem_local.readiness):
    a slow app on a busy machine is waited for, with a line to `say` every 10 s, and never stops storage. A full or
    read-only disk is a StackError in words (drem_local.disk), never a traceback."""
    try:
        return _start_stack(config, admin_username, admin_password, timeout, say)
    except OSError as exc:
        raise disk_error(exc, config.state_dir, "drem could not write to its state dir") from exc
    except Exception as exc:
        refusal = storage_disk_refusal(exc)
        if refusal is None:
            raise
        raise StackError(f"the storage server refused to store the setup: {refusal}") from exc


def storage_disk_refusal(exc: BaseException) -> str | None:
    """The storage server's own words when `exc` is its refusal for a full or read-only disk (drem_local.durable)."""
    from drem_local.durable.disk_guard import DISK_ERROR_CODES

    response = getattr(exc, "response", None)
    if not isinstance(response, dict):
        return None
    error = response.get("Error", {})
    return str(error.get("Message", "")) if error.get("Code") in DISK_ERROR_CODES else None


def _start_stack(config: StackConfig, admin_username: str, admin_password: str | None, timeout: float,
                 say: Callable[[str], None] | None) -> RunningStack:
    refuse_if_running(config.state_dir)
    _require_free_port(config.host, config.storage_port, "storage (durable moto) server", "--storage-port")
    _require_free_port(config.app_host, config.app_port, "app server", "--port")
    _require_free_port(config.app_host, config.live_server_port, "live server", "--live-port")
    from drem_local.storage_keys import load_or_create

    load_or_create(config.state_dir)  # the state dir 0700, its files 0600, the storage keys drawn once
    started = time.perf_counter()
    storage = start_storage(config, timeout, say)
    storage_ready = time.perf_counter()
    app = live = None
    try:
        outputs, admin = bootstrap(config, admin_username, admin_password)
        bootstrapped = time.perf_counter()
        env = app_environment(config, outputs)
        write_stack_file(config, outputs, admin.username, storage_pid=storage.pid, app_pid=None)
        app = start_app(config, env, timeout, say)
        # After the app (not beside it: on two cores their imports would slow the app's start); until it answers the
        # pages poll the app, and their EventSource connects once it does.
        live = start_live(config, env, timeout, say=say)
        trainer = start_trainer(config, env) if config.trainer else None
    except BaseException:
        for process in (app, live):
            if process is not None:
                process.stop(5)
        storage.stop(30)
        raise
    ready = time.perf_counter()
    scrutineer = start_scrutineer(config, env)
    write_stack_file(config, outputs, admin.username, storage_pid=storage.pid, app_pid=app.pid, live_pid=live.pid,
                     trainer_pid=trainer.pid if trainer else None, scrutineer_pid=scrutineer.pid)
    timings = {"storage_s": storage_ready - started, "bootstrap_s": bootstrapped - storage_ready,
               "app_s": ready - bootstrapped, "total_s": ready - started}
    return RunningStack(config, storage, app, outputs, admin, env, live, timings, trainer, scrutineer, say)


# --- stack.json -----------------------------------------------------------------------------------------------

def write_stack_file(config: StackConfig, outputs: Any, admin_username: str, *, storage_pid: int,
                     app_pid: int | None, live_pid: int | None = None, trainer_pid: int | None = None,
                     scrutineer_pid: int | None = None) -> None:
    _write_json(config.state_dir / STACK_FILE, {
        "outputs": json.loads(outputs.to_json()),
        "admin_username": admin_username,
        "host": config.host,
        "app_host": config.app_host,
        "ports": {"app": config.app_port, "storage": config.storage_port, "live": config.live_server_port},
        "urls": {"app": config.app_url, "app_local": config.app_local_url, "storage": config.storage_url,
                 "live": config.live_url, "live_local": config.live_local_url},
        "pids": {"storage": storage_pid, "app": app_pid, "live": live_pid, "trainer": trainer_pid,
                 "scrutineer": scrutineer_pid, "drem_up": os.getpid()},
        "started_at": time.time(),
        "stopped_at": None,
    })


def read_stack_file(state_dir: Path) -> dict[str, Any] | None:
    try:
        return json.loads((state_dir / STACK_FILE).read_text())
    except (OSError, ValueError):
        return None


def _write_json(path: Path, data: dict[str, Any]) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with os.fdopen(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600), "w") as handle:
        handle.write(json.dumps(data, indent=2, sort_keys=True))
    os.replace(tmp, path)


def pid_is_drem(pid: int | None) -> bool:
    """True when `pid` is alive and is one of ours (a stale pid may have been reused by something else)."""
    if not pid:
        return False
    try:
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ")
    except OSError:
        try:
            os.kill(pid, 0)
        except OSError:
            return False
        return True  # no /proc: alive is the best we can tell
    return b"drem" in cmdline


def refuse_if_running(state_dir: Path) -> None:
    """A stack.json left by a crashed run is fine; one whose processes still run means a second `drem up`."""
    info = read_stack_file(state_dir)
    if not info:
        return
    running = {name: pid for name, pid in info.get("pids", {}).items() if name != "drem_up" and pid_is_drem(pid)}
    if running:
        listing = ", ".join(f"{name} pid {pid}" for name, pid in running.items())
        raise StackError(f"drem is already running on the state dir {state_dir} ({listing}). Open "
                         f"{info.get('urls', {}).get('app', 'the app')} or stop it first (Ctrl-C in its terminal, "
                         f"or `kill {' '.join(str(p) for p in running.values())}`).")
