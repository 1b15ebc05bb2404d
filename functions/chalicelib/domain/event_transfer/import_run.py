"""Running an import plan against the target stack, in an order that never shows a half-imported event."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from chalicelib.core.errors import Conflict, DremError
from chalicelib.domain.event_transfer.import_plan import ImportPlan
from chalicelib.domain.event_transfer.ports import ImportJournal, StackWriter
from chalicelib.formats.event_export.records import EVENT_SCOPED_TABLES, ITEM_FILES
from chalicelib.formats.event_export.remap import remap


class PartialImport(DremError):
    """A write failed after others had succeeded; `written` lists them (also in the message)."""

    def __init__(self, message: str, written: list[str]) -> None:
        super().__init__(message)
        self.written = written


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
    already_written: int = 0  # items an interrupted run of this import had written (resuming)
    logo_written: bool = False

    def report(self) -> dict[str, Any]:
        return {"event_id": self.event_id, "source_event_id": self.source_event_id, "sub_map": self.sub_map,
                "accounts": self.accounts, "written": self.written, "archives_written": self.archives_written,
                "kept_existing": self.kept, "already_written_by_an_interrupted_run": self.already_written,
                "logo_written": self.logo_written}


def run_import(plan: ImportPlan, target: StackWriter, journal: ImportJournal | None = None) -> ImportResult:
    """Write the plan: accounts, archives, shared items, races, boards, the logo, the event item last.

    Each account is noted in `journal` (with its temporary password) before it is created, so a run cut off here can
    be resumed (`plan_import`). Resuming, an event item that is already stored and equal to this import's counts as
    written; the boards are recomputed from the races either way."""
    written: list[str] = []
    step = "creating accounts"
    try:
        sub_map: dict[str, str] = {}
        for action in plan.accounts:
            account = action.account.model_copy(update={"groups": action.roles_granted})
            if action.action == "create":
                if journal is not None:
                    journal.intend(action.account.username, action.temporary_password or "")
                action.target_sub = target.create_account(account, action.temporary_password or "")
                written.append(f"account {action.account.username}")
            elif action.action == "resume":  # the interrupted run may have stopped between its account and groups
                target.finish_account(account)
            sub_map[action.account.sub] = action.target_sub or action.account.sub
        if plan.event_written:
            return _result(plan, sub_map, {}, 0, sum(len(items) for items in plan.bundle.items.values()),
                           logo_written=False)
        bundle = remap(plan.bundle, sub_map, plan.event_id)
        step = "uploading model archives"
        archives_written = 0
        for entry in bundle.archives:
            if entry.model_id not in plan.skip_archives:
                target.write_object("models", entry.key, bundle.archive_data[entry.file])
                written.append(f"archive {entry.key}")
                archives_written += 1
        counts: dict[str, int] = {}
        resumed = 0
        originals = {t: plan.bundle.items.get(t, []) for t in ITEM_FILES.values()}
        for table in ITEM_FILES.values():
            if table == "events":  # before the event shows: imported board bodies are never what the public sees
                step = "recomputing the boards from the races"
                target.recompute_boards(bundle.items["events"][0])
                if bundle.logo is not None:  # replaces what an interrupted run of this import wrote
                    step = "writing the event's logo"
                    target.write_logo(plan.event_id, bundle.logo)
                    written.append(f"the logo of event {plan.event_id}")
            step = f"writing the {table} table"
            counts[table] = 0
            for original, item in zip(originals[table], bundle.items.get(table, []), strict=True):
                if (table, original["pk"]["S"], original["sk"]["S"]) in plan.skip_keys:
                    continue
                if not target.put_new_item(table, item):
                    if plan.resuming and (table == "leaderboards" or target.get_item(
                            table, item["pk"]["S"], item["sk"]["S"]) == item):
                        resumed += 1  # written by the interrupted run (boards: recomputed from the races anyway)
                        continue
                    if table in EVENT_SCOPED_TABLES:
                        raise Conflict(f"{table} item {item['pk']['S']} / {item['sk']['S']} appeared on the target "
                                       "meanwhile; someone else is writing this event.")
                    plan.kept.append(f"{table} item {item['pk']['S']} / {item['sk']['S']} (appeared meanwhile)")
                    continue
                written.append(f"{table} {item['pk']['S']} / {item['sk']['S']}")
                # Counted as the export counts them: an audit entry rides in the races table but is no race.
                kind = "audit_entries" if table == "races" and item["sk"]["S"].startswith("AUDIT#") else table
                counts[kind] = counts.get(kind, 0) + 1
    except DremError as exc:
        raise PartialImport(_partial_message(step, exc.message, written), written) from exc
    except Exception as exc:  # an unexpected failure still must say what is already on the target
        raise PartialImport(_partial_message(step, repr(exc), written), written) from exc
    return _result(plan, sub_map, counts, archives_written, resumed, logo_written=bundle.logo is not None)


def _result(plan: ImportPlan, sub_map: dict[str, str], counts: dict[str, int], archives_written: int,
            resumed: int, *, logo_written: bool) -> ImportResult:
    actions = {"create": "created", "resume": "created (by the interrupted run)", "match": "matched existing"}
    accounts = [{"username": a.account.username, "old_sub": a.account.sub, "new_sub": a.target_sub or "",
                 "action": actions[a.action],
                 "roles_granted": a.roles_granted, "roles_skipped": a.roles_skipped} for a in plan.accounts]
    return ImportResult(event_id=plan.event_id, source_event_id=plan.bundle.event_id, sub_map=sub_map,
                        accounts=accounts, written=counts, archives_written=archives_written, kept=plan.kept,
                        temporary_passwords={a.account.username: a.temporary_password or ""
                                             for a in plan.accounts if a.action in ("create", "resume")},
                        already_written=resumed, logo_written=logo_written)


def _partial_message(step: str, reason: str, written: list[str]) -> str:
    if not written:
        return f"The import failed while {step}: {reason} Nothing was written."
    listing = "\n  ".join(written)
    return (f"The import failed while {step}: {reason}\nAlready written to the target ({len(written)}):\n  {listing}\n"
            "Run the same import again to finish it (it resumes from here), or remove these.")
