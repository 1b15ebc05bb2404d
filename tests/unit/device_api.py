"""The driver of the events, fleets and devices API tests (their fixture, `api`, is in conftest.py): JSON calls as
signed-in staff of every role or as a device, and the common set-ups (a fleet, an activation code, a device).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from chalice.test import Client

from tests.unit.conftest import Users, bearer

JSON = {"Content-Type": "application/json", "Accept": "application/json"}


@dataclass
class Api:
    client: Client
    users: Users
    tokens: dict[str, str] = field(default_factory=dict)

    def token(self, role: str) -> str:
        if role not in self.tokens:
            groups = () if role == "nobody" else (role,)
            self.tokens[role] = self.users.access_token(f"{role}-user", groups)
        return self.tokens[role]

    def call(self, method: str, path: str, *, as_: str | None = "operator", device: str | None = None,
             body: Any = None) -> Any:
        headers = dict(JSON)
        if device is not None:
            headers["Authorization"] = f"Device {device}"
        elif as_ is not None:
            headers.update(bearer(self.token(as_)))
        payload = b"" if body is None else json.dumps(body).encode()
        response = getattr(self.client.http, method.lower())(path, headers=headers, body=payload)
        response.data = json.loads(response.body) if response.body else None
        return response

    def get(self, path: str, **kw: Any) -> Any:
        return self.call("GET", path, **kw)

    def post(self, path: str, body: Any = None, **kw: Any) -> Any:
        return self.call("POST", path, body=body if body is not None else {}, **kw)

    def put(self, path: str, body: Any, **kw: Any) -> Any:
        return self.call("PUT", path, body=body, **kw)

    def delete(self, path: str, **kw: Any) -> Any:
        return self.call("DELETE", path, **kw)

    # --- common set-ups ---
    def fleet(self, name: str = "Track 1 cars", device_ids: list[str] | None = None) -> str:
        body: dict[str, Any] = {"name": name}
        if device_ids is not None:
            body["device_ids"] = device_ids
        reply = self.post("/api/fleets", body)
        assert reply.status_code == 201, reply.data
        return reply.data["fleet_id"]

    def activation_code(self, fleet_id: str, hostname: str, kind: str = "car", **extra: Any) -> str:
        reply = self.post("/api/devices/activation-codes",
                          {"fleet_id": fleet_id, "hostname": hostname, "device_kind": kind, **extra})
        assert reply.status_code == 201, reply.data
        return reply.data["code"]

    def activate(self, fleet_id: str, hostname: str, kind: str = "car") -> dict[str, Any]:
        code = self.activation_code(fleet_id, hostname, kind)
        reply = self.post("/api/devices/activate", {"code": code, "hostname": hostname, "device_kind": kind},
                          as_=None)
        assert reply.status_code == 201, reply.data
        return reply.data

