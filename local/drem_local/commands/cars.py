"""`drem cars`: list devices, issue activation codes, send commands and deregister, through the drem HTTP API."""
from __future__ import annotations

import argparse
import json
import sys
from datetime import UTC, datetime
from typing import Any
from urllib.parse import quote

HELP = "list cars and timers, make activation codes, send commands, deregister (via the drem API)"
COMMANDS = ("RESTART_SERVICE", "START_CAR", "EMERGENCY_STOP", "SET_TAIL_LIGHT", "DELETE_ALL_MODELS",
            "SET_THROTTLE_CAP")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from drem_local.api_client import add_connection_arguments

    add_connection_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print the API's JSON answer")
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    listing = actions.add_parser("list", help="devices with status, fleet and last seen")
    listing.add_argument("--online", action="store_true", help="only devices seen in the last 15 s")
    listing.add_argument("--fleet", dest="fleet_id", help="only this fleet")
    code = actions.add_parser("activate-code", help="a one-time code a car or timer exchanges for its credential")
    code.add_argument("hostname")
    code.add_argument("--fleet", dest="fleet_id", required=True)
    code.add_argument("--kind", choices=("car", "timer"), default="car")
    code.add_argument("--ttl-minutes", type=int, default=60)
    command = actions.add_parser("command", help="queue a command for a device")
    command.add_argument("device_id")
    command.add_argument("type", choices=COMMANDS, type=str.upper)
    command.add_argument("--colour", help="SET_TAIL_LIGHT: palette name or #RRGGBB")
    command.add_argument("--throttle-cap", type=int, help="SET_THROTTLE_CAP: 0-100 %%")
    command.add_argument("--with-system-logs", action="store_true", help="DELETE_ALL_MODELS: clear logs too")
    deregister = actions.add_parser("deregister", help="remove a device; its credential stops working at once")
    deregister.add_argument("device_id")


def run(args: argparse.Namespace) -> int:
    from drem_local.api_client import ApiClient, ApiError

    try:
        answer = _perform(ApiClient.from_args(args), args)
    except ApiError as exc:
        print(f"drem cars {args.action}: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(answer, indent=2) if args.json else describe(args.action, answer))
    return 0


def _perform(api: Any, args: argparse.Namespace) -> Any:
    if args.action == "list":
        params = {k: v for k, v in (("online", "true" if args.online else None), ("fleet_id", args.fleet_id)) if v}
        return api.get("/api/devices", params=params)
    if args.action == "activate-code":
        return api.post("/api/devices/activation-codes", json={
            "fleet_id": args.fleet_id, "hostname": args.hostname, "device_kind": args.kind,
            "ttl_minutes": args.ttl_minutes})
    device = quote(args.device_id, safe="")
    if args.action == "command":
        body: dict[str, Any] = {"type": args.type}
        if args.colour is not None:
            body["colour"] = args.colour
        if args.throttle_cap is not None:
            body["throttle_cap_pct"] = args.throttle_cap
        if args.with_system_logs:
            body["with_system_logs"] = True
        return api.post(f"/api/devices/{device}/commands", json=body)
    api.delete(f"/api/devices/{device}")
    return {"deregistered": args.device_id}


def describe(action: str, answer: dict[str, Any]) -> str:
    if action == "list":
        if not answer["devices"]:
            return "No devices match."
        return "\n".join(_device_line(d) for d in answer["devices"])
    if action == "activate-code":
        return (f"Activation code for {answer['device_kind']} {answer['hostname']} (fleet {answer['fleet_id']}), "
                f"single use, valid until {_when(answer['expires_at_ms'])}:\n  {answer['code']}")
    if action == "command":
        return f"Queued {answer['type']} for {answer['device_id']} as command {answer['command_id']}."
    return f"Deregistered {answer['deregistered']}."


def _device_line(device: dict[str, Any]) -> str:
    telemetry = device.get("telemetry") or {}
    seen = "never seen" if device["last_seen_ms"] is None else f"seen {device['seconds_since_seen']} s ago"
    extras = [f"agent {telemetry['agent_version']}" if telemetry.get("agent_version") else "",
              f"battery {telemetry['battery_pct']:g}%" if telemetry.get("battery_pct") is not None else "",
              f"model {telemetry['model']['name']}" if telemetry.get("model") else ""]
    return (f"{device['device_id']:<18} {device['kind']:<6} {device['hostname']:<16} "
            f"{'ONLINE ' if device['online'] else 'offline'} fleet {device['fleet_id'] or '-':<14} {seen}"
            + "".join(f", {e}" for e in extras if e))


def _when(ms: int) -> str:
    return datetime.fromtimestamp(ms / 1000, tz=UTC).strftime("%Y-%m-%d %H:%M UTC")
