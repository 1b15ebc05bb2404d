"""`drem models upload` and `drem league push` when the server answers /complete before the check ended (it waits
25 s: chalicelib.domain.model_checks): the CLI reads the model again until the verdict, instead of reporting an
UPLOADED model as refused. Over a stand-in API that answers as the server does."""
from __future__ import annotations

from typing import Any

import pytest

from drem_local.commands.models import completed

pytestmark = pytest.mark.unit


class StillCheckingApi:
    """/complete answers UPLOADED; the model's GET says UPLOADED `reads_until_done` times, then AVAILABLE."""

    def __init__(self, reads_until_done: int) -> None:
        self.reads_until_done = reads_until_done
        self.calls: list[tuple[str, str]] = []

    def _model(self, status: str) -> dict[str, Any]:
        return {"model": {"model_id": "m1", "name": "fast", "status": status}}

    def post(self, path: str, body: Any = None) -> dict[str, Any]:
        self.calls.append(("POST", path))
        return self._model("UPLOADED")

    def get(self, path: str) -> dict[str, Any]:
        self.calls.append(("GET", path))
        self.reads_until_done -= 1
        return self._model("UPLOADED" if self.reads_until_done > 0 else "AVAILABLE")


def test_a_check_still_running_is_waited_for(capsys: pytest.CaptureFixture[str]) -> None:
    api = StillCheckingApi(reads_until_done=2)
    model = completed(api, "m1", timeout_s=30)
    assert model["status"] == "AVAILABLE"
    assert api.calls == [("POST", "/api/models/m1/complete"), ("GET", "/api/models/m1"), ("GET", "/api/models/m1")]
    assert "checking the archive" in capsys.readouterr().err


def test_a_check_that_never_ends_is_reported_as_it_stands() -> None:
    api = StillCheckingApi(reads_until_done=10_000)
    assert completed(api, "m1", timeout_s=0.0)["status"] == "UPLOADED"
