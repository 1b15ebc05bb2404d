"""A car whose activation answer is lost (the app restarted, the WiFi dropped) still gets its credential: it retries
with the same attempt id and the server resumes the activation it had stored (chalicelib/domain/activation.py)."""
from __future__ import annotations

import http.server
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import requests

from drem_cars.client import DeviceClient, activate
from drem_cars.credentials import CredentialStore
from drem_local.api_client import ApiClient

pytestmark = pytest.mark.integration


class AnswerLosingProxy(http.server.ThreadingHTTPServer):
    """Forwards activations to the real app; the first one's answer is dropped (the connection closes unanswered)."""

    def __init__(self, upstream: str) -> None:
        self.upstream, self.forwarded, self.dropped = upstream, 0, 0
        super().__init__(("127.0.0.1", 0), _Forward)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server_address[1]}"


class _Forward(http.server.BaseHTTPRequestHandler):
    server: AnswerLosingProxy

    def do_POST(self) -> None:  # noqa: N802 - the stdlib's name
        body = self.rfile.read(int(self.headers.get("Content-Length", "0")))
        headers = {name: value for name, value in self.headers.items()
                   if name.lower() not in ("host", "content-length")}
        reply = requests.post(self.server.upstream + self.path, data=body, headers=headers, timeout=30)
        self.server.forwarded += 1
        if self.server.dropped == 0:
            self.server.dropped += 1
            self.close_connection = True  # the app stored it; the car never hears back
            return
        self.send_response(reply.status_code)
        self.send_header("Content-Type", reply.headers.get("Content-Type", "application/json"))
        self.send_header("Content-Length", str(len(reply.content)))
        self.end_headers()
        self.wfile.write(reply.content)

    def log_message(self, *args: object) -> None:
        pass


@pytest.fixture
def lossy(live_stack) -> Iterator[AnswerLosingProxy]:
    proxy = AnswerLosingProxy(live_stack.url)
    thread = threading.Thread(target=proxy.serve_forever, daemon=True)
    thread.start()
    yield proxy
    proxy.shutdown()


def test_a_lost_activation_answer_is_resumed_and_leaves_one_device(live_stack, lossy: AnswerLosingProxy,
                                                                   tmp_path: Path) -> None:
    admin = ApiClient(live_stack.url)
    admin.sign_in(live_stack.admin_username, live_stack.admin_password)
    fleet_id = admin.post("/api/fleets", {"name": "Lost answers"})["fleet_id"]
    code = admin.post("/api/devices/activation-codes",
                      {"fleet_id": fleet_id, "hostname": "lossy-car", "device_kind": "car"})["code"]

    store = CredentialStore(tmp_path)
    credential = activate(lossy.url, code, "lossy-car", attempt_id=store.attempt_id_for(code),
                          retry_delays_s=(0.05,))
    store.save(credential)

    assert (lossy.forwarded, lossy.dropped) == (2, 1)  # the app saw both tries; the first answer was lost
    me = DeviceClient(store, api=live_stack.url).request("GET", "/api/devices/self")
    assert (me["device_id"], me["hostname"]) == (credential.device_id, "lossy-car")
    in_fleet = [d for d in admin.get("/api/devices")["devices"] if d["fleet_id"] == fleet_id]
    assert [d["device_id"] for d in in_fleet] == [credential.device_id]


def test_a_rerun_with_the_same_code_reuses_its_attempt_until_the_credential_is_saved(tmp_path: Path) -> None:
    store = CredentialStore(tmp_path)
    first = store.attempt_id_for("ABCD-EFGH-IJKL-MNOP-QRST")
    assert store.attempt_id_for("abcd efgh ijkl mnop qrst") == first  # typed differently, same code
    assert store.attempt_id_for("ZZZZ-EFGH-IJKL-MNOP-QRST") != first
    assert (tmp_path / "activation-attempt.json").stat().st_mode & 0o077 == 0
