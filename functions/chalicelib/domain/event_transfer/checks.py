"""Re-validating an event export before `drem import` writes a byte: a tampered export is hostile input.

The manifest's checksums only catch accidents: whoever edits a file can recompute them. So every item that the app
later trusts is checked here against the rules the app itself would have applied when it was first written:

* accounts: roles are known role names (granting them is a separate, explicit decision:
  `chalicelib.domain.event_transfer.import_plan.plan_import(grant_roles=)`);
* the event and every race parse as the app's own models; races are finished, belong to this event and to the
  racer their key says; races.json holds races only (a `LIVE#` pointer would start a race on the target);
* boards and overlays sit under the event's own tracks; a board's public body and etag must be exactly what its
  rows give (the combined board: what the track boards' rows give), and the rows are then recomputed from the races
  on the target; an overlay must describe a race of its track as the race document has it;
* model records and their id pointers agree with each other; archive keys are exactly `models/{owner}/{id}.tar.gz`
  of a record in the export (no key anywhere else in the bucket), and every archive goes through the same
  validator as an upload and must give the facts (model/metadata md5, kind) its record claims.
"""
from __future__ import annotations

import io
import json
from typing import Any

from pydantic import BaseModel, ValidationError

from chalicelib.core.errors import DremError
from chalicelib.core.principals import Role
from chalicelib.domain.events import Event
from chalicelib.domain.leaderboards import BoardRow, BoardState, OverlaySnapshot, board_item_content
from chalicelib.domain.names import check_display_name
from chalicelib.domain.profiles import anonymised_name
from chalicelib.domain.racer_models import (
    ModelStatus,
    converted_key,
    model_key,
    scrutineer_clip_key,
    upload_key,
)
from chalicelib.domain.races import RaceRecord
from chalicelib.formats.event_export.records import EventBundle, InvalidExport, Item, archive_file
from chalicelib.formats.model_archive.limits import DEFAULT_LIMITS, ArchiveLimits
from chalicelib.formats.model_archive.verdict import inspect_archive
from drem_leaderboard.models import TERMINAL_STATUSES, Race, RankingMethod
from drem_leaderboard.ranking import COMBINED_TRACK_ID

ANONYMISED_PREFIX = anonymised_name("")  # "Deleted racer ": how a deleted racer's profile shows
ACCOUNT_ROLES = frozenset({Role.ADMIN, Role.OPERATOR, Role.COMMENTATOR, Role.REGISTRATION, Role.RACER})


def check_bundle(bundle: EventBundle, *, limits: ArchiveLimits = DEFAULT_LIMITS) -> None:
    """Raise InvalidExport naming the first file and item at fault; return quietly when everything holds."""
    _check_accounts(bundle)
    event = _check_event(bundle)
    races = _check_races(bundle)
    _check_boards(bundle, event, races)
    records = _check_models(bundle)
    _check_archives(bundle, records, limits)


def _invalid(message: str, field: str | None = None) -> Exception:
    return InvalidExport(message, field=field)


def _parse(model: type[BaseModel], text: str | None, where: str) -> Any:
    try:
        return model.model_validate_json(text or "")
    except ValidationError as exc:
        first = exc.errors()[0]
        location = ".".join(str(part) for part in first["loc"]) or "?"
        raise _invalid(f"{where}: {location}: {first['msg']}.", field=location) from None


def _text(item: Item, attribute: str) -> str | None:
    value = item.get(attribute, {})
    return value.get("S") if isinstance(value, dict) else None


def _check_accounts(bundle: EventBundle) -> None:
    known = {role.value for role in ACCOUNT_ROLES}
    for account in bundle.accounts:
        unknown = sorted(set(account.groups) - known)
        if unknown:
            raise _invalid(f"users.json: account {account.username} has unknown role(s) {', '.join(unknown)}; "
                           f"roles are {', '.join(sorted(known))}.", field="groups")


