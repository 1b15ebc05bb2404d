"""Uploaded model archives are hostile: every archive here is built in the test with tarfile/gzip, fed to
`inspect_archive` and `safe_extract`, and must come back QUARANTINED or NOT_VALID with a reason a racer can read, with
nothing written outside a throw-away sandbox. The two real layouts (console TensorFlow, drem ONNX) must be AVAILABLE."""
from __future__ import annotations

import gzip
import hashlib
import io
import json
import os
import stat
import tarfile
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import onnx
import pytest
from onnx import TensorProto, helper

from chalicelib.formats.model_archive.extract import ArchiveRejected, safe_extract
from chalicelib.formats.model_archive.limits import ArchiveLimits
from chalicelib.formats.model_archive.names import InvalidModelName, model_name_from_filename, validate_model_name
from chalicelib.formats.model_archive.report import ArchiveStatus
from chalicelib.formats.model_archive.verdict import inspect_archive

pytestmark = pytest.mark.unit

MiB = 1024 * 1024
QUARANTINED = ArchiveStatus.QUARANTINED
NOT_VALID = ArchiveStatus.NOT_VALID

CONSOLE_METADATA = {  # DRfC's default discrete model, as the console writes it
    "action_space": [
        {"steering_angle": angle, "speed": 0.6, "index": i} for i, angle in enumerate((-30, -15, 0, 15, 30))
    ],
    "sensor": ["FRONT_FACING_CAMERA"],
    "neural_network": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
    "training_algorithm": "clipped_ppo",
    "action_space_type": "discrete",
    "version": "5",
}
DREM_METADATA = {
    "action_space": {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.5, "high": 2.0}},
    "action_space_type": "continuous",
    "sensor": ["FRONT_FACING_CAMERA"],
    "neural_network": "DREM_SMALL_CNN",
    "training_algorithm": "behaviour_cloning",
    "version": "1",
    "drem_input": {"shape": [1, 120, 160, 1], "scale": "raw_0_255"},
}
FAKE_FROZEN_GRAPH = bytes(range(256)) * 64  # opaque bytes: we only hash a .pb, we never parse it


@dataclass
class Member:
    name: str
    data: bytes | None = b""
    type: bytes = tarfile.REGTYPE
    linkname: str = ""
    mode: int = 0o644
    size: int | None = None  # header size when it must differ from len(data)


def tar_bytes(members: list[Member], *, fmt: int = tarfile.PAX_FORMAT) -> bytes:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w", format=fmt) as archive:
        for member in members:
            info = tarfile.TarInfo(member.name)
            info.type = member.type
            info.linkname = member.linkname
            info.mode = member.mode
            if member.type in (tarfile.CHRTYPE, tarfile.BLKTYPE):
                info.devmajor, info.devminor = 1, 3
            data = member.data if member.type in tarfile.REGULAR_TYPES else None
            info.size = len(data) if data is not None else 0
            archive.addfile(info, io.BytesIO(data) if data is not None else None)
    return buffer.getvalue()


def tar_gz(members: list[Member], **options) -> bytes:
    return gzip.compress(tar_bytes(members, **options), mtime=0)


def metadata_member(document: dict | None = None, name: str = "model_metadata.json") -> Member:
    return Member(name, json.dumps(document or CONSOLE_METADATA).encode())


def console_members() -> list[Member]:
    return [Member("agent", None, tarfile.DIRTYPE, mode=0o755), Member("agent/model.pb", FAKE_FROZEN_GRAPH),
            metadata_member()]


