"""Drivers for the race, timing and leaderboard API tests (their fixtures, `desk` and `clock`, are in conftest.py).

`Desk` is a staff-side driver over the Chalice test client with real Cognito tokens and real activated devices;
`FakeClock` stands in for the server clock so manual lap times are exact.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from chalice.test import Client

from tests.unit.conftest import Users, bearer


@dataclass
class FakeClock:
    now: int = 1_800_000_000_000

    def __call__(self) -> int:
        return self.now

    def advance(self, ms: int) -> int:
        self.now += ms
        return self.now


@dataclass
class Desk:
    """Drives the API as staff (operator token) and as devices; every call returns the test client's response."""
    client: Client
    users: Users
    tokens: dict[str, str] = field(default_factory=dict)

    def token(self, username: str, *groups: str) -> str:
        if username not in self.tokens:
            self.tokens[username] = self.users.access_token(username, tuple(groups))
        return self.tokens[username]

    def call(self, method: str, path: str, body: Any = None, *, as_user: str = "op",
             headers: dict[str, str] | None = None) -> Any:
        all_headers = {**bearer(self.tokens[as_user]), "Content-Type": "application/json", **(headers or {})}
        payload = b"" if body is None else json.dumps(body).encode()
        return getattr(self.client.http, method.lower())(path, headers=all_headers, body=payload)

    def anonymous_get(self, path: str, headers: dict[str, str] | None = None) -> Any:
        return self.client.http.get(path, headers={"Accept": "application/json", **(headers or {})})

    # --- setup -------------------------------------------------------------------------------------------------

    def fleet(self, name: str = "Track fleet") -> str:
        reply = self.call("POST", "/api/fleets", {"name": name})
        assert reply.status_code == 201, reply.body
        return json.loads(reply.body)["fleet_id"]

    def event(self, *, tracks: list[dict[str, Any]] | None = None, name: str = "Summit Stockholm 2026",
              **race_config: Any) -> dict[str, Any]:
        body = {"name": name, "event_type": "AWS_SUMMIT", "date": "2026-05-14", "country_code": "SE",
                "race_config": race_config, "tracks": tracks or [{"track_id": "1"}]}
        reply = self.call("POST", "/api/events", body)
        assert reply.status_code == 201, reply.body
        return json.loads(reply.body)

    def device(self, fleet_id: str, hostname: str, kind: str = "timer") -> str:
        """Activate a real device in `fleet_id`; returns its `Authorization: Device` credential."""
        issued = self.call("POST", "/api/devices/activation-codes",
                           {"fleet_id": fleet_id, "hostname": hostname, "device_kind": kind})
        assert issued.status_code == 201, issued.body
        exchange = {"code": json.loads(issued.body)["code"], "hostname": hostname, "device_kind": kind}
        reply = self.client.http.post("/api/devices/activate", body=json.dumps(exchange).encode(), headers={
            "Content-Type": "application/json", "Accept": "application/json"})
        assert reply.status_code in (200, 201), reply.body
        return json.loads(reply.body)["credential"]

    # --- racing ------------------------------------------------------------------------------------------------

    def create_race(self, event_id: str, racer: str, track_id: str = "1", **extra: Any) -> Any:
        return self.call("POST", f"/api/events/{event_id}/races", {"track_id": track_id, "racer_username": racer,
                                                                   **extra})

    def command(self, event_id: str, race_id: str, kind: str, **extra: Any) -> Any:
        return self.call("POST", f"/api/events/{event_id}/races/{race_id}/commands", {"kind": kind, **extra})

    def ok(self, reply: Any, status: int = 200) -> dict[str, Any]:
        assert reply.status_code == status, reply.body
        return json.loads(reply.body)

    def strip(self, credential: str, event_id: str, timestamp_ms: int, key: str, *, sensor: int = 17,
              track_id: str = "1") -> Any:
        body = {"event_id": event_id, "track_id": track_id, "timestamp_ms": timestamp_ms, "sensor": sensor,
                "idempotency_key": key}
        return self.client.http.post("/api/timing/strip-events", body=json.dumps(body).encode(), headers={
            "Authorization": f"Device {credential}", "Content-Type": "application/json", "Accept": "application/json"})

    def board(self, event_id: str, track: str = "1") -> dict[str, Any]:
        return self.ok(self.anonymous_get(f"/api/leaderboard/{event_id}?track={track}"))

