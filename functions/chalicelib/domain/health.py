"""What /healthz reports. Storage is the one hard dependency: if it cannot be reached the app is not healthy."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pydantic import BaseModel


class HealthReport(BaseModel):
    status: str
    storage: str
    region: str
    stage: str
    tables: str
    state_dir: dict[str, Any] | str | None = None

    @property
    def healthy(self) -> bool:
        return self.status == "ok"


def check_health(*, storage_label: str, region: str, stage: str, probe_table: Callable[[], str],
                 durable_health: Callable[[], dict[str, Any] | str] | None) -> HealthReport:
    tables = probe_table()
    state_dir = durable_health() if durable_health is not None else None
    status = "ok" if tables == "ok" else ("unavailable" if tables == "unreachable" else "degraded")
    return HealthReport(status=status, storage=storage_label, region=region, stage=stage, tables=tables,
                        state_dir=state_dir)
