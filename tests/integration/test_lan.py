"""`drem up --host ADDR` on a venue network, tried from a device on that network (tests/integration/venue_network.py).

What people on the WiFi must get: the app at the announced URL, in the QR code and in the activation command; a
racer's model upload working through the app; and no way at all to the storage server, which stays on loopback.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from drem_local.stack import free_port, read_stack_file
from tests.integration.venue_network import can_create, venue_network
from tests.stack_fixtures import read_until

pytestmark = pytest.mark.integration

DREM = Path(sys.executable).parent / "drem"

# Runs on the device: signs in, makes what it needs, and reports what a person there would see.
DEVICE_SCRIPT = r"""
import json, re, sys, requests
app, storage_port, password, archive = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
seen = {"health": requests.get(app + "/healthz", timeout=10).status_code}
bearer = {"Authorization": "Bearer " + requests.post(app + "/api/auth/token", timeout=10,
          json={"username": "admin", "password": password}).json()["access_token"]}
fleet = requests.post(app + "/api/fleets", json={"name": "Venue timers"}, headers=bearer, timeout=10).json()
page = requests.post(app + "/console/cars/activate", headers=bearer, timeout=10, data={
    "fleet_id": fleet["fleet_id"], "hostname": "timer-1", "device_kind": "timer", "ttl_minutes": "60"})
command = re.search(r'data-testid="activation-command">([^<]*)<', page.text)
seen["activation_command"] = command.group(1) if command else page.text[:500]
event = requests.post(app + "/api/events", headers=bearer, timeout=10, json={
    "name": "LAN Cup", "event_type": "AWS_SUMMIT", "date": "2026-05-14", "country_code": "DE",
    "tracks": [{"track_id": "1", "fleet_id": fleet["fleet_id"]}]}).json()
board = requests.get(app + "/leaderboard/" + event["event_id"], timeout=10).text
url = re.search(r'class="qr-url">([^<]*)<', board)
seen["qr_url"] = url.group(1).replace("&amp;", "&") if url else None
ticket = requests.post(app + "/api/models", json={"filename": "lan_model.tar.gz"}, headers=bearer, timeout=10).json()
seen["upload_url"] = ticket["upload"]["url"]
posted = requests.post(ticket["upload"]["url"], data=ticket["upload"]["fields"], timeout=30,
                       files={"file": ("lan_model.tar.gz", open(archive, "rb").read())})
seen["upload_status"] = posted.status_code
done = requests.post(app + "/api/models/" + ticket["model"]["model_id"] + "/complete", json={}, headers=bearer,
                     timeout=30).json()
seen["model_status"] = done["model"]["status"]
host = app.split("//")[1].split(":")[0]
for name, target in (("storage_on_lan", (host, storage_port)),
                     ("storage_on_own_loopback", ("127.0.0.1", storage_port))):
    try:
        requests.get("http://%s:%d/_drem/health" % target, timeout=3)
        seen[name] = "answered"
    except requests.ConnectionError:
        seen[name] = "unreachable"
print(json.dumps(seen))
"""


@pytest.fixture(scope="module")
def venue():
    reason = can_create()
    if reason:
        # A developer without root may skip it (and is told why); CI runs as root and must never skip it.
        if os.environ.get("CI"):
            pytest.fail(f"CI must test serving the venue network, but cannot create one: {reason}")
        pytest.skip(f"no venue network to test on (needs root and iproute2): {reason}")
    with venue_network() as network:
        yield network


def _listening_addresses(port: int) -> set[str]:
    """IPv4 addresses with a socket in LISTEN on `port`, from /proc/net/tcp (what `ss -ltn` shows)."""
    found = set()
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        local, state = line.split()[1], line.split()[3]
        address, port_hex = local.split(":")
        if state == "0A" and int(port_hex, 16) == port:
            found.add(".".join(str(int(address[i:i + 2], 16)) for i in (6, 4, 2, 0)))
    return found


def test_drem_up_on_the_venue_network(venue, tmp_path):
    from tests.unit.models_helpers import onnx_archive

    app_port, storage_port = free_port(), free_port()
    state_dir = tmp_path / "state"
    archive = tmp_path / "lan_model.tar.gz"
    archive.write_bytes(onnx_archive(0.25))
    (tmp_path / "device.py").write_text(DEVICE_SCRIPT)
    up = subprocess.Popen([str(DREM), "up", "--host", venue.laptop_address, "--port", str(app_port),
                           "--storage-port", str(storage_port), "--state-dir", str(state_dir)],
                          cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        banner = read_until(up, "Press Ctrl-C", timeout=90)
        lan_url = f"http://{venue.laptop_address}:{app_port}"
        assert f"Open the app:        {lan_url}" in banner
        password = re.search(r"Admin login:\s+admin / (\S+)", banner).group(1)

        assert _listening_addresses(storage_port) == {"127.0.0.1"}
        assert _listening_addresses(app_port) == {venue.laptop_address}
        assert read_stack_file(state_dir)["urls"]["app"] == lan_url

        device = venue.run([sys.executable, str(tmp_path / "device.py"), lan_url, str(storage_port), password,
                            str(archive)], timeout=120)
        assert device.returncode == 0, device.stderr
        seen = json.loads(device.stdout.strip().splitlines()[-1])
        assert seen["health"] == 200
        assert seen["activation_command"].endswith(f"--api {lan_url}"), seen["activation_command"]
        assert seen["qr_url"].startswith(f"{lan_url}/event/"), seen["qr_url"]  # the event landing page
        assert seen["upload_url"].startswith(f"{lan_url}/_storage/")
        assert seen["upload_status"] in (200, 204) and seen["model_status"] == "AVAILABLE", seen
        assert seen["storage_on_lan"] == "unreachable" and seen["storage_on_own_loopback"] == "unreachable"
    finally:
        up.send_signal(signal.SIGINT)
        rest, _ = up.communicate(timeout=60)
    assert up.returncode == 0 and "stopped cleanly" in rest, rest


def test_drem_up_refuses_an_address_this_machine_does_not_have(tmp_path):
    result = subprocess.run([str(DREM), "up", "--host", "203.0.113.77", "--port", str(free_port()),
                             "--storage-port", str(free_port()), "--state-dir", str(tmp_path / "state")],
                            cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert "203.0.113.77 is not an IPv4 address of this machine" in result.stderr
