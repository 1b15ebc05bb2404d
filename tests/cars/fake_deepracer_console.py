"""A stand-in DeepRacer device console, written from the documented API (not from our client).

GET / sets a Flask-style session cookie and embeds a CSRF token bound to it in `<meta name="csrf-token">`; POST /login
with the right password sets `deepracer_token`; every /api call needs that cookie and the session's token in
`X-CSRFToken` (400 "CSRF token missing/invalid" otherwise, 401 without the login cookie).
"""
from __future__ import annotations

import json
from email import policy
from email.parser import BytesParser
import secrets
import threading
from http.cookies import SimpleCookie
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import parse_qs


class ConsoleState:
    def __init__(self, password: str) -> None:
        self.password = password
        self.sessions: dict[str, str] = {}  # session id → csrf token
        self.tokens: set[str] = set()
        self.calls: list[tuple[str, str, object]] = []
        self.uploads: dict[str, bytes] = {}
        self.battery_level = 7


def make_handler(state: ConsoleState) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        def log_message(self, *args: object) -> None: ...

        def _cookies(self) -> dict[str, str]:
            jar = SimpleCookie(self.headers.get("Cookie", ""))
            return {k: v.value for k, v in jar.items()}

        def _send(self, status: int, body: object, cookies: dict[str, str] | None = None,
                  content_type: str = "application/json") -> None:
            data = body if isinstance(body, bytes) else json.dumps(body).encode()
            self.send_response(status)
            self.send_header("Content-Type", content_type)
            self.send_header("Content-Length", str(len(data)))
            for name, value in (cookies or {}).items():
                self.send_header("Set-Cookie", f"{name}={value}; Path=/; HttpOnly")
            self.end_headers()
            self.wfile.write(data)

        def _body(self) -> bytes:
            return self.rfile.read(int(self.headers.get("Content-Length") or 0))

        def do_GET(self) -> None:
            if self.path == "/":
                sid, token = secrets.token_hex(8), secrets.token_hex(16)
                state.sessions[sid] = token
                page = f'<html><head><meta name="csrf-token" content="{token}"></head><body>DeepRacer</body></html>'
                return self._send(200, page.encode(), {"session": sid}, "text/html")
            self._api("GET", b"")

        def do_POST(self) -> None:
            body = self._body()
            if self.path == "/login":
                form = parse_qs(body.decode())
                if self._csrf_ok() and form.get("password") == [state.password]:
                    token = secrets.token_hex(16)
                    state.tokens.add(token)
                    return self._send(200, {"success": True}, {"deepracer_token": token})
                return self._send(401, {"success": False, "reason": "bad password"})
            self._api("POST", body)

        def do_PUT(self) -> None:
            self._api("PUT", self._body())

        def _csrf_ok(self) -> bool:
            sid = self._cookies().get("session")
            return sid in state.sessions and self.headers.get("X-CSRFToken", state.sessions[sid]) == state.sessions[sid]

        def _api(self, method: str, body: bytes) -> None:
            cookies = self._cookies()
            if cookies.get("deepracer_token") not in state.tokens:
                return self._send(401, {"success": False, "reason": "login required"})
            sid = cookies.get("session")
            if sid not in state.sessions or self.headers.get("X-CSRFToken") != state.sessions[sid]:
                return self._send(400, {"success": False, "reason": "The CSRF token is missing or invalid."})
            path = self.path
            if path == "/api/uploadModels" and method in ("PUT", "POST"):
                head = f"Content-Type: {self.headers['Content-Type']}\r\n\r\n".encode()
                message = BytesParser(policy=policy.default).parsebytes(head + body)
                part = next(p for p in message.iter_parts() if p.get_param("name", header="content-disposition") == "file")
                filename = part.get_filename() or ""
                if not filename.endswith(".tar.gz"):
                    return self._send(200, {"success": False, "reason": "only .tar.gz"})
                state.uploads[filename[: -len(".tar.gz")]] = part.get_payload(decode=True)
                state.calls.append((method, path, filename))
                return self._send(200, {"success": True, "message": "done-upload"})
            if path.startswith("/api/models/") and method in ("PUT", "POST"):
                folder = path.split("/")[3]
                state.calls.append((method, path, None))
                if folder not in state.uploads:
                    return self._send(200, {"success": False, "reason": f"no model {folder}"})
                return self._send(200, {"success": True})
            if path == "/api/get_battery_level" and method == "GET":
                return self._send(200, {"success": True, "battery_level": state.battery_level})
            if path in ("/api/drive_mode", "/api/start_stop", "/api/max_nav_throttle", "/api/set_led_color"):
                state.calls.append((method, path, json.loads(body or b"{}")))
                return self._send(200, {"success": True})
            return self._send(404, {"success": False, "reason": "not found"})

    return Handler


class FakeConsole:
    def __init__(self, password: str = "car-password") -> None:
        self.state = ConsoleState(password)
        self.server = ThreadingHTTPServer(("127.0.0.1", 0), make_handler(self.state))
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    def __enter__(self) -> FakeConsole:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.server.shutdown()
        self.server.server_close()