def _check_event(bundle: EventBundle) -> Event:
    event: Event = _parse(Event, _text(bundle.items["events"][0], "doc"), "event.json: item 0 field 'doc'")
    if event.event_id != bundle.event_id:
        raise _invalid(f"event.json: the event is {event.event_id!r} but the manifest says {bundle.event_id!r}.",
                       field="event_id")
    return event


def _check_races(bundle: EventBundle) -> dict[str, Race]:
    races: dict[str, Race] = {}
    for index, item in enumerate(bundle.items["races"]):
        where = f"races.json: item {index}"
        sk = item["sk"]["S"]
        if sk.startswith("AUDIT#"):  # the event's audit trail travels with its races (domain/audit.py)
            _check_audit_entry(bundle, item, sk, where)
            continue
        if not sk.startswith("RACE#"):
            raise _invalid(f"{where} field 'sk' is {sk!r}; an export holds finished races only (no live pointers).",
                           field="sk")
        record: RaceRecord = _parse(RaceRecord, _text(item, "doc"), f"{where} field 'doc'")
        race = record.race
        if sk != f"RACE#{race.race_id}" or race.event_id != bundle.event_id:
            raise _invalid(f"{where}: the race document ({race.event_id}/{race.race_id}) does not match its key "
                           f"{item['pk']['S']} / {sk}.", field="doc")
        if race.status not in TERMINAL_STATUSES:
            raise _invalid(f"{where}: race {race.race_id} is {race.status.value}; only submitted or discarded "
                           "races move between stacks.", field="status")
        if _text(item, "racer_sub") not in (None, race.racer.sub):
            raise _invalid(f"{where}: field 'racer_sub' is not the racer of the race document.", field="racer_sub")
        races[race.race_id] = race
    return races


def _check_audit_entry(bundle: EventBundle, item: Item, sk: str, where: str) -> None:
    """An audit entry must be what the app writes: an AuditEntry of this event, under its own time and id."""
    from chalicelib.domain.audit import AuditEntry

    entry: AuditEntry = _parse(AuditEntry, _text(item, "doc"), f"{where} field 'doc'")
    if entry.event_id != bundle.event_id or sk != f"AUDIT#{entry.at_ms:013d}#{entry.entry_id}":
        raise _invalid(f"{where}: the audit entry ({entry.event_id}, {sk}) does not match its key.", field="doc")
    if _text(item, "action") not in (None, entry.action):
        raise _invalid(f"{where}: field 'action' is not the action of the audit entry.", field="action")


def _check_boards(bundle: EventBundle, event: Event, races: dict[str, Race]) -> None:
    tracks = [track.track_id for track in event.tracks if track.track_id]
    method = event.race_config.ranking_method
    boards: dict[str, tuple[int, Item]] = {}
    for index, item in enumerate(bundle.items["leaderboards"]):
        where = f"leaderboards.json: item {index}"
        kind, _, track = item["sk"]["S"].partition("#")
        allowed = {*tracks, COMBINED_TRACK_ID} if kind == "BOARD" else set(tracks)
        if kind not in ("BOARD", "OVERLAY") or track not in allowed:
            raise _invalid(f"{where} field 'sk' is {item['sk']['S']!r}, which is not a board or overlay of this "
                           "event's tracks.", field="sk")
        if kind == "BOARD":
            boards[track] = (index, item)
        else:
            _check_overlay(where, item, track, races, _profile_names(bundle))
    rows_by_track = {track: _parse(BoardState, _text(item, "state") or '{"rows": []}',
                                   f"leaderboards.json: item {index} field 'state'").rows
                     for track, (index, item) in boards.items() if track != COMBINED_TRACK_ID}
    for track, (index, item) in boards.items():
        rows = rows_by_track[track] if track != COMBINED_TRACK_ID else \
            [row for t in tracks for row in rows_by_track.get(t, [])]
        _check_board_body(f"leaderboards.json: item {index}", item, bundle.event_id, track, rows, method)


