"""`drem import DIR [--event-id NEW]`: load a `drem export` folder into this stack.

The whole folder is checked first (checksums, format, every item); the target must not have the event yet. Then
accounts are created (temporary passwords printed once, or taken from --password-file) or matched by username,
every old sub is rewritten to the new one, and the items and model archives are written. Every item and archive is
re-validated first (a tampered export is refused, naming the file), the boards are recomputed from the races, and
created accounts are racers unless --grant-roles applies the roles the export lists (reported either way). The
report (sub mapping, roles, what was written and kept) goes next to the folder; it never holds passwords.

An import cut off part-way (a crash, storage down, kill -9 at any point) is finished by running the same command
again: the event item is written last, so the event never shows half-imported, and the re-run matches what the first
run wrote. The import's resume record, `DIR.import-EVENT.resume.json` (0600, beside the folder), exists from before
the first write until the audit entry is written: it holds the import's id and start, and each account about to be
created with its temporary password (noted before the account is created). The re-run finishes what was cut off
(an account's groups and disable included, and everything after the event item: the audit entry, written once),
shows those passwords again and deletes the file once the import is complete.
"""
from __future__ import annotations

import argparse
import getpass
import json
import os
import secrets
import sys
import time
import uuid
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from drem_local.commands.export import add_location_arguments, open_stack

HELP = "import a folder written by `drem export` (optionally under another event id)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", metavar="DIR", type=Path, help="the export folder")
    parser.add_argument("--event-id", default=None, help="import under this event id instead of the exported one")
    parser.add_argument("--password-file", type=Path, default=None,
                        help="temporary passwords for the accounts to create: JSON {\"user\": \"pw\"} or lines "
                             "'user pw' (accounts not listed get a generated one, printed once)")
    parser.add_argument("--grant-roles", action="store_true",
                        help="give created accounts the staff roles (admin, operator, ...) the export lists; without "
                             "it they are racers and the skipped roles are reported")
    parser.add_argument("--report", type=Path, default=None,
                        help="where to write the import report (default: next to DIR)")
    add_location_arguments(parser)


def record_import(target: Any, result: Any, journal: FileImportJournal) -> None:
    """The import itself goes into the event's audit trail (who ran it, from which event, what it wrote). Its key
    comes from the resume record (when the import began, its id), so a re-run after a crash that came after this
    entry writes no second one."""
    from chalicelib.domain.audit import AuditEntry
    from chalicelib.storage.audit import audit_item

    import_id, started_ms = journal.identity()
    entry = AuditEntry(entry_id=import_id, event_id=result.event_id, at_ms=started_ms,
                       by=f"drem import ({getpass.getuser()})", action="import",
                       after={"source_event_id": result.source_event_id, "written": result.written})
    target.put_new_item("races", audit_item(entry))


