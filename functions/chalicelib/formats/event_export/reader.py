"""Reading an event export folder: every listed file checked (name, kind, checksum), every record parsed.

A tampered export is hostile input: checksums only catch accidents, so what `read_export` returns is re-validated
(`chalicelib.domain.event_transfer.checks.check_bundle`: the app's own models, keys only under their expected
prefixes, every archive through the upload validator) before `drem import` writes anything. Listed names go
through the one member-name vetting of `drem_archive.member_names`, and every file is opened without
following links: a link or device in the folder is refused, never read.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

from chalicelib.core.errors import InvalidInput
from chalicelib.formats.event_export.records import (
    ALLOWED_PK,
    ARCHIVES_FILE,
    ATTRIBUTE_TYPES,
    EVENT_ID,
    EVENT_SCOPED_TABLES,
    FORMAT,
    FORMAT_VERSION,
    ITEM_FILES,
    LOGO_FILES,
    MANIFEST,
    USERS_FILE,
    Account,
    ArchiveEntry,
    EventBundle,
    InvalidExport,
    Item,
)
from chalicelib.formats.event_export.writer import checksums
from chalicelib.formats.logo_image import LogoImage, normalised_logo
from drem_archive.member_names import RefusedMember, vet_folder_file


def read_export(folder: Path) -> EventBundle:
    """Parse and check the whole folder; raises InvalidExport naming the first file/field at fault."""
    manifest = _load_json(MANIFEST, _read(folder, MANIFEST))
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise InvalidExport(f"{MANIFEST}: field 'format' must be {FORMAT!r}; this is not a drem event export.",
                            field="format")
    if manifest.get("format_version") != FORMAT_VERSION:
        raise InvalidExport(f"{MANIFEST}: field 'format_version' is {manifest.get('format_version')!r}; this drem "
                            f"reads version {FORMAT_VERSION}.", field="format_version")
    event_id = manifest.get("event_id")
    if not isinstance(event_id, str) or not EVENT_ID.match(event_id):
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
        items[table] = _parse_items(name, table, _load_json(name, contents[name]), event_id)
    if [i["sk"]["S"] for i in items["events"]] != ["META"]:
        raise InvalidExport("event.json: field 'items' must hold exactly the event's META item.", field="items")
    accounts = _parse_list(USERS_FILE, _load_json(USERS_FILE, contents[USERS_FILE]), Account)
    archives = _parse_list(ARCHIVES_FILE, _load_json(ARCHIVES_FILE, contents[ARCHIVES_FILE]), ArchiveEntry)
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
                         archive_data=archive_data, logo=_logo(manifest.get("logo"), contents))
    return bundle


def _logo(name: Any, contents: dict[str, bytes]) -> LogoImage | None:
    """The manifest's logo file drawn again from its pixels, as an upload is: the file is hostile input too."""
    if name is None:
        return None
    if name not in LOGO_FILES.values() or name not in contents:
        raise InvalidExport(f"{MANIFEST}: field 'logo' must name a listed {' or '.join(LOGO_FILES.values())}.",
                            field="logo")
    try:
        return normalised_logo(contents[name])
    except InvalidInput as refused:
        raise InvalidExport(f"{name}: {refused.message}", field="logo") from None


def _verified_files(folder: Path, listed: dict[str, Any]) -> dict[str, bytes]:
    contents: dict[str, bytes] = {}
    for path, sums in sorted(listed.items()):
        if path == MANIFEST:
            raise InvalidExport(f"{MANIFEST}: field 'files' lists {path!r}, which is not a plain relative path.",
                                field="files")
        data = _read(folder, path)
        if not isinstance(sums, dict) or checksums(data) != {k: sums.get(k) for k in ("bytes", "md5", "sha256")}:
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
    prefixes = (f"EVENT#{event_id}",) if table in EVENT_SCOPED_TABLES else ALLOWED_PK[table]
    for index, item in enumerate(document["items"]):
        where = f"{name}: item {index}"
        if not isinstance(item, dict):
            raise InvalidExport(f"{where} is not an object.", field="items")
        for attribute, value in item.items():
            if not (isinstance(value, dict) and len(value) == 1 and next(iter(value)) in ATTRIBUTE_TYPES):
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
                load_json_text(f"{where} field {attribute!r}", text, attribute)
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


def _read(folder: Path, path: str) -> bytes:
    try:
        return vet_folder_file(folder, path).read_bytes()
    except RefusedMember as refused:
        where = MANIFEST if path == MANIFEST else f"{MANIFEST}: field 'files' lists {path!r}, which"
        raise InvalidExport(f"{where} is not a plain file under a plain relative name ({refused.reason}).",
                            field="files") from None
    except FileNotFoundError:
        raise InvalidExport(f"{path}: missing from {folder} (the manifest lists it, or every export has it).",
                            field="files") from None
    except OSError as exc:
        raise InvalidExport(f"{path}: cannot be read ({exc.strerror}).", field="files") from None


def _load_json(name: str, data: bytes) -> Any:
    return load_json_text(name, data.decode("utf-8", errors="replace"), None)


def load_json_text(where: str, text: str, field_name: str | None) -> Any:
    try:
        return json.loads(text)
    except ValueError as exc:
        raise InvalidExport(f"{where} is not valid JSON ({exc}).", field=field_name) from None
    except RecursionError:  # json recurses per nesting level; a hand-made `[[[[...` would crash the CLI
        raise InvalidExport(f"{where} is nested too deeply.", field=field_name) from None