def _check_board_body(where: str, item: Item, event_id: str, track: str, rows: list[BoardRow],
                      method: RankingMethod) -> None:
    """The public body must be exactly what the rows give: an edited body (a faster lap, another name) is refused,
    and the rows themselves are recomputed from the races on the target."""
    body = _json_object(_text(item, "body"), f"{where} field 'body'")
    version, updated_at_ms = body.get("version"), body.get("updated_at_ms")
    if not isinstance(version, int) or not isinstance(updated_at_ms, int) or \
            item.get("version", {}).get("N") != str(version):
        raise _invalid(f"{where}: the board's version/updated_at_ms are missing or disagree.", field="version")
    expected_body, expected_etag = board_item_content(event_id, track, rows, method, version, updated_at_ms)
    if json.loads(expected_body) != body or _text(item, "etag") != expected_etag:
        raise _invalid(f"{where}: the board's public body does not match its rows; it was edited after the export.",
                       field="body")


def _profile_names(bundle: EventBundle) -> dict[str, set[str]]:
    """Every name a racer may be shown under (overlays carry the display name): the sign-in name and the display
    name, which must be one drem itself would have stored (no text-direction controls slipped in by an edit)."""
    names: dict[str, set[str]] = {}
    for item in bundle.items["profiles"]:
        sub, username, display_name = _text(item, "sub"), _text(item, "username"), _text(item, "display_name")
        if display_name:
            try:
                valid = check_display_name(display_name) == display_name
            except DremError:
                valid = False
            if not valid:
                raise _invalid(f"profiles.json: the display name of {username or sub} is not one drem accepts.",
                               field="display_name")
        if sub and username:
            names.setdefault(sub, set()).update(name for name in (username, display_name) if name)
    return names


def _check_overlay(where: str, item: Item, track: str, races: dict[str, Race],
                   profile_names: dict[str, set[str]]) -> None:
    overlay: OverlaySnapshot = _parse(OverlaySnapshot, _text(item, "body"), f"{where} field 'body'")
    if overlay.status == "NO_RACE" and overlay.race_id is None:
        return
    race = races.get(overlay.race_id or "")
    fastest = race.fastest_valid_lap if race else None
    names = {race.racer.username, *profile_names.get(race.racer.sub, set())} if race else set()
    facts_match = race is not None and race.track_id == track == overlay.track_id and (
        overlay.username in names or overlay.username.startswith(ANONYMISED_PREFIX)) and (
        overlay.laps, overlay.valid_laps, overlay.fastest_lap_ms, overlay.last_lap_ms) == (
        len(race.laps), len(race.valid_laps), fastest.time_ms if fastest else None,
        race.laps[-1].time_ms if race.laps else None)
    if not facts_match:
        raise _invalid(f"{where}: the overlay does not describe race {overlay.race_id} of track {track} as the race "
                       "document has it.", field="body")


def _json_object(text: str | None, where: str) -> dict[str, Any]:
    try:
        value = json.loads(text or "")
    except (ValueError, RecursionError):
        value = None
    if not isinstance(value, dict):
        raise _invalid(f"{where} is not a JSON object.", field="body")
    return value


