"""THE authorization matrix: for every route, who may call it — one entry per (METHOD, path) of the app.

Outcomes per principal: "allow" (answer is not 401/403), "deny" (401 or 403), "deny404" (401, 403 or 404: the route
hides other people's objects). A route added to the app without an entry here fails test_authz_matrix, and so does
an entry for a route that no longer exists.

`build(world, caller)` prepares what one call needs (objects owned by someone, path parameters, a body). It runs for
every allowed call, so each principal that may act meets a fresh object; the principals a route refuses share one
object built for them (a refused call changes nothing; see test_authz_matrix.scenario_for). `consumes_caller` runs an
allowed call as a freshly minted principal of the same kind (the call deletes the account or rotates the secret it
is made with).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from tests.unit.authz_principals import PRINCIPALS, World

USERS = ("racer_a", "racer_b", "registration", "commentator", "operator", "admin")
RACERS = ("racer_a", "racer_b")
CARS = ("car_x", "car_y")
DEVICE_PRINCIPALS = (*CARS, "timer")
STAFF = ("registration", "commentator", "operator", "admin")
EVERYONE = PRINCIPALS


def allow(*who: str, deny404: tuple[str, ...] = ()) -> dict[str, str]:
    unknown = (set(who) | set(deny404)) - set(PRINCIPALS)
    assert not unknown, f"unknown principals {unknown}"
    # The admin signed in with a browser session (cookies + CSRF token) may do exactly what the Bearer admin may.
    who = (*who, "admin_cookie") if "admin" in who else who
    deny404 = (*deny404, "admin_cookie") if "admin" in deny404 else deny404
    return {p: "allow" if p in who else "deny404" if p in deny404 else "deny" for p in PRINCIPALS}


@dataclass(frozen=True)
class Call:
    params: dict[str, str] = field(default_factory=dict)
    body: Any = None
    headers: dict[str, str] = field(default_factory=dict)
    raw: bytes | None = None  # a body that is not JSON (an image), sent with `headers`' Content-Type


@dataclass(frozen=True)
class Case:
    expect: dict[str, str]
    build: Callable[[World, str], Call] | None = None
    consumes_caller: bool = False
    # The refused callers may not share one scenario: building the next one ends it (a racer drives one live drive).
    fresh_for_each_caller: bool = False
    content_type: str = "application/json"  # what the route takes (others are refused with 415 before anything)


# --- scenarios ------------------------------------------------------------------------------------------------------

def racer_a_model(world: World, caller: str) -> Call:
    """A model owned by racer A (racer B, and staff without model rights, must not reach it). Uploaded and judged,
    so racer A never holds more open upload tickets than a racer may (MAX_PENDING_UPLOADS)."""
    import requests

    ticket = world.ok("POST", "/api/models", "racer_a", {"filename": "matrix-model.tar.gz"})
    upload, model_id = ticket["upload"], ticket["model"]["model_id"]
    posted = requests.post(upload["url"], data=upload["fields"], files={"file": ("m.tar.gz", b"not a model")},
                           timeout=10)
    assert posted.status_code in (200, 204), posted.text
    world.ok("POST", f"/api/models/{model_id}/complete", "racer_a")
    return Call({"model_id": model_id})


def racer_a_model_evaluation(world: World, caller: str) -> Call:
    """An evaluation (a `drem sim eval` metrics.json) posted for racer A's model."""
    body = {"track": "reinvent_base", "attempts": 3, "laps_completed": 3, "completion_pct": 100.0,
            "offtrack_count": 0, "lap_times_s": [11.2, 11.0, 11.4]}
    return Call(racer_a_model(world, caller).params, body)


def racer_a_run(world: World, caller: str) -> Call:
    """A run of racer A on the booth's oval (created, not yet driven): racer B must not reach it. One open run is
    reused (a racer may hold only a few open runs at a time)."""
    runs = world.ok("GET", "/api/runs", "racer_a")["runs"]
    open_runs = [r for r in runs if r["status"] == "RECORDING"]
    run = open_runs[0] if open_runs else world.ok("POST", "/api/runs", "racer_a",
                                                  {"track_id": "drem_oval", "mode": "manual"})["run"]
    return Call({"run_id": run["run_id"], "name": "controls.jsonl"})


