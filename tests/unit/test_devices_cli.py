"""`drem events|fleets|cars` against the real API in-process: the CLI's HTTP client is pointed at the Chalice test
client (the only substitution), so every command goes through routing, auth, validation and moto storage."""
from __future__ import annotations

import argparse
import json
from typing import Any
from urllib.parse import urlencode

import pytest

from drem_local.api_client import ApiClient, ApiError
from tests.unit.device_api import Api

pytestmark = pytest.mark.unit


@pytest.fixture
def cli(api: Api, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> Any:
    def through_test_client(self: ApiClient, method: str, path: str, *, json: Any = None,
                            params: dict[str, Any] | None = None) -> Any:
        if params:
            path = f"{path}?{urlencode(params)}"
        reply = _with_token(api, self.token or "", method, path, json)
        if reply.status_code >= 400:
            error = reply.data["error"]
            raise ApiError(reply.status_code, error["message"], error["field"])
        return reply.data

    monkeypatch.setattr(ApiClient, "request", through_test_client)
    token = api.token("operator")

    def run(module: Any, *argv: str) -> tuple[int, str, str]:
        parser = argparse.ArgumentParser()
        module.add_arguments(parser)
        code = module.run(parser.parse_args(["--token", token, *argv]))
        captured = capsys.readouterr()
        return code, captured.out, captured.err

    return run


def _with_token(api: Api, token: str, method: str, path: str, body: Any) -> Any:
    headers = {"Content-Type": "application/json", "Accept": "application/json", "Authorization": f"Bearer {token}"}
    reply = getattr(api.client.http, method.lower())(path, headers=headers,
                                                     body=b"" if body is None else json.dumps(body).encode())
    reply.data = json.loads(reply.body) if reply.body else None
    return reply


def test_fleet_event_and_car_commands_end_to_end(cli: Any, api: Api) -> None:
    from drem_local.commands import cars, events, fleets

    code, out, _ = cli(fleets, "--json", "create", "North")
    assert code == 0
    fleet_id = json.loads(out)["fleet_id"]
    assert "North" in cli(fleets, "list")[1]

    code, out, _ = cli(events, "--json", "create", "Summit", "--type", "AWS_SUMMIT", "--date", "2026-05-14",
                       "--country", "SE", "--race-time", "4", "--track", f"North@{fleet_id}", "--track", "South")
    assert code == 0, out
    event = json.loads(out)
    assert event["combined_board"] is True and event["race_config"]["race_time_min"] == 4
    shown = cli(events, "show", event["event_id"])[1]
    assert "4 min" in shown and "combined leaderboard" in shown and f"fleet {fleet_id}" in shown
    # People read words, not enum values.
    assert "AWS Summit" in shown and "ranking: fastest lap" in shown and "AWS_SUMMIT" not in shown
    listed = cli(events, "list")[1]
    assert event["event_id"] in listed and "AWS Summit" in listed and "AWS_SUMMIT" not in listed

    code, _, err = cli(events, "create", "Bad", "--date", "2026-05-14", "--country", "SE", "--race-time", "11")
    assert code == 1 and "race_config.race_time_min" in err

    code, out, _ = cli(cars, "--json", "activate-code", "car-07", "--fleet", fleet_id)
    assert code == 0
    device = api.post("/api/devices/activate", {"code": json.loads(out)["code"], "hostname": "car-07",
                                                "device_kind": "car"}, as_=None).data
    api.post("/api/devices/self/heartbeat", {"battery_pct": 77}, device=device["credential"])
    listed = cli(cars, "list", "--online")[1]
    assert "car-07" in listed and "ONLINE" in listed and "battery 77%" in listed

    code, out, _ = cli(cars, "command", device["device_id"], "set_tail_light", "--colour", "#00ff00")
    assert code == 0 and "SET_TAIL_LIGHT" in out
    assert api.get("/api/devices/self/commands", device=device["credential"]).data["commands"][0]["parameters"] == {
        "colour": "#00FF00"}

    code, _, err = cli(cars, "deregister", device["device_id"])
    assert code == 1 and "admin" in err  # operators may not deregister
    assert cli(events, "delete", event["event_id"])[0] == 0
    assert cli(fleets, "delete", fleet_id)[0] == 0
    assert cli(fleets, "list")[1].strip() == "No fleets yet."
