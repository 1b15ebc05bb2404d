"""`drem export` / `drem import` between two real local stacks (durable moto + app server each).

The source is the session's `live_stack`; the target is a second, fresh stack started here. A realistic event is
built through the JSON API, exported, imported into the target, and exported again: the two exports must hold the
same content except `exported_at` and the subs Cognito assigned anew (compared through the import report's mapping).
"""
from __future__ import annotations

import argparse
import json
import re
import secrets
import stat
from pathlib import Path

import pytest
import requests

from chalicelib.formats.event_export.records import ITEM_FILES, MANIFEST
from chalicelib.formats.event_export.remap import remap_items
from chalicelib.storage.event_archive import StackLocation, connect
from drem_local import stack as local_stack
from drem_local.api_client import ApiClient
from drem_local.bootstrap import generate_password
from drem_local.storage_keys import load as load_keys
from drem_local.storage_keys import local_client
from tests.unit.models_helpers import onnx_archive

pytestmark = pytest.mark.integration


def _cli(module, argv: list[str]) -> int:
    parser = argparse.ArgumentParser()
    module.add_arguments(parser)
    return module.run(parser.parse_args(argv))


def _export(event_id: str, out: Path, state_dir: Path) -> int:
    from drem_local.commands import export

    return _cli(export, [event_id, "--out", str(out), "--state-dir", str(state_dir)])


def _import(folder: Path, state_dir: Path, *extra: str) -> int:
    from drem_local.commands import import_

    return _cli(import_, [str(folder), "--state-dir", str(state_dir), *extra])


def _cognito(storage_url: str, state_dir: Path):
    return local_client("cognito-idp", storage_url, load_keys(state_dir), local_stack.REGION)


@pytest.fixture(scope="module")
def target_stack(tmp_path_factory: pytest.TempPathFactory):
    state_dir = tmp_path_factory.mktemp("transfer-target") / "state"
    config = local_stack.StackConfig(state_dir=state_dir, app_port=local_stack.free_port(),
                                     storage_port=local_stack.free_port(), live_port=local_stack.free_port())
    try:
        running = local_stack.start_stack(config, "admin", generate_password(), timeout=60.0)
    except local_stack.StackError as exc:
        pytest.fail(f"the target stack did not start: {exc}")
    yield running
    running.stop()


@pytest.fixture(scope="module")
def source_event(live_stack) -> dict:
    """Two tracks, a fleet with a car, two racers with profiles, a validated model, submitted races incl. an
    invalid lap, and the materialised boards — all through the API."""
    admin = ApiClient(live_stack.url)
    admin.sign_in(live_stack.admin_username, live_stack.admin_password)
    suffix = secrets.token_hex(3)
    fleet_id = admin.post("/api/fleets", {"name": f"Transfer fleet {suffix}"})["fleet_id"]
    event = admin.post("/api/events", {
        "name": f"Transfer Cup {suffix}", "event_type": "OFFICIAL_TRACK_RACE", "date": "2026-06-01",
        "country_code": "SE", "race_config": {"resets_per_lap": 0, "min_lap_ms": 0, "debounce_ms": 0},
        "tracks": [{"track_id": "1", "fleet_id": fleet_id, "leaderboard_title": "Main"}, {"track_id": "2"}]})
    code = admin.post("/api/devices/activation-codes",
                      {"fleet_id": fleet_id, "hostname": f"car-{suffix}", "device_kind": "car"})["code"]
    activated = requests.post(f"{live_stack.url}/api/devices/activate", timeout=30,
                              json={"code": code, "hostname": f"car-{suffix}", "device_kind": "car"})
    assert activated.status_code in (200, 201), activated.text

    racers = {}
    cognito = _cognito(live_stack.storage_url, live_stack.state_dir)
    for name, colour, country, shown in (("ada", "#FF0000", "GB", "Zoë.Müller"), ("linus", "#0000FF", "FI", "김민준")):
        username = f"{name}{suffix}"
        admin.post("/api/users", {"username": username, "email": f"{username}@example.com", "country_code": country,
                                  "display_name": shown})
        admin.put(f"/api/users/{username}/profile", {"highlight_colour": colour})
        racers[name] = username

    ada = ApiClient(live_stack.url)
    ada.sign_in(racers["ada"], _set_password(cognito, live_stack.outputs.user_pool_id, racers["ada"]))
    ticket = ada.post("/api/models", {"filename": "transfer_model.tar.gz"})
    posted = requests.post(ticket["upload"]["url"], data=ticket["upload"]["fields"], timeout=30,
                           files={"file": ("transfer_model.tar.gz", onnx_archive(0.25))})
    assert posted.status_code in (200, 204), posted.text
    model = ada.post(f"/api/models/{ticket['model']['model_id']}/complete")["model"]
    assert model["status"] == "AVAILABLE"

    eid = event["event_id"]
    laps = []
    for racer, track, commands in ((racers["ada"], "1", ["start", "capture_lap", "reset_add", "capture_lap",
                                                         "capture_lap", "end", "submit"]),
                                   (racers["linus"], "2", ["start", "capture_lap", "capture_lap", "end", "submit"])):
        race = admin.post(f"/api/events/{eid}/races", {"track_id": track, "racer_username": racer,
                                                        "car": f"car-{suffix}"})
        for kind in commands:
            last = admin.post(f"/api/events/{eid}/races/{race['race_id']}/commands", {"kind": kind})
        assert last["status"] == "SUBMITTED"
        laps += last["laps"]
    assert any(not lap["is_valid"] for lap in laps), "the reset made one lap invalid"
    # A race admin correction: it goes into the audit trail, which travels with the races.
    admin.put(f"/api/events/{eid}/races/{race['race_id']}/laps/0", {"resets": 1})
    logo = requests.put(f"{live_stack.url}/api/events/{eid}/logo", data=_logo_png(), timeout=30,
                        headers={"Authorization": f"Bearer {admin.token}", "Content-Type": "image/png"})
    assert logo.status_code == 200, logo.text
    return {"event_id": eid, "racers": racers, "model_id": model["model_id"], "fleet_id": fleet_id,
            "logo_version": logo.json()["version"]}