def tiny_onnx_policy() -> bytes:
    """A real (if tiny) ONNX graph with the car's input contract: grayscale 1x120x160x1 in, 2 means out."""
    image = helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 120, 160, 1])
    means = helper.make_tensor_value_info("means", TensorProto.FLOAT, [1, 2])
    weights = helper.make_tensor("weights", TensorProto.FLOAT, [120 * 160, 2], [0.0] * (120 * 160 * 2))
    shape = helper.make_tensor("shape", TensorProto.INT64, [2], [1, 120 * 160])
    graph = helper.make_graph(
        [helper.make_node("Reshape", ["image", "shape"], ["flat"]), helper.make_node("MatMul", ["flat", "weights"],
                                                                                     ["means"])],
        "drem_policy", [image], [means], initializer=[weights, shape],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    onnx.checker.check_model(model)
    return model.SerializeToString()


def snapshot(root: Path) -> set[str]:
    return {str(path.relative_to(root)) for path in root.rglob("*")}


class CountingStream(io.RawIOBase):
    """A non-seekable upload stream that records how many compressed bytes the validator pulled."""

    def __init__(self, data: bytes) -> None:
        self._data = io.BytesIO(data)
        self.bytes_read = 0

    def readable(self) -> bool:
        return True

    def read(self, size: int = -1) -> bytes:
        chunk = self._data.read(size)
        self.bytes_read += len(chunk)
        return chunk

    def readinto(self, buffer) -> int:
        chunk = self.read(len(buffer))
        buffer[: len(chunk)] = chunk
        return len(chunk)


@pytest.fixture(scope="module")
def gzip_of_300_mib_of_zeros() -> bytes:
    """~300 KiB of gzip that inflates to 300 MiB. gzip members concatenate, so a header can be glued in front."""
    compressor = zlib.compressobj(9, zlib.DEFLATED, 31)
    block = bytes(MiB)
    return b"".join([*(compressor.compress(block) for _ in range(300)), compressor.flush()])


# --- the dangerous ones: QUARANTINED ----------------------------------------------------------------------------

def _traversal(tmp: Path) -> list[Member]:
    return [*console_members(), Member("../escaped.txt", b"owned")]


def _deep_traversal(tmp: Path) -> list[Member]:
    return [Member("agent/../../escaped.txt", b"owned"), *console_members()]


def _absolute(tmp: Path) -> list[Member]:
    return [*console_members(), Member(str(tmp / "escaped.txt"), b"owned")]


def _symlink_then_write_through(tmp: Path) -> list[Member]:
    return [Member("agent", type=tarfile.SYMTYPE, linkname=str(tmp)), Member("agent/escaped.txt", b"owned"),
            metadata_member()]


def _hardlink(tmp: Path) -> list[Member]:
    return [*console_members(), Member("passwd", type=tarfile.LNKTYPE, linkname="/etc/passwd")]


def _char_device(tmp: Path) -> list[Member]:
    return [*console_members(), Member("null", type=tarfile.CHRTYPE)]


def _block_device(tmp: Path) -> list[Member]:
    return [*console_members(), Member("sda", type=tarfile.BLKTYPE)]


def _fifo(tmp: Path) -> list[Member]:
    return [*console_members(), Member("pipe", type=tarfile.FIFOTYPE)]


def _nul_in_name(tmp: Path) -> list[Member]:
    # A long name travels in a pax header, where a NUL survives; C tools would cut the name at the NUL.
    return [*console_members(), Member("agent/" + "x" * 120 + "\x00/../../escaped.txt", b"owned")]


def _backslash_traversal(tmp: Path) -> list[Member]:
    return [*console_members(), Member("..\\..\\escaped.txt", b"owned")]


def _drive_letter(tmp: Path) -> list[Member]:
    return [*console_members(), Member("C:/Windows/escaped.txt", b"owned")]


def _control_characters(tmp: Path) -> list[Member]:
    return [*console_members(), Member("agent/model.pb\n\x1b[2Jfine.txt", b"owned")]


def _bidi_override(tmp: Path) -> list[Member]:
    # "Trojan Source": U+202E shows `model\u202egnp.pb` as `modelbp.png` to whoever reviews the listing.
    return [*console_members(), Member("agent/model\u202egnp.pb", b"owned")]


def _isolate_and_zero_width(tmp: Path) -> list[Member]:
    return [*console_members(), Member("agent/\u2066model\u200b.pb\u2069", b"owned")]


def _c1_control(tmp: Path) -> list[Member]:
    return [*console_members(), Member("agent/next\x85line.txt", b"owned")]


QUARANTINE_CASES: dict[str, tuple[Callable[[Path], list[Member]], str]] = {
    "path traversal": (_traversal, "'..'"),
    "traversal hidden in a folder": (_deep_traversal, "'..'"),
    "absolute path": (_absolute, "absolute path"),
    "symlink then write through it": (_symlink_then_write_through, "symbolic link"),
    "hardlink": (_hardlink, "hard link"),
    "char device": (_char_device, "device file"),
    "block device": (_block_device, "device file"),
    "fifo": (_fifo, "named pipe"),
    "NUL in name": (_nul_in_name, "NUL byte"),
    "backslash traversal": (_backslash_traversal, "backslash"),
    "drive letter": (_drive_letter, "drive letter"),
    "control characters in name": (_control_characters, "control characters"),
    "bidi override in name": (_bidi_override, "U+202E"),
    "bidi isolate and zero-width space in name": (_isolate_and_zero_width, "U+2066"),
    "C1 control (NEL) in name": (_c1_control, "U+0085"),
}


@pytest.mark.parametrize("case", QUARANTINE_CASES, ids=list(QUARANTINE_CASES))
def test_dangerous_archives_are_quarantined_and_nothing_escapes(case: str, tmp_path: Path) -> None:
    build, reason_part = QUARANTINE_CASES[case]
    archive = tmp_path / "upload.tar.gz"
    archive.write_bytes(tar_gz(build(tmp_path)))
    sandboxes = tmp_path / "sandboxes"
    sandboxes.mkdir()
    before = snapshot(tmp_path)

    report = inspect_archive(archive)
    assert report.status is QUARANTINED
    assert reason_part in (report.reason or "")
    assert report.model_md5 is None and report.metadata is None

    with pytest.raises(ArchiveRejected) as rejected:
        safe_extract(archive, sandboxes)
    assert rejected.value.report.status is QUARANTINED

    assert snapshot(tmp_path) == before  # no sandbox left behind, nothing written beside it
    assert not (tmp_path / "escaped.txt").exists()
    assert not (tmp_path.parent / "escaped.txt").exists()


def test_traversal_in_the_middle_does_not_leave_earlier_files_behind(tmp_path: Path) -> None:
    archive = tar_gz([*console_members(), Member("../escaped.txt", b"owned"), Member("model.onnx", b"late")])

    with pytest.raises(ArchiveRejected):
        safe_extract(io.BytesIO(archive), tmp_path)

    assert list(tmp_path.iterdir()) == []


# --- data smuggled after the tar end marker: QUARANTINED ------------------------------------------------------------

_HIDDEN = [Member("../escaped.txt", b"owned")]


def _members_tar_i_would_extract(archive: bytes) -> list[str]:
    """What `tar --ignore-zeros` (and bsdtar, which reads on past the marker) would unpack: the attack is real."""
    with tarfile.open(fileobj=io.BytesIO(gzip.decompress(archive)), mode="r:", ignore_zeros=True) as reader:
        return reader.getnames()


def _without_end_marker(tar: bytes) -> bytes:
    with tarfile.open(fileobj=io.BytesIO(tar), mode="r:") as reader:
        reader.getmembers()
        return tar[: reader.offset]


SMUGGLED_CASES: dict[str, Callable[[], bytes]] = {
    "tar member after the end marker": lambda: gzip.compress(tar_bytes(console_members()) + tar_bytes(_HIDDEN)),
    "second gzip member": lambda: tar_gz(console_members()) + tar_gz(_HIDDEN),
    "member after a lone zero block": lambda: gzip.compress(
        _without_end_marker(tar_bytes(console_members())) + bytes(tarfile.BLOCKSIZE) + tar_bytes(_HIDDEN)),
    "member far past tarfile's read-ahead": lambda: gzip.compress(
        tar_bytes(console_members()) + bytes(256 * 1024) + tar_bytes(_HIDDEN)),
}


@pytest.mark.parametrize("case", SMUGGLED_CASES, ids=list(SMUGGLED_CASES))
def test_data_after_the_tar_end_marker_is_quarantined(case: str, tmp_path: Path) -> None:
    archive = SMUGGLED_CASES[case]()
    assert "../escaped.txt" in _members_tar_i_would_extract(archive)

    report = inspect_archive(io.BytesIO(archive))

    assert report.status is QUARANTINED, report
    assert "after the tar end marker" in (report.reason or "")
    with pytest.raises(ArchiveRejected):
        safe_extract(io.BytesIO(archive), tmp_path)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("padding", [
    pytest.param(lambda tar: gzip.compress(tar + bytes(64 * 1024)), id="extra zero records"),
    pytest.param(lambda tar: gzip.compress(tar) + gzip.compress(bytes(4096)), id="a gzip member of zeros"),
    pytest.param(lambda tar: gzip.compress(tar) + bytes(512), id="zeros after the gzip stream"),
])
def test_zero_padding_after_the_end_marker_is_still_a_valid_model(padding: Callable[[bytes], bytes]) -> None:
    report = inspect_archive(io.BytesIO(padding(tar_bytes(console_members()))))

    assert report.status is ArchiveStatus.AVAILABLE, report.reason
    assert report.model_md5 == hashlib.md5(FAKE_FROZEN_GRAPH).hexdigest()


# --- broken or unusable: NOT_VALID --------------------------------------------------------------------------------

def _zip_file() -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("model_metadata.json", json.dumps(CONSOLE_METADATA))
    return buffer.getvalue()


def _with_metadata_text(text: bytes) -> bytes:
    return tar_gz([Member("agent/model.pb", FAKE_FROZEN_GRAPH), Member("model_metadata.json", text)])


def _with_metadata(document: dict) -> bytes:
    return tar_gz([Member("agent/model.pb", FAKE_FROZEN_GRAPH), metadata_member(document)])


def pax_record(keyword: bytes, value: bytes) -> bytes:
    body = b" " + keyword + b"=" + value + b"\n"
    length = len(body) + 1
    length += len(str(length + len(str(length)))) - 1
    return str(length).encode() + body


def raw_header(kind: bytes, payload: bytes, name: str = "pax_header") -> bytes:
    """A bare tar header plus its padded payload, for header types tarfile will not write on demand."""
    info = tarfile.TarInfo(name)
    info.type = kind
    info.size = len(payload)
    padding = -len(payload) % tarfile.BLOCKSIZE
    return info.tobuf(tarfile.USTAR_FORMAT) + payload + bytes(padding)


def _after_raw_headers(*headers: bytes) -> bytes:
    return gzip.compress(b"".join(headers) + tar_bytes(console_members()))


def _sparse_member() -> bytes:
    sparse = tarfile.TarInfo("agent/model.pb")
    sparse.type = tarfile.GNUTYPE_SPARSE
    return _after_raw_headers(sparse.tobuf(tarfile.GNU_FORMAT))


_VALID = tar_gz(console_members())

NOT_VALID_CASES: dict[str, tuple[Callable[[], bytes], str]] = {
    "not gzip at all": (lambda: b"this is a reward function, not a model\n" * 20, "not gzip-compressed"),
    "empty file": (lambda: b"", "empty"),
    "uncompressed tar": (lambda: tar_bytes(console_members()), "uncompressed .tar"),
    "zip instead of tar.gz": (_zip_file, "zip file"),
    "not a tar (gzip of text)": (lambda: gzip.compress(os.urandom(64).hex().encode() * 50), "not contain a valid tar"),
    "truncated gzip (half)": (lambda: _VALID[: len(_VALID) // 2], "truncated"),
    "truncated gzip (trailer cut)": (lambda: _VALID[:-4], "truncated"),
    "corrupt gzip (CRC)": (lambda: _VALID[:-8] + bytes(b ^ 0xFF for b in _VALID[-8:-4]) + _VALID[-4:], "corrupt"),
    "too many members": (lambda: tar_gz([*console_members(), *(Member(f"log/{i}.txt") for i in range(70))]),
                         "more than 64 files"),
    "sparse member": (_sparse_member, "sparse file"),
    "thousands of pax global headers": (
        lambda: _after_raw_headers(*[raw_header(tarfile.XGLTYPE, pax_record(f"k{i}".encode(), b"v"))
                                     for i in range(500)]), "tar extension headers"),
    "pax header with a broken charset": (
        lambda: _after_raw_headers(raw_header(tarfile.XHDTYPE, pax_record(b"hdrcharset", b"\xff\xfe"))),
        "malformed"),
    "missing metadata": (lambda: tar_gz([Member("agent/model.pb", FAKE_FROZEN_GRAPH)]), "no model_metadata.json"),
    "metadata only in a sub-folder": (lambda: tar_gz([Member("agent/model.pb", FAKE_FROZEN_GRAPH),
                                                      metadata_member(name="other/model_metadata.json")]),
                                      "no model_metadata.json"),
    "invalid JSON": (lambda: _with_metadata_text(b'{"action_space": [,]}'), "not valid JSON"),
    "JSON is not an object": (lambda: _with_metadata_text(b"[1, 2, 3]"), "JSON object"),
    "huge JSON": (lambda: _with_metadata_text(json.dumps({**CONSOLE_METADATA, "pad": "x" * 70_000}).encode()),
                  "at most 64.0 KiB"),
    "deeply nested JSON": (lambda: _with_metadata_text(b"[" * 30_000 + b"]" * 30_000), "nested too deeply"),
    "repeated JSON key": (lambda: _with_metadata_text(b'{"action_space": [], "action_space": 1}'), "appears twice"),
    "metadata schema error": (lambda: _with_metadata({**CONSOLE_METADATA, "action_space": [
        {"steering_angle": 0, "speed": 9}]}), "action_space[0].speed"),
    "metadata type disagrees": (lambda: _with_metadata({**DREM_METADATA, "action_space_type": "discrete"}),
                                "action_space_type"),
    "missing model file": (lambda: tar_gz([metadata_member(), Member("agent/model.xml", b"<net/>")]),
                           "no model file"),
    "empty model file": (lambda: tar_gz([metadata_member(), Member("model.onnx", b"")]), "empty"),
    "two models": (lambda: tar_gz([*console_members(), Member("model.onnx", b"onnx")]), "both"),
    "duplicate names": (lambda: tar_gz([*console_members(), metadata_member()]), "more than once"),
    "duplicate names via ./": (lambda: tar_gz([*console_members(), Member("./agent/model.pb", b"other")]),
                               "more than once"),
    "names differing only in case": (lambda: tar_gz([*console_members(), Member("agent/Model.pb", b"other")]),
                                     "more than once"),
    "file used as a folder": (lambda: tar_gz([Member("agent", b"file"), Member("agent/model.pb", b"x"),
                                              metadata_member()]), "both as a file and as a folder"),
}


@pytest.mark.parametrize("case", NOT_VALID_CASES, ids=list(NOT_VALID_CASES))
def test_broken_archives_are_not_valid_with_a_reason(case: str, tmp_path: Path) -> None:
    build, reason_part = NOT_VALID_CASES[case]
    archive = tmp_path / "upload.tar.gz"
    archive.write_bytes(build())
    before = snapshot(tmp_path)

    report = inspect_archive(archive)
    assert report.status is NOT_VALID, report
    assert reason_part in (report.reason or ""), report.reason
    assert report.model_md5 is None

    with pytest.raises(ArchiveRejected) as rejected:
        safe_extract(archive, tmp_path)
    assert rejected.value.report.status is NOT_VALID
    assert rejected.value.field == "archive"
    assert snapshot(tmp_path) == before


def test_gzip_bomb_is_stopped_at_the_header_without_inflating(gzip_of_300_mib_of_zeros: bytes) -> None:
    header = tar_bytes([metadata_member()])[:-2 * tarfile.RECORDSIZE]  # keep the tar open: no end-of-archive
    bomb_header = tarfile.TarInfo("agent/model.pb")
    bomb_header.size = 300 * MiB
    upload = CountingStream(gzip.compress(header + bomb_header.tobuf(tarfile.PAX_FORMAT)) + gzip_of_300_mib_of_zeros)

    report = inspect_archive(upload)

    assert report.status is NOT_VALID
    assert "'agent/model.pb' is 300.0 MiB" in (report.reason or "")
    assert upload.bytes_read < len(gzip_of_300_mib_of_zeros) / 2  # stopped long before the end of the bomb


def test_gnu_long_name_bomb_is_refused_before_it_is_read_into_memory(gzip_of_300_mib_of_zeros: bytes) -> None:
    long_name = tarfile.TarInfo("././@LongLink")
    long_name.type = tarfile.GNUTYPE_LONGNAME
    long_name.size = 300 * MiB
    upload = CountingStream(gzip.compress(long_name.tobuf(tarfile.GNU_FORMAT)) + gzip_of_300_mib_of_zeros)

    report = inspect_archive(upload)

    assert report.status is NOT_VALID
    assert "300.0 MiB tar header" in (report.reason or "")
    assert upload.bytes_read < len(gzip_of_300_mib_of_zeros) / 2


def test_zeros_after_the_tar_end_stop_at_the_inflate_budget(gzip_of_300_mib_of_zeros: bytes) -> None:
    report = inspect_archive(io.BytesIO(_VALID + gzip_of_300_mib_of_zeros))

    assert report.status is NOT_VALID
    assert "compression bomb" in (report.reason or "")


def test_total_size_is_counted_across_members_before_reading_the_one_that_overflows() -> None:
    limits = ArchiveLimits(max_total_bytes=5 * MiB, max_member_bytes=4 * MiB)
    archive = tar_gz([*console_members(), *(Member(f"agent/part{i}.bin", bytes(2 * MiB)) for i in range(3))])

    report = inspect_archive(io.BytesIO(archive), limits=limits)

    assert report.status is NOT_VALID
    assert "add up to more than 5.0 MiB" in (report.reason or "")
    assert report.member_count == 6  # three layout members, two parts read, refused at the third header


def test_single_member_over_limit_is_refused() -> None:
    limits = ArchiveLimits(max_member_bytes=1 * MiB)
    archive = tar_gz([metadata_member(), Member("agent/model.pb", bytes(2 * MiB))])

    report = inspect_archive(io.BytesIO(archive), limits=limits)

    assert report.status is NOT_VALID
    assert report.reason == "'agent/model.pb' is 2.0 MiB; a single file may be at most 1.0 MiB"


def test_oversize_compressed_upload_is_refused_from_a_path_and_from_a_stream(tmp_path: Path) -> None:
    limits = ArchiveLimits(max_compressed_bytes=64 * 1024)
    archive = tar_gz([*console_members(), Member("agent/noise.bin", os.urandom(200 * 1024))])  # incompressible
    path = tmp_path / "big.tar.gz"
    path.write_bytes(archive)
    stream = CountingStream(archive)

    from_path = inspect_archive(path, limits=limits)
    from_stream = inspect_archive(stream, limits=limits)

    assert from_path.status is NOT_VALID and "uploads are limited to 64.0 KiB" in (from_path.reason or "")
    assert from_stream.status is NOT_VALID and "larger than the 64.0 KiB upload limit" in (from_stream.reason or "")
    assert stream.bytes_read <= 64 * 1024 + 1


# --- the real layouts: AVAILABLE ----------------------------------------------------------------------------------

def test_console_layout_is_available_with_the_md5s_drem_keeps(tmp_path: Path) -> None:
    metadata_bytes = json.dumps(CONSOLE_METADATA).encode()
    archive = tmp_path / "Console-model_1.tar.gz"
    archive.write_bytes(tar_gz(console_members()))

    report = inspect_archive(archive)

    assert report.status is ArchiveStatus.AVAILABLE and report.reason is None
    assert report.model_kind == "tensorflow" and report.model_member == "agent/model.pb"
    assert report.model_md5 == hashlib.md5(FAKE_FROZEN_GRAPH).hexdigest()
    assert report.metadata_md5 == hashlib.md5(metadata_bytes).hexdigest()
    assert report.sensor == ["FRONT_FACING_CAMERA"]
    assert (report.action_space_type, report.training_algorithm) == ("discrete", "clipped_ppo")
    assert report.metadata is not None and report.metadata.action_count == 5
    assert report.member_count == 3
    assert report.total_size == len(FAKE_FROZEN_GRAPH) + len(metadata_bytes)


def test_onnx_layout_is_available_and_keeps_our_own_metadata_keys() -> None:
    policy = tiny_onnx_policy()
    archive = tar_gz([Member("model.onnx", policy), metadata_member(DREM_METADATA)])

    report = inspect_archive(io.BytesIO(archive))

    assert report.status is ArchiveStatus.AVAILABLE
    assert report.model_kind == "onnx" and report.model_member == "model.onnx"
    assert report.model_md5 == hashlib.md5(policy).hexdigest()
    assert report.metadata_md5 == hashlib.md5(json.dumps(DREM_METADATA).encode()).hexdigest()
    assert (report.action_space_type, report.training_algorithm) == ("continuous", "behaviour_cloning")
    assert report.metadata is not None
    assert report.metadata.model_dump(mode="json")["drem_input"] == DREM_METADATA["drem_input"]


@pytest.mark.parametrize(
    "members",
    [
        pytest.param([Member("model.pb", FAKE_FROZEN_GRAPH), metadata_member()], id="flat DROA layout"),
        pytest.param([Member(".", None, tarfile.DIRTYPE), Member("./agent/model.pb", FAKE_FROZEN_GRAPH),
                      metadata_member(name="./model_metadata.json")], id="tar -C dir ."),
        pytest.param([Member("agent/model.pb", FAKE_FROZEN_GRAPH),
                      metadata_member(name="agent/model_metadata.json")], id="metadata under agent/"),
    ],
)
def test_other_real_producers_layouts_are_available(members: list[Member]) -> None:
    report = inspect_archive(io.BytesIO(tar_gz(members, fmt=tarfile.GNU_FORMAT)))

    assert report.status is ArchiveStatus.AVAILABLE, report.reason
    assert report.model_kind == "tensorflow"
    assert report.model_md5 == hashlib.md5(FAKE_FROZEN_GRAPH).hexdigest()


def test_a_non_seekable_stream_gives_the_same_verdict_as_a_file(tmp_path: Path) -> None:
    path = tmp_path / "model.tar.gz"
    path.write_bytes(_VALID)

    assert inspect_archive(CountingStream(_VALID)) == inspect_archive(path)


def test_safe_extract_writes_only_regular_files_into_a_fresh_sandbox(tmp_path: Path) -> None:
    policy = tiny_onnx_policy()
    archive = tar_gz([Member("assets", None, tarfile.DIRTYPE, mode=0o777), Member("model.onnx", policy, mode=0o4755),
                      Member("assets/readme.txt", b"hi", mode=0o777), metadata_member(DREM_METADATA)])

    first = safe_extract(io.BytesIO(archive), tmp_path / "cars")
    second = safe_extract(io.BytesIO(archive), tmp_path / "cars")

    assert first.root != second.root and first.root.parent == second.root.parent == (tmp_path / "cars").resolve()
    assert snapshot(first.root) == {"assets", "assets/readme.txt", "model.onnx", "model_metadata.json"}
    for path in first.root.rglob("*"):
        assert not path.is_symlink()
        assert path.is_dir() or stat.S_ISREG(path.lstat().st_mode)
        if path.is_file():
            assert path.stat().st_mode & (stat.S_ISUID | stat.S_IXUSR | stat.S_IWOTH) == 0  # archive modes ignored
    assert first.model_path.read_bytes() == policy
    assert json.loads(first.metadata_path.read_text()) == DREM_METADATA
    assert onnx.load_model_from_string(first.model_path.read_bytes()).graph.name == "drem_policy"


# --- model names --------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["a", "Console-model_1", "x" * 64, "2018-CCW-Centerline-tracking"])
def test_good_model_names_pass(name: str) -> None:
    assert validate_model_name(name) == name


@pytest.mark.parametrize("name", ["", "x" * 65, "my model", "../evil", "model.v2", "modèle", "a/b", "name\n"])
def test_bad_model_names_are_refused_with_the_rule(name: str) -> None:
    with pytest.raises(InvalidModelName) as refused:
        validate_model_name(name)
    assert "1-64 letters, digits, '-' or '_'" in refused.value.message
    assert refused.value.field == "name"


def test_model_name_comes_from_the_upload_file_name() -> None:
    assert model_name_from_filename("AtoZ-CW-Steering-penalty.tar.gz") == "AtoZ-CW-Steering-penalty"
    with pytest.raises(InvalidModelName, match=r"\.tar\.gz"):
        model_name_from_filename("model.zip")
    with pytest.raises(InvalidModelName):
        model_name_from_filename("bad name.tar.gz")


def test_a_git_archive_style_global_header_is_fine() -> None:
    commit = raw_header(tarfile.XGLTYPE, pax_record(b"comment", b"4b825dc642cb6eb9a060e54bf8d69288fbee4904"))

    report = inspect_archive(io.BytesIO(_after_raw_headers(commit)))

    assert report.status is ArchiveStatus.AVAILABLE, report.reason
