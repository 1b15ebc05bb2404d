"""Shared helpers for the model and assignment tests: real archives, the HTTP upload flow, activated cars."""
from __future__ import annotations

import gzip
import io
import json
import tarfile
import time
from dataclasses import dataclass
from typing import Any

import onnx
import requests
from onnx import TensorProto, helper

DREM_METADATA = {
    "action_space": {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.5, "high": 2.0}},
    "action_space_type": "continuous",
    "sensor": ["FRONT_FACING_CAMERA"],
    "neural_network": "DREM_SMALL_CNN",
    "training_algorithm": "behaviour_cloning",
    "version": "1",
    "drem_input": {"shape": [1, 120, 160, 1], "scale": "raw_0_255"},
}


# An ONNX IR version far beyond any that exists (IR 14 is current in 2026): every runtime refuses the file.
UNREADABLE_IR_VERSION = 10_000


def onnx_policy(bias: float = 0.0, ir_version: int | None = None) -> bytes:
    """A real ONNX graph with the car's input contract (grayscale 1x120x160x1 → 2 means); `bias` changes its bytes.

    `ir_version` overrides the file's IR version after the checker ran (the checker refuses unknown versions)."""
    image = helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 120, 160, 1])
    means = helper.make_tensor_value_info("means", TensorProto.FLOAT, [1, 2])
    weights = helper.make_tensor("weights", TensorProto.FLOAT, [120 * 160, 2], [bias] * (120 * 160 * 2))
    shape = helper.make_tensor("shape", TensorProto.INT64, [2], [1, 120 * 160])
    graph = helper.make_graph(
        [helper.make_node("Reshape", ["image", "shape"], ["flat"]),
         helper.make_node("MatMul", ["flat", "weights"], ["means"])],
        "drem_policy", [image], [means], initializer=[weights, shape])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    onnx.checker.check_model(model)
    if ir_version is not None:
        model.ir_version = ir_version
    return model.SerializeToString()


def tar_gz(members: list[tuple[str, bytes]], *, symlinks: dict[str, str] | None = None) -> bytes:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w", format=tarfile.PAX_FORMAT) as archive:
        for name, data in members:
            info = tarfile.TarInfo(name)
            info.size = len(data)
            archive.addfile(info, io.BytesIO(data))
        for name, target in (symlinks or {}).items():
            info = tarfile.TarInfo(name)
            info.type, info.linkname = tarfile.SYMTYPE, target
            archive.addfile(info)
    return gzip.compress(buffer.getvalue(), mtime=0)


def onnx_archive(bias: float = 0.0, metadata: dict | None = None, ir_version: int | None = None) -> bytes:
    return tar_gz([("model.onnx", onnx_policy(bias, ir_version)),
                   ("model_metadata.json", json.dumps(metadata or DREM_METADATA).encode())])


def archive_without_metadata() -> bytes:
    return tar_gz([("model.onnx", onnx_policy())])


def traversal_archive() -> bytes:
    return tar_gz([("model.onnx", onnx_policy()), ("model_metadata.json", json.dumps(DREM_METADATA).encode()),
                   ("../../etc/cron.d/evil", b"* * * * * root rm -rf /\n")])


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}", "Accept": "application/json", "Content-Type": "application/json"}


@dataclass
class ModelsApi:
    """One caller of the models API through the Chalice test client."""
    client: Any
    headers: dict[str, str]

    def call(self, method: str, path: str, body: Any = None) -> Any:
        payload = json.dumps(body).encode() if body is not None else b""
        return getattr(self.client.http, method.lower())(path, headers=self.headers, body=payload)

    def request_upload(self, filename: str) -> Any:
        return self.call("POST", "/api/models", {"filename": filename})

    def upload(self, filename: str, data: bytes) -> dict[str, Any]:
        """Ticket → presigned POST with requests (mock_aws answers) → the model as the ticket described it."""
        ticket = self.request_upload(filename)
        assert ticket.status_code == 201, ticket.json_body
        upload = ticket.json_body["upload"]
        posted = requests.post(upload["url"], data=upload["fields"], files={"file": (filename, data)}, timeout=10)
        assert posted.status_code in (200, 204), posted.text
        return ticket.json_body["model"]

    def upload_and_complete(self, filename: str, data: bytes) -> dict[str, Any]:
        model = self.upload(filename, data)
        done = self.complete(model["model_id"])
        assert done.status_code == 200, done.json_body
        return done.json_body["model"]

    def complete(self, model_id: str) -> Any:
        return self.call("POST", f"/api/models/{model_id}/complete")

    def list(self, query: str = "") -> Any:
        return self.call("GET", f"/api/models{query}")

    def get(self, model_id: str) -> Any:
        return self.call("GET", f"/api/models/{model_id}")

    def delete(self, model_id: str) -> Any:
        return self.call("DELETE", f"/api/models/{model_id}")


def make_fleet(fleet_id: str = "fleet-1") -> str:
    from chalicelib.domain.fleets import FleetRecord
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from chalicelib.storage.fleets import DynamoFleetStore

    store = DynamoFleetStore(clients.dynamodb(), get_settings().table("fleet"))
    store.put_fleet(FleetRecord(fleet_id=fleet_id, name=fleet_id, created_at_ms=int(time.time() * 1000),
                                created_by="test"))
    return fleet_id


def activate_device(hostname: str, fleet_id: str, kind: str = "car") -> Any:
    """A car or timer brought in through the devices area's own activation service; returns its IssuedCredential."""
    from chalicelib import services
    from chalicelib.core.principals import User
    from chalicelib.domain.activation import ActivationCodeRequest, ActivationExchange

    operator = User(sub="operator-sub", username="olga", groups=frozenset({"operator"}))
    service = services.activation_service()
    issued = service.issue_code(operator, ActivationCodeRequest(fleet_id=fleet_id, hostname=hostname,
                                                                device_kind=kind))
    return service.activate(ActivationExchange(code=issued.code, hostname=hostname, device_kind=kind))


def device_headers(credential: str) -> dict[str, str]:
    return {"Authorization": f"Device {credential}", "Accept": "application/json",
            "Content-Type": "application/json"}