def racer_a_live_drive(world: World, caller: str) -> Call:
    """Racer A driving the oval live: only racer A steers (or finishes) it; staff see the run but never drive it."""
    started = world.ok("POST", "/api/drive", "racer_a", {"track_id": "drem_oval"})
    return Call({"run_id": started["run_id"]}, {"steering": 0.0, "throttle": 0.5})


def racer_a_training_job(world: World, caller: str) -> Call:
    """A training job of racer A, queued on one short drive of theirs (a racer has one job in the queue at a time, so
    a job already waiting is reused)."""
    waiting = [j for j in world.ok("GET", "/api/training-jobs", "racer_a")["jobs"] if j["status"] == "QUEUED"]
    if waiting:
        return Call({"job_id": waiting[0]["job_id"]})
    started = world.ok("POST", "/api/drive", "racer_a", {"track_id": "drem_oval"})
    world.ok("POST", f"/api/runs/{started['run_id']}/drive", "racer_a", {"throttle": 0.5})
    world.ok("POST", f"/api/runs/{started['run_id']}/drive/finish", "racer_a")
    job = world.ok("POST", "/api/training-jobs", "racer_a", {"run_ids": [started["run_id"]]})
    return Call({"job_id": job["job"]["job_id"]})


def car_x_command(world: World, caller: str) -> Call:
    """A command queued for car X: only car X may acknowledge it (car Y simply does not find it)."""
    command = world.ok("POST", f"/api/devices/{world.device_ids['car_x']}/commands", "admin",
                       {"type": "RESTART_SERVICE"})
    return Call({"command_id": command["command_id"]}, {"result": "ok"})


def car_x_device(world: World, caller: str) -> Call:
    return Call({"device_id": world.device_ids["car_x"]})


def car_x_video(world: World, caller: str) -> Call:
    return Call({"device_id": world.device_ids["car_x"]},
                body={"fps": 15, "width": 480, "height": 360, "view": "camera"})


def disposable_car(world: World, caller: str) -> Call:
    return Call({"device_id": world.device_ids[world.mint("car_x")]})


def disposable_racer(world: World, caller: str) -> Call:
    return Call({"username": world.usernames[world.mint("racer_a")]})


def racer_a_username(world: World, caller: str) -> Call:
    return Call({"username": world.usernames["racer_a"]})


def matrix_fleet(world: World, caller: str) -> Call:
    return Call({"fleet_id": world.fleet_id})


def fleet_video(world: World, caller: str) -> Call:
    return Call({"fleet_id": world.fleet_id}, body={"fps": 15, "width": 480, "height": 360, "view": "camera"})


def matrix_event(world: World, caller: str) -> dict:
    """An event whose one track races with the matrix fleet (car X and car Y are in it)."""
    body = {"name": "Matrix event", "event_type": "TEST_EVENT", "date": "2026-05-14", "country_code": "SE",
            "race_config": {}, "tracks": [{"track_id": "1", "fleet_id": world.fleet_id}]}
    return world.ok("POST", "/api/events", "admin", body)


def event_only(world: World, caller: str) -> Call:
    return Call({"event_id": matrix_event(world, caller)["event_id"], "track_id": "1"})


def event_logo_upload(world: World, caller: str) -> Call:
    """An event and a real PNG for its logo: staff's upload is taken, everyone else is refused before it is read."""
    import io

    from PIL import Image

    png = io.BytesIO()
    Image.new("RGB", (120, 40), (255, 153, 0)).save(png, format="PNG")
    return Call(event_only(world, caller).params, headers={"Content-Type": "image/png"}, raw=png.getvalue())


def racer_a_race(world: World, caller: str) -> Call:
    """A race of racer A with one lap: racer B must not read it; staff who run races may."""
    event_id = matrix_event(world, caller)["event_id"]
    race = world.ok("POST", f"/api/events/{event_id}/races", "operator",
                    {"track_id": "1", "racer_username": world.usernames["racer_a"]})
    commands = f"/api/events/{event_id}/races/{race['race_id']}/commands"
    for kind in ("start", "capture_lap"):
        world.ok("POST", commands, "operator", {"kind": kind})
    return Call({"event_id": event_id, "race_id": race["race_id"], "track_id": "1", "lap_id": "0"},
                {"time_ms": 12345, "resets": 0, "is_valid": True})


