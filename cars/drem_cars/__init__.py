"""drem_cars: the car (and timer) agent — drive loop, parts, drivers, device API client, outbox."""
from __future__ import annotations

__version__ = "0.1.0"
