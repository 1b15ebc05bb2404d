"""Planning an import: every account, kept item and refusal decided before the first write."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from chalicelib.core.errors import Conflict, InvalidInput
from chalicelib.domain.event_transfer.passwords import password_problem
from chalicelib.domain.event_transfer.ports import ImportJournal, StackReader, StackWriter
from chalicelib.formats.event_export.records import EVENT_ID, Account, EventBundle, Item
from chalicelib.formats.event_export.remap import remap
from drem_infra import resources

RACER_ROLE = "racer"  # the role every created account gets; staff roles need grant_roles


@dataclass
class AccountAction:
    account: Account
    action: str  # "create", "match", or "resume" (created by an interrupted run of this import)
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
    resuming: bool = False  # an earlier run of this import was cut off: its races are on the target already
    event_written: bool = False  # it was cut off after the event item (its last write): only the ending is left


def plan_import(bundle: EventBundle, target: StackReader | StackWriter, *, new_event_id: str | None = None,
                passwords: dict[str, str] | None = None, generate: Callable[[], str] | None = None,
                grant_roles: bool = False, journal: ImportJournal | None = None) -> ImportPlan:
    """Decide everything (and refuse clearly) before the first write.

    Roles are power over the target event: an export (a file anyone may have edited) grants none silently. Without
    `grant_roles`, a created account is a racer only, and its other exported roles are reported as skipped.

    An import cut off part-way (the event item, written last, is missing) is resumed by running it again: the
    accounts it created are matched (their temporary passwords, from `journal`, shown again), and the races it wrote
    must be exactly what this import writes, or nothing is written."""
    event_id = new_event_id or bundle.event_id
    if not EVENT_ID.match(event_id):
        raise InvalidInput("Use 1-64 letters, digits, '-' or '_' for the event id.", field="event_id")
    pk = f"EVENT#{event_id}"
    if target.get_item("events", pk, "META") is not None:
        if journal is not None and journal.started():
            return _ending_plan(bundle, target, event_id, journal, grant_roles)  # type: ignore[arg-type]
        raise Conflict(f"The target stack already has event {event_id}; nothing was written. Import under another "
                       "id with --event-id NEW, or delete that event first.", field="event_id")
    leftovers = target.partition("races", pk)
    interrupted = journal.intended() if journal is not None else {}
    passwords = {k.casefold(): v for k, v in (passwords or {}).items()}
    generate = generate or resources.USER_POOL.password_policy.random_password
    actions: list[AccountAction] = []
    for account in bundle.accounts:
        existing = target.find_account(account.username)  # type: ignore[union-attr]
        if existing is not None and account.username in interrupted:
            actions.append(AccountAction(account, "resume", existing.sub,
                                         temporary_password=interrupted[account.username],
                                         roles_granted=sorted(account.groups) if grant_roles else [RACER_ROLE]))
            continue
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

    plan = ImportPlan(bundle=bundle, event_id=event_id, accounts=actions, resuming=bool(leftovers))
    if leftovers:
        _check_leftovers(plan, leftovers)
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
    # A model id the target already knows keeps the target's model, whether or not the export carries the id's
    # pointer: a record reusing another racer's id without it would otherwise overwrite that racer's archive.
    model_ids = sorted({item["pk"]["S"].removeprefix("MODELID#") if item["pk"]["S"].startswith("MODELID#")
                        else item.get("model_id", {}).get("S", "") for item in models} - {""})
    for model_id in model_ids:
        if target.get_item("models", f"MODELID#{model_id}", "OWNER") is not None:
            plan.kept.append(f"model {model_id} (the target already has it)")
            plan.skip_archives.add(model_id)
    for item in models:
        model_id = item.get("model_id", {}).get("S") or item["pk"]["S"].removeprefix("MODELID#")
        if model_id in plan.skip_archives:
            plan.skip_keys.add(("models", item["pk"]["S"], item["sk"]["S"]))
    return plan


def _check_leftovers(plan: ImportPlan, leftovers: list[Item]) -> None:
    """Race items already under the event: only an interrupted run of this very import may have left them."""
    pending = [a.account.username for a in plan.accounts if a.action == "create"]
    ours = {(i["pk"]["S"], i["sk"]["S"]): i for i in remap(
        plan.bundle, {a.account.sub: a.target_sub or a.account.sub for a in plan.accounts}, plan.event_id,
    ).items.get("races", [])}
    foreign = [f"{i['pk']['S']} / {i['sk']['S']}" for i in leftovers
               if pending or ours.get((i["pk"]["S"], i["sk"]["S"])) != i]
    if foreign:
        raise Conflict(f"The target stack already has races under event {plan.event_id} that this import did not "
                       f"write ({len(foreign)}, e.g. {foreign[0]}); nothing was written. Import under another id "
                       "with --event-id NEW, or delete that event first.", field="event_id")


def _ending_plan(bundle: EventBundle, target: StackWriter, event_id: str, journal: ImportJournal,
                 grant_roles: bool) -> ImportPlan:
    """An import cut off after its event item was written (its last write): every item is on the target, so only its
    ending is left: the accounts it created finished (groups, disable) and their passwords shown, the audit entry,
    the resume file removed. Nothing else is written."""
    interrupted = journal.intended()
    actions: list[AccountAction] = []
    for account in bundle.accounts:
        existing = target.find_account(account.username)
        if existing is None:
            raise Conflict(f"The target stack has event {event_id}, but not the account {account.username} its "
                           "import would have created; nothing was written. Import under another id with "
                           "--event-id NEW, or delete that event first.", field="event_id")
        if account.username in interrupted:
            actions.append(AccountAction(account, "resume", existing.sub,
                                         temporary_password=interrupted[account.username],
                                         roles_granted=sorted(account.groups) if grant_roles else [RACER_ROLE]))
        else:
            actions.append(AccountAction(account, "match", existing.sub))
    return ImportPlan(bundle=bundle, event_id=event_id, accounts=actions, resuming=True, event_written=True)