def event_summary_pdf(world: World, caller: str) -> Call:
    """The printed race summary of an event (a PDF for the race staff)."""
    return Call({"event_id": matrix_event(world, caller)["event_id"], "file_name": "summary.pdf"})


def racer_card_form(world: World, caller: str) -> Call:
    """The registration desk prints the card of the racer it has just created."""
    return Call(body={"username": "new_racer", "temporary_password": "Tmp-Pass-123"})


PUBLIC = Case(allow(*EVERYONE))
SIGNED_IN = Case(allow(*USERS))
ADMIN_ONLY = Case(allow("admin"))
ADMIN_OPERATOR = Case(allow("admin", "operator"))
ALL_STAFF = Case(allow(*STAFF))
DEVICES = Case(allow(*DEVICE_PRINCIPALS))

TABLE: dict[tuple[str, str], Case] = {
    # pages, static files, sign-in forms: public (they carry their own CSRF protection)
    ("GET", "/"): PUBLIC,
    ("GET", "/static/{name}"): Case(allow(*EVERYONE), lambda w, c: Call({"name": "drem.css"})),
    ("GET", "/static/vendor/{name}"): Case(allow(*EVERYONE), lambda w, c: Call({"name": "htmx.min.js"})),
    ("GET", "/favicon.ico"): Case(allow(*EVERYONE)),
    ("GET", "/static/vendor/flags/{name}"): Case(allow(*EVERYONE), lambda w, c: Call({"name": "se.svg"})),
    ("GET", "/_drem/not-found"): Case(allow(*EVERYONE)),
    ("GET", "/api/_drem/not-found"): Case(allow(*EVERYONE)),
    ("GET", "/login"): PUBLIC,
    ("POST", "/login"): PUBLIC,
    ("GET", "/login/new-password"): PUBLIC,
    ("POST", "/login/new-password"): PUBLIC,
    ("POST", "/logout"): Case(allow(*EVERYONE), consumes_caller=True),  # a real sign-out ends its caller
    # JSON sign-in for API clients: public, CSRF-exempt (the password / refresh token in the body is the credential)
    ("POST", "/api/auth/token"): PUBLIC,
    ("POST", "/api/auth/refresh"): PUBLIC,
    ("GET", "/healthz"): PUBLIC,
    ("GET", "/api/ping"): PUBLIC,
    ("GET", "/api/openapi.json"): PUBLIC,
    ("GET", "/api/docs"): PUBLIC,
    # accounts and users
    ("GET", "/api/me"): SIGNED_IN,
    ("DELETE", "/api/me"): Case(allow(*USERS), consumes_caller=True),
    ("GET", "/api/users/{username}/groups"): Case(allow("admin"), racer_a_username),
    ("POST", "/api/signup"): PUBLIC,
    ("POST", "/api/signup/confirm"): PUBLIC,
    ("POST", "/api/users"): Case(allow("admin", "registration")),
    ("GET", "/api/users"): Case(allow("admin", "operator", "registration")),
    ("PUT", "/api/users/{username}/role"): Case(allow("admin"), disposable_racer),
    ("POST", "/api/users/{username}/disable"): Case(allow("admin"), disposable_racer),
    ("POST", "/api/users/{username}/enable"): Case(allow("admin"), disposable_racer),
    ("POST", "/api/users/{username}/confirm"): Case(allow("admin"), disposable_racer),
    # profiles
    ("GET", "/api/me/profile"): SIGNED_IN,
    ("PUT", "/api/me/profile"): SIGNED_IN,
    ("PUT", "/api/users/{username}/profile"): Case(allow("admin"), racer_a_username),
    ("GET", "/api/profiles/{username}"): Case(allow(*EVERYONE), racer_a_username),
    ("GET", "/api/profiles/{username}/avatar.svg"): Case(allow(*EVERYONE), racer_a_username),
    # events
    ("GET", "/api/events"): ALL_STAFF,
    ("POST", "/api/events"): ADMIN_OPERATOR,
    ("GET", "/api/events/{event_id}"): ALL_STAFF,
    ("PUT", "/api/events/{event_id}"): ADMIN_OPERATOR,
    ("DELETE", "/api/events/{event_id}"): ADMIN_OPERATOR,
    # fleets
    ("GET", "/api/fleets"): ADMIN_OPERATOR,
    ("POST", "/api/fleets"): ADMIN_OPERATOR,
    ("GET", "/api/fleets/{fleet_id}"): Case(allow("admin", "operator"), matrix_fleet),
    ("PUT", "/api/fleets/{fleet_id}"): ADMIN_OPERATOR,
    ("DELETE", "/api/fleets/{fleet_id}"): ADMIN_OPERATOR,
    ("PUT", "/api/fleets/{fleet_id}/video"): Case(allow("admin", "operator"), fleet_video),
    # devices: staff side
    ("POST", "/api/devices/activation-codes"): ADMIN_OPERATOR,
    ("GET", "/api/devices"): ADMIN_OPERATOR,
    ("GET", "/api/devices/{device_id}"): Case(allow("admin", "operator"), car_x_device),
    ("PUT", "/api/devices/{device_id}/fleet"): ADMIN_OPERATOR,
    ("DELETE", "/api/devices/{device_id}"): Case(allow("admin"), disposable_car),
    ("PUT", "/api/devices/{device_id}/video"): Case(allow("admin", "operator"), car_x_video),
    ("POST", "/api/devices/{device_id}/commands"): Case(allow("admin", "operator"), car_x_device),
    ("GET", "/api/devices/{device_id}/commands"): Case(allow("admin", "operator"), car_x_device),
    # devices: the device itself (acts on its own id only)
    ("POST", "/api/devices/activate"): PUBLIC,
    ("GET", "/api/devices/self"): DEVICES,
    ("POST", "/api/devices/self/rotate"): Case(allow(*DEVICE_PRINCIPALS), consumes_caller=True),
    ("POST", "/api/devices/self/heartbeat"): DEVICES,
    ("GET", "/api/devices/self/commands"): DEVICES,
    ("POST", "/api/devices/self/commands/{command_id}/ack"): Case(allow("car_x", deny404=("car_y", "timer")),
                                                                  car_x_command),
    # models: racer A's model — racer B is refused, model staff (admin, operator) may act for racers
    ("POST", "/api/models"): SIGNED_IN,
    ("GET", "/api/models"): SIGNED_IN,
    ("GET", "/api/models/{model_id}"): Case(allow("racer_a", "operator", "admin"), racer_a_model),
    ("DELETE", "/api/models/{model_id}"): Case(allow("racer_a", "operator", "admin"), racer_a_model),
    ("POST", "/api/models/{model_id}/complete"): Case(allow("racer_a", "operator", "admin"), racer_a_model),
    ("POST", "/api/models/{model_id}/scrutineer"): Case(allow("racer_a", "operator", "admin"), racer_a_model),
    ("GET", "/api/models/{model_id}/scrutineer/clip.gif"): Case(allow("racer_a", "operator", "admin"),
                                                                racer_a_model),
    # model assignments to cars
    ("PUT", "/api/cars/{device_id}/models"): Case(allow("admin", "operator"), car_x_device),
    ("GET", "/api/cars/{device_id}/models"): Case(allow(*STAFF), car_x_device),
    ("GET", "/api/devices/self/assignment"): Case(allow("car_x", "car_y")),
    ("POST", "/api/devices/self/assignment/status"): Case(allow("car_x", "car_y")),
    ("GET", "/api/events/{event_id}/model-status"): ALL_STAFF,
    # races and timing
    ("POST", "/api/events/{event_id}/races"): ADMIN_OPERATOR,
    ("GET", "/api/events/{event_id}/races"): Case(allow("admin", "operator", "commentator")),
    ("GET", "/api/events/{event_id}/races/{race_id}"): Case(
        allow("racer_a", "commentator", "operator", "admin"), racer_a_race),
    ("GET", "/api/me/races"): SIGNED_IN,
    ("POST", "/api/events/{event_id}/races/{race_id}/commands"): ADMIN_OPERATOR,
    ("PUT", "/api/events/{event_id}/races/{race_id}/laps/{lap_id}"): ADMIN_OPERATOR,
    ("DELETE", "/api/events/{event_id}/races/{race_id}"): ADMIN_OPERATOR,
    ("POST", "/api/events/{event_id}/recompute"): ADMIN_OPERATOR,
    ("GET", "/api/events/{event_id}/export/{file_name}"): ADMIN_OPERATOR,
    ("GET", "/api/events/{event_id}/results/{file_name}"): Case(allow("admin", "operator"), event_summary_pdf),
    ("POST", "/api/timing/strip-events"): DEVICES,
    # public polls
    ("GET", "/api/leaderboard/{event_id}"): PUBLIC,
    ("GET", "/api/overlay/{event_id}"): PUBLIC,
    # public pages (the big screen, the stream overlay) and the commentator's view
    ("GET", "/leaderboard/{event_id}"): Case(allow(*EVERYONE), event_only),
    ("GET", "/leaderboard/{event_id}/live"): Case(allow(*EVERYONE), event_only),
    ("GET", "/overlay/{event_id}"): Case(allow(*EVERYONE), event_only),
    ("GET", "/overlay/{event_id}/live"): Case(allow(*EVERYONE), event_only),
    ("GET", "/commentator/{event_id}"): Case(allow("commentator", "operator", "admin"), event_only),
    ("GET", "/commentator/{event_id}/live"): Case(allow("commentator", "operator", "admin"), event_only),
    # console: sign-up and the racer's own pages
    ("GET", "/signup"): PUBLIC,
    ("POST", "/signup"): PUBLIC,
    ("GET", "/signup/confirm"): PUBLIC,
    ("POST", "/signup/confirm"): PUBLIC,
    ("GET", "/console/password"): SIGNED_IN,
    ("POST", "/console/password"): SIGNED_IN,
    ("GET", "/console/profile"): SIGNED_IN,
    ("POST", "/console/profile"): SIGNED_IN,
    ("GET", "/console/my-models"): SIGNED_IN,
    ("GET", "/console/my-models/rows"): SIGNED_IN,
    ("GET", "/console/my-models/{model_id}/row"): Case(allow("racer_a"), racer_a_model),
    ("POST", "/console/my-models/{model_id}/delete"): Case(allow("racer_a"), racer_a_model),
    ("GET", "/console/my-races"): SIGNED_IN,
    ("GET", "/console/my-races/{event_id}/{race_id}"): Case(allow("racer_a", deny404=STAFF + ("racer_b",)),
                                                          racer_a_race),
    # console: registration desk and user admin
    ("GET", "/console/registration"): Case(allow("admin", "registration")),
    ("POST", "/console/registration"): Case(allow("admin", "registration")),
    ("GET", "/console/users"): ADMIN_ONLY,
    ("GET", "/console/users/rows"): ADMIN_ONLY,
    ("POST", "/console/users/{username}/role"): Case(allow("admin"), disposable_racer),
    ("POST", "/console/users/{username}/disable"): Case(allow("admin"), disposable_racer),
    ("POST", "/console/users/{username}/enable"): Case(allow("admin"), disposable_racer),
    ("POST", "/console/users/{username}/confirm"): Case(allow("admin"), disposable_racer),
    # console: operators' screens
    ("GET", "/console/models"): ADMIN_OPERATOR,
    ("GET", "/console/models/rows"): ADMIN_OPERATOR,
    ("POST", "/console/models/assign"): ADMIN_OPERATOR,
    ("POST", "/console/models/{model_id}/check"): Case(allow("admin", "operator"), racer_a_model),
    ("POST", "/console/models/{model_id}/scrutineer"): Case(allow("racer_a", "operator", "admin"), racer_a_model),
    ("GET", "/console/models/{model_id}/scrutiny"): Case(allow("racer_a", "operator", "admin"), racer_a_model),
    ("GET", "/console/models/car-status"): Case(allow("admin", "operator"),
                                                lambda w, c: Call({}, None)),
    ("GET", "/console/events"): ADMIN_OPERATOR,
    ("POST", "/console/events"): ADMIN_OPERATOR,
    ("GET", "/console/events/new"): ADMIN_OPERATOR,
    ("GET", "/console/events/{event_id}/overlay"): Case(allow("admin", "operator"), event_only),
    ("POST", "/console/events/{event_id}"): Case(allow("admin", "operator"), event_only),
    ("GET", "/console/events/{event_id}/edit"): Case(allow("admin", "operator"), event_only),
    ("GET", "/console/events/{event_id}/delete"): Case(allow("admin", "operator"), event_only),
    ("POST", "/console/events/{event_id}/delete"): Case(allow("admin", "operator"), event_only),
    ("POST", "/console/events/{event_id}/logo"): Case(allow("admin", "operator"), event_only),
    ("POST", "/console/events/{event_id}/logo/remove"): Case(allow("admin", "operator"), event_only),
    ("GET", "/console/fleets"): ADMIN_OPERATOR,
    ("POST", "/console/fleets"): ADMIN_OPERATOR,
    ("POST", "/console/fleets/{fleet_id}/video"): Case(allow("admin", "operator"), fleet_video),
    ("GET", "/console/cars"): ADMIN_OPERATOR,
    ("GET", "/console/cars/live"): ADMIN_OPERATOR,
    ("GET", "/console/cars/activate"): ADMIN_OPERATOR,
    ("POST", "/console/cars/activate"): ADMIN_OPERATOR,
    ("POST", "/console/cars/{device_id}/commands"): Case(allow("admin", "operator"), car_x_device),
    ("POST", "/console/cars/{device_id}/fleet"): Case(allow("admin", "operator"), car_x_device),
    ("POST", "/console/cars/{device_id}/models"): Case(allow("admin", "operator"), car_x_device),
    ("POST", "/console/cars/{device_id}/deregister"): Case(allow("admin"), disposable_car),
    ("POST", "/console/cars/{device_id}/video"): Case(allow("admin", "operator"), car_x_video),
    ("GET", "/console/timekeeper"): ADMIN_OPERATOR,
    ("GET", "/console/timekeeper/racers"): ADMIN_OPERATOR,
    ("GET", "/console/timekeeper/{event_id}/{track_id}"): Case(allow("admin", "operator"), event_only),
    ("GET", "/console/timekeeper/{event_id}/{track_id}/state"): Case(allow("admin", "operator"), event_only),
    ("POST", "/console/timekeeper/{event_id}/{track_id}/races"): Case(allow("admin", "operator"), event_only),
    ("POST", "/console/timekeeper/{event_id}/{track_id}/commands"): Case(allow("admin", "operator"), event_only),
    ("GET", "/console/timekeeper/{event_id}/{track_id}/queue"): Case(allow("admin", "operator"), event_only),
    ("POST", "/console/timekeeper/{event_id}/{track_id}/queue"): Case(allow("admin", "operator"), event_only),
    ("POST", "/console/timekeeper/{event_id}/{track_id}/queue/move"): Case(allow("admin", "operator"), event_only),
    ("POST", "/console/timekeeper/{event_id}/{track_id}/queue/remove"): Case(allow("admin", "operator"), event_only),
    ("POST", "/console/timekeeper/{event_id}/{track_id}/queue/start"): Case(allow("admin", "operator"), event_only),
    ("GET", "/console/races"): ADMIN_OPERATOR,
    ("GET", "/stats"): PUBLIC,
    ("GET", "/event/{event_id}"): Case(allow(*EVERYONE), event_only),
    ("GET", "/event/{event_id}/logo"): Case(allow(*EVERYONE), event_only),
    ("PUT", "/api/events/{event_id}/logo"): Case(allow("admin", "operator"), event_logo_upload,
                                                 content_type="image/png"),
    ("DELETE", "/api/events/{event_id}/logo"): Case(allow("admin", "operator"), event_only),
    ("GET", "/console/cars/labels.pdf"): Case(allow("admin", "operator")),
    ("POST", "/console/registration/card.pdf"): Case(allow("admin", "registration"), racer_card_form),
    ("GET", "/console/races/{event_id}/{race_id}"): Case(allow("admin", "operator"), racer_a_race),
    ("GET", "/console/races/{event_id}/{race_id}/delete"): Case(allow("admin", "operator"), racer_a_race),
    ("POST", "/console/races/{event_id}/{race_id}/delete"): Case(allow("admin", "operator"), racer_a_race),
    ("POST", "/console/races/{event_id}/{race_id}/laps/{lap_id}"): Case(allow("admin", "operator"), racer_a_race),
    # the virtual league (anyone reads; racers push their own; admins delete) and the model registry
    ("POST", "/api/league/{track}/submissions"): SIGNED_IN,
    ("GET", "/api/league/{track}"): PUBLIC,
    ("GET", "/api/league/{track}/racers/{racer}"): PUBLIC,
    ("PUT", "/api/league/{track}/policy"): ADMIN_ONLY,
    ("PUT", "/api/league-tracks/{track}"): ADMIN_ONLY,
    ("DELETE", "/api/league/{track}/racers/{racer}"): ADMIN_ONLY,
    ("GET", "/league/{track}"): PUBLIC,
    ("GET", "/league/{track}/racers/{racer}"): PUBLIC,
    ("GET", "/console/models/registry"): ADMIN_OPERATOR,
    ("GET", "/models/registry"): SIGNED_IN,
    ("GET", "/models/registry/{model_id}"): Case(allow("racer_a", "operator", "admin"), racer_a_model),
    ("POST", "/api/models/{model_id}/evaluations"): Case(allow("racer_a", "operator", "admin"),
                                                          racer_a_model_evaluation),
    ("GET", "/api/models/{model_id}/evaluations"): Case(allow("racer_a", "operator", "admin"), racer_a_model),
    # the learning booth: tracks are public; a racer drives, uploads and trains on their own runs only; admins and
    # operators see every racer's runs and jobs (a live drive is steered by its driver alone)
    ("GET", "/api/tracks"): PUBLIC,
    ("GET", "/api/tracks/{track_id}"): PUBLIC,
    ("POST", "/api/runs"): SIGNED_IN,
    ("GET", "/api/runs"): SIGNED_IN,
    ("GET", "/api/metrics/runs"): SIGNED_IN,
    ("GET", "/api/runs/{run_id}"): Case(allow("racer_a", "operator", "admin"), racer_a_run),
    ("PUT", "/api/runs/{run_id}/artifacts/{name}"): Case(allow("racer_a", "operator", "admin"), racer_a_run),
    ("GET", "/api/runs/{run_id}/artifacts/{name}"): Case(allow("racer_a", "operator", "admin"), racer_a_run),
    ("POST", "/api/runs/{run_id}/finalise"): Case(allow("racer_a", "operator", "admin"), racer_a_run),
    ("POST", "/api/drive"): SIGNED_IN,
    ("POST", "/api/runs/{run_id}/drive"): Case(allow("racer_a"), racer_a_live_drive, fresh_for_each_caller=True),
    ("POST", "/api/runs/{run_id}/drive/finish"): Case(allow("racer_a"), racer_a_live_drive,
                                                      fresh_for_each_caller=True),
    ("POST", "/api/training-jobs"): SIGNED_IN,
    ("GET", "/api/training-jobs"): SIGNED_IN,
    ("GET", "/api/training-jobs/{job_id}"): Case(allow("racer_a", "operator", "admin"), racer_a_training_job),
    ("POST", "/api/models/{model_id}/active"): Case(allow("racer_a", "operator", "admin"), racer_a_model),
    ("GET", "/booth"): SIGNED_IN,
    ("GET", "/booth/jobs"): SIGNED_IN,
    ("POST", "/booth/train"): SIGNED_IN,
    ("GET", "/booth/train-action"): SIGNED_IN,
    ("GET", "/booth/drive/{track_id}"): SIGNED_IN,
    ("GET", "/booth/runs/{run_id}"): Case(allow("racer_a", "operator", "admin"), racer_a_run),
    ("POST", "/booth/versions/{model_id}/active"): Case(allow("racer_a", "operator", "admin"), racer_a_model),
}