def _logo_png() -> bytes:
    """A sponsor's logo with a transparent margin, as organisers upload them."""
    import io

    from PIL import Image, ImageDraw

    image = Image.new("RGBA", (600, 300), (0, 0, 0, 0))
    ImageDraw.Draw(image).ellipse((150, 50, 450, 250), fill=(255, 153, 0, 255))
    out = io.BytesIO()
    image.save(out, format="PNG")
    return out.getvalue()


def _logo(url: str, event_id: str) -> requests.Response:
    return requests.get(f"{url}/event/{event_id}/logo", timeout=30)


def _set_password(cognito, pool_id: str, username: str) -> str:
    password = generate_password()
    cognito.admin_set_user_password(UserPoolId=pool_id, Username=username, Password=password, Permanent=True)
    return password


def _boards(url: str, event_id: str) -> dict[str, dict]:
    boards = {}
    for track in ("1", "2", "combined"):
        reply = requests.get(f"{url}/api/leaderboard/{event_id}", params={"track": track}, timeout=30)
        assert reply.status_code == 200, reply.text
        boards[track] = reply.json()
    return boards


def _comparable(folder: Path, sub_map: dict[str, str]) -> dict[str, object]:
    """Everything in an export, subs mapped, and the manifest without `exported_at` and the checksums of the files
    that hold subs (those checksums follow from the content compared here)."""
    content: dict[str, object] = {}
    for path in sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()):
        data = (folder / path).read_bytes()
        if path in ITEM_FILES:
            document = json.loads(data)
            content[path] = {"table": document["table"], "items": remap_items(document["items"], sub_map)}
        elif path == "users.json":
            content[path] = [{**u, "sub": sub_map.get(u["sub"], u["sub"])} for u in json.loads(data)]
        elif path == "archives.json":
            content[path] = json.loads(remap_text(data.decode(), sub_map))
        elif path == MANIFEST:
            manifest = json.loads(data)
            manifest.pop("exported_at")
            manifest["files"] = sorted(manifest["files"])
            content[path] = manifest
        else:
            content[path] = data
    return content


def _without_import_entries(content: dict[str, object]) -> dict[str, object]:
    """An export minus the audit entries `drem import` wrote on the target (the only content an import adds), and
    the manifest parts that follow from them."""
    races = content["races.json"]
    kept = [i for i in races["items"] if '"action":"import"' not in i.get("doc", {}).get("S", "")]
    manifest = dict(content[MANIFEST])
    manifest["counts"] = {**manifest["counts"], "audit_entries": manifest["counts"]["audit_entries"]
                          - (len(races["items"]) - len(kept))}
    manifest["files"] = [f for f in manifest["files"] if f != "races.json"]
    return {**content, "races.json": {**races, "items": kept}, MANIFEST: manifest}


def remap_text(text: str, sub_map: dict[str, str]) -> str:
    for old, new in sub_map.items():
        text = text.replace(old, new)
    return text


