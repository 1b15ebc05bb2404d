"""Moving a whole event between stacks (laptop ↔ AWS): export to a folder, validate, import elsewhere.

The folder (format `drem-event-export`, version 1):

    manifest.json       format, version, event id, `exported_at`, sha256 + md5 + size of every other file
    event.json          the event item                          (table `events`)
    races.json          its finished races with their laps,     (table `races`)
                        and the audit trail of results changes
    leaderboards.json   its materialised boards and overlays    (table `leaderboards`)
    profiles.json       the racers' public profiles + name alias (table `profiles`)
    fleets.json         the fleets its tracks use               (table `fleet`, fleet items only)
    models.json         the model records of its people         (table `models`, record + id pointer)
    users.json          the accounts: username, old sub, email, country, roles, enabled
    archives.json       model id → archive key, file and md5
    archives/<model_id>.tar.gz   the validated model archives, byte for byte

Items are stored as DynamoDB attribute values (`{"S": ...}`), so an export is lossless and never depends on how
the app parses them today. Content files are deterministic (sorted keys, items sorted by key, no run timestamps):
only `manifest.json`'s `exported_at` says when. Not carried: devices and their credentials (cars and timers
re-activate on the target, into the imported fleets), live races (refused: submit or discard first), device
commands, strip idempotency records, raw uploads and quarantined uploads, soft-deleted models.

Accounts are recreated on import with the same username (or matched by username where the target has one), and
Cognito gives them new subs. A created account gets the racer role only: staff roles in users.json are granted only
with `grant_roles=True` (`drem import --grant-roles`), and the report lists, per account, the roles granted and
skipped. Matched accounts keep their own roles. Every old sub in every item is rewritten to the new one (the
mapping goes into the import report). `--event-id NEW` rewrites the event id the same way in the event-scoped items.

A tampered export is hostile input: checksums only catch accidents, so `read_export` also re-validates every item
and archive (`chalicelib.formats.import_checks`: the app's own models, keys only under their expected prefixes,
every archive through the upload validator), and `run_import` has the target recompute the boards from the races.

Everything is read and validated before the first write; writes then go accounts → archives → shared items
(fleets, profiles, models; kept where the target already has them) → races → boards → the event item last, so an
event only shows once its data is in. A failure part-way raises `PartialImport` listing exactly what was written.
"""
from __future__ import annotations

import hashlib
import json
import re
import secrets
import string
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any, Protocol

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from chalicelib.domain.errors import Conflict, DremError, InvalidInput, NotFound
from chalicelib.formats.import_checks import check_bundle

FORMAT = "drem-event-export"
FORMAT_VERSION = 1
MANIFEST = "manifest.json"
USERS_FILE = "users.json"
ARCHIVES_FILE = "archives.json"
ARCHIVE_DIR = "archives"
# file → logical table; the order is the order of writes on import (the event item last).
ITEM_FILES: dict[str, str] = {"fleets.json": "fleet", "profiles.json": "profiles", "models.json": "models",
                              "races.json": "races", "leaderboards.json": "leaderboards", "event.json": "events"}
EVENT_SCOPED_TABLES = frozenset({"events", "races", "leaderboards"})
# The key prefixes each file may hold: anything else in a file is refused on import.
_ALLOWED_PK = {"fleet": ("FLEET#",), "profiles": ("USER#", "USERNAME#"), "models": ("OWNER#", "MODELID#")}
_EVENT_ID = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
_ATTRIBUTE_TYPES = frozenset({"S", "N", "B", "BOOL", "NULL", "M", "L", "SS", "NS", "BS"})
_SYMBOLS = "!#%*+-=?@^_"
RACER_ROLE = "racer"  # the role every created account gets; staff roles need grant_roles

Item = dict[str, Any]  # one DynamoDB item in attribute-value JSON


class InvalidExport(InvalidInput):
    """The export folder is not one drem can import; the message names the file (and field) at fault."""


