"""A track's racer queue in memory: the port RacerQueueService takes.

Copies chalicelib/storage/racer_queue.py (DynamoQueueStore): the queue is kept as its JSON, so a read never hands out
the stored object; `put` with expected version 0 only creates (a queue already stored fails, as
`attribute_not_exists(pk)` does), any other version must be the stored one (`version = :expected`, which a missing
queue fails too), and a failed condition raises QueueChanged.
"""
from __future__ import annotations

from chalicelib.domain.racer_queue import QueueChanged, RacerQueue


class InMemoryQueueStore:
    def __init__(self) -> None:
        self._queues: dict[tuple[str, str], tuple[int, str]] = {}  # (event, track) -> (version, the queue's JSON)

    def get(self, event_id: str, track_id: str) -> RacerQueue | None:
        found = self._queues.get((event_id, track_id))
        return RacerQueue.model_validate_json(found[1]) if found else None

    def put(self, queue: RacerQueue, *, expected_version: int) -> None:
        found = self._queues.get((queue.event_id, queue.track_id))
        if (found is not None) if expected_version == 0 else (found is None or found[0] != expected_version):
            raise QueueChanged(queue.track_id)
        self._queues[(queue.event_id, queue.track_id)] = (queue.version, queue.model_dump_json())
