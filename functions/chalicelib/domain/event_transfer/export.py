"""Reading everything one event needs from a stack, into an `EventBundle` the folder writer can write."""
from __future__ import annotations

import hashlib
import json

from chalicelib.core.errors import Conflict, NotFound
from chalicelib.domain.event_transfer.ports import StackReader
from chalicelib.formats.event_export.records import ArchiveEntry, EventBundle, Item, archive_file, sorted_items


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
    # A long board's further pages and parts are its storage layout: the import recomputes the boards from the races.
    # The big screen's settings (SCREEN) are published again from the event on its next edit.
    boards = [i for i in source.partition("leaderboards", pk) if "~" not in i["sk"]["S"] and
              i["sk"]["S"].startswith(("BOARD#", "OVERLAY#"))]
    too_big = sorted(i["sk"]["S"] for i in boards if "state_ref" in i)
    if too_big:
        raise Conflict(f"Event {event_id}'s board(s) {', '.join(too_big)} hold too many racers to export yet (their "
                       "rows are stored in parts); the export would be incomplete.")
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
                file = archive_file(model_id)
                archive_data[file] = data
                archives.append(ArchiveEntry(model_id=model_id, key=key, file=file,
                                             md5=hashlib.md5(data).hexdigest(), bytes=len(data)))

    items = {"events": [event_item], "races": races + audit_trail, "leaderboards": boards, "profiles": profiles,
             "fleet": fleets, "models": models}
    return EventBundle(event_id=event_id, items={t: sorted_items(v) for t, v in items.items()},
                       accounts=accounts, archives=sorted(archives, key=lambda a: a.model_id),
                       archive_data=archive_data, logo=source.read_logo(event_id))