class PartialImport(DremError):
    """A write failed after others had succeeded; `written` lists them (also in the message)."""

    def __init__(self, message: str, written: list[str]) -> None:
        super().__init__(message)
        self.written = written


class Account(BaseModel):
    """A person the event refers to, as their account was on the source stack."""
    model_config = ConfigDict(frozen=True, extra="forbid")

    username: str = Field(min_length=1, max_length=128)
    sub: str = Field(min_length=8, max_length=128)
    email: str | None = None
    country_code: str | None = None
    groups: list[str] = Field(default_factory=list)
    enabled: bool = True


class ArchiveEntry(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    model_id: str = Field(min_length=1)
    key: str = Field(min_length=1, description="object key in the models bucket (holds the owner's sub)")
    file: str = Field(min_length=1)
    md5: str = Field(pattern=r"^[0-9a-f]{32}$")
    bytes: int = Field(ge=0)


@dataclass
class EventBundle:
    event_id: str
    items: dict[str, list[Item]]  # logical table → items
    accounts: list[Account]
    archives: list[ArchiveEntry]
    archive_data: dict[str, bytes]  # file → content


# --- ports ----------------------------------------------------------------------------------------------------------

class StackReader(Protocol):
    def get_item(self, table: str, pk: str, sk: str) -> Item | None: ...
    def partition(self, table: str, pk: str, sk_prefix: str = "") -> list[Item]: ...
    def accounts_by_sub(self) -> dict[str, Account]: ...
    def read_object(self, bucket: str, key: str) -> bytes | None: ...


class StackWriter(StackReader, Protocol):
    def find_account(self, username: str) -> Account | None: ...
    def create_account(self, account: Account, temporary_password: str) -> str: ...
    def put_new_item(self, table: str, item: Item) -> bool: ...
    def write_object(self, bucket: str, key: str, data: bytes) -> None: ...
    def recompute_boards(self, event_item: Item) -> None: ...


# --- export ---------------------------------------------------------------------------------------------------------

def collect_event(source: StackReader, event_id: str) -> EventBundle:
    """Everything the event needs, read from `source`. Refuses while a track has a live race."""
    pk = f"EVENT#{event_id}"
    event_item = source.get_item("events", pk, "META")
    if event_item is None:
        raise NotFound(f"There is no event {event_id} on this stack.")
    race_items = source.partition("races", pk)
    live = sorted(i["sk"]["S"].removeprefix("LIVE#") for i in race_items if i["sk"]["S"].startswith("LIVE#"))
    if live:
        raise Conflict(f"Event {event_id} has a live race on track(s) {', '.join(live)}; submit or discard it "
                       "before exporting (a race in progress does not move between stacks).")
    races = [i for i in race_items if i["sk"]["S"].startswith("RACE#")]
    audit_trail = [i for i in race_items if i["sk"]["S"].startswith("AUDIT#")]  # who changed results, carried along
    boards = source.partition("leaderboards", pk)
    event_doc = json.loads(event_item["doc"]["S"])

    fleets = [f for f in (source.get_item("fleet", f"FLEET#{fid}", "META")
                          for fid in sorted({t["fleet_id"] for t in event_doc.get("tracks", []) if t.get("fleet_id")}))
              if f is not None]
    subs = {event_doc.get("created_by", "")} | {i["racer_sub"]["S"] for i in races if "racer_sub" in i}
    subs |= {f["createdBy"]["S"] for f in fleets if "createdBy" in f}
    subs.discard("")
    known = source.accounts_by_sub()
    accounts = sorted((known[s] for s in subs if s in known), key=lambda a: a.username.casefold())

    profiles: list[Item] = []
    models: list[Item] = []
    archives: list[ArchiveEntry] = []
    archive_data: dict[str, bytes] = {}
    for sub in sorted(subs):
        profile = source.get_item("profiles", f"USER#{sub}", "PROFILE")
        if profile is not None:
            profiles.append(profile)
        username = known[sub].username if sub in known else (profile or {}).get("username", {}).get("S")
        alias = source.get_item("profiles", f"USERNAME#{username.casefold()}", "SUB") if username else None
        if alias is not None and alias.get("sub", {}).get("S") == sub:
            profiles.append(alias)
        for record in source.partition("models", f"OWNER#{sub}", "MODEL#"):
            if record.get("status", {}).get("S") == "DELETED":
                continue
            model_id = record["model_id"]["S"]
            models.append(record)
            pointer = source.get_item("models", f"MODELID#{model_id}", "OWNER")
            if pointer is not None:
                models.append(pointer)
            key = record.get("s3_key", {}).get("S")
            if key:
                data = source.read_object("models", key)
                if data is None:
                    raise Conflict(f"The archive of model {model_id} ({key}) is missing from the models bucket; "
                                   "the export would be incomplete.")
                file = f"{ARCHIVE_DIR}/{model_id}.tar.gz"
                archive_data[file] = data
                archives.append(ArchiveEntry(model_id=model_id, key=key, file=file,
                                             md5=hashlib.md5(data).hexdigest(), bytes=len(data)))

    items = {"events": [event_item], "races": races + audit_trail, "leaderboards": boards, "profiles": profiles,
             "fleet": fleets, "models": models}
    return EventBundle(event_id=event_id, items={t: _sorted_items(v) for t, v in items.items()},
                       accounts=accounts, archives=sorted(archives, key=lambda a: a.model_id),
                       archive_data=archive_data)


def render_files(bundle: EventBundle) -> dict[str, bytes]:
    """Every file of the export except the manifest, deterministically."""
    files = {name: _json_bytes({"table": table, "items": _sorted_items(bundle.items.get(table, []))})
             for name, table in ITEM_FILES.items()}
    files[USERS_FILE] = _json_bytes([a.model_dump() for a in sorted(bundle.accounts,
                                                                    key=lambda a: a.username.casefold())])
    files[ARCHIVES_FILE] = _json_bytes([a.model_dump() for a in sorted(bundle.archives, key=lambda a: a.model_id)])
    files.update(bundle.archive_data)
    return files


def manifest_for(bundle: EventBundle, files: dict[str, bytes], exported_at: str) -> dict[str, Any]:
    audit = sum(1 for i in bundle.items.get("races", []) if i["sk"]["S"].startswith("AUDIT#"))
    counts = {table: len(items) for table, items in sorted(bundle.items.items())}
    counts["races"] = counts.get("races", 0) - audit  # races.json also holds the audit trail, counted apart
    return {
        "format": FORMAT, "format_version": FORMAT_VERSION, "event_id": bundle.event_id, "exported_at": exported_at,
        "counts": counts | {"audit_entries": audit, "accounts": len(bundle.accounts), "archives": len(bundle.archives)},
        "files": {path: _checksums(data) for path, data in sorted(files.items())},
        "not_carried": ["devices and their credentials (cars and timers re-activate on the target)",
                        "live races", "device commands and strip idempotency records",
                        "raw and quarantined uploads", "soft-deleted models", "passwords"],
    }


def write_export(bundle: EventBundle, out_dir: Path, exported_at: str) -> dict[str, Any]:
    """Write the folder (which must be new or empty); returns the manifest."""
    if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
        raise InvalidInput(f"{out_dir} already exists and is not an empty folder; export into a new folder.",
                           field="out")
    files = render_files(bundle)
    manifest = manifest_for(bundle, files, exported_at)
    for path, data in files.items():
        target = out_dir / path
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
    (out_dir / MANIFEST).write_bytes(_json_bytes(manifest))  # last: a folder without it is visibly unfinished
    return manifest


# --- reading and validating a folder --------------------------------------------------------------------------------

def read_export(folder: Path) -> EventBundle:
    """Parse and check the whole folder; raises InvalidExport naming the first file/field at fault."""
    manifest = _load_json(folder, MANIFEST, _read(folder, MANIFEST))
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise InvalidExport(f"{MANIFEST}: field 'format' must be {FORMAT!r}; this is not a drem event export.",
                            field="format")
    if manifest.get("format_version") != FORMAT_VERSION:
        raise InvalidExport(f"{MANIFEST}: field 'format_version' is {manifest.get('format_version')!r}; this drem "
                            f"reads version {FORMAT_VERSION}.", field="format_version")
    event_id = manifest.get("event_id")
    if not isinstance(event_id, str) or not _EVENT_ID.match(event_id):
        raise InvalidExport(f"{MANIFEST}: field 'event_id' is missing or not a valid event id.", field="event_id")
    listed = manifest.get("files")
    if not isinstance(listed, dict):
        raise InvalidExport(f"{MANIFEST}: field 'files' must map each file to its checksums.", field="files")
    contents = _verified_files(folder, listed)
    for required in [*ITEM_FILES, USERS_FILE, ARCHIVES_FILE]:
        if required not in contents:
            raise InvalidExport(f"{MANIFEST}: field 'files' does not list {required}, which every export has.",
                                field="files")

    items: dict[str, list[Item]] = {}
    for name, table in ITEM_FILES.items():
        items[table] = _parse_items(name, table, _load_json(folder, name, contents[name]), event_id)
    if [i["sk"]["S"] for i in items["events"]] != ["META"]:
        raise InvalidExport("event.json: field 'items' must hold exactly the event's META item.", field="items")
    accounts = _parse_list(USERS_FILE, _load_json(folder, USERS_FILE, contents[USERS_FILE]), Account)
    archives = _parse_list(ARCHIVES_FILE, _load_json(folder, ARCHIVES_FILE, contents[ARCHIVES_FILE]), ArchiveEntry)
    archive_data: dict[str, bytes] = {}
    for index, entry in enumerate(archives):
        if entry.file not in contents:
            raise InvalidExport(f"{ARCHIVES_FILE}: item {index} field 'file' names {entry.file}, which the manifest "
                                "does not list.", field="file")
        data = contents[entry.file]
        if hashlib.md5(data).hexdigest() != entry.md5 or len(data) != entry.bytes:
            raise InvalidExport(f"{entry.file}: md5/size differ from {ARCHIVES_FILE} item {index}; the archive is "
                                "damaged.", field="md5")
        archive_data[entry.file] = data
    usernames = [a.username.casefold() for a in accounts]
    if len(usernames) != len(set(usernames)):
        raise InvalidExport(f"{USERS_FILE}: a username appears twice.", field="username")
    bundle = EventBundle(event_id=event_id, items=items, accounts=accounts, archives=archives,
                         archive_data=archive_data)
    check_bundle(bundle)
    return bundle


def _verified_files(folder: Path, listed: dict[str, Any]) -> dict[str, bytes]:
    contents: dict[str, bytes] = {}
    for path, sums in sorted(listed.items()):
        pure = PurePosixPath(path)
        if pure.is_absolute() or ".." in pure.parts or path == MANIFEST:
            raise InvalidExport(f"{MANIFEST}: field 'files' lists {path!r}, which is not a plain relative path.",
                                field="files")
        data = _read(folder, path)
        if not isinstance(sums, dict) or _checksums(data) != {k: sums.get(k) for k in ("bytes", "md5", "sha256")}:
            expected = sums.get("sha256") if isinstance(sums, dict) else None
            raise InvalidExport(f"{path}: checksum mismatch (manifest sha256 {expected}, file "
                                f"{hashlib.sha256(data).hexdigest()}); the file changed or was damaged after the "
                                "export. Nothing was written.", field="sha256")
        contents[path] = data
    on_disk = {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()} - {MANIFEST}
    unlisted = sorted(on_disk - set(listed))
    if unlisted:
        raise InvalidExport(f"{unlisted[0]}: this file is in the folder but not in {MANIFEST}; an export is "
                            "imported exactly as it was written.", field="files")
    return contents


def _parse_items(name: str, table: str, document: Any, event_id: str) -> list[Item]:
    if not isinstance(document, dict) or document.get("table") != table or not isinstance(document.get("items"),
                                                                                           list):
        raise InvalidExport(f"{name}: must be {{\"table\": \"{table}\", \"items\": [...]}}.", field="items")
    prefixes = (f"EVENT#{event_id}",) if table in EVENT_SCOPED_TABLES else _ALLOWED_PK[table]
    for index, item in enumerate(document["items"]):
        where = f"{name}: item {index}"
        if not isinstance(item, dict):
            raise InvalidExport(f"{where} is not an object.", field="items")
        for attribute, value in item.items():
            if not (isinstance(value, dict) and len(value) == 1 and next(iter(value)) in _ATTRIBUTE_TYPES):
                raise InvalidExport(f"{where} field {attribute!r} is not a DynamoDB attribute value.",
                                    field=attribute)
        for key in ("pk", "sk"):
            if not isinstance(item.get(key, {}).get("S"), str):
                raise InvalidExport(f"{where} field {key!r} must be a string key.", field=key)
        pk = item["pk"]["S"]
        if (pk != prefixes[0]) if table in EVENT_SCOPED_TABLES else not pk.startswith(prefixes):
            raise InvalidExport(f"{where} field 'pk' is {pk!r}, which does not belong in {name}.", field="pk")
        for attribute in ("doc", "body", "state"):  # JSON documents the app parses on every read
            text = item.get(attribute, {}).get("S")
            if text:
                _load_json_text(f"{where} field {attribute!r}", text, attribute)
    return document["items"]


def _parse_list(name: str, document: Any, model: type[BaseModel]) -> list[Any]:
    if not isinstance(document, list):
        raise InvalidExport(f"{name}: must be a list.", field="items")
    parsed = []
    for index, entry in enumerate(document):
        try:
            parsed.append(model.model_validate(entry))
        except ValidationError as exc:
            first = exc.errors()[0]
            where = ".".join(str(p) for p in first["loc"]) or "?"
            raise InvalidExport(f"{name}: item {index} field {where!r}: {first['msg']}.", field=where) from exc
    return parsed


# --- importing ------------------------------------------------------------------------------------------------------

@dataclass
class AccountAction:
    account: Account
    action: str  # "create" or "match"
    target_sub: str | None = None  # known up front for "match", after creation for "create"
    temporary_password: str | None = None
    roles_granted: list[str] = field(default_factory=list)  # for "create": what the new account gets
    roles_skipped: list[str] = field(default_factory=list)  # exported roles not granted (no --grant-roles)


@dataclass
class ImportPlan:
    bundle: EventBundle
    event_id: str
    accounts: list[AccountAction]
    kept: list[str] = field(default_factory=list)  # shared items the target already has
    skip_keys: set[tuple[str, str, str]] = field(default_factory=set)  # (table, pk, sk) not to write
    skip_archives: set[str] = field(default_factory=set)  # model ids


def plan_import(bundle: EventBundle, target: StackReader | StackWriter, *, new_event_id: str | None = None,
                passwords: dict[str, str] | None = None, generate: Callable[[], str] | None = None,
                grant_roles: bool = False) -> ImportPlan:
    """Decide everything (and refuse clearly) before the first write.

    Roles are power over the target event: an export (a file anyone may have edited) grants none silently. Without
    `grant_roles`, a created account is a racer only, and its other exported roles are reported as skipped."""
    event_id = new_event_id or bundle.event_id
    if not _EVENT_ID.match(event_id):
        raise InvalidInput("Use 1-64 letters, digits, '-' or '_' for the event id.", field="event_id")
    pk = f"EVENT#{event_id}"
    if target.get_item("events", pk, "META") is not None or target.partition("races", pk) \
            or target.partition("leaderboards", pk):
        raise Conflict(f"The target stack already has event {event_id} (or races/boards under it); nothing was "
                       "written. Import under another id with --event-id NEW, or delete that event first.",
                       field="event_id")
    passwords = {k.casefold(): v for k, v in (passwords or {}).items()}
    generate = generate or temporary_password
    actions: list[AccountAction] = []
    for account in bundle.accounts:
        existing = target.find_account(account.username)  # type: ignore[union-attr]
        if existing is not None:
            actions.append(AccountAction(account, "match", existing.sub))
            continue
        password = passwords.get(account.username.casefold()) or generate()
        problem = password_problem(password)
        if problem:
            raise InvalidInput(f"The password file's password for {account.username} {problem}.", field="password")
        granted = sorted(account.groups) if grant_roles else [RACER_ROLE]
        skipped = sorted(set(account.groups) - set(granted))
        actions.append(AccountAction(account, "create", temporary_password=password, roles_granted=granted,
                                     roles_skipped=skipped))

    plan = ImportPlan(bundle=bundle, event_id=event_id, accounts=actions)
    matched = {a.account.sub: a.target_sub for a in actions if a.action == "match"}
    for item in bundle.items.get("fleet", []):
        if target.get_item("fleet", item["pk"]["S"], item["sk"]["S"]) is not None:
            plan.kept.append(f"fleet {item['pk']['S'].removeprefix('FLEET#')} (the target already has it)")
            plan.skip_keys.add(("fleet", item["pk"]["S"], item["sk"]["S"]))
    for item in bundle.items.get("profiles", []):
        sub = item.get("sub", {}).get("S", "")
        if sub in matched and target.get_item("profiles", f"USER#{matched[sub]}", "PROFILE") is not None:
            plan.kept.append(f"profile of {item.get('username', {}).get('S') or sub} (the target's own is kept)")
            plan.skip_keys.add(("profiles", item["pk"]["S"], item["sk"]["S"]))
    models = bundle.items.get("models", [])
    for item in models:
        if item["pk"]["S"].startswith("MODELID#"):
            model_id = item["pk"]["S"].removeprefix("MODELID#")
            if target.get_item("models", item["pk"]["S"], "OWNER") is not None:
                plan.kept.append(f"model {model_id} (the target already has it)")
                plan.skip_archives.add(model_id)
    for item in models:
        model_id = item.get("model_id", {}).get("S") or item["pk"]["S"].removeprefix("MODELID#")
        if model_id in plan.skip_archives:
            plan.skip_keys.add(("models", item["pk"]["S"], item["sk"]["S"]))
    return plan


@dataclass
class ImportResult:
    event_id: str
    source_event_id: str
    sub_map: dict[str, str]
    accounts: list[dict[str, Any]]
    written: dict[str, int]
    archives_written: int
    kept: list[str]
    temporary_passwords: dict[str, str]  # printed once by the CLI, never stored in the report

    def report(self) -> dict[str, Any]:
        return {"event_id": self.event_id, "source_event_id": self.source_event_id, "sub_map": self.sub_map,
                "accounts": self.accounts, "written": self.written, "archives_written": self.archives_written,
                "kept_existing": self.kept}


def run_import(plan: ImportPlan, target: StackWriter) -> ImportResult:
    """Write the plan: accounts, archives, shared items, races, boards, the event item last."""
    written: list[str] = []
    step = "creating accounts"
    try:
        sub_map: dict[str, str] = {}
        for action in plan.accounts:
            if action.action == "create":
                account = action.account.model_copy(update={"groups": action.roles_granted})
                action.target_sub = target.create_account(account, action.temporary_password or "")
                written.append(f"account {action.account.username}")
            sub_map[action.account.sub] = action.target_sub or action.account.sub
        bundle = remap(plan.bundle, sub_map, plan.event_id)
        step = "uploading model archives"
        archives_written = 0
        for entry in bundle.archives:
            if entry.model_id not in plan.skip_archives:
                target.write_object("models", entry.key, bundle.archive_data[entry.file])
                written.append(f"archive {entry.key}")
                archives_written += 1
        counts: dict[str, int] = {}
        originals = {t: plan.bundle.items.get(t, []) for t in ITEM_FILES.values()}
        for table in ITEM_FILES.values():
            if table == "events":  # before the event shows: imported board bodies are never what the public sees
                step = "recomputing the boards from the races"
                target.recompute_boards(bundle.items["events"][0])
            step = f"writing the {table} table"
            counts[table] = 0
            for original, item in zip(originals[table], bundle.items.get(table, []), strict=True):
                if (table, original["pk"]["S"], original["sk"]["S"]) in plan.skip_keys:
                    continue
                if not target.put_new_item(table, item):
                    if table in EVENT_SCOPED_TABLES:
                        raise Conflict(f"{table} item {item['pk']['S']} / {item['sk']['S']} appeared on the target "
                                       "meanwhile; someone else is writing this event.")
                    plan.kept.append(f"{table} item {item['pk']['S']} / {item['sk']['S']} (appeared meanwhile)")
                    continue
                written.append(f"{table} {item['pk']['S']} / {item['sk']['S']}")
                counts[table] += 1
    except DremError as exc:
        raise PartialImport(_partial_message(step, exc.message, written), written) from exc
    except Exception as exc:  # an unexpected failure still must say what is already on the target
        raise PartialImport(_partial_message(step, repr(exc), written), written) from exc
    accounts = [{"username": a.account.username, "old_sub": a.account.sub, "new_sub": a.target_sub or "",
                 "action": "created" if a.action == "create" else "matched existing",
                 "roles_granted": a.roles_granted, "roles_skipped": a.roles_skipped} for a in plan.accounts]
    return ImportResult(event_id=plan.event_id, source_event_id=plan.bundle.event_id, sub_map=sub_map,
                        accounts=accounts, written=counts, archives_written=archives_written, kept=plan.kept,
                        temporary_passwords={a.account.username: a.temporary_password or ""
                                             for a in plan.accounts if a.action == "create"})


def _partial_message(step: str, reason: str, written: list[str]) -> str:
    if not written:
        return f"The import failed while {step}: {reason} Nothing was written."
    listing = "\n  ".join(written)
    return (f"The import failed while {step}: {reason}\nAlready written to the target ({len(written)}):\n  {listing}\n"
            "Remove these (or import into a fresh stack) before trying again.")


# --- rewriting subs and the event id --------------------------------------------------------------------------------

def remap(bundle: EventBundle, sub_map: dict[str, str], event_id: str) -> EventBundle:
    """A copy with every old sub replaced by its new one, and the event id by `event_id` in event-scoped items."""
    subs = _replacer(sub_map)
    ids = _replacer({bundle.event_id: event_id})
    items = {table: [_map_strings(item, (lambda s: ids(subs(s))) if table in EVENT_SCOPED_TABLES else subs)
                     for item in table_items] for table, table_items in bundle.items.items()}
    archives = [a.model_copy(update={"key": subs(a.key)}) for a in bundle.archives]
    return EventBundle(event_id=event_id, items=items, accounts=bundle.accounts, archives=archives,
                       archive_data=bundle.archive_data)


def remap_items(items: list[Item], sub_map: dict[str, str]) -> list[Item]:
    """Items with subs rewritten, re-sorted by key (used to compare two exports of the same event)."""
    subs = _replacer(sub_map)
    return _sorted_items([_map_strings(item, subs) for item in items])


def _replacer(mapping: dict[str, str]) -> Callable[[str], str]:
    changes = {old: new for old, new in mapping.items() if old != new}
    if not changes:
        return lambda text: text
    # Whole ids only: an id is never rewritten inside a longer word (a hash, another id).
    pattern = re.compile(r"(?<![A-Za-z0-9])(" + "|".join(re.escape(o) for o in sorted(changes, key=len,
                                                                                         reverse=True))
                         + r")(?![A-Za-z0-9])")
    return lambda text: pattern.sub(lambda m: changes[m.group(1)], text)


def _map_strings(value: Any, change: Callable[[str], str]) -> Any:
    if isinstance(value, dict):
        return {key: (value[key] if key in ("N", "NS") else _map_strings(value[key], change)) for key in value}
    if isinstance(value, list):
        return [_map_strings(v, change) for v in value]
    if isinstance(value, str):
        return change(value)
    return value


# --- helpers --------------------------------------------------------------------------------------------------------

def temporary_password(length: int = 16) -> str:
    """Meets the pool's policy: at least 8 characters with lower, upper, digit and symbol."""
    classes = [string.ascii_lowercase, string.ascii_uppercase, string.digits, _SYMBOLS]
    chars = [secrets.choice(c) for c in classes] + [secrets.choice("".join(classes)) for _ in range(length - 4)]
    secrets.SystemRandom().shuffle(chars)
    return "".join(chars)


def password_problem(password: str) -> str | None:
    checks = [(len(password) >= 8, "is shorter than 8 characters"),
              (any(c.islower() for c in password), "has no lower-case letter"),
              (any(c.isupper() for c in password), "has no upper-case letter"),
              (any(c.isdigit() for c in password), "has no digit"),
              (any(not c.isalnum() for c in password), "has no symbol")]
    return next((problem for ok, problem in checks if not ok), None)


def parse_password_file(text: str) -> dict[str, str]:
    """`{"username": "password", ...}` JSON, or lines `username password` (blank lines and # comments skipped)."""
    stripped = text.strip()
    if stripped.startswith("{"):
        try:
            data = json.loads(stripped)
        except (ValueError, RecursionError):
            raise InvalidInput("The password file is not valid JSON.", field="password_file") from None
        if not isinstance(data, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in data.items()):
            raise InvalidInput("The password file must map usernames to password strings.", field="password_file")
        return data
    passwords: dict[str, str] = {}
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        parts = line.split(None, 1)
        if len(parts) != 2:
            raise InvalidInput(f"Password file line {number}: use 'username password'.", field="password_file")
        passwords[parts[0]] = parts[1].strip()
    return passwords


def _sorted_items(items: Iterable[Item]) -> list[Item]:
    return sorted(items, key=lambda i: (i["pk"]["S"], i["sk"]["S"]))


def _json_bytes(value: Any) -> bytes:
    return (json.dumps(value, indent=2, sort_keys=True, ensure_ascii=False) + "\n").encode()


def _checksums(data: bytes) -> dict[str, Any]:
    return {"bytes": len(data), "md5": hashlib.md5(data).hexdigest(), "sha256": hashlib.sha256(data).hexdigest()}


def _read(folder: Path, path: str) -> bytes:
    try:
        return (folder / path).read_bytes()
    except FileNotFoundError:
        raise InvalidExport(f"{path}: missing from {folder} (the manifest lists it, or every export has it).",
                            field="files") from None
    except OSError as exc:
        raise InvalidExport(f"{path}: cannot be read ({exc.strerror}).", field="files") from None


def _load_json(folder: Path, name: str, data: bytes) -> Any:
    return _load_json_text(name, data.decode("utf-8", errors="replace"), None)


def _load_json_text(where: str, text: str, field_name: str | None) -> Any:
    try:
        return json.loads(text)
    except ValueError as exc:
        raise InvalidExport(f"{where} is not valid JSON ({exc}).", field=field_name) from None
    except RecursionError:  # json recurses per nesting level; a hand-made `[[[[...` would crash the CLI
        raise InvalidExport(f"{where} is nested too deeply.", field=field_name) from None
