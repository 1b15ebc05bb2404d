"""Set-up for the console journeys through the same doors a real client uses: Cognito (the local stack's durable
moto) for accounts and tokens, the JSON API over HTTP for everything else, and a device's own activation call."""
from __future__ import annotations

import json
from typing import Any

import requests

PASSWORD = "Journey-Pass-9"


def cognito(live_stack: Any) -> Any:
    return live_stack.client("cognito-idp")


def create_user(live_stack: Any, username: str, group: str) -> str:
    client, pool = cognito(live_stack), live_stack.outputs.user_pool_id
    client.admin_create_user(UserPoolId=pool, Username=username, TemporaryPassword=PASSWORD, MessageAction="SUPPRESS",
                             UserAttributes=[{"Name": "email", "Value": f"{username}@example.test"}])
    client.admin_set_user_password(UserPoolId=pool, Username=username, Password=PASSWORD, Permanent=True)
    client.admin_add_user_to_group(UserPoolId=pool, Username=username, GroupName=group)
    return username


def access_token(live_stack: Any, username: str) -> str:
    reply = cognito(live_stack).initiate_auth(AuthFlow="USER_PASSWORD_AUTH",
                                              ClientId=live_stack.outputs.user_pool_client_id,
                                              AuthParameters={"USERNAME": username, "PASSWORD": PASSWORD})
    return reply["AuthenticationResult"]["AccessToken"]


def call(url: str, method: str, path: str, *, token: str | None = None, device: str | None = None,
         body: Any = None, expect: int | tuple[int, ...] = (200, 201)) -> Any:
    headers = {"Accept": "application/json", "Content-Type": "application/json"}
    if token:
        headers["Authorization"] = f"Bearer {token}"
    if device:
        headers["Authorization"] = f"Device {device}"
    reply = requests.request(method, url + path, headers=headers, timeout=15,
                             data=json.dumps(body).encode() if body is not None else None)
    expected = (expect,) if isinstance(expect, int) else expect
    assert reply.status_code in expected, f"{method} {path}: {reply.status_code} {reply.text}"
    return reply.json() if reply.content else None


def upload_model(url: str, token: str, filename: str, archive: bytes) -> dict:
    """A model archive uploaded as a racer's browser does (ticket, form POST to storage, complete): its record."""
    ticket = call(url, "POST", "/api/models", token=token, body={"filename": filename}, expect=201)
    posted = requests.post(ticket["upload"]["url"], data=ticket["upload"]["fields"],
                           files={"file": (filename, archive)}, timeout=30)
    assert posted.status_code in (200, 204), posted.text
    return call(url, "POST", f"/api/models/{ticket['model']['model_id']}/complete", token=token)["model"]


def sign_in(page: Any, url: str, username: str) -> None:
    page.goto(url + "/login")
    page.fill("#username", username)
    page.fill("#password", PASSWORD)
    page.get_by_role("button", name="Sign in").click()
    page.wait_for_url(url + "/")


def submitted_race(url: str, token: str, event_id: str, racer: str, laps_ms: list[int], track_id: str = "1") -> str:
    """A race run by hand on the timekeeper's commands (start, one capture per lap, end, submit), its laps then set to
    `laps_ms` by the staff's lap edit, as a timekeeper corrects hand-captured times. Returns the race id."""
    race_id: str = call(url, "POST", f"/api/events/{event_id}/races", token=token, expect=201,
                        body={"track_id": track_id, "racer_username": racer})["race_id"]
    path = f"/api/events/{event_id}/races/{race_id}"
    for kind in ("start", *["capture_lap"] * len(laps_ms), "end", "submit"):
        call(url, "POST", path + "/commands", token=token, body={"kind": kind})
    for lap_id, time_ms in enumerate(laps_ms):
        call(url, "PUT", f"{path}/laps/{lap_id}", token=token, body={"time_ms": time_ms, "is_valid": True})
    return race_id


def running_race(url: str, token: str, event_id: str, racer: str, track_id: str = "1") -> str:
    """A race started and left running (the "Now racing" bar). Returns the race id."""
    race_id: str = call(url, "POST", f"/api/events/{event_id}/races", token=token, expect=201,
                        body={"track_id": track_id, "racer_username": racer})["race_id"]
    call(url, "POST", f"/api/events/{event_id}/races/{race_id}/commands", token=token, body={"kind": "start"})
    return race_id
