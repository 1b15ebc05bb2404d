"""Console / DRfC archives at upload: validated as the car validates them, converted to ONNX for scrutineering in a
contained worker, the original archive kept byte for byte for stock cars."""
from __future__ import annotations

import hashlib
from typing import Any

import numpy as np
import pytest

from chalicelib import services
from chalicelib.core.principals import User
from chalicelib.domain.model_conversion import ConsoleConverter, ConversionLimits
from chalicelib.domain.racer_models import ModelStatus, UploadRequest
from tests import console_fixture

pytestmark = pytest.mark.unit

ALICE = User(sub="sub-alice", username="alice", groups=frozenset({"racer"}))


def _upload(aws_clients: Any, stack: Any, data: bytes, name: str, **options: Any):
    service = services.model_service(**options)
    ticket = service.request_upload(ALICE, UploadRequest(filename=f"{name}.tar.gz"))
    aws_clients.s3.put_object(Bucket=stack.buckets["models"], Key=ticket.model.upload_key, Body=data)
    return service, service.complete(ALICE, ticket.model.model_id)


def _object(aws_clients: Any, stack: Any, key: str) -> bytes:
    return aws_clients.s3.get_object(Bucket=stack.buckets["models"], Key=key)["Body"].read()


def test_a_console_model_is_available_converted_and_its_archive_untouched(stack: Any, aws_clients: Any) -> None:
    original = console_fixture.require_fixture().read_bytes()

    service, model = _upload(aws_clients, stack, original, "console-shallow")

    assert model.status is ModelStatus.AVAILABLE, model.reason
    assert model.model_kind == "tensorflow" and model.scrutiny == "ready", model.scrutiny_reason
    assert model.conversion_max_diff is not None and model.conversion_max_diff <= 1e-4
    stored = _object(aws_clients, stack, model.s3_key)
    assert hashlib.md5(stored).hexdigest() == hashlib.md5(original).hexdigest(), "a stock car gets the upload as is"
    assert model.converted_key == model.s3_key.removesuffix(".tar.gz") + ".onnx"
    converted = _object(aws_clients, stack, model.converted_key)
    from drem_sim.console.convert import onnx_session

    session = onnx_session(converted)
    frames = np.load(console_fixture.FRAMES).astype(np.float32)
    outputs = session.run(None, {session.get_inputs()[0].name: frames})[0]
    assert np.max(np.abs(outputs - np.load(console_fixture.EXPECTED))) <= 1e-5
    public = model.public()
    assert public["scrutiny"] == "ready" and "converted_key" not in public
    assert service.get(ALICE, model.model_id).scrutiny == "ready"  # stored, not just returned


def test_checking_a_console_upload_reads_its_archive_from_storage_once(stack: Any, aws_clients: Any) -> None:
    """The inspection and the conversion share one copy: the app (which also answers the public board) does not
    fetch tens of MB twice while the upload is checked."""
    service = services.model_service()
    ticket = service.request_upload(ALICE, UploadRequest(filename="console-once.tar.gz"))
    aws_clients.s3.put_object(Bucket=stack.buckets["models"], Key=ticket.model.upload_key,
                              Body=console_fixture.require_fixture().read_bytes())
    reads: list[str] = []
    real_download = service.files.download_bounded

    def counted(key: str, *, limit: int) -> Any:
        reads.append(key)
        return real_download(key, limit=limit)

    service.files.download_bounded = counted  # type: ignore[method-assign]

    model = service.complete(ALICE, ticket.model.model_id)

    assert model.status is ModelStatus.AVAILABLE and model.scrutiny == "ready", model.scrutiny_reason
    assert reads == [ticket.model.upload_key]


def test_a_stereo_model_races_on_a_stock_car_but_cannot_be_scrutineered(stack: Any, aws_clients: Any) -> None:
    data = console_fixture.console_archive(metadata={"sensor": ["STEREO_CAMERAS"]}, flat=True)  # DROA flat layout

    _, model = _upload(aws_clients, stack, data, "stereo")

    assert model.status is ModelStatus.AVAILABLE
    assert model.scrutiny == "cannot_scrutineer"
    assert model.scrutiny_text.startswith("cannot be scrutineered: the model reads STEREO_CAMERAS")
    assert model.converted_key is None


