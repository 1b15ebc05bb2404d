"""Racers' model records in memory: the port ModelService (ModelStore) takes.

Copies chalicelib/storage/racer_models.py (DynamoModelStore): a record is kept as the adapter writes and reads it
back (its JSON);
`create` needs the model id free, else the transaction is refused (UpstreamError, as `call` words a cancelled
transaction); `replace` needs the stored status to be the one the writer read and, given `result_as_in`, the stored
scrutineering result to be that record's (a missing record fails too), else ModelChanged, storing nothing. An
owner's models list newest first (model ids sort by creation), without DELETED ones unless asked; the listing of
every model is by upload time, newest first, and leaves DELETED ones out. Pages hold at most `limit` records read
(a filtered-out one still counts, as DynamoDB's Limit does) and a page token is good only for the listing that gave
it (else InvalidInput naming `next`).
"""
from __future__ import annotations

import base64
import json
from collections.abc import Callable

from chalicelib.core.errors import InvalidInput, UpstreamError
from chalicelib.domain.racer_models import ModelChanged, ModelPage, ModelRecord, ModelStatus


class InMemoryModelStore:
    def __init__(self) -> None:
        self._records: dict[str, str] = {}  # model id -> the record's JSON (the owner is inside)

    # -- writes --
    def create(self, record: ModelRecord) -> None:
        if record.model_id in self._records:
            raise UpstreamError("The model store refused the request (TransactionCanceledException).")
        self._records[record.model_id] = _as_stored(record)

    def replace(self, record: ModelRecord, *, expected_status: ModelStatus,
                result_as_in: ModelRecord | None = None) -> None:
        stored = self.get(record.owner_sub, record.model_id)
        if (stored is None or stored.status is not expected_status
                or (result_as_in is not None and stored.scrutineer_result != result_as_in.scrutineer_result)):
            raise ModelChanged(record.model_id)
        self._records[record.model_id] = _as_stored(record)

    # -- reads --
    def get(self, owner_sub: str, model_id: str) -> ModelRecord | None:
        found = self.get_by_id(model_id)
        return found if found is not None and found.owner_sub == owner_sub else None

    def owner_of(self, model_id: str) -> str | None:
        found = self.get_by_id(model_id)
        return found.owner_sub if found else None

    def get_by_id(self, model_id: str) -> ModelRecord | None:
        found = self._records.get(model_id)
        return ModelRecord.model_validate_json(found) if found else None

    def list_owner(self, owner_sub: str, *, limit: int, next_token: str | None,
                   include_deleted: bool = False) -> ModelPage:
        owned = sorted((r for r in self._all() if r.owner_sub == owner_sub), key=lambda r: r.model_id, reverse=True)
        return _page(owned, [r.model_id for r in owned], f"owner:{owner_sub}", limit, next_token,
                     keep=lambda r: include_deleted or r.status is not ModelStatus.DELETED)

    def list_all(self, *, limit: int, next_token: str | None) -> ModelPage:
        listed = sorted((r for r in self._all() if r.status is not ModelStatus.DELETED),
                        key=lambda r: f"{r.uploaded_at}#{r.model_id}", reverse=True)
        return _page(listed, [f"{r.uploaded_at}#{r.model_id}" for r in listed], "all", limit, next_token,
                     keep=lambda r: True)

    def find_available_by_md5(self, owner_sub: str, model_md5: str) -> list[ModelRecord]:
        return sorted((r for r in self._all() if r.owner_sub == owner_sub and r.status is ModelStatus.AVAILABLE
                       and r.model_md5 == model_md5), key=lambda r: r.model_id)

    def _all(self) -> list[ModelRecord]:
        return [ModelRecord.model_validate_json(doc) for doc in self._records.values()]


def _as_stored(record: ModelRecord) -> str:
    return record.model_dump_json()


def _page(records: list[ModelRecord], keys: list[str], listing: str, limit: int, next_token: str | None,
          keep: Callable[[ModelRecord], bool]) -> ModelPage:
    start = 0
    if next_token:
        after = _decode(next_token, listing)
        start = next((i for i, key in enumerate(keys) if key < after), len(keys))  # newest first: keys descend
    read = records[start:start + limit]
    more = start + limit < len(records)
    token = _encode(listing, keys[start + limit - 1]) if more else None
    return ModelPage(models=[r for r in read if keep(r)], next_token=token)


def _encode(listing: str, key: str) -> str:
    return base64.urlsafe_b64encode(json.dumps([listing, key]).encode()).decode().rstrip("=")


def _decode(token: str, listing: str) -> str:
    try:
        plain = json.loads(base64.urlsafe_b64decode(token + "=" * (-len(token) % 4)))
    except ValueError:
        plain = None
    if not (isinstance(plain, list) and len(plain) == 2 and plain[0] == listing and isinstance(plain[1], str)):
        raise InvalidInput("This page token is not valid here; start again from the first page.", field="next")
    return plain[1]
