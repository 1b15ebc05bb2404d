"""Writing an event export folder: deterministic content files, then the manifest of their checksums, last."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from chalicelib.core.errors import InvalidInput
from chalicelib.formats import private_files
from chalicelib.formats.event_export.records import (
    ARCHIVES_FILE,
    FORMAT,
    FORMAT_VERSION,
    ITEM_FILES,
    LOGO_FILES,
    MANIFEST,
    NOT_CARRIED,
    USERS_FILE,
    EventBundle,
    sorted_items,
)


def render_files(bundle: EventBundle) -> dict[str, bytes]:
    """Every file of the export except the manifest, deterministically."""
    files = {name: json_bytes({"table": table, "items": sorted_items(bundle.items.get(table, []))})
             for name, table in ITEM_FILES.items()}
    files[USERS_FILE] = json_bytes([a.model_dump() for a in sorted(bundle.accounts,
                                                                   key=lambda a: a.username.casefold())])
    files[ARCHIVES_FILE] = json_bytes([a.model_dump() for a in sorted(bundle.archives, key=lambda a: a.model_id)])
    files.update(bundle.archive_data)
    if bundle.logo is not None:
        files[LOGO_FILES[bundle.logo.content_type]] = bundle.logo.data
    return files


def manifest_for(bundle: EventBundle, files: dict[str, bytes], exported_at: str) -> dict[str, Any]:
    audit = sum(1 for i in bundle.items.get("races", []) if i["sk"]["S"].startswith("AUDIT#"))
    counts = {table: len(items) for table, items in sorted(bundle.items.items())}
    counts["races"] = counts.get("races", 0) - audit  # races.json also holds the audit trail, counted apart
    manifest = {
        "format": FORMAT, "format_version": FORMAT_VERSION, "event_id": bundle.event_id, "exported_at": exported_at,
        "counts": counts | {"audit_entries": audit, "accounts": len(bundle.accounts), "archives": len(bundle.archives)},
        "files": {path: checksums(data) for path, data in sorted(files.items())},
        "not_carried": list(NOT_CARRIED),
    }
    if bundle.logo is not None:
        manifest["logo"] = LOGO_FILES[bundle.logo.content_type]
    return manifest


def write_export(bundle: EventBundle, out_dir: Path, exported_at: str) -> dict[str, Any]:
    """Write the folder (which must be new or empty); returns the manifest."""
    if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
        raise InvalidInput(f"{out_dir} already exists and is not an empty folder; export into a new folder.",
                           field="out")
    files = render_files(bundle)
    manifest = manifest_for(bundle, files, exported_at)
    # Accounts hold e-mail addresses: folders 0700, files 0600, each created new (private_files).
    private_files.make_dir(out_dir)
    for path, data in files.items():
        target = out_dir / path
        private_files.make_dir(target.parent)
        private_files.write_new(target, data)
    private_files.write_new(out_dir / MANIFEST, json_bytes(manifest))  # last: without it the folder is unfinished
    return manifest


def json_bytes(value: Any) -> bytes:
    return (json.dumps(value, indent=2, sort_keys=True, ensure_ascii=False) + "\n").encode()


def checksums(data: bytes) -> dict[str, Any]:
    return {"bytes": len(data), "md5": hashlib.md5(data).hexdigest(), "sha256": hashlib.sha256(data).hexdigest()}
