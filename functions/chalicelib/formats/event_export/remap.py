"""Rewriting an export's ids: every old sub to the target's new one, and the event id under `--event-id NEW`."""
from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

from chalicelib.formats.event_export.records import EVENT_SCOPED_TABLES, EventBundle, Item, sorted_items


def remap(bundle: EventBundle, sub_map: dict[str, str], event_id: str) -> EventBundle:
    """A copy with every old sub replaced by its new one, and the event id by `event_id` in event-scoped items."""
    subs = _replacer(sub_map)
    ids = _replacer({bundle.event_id: event_id})
    items = {table: [_map_strings(item, (lambda s: ids(subs(s))) if table in EVENT_SCOPED_TABLES else subs)
                     for item in table_items] for table, table_items in bundle.items.items()}
    archives = [a.model_copy(update={"key": subs(a.key)}) for a in bundle.archives]
    return EventBundle(event_id=event_id, items=items, accounts=bundle.accounts, archives=archives,
                       archive_data=bundle.archive_data, logo=bundle.logo)


def remap_items(items: list[Item], sub_map: dict[str, str]) -> list[Item]:
    """Items with subs rewritten, re-sorted by key (used to compare two exports of the same event)."""
    subs = _replacer(sub_map)
    return sorted_items([_map_strings(item, subs) for item in items])


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