def test_round_trip_to_a_fresh_stack(live_stack, target_stack, source_event, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    eid = source_event["event_id"]
    first, second = tmp_path / "first", tmp_path / "second"
    assert _export(eid, first, live_stack.state_dir) == 0
    manifest = json.loads((first / MANIFEST).read_text())
    # The stack is shared by the session: the event's staff (admin) may own models from other tests, and an export
    # carries every referenced account's models. The racer's model must be among them, byte for byte.
    assert manifest["counts"]["races"] == 2 and manifest["counts"]["audit_entries"] == 1  # the lap edit
    assert manifest["counts"]["archives"] == len(list((first / "archives").glob("*.tar.gz"))) >= 1
    assert (first / "archives" / f"{source_event['model_id']}.tar.gz").read_bytes() == onnx_archive(0.25)
    assert manifest["logo"] == "logo.png"
    assert (first / "logo.png").read_bytes() == _logo(live_stack.url, eid).content
    capsys.readouterr()

    # Issue 27: the folder holds e-mail addresses; it and everything in it are its owner's only.
    assert all(stat.S_IMODE(path.stat().st_mode) == (0o700 if path.is_dir() else 0o600)
               for path in [first, *first.rglob("*")]), "export folders 0700, files 0600"

    report_path = tmp_path / "report.json"
    assert _import(first, target_stack.config.state_dir, "--report", str(report_path)) == 0
    printed = capsys.readouterr().out
    assert stat.S_IMODE(report_path.stat().st_mode) == 0o600
    report = json.loads(report_path.read_text())
    actions = {a["username"]: a["action"] for a in report["accounts"]}
    assert actions[source_event["racers"]["ada"]] == "created"
    assert actions[live_stack.admin_username] == "matched existing"  # the target's own admin, by username

    assert _export(eid, second, target_stack.config.state_dir) == 0
    assert _without_import_entries(_comparable(second, {})) == \
        _without_import_entries(_comparable(first, report["sub_map"]))
    trail = [json.loads(i["doc"]["S"]) for i in json.loads((second / "races.json").read_text())["items"]
             if i["sk"]["S"].startswith("AUDIT#")]
    assert sorted(e["action"] for e in trail) == ["import", "lap_edit"]
    imported = next(e for e in trail if e["action"] == "import")
    # Counted as the export counted them (2 races and the lap edit's audit entry, not "3 races").
    assert imported["by"].startswith("drem import") and imported["after"]["written"]["races"] == 2
    assert imported["after"]["written"]["audit_entries"] == 1
    assert re.search(r"\b2 races, 1 audit entries\b", printed), printed
    assert set(report["sub_map"].values()).isdisjoint(set(report["sub_map"]) - set(report["sub_map"].values()))

    # The public board reads the same on both stacks (the racers' display names included), and shows the same logo
    # at the same address; the avatar is the same picture although the account's sub changed.
    assert _boards(target_stack.config.app_url, eid) == _boards(live_stack.url, eid)
    assert "Zoë.Müller" in json.dumps(_boards(target_stack.config.app_url, eid)["1"], ensure_ascii=False)
    ada_name = source_event["racers"]["ada"]
    assert requests.get(f"{target_stack.config.app_url}/api/profiles/{ada_name}", timeout=30).json()[
        "display_name"] == "Zoë.Müller"
    assert requests.get(f"{target_stack.config.app_url}/api/profiles/{ada_name}/avatar.svg", timeout=30).content == \
        requests.get(f"{live_stack.url}/api/profiles/{ada_name}/avatar.svg", timeout=30).content
    version = source_event["logo_version"]
    assert f"/event/{eid}/logo?v={version}" in requests.get(f"{target_stack.config.app_url}/leaderboard/{eid}",
                                                            timeout=30).text
    moved = _logo(target_stack.config.app_url, eid)
    assert moved.status_code == 200 and moved.content == _logo(live_stack.url, eid).content
    said = next(line for line in printed.splitlines() if line.startswith("Imported event"))
    assert said.endswith("model archives, the logo."), said

    # A created racer signs in on the target with the temporary password printed once (and never stored).
    ada = source_event["racers"]["ada"]
    password = next(line.split("temporary password ")[1].split()[0] for line in printed.splitlines()
                    if f"account {ada}:" in line)
    assert password not in report_path.read_text()
    challenge = requests.post(f"{target_stack.config.app_url}/api/auth/token", timeout=30,
                              json={"username": ada, "password": password}).json()
    assert challenge["challenge"] == "NEW_PASSWORD_REQUIRED"
    new_password = generate_password()
    _cognito(target_stack.config.storage_url, target_stack.config.state_dir).respond_to_auth_challenge(
        ClientId=target_stack.outputs.user_pool_client_id, ChallengeName="NEW_PASSWORD_REQUIRED",
        Session=challenge["session"], ChallengeResponses={"USERNAME": ada, "NEW_PASSWORD": new_password})
    racer = ApiClient(target_stack.config.app_url)
    racer.sign_in(ada, new_password)
    assert racer.get("/api/me")["username"] == ada
    mine = racer.get("/api/models")["models"]
    assert [m["model_id"] for m in mine] == [source_event["model_id"]]  # the model moved with its new owner sub

    # Importing the same event again into the now non-empty stack is refused, naming the event.
    capsys.readouterr()
    assert _import(first, target_stack.config.state_dir) == 1
    assert f"already has event {eid}" in capsys.readouterr().err


def test_import_under_another_event_id_reuses_matched_accounts(live_stack, source_event, tmp_path: Path) -> None:
    eid = source_event["event_id"]
    folder = tmp_path / "export"
    assert _export(eid, folder, live_stack.state_dir) == 0
    new_id = f"{eid}-copy"
    report_path = tmp_path / "copy-report.json"
    assert _import(folder, live_stack.state_dir, "--event-id", new_id, "--report", str(report_path)) == 0
    report = json.loads(report_path.read_text())
    assert {a["action"] for a in report["accounts"]} == {"matched existing"}
    assert all(old == new for old, new in report["sub_map"].items())  # same stack: nobody recreated

    original, copy = _boards(live_stack.url, eid), _boards(live_stack.url, new_id)
    assert [(e["username"], e["fastest_lap_ms"]) for e in copy["combined"]["entries"]] == \
        [(e["username"], e["fastest_lap_ms"]) for e in original["combined"]["entries"]]
    event = requests.get(f"{live_stack.url}/api/leaderboard/{new_id}", params={"track": "1"}, timeout=30)
    assert event.status_code == 200
    assert any("model" in line for line in report["kept_existing"])  # the model already exists here: kept


def test_a_corrupted_file_is_refused_before_anything_is_written(live_stack, target_stack, source_event,
                                                                 tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "export"
    assert _export(source_event["event_id"], folder, live_stack.state_dir) == 0
    races = folder / "races.json"
    races.write_text(races.read_text().replace('"status"', '"statuz"', 1))
    users_before = _cognito(target_stack.config.storage_url, target_stack.config.state_dir).list_users(
        UserPoolId=target_stack.outputs.user_pool_id)["Users"]
    capsys.readouterr()

    assert _import(folder, target_stack.config.state_dir, "--event-id", "never-written") == 1
    err = capsys.readouterr().err
    assert "races.json: checksum mismatch" in err and "Nothing was written" in err
    target = connect(StackLocation.from_state_dir(target_stack.config.state_dir))
    assert target.get_item("events", "EVENT#never-written", "META") is None
    assert target.partition("races", "EVENT#never-written") == []
    users_after = _cognito(target_stack.config.storage_url, target_stack.config.state_dir).list_users(
        UserPoolId=target_stack.outputs.user_pool_id)["Users"]
    assert len(users_after) == len(users_before)


# --- a tampered export is hostile input -------------------------------------------------------------------------
# Whoever edits an export can recompute the manifest's checksums, so each attack below re-signs the folder the way
# an attacker would (`_tamper`); what stops it is import re-validating everything, not the checksums.

@pytest.fixture(scope="module")
def pristine_export(live_stack, source_event, tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("pristine") / "export"
    assert _export(source_event["event_id"], folder, live_stack.state_dir) == 0
    return folder


def _copy_of(folder: Path, tmp_path: Path) -> Path:
    import shutil

    return Path(shutil.copytree(folder, tmp_path / "tampered"))


def _tamper(folder: Path, path: str, data: bytes) -> None:
    """Write `path` and fix its checksums in the manifest, as an attacker with a text editor and sha256sum would."""
    import hashlib

    (folder / path).parent.mkdir(parents=True, exist_ok=True)
    (folder / path).write_bytes(data)
    manifest = json.loads((folder / MANIFEST).read_text())
    manifest["files"][path] = {"bytes": len(data), "md5": hashlib.md5(data).hexdigest(),
                               "sha256": hashlib.sha256(data).hexdigest()}
    (folder / MANIFEST).write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")


def _tamper_json(folder: Path, path: str, change) -> None:
    document = json.loads((folder / path).read_text())
    change(document)
    _tamper(folder, path, (json.dumps(document, indent=2, sort_keys=True) + "\n").encode())


def _nothing_written(target_stack, event_id: str, bucket_keys_before: set[str]) -> None:
    target = connect(StackLocation.from_state_dir(target_stack.config.state_dir))
    assert target.get_item("events", f"EVENT#{event_id}", "META") is None
    assert target.get_item("events", f"EVENT#{event_id}", "LOGO") is None
    assert target.partition("races", f"EVENT#{event_id}") == []
    assert _bucket_keys(target_stack) == bucket_keys_before


def _bucket_keys(stack) -> set[str]:
    location = StackLocation.from_state_dir(stack.config.state_dir)
    s3 = connect(location)._s3
    return {o["Key"] for o in s3.list_objects_v2(Bucket=location.buckets["models"]).get("Contents", [])}


def test_an_admin_account_slipped_into_the_export_is_created_as_a_racer(target_stack, pristine_export,
                                                                        tmp_path: Path) -> None:
    """Through the installed `drem import`, as the organiser runs it."""
    from tests.cli.test_installed_cli import drem, ok

    folder = _copy_of(pristine_export, tmp_path)
    mallory = f"mallory{secrets.token_hex(3)}"
    _tamper_json(folder, "users.json", lambda users: users.append(
        {"username": mallory, "sub": "00000000-0000-4000-8000-0000000000aa", "email": None, "country_code": None,
         "groups": ["admin", "racer"], "enabled": True}))
    report_path = tmp_path / "report.json"

    printed = ok(drem("import", str(folder), "--state-dir", str(target_stack.config.state_dir), "--event-id",
                      f"roles-{secrets.token_hex(3)}", "--report", str(report_path), cwd=tmp_path))

    assert f"account {mallory}: roles granted: racer; NOT granted: admin (use --grant-roles)" in printed
    entry = next(a for a in json.loads(report_path.read_text())["accounts"] if a["username"] == mallory)
    assert (entry["roles_granted"], entry["roles_skipped"]) == (["racer"], ["admin"])
    groups = _cognito(target_stack.config.storage_url, target_stack.config.state_dir).admin_list_groups_for_user(
        UserPoolId=target_stack.outputs.user_pool_id, Username=mallory)["Groups"]
    assert [g["GroupName"] for g in groups] == ["racer"]


def test_grant_roles_applies_the_exported_roles_and_says_so(target_stack, pristine_export, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    folder = _copy_of(pristine_export, tmp_path)
    desk = f"desk{secrets.token_hex(3)}"
    _tamper_json(folder, "users.json", lambda users: users.append(
        {"username": desk, "sub": "00000000-0000-4000-8000-0000000000bb", "email": None, "country_code": None,
         "groups": ["registration"], "enabled": True}))
    capsys.readouterr()

    assert _import(folder, target_stack.config.state_dir, "--event-id", f"grant-{secrets.token_hex(3)}",
                   "--grant-roles") == 0

    assert f"account {desk}: roles granted: registration" in capsys.readouterr().out
    groups = _cognito(target_stack.config.storage_url, target_stack.config.state_dir).admin_list_groups_for_user(
        UserPoolId=target_stack.outputs.user_pool_id, Username=desk)["Groups"]
    assert [g["GroupName"] for g in groups] == ["registration"]


def _archive_key_elsewhere(folder: Path) -> str:
    _tamper_json(folder, "archives.json", lambda entries: entries[0].update(key="public/index.html"))
    return "public/index.html"


def _traversal_archive_in_place_of_the_model(folder: Path) -> str:
    from tests.unit.models_helpers import traversal_archive

    entries = json.loads((folder / "archives.json").read_text())
    hostile = traversal_archive()
    _tamper(folder, entries[0]["file"], hostile)
    import hashlib

    _tamper_json(folder, "archives.json", lambda entries: entries[0].update(
        md5=hashlib.md5(hostile).hexdigest(), bytes=len(hostile)))
    return "fails the upload checks"


def _other_valid_model_under_the_records_name(folder: Path) -> str:
    import hashlib

    entries = json.loads((folder / "archives.json").read_text())
    other = onnx_archive(0.75)
    _tamper(folder, entries[0]["file"], other)
    _tamper_json(folder, "archives.json", lambda entries: entries[0].update(
        md5=hashlib.md5(other).hexdigest(), bytes=len(other)))
    # The model file always differs; the metadata too when the first archive is another test's model (shared stack).
    return "model_md5)"


def _audit_entry_of_another_event(folder: Path) -> str:
    def move(document: dict) -> None:
        entry = next(item for item in document["items"] if item["sk"]["S"].startswith("AUDIT#"))
        doc = json.loads(entry["doc"]["S"])
        doc["event_id"] = "someone-elses-event"
        entry["doc"]["S"] = json.dumps(doc)
    _tamper_json(folder, "races.json", move)
    return "does not match its key"


def _first_race(document: dict) -> dict:
    """The first race item (races.json also carries the event's audit trail, `AUDIT#` items, which sort first)."""
    return next(item for item in document["items"] if item["sk"]["S"].startswith("RACE#"))


def _live_pointer_in_races(folder: Path) -> str:
    def add_live(document: dict) -> None:
        race = _first_race(document)
        document["items"].append({"pk": race["pk"], "sk": {"S": "LIVE#1"}, "race_id": {"S": race["sk"]["S"][5:]}})
    _tamper_json(folder, "races.json", add_live)
    return "finished races only"


def _race_made_live_again(folder: Path) -> str:
    def revive(document: dict) -> None:
        race = _first_race(document)
        doc = json.loads(race["doc"]["S"])
        doc["race"]["status"] = "RUNNING"
        race["doc"]["S"] = json.dumps(doc)
    _tamper_json(folder, "races.json", revive)
    return "only submitted or discarded races"


def _deeply_nested_profiles(folder: Path) -> str:
    _tamper(folder, "profiles.json", b"[" * 100_000 + b"]" * 100_000)
    return "nested too deeply"


def _board_of_a_track_the_event_lacks(folder: Path) -> str:
    _tamper_json(folder, "leaderboards.json", lambda document: document["items"][0].update(sk={"S": "BOARD#99"}))
    return "not a board or overlay of this event's tracks"


def _model_record_moved_to_another_owner_key(folder: Path) -> str:
    def move(document: dict) -> None:
        record = next(i for i in document["items"] if i["pk"]["S"].startswith("OWNER#") and "s3_key" in i)
        record["s3_key"] = {"S": "models/someone-else/" + record["model_id"]["S"] + ".tar.gz"}
    _tamper_json(folder, "models.json", move)
    return "is not this model's place in the bucket"


def _board_body_edited_apart_from_its_rows(folder: Path) -> str:
    def forge(document: dict) -> None:
        item = next(i for i in document["items"] if i["sk"]["S"].startswith("BOARD#"))
        body = json.loads(item["body"]["S"])
        body["entries"] = [{**entry, "username": "Mallory", "fastest_lap_ms": 1} for entry in body["entries"]]
        item["body"]["S"] = json.dumps(body)
    _tamper_json(folder, "leaderboards.json", forge)
    return "the board's public body does not match its rows"


def _overlay_with_a_forged_lap(folder: Path) -> str:
    def forge(document: dict) -> None:
        overlay = next(i for i in document["items"] if i["sk"]["S"].startswith("OVERLAY#"))
        body = json.loads(overlay["body"]["S"])
        body["fastest_lap_ms"] = 1
        overlay["body"]["S"] = json.dumps(body)
    _tamper_json(folder, "leaderboards.json", forge)
    return "the overlay does not describe race"


def _script_in_place_of_the_logo(folder: Path) -> str:
    _tamper(folder, "logo.png", b'<svg xmlns="http://www.w3.org/2000/svg"><script>alert(document.cookie)</script></svg>')
    return "logo.png: SVG logos are not accepted"


def _logo_pointing_at_another_file(folder: Path) -> str:
    manifest = json.loads((folder / MANIFEST).read_text())
    manifest["logo"] = "event.json"
    (folder / MANIFEST).write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    return "field 'logo' must name a listed logo.png or logo.webp"


def _model_record_without_its_id_pointer(folder: Path) -> str:
    """Issue 27: a record reusing another racer's model id, without the MODELID# pointer by which the import sees
    that the target has that model already, overwrote that racer's archive."""
    def drop_pointer(document: dict) -> None:
        document["items"] = [i for i in document["items"] if not i["pk"]["S"].startswith("MODELID#")]
    _tamper_json(folder, "models.json", drop_pointer)
    return "has no id pointer"


def _object_key_of_another_racer(attribute: str, suffix: str):
    """Issue 27: scrutineer_clip_key / converted_key naming another racer's objects let the importer download them."""
    def tamper(folder: Path) -> str:
        def point_elsewhere(document: dict) -> None:
            record = next(i for i in document["items"] if i["pk"]["S"].startswith("OWNER#"))
            record[attribute] = {"S": f"models/victim-sub/victim-model{suffix}"}
        _tamper_json(folder, "models.json", point_elsewhere)
        return f"{attribute} 'models/victim-sub/victim-model{suffix}' is not this model's place in the bucket"
    return tamper


TAMPERINGS = {
    "a model record without its id pointer": (_model_record_without_its_id_pointer, None),
    "a scrutineering clip key of another racer": (_object_key_of_another_racer("scrutineer_clip_key",
                                                                               ".scrutineer.gif"), None),
    "a converted model key of another racer": (_object_key_of_another_racer("converted_key", ".onnx"), None),
    "a script in place of the logo": (_script_in_place_of_the_logo, None),
    "the logo naming another file": (_logo_pointing_at_another_file, None),
    "board body edited apart from its rows": (_board_body_edited_apart_from_its_rows, None),
    "overlay with a forged lap": (_overlay_with_a_forged_lap, None),
    "archive key outside models/{owner}/": (_archive_key_elsewhere, "archives are written only to their model's"),
    "traversal archive in place of the model": (_traversal_archive_in_place_of_the_model, None),
    "another valid model under the record's name": (_other_valid_model_under_the_records_name, None),
    "live pointer smuggled into races.json": (_live_pointer_in_races, None),
    "race made live again": (_race_made_live_again, None),
    "audit entry moved to another event": (_audit_entry_of_another_event, None),
    "deeply nested JSON": (_deeply_nested_profiles, None),
    "board of a track the event lacks": (_board_of_a_track_the_event_lacks, None),
    "model record pointing at another key": (_model_record_moved_to_another_owner_key, None),
}


def test_the_installed_cli_refuses_a_tampered_export_and_writes_nothing(target_stack, pristine_export,
                                                                        tmp_path: Path) -> None:
    from tests.cli.test_installed_cli import drem

    folder = _copy_of(pristine_export, tmp_path)
    _archive_key_elsewhere(folder)
    event_id = f"cli-tampered-{secrets.token_hex(3)}"
    keys_before = _bucket_keys(target_stack)

    refused = drem("import", str(folder), "--state-dir", str(target_stack.config.state_dir), "--event-id", event_id,
                   cwd=tmp_path)

    assert refused.returncode == 1 and "Traceback" not in refused.stderr
    assert "archives are written only to their model's own key" in refused.stderr
    _nothing_written(target_stack, event_id, keys_before)


@pytest.mark.parametrize("case", TAMPERINGS, ids=list(TAMPERINGS))
def test_a_tampered_export_is_refused_before_anything_is_written(case: str, target_stack, pristine_export,
                                                                 tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    folder = _copy_of(pristine_export, tmp_path)
    tamper, expected = TAMPERINGS[case]
    said = tamper(folder)
    event_id = f"tampered-{secrets.token_hex(3)}"
    keys_before = _bucket_keys(target_stack)
    capsys.readouterr()

    assert _import(folder, target_stack.config.state_dir, "--event-id", event_id) == 1

    err = capsys.readouterr().err
    assert (expected or said) in err, err
    assert "Traceback" not in err
    _nothing_written(target_stack, event_id, keys_before)


def test_forged_boards_with_matching_rows_are_recomputed_from_the_races(live_stack, target_stack, source_event,
                                                                        pristine_export, tmp_path: Path) -> None:
    """The careful forger edits the rows too and rebuilds body and etag with drem's own code: the import accepts the
    file, but the boards the public sees are recomputed from the races (and the races are the app's own models)."""
    from chalicelib.domain.leaderboards import BoardState, board_item_content
    from drem_leaderboard.models import RankingMethod

    folder = _copy_of(pristine_export, tmp_path)
    method = RankingMethod(json.loads(json.loads((folder / "event.json").read_text())["items"][0]["doc"]["S"])
                           ["race_config"]["ranking_method"])

    def forge(document: dict) -> None:
        boards = {i["sk"]["S"].removeprefix("BOARD#"): i for i in document["items"]
                  if i["sk"]["S"].startswith("BOARD#")}
        rows = {}
        for track, item in boards.items():
            if track == "combined":
                continue
            state = BoardState.model_validate_json(item["state"]["S"])
            forged = [row.model_copy(update={"summary": row.summary.model_copy(update={"fastest_lap_ms": 1})})
                      for row in state.rows]
            rows[track] = forged
            item["state"]["S"] = BoardState(rows=forged).model_dump_json()
        for track, item in boards.items():
            body = json.loads(item["body"]["S"])
            chosen = rows[track] if track != "combined" else [r for t in sorted(rows) for r in rows[t]]
            text, etag = board_item_content(body["event_id"], track, chosen, method, body["version"],
                                            body["updated_at_ms"])
            item["body"]["S"], item["etag"]["S"] = text, etag
    _tamper_json(folder, "leaderboards.json", forge)
    event_id = f"forged-{secrets.token_hex(3)}"

    assert _import(folder, target_stack.config.state_dir, "--event-id", event_id) == 0

    source_boards = _boards(live_stack.url, source_event["event_id"])
    target_boards = _boards(target_stack.config.app_url, event_id)
    for track in ("1", "2", "combined"):
        assert [(e["username"], e["fastest_lap_ms"]) for e in target_boards[track]["entries"]] == \
            [(e["username"], e["fastest_lap_ms"]) for e in source_boards[track]["entries"]]
        assert all(e["fastest_lap_ms"] != 1 for e in target_boards[track]["entries"])


def test_an_import_cut_off_part_way_is_finished_by_running_it_again(live_stack, target_stack, source_event,
                                                                     tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """Storage fails while the races are written (after the accounts were created): nothing shows on the target,
    and the same command run again finishes the import and shows the temporary passwords nobody saw."""
    from chalicelib.core.errors import ServiceUnavailable
    from chalicelib.storage.event_archive import StackStorage

    folder = tmp_path / "export"
    assert _export(source_event["event_id"], folder, live_stack.state_dir) == 0
    cognito = _cognito(target_stack.config.storage_url, target_stack.config.state_dir)
    racers = sorted(source_event["racers"].values())
    for username in racers:  # other tests may have imported them here already: start without them
        try:
            cognito.admin_delete_user(UserPoolId=target_stack.outputs.user_pool_id, Username=username)
        except cognito.exceptions.UserNotFoundException:
            pass
    new_id = f"resumed-{secrets.token_hex(3)}"
    real_put = StackStorage.put_new_item
    races_written: list[str] = []

    def storage_dies_after_one_race(self, table, item):  # type: ignore[no-untyped-def]
        if table == "races" and races_written:
            raise ServiceUnavailable("The races table cannot be reached.")
        if table == "races":
            races_written.append(item["sk"]["S"])
        return real_put(self, table, item)

    monkeypatch.setattr(StackStorage, "put_new_item", storage_dies_after_one_race)
    capsys.readouterr()
    assert _import(folder, target_stack.config.state_dir, "--event-id", new_id) == 1
    failed = capsys.readouterr().err
    journal = tmp_path / f"export.import-{new_id}.resume.json"
    assert "running the same command again" in failed and journal.stat().st_mode & 0o077 == 0
    assert target_stack_event(target_stack, new_id) is None  # the event item is written last: not there

    monkeypatch.setattr(StackStorage, "put_new_item", real_put)
    assert _import(folder, target_stack.config.state_dir, "--event-id", new_id) == 0
    printed = capsys.readouterr().out
    assert "finished an interrupted import" in printed
    for username in racers:
        password = next(line.split("temporary password ")[1].split()[0] for line in printed.splitlines()
                        if f"account {username}:" in line)
        challenge = requests.post(f"{target_stack.config.app_url}/api/auth/token", timeout=30,
                                  json={"username": username, "password": password}).json()
        assert challenge["challenge"] == "NEW_PASSWORD_REQUIRED"  # the password shown again works
    assert not journal.exists()
    assert target_stack_event(target_stack, new_id) is not None
    def without_event_id(boards: dict[str, dict]) -> dict[str, dict]:
        return {track: {k: v for k, v in board.items() if k != "event_id"} for track, board in boards.items()}

    assert without_event_id(_boards(target_stack.config.app_url, new_id)) == \
        without_event_id(_boards(live_stack.url, source_event["event_id"]))


def target_stack_event(target_stack, event_id: str) -> dict | None:
    location = StackLocation.from_state_dir(target_stack.config.state_dir)
    return connect(location).get_item("events", f"EVENT#{event_id}", "META")


class _PowerCut(BaseException):
    """kill -9 of `drem import`: nothing after this line of it runs (not even its own error handling)."""


@pytest.mark.parametrize("kill_point", ["after an account is created", "after the event item",
                                        "after the audit entry"])
def test_an_import_killed_at_any_point_is_finished_by_running_it_again(kill_point: str, live_stack, target_stack,
                                                                       source_event, tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """The re-run exits 0, gives the accounts their groups, shows the temporary passwords nobody saw, writes the
    "Event imported" audit entry exactly once and deletes the resume file (plaintext passwords) at the end."""
    from chalicelib.storage.audit import AUDIT_PREFIX
    from chalicelib.storage.event_archive import StackStorage
    from drem_local.commands.import_ import FileImportJournal

    folder = tmp_path / "export"
    assert _export(source_event["event_id"], folder, live_stack.state_dir) == 0
    cognito = _cognito(target_stack.config.storage_url, target_stack.config.state_dir)
    pool_id = target_stack.outputs.user_pool_id
    racers = sorted(source_event["racers"].values())
    for username in racers:  # other tests may have imported them here already: start without them
        try:
            cognito.admin_delete_user(UserPoolId=pool_id, Username=username)
        except cognito.exceptions.UserNotFoundException:
            pass
    new_id = f"killed-{secrets.token_hex(3)}"
    if kill_point == "after an account is created":
        def account_only(self, account, temporary_password):  # type: ignore[no-untyped-def]
            cognito.admin_create_user(UserPoolId=pool_id, Username=account.username,
                                      TemporaryPassword=temporary_password, MessageAction="SUPPRESS")
            raise _PowerCut()
        monkeypatch.setattr(StackStorage, "create_account", account_only)
    elif kill_point == "after the event item":
        real_put = StackStorage.put_new_item

        def put_then_die(self, table, item):  # type: ignore[no-untyped-def]
            stored = real_put(self, table, item)
            if table == "events":
                raise _PowerCut()
            return stored
        monkeypatch.setattr(StackStorage, "put_new_item", put_then_die)
    else:
        monkeypatch.setattr(FileImportJournal, "finished", lambda self: (_ for _ in ()).throw(_PowerCut()))

    with pytest.raises(_PowerCut):
        _import(folder, target_stack.config.state_dir, "--event-id", new_id)
    journal = tmp_path / f"export.import-{new_id}.resume.json"
    assert journal.exists() and journal.stat().st_mode & 0o077 == 0
    monkeypatch.undo()
    capsys.readouterr()

    assert _import(folder, target_stack.config.state_dir, "--event-id", new_id) == 0
    printed = capsys.readouterr().out
    assert not journal.exists()  # no plaintext temporary password left behind
    assert target_stack_event(target_stack, new_id) is not None
    storage = connect(StackLocation.from_state_dir(target_stack.config.state_dir))
    audit = [i for i in storage.partition("races", f"EVENT#{new_id}", AUDIT_PREFIX) if i["action"]["S"] == "import"]
    assert len(audit) == 1, audit
    for username in racers:
        groups = cognito.admin_list_groups_for_user(UserPoolId=pool_id, Username=username)["Groups"]
        assert [g["GroupName"] for g in groups] == ["racer"], username
        password = next(line.split("temporary password ")[1].split()[0] for line in printed.splitlines()
                        if f"account {username}:" in line)
        challenge = requests.post(f"{target_stack.config.app_url}/api/auth/token", timeout=30,
                                  json={"username": username, "password": password}).json()
        assert challenge["challenge"] == "NEW_PASSWORD_REQUIRED"  # the password shown again works