def test_a_console_model_a_stock_car_cannot_run_is_not_raceable_in_plain_words(stack: Any, aws_clients: Any) -> None:
    whole = console_fixture.members()["agent/model.pb"]
    _, truncated = _upload(aws_clients, stack, console_fixture.console_archive(pb=whole[: len(whole) // 2]), "cut")
    assert truncated.status is ModelStatus.NOT_VALID, "not 'Ready to race'"
    assert (truncated.reason or "").startswith("a stock car cannot load this model: its agent/model.pb is damaged")
    assert "Unable to read the model" in (truncated.scrutiny_detail or ""), truncated.scrutiny_detail
    assert "core.cpp" not in (truncated.scrutiny_detail or "")
    two_actions = console_fixture.console_archive(metadata={"action_space": [
        {"steering_angle": -30, "speed": 1.0, "index": 0}, {"steering_angle": 30, "speed": 1.0, "index": 1}]})
    _, mismatched = _upload(aws_clients, stack, two_actions, "two-actions")
    assert mismatched.status is ModelStatus.NOT_VALID
    assert "2 actions in model_metadata.json but its network chooses among 9" in (mismatched.reason or "")
    assert mismatched.s3_key is None, "nothing is kept for a car to receive"


@pytest.mark.parametrize(("limits", "reason"), [
    (ConversionLimits(wall_seconds=0.05), "took longer than"),
    (ConversionLimits(memory_bytes=64 * 1024 * 1024), "the convert"),
])
def test_a_conversion_that_runs_away_or_crashes_is_contained_and_reported(
        stack: Any, aws_clients: Any, limits: ConversionLimits, reason: str) -> None:
    data = console_fixture.console_archive()

    service, model = _upload(aws_clients, stack, data, "runaway", converter=ConsoleConverter(limits))

    assert model.status is ModelStatus.AVAILABLE, "a stock car can still race it"
    assert model.scrutiny == "cannot_scrutineer" and reason in (model.scrutiny_reason or "")
    assert model.converted_key is None
    assert service.get(ALICE, model.model_id).scrutiny_reason == model.scrutiny_reason
    keys = [o["Key"] for o in aws_clients.s3.list_objects_v2(Bucket=stack.buckets["models"])["Contents"]]
    assert keys == [model.s3_key], "no upload left behind, no half-written conversion"


def test_without_the_converter_console_models_say_so(stack: Any, aws_clients: Any) -> None:
    _, model = _upload(aws_clients, stack, console_fixture.console_archive(), "no-openvino", converter=None)
    assert model.status is ModelStatus.AVAILABLE
    assert model.scrutiny_reason == "the model converter (OpenVINO) is not installed on this server"


@pytest.mark.parametrize(("metadata", "field", "words"), [
    ({"training_algorithm": "behaviour_cloning"}, "training_algorithm", "only clipped_ppo or sac"),
    ({"sensor": ["FRONT_FACING_CAMERA", "DISCRETIZED_SECTOR_LIDAR"]}, "sensor", "does not know"),
    ({"action_space_type": "continuous"}, "action_space_type", "but action_space is discrete"),
    ({"neural_network": "RESNET_50"}, "neural_network", "must be one of"),
    ({"version": "five"}, "version", "must look like"),
])
def test_console_metadata_a_car_would_refuse_is_not_valid_with_the_field_named(
        stack: Any, aws_clients: Any, metadata: dict, field: str, words: str) -> None:
    _, model = _upload(aws_clients, stack, console_fixture.console_archive(metadata=metadata), "bad-meta",
                       converter=None)
    assert model.status is ModelStatus.NOT_VALID
    assert f"{field}:" in (model.reason or "") and words in (model.reason or "")


def test_a_graph_with_an_operation_drem_cannot_translate_stays_raceable(stack: Any, aws_clients: Any,
                                                                        tmp_path: Any) -> None:
    from tests.sim.test_console_convert import _tiny_pb

    pb = _tiny_pb(tmp_path / "odd.pb", network="main", outputs=9, extra_op="Sin",
                  head="main_level/agent/main/online/network_1/ppo_head_0/policy").read_bytes()

    _, model = _upload(aws_clients, stack, console_fixture.console_archive(pb=pb), "odd-op")

    assert model.status is ModelStatus.AVAILABLE
    assert model.scrutiny_text.startswith("cannot be scrutineered: operation Sin")


def test_the_openvino_ir_some_tools_add_beside_the_pb_is_accepted(stack: Any, aws_clients: Any) -> None:
    extra = {"agent/model.xml": b"<?xml version='1.0'?><net/>", "agent/model.bin": b"\x00" * 64,
             "agent/model.mapping": b"<mapping/>"}
    _, model = _upload(aws_clients, stack, console_fixture.console_archive(extra=extra), "with-ir", converter=None)
    assert model.status is ModelStatus.AVAILABLE and model.model_kind == "tensorflow"
    files = console_fixture.members()
    assert model.model_md5 == hashlib.md5(files["agent/model.pb"]).hexdigest()  # the car's checksum.txt


def test_a_spare_converter_worker_is_ready_before_the_upload_and_replaced_after_each_use() -> None:
    import io

    converter = ConsoleConverter(keep_spare=True)
    converter.warm_up()  # what asking to upload does: the worker loads OpenVINO while the archive travels
    spare = converter._spare
    assert spare is not None and spare.poll() is None
    archive = console_fixture.require_fixture().read_bytes()
    first = converter.convert(io.BytesIO(archive))
    assert first.scrutiny == "ready" and first.onnx, first.reason
    assert spare.wait(timeout=30) == 0, "the spare did the conversion, in a process of its own, and ended"
    replacement = converter._spare
    assert replacement is not None and replacement is not spare and replacement.poll() is None
    replacement.kill()  # a spare that died meanwhile: the next conversion starts a worker of its own
    replacement.wait(timeout=30)
    second = converter.convert(io.BytesIO(archive))
    assert second.scrutiny == "ready" and second.onnx == first.onnx
    if converter._spare is not None:  # no stray process left behind by the test
        converter._spare.kill()
        converter._spare.wait(timeout=30)


def test_the_converter_runs_at_the_lowest_cpu_priority_so_the_public_pages_stay_fast() -> None:
    """A console upload loads OpenVINO and converts in a worker the app server starts; on a 2-core venue laptop it
    must take only the CPU the pages being watched do not want (SCHED_IDLE, niced, on the last core only: idle-class
    work on every core still lengthened the board's tail), never compete with them."""
    import os

    converter = ConsoleConverter(keep_spare=True)
    converter.warm_up()
    spare = converter._spare
    assert spare is not None
    try:
        assert os.sched_getscheduler(spare.pid) == os.SCHED_IDLE
        assert os.getpriority(os.PRIO_PROCESS, spare.pid) >= os.getpriority(os.PRIO_PROCESS, 0) + 10
        ours = sorted(os.sched_getaffinity(0))
        assert sorted(os.sched_getaffinity(spare.pid)) == (ours[-1:] if len(ours) > 1 else ours)
    finally:
        spare.kill()
        spare.wait(timeout=30)
