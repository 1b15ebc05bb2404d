"""The JSON poll's answer as a client receives it over a socket, from the live server's real aiohttp app: the bytes
built once per view (drem_live.prepared, keep-alive HTTP/1.1 GETs) are exactly what aiohttp's own `web.Response`
sends for the same view (HEAD, HTTP/1.0, `Connection: close`), apart from the Date and the connection header those
need, and a kept connection carries the next poll. Storage is a stub: only the bytes on the wire are under test."""
from __future__ import annotations

import asyncio
import json
import re
from types import SimpleNamespace
from typing import Any

import pytest
from aiohttp import web

from drem_live.limits import Limits
from drem_live.prepared import WireAnswer
from drem_live.server import make_app
from tests import coroutines

BOARD = json.dumps({"rows": [{"racer": f"racer-{n}", "best_ms": 9000 + n} for n in range(300)]}).encode()
PATH = "/live/api/leaderboard/ev-1?track=1"


class Storage:
    """AppCode's `view`: the board at version 7."""

    def view(self, _kind: str, _event_id: str, _track: str) -> Any:
        return SimpleNamespace(version=7, body=BOARD.decode())

    def changed(self, _event_id: str) -> None:
        pass


async def _exchange(port: int, requests: list[str]) -> list[tuple[str, dict[str, str], bytes]]:
    """Send `requests` on one connection (pipelined) and read one answer per request: (status line, headers, body)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write("".join(requests).encode())
    answers = []
    try:
        for request in requests:
            head = (await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), 30)).decode("latin-1")
            status, *lines = head[:-4].split("\r\n")
            headers = dict(line.split(": ", 1) for line in lines)
            size = 0 if request.startswith("HEAD") else int(headers.get("Content-Length", "0"))
            answers.append((status, headers, await asyncio.wait_for(reader.readexactly(size), 30)))
    finally:
        writer.close()
    return answers


def _polls(requests: list[str]) -> list[tuple[str, dict[str, str], bytes]]:
    async def run() -> list[tuple[str, dict[str, str], bytes]]:
        runner = web.AppRunner(make_app(Storage(), poll_s=60, limits=Limits()), access_log=None)  # type: ignore[arg-type]
        await runner.setup()
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        port = site._server.sockets[0].getsockname()[1]  # type: ignore[union-attr]
        try:
            return await _exchange(port, requests)
        finally:
            await runner.cleanup()
    return coroutines.run(run())


def _get(if_none_match: str, version: str = "1.1", extra: str = "", method: str = "GET") -> str:
    return f"{method} {PATH} HTTP/{version}\r\nHost: x\r\nIf-None-Match: {if_none_match}\r\n{extra}\r\n"


def _without_date(headers: dict[str, str]) -> dict[str, str]:
    assert re.fullmatch(r"\w{3}, \d\d \w{3} \d{4} \d\d:\d\d:\d\d GMT", headers.pop("Date"))
    return headers


@pytest.mark.parametrize(("if_none_match", "status"), [('"v0"', "200 OK"), ('"v7"', "304 Not Modified")])
def test_a_kept_poll_gets_the_same_answer_as_aiohttp_builds_and_its_connection_carries_the_next(
        if_none_match: str, status: str) -> None:
    kept, again = _polls([_get(if_none_match), _get(if_none_match)])
    [closing] = _polls([_get(if_none_match, extra="Connection: close\r\n")])
    [old_client] = _polls([_get(if_none_match, version="1.0")])
    assert kept[0] == f"HTTP/1.1 {status}" and again == kept
    assert _without_date(closing[1]).pop("Connection") == "close"
    assert (kept[0], _without_date(kept[1]), kept[2]) == closing
    assert _without_date(old_client[1]) == kept[1] and old_client[2] == kept[2]
    assert kept[1]["ETag"] == '"v7"' and kept[1]["Cache-Control"] == "no-cache"
    assert kept[1]["X-Content-Type-Options"] == "nosniff" and kept[1]["Access-Control-Allow-Origin"] == "*"
    if status.startswith("200"):
        assert kept[2] == BOARD and kept[1]["Content-Type"] == "application/json"
    else:
        assert kept[2] == b"" and "Content-Length" not in kept[1] and "Content-Type" not in kept[1]


def test_head_answers_the_headers_of_a_get_without_its_body() -> None:
    head, get = _polls([_get('"v0"', method="HEAD"), _get('"v0"')])
    assert head[0] == "HTTP/1.1 200 OK" and head[2] == b""
    assert _without_date(head[1]) == _without_date(get[1])


def test_a_header_value_that_would_end_the_head_early_is_refused() -> None:
    with pytest.raises(ValueError, match="refusing to send the header"):
        WireAnswer(200, {"ETag": '"v1"\r\nSet-Cookie: taken=1'}, b"{}")
