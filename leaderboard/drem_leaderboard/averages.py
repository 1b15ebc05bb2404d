"""Rolling averages: every run of X consecutive valid laps, in lap order, is one window."""
from __future__ import annotations

from collections.abc import Sequence
from decimal import ROUND_HALF_UP, Decimal
from typing import Protocol

from pydantic import BaseModel, ConfigDict, Field


class AverageWindow(BaseModel):
    model_config = ConfigDict(frozen=True)

    start_lap_id: int = Field(ge=0)
    end_lap_id: int = Field(ge=0)
    avg_ms: int = Field(ge=0, description="mean lap time of the window, rounded half up to whole ms like DREM")
    achieved_at_ms: int = Field(ge=0, description="server clock when the window's last lap ended")


class _LapLike(Protocol):
    @property
    def lap_id(self) -> int: ...
    @property
    def time_ms(self) -> int: ...
    @property
    def is_valid(self) -> bool: ...
    @property
    def captured_at_ms(self) -> int: ...


def rounded_mean_ms(times_ms: Sequence[int]) -> int:
    # Decimal avoids float half-to-even surprises: a mean of 1000.5 ms rounds to 1001 as DREM's Math.round does.
    mean = Decimal(sum(times_ms)) / Decimal(len(times_ms))
    return int(mean.quantize(Decimal(1), rounding=ROUND_HALF_UP))


def average_windows(laps: Sequence[_LapLike], window: int) -> list[AverageWindow]:
    """Windows of ``window`` consecutive laps that are all valid; an invalid lap breaks the run."""
    if window < 1:
        raise ValueError("the average window must be at least one lap")
    ordered = sorted(laps, key=lambda lap: lap.lap_id)
    result: list[AverageWindow] = []
    for start in range(len(ordered) - window + 1):
        run = ordered[start : start + window]
        if all(lap.is_valid for lap in run):
            result.append(
                AverageWindow(
                    start_lap_id=run[0].lap_id,
                    end_lap_id=run[-1].lap_id,
                    avg_ms=rounded_mean_ms([lap.time_ms for lap in run]),
                    achieved_at_ms=run[-1].captured_at_ms,
                )
            )
    return result


def fastest_window(windows: Sequence[AverageWindow]) -> AverageWindow | None:
    """The lowest average; on equal averages the one achieved first wins."""
    return min(windows, key=lambda w: (w.avg_ms, w.achieved_at_ms, w.start_lap_id), default=None)
