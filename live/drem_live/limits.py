"""What one venue-WiFi attacker may take from the live server: streams in total and per client address, channels
(distinct option sets, each one a storage reader), and the size of a request's query. Beyond a cap the answer is a
clear 503 with Retry-After (the page then falls back to polling the app); nothing queues.
"""
from __future__ import annotations

import os
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Limits:
    max_streams: int = 5000
    max_streams_per_client: int = 64
    max_channels: int = 256
    max_query_bytes: int = 1024
    # Behind a proxy that names the viewer (CloudFront: CloudFront-Viewer-Address), the header to count clients by.
    client_address_header: str = ""

    @classmethod
    def from_env(cls, env: Mapping[str, str]) -> Limits:
        def number(name: str, default: int) -> int:
            value = env.get(name, "")
            return int(value) if value.isdigit() else default

        defaults = cls()
        return cls(max_streams=number("DREM_LIVE_MAX_STREAMS", defaults.max_streams),
                   max_streams_per_client=number("DREM_LIVE_MAX_STREAMS_PER_CLIENT", defaults.max_streams_per_client),
                   max_channels=number("DREM_LIVE_MAX_CHANNELS", defaults.max_channels),
                   client_address_header=env.get("DREM_LIVE_CLIENT_ADDRESS_HEADER", ""))


@dataclass
class StreamCount:
    limits: Limits
    total: int = 0
    by_client: Counter[str] = field(default_factory=Counter)

    def refusal(self, client: str) -> str | None:
        """Why a new stream from `client` is refused now, or None to accept it."""
        if self.total >= self.limits.max_streams:
            return f"the live server is full ({self.limits.max_streams} viewers)"
        if self.by_client[client] >= self.limits.max_streams_per_client:
            return f"too many live streams from one address (at most {self.limits.max_streams_per_client})"
        return None

    def open(self, client: str) -> None:
        self.total += 1
        self.by_client[client] += 1

    def close(self, client: str) -> None:
        self.total -= 1
        self.by_client[client] -= 1
        if self.by_client[client] <= 0:
            del self.by_client[client]


def env_limits() -> Limits:
    return Limits.from_env(os.environ)