class FileImportJournal:
    """The import's resume record, a 0600 file (fsynced) beside the export folder: when it began and its id, and the
    accounts it is about to create with their temporary passwords. It exists from the first write until the import
    is complete (the audit entry written), so a re-run after a crash at any point knows it is finishing this
    import (even past the event item, its last write) and shows the passwords nobody saw.

    Each version is written to a new file of a random name (O_EXCL, never through a file or link someone else put
    there) and renamed over the last; a resume file this user does not own, or that others may read or write, is
    refused rather than trusted (its passwords could be someone else's choice)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def _read(self) -> dict[str, Any]:
        from chalicelib.formats import private_files

        raw = private_files.read_own(self.path)
        if raw is None:
            return {}
        try:
            data = json.loads(raw)
        except ValueError:
            return {}
        if not isinstance(data, dict):
            return {}
        if "accounts" not in data and "import_id" not in data:  # written before the record had an id: accounts
            return {"accounts": data}
        return data

    def started(self) -> bool:
        return bool(self._read().get("import_id"))

    def begin(self) -> None:
        """Note that the import begins now (kept as it is when an interrupted run already began it)."""
        if not self.started():
            self._write({**self._read(), "import_id": uuid.uuid4().hex, "started_at_ms": time.time_ns() // 1_000_000})

    def identity(self) -> tuple[str, int]:
        data = self._read()
        return str(data.get("import_id") or uuid.uuid4().hex), int(data.get("started_at_ms") or time.time() * 1000)

    def intended(self) -> dict[str, str]:
        accounts = self._read().get("accounts") or {}
        return {str(k): str(v) for k, v in accounts.items()} if isinstance(accounts, dict) else {}

    def intend(self, username: str, temporary_password: str) -> None:
        data = self._read()
        self._write({**data, "accounts": {**self.intended(), username: temporary_password}})

    def _write(self, data: dict[str, Any]) -> None:
        from chalicelib.formats import private_files

        temporary = self.path.with_name(f"{self.path.name}.{secrets.token_hex(8)}.tmp")
        private_files.write_new(temporary, json.dumps(data).encode(), fsync=True)
        try:
            os.replace(temporary, self.path)
        except OSError:
            temporary.unlink(missing_ok=True)
            raise

    def finished(self) -> None:
        self.path.unlink(missing_ok=True)


def journal_for(folder: Path, event_id: str) -> FileImportJournal:
    folder = folder.resolve()
    return FileImportJournal(folder.parent / f"{folder.name}.import-{event_id}.resume.json")


def run(args: argparse.Namespace) -> int:
    from chalicelib.core.errors import DremError
    from chalicelib.domain.event_transfer.checks import check_bundle
    from chalicelib.domain.event_transfer.import_plan import plan_import
    from chalicelib.domain.event_transfer.import_run import PartialImport, run_import
    from chalicelib.domain.event_transfer.passwords import parse_password_file
    from chalicelib.formats.event_export.reader import read_export

    try:
        passwords = parse_password_file(args.password_file.read_text()) if args.password_file else {}
        bundle = read_export(args.folder)
        check_bundle(bundle)  # every record as drem would have written it, before anything is stored
        target = open_stack(args)
        journal = journal_for(args.folder, args.event_id or bundle.event_id)
        plan = plan_import(bundle, target, new_event_id=args.event_id, passwords=passwords,
                           grant_roles=args.grant_roles, journal=journal)
        journal.begin()
        result = run_import(plan, target, journal)
        record_import(target, result, journal)
        journal.finished()
    except PartialImport as exc:
        print(f"drem import: {exc.message}", file=sys.stderr)
        if journal.intended():
            print(f"drem import: the temporary passwords of the accounts created so far are in {journal.path} "
                  "(0600); running the same command again shows them and finishes the import.", file=sys.stderr)
        return 1
    except (DremError, OSError, ValueError) as exc:
        print(f"drem import: {getattr(exc, 'message', exc)}", file=sys.stderr)
        return 1
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    report_path = args.report or args.folder.resolve().parent / f"{args.folder.resolve().name}.import-{stamp}.json"
    report = {**result.report(), "imported_at": stamp, "folder": str(args.folder.resolve())}
    from chalicelib.formats import private_files

    try:  # it names every racer and their e-mail: 0600, created new
        private_files.write_new(report_path, (json.dumps(report, indent=2, sort_keys=True) + "\n").encode())
    except OSError as exc:
        print(f"drem import: imported, but the report could not be written to {report_path}: {exc}", file=sys.stderr)
    written = ", ".join(f"{n} {table.replace('_', ' ')}" for table, n in result.written.items())
    print(f"Imported event {result.source_event_id} as {result.event_id}: {written}, "
          f"{result.archives_written} model archives{', the logo' if result.logo_written else ''}.")
    if result.already_written:
        print(f"  finished an interrupted import: {result.already_written} items were already written by it")
    for line in result.kept:
        print(f"  kept existing: {line}")
    for username, password in sorted(result.temporary_passwords.items()):
        print(f"  account {username}: temporary password {password}  (must be changed at first sign-in)")
    for account in result.accounts:
        if not account["action"].startswith("created"):
            continue
        granted = ", ".join(account["roles_granted"]) or "none"
        skipped = f"; NOT granted: {', '.join(account['roles_skipped'])} (use --grant-roles)" \
            if account["roles_skipped"] else ""
        print(f"  account {account['username']}: roles granted: {granted}{skipped}")
    matched = [a["username"] for a in result.accounts if a["action"] == "matched existing"]
    if matched:
        print(f"  matched existing accounts (their passwords and roles unchanged): {', '.join(matched)}")
    print(f"Report (sub mapping, what was written; no passwords): {report_path}")
    print("Cars and timers are not carried: activate them on this stack into the imported fleets.")
    return 0
