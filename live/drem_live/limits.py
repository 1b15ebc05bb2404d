"""What one venue-WiFi attacker may take from the live server, designed for a crowd behind one address (issue 27).

A venue's phones often share one public address (a NAT; CloudFront then names that one address for all of them), so
a cap per address turns spectators away. Admission is by page instead:
- streams: a global cap (`max_streams`); once the server is past `PRESSURE` of it, a new stream is admitted only to
  a channel (page and options) holding less than its fair share (`max_streams / open channels`), so one page flooded
  by an attacker cannot crowd out the others; at the cap everyone is shed alike. A per-address cap exists for a LAN
  of distinct addresses (`max_streams_per_client`), off by default.
- channels (distinct option sets, each one a storage reader): at most `max_channels_per_page` option sets of one page
  (kind and event) within the global `max_channels`, so made-up option sets of one page cannot take every channel;
  joining an option set already open is always free (the board everybody watches is one channel).
Beyond a cap the answer is a clear 503 with Retry-After (the page then falls back to polling the app); nothing queues.
"""
from __future__ import annotations

import os
from collections import Counter
from collections.abc import Hashable, Mapping
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Limits:
    max_streams: int = 5000
    max_streams_per_client: int = 0  # 0: no per-address cap (a venue behind one NAT is one address)
    max_channels: int = 256
    max_channels_per_page: int = 16
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
                   max_channels_per_page=number("DREM_LIVE_MAX_CHANNELS_PER_PAGE", defaults.max_channels_per_page),
                   client_address_header=env.get("DREM_LIVE_CLIENT_ADDRESS_HEADER", ""))


PRESSURE = 0.8  # past this share of max_streams, new streams go only to channels under their fair share


@dataclass
class StreamCount:
    limits: Limits
    total: int = 0
    by_client: Counter[str] = field(default_factory=Counter)
    by_channel: Counter[Hashable] = field(default_factory=Counter)

    def refusal(self, client: str, channel: Hashable | None = None, open_channels: int = 1) -> str | None:
        """Why a new stream from `client` to `channel` is refused now, or None to accept it."""
        limits = self.limits
        if self.total >= limits.max_streams:
            return f"the live server is full ({limits.max_streams} viewers)"
        if limits.max_streams_per_client and self.by_client[client] >= limits.max_streams_per_client:
            return f"too many live streams from one address (at most {limits.max_streams_per_client})"
        if self.total >= limits.max_streams * PRESSURE and channel is not None:
            share = limits.max_streams // max(1, open_channels + (channel not in self.by_channel))
            if self.by_channel[channel] >= share:
                return f"the live server is nearly full and this page already has its share ({share} viewers)"
        return None

    def open(self, client: str, channel: Hashable | None = None) -> None:
        self.total += 1
        self.by_client[client] += 1
        if channel is not None:
            self.by_channel[channel] += 1

    def close(self, client: str, channel: Hashable | None = None) -> None:
        self.total -= 1
        self.by_client[client] -= 1
        if self.by_client[client] <= 0:
            del self.by_client[client]
        if channel is not None:
            self.by_channel[channel] -= 1
            if self.by_channel[channel] <= 0:
                del self.by_channel[channel]


def env_limits() -> Limits:
    return Limits.from_env(os.environ)
