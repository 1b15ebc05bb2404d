"""Issue 27, item 4: the app server (waitress in front of the Chalice app, drem_local.http_front) against what a racer
on the venue WiFi did to Chalice's development server: half-sent requests holding every thread, 400 MiB bodies read
into memory before any check, every caller reported as 127.0.0.1, and TRACE/QUERY answered 501 by http.server."""
from __future__ import annotations

import json
import socket
import time
from urllib.parse import urlsplit

import pytest
import requests

from tests.waiting import wait_until

pytestmark = pytest.mark.integration

MIB = 1024 * 1024


def _address(url: str) -> tuple[str, int]:
    parts = urlsplit(url)
    assert parts.hostname is not None and parts.port is not None
    return parts.hostname, parts.port


def _rss_bytes(pid: int) -> int:
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS")


def _connect(url: str, source: str = "127.0.0.1") -> socket.socket:
    sock = socket.create_connection(_address(url), timeout=30, source_address=(source, 0))
    return sock


def _status_of(sock: socket.socket) -> int:
    head = b""
    while b"\r\n" not in head:
        chunk = sock.recv(4096)
        if not chunk:
            break
        head += chunk
    return int(head.split(b" ", 2)[1]) if head.startswith(b"HTTP/") else 0


def _closed_by_server(sock: socket.socket) -> bool:
    sock.setblocking(False)
    try:
        return sock.recv(4096) == b""
    except BlockingIOError:
        return False
    except OSError:
        return True


def test_half_sent_requests_hold_no_worker_and_are_cut_off(live_stack) -> None:
    """500 half-sent requests held 500 threads for over 60 s: now they hold sockets only, and are closed at the
    header deadline, while everyone else is served."""
    slow = []
    for _ in range(500):
        sock = _connect(live_stack.url)
        sock.sendall(b"GET /login HTTP/1.1\r\nHost: venue\r\nX-Slow: ")
        slow.append(sock)
    try:
        started = time.monotonic()
        for _ in range(20):  # far more than the worker threads: none of them is held by the half-sent requests
            assert requests.get(live_stack.url + "/login", timeout=10).status_code == 200
        assert time.monotonic() - started < 30

        def all_cut() -> bool:
            for sock in slow:
                if sock.fileno() != -1 and not _closed_by_server(sock):
                    sock.send(b"a")  # trickle: never idle, yet past the header deadline
                    return False
            return True

        wait_until(all_cut, timeout_s=90, what="the server to close every half-sent request", poll_s=1.0)
    finally:
        for sock in slow:
            sock.close()


@pytest.mark.parametrize("path", ["/api/auth/token", "/_storage/drem-local-models"])
def test_a_400_mib_body_is_refused_before_it_is_read(live_stack, path) -> None:
    """400 MiB to /api/auth/token grew the app by 400 MB, and to the storage gateway grew storage by 400 MB."""
    app_rss, storage_rss = _rss_bytes(live_stack.running.app.pid), _rss_bytes(live_stack.running.storage.pid)
    sock = _connect(live_stack.url)
    sock.sendall((f"POST {path} HTTP/1.1\r\nHost: venue\r\nContent-Type: multipart/form-data; boundary=x\r\n"
                  f"Content-Length: {400 * MIB}\r\n\r\n").encode())
    sent = 0
    try:
        block = b"\0" * MIB
        sock.settimeout(10)
        while sent < 400 * MIB:
            sock.sendall(block)
            sent += len(block)
    except OSError:
        pass  # the server answered and closed: what we want
    status = _status_of(sock) if sock.fileno() != -1 else 0
    sock.close()

    assert status == 413
    assert sent < 64 * MIB, f"the server read {sent // MIB} MiB before refusing"
    assert _rss_bytes(live_stack.running.app.pid) - app_rss < 50 * MIB
    assert _rss_bytes(live_stack.running.storage.pid) - storage_rss < 50 * MIB


def test_an_app_route_body_over_20_mib_is_refused(live_stack) -> None:
    too_big = requests.post(live_stack.url + "/api/auth/token", data=b"x" * (21 * MIB),
                            headers={"Content-Type": "application/json"}, timeout=60)
    assert too_big.status_code == 413


@pytest.mark.parametrize("method", ["TRACE", "QUERY", "PROPFIND"])
def test_unusual_methods_get_the_apps_answer_not_a_dev_server_501(live_stack, method) -> None:
    answer = requests.request(method, live_stack.url + "/api/events", timeout=10)
    assert answer.status_code == 405, (answer.status_code, answer.text[:200])
    assert answer.json()["Code"] == "MethodNotAllowedError"  # Chalice's own answer, as on API Gateway


def _token(url: str, username: str, password: str, source: str, forwarded_for: str | None = None) -> int:
    body = json.dumps({"username": username, "password": password}).encode()
    extra = f"X-Forwarded-For: {forwarded_for}\r\n" if forwarded_for else ""
    sock = _connect(url, source)
    try:
        sock.sendall((f"POST /api/auth/token HTTP/1.1\r\nHost: venue\r\nContent-Type: application/json\r\n{extra}"
                      f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n").encode() + body)
        return _status_of(sock)
    finally:
        sock.close()


def test_limits_see_each_phones_real_address_and_ignore_a_forged_forwarded_for(live_stack) -> None:
    """Every caller was 127.0.0.1. Now one phone (127.0.0.23) spraying wrong passwords is slowed on its own; another
    phone (127.0.0.24) is not, and naming that phone in X-Forwarded-For does not move the sprayer's count there."""
    sprayer, other = "127.0.0.23", "127.0.0.24"
    answers = [_token(live_stack.url, f"made-up-{n}", "Wrong-Pass-1", sprayer, forwarded_for=other)
               for n in range(31)]

    assert answers.count(401) == 30 and answers[-1] == 429
    assert _token(live_stack.url, "made-up-x", "Wrong-Pass-1", other) == 401
    assert _token(live_stack.url, live_stack.admin_username, live_stack.admin_password, sprayer) == 200