def _check_models(bundle: EventBundle) -> dict[str, Item]:
    records: dict[str, Item] = {}
    pointers: dict[str, str] = {}
    for index, item in enumerate(bundle.items["models"]):
        where = f"models.json: item {index}"
        pk, sk = item["pk"]["S"], item["sk"]["S"]
        if pk.startswith("MODELID#"):
            if sk != "OWNER" or not _text(item, "owner_sub"):
                raise _invalid(f"{where}: a model id pointer has sk 'OWNER' and an 'owner_sub'.", field="sk")
            pointers[pk.removeprefix("MODELID#")] = _text(item, "owner_sub") or ""
            continue
        owner, model_id = pk.removeprefix("OWNER#"), _text(item, "model_id") or ""
        if sk != f"MODEL#{model_id}" or _text(item, "owner_sub") != owner:
            raise _invalid(f"{where}: model_id/owner_sub do not match the key {pk} / {sk}.", field="model_id")
        status = _text(item, "status")
        if status not in {s.value for s in ModelStatus} or status == ModelStatus.DELETED.value:
            raise _invalid(f"{where}: status {status!r} cannot be imported.", field="status")
        _check_object_keys(where, item, owner, model_id)
        records[model_id] = item
    for model_id, owner in pointers.items():
        if model_id not in records or records[model_id]["owner_sub"]["S"] != owner:
            raise _invalid(f"models.json: the id pointer of model {model_id} names an owner whose record is not in "
                           "the export.", field="owner_sub")
    for model_id in records:
        if model_id not in pointers:  # the import decides "the target has this model already" by its pointer
            raise _invalid(f"models.json: model {model_id} has no id pointer (MODELID#{model_id}); every model "
                           "drem exports carries one.", field="model_id")
    return records


# Every bucket key a model record may hold, and the one place each may name: the model's own objects. A key naming
# another racer's object would let the importing racer download it (a scrutineering clip, a converted model).
_OWN_OBJECT_KEYS = {"s3_key": model_key, "converted_key": converted_key, "scrutineer_clip_key": scrutineer_clip_key}


def _check_object_keys(where: str, item: Item, owner: str, model_id: str) -> None:
    if _text(item, "upload_key") != upload_key(owner, model_id):
        raise _invalid(f"{where}: upload_key is not {upload_key(owner, model_id)}.", field="upload_key")
    for name in sorted(item):
        if not name.endswith("_key") or name == "upload_key":
            continue
        own = _OWN_OBJECT_KEYS.get(name)
        if own is None:
            raise _invalid(f"{where}: {name} is not an attribute a model record has.", field=name)
        value = _text(item, name)
        if value is not None and value != own(owner, model_id):
            raise _invalid(f"{where}: {name} {value!r} is not this model's place in the bucket "
                           f"({own(owner, model_id)}); a model record may only name its own files.", field=name)


def _check_archives(bundle: EventBundle, records: dict[str, Item], limits: ArchiveLimits) -> None:
    carried: set[str] = set()
    for index, entry in enumerate(bundle.archives):
        where = f"archives.json: item {index}"
        record = records.get(entry.model_id)
        if record is None:
            raise _invalid(f"{where}: model {entry.model_id} has no record in models.json.", field="model_id")
        expected_key = model_key(record["owner_sub"]["S"], entry.model_id)
        if entry.key != expected_key or _text(record, "s3_key") != expected_key:
            raise _invalid(f"{where}: key {entry.key!r} is not {expected_key}; archives are written only to their "
                           "model's own key.", field="key")
        if entry.file != archive_file(entry.model_id):
            raise _invalid(f"{where}: file must be {archive_file(entry.model_id)}.", field="file")
        if entry.model_id in carried:
            raise _invalid(f"{where}: model {entry.model_id} is listed twice.", field="model_id")
        carried.add(entry.model_id)
        report = inspect_archive(io.BytesIO(bundle.archive_data[entry.file]), limits=limits)
        if not report.available:
            raise _invalid(f"{entry.file}: the archive fails the upload checks ({report.status.value}: "
                           f"{report.reason}).", field="archive")
        claimed = {"model_md5": _text(record, "model_md5"), "metadata_md5": _text(record, "metadata_md5"),
                   "model_kind": _text(record, "model_kind")}
        found = {"model_md5": report.model_md5, "metadata_md5": report.metadata_md5, "model_kind": report.model_kind}
        differing = sorted(name for name in claimed if claimed[name] != found[name])
        if differing:
            raise _invalid(f"{entry.file}: the archive does not match its record in models.json "
                           f"({', '.join(differing)}).", field=differing[0])
    for model_id, record in records.items():
        if _text(record, "s3_key") and model_id not in carried:
            raise _invalid(f"models.json: model {model_id} has an archive key but no archive in the export.",
                           field="s3_key")
