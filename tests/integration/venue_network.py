"""A venue network to test `drem up --lan` on: a network namespace joined to this machine by a veth pair.

This machine (the organiser's laptop) gets `laptop_address` on its end; everything run with `venue.run(...)` is a
device on the venue WiFi (a racer's phone, a timer): it has its own loopback, so it can reach the laptop only
through that address, exactly like a phone can. Only addresses inside the namespace and the veth pair we create are
used; both are removed afterwards. Needs root (CAP_NET_ADMIN) and `ip`.
"""
from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass


@dataclass(frozen=True)
class VenueNetwork:
    namespace: str
    laptop_address: str
    device_address: str

    def run(self, argv: list[str], timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
        """Run `argv` on a device of the venue network."""
        return subprocess.run(["ip", "netns", "exec", self.namespace, *argv], capture_output=True, text=True,
                              timeout=timeout)


def can_create() -> str | None:
    """None when a venue network can be made here; otherwise why not."""
    if os.geteuid() != 0:
        return "creating a network namespace needs root"
    if shutil.which("ip") is None:
        return "the `ip` tool (iproute2) is not installed"
    return None


@contextmanager
def venue_network() -> Iterator[VenueNetwork]:
    tag = f"{os.getpid() % 100000:05d}"
    namespace, laptop_end, device_end = f"drem-venue-{tag}", f"drl{tag}", f"drv{tag}"
    # A /30 in 10.213.0.0/16 picked by pid, so two test runs at once do not collide.
    slot = os.getpid() % 16384
    subnet = f"10.213.{slot // 64}"
    laptop_address, device_address = f"{subnet}.{(slot % 64) * 4 + 1}", f"{subnet}.{(slot % 64) * 4 + 2}"
    steps = [
        ["ip", "netns", "add", namespace],
        ["ip", "link", "add", laptop_end, "type", "veth", "peer", "name", device_end],
        ["ip", "link", "set", device_end, "netns", namespace],
        ["ip", "addr", "add", f"{laptop_address}/30", "dev", laptop_end],
        ["ip", "link", "set", laptop_end, "up"],
        ["ip", "netns", "exec", namespace, "ip", "addr", "add", f"{device_address}/30", "dev", device_end],
        ["ip", "netns", "exec", namespace, "ip", "link", "set", device_end, "up"],
        ["ip", "netns", "exec", namespace, "ip", "link", "set", "lo", "up"],
    ]
    try:
        for step in steps:
            subprocess.run(step, check=True, capture_output=True, text=True, timeout=30)
        yield VenueNetwork(namespace, laptop_address, device_address)
    finally:
        subprocess.run(["ip", "link", "del", laptop_end], capture_output=True, timeout=30)
        subprocess.run(["ip", "netns", "del", namespace], capture_output=True, timeout=30)
