"""Part: timing-line crossings → strip events in the outbox (durable; the agent delivers them in order)."""
from __future__ import annotations

import uuid

from drem_cars.outbox import STRIP_EVENT, Outbox


def strip_event(event_id: str, track_id: str, timestamp_ms: int, sensor: int, device_id: str) -> dict:
    # The key is chosen once, here, and stored with the event: every redelivery repeats it.
    return {"event_id": event_id, "track_id": track_id, "timestamp_ms": int(timestamp_ms), "sensor": int(sensor),
            "idempotency_key": f"{device_id}:{timestamp_ms}:{sensor}:{uuid.uuid4().hex[:8]}"}


class StripEventsToOutbox:
    def __init__(self, outbox: Outbox, event_id: str, track_id: str, device_id: str) -> None:
        self.outbox = outbox
        self.event_id = event_id
        self.track_id = track_id
        self.device_id = device_id
        self.queued = 0

    def run(self, crossings: list[tuple[int, int]] | None) -> None:
        for timestamp_ms, sensor in crossings or []:
            body = strip_event(self.event_id, self.track_id, timestamp_ms, sensor, self.device_id)
            self.outbox.enqueue(STRIP_EVENT, body, body["idempotency_key"])
            self.queued += 1
