"""Fixtures that start real local stacks (moto server subprocess, app over HTTP) for integration and browser tests.

- `durable_server_factory`: start / `kill -9` / restart durable moto servers on free ports in tmp state dirs.
- `live_stack`: the whole `drem up` stack (durable moto + bootstrap + live server + app server) once per test
  session.
Subprocess logs are printed when something fails to start, so a red test says why.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from drem_local import stack as local_stack


@dataclass
class DurableServer:
    """One durable moto server subprocess bound to a state dir; restart keeps the dir and the port."""

    state_dir: Path
    port: int
    snapshot_interval: float
    process: local_stack.ManagedProcess | None = None

    @property
    def config(self) -> local_stack.StackConfig:
        return local_stack.StackConfig(state_dir=self.state_dir, storage_port=self.port,
                                       snapshot_interval=self.snapshot_interval)

    @property
    def url(self) -> str:
        return self.config.storage_url

    def start(self) -> DurableServer:
        try:
            self.process = local_stack.start_storage(self.config, timeout=30.0)
        except local_stack.StackError as exc:
            pytest.fail(f"durable server did not start: {exc}")
        return self

    def kill9(self) -> None:
        if self.process is not None:
            self.process.kill_hard()

    def stop(self) -> int | None:
        return self.process.stop(timeout=30.0) if self.process is not None else None

    def restart(self) -> DurableServer:
        self.stop()
        return self.start()

    def health(self) -> dict[str, Any]:
        import json

        answer = local_stack.http_get(self.url + local_stack.HEALTH_PATH)
        assert answer is not None and answer[0] == 200, f"no health answer from {self.url}"
        return json.loads(answer[1])

    @property
    def keys(self) -> Any:
        from drem_local.storage_keys import load

        return load(self.state_dir)

    def clients(self, *, retries: int = 1) -> Any:
        """boto3 clients (signed with the installation's keys) that fail fast (no retries), so a killed server shows
        up as an error, not a wait."""
        from botocore.config import Config

        from drem_local.storage_keys import local_client

        config = Config(retries={"total_max_attempts": retries}, connect_timeout=2, read_timeout=10)
        return _Clients(*(local_client(name, self.url, self.keys, local_stack.REGION, config)
                          for name in ("dynamodb", "s3", "cognito-idp")))


@dataclass(frozen=True)
class _Clients:
    dynamodb: Any
    s3: Any
    cognito: Any


@dataclass
class DurableServerFactory:
    base_dir: Path
    servers: list[DurableServer] = field(default_factory=list)

    def start(self, name: str = "server", *, snapshot_interval: float = 5.0) -> DurableServer:
        state_dir = self.base_dir / f"{name}-{len(self.servers)}"
        server = DurableServer(state_dir, local_stack.free_port(), snapshot_interval)
        self.servers.append(server)
        return server.start()

    def close(self) -> None:
        for server in self.servers:
            server.stop()


@pytest.fixture(scope="session")
def durable_server_factory(tmp_path_factory: pytest.TempPathFactory):
    factory = DurableServerFactory(tmp_path_factory.mktemp("durable"))
    yield factory
    factory.close()


@dataclass(frozen=True)
class LiveStack:
    url: str
    live_url: str  # the live server (drem_live) the pages' live regions subscribe to
    storage_url: str
    outputs: Any  # drem_local.bootstrap.StackOutputs
    env: dict[str, str]
    admin_username: str
    admin_password: str
    state_dir: Path
    running: local_stack.RunningStack

    def client(self, service: str) -> Any:
        """A boto3 client for the stack's storage server, signed with the installation's keys."""
        from drem_local.storage_keys import load, local_client

        return local_client(service, self.storage_url, load(self.state_dir), local_stack.REGION)


@pytest.fixture(scope="session")
def live_stack(tmp_path_factory: pytest.TempPathFactory):
    from drem_local.bootstrap import generate_password

    state_dir = tmp_path_factory.mktemp("live-stack") / "state"
    config = local_stack.StackConfig(state_dir=state_dir, app_port=local_stack.free_port(),
                                     storage_port=local_stack.free_port(), live_port=local_stack.free_port())
    password = generate_password()
    try:
        running = local_stack.start_stack(config, "admin", password, timeout=60.0)
    except local_stack.StackError as exc:
        pytest.fail(f"the local stack did not start: {exc}")
    yield LiveStack(url=config.app_url, live_url=config.live_url, storage_url=config.storage_url,
                    outputs=running.outputs, env=running.env,
                    admin_username="admin", admin_password=password, state_dir=state_dir, running=running)
    _app_code, storage_code = running.stop()
    if storage_code not in (0, None):
        print(f"storage server exited with {storage_code}:\n{running.storage.log_tail()}")


def read_until(process: Any, marker: str, timeout: float = 60.0) -> str:
    """The lines `process` prints up to the first one holding `marker` (e.g. drem up's "Press Ctrl-C" banner line).
    If the output ends or `timeout` passes first, the process is killed and the test fails with what it printed."""
    import time

    lines: list[str] = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if not line:
            break
        lines.append(line)
        if marker in line:
            return "".join(lines)
    process.kill()
    pytest.fail(f"never printed {marker!r}:\n" + "".join(lines) + (process.stdout.read() or ""))
